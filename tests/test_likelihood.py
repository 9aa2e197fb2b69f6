"""Likelihood: binning with reduced noise, stacking of runs, -inf instead of NaN, and that binning barely moves
the likelihood surface of a stiffness parameter."""

import json
from dataclasses import replace
from functools import partial
from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.inference.likelihood import log_likelihood, pointwise_log_likelihood, predict
from peano_bayes.inference.reduce import (
    DEFAULT_BIN_SIZES,
    DEFAULT_BINS_PER_SEGMENT,
    SNAP_SAMPLES,
    Observations,
    _snap,
    bin_means,
    prepare,
    sample_times,
    segment_bins,
    segment_starts,
    with_path_samples,
)
from peano_bayes.physics import DEFAULT_CONFIG, ModelConfig
from peano_bayes.rig import RigNoise, RigProtocol, simulate_dataset

from .helpers import jit_lean

NOISE = {
    "noise_load_cycle_force_n": 0.2,
    "noise_blocking_force_n": 0.2,
    "noise_stroke_strain": 2e-4,
    "noise_step_strain": 2e-4,
}


@pytest.fixture(scope="module")
def dataset():
    """TP: one specimen, one repeat of each test, the rig's default noise."""
    return simulate_dataset("TP", None, seed=3, specimens=1, repeats=1, noise=RigNoise())


@pytest.fixture(scope="module")
def truth():
    return {k: jnp.asarray(v) for k, v in DEFAULT_CONFIG.nominal_parameters().items()}


def only(dataset, test: str):
    """``dataset`` with the runs of ``test`` alone."""
    return replace(dataset, runs=tuple(r for r in dataset.runs if r.test == test))


def test_bin_means_by_hand():
    means, counts = bin_means(np.array([1.0, 3.0, 5.0, np.nan, 9.0]), 2)
    np.testing.assert_array_equal(means, [2.0, 5.0, 9.0])
    np.testing.assert_array_equal(counts, [2.0, 1.0, 1.0])


def test_bin_mean_noise_shrinks_by_sqrt_k(rng):
    sigma, k = 0.2, 4
    means, _ = bin_means(rng.normal(0.0, sigma, 400_000), k)
    # 100 000 bin means: the sample sd is within 1 % of sigma / 2 with overwhelming probability.
    assert np.std(means) == pytest.approx(sigma / np.sqrt(k), rel=0.01)


def test_prepare_stacks_runs_and_keeps_every_sample(dataset):
    obs = prepare(dataset, DEFAULT_BIN_SIZES)
    tests = sorted(g.test for g in obs.groups)
    assert tests == ["blocking", "load_cycle", "step", "stroke"]
    for group in obs.groups:
        raw = [r for r in dataset.runs if r.key in group.keys]
        signal = "force_n" if group.test in ("load_cycle", "blocking") else "strain"
        n_measured = sum(int(np.sum(np.isfinite(getattr(r, signal)))) for r in raw)
        assert int(group.counts.sum()) == n_measured
        k = DEFAULT_BIN_SIZES[group.test]
        first = raw[0]
        np.testing.assert_allclose(group.observed[group.keys.index(first.key), 0], getattr(first, signal)[:k].mean())
    cycle = next(g for g in obs.groups if g.test == "load_cycle")
    assert cycle.observed.shape[0] == 2  # the 0 kPa and the test-pressure cycle, one vmapped simulation


@partial(jit_lean, static_argnums=2)
def _total_and_pointwise(params, groups, geometry):
    """The total and the pointwise log-likelihood from one compiled program: the run groups are an argument,
    not constants of the program, so the tests of this module evaluating ``dataset`` share it."""
    obs = Observations((), groups, MappingProxyType({}), geometry)
    return log_likelihood(params, obs), pointwise_log_likelihood(params, obs)


def _likelihood_of(obs):
    """``params -> (total, pointwise)`` on ``obs``."""
    return lambda params: _total_and_pointwise(params, obs.groups, obs.geometry)


def test_likelihood_prefers_the_truth_and_is_consistent(dataset, truth):
    obs = prepare(dataset)
    ll = _likelihood_of(obs)
    at_truth, pointwise = ll({**truth, **NOISE})
    at_truth = float(at_truth)
    assert np.isfinite(at_truth)
    for name in ("tensile_ka_n_per_m", "bending_k2_n", "friction_force_n"):
        assert float(ll({**truth, **NOISE, name: truth[name] * 1.5})[0]) < at_truth - 10.0, name
    assert sum(float(jnp.sum(p)) for p in pointwise) == pytest.approx(at_truth, rel=1e-12)
    assert sum(p.size for p in pointwise) == obs.n_bins


def test_bad_parameters_give_minus_infinity_not_nan(dataset, truth):
    ll = _likelihood_of(prepare(dataset))
    for bad in ({"tensile_ka_n_per_m": jnp.nan}, {"noise_load_cycle_force_n": -1.0}, {"length_fraction": -0.5}):
        value = float(ll({**truth, **NOISE, **bad})[0])
        assert value == -np.inf, bad


def test_a_geometry_with_array_fields_predicts_as_one_with_floats(dataset, truth):
    """Predictions go through one compiled program that takes the geometry as a static (hashed) argument; a
    geometry holding arrays, which cannot be hashed, is simulated directly and gives the same prediction."""
    obs = prepare(only(dataset, "blocking"))
    group, geometry = obs.groups[0], obs.geometry
    with_arrays = replace(geometry, tube_width_m=jnp.asarray(geometry.tube_width_m))
    with pytest.raises(TypeError):
        hash(with_arrays)
    expected, _ = predict(truth, group, geometry=geometry)
    got, _ = predict(truth, group, geometry=with_arrays)
    # Op by op against one fused program: the same arithmetic, rounded in another order (and root solves that
    # stop within 1e-12 of their root), so equal to 1e-9, not bit for bit.
    np.testing.assert_allclose(np.asarray(got), np.asarray(expected), rtol=1e-9, atol=0.0)


def test_binning_barely_moves_the_likelihood_surface(dataset, truth):
    """Profile of the tensile stiffness on the load cycles, raw (k = 1) against binned (k = 4): the maximum
    moves by less than 2 % and the curvature (Fisher information) by less than 15 %."""
    cycles = only(dataset, "load_cycle")
    grid = truth["tensile_ka_n_per_m"] * jnp.exp(jnp.linspace(-0.1, 0.1, 9))

    def profile(k):
        obs = prepare(cycles, {"load_cycle": k})
        ll = jit_lean(jax.vmap(lambda ka: log_likelihood({**truth, **NOISE, "tensile_ka_n_per_m": ka}, obs)))
        values = np.asarray(ll(grid))
        c2, c1, _ = np.polyfit(np.log(np.asarray(grid)), values, 2)
        return -c1 / (2.0 * c2), -2.0 * c2  # peak in log(ka) and curvature

    peak_raw, curv_raw = profile(1)
    peak_bin, curv_bin = profile(4)
    assert abs(peak_bin - peak_raw) < 0.02
    assert curv_bin == pytest.approx(curv_raw, rel=0.15)


def test_segments_are_the_ramps_of_the_inputs_and_bins_never_straddle_a_reversal():
    strain = np.concatenate([np.linspace(0.0, -1.0, 41), np.linspace(-1.0, 0.0, 41)[1:]])  # down, then up
    pressure = np.full(81, 3.0)
    starts = segment_starts([strain, pressure])
    assert starts.tolist() == [0, 40]  # the reversal sample opens the second ramp
    assert segment_starts([pressure]).tolist() == [0]  # a hold is one segment
    bins = segment_bins(starts, 81, 8)
    assert bins.tolist() == [0, 5, 10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 60, 65, 70, 75]
    assert segment_bins(np.array([0, 40, 41]), 81, 4).tolist() == [0, 10, 20, 30, 40, 50, 60, 70]  # kink on 2 samples
    assert segment_bins(np.array([0]), 5, 8).tolist() == [0, 1, 2, 3, 4]  # never more bins than samples


@pytest.fixture(scope="module")
def fast_rig():
    """The TP load cycles of ``dataset``'s specimen sampled at 100 Hz instead of 20 Hz."""
    return simulate_dataset(
        "TP", None, seed=3, specimens=1, repeats=1, noise=RigNoise(), tests=("load_cycle",),
        protocol=RigProtocol(quasi_static_rate_hz=100.0),
    )


def test_cost_is_set_by_segments_not_by_the_sampling_rate(dataset, fast_rig):
    """Binned by segment, a load cycle sampled at 100 Hz is simulated at as many points as one at 20 Hz, each
    bin holding five times the samples."""
    slow = next(g for g in prepare(only(dataset, "load_cycle")).groups)
    fast = next(g for g in prepare(fast_rig).groups)
    per = DEFAULT_BINS_PER_SEGMENT["load_cycle"]
    assert slow.observed.shape[1] == fast.observed.shape[1] == 2 * per  # two ramps, stretch and relax
    assert slow.time_s.shape[1] == fast.time_s.shape[1]
    assert np.median(fast.counts) == pytest.approx(5 * np.median(slow.counts), rel=0.1)


def test_segment_binning_barely_moves_the_likelihood_surface_at_100_hz(fast_rig, truth):
    """Profile of the tensile stiffness on 100 Hz load cycles, every sample (k = 1) against the default
    segment bins (about 20 samples each): the same tolerances as fixed bins of four at 20 Hz above."""
    grid = truth["tensile_ka_n_per_m"] * jnp.exp(jnp.linspace(-0.1, 0.1, 9))

    def profile(obs):
        ll = jit_lean(jax.vmap(lambda ka: log_likelihood({**truth, **NOISE, "tensile_ka_n_per_m": ka}, obs)))
        values = np.asarray(ll(grid))
        c2, c1, _ = np.polyfit(np.log(np.asarray(grid)), values, 2)
        return -c1 / (2.0 * c2), -2.0 * c2

    peak_raw, curv_raw = profile(prepare(fast_rig, {"load_cycle": 1}))
    peak_bin, curv_bin = profile(prepare(fast_rig))
    assert abs(peak_bin - peak_raw) < 0.02
    assert curv_bin == pytest.approx(curv_raw, rel=0.15)


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 40), k=st.integers(1, 7), jitter=st.floats(0.0, 0.4))
def test_sample_times_keep_every_bins_own_samples_and_mean(n, k, jitter):
    """``k`` nodes per bin; a full bin's nodes are its sample times, every bin's nodes average to the bin's mean
    time (a signal linear in time is reproduced exactly in the short last bin too), and evenly sampled runs of two
    or more samples give strictly increasing nodes."""
    time = np.arange(n) + jitter * np.sin(np.arange(n))  # increasing, unevenly spaced
    nodes = sample_times(time, k)
    m = -(-n // k)
    assert nodes.shape == (k * m,)
    full = (n // k) * k
    np.testing.assert_array_equal(nodes[:full], time[:full])
    centre, _ = bin_means(time, k)
    np.testing.assert_allclose(nodes.reshape(m, k).mean(axis=1), centre, rtol=0, atol=1e-12)
    if n > 1:  # a one-sample run has no interval to spread its nodes in
        assert np.all(np.diff(sample_times(0.01 * np.arange(n), k)) > 0)


def test_every_sample_bins_are_the_bin_means_of_one_sample_predictions(dataset, truth):
    """Blocking binned by 4 with every sample simulated predicts exactly the bin means of the one-sample
    prediction, kinks included (the two-node quadrature does not: at the ramp start it differs)."""
    blocking = only(dataset, "blocking")
    k = 4
    (one,) = prepare(blocking, {"blocking": 1}).groups
    (every,) = prepare(blocking, {"blocking": k}, every_sample=frozenset({"blocking"})).groups
    (two,) = prepare(blocking, {"blocking": k}).groups
    n = one.observed.shape[1]
    full = n // k
    per_sample, _ = predict(truth, one)
    expected = np.stack([bin_means(np.asarray(row), k)[0] for row in per_sample])
    got, _ = predict(truth, every)
    got = np.asarray(got)
    np.testing.assert_allclose(got[:, :full], expected[:, :full], rtol=1e-9, atol=1e-9)
    if n % k:
        assert k % (n % k) == 0  # the short last bin repeats its samples, spread by a thousandth of a step
        np.testing.assert_allclose(got[:, full:], expected[:, full:], rtol=1e-5, atol=1e-4)
    quadrature, _ = predict(truth, two)
    assert float(np.max(np.abs(np.asarray(quadrature) - expected))) > 1e-3


def test_path_samples_add_the_first_sample_and_the_window_around_each_turn():
    time_s = np.arange(40) * 0.5
    nodes = np.array([0.3, 1.2, 2.3, 3.2, 14.3, 15.2])
    times, index = with_path_samples(time_s, nodes, np.array([0, 20]))
    window = time_s[20 - SNAP_SAMPLES - 1 : 20 + SNAP_SAMPLES + 2]  # samples 7-33 around the turn at 20-21
    assert times.tolist() == sorted({0.0, *nodes.tolist(), *window.tolist()})
    np.testing.assert_array_equal(times[index], nodes)
    again, _ = with_path_samples(time_s, window, np.array([0, 20]))
    assert again.tolist() == [0.0, *window.tolist()]  # samples that are already nodes are not added twice


def test_a_run_binned_like_an_earlier_repeat_still_simulates_its_own_turn():
    """A repeat whose reversal the denoising puts up to SNAP_SAMPLES from an earlier repeat's is binned like
    it (so they can share a simulation), and the samples of its own reversal (the start and the sample after
    it) and the one before are simulated: the path does not cut its corner. (With only the two samples at the
    earlier run's start, noise in the strain alone moved PR's fitted friction limit by 2.5-4.1 of its
    conditional sd on virtual-rig seeds 11 and 12.)"""
    time_s = np.arange(400) * 0.05
    earlier = np.array([0, 200])
    for offset in range(-SNAP_SAMPLES, SNAP_SAMPLES + 1):
        own = np.array([0, 200 + offset])
        known = [earlier]
        assert _snap(own, known) is earlier
        times, _ = with_path_samples(time_s, np.array([1.0, 2.0]), earlier)
        assert {time_s[own[1] + d] for d in (-1, 0, 1)} <= set(times.tolist()), offset
    assert _snap(np.array([0, 200 + SNAP_SAMPLES + 1]), [earlier]) is not earlier


def test_binned_predictions_follow_the_path_of_a_high_friction_muscle():
    """The bundled PC specimen A (friction limit 9.6 N + 0.4 x the active force) without noise: the default
    binning's prediction at the generating values matches the bin means of the signal within 0.05 N, half a
    bin's noise sd at the rig's default noise. Started at the first bin's first node instead of the run's
    first sample, the blocking test was 0.19 N off; cutting the corner at the load cycle's reversal, 0.07 N."""
    bundled = load(dataset_path("PC"))
    truth = json.loads(bundled.provenance["specimen_parameters"])["A"]
    config = ModelConfig(**json.loads(bundled.provenance["config"]))
    quiet = RigNoise(force_sd_n=2e-4, strain_sd=2e-7, pressure_sd_pa=0.5, flow_sd_m3_per_s=5e-10)
    data = simulate_dataset(
        "PC", truth, config=config, seed=5, specimens=1, repeats=1, noise=quiet, specimen_spread=0.0,
        tests=("load_cycle", "blocking"),
    )
    params = {k: jnp.asarray(v) for k, v in {**config.nominal_parameters(), **truth}.items()}
    for group in prepare(data).groups:  # the prediction alone: the likelihood's input-error Jacobian is not read
        predicted, _ = predict(params, group, config=config, geometry=data.geometry)
        error = np.abs(group.observed - np.asarray(predicted))
        assert np.nanmax(error) < 0.05, (group.test, np.nanmax(error))


_TWO_MOUNTS = (0.0, 2e-5)
_MOUNT_CONFIG = ModelConfig(bending=True, tensile=True, extension=False, friction="none", mount=True)
_QUIET = RigNoise(0.0, 0.0, 0.0, 0.0, 0.0)


def _two_mount_session(params, tmp_path):
    """PC's load cycles and blocking on two mounts (the second adds 2e-5 m/N), one specimen, one repeat,
    noise-free, written and read back through the data format."""
    from peano_bayes.data import save

    dataset = simulate_dataset(
        "PC", params, config=_MOUNT_CONFIG, seed=3, noise=_QUIET, specimens=1, repeats=1,
        tests=("load_cycle", "blocking"), protocol=RigProtocol(quasi_static_rate_hz=5.0), added_compliances=_TWO_MOUNTS,
    )
    return load(save(dataset, tmp_path / "two_mounts.csv"))


def test_runs_on_a_second_mount_record_it_and_the_likelihood_adds_it(tmp_path):
    """The rig runs the protocol once per mount and each run records its mount's added compliance, which the
    reader returns; the likelihood adds it to the specimen's own mount, so at the generating values every run of
    both mounts is predicted to round-off, and with the added compliance dropped the second mount's are not."""
    params = {**_MOUNT_CONFIG.nominal_parameters(), "tensile_ka_n_per_m": 2000.0, "mount_compliance_m_per_n": 1e-5}
    dataset = _two_mount_session(params, tmp_path)
    mounts = {(r.test, r.run): r.added_compliance for r in dataset.runs}
    assert mounts == {
        ("load_cycle", 0): 0.0, ("load_cycle", 1): 0.0, ("load_cycle", 2): 2e-5, ("load_cycle", 3): 2e-5,
        ("blocking", 0): 0.0, ("blocking", 1): 2e-5,
    }
    truth = {k: jnp.asarray(v) for k, v in json.loads(dataset.provenance["specimen_parameters"])["A"].items()}
    observations = prepare(dataset, {"load_cycle": 1, "blocking": 1}, denoise_inputs=False)
    for group in observations.groups:
        predicted, _ = predict(truth, group, config=_MOUNT_CONFIG)
        scale = float(np.max(np.abs(group.observed)))
        np.testing.assert_allclose(np.asarray(predicted), group.observed, rtol=0, atol=1e-9 * scale)
        dropped = replace(group, added_compliance_m_per_n=np.zeros_like(group.added_compliance_m_per_n))
        wrong, _ = predict(truth, dropped, config=_MOUNT_CONFIG)
        second = np.asarray(group.added_compliance_m_per_n)[group.shared] > 0
        assert np.max(np.abs(np.asarray(wrong) - group.observed)[second]) > 0.01 * scale, group.test


def test_two_known_mounts_do_not_separate_a_mount_from_a_linear_film(tmp_path):
    """Why a second mount of known compliance cannot name a hidden mount: with a linear film (kb = 0) the film
    ka and a mount c are one series chain, ka / (1 + ka c), and a known added compliance c2 extends the chain in
    both readings: film ka with mount c + c2 and film ka / (1 + ka c) with mount c2 give the same signals on
    both mounts. Measured: every run of both mounts agrees to round-off."""
    ka, c = 2000.0, 1e-5
    base = {**_MOUNT_CONFIG.nominal_parameters(), "tensile_kb_n_per_m2": 0.0}
    dataset = _two_mount_session({**base, "tensile_ka_n_per_m": ka, "mount_compliance_m_per_n": c}, tmp_path)
    film = {k: jnp.asarray(v) for k, v in base.items()}
    film_only = film | {"tensile_ka_n_per_m": jnp.asarray(ka / (1 + ka * c)), "mount_compliance_m_per_n": 0.0}
    with_mount = film | {"tensile_ka_n_per_m": jnp.asarray(ka), "mount_compliance_m_per_n": jnp.asarray(c)}
    for group in prepare(dataset, {"load_cycle": 1, "blocking": 1}, denoise_inputs=False).groups:
        a, _ = predict(with_mount, group, config=_MOUNT_CONFIG)
        b, _ = predict(film_only, group, config=_MOUNT_CONFIG)
        scale = float(np.max(np.abs(np.asarray(a))))
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-9 * scale, err_msg=group.test)


def test_an_added_mount_needs_the_mount_element_and_the_rig_checks_its_mounts(tmp_path):
    """A posterior on runs with an added compliance and a model without the mount element would ignore it:
    build_posterior refuses, naming a run; with the mount it builds. The rig refuses a negative or missing
    mount list before simulating anything."""
    from peano_bayes.errors import PeanoBayesInputError
    from peano_bayes.inference import prior_for
    from peano_bayes.inference.posterior import build_posterior

    observations = prepare(_two_mount_session(_MOUNT_CONFIG.nominal_parameters(), tmp_path))
    prior = prior_for("PC")
    with pytest.raises(ValueError, match=r"first \('A', '\w+', \d\)\) carry an added mount compliance"):
        build_posterior(observations, prior, config=replace(prior.config, mount=False))
    assert build_posterior(observations, prior, config=replace(prior.config, mount=True)).ndim > 0
    for bad in ((), (0.0, -1e-5), (0.0, float("nan"))):
        with pytest.raises(PeanoBayesInputError, match="added_compliances"):
            simulate_dataset("PC", added_compliances=bad)
