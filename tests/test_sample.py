"""The chunked, resumable emcee driver: convergence gates on a known density and bit-identical resumes. A real
fit killed mid-sampling and resumed from its last chunk, and the command line's resume with a larger step limit,
are in tests/test_fanout.py (the Dask worker test)."""

from dataclasses import dataclass

import numpy as np
import pytest

from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.sample import (
    TARGETS,
    Convergence,
    IndependenceProposal,
    convergence,
    load_state,
    planned_chunk,
    sample,
    walker_count,
)


@dataclass
class Gaussian:
    """A correlated 3-D Gaussian with the duck type ``sample`` needs: ``names``, ``ndim``, ``batched``."""

    mean = np.array([1.0, -2.0, 0.5])
    cov = np.array([[1.0, 0.8, 0.0], [0.8, 1.0, 0.3], [0.0, 0.3, 0.5]])
    names = ("a", "b", "c")
    ndim = 3

    def batched(self, thetas):
        d = thetas - self.mean
        return -0.5 * np.einsum("ni,ij,nj->n", d, np.linalg.inv(self.cov), d)


def test_converges_on_a_gaussian_and_recovers_its_moments():
    g = Gaussian()
    result = sample(
        g,
        g.mean + 0.1,
        0.01 * np.eye(3),
        n_walkers=16,
        seed=3,
        chunk=1000,
        max_steps=20_000,
        progress=False,
        log=lambda m: None,
    )
    conv = result.convergence
    assert conv.converged, conv.problems
    assert conv.tau_lengths >= TARGETS["min_tau_lengths"]
    assert np.all(conv.rhat <= 1.01) and np.all(conv.ess_bulk >= 1000)
    draws = result.kept().reshape(-1, 3)
    # Means within 5 Monte Carlo standard errors (sd / sqrt(ESS)); covariance within 10 %.
    se = np.sqrt(np.diag(g.cov) / conv.ess_bulk)
    assert np.all(np.abs(draws.mean(axis=0) - g.mean) < 5 * se)
    np.testing.assert_allclose(np.cov(draws.T), g.cov, atol=0.1)


def test_a_converged_run_goes_on_to_min_steps_and_begins_as_the_shorter_run():
    """``min_steps`` lengthens a run the rule has certified, in chunks, to exactly ``min_steps``; the seeds are
    the same, so its first steps are the shorter run's, bit for bit."""
    g = Gaussian()
    kw = dict(n_walkers=16, seed=3, chunk=400, warmup=100, max_steps=20_000, progress=False, log=lambda m: None)
    short = sample(g, g.mean + 0.1, 0.01 * np.eye(3), **kw)
    assert short.convergence.converged
    steps = short.chain.shape[0]
    longer = sample(g, g.mean + 0.1, 0.01 * np.eye(3), min_steps=steps + 450, **kw)
    assert longer.chain.shape[0] == steps + 450 and longer.convergence.converged
    assert [c["steps"] for c in longer.chunks][-2:] == [steps + 400, steps + 450]
    np.testing.assert_array_equal(longer.chain[:steps], short.chain)


def test_a_lengthened_run_resumes_to_the_same_chain_and_min_steps_cannot_exceed_the_limit(tmp_path):
    """Stopped part way through the lengthening (a step limit below ``min_steps`` is refused, so stop by a
    smaller ``min_steps`` with the same limit) and resumed, the run is the uninterrupted one, bit for bit."""
    g = Gaussian()
    kw = dict(n_walkers=16, seed=3, chunk=400, warmup=100, progress=False, log=lambda m: None)
    short = sample(g, g.mean + 0.1, 0.01 * np.eye(3), max_steps=20_000, **kw)
    steps = short.chain.shape[0]
    whole = sample(g, g.mean + 0.1, 0.01 * np.eye(3), max_steps=steps + 450, min_steps=steps + 450, **kw)
    state = tmp_path / "state.npz"
    first = sample(
        g, g.mean + 0.1, 0.01 * np.eye(3), max_steps=steps + 200, min_steps=steps + 200, state_path=state, **kw
    )
    assert first.chain.shape[0] == steps + 200
    rest = sample(
        g,
        g.mean + 0.1,
        0.01 * np.eye(3),
        max_steps=steps + 450,
        min_steps=steps + 450,
        state_path=state,
        resume=True,
        **kw,
    )
    np.testing.assert_array_equal(rest.chain, whole.chain)
    with pytest.raises(PeanoBayesInputError, match=r"min_steps \(500\) exceeds max_steps \(400\)"):
        sample(g, g.mean, 0.05 * np.eye(3), max_steps=400, min_steps=500, **kw)
    with pytest.raises(PeanoBayesInputError, match="chunk must be >= 1"):
        sample(g, g.mean, 0.05 * np.eye(3), **{**kw, "chunk": 0})


def test_independence_move_alone_samples_the_target_despite_a_wrong_proposal():
    """The Hastings factor is right: an MH chain whose only move is a proposal centred off the target and
    with the wrong shape still has the target's mean and covariance (a sign error would bias both)."""
    import emcee

    g = Gaussian()
    proposal = IndependenceProposal(g.mean + np.array([0.5, -0.3, 0.2]), np.diag([2.0, 1.5, 1.0]), df=5.0)
    sampler = emcee.EnsembleSampler(8, 3, g.batched, vectorize=True, moves=[(emcee.moves.MHMove(proposal), 1.0)])
    rng = np.random.RandomState(11)
    start = emcee.State(rng.multivariate_normal(g.mean, g.cov, 8), random_state=rng.get_state())
    sampler.run_mcmc(start, 6000, progress=False)
    draws = sampler.get_chain(discard=200, flat=True)
    tau = float(np.max(emcee.autocorr.integrated_time(sampler.get_chain(discard=200), tol=0)))
    se = np.sqrt(np.diag(g.cov) * tau / draws.shape[0])
    assert np.all(np.abs(draws.mean(axis=0) - g.mean) < 5 * se)
    np.testing.assert_allclose(np.cov(draws.T), g.cov, atol=0.06)


def test_proposal_log_density_matches_its_own_draws():
    proposal = IndependenceProposal(np.array([1.0, 2.0]), np.array([[1.0, 0.3], [0.3, 0.5]]), df=4.0)
    new, factor = proposal(np.zeros((4000, 2)), np.random.RandomState(0))
    # Draws have the t's mean, and covariance df / (df - 2) times the scale matrix.
    np.testing.assert_allclose(new.mean(axis=0), proposal.mean, atol=0.06)
    np.testing.assert_allclose(np.cov(new.T), 2.0 * proposal.covariance, rtol=0.15, atol=0.05)
    np.testing.assert_allclose(factor, proposal.log_density(np.zeros((4000, 2))) - proposal.log_density(new))


def test_proposal_draws_with_a_generator_as_the_move_does_with_a_random_state():
    """``draw`` takes a ``Generator`` too (importance_sampling.py): the t's mean and covariance df / (df - 2)
    times the scale matrix; and the emcee move's points are ``draw``'s from the same random state."""
    proposal = IndependenceProposal(np.array([1.0, 2.0]), np.array([[1.0, 0.3], [0.3, 0.5]]), df=4.0)
    x = proposal.draw(4000, np.random.default_rng(5))
    np.testing.assert_allclose(x.mean(axis=0), proposal.mean, atol=0.06)
    np.testing.assert_allclose(np.cov(x.T), 2.0 * proposal.covariance, rtol=0.15, atol=0.05)
    moved, _ = proposal(np.zeros((7, 2)), np.random.RandomState(9))
    np.testing.assert_array_equal(moved, proposal.draw(7, np.random.RandomState(9)))


def test_proposal_log_density_is_scipys_multivariate_t():
    from scipy import stats

    cov = np.array([[1.0, 0.3, 0.1], [0.3, 0.5, -0.2], [0.1, -0.2, 2.0]])
    proposal = IndependenceProposal(np.array([1.0, 2.0, -1.0]), cov, df=5.0)
    x = np.random.default_rng(3).normal(size=(50, 3)) * 3
    np.testing.assert_allclose(
        proposal.log_density(x), stats.multivariate_t(proposal.mean, cov, df=5.0).logpdf(x), rtol=1e-12
    )


def test_proposal_from_stuck_walkers_is_still_usable():
    """A short warm-up where walkers never moved: 12 draws of 9 parameters, all on two points (rank 1). The
    fitted proposal must still draw and evaluate finite densities (CI's wheel smoke failed here)."""
    rng = np.random.default_rng(0)
    two = rng.normal(size=(2, 9))
    proposal = IndependenceProposal.fit(np.repeat(two, 6, axis=0))
    new, factor = proposal(np.repeat(two, 2, axis=0), np.random.RandomState(1))
    assert np.all(np.isfinite(new)) and np.all(np.isfinite(factor))


def test_a_step_limit_inside_the_warmup_says_so():
    g = Gaussian()
    result = sample(
        g, g.mean, 0.01 * np.eye(3), n_walkers=8, seed=0, warmup=300, max_steps=100, progress=False, log=lambda m: None
    )
    assert result.chain.shape == (100, 4 * 8, 3)  # four ensembles of eight walkers
    assert not result.convergence.converged
    assert "inside the warm-up" in result.convergence.problems[0]
    assert result.warmup == 300  # the run's own warm-up, what summary.json records


def test_step_limit_gives_an_unconverged_result_that_says_why():
    g = Gaussian()
    result = sample(
        g,
        g.mean,
        0.01 * np.eye(3),
        n_walkers=8,
        seed=0,
        chunk=50,
        warmup=30,
        max_steps=100,
        progress=False,
        log=lambda m: None,
    )
    assert result.chain.shape == (100, 4 * 8, 3)
    assert not result.convergence.converged
    assert any("autocorrelation times" in p for p in result.convergence.problems)


def figures(tau, ess, discard):
    """A not-yet-converged :class:`Convergence` of two parameters: the first's tau and bulk ESS are the given
    ones (the binding ones), its tail ESS twice that."""
    tau, bulk = np.array([tau, tau / 2]), np.array([ess, 2 * ess])  # the first parameter binds
    return Convergence(tau, discard, 0.0, np.ones(2), bulk, 2 * bulk, False, ("not yet",), 4)


def test_the_next_chunk_is_what_tau_and_ess_say_is_missing():
    # tau 20 after 300 sampled steps (warm-up 300, discard 340): 22 tau = 440 steps, plus a tenth: 484, so 184.
    assert planned_chunk(figures(20.0, 5000.0, 340), 600, 300, 500) == 184
    # Early on the chunk caps it: tau 40, 968 - 300 sampled = 668 > 500.
    assert planned_chunk(figures(40.0, 5000.0, 380), 600, 300, 500) == 500
    # ESS-bound: tau 2 (44 steps suffice), ESS 500 of 1000 on 400 kept steps of 500 sampled: 400 more kept
    # steps, 900 sampled, a tenth more: 990, so 490.
    assert planned_chunk(figures(2.0, 500.0, 400), 800, 300, 1000) == 490
    # Nearly there: never fewer than MIN_CHUNK (50); tau undefined (a stuck walker): the whole chunk.
    assert planned_chunk(figures(20.0, 5000.0, 340), 780, 300, 500) == 50
    assert planned_chunk(figures(np.inf, 5000.0, 340), 1300, 300, 500) == 500


def test_resume_continues_bit_identically(tmp_path):
    g = Gaussian()
    kw = dict(n_walkers=8, seed=7, chunk=40, warmup=30, progress=False, log=lambda m: None)
    whole = sample(g, g.mean, 0.05 * np.eye(3), max_steps=120, **kw)
    state = tmp_path / "state.npz"
    first = sample(g, g.mean, 0.05 * np.eye(3), max_steps=80, state_path=state, **kw)
    assert load_state(state)[0].shape[0] == 80
    rest = sample(g, g.mean, 0.05 * np.eye(3), max_steps=120, state_path=state, resume=True, **kw)
    assert rest.resumed_from == 80
    np.testing.assert_array_equal(rest.chain[:80], first.chain)
    np.testing.assert_array_equal(rest.chain, whole.chain)
    np.testing.assert_array_equal(rest.log_prob, whole.log_prob)
    # Resumed at the limit it already reached: the saved chain's own figures, not a warm-up message.
    again = sample(g, g.mean, 0.05 * np.eye(3), max_steps=120, state_path=state, resume=True, **kw)
    np.testing.assert_array_equal(again.chain, whole.chain)
    np.testing.assert_array_equal(again.convergence.rhat, whole.convergence.rhat)


def test_resume_refuses_a_state_of_another_run(tmp_path):
    g = Gaussian()
    kw = dict(n_walkers=8, chunk=20, state_path=tmp_path / "state.npz", progress=False, log=lambda m: None)
    sample(g, g.mean, 0.05 * np.eye(3), seed=1, warmup=10, max_steps=20, **kw)
    with pytest.raises(PeanoBayesInputError, match="another run: --seed: saved 1, now 2; give") as err:
        sample(g, g.mean, 0.05 * np.eye(3), seed=2, warmup=10, max_steps=40, resume=True, **kw)
    assert "--warmup" not in str(err.value)  # only what differs is named
    # Another warm-up is another run too, and the message gives the saved one (the default changed once).
    with pytest.raises(PeanoBayesInputError, match="another run: --warmup: saved 10, now 20; give"):
        sample(g, g.mean, 0.05 * np.eye(3), seed=1, warmup=20, max_steps=40, resume=True, **kw)
    with pytest.raises(
        PeanoBayesInputError, match=r"--walkers \(per ensemble\): saved 8, now 10; --seed: saved 1, now 3"
    ):
        sample(g, g.mean, 0.05 * np.eye(3), seed=3, warmup=10, max_steps=40, resume=True, **{**kw, "n_walkers": 10})


def test_a_resume_mismatch_names_the_parameters_only_one_side_has_and_what_an_old_state_lacks():
    from peano_bayes.inference.sample import _differences

    now = {"names": ["a", "b", "c"], "n_walkers": 8, "seed": 0, "warmup": 900, "coordinates": {"kind": "theta"}}
    assert _differences(dict(now), now) == []
    assert _differences({**now, "names": ["a", "d"]}, now) == ["sampled parameters: only saved: d; only now: b, c"]
    assert _differences({**now, "names": ["c", "b", "a"]}, now) == [
        "sampled parameters: the same names in another order"
    ]
    old = {k: v for k, v in now.items() if k not in ("warmup", "names")}  # written before these were recorded
    assert _differences(old, now) == [
        "sampled parameters: unrecorded in the saved state",
        "--warmup: saved unrecorded, now 900",
    ]
    # Coordinates that print alike but differ are shown whole; a key without a label is named as itself.
    shifted = {**now, "coordinates": {"kind": "theta", "scale": 2}, "chunk": 5}
    assert _differences({**now, "chunk": 4}, shifted) == [
        "--coordinates: saved {'kind': 'theta'}, now {'kind': 'theta', 'scale': 2}",
        "chunk: saved 4, now 5",
    ]


def test_too_few_walkers_for_the_dimension_is_an_input_error():
    assert walker_count(None, 20) == 42 and walker_count(None, 3) == 32 and walker_count(9, 4) == 10
    with pytest.raises(PeanoBayesInputError, match="fewer than twice the 14 sampled parameters"):
        walker_count(24, 14)


def test_one_ensemble_never_certifies_convergence():
    chain = np.random.default_rng(6).normal(size=(3000, 32, 2))
    conv = convergence(chain, ("x", "y"), n_ensembles=1)
    assert not conv.converged and "at least 4" in conv.problems[0]


def test_convergence_flags_a_stuck_chain():
    rng = np.random.default_rng(0)
    # Each walker sits still: R-hat is huge and tau is the whole chain.
    chain = np.repeat(rng.normal(size=(1, 8, 2)), 200, axis=0) + 1e-9 * rng.normal(size=(200, 8, 2))
    conv = convergence(chain, ("x", "y"), n_ensembles=4)
    assert not conv.converged
    assert any("R-hat" in p for p in conv.problems)


def test_convergence_of_a_chain_with_a_walker_that_never_moved_is_a_verdict_not_an_error():
    rng = np.random.default_rng(1)
    chain = rng.normal(size=(30, 8, 2))
    chain[:, 0, 1] = 0.25  # one walker never accepted a move in y: its autocorrelation is 0/0
    conv = convergence(chain, ("x", "y"), n_ensembles=4)
    assert not conv.converged
    assert any("walker never moved" in p and "y" in p for p in conv.problems)
    assert 0 <= conv.discard <= 15


def test_main_job_continues_only_an_unconverged_material_with_kept_state_and_steps_left(tmp_path):
    from peano_bayes.app.batch import _can_continue

    unconverged = {"convergence": {"converged": False}, "steps": 20000}
    assert not _can_continue(unconverged, tmp_path, 40000)  # no sampler state kept
    (tmp_path / "sampler_state.npz").write_bytes(b"")
    assert _can_continue(unconverged, tmp_path, 40000)
    assert not _can_continue(unconverged, tmp_path, 20000)  # the limit allows no more steps
    assert not _can_continue({"convergence": {"converged": True}, "steps": 5000}, tmp_path, 40000)


# --- The convergence rule (nested R-hat across ensembles split in time, walker ESS, 20 stable tau) ---------


def ar1(rng, rho: float, shape) -> np.ndarray:
    """Stationary AR(1) draws of unit variance and lag-1 correlation ``rho`` along the first axis."""
    x = rng.normal(size=shape)
    for t in range(1, shape[0]):
        x[t] = rho * x[t - 1] + np.sqrt(1 - rho**2) * x[t]
    return x


def test_a_stationary_run_of_four_ensembles_is_certified():
    rng = np.random.default_rng(11)
    chain = ar1(rng, 0.8, (600, 4 * 16, 3))  # tau = (1 + 0.8) / (1 - 0.8) = 9 steps
    conv = convergence(chain, ("a", "b", "c"), n_ensembles=4, previous_tau=9.0)
    assert conv.converged, conv.problems
    assert np.all(conv.rhat < 1.005)
    assert 6.0 < conv.tau_max < 12.0


def test_a_run_whose_ensembles_drift_together_in_time_is_refused():
    """Every walker's mean moves by 0.6 sd over the run, the same in all four ensembles. The former rule laid each
    ensemble's walkers end to end and split that line in half (walkers against walkers, not early against late):
    it saw no difference and certified this run. Nested R-hat splits each ensemble in time and refuses it."""
    rng = np.random.default_rng(0)
    chain = rng.normal(size=(3000, 4 * 8, 2)) + np.linspace(-0.3, 0.3, 3000)[:, None, None]
    conv = convergence(chain, ("x", "y"), n_ensembles=4, previous_tau=1.5)
    assert conv.tau_lengths > 50 and np.all(conv.ess_bulk > 1000)  # long and "well mixed" by every other test
    assert not conv.converged
    assert np.all(conv.rhat > 1.01) and any("R-hat" in p for p in conv.problems)


def test_one_ensemble_stuck_in_a_second_mode_is_refused():
    rng = np.random.default_rng(5)
    chain = rng.normal(size=(800, 4 * 8, 2))
    good = convergence(chain, ("x", "y"), n_ensembles=4, previous_tau=1.0)
    assert good.converged, good.problems
    chain[:, :8, 0] += 3.0  # ensemble 1 sits in a mode 3 sd away in x and never leaves it
    bad = convergence(chain, ("x", "y"), n_ensembles=4, previous_tau=1.0)
    assert not bad.converged and bad.rhat[0] > 1.1 and bad.rhat[1] < 1.01
    assert any("R-hat misses its target for 1 parameter(s): x" in p for p in bad.problems)


def test_a_different_spread_in_one_ensemble_is_seen_by_the_folded_rhat():
    """Same mean, twice the sd in one ensemble: the rank-normalized R-hat of the draws barely moves; on the folded
    draws ``|x - median|`` it refuses."""
    from peano_bayes.inference.diagnostics import nested_rhat

    rng = np.random.default_rng(3)
    chain = rng.normal(size=(400, 4 * 16, 1))
    chain[:, :16] *= 2.0
    assert nested_rhat(chain, 4)[0] > 1.01


def test_nested_rhat_is_the_published_formula():
    """Against the definition of Margossian et al. (superchain means' variance over the mean within-superchain
    variance, which adds the subchains' means' spread to their own), written out with loops, on raw (not
    rank-normalized) draws of a case with unequal superchains."""
    from peano_bayes.inference.diagnostics import _nested_ratio

    rng = np.random.default_rng(2)
    k, m, n = 3, 4, 7
    x = rng.normal(size=(k, m, n, 1)) + np.arange(k)[:, None, None, None] * 0.5
    chain_means = [[sum(x[a, b, :, 0]) / n for b in range(m)] for a in range(k)]
    super_means = [sum(chain_means[a]) / m for a in range(k)]
    grand = sum(super_means) / k
    between = sum((s - grand) ** 2 for s in super_means) / (k - 1)
    within = 0.0
    for a in range(k):
        b_tilde = sum((c - super_means[a]) ** 2 for c in chain_means[a]) / (m - 1)
        w_tilde = sum(sum((v - chain_means[a][b]) ** 2 for v in x[a, b, :, 0]) / (n - 1) for b in range(m)) / m
        within += (b_tilde + w_tilde) / k
    np.testing.assert_allclose(_nested_ratio(x)[0], np.sqrt(1 + between / within), rtol=1e-12)


def test_walker_ess_of_independent_and_of_ar1_draws_is_their_known_size():
    """Independent draws: ESS is the number of draws; AR(1) with lag-1 0.8: ``N (1 - 0.8) / (1 + 0.8) = N / 9``
    (each within 15 %); the tail ESS of independent draws likewise."""
    from peano_bayes.inference.diagnostics import walker_ess

    rng = np.random.default_rng(4)
    white = rng.normal(size=(500, 32, 1))
    bulk, tail = walker_ess(white)
    np.testing.assert_allclose([bulk[0], tail[0]], 16000, rtol=0.15)
    red = ar1(rng, 0.8, (2000, 32, 1))
    np.testing.assert_allclose(walker_ess(red)[0][0], 64000 / 9, rtol=0.15)


def test_tau_max_must_be_stable_between_two_checks():
    rng = np.random.default_rng(8)
    chain = ar1(rng, 0.8, (600, 4 * 16, 2))
    first = convergence(chain, ("x", "y"), n_ensembles=4)
    assert not first.converged and first.problems == ("tau_max not yet compared between two checks",)
    grown = convergence(chain, ("x", "y"), n_ensembles=4, previous_tau=0.6 * first.tau_max)
    assert not grown.converged and "tau_max changed by 40 %" in grown.problems[0]
    steady = convergence(chain, ("x", "y"), n_ensembles=4, previous_tau=0.9 * first.tau_max)
    assert steady.converged and steady.tau_change == pytest.approx(0.1)


# --- The adaptive warm-up and dispersed starts -----------------------------------------------------------


def test_the_warmup_ends_where_the_proposal_is_stable_and_not_before():
    from peano_bayes.inference.sample import adapt, proposal_change, warmup_bounds

    assert warmup_bounds(None, 1000) == [100, 200, 300, 450, 700, 1000]
    assert warmup_bounds(250) == [100, 200, 250] and warmup_bounds(0) == []
    rng = np.random.default_rng(0)
    stationary = rng.normal(size=(700, 32, 3))
    a = adapt(stationary, None)
    assert a.end == 200 and a.stable and a.changes[0]["step"] == 200
    assert a.proposal_at(5000) is a.proposals[200] and a.proposal_at(99) is None
    np.testing.assert_allclose(a.proposals[200].mean, stationary[100:200].reshape(-1, 3).mean(axis=0))
    # Walkers still contracting from a wide start (sd 4 -> 1 with a 150-step time constant): not stable until
    # the spread has settled, then it ends.
    scale = 1.0 + 3.0 * np.exp(-np.arange(1100) / 150.0)
    contracting = rng.normal(size=(1100, 32, 3)) * scale[:, None, None]
    b = adapt(contracting, None)
    assert b.changes[0]["scale"] > 0.2 and b.end is not None and b.end >= 450 and b.stable
    # A fixed warm-up ends where it is told; an unfinished adaptive one has no end yet.
    assert adapt(contracting, 200).end == 200 and not adapt(contracting, 200).stable
    assert adapt(contracting[:150], None).end is None
    # The change is symmetric in what it measures: a proposal against itself has not moved.
    p = a.proposals[100]
    assert proposal_change(p, p) == {"scale": pytest.approx(0.0, abs=1e-12), "centre": 0.0}


def test_each_ensemble_starts_from_its_own_centre():
    from peano_bayes.inference.sample import CENTRE_SPREAD, ensemble_centres

    g = Gaussian()
    cov = 0.04 * np.eye(3)
    centres = ensemble_centres(g, g.mean, cov, 4, seed=1)
    assert centres.shape == (4, 3) and len({tuple(c) for c in centres}) == 4
    distance = np.linalg.norm((centres - g.mean) / 0.2, axis=1)  # in the approximation's sd
    assert np.all(distance > 0.3) and np.all(distance < 4 * CENTRE_SPREAD * np.sqrt(3))
    optima = np.array([[0.0, 0.0, 0.0], [2.0, -1.0, 0.0]])
    with_optima = ensemble_centres(g, g.mean, cov, 4, seed=1, optima=optima)
    np.testing.assert_array_equal(with_optima[:2], optima)
    np.testing.assert_array_equal(with_optima[2:], centres[2:])  # the same draws for the rest


def test_a_run_reports_its_adaptive_warmup_and_checks():
    g = Gaussian()
    result = sample(g, g.mean, 0.05 * np.eye(3), n_walkers=8, seed=2, max_steps=5000, progress=False,
                    log=lambda m: None)  # fmt: skip
    assert result.convergence.converged
    assert result.warmup in (200, 300, 450, 700) and result.warmup_stable
    assert [c["step"] for c in result.warmup_changes][-1] == result.warmup
    assert len(result.checks) >= 2 and result.checks[-1][0] == result.chain.shape[0]
    assert result.convergence.discard > result.warmup


# --- Interruption and progress ---------------------------------------------------------------------------


class Interrupting(Gaussian):
    """The Gaussian, which sends itself SIGINT (Ctrl-C) inside its ``calls``-th density evaluation."""

    def __init__(self, calls: int):
        self.calls, self.seen = calls, 0

    def batched(self, thetas):
        import os
        import signal

        self.seen += 1
        if self.seen == self.calls:
            os.kill(os.getpid(), signal.SIGINT)
        return super().batched(thetas)


def test_ctrl_c_stops_after_the_step_saves_the_state_and_resumes(tmp_path, capsys):
    from peano_bayes.inference.sample import SamplingInterrupted

    kw = dict(n_walkers=8, seed=4, warmup=50, chunk=60, max_steps=170, progress=False, log=lambda m: None)
    whole = sample(Gaussian(), Gaussian.mean, 0.05 * np.eye(3), **kw)
    state = tmp_path / "state.npz"
    # The signal lands in the 251st density call, inside the warm-up's first round.
    with pytest.raises(SamplingInterrupted, match=r"stopped at step \d+; state saved in .*--resume") as stop:
        sample(Interrupting(251), Gaussian.mean, 0.05 * np.eye(3), state_path=state, **kw)
    stopped = int(str(stop.value).split("step ")[1].split(";")[0])
    assert "Traceback" not in capsys.readouterr().err  # emcee printed nothing of the walkers
    assert 0 < stopped < 50 and load_state(state)[0].shape[0] == stopped  # saved at the step it stopped after
    rest = sample(Gaussian(), Gaussian.mean, 0.05 * np.eye(3), state_path=state, resume=True, **kw)
    np.testing.assert_array_equal(rest.chain, whole.chain)  # the uninterrupted run, bit for bit


def test_without_a_terminal_progress_is_one_line_per_check(capsys):
    g = Gaussian()
    lines = []
    sample(g, g.mean, 0.05 * np.eye(3), n_walkers=8, seed=2, max_steps=400, progress=True, log=lines.append)
    assert "\r" not in capsys.readouterr().err  # pytest's stderr is no terminal: no bars
    checks = [line for line in lines if line.startswith("sampling step")]
    assert checks and all("tau_max" in c and "R-hat" in c and "ESS" in c for c in checks)
    assert all("ETA" in c or "converged" in c for c in checks)
    assert any(line.startswith("warm-up step 200") for line in lines)


def test_distinct_least_squares_optima_are_the_converged_far_and_nearly_as_good_starts():
    """Five starts in 2-D, Laplace sd 1 at the best (0, 0), cost 10: a start at the best itself, one 5 sd away at
    cost 11 (an optimum), its twin 0.1 sd from it (the same optimum), one 5 sd away but 3 worse than d = 2 allows,
    one far and good but unconverged."""
    from peano_bayes.inference.fit import OPTIMUM_DISTANCE, distinct_optima

    values = np.array([[0.0, 0.0], [5.0, 0.0], [5.1, 0.0], [0.0, -5.0], [-5.0, 5.0]])
    costs = np.array([10.0, 11.0, 11.2, 13.0, 10.5])
    converged = np.array([True, True, True, True, False])
    assert OPTIMUM_DISTANCE < 5.0
    assert distinct_optima(values, costs, converged, np.eye(2), values[0], 10.0) == [1]
    # in a metric where 5 units are under 3 sd, none is distinct
    assert distinct_optima(values, costs, converged, 4.0 * np.eye(2), values[0], 10.0) == []
