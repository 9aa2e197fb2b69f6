"""Parameter recovery on virtual-rig data with known truth: the multi-start least squares (optimistix LM),
then emcee from its Laplace approximation. One dataset and one fit (the ``recovered`` fixture of conftest.py) serve
every check; they are the slow part of the suite."""

import arviz as az
import numpy as np
import pytest

# One xdist worker runs this group, so the session fixture `recovered` (a fit and a sampling run) is built once.
pytestmark = pytest.mark.xdist_group("recovered")


@pytest.mark.slow
def test_multistart_fit_recovers_the_generating_parameters(recovered):
    _, _, _, truth, fitted = recovered
    # 8 starts asked, solved in batches of 4: the second batch runs only if the first's best starts disagree
    assert fitted.n_starts in (4, 8) and 0 <= fitted.n_failed < fitted.n_starts
    assert len(fitted.start_costs) == fitted.n_starts
    assert np.isfinite(fitted.start_costs).sum() == fitted.n_starts - fitted.n_failed
    cov = np.asarray(fitted.covariance)
    for i, name in enumerate(fitted.names):
        sd = np.sqrt(cov[i, i])
        # Within 4 Laplace standard deviations (in log units) and within 10 % of the truth.
        assert abs(np.log(fitted.params[name] / truth[name])) < max(4 * sd, 1e-3), (name, fitted.params[name])
        assert fitted.params[name] == pytest.approx(truth[name], rel=0.1), name
    assert fitted.quality["load_cycle"]["r2"] > 0.99


@pytest.mark.slow
def test_least_squares_continues_in_rounds_until_the_best_start_converges(recovered):
    """Rounds of 10 steps from two starts reach the optimum that the fixture's fit of 80-step rounds found, and
    say how many rounds that took; with one round of 10 steps the fit says it did not converge."""
    from peano_bayes.inference.fit import fit
    from peano_bayes.inference.prior_files import prior_for

    posterior, _, _, _, fitted = recovered
    names = list(fitted.names)
    prior = prior_for("TP").select(names)
    kwargs = dict(config=posterior.config, n_starts=2, seed=0, fixed=posterior.fixed, max_steps=10)
    short = fit(posterior.observations, prior, max_rounds=1, **kwargs)
    assert not short.converged and short.rounds == 1
    rounds = fit(posterior.observations, prior, max_rounds=30, **kwargs)
    assert rounds.converged and 1 < rounds.rounds < 30
    assert np.isfinite(rounds.start_costs).sum() == rounds.n_starts - rounds.n_failed
    assert 0 <= rounds.n_step_limit <= rounds.n_starts - rounds.n_failed - 1  # the best start finished
    assert fitted.converged
    sd = np.sqrt(np.diag(np.asarray(fitted.covariance)))
    shift = [abs(np.log(rounds.params[n] / fitted.params[n])) for n in names]
    assert np.all(np.asarray(shift) < np.maximum(1e-2 * sd, 1e-5)), dict(zip(names, shift, strict=True))
    assert rounds.cost == pytest.approx(fitted.cost, rel=1e-6)
    with pytest.raises(ValueError, match="max_rounds"):
        fit(posterior.observations, prior, max_rounds=0, **kwargs)


@pytest.mark.slow
def test_seeds_and_held_values_are_arguments_of_the_least_squares_program_not_constants(recovered):
    """``fit``'s own compiled program (:func:`least_squares_program`) lowers to one text for two seeds (the prior
    term's spread is drawn with the seed), two sets of held parameter values and two sets of noise scales, so the
    persistent compilation cache serves the second fit (SBC replicates, benchmark runs, datasets with drawn
    constants); and run, that program's result moves with each of the three."""
    import inspect

    from peano_bayes.inference.fit import (
        DEFAULT_NOISE,
        START_BATCH,
        fit,
        least_squares_program,
        prior_spread,
        program_arguments,
    )
    from peano_bayes.inference.prior_files import prior_for

    posterior, _, _, _, fitted = recovered
    prior = prior_for("TP").select(list(fitted.names))
    groups, fixed = posterior.observations.groups, {k: float(v) for k, v in posterior.fixed.items()}
    assert fixed

    def arguments(seed=0, held=1.0, noise=1.0):
        return program_arguments(
            groups,
            prior_spread(prior, seed),
            {k: held * v for k, v in fixed.items()},
            {k: noise * v for k, v in DEFAULT_NOISE.items()},
        )

    # the settings and batch shape of the fixture's own fit, whose compiled program the persistent cache holds
    solver = {k: inspect.signature(fit).parameters[k].default for k in ("max_steps", "rtol", "atol")}
    run = least_squares_program(posterior.observations, prior, posterior.config, **solver)
    # off the prior's centre, so the prior term (u - centre) / spread is not zero
    starts = np.repeat(np.asarray(prior.median_unconstrained())[None] + 0.1, min(8, START_BATCH), axis=0)
    assert run.lower(starts, arguments()).as_text() == run.lower(starts, arguments(1, 1.1, 1.2)).as_text()
    cost = lambda args: np.asarray(run(starts, args)[3])  # noqa: E731  (per start: the end point's cost)
    base = cost(arguments())
    assert np.all(np.isfinite(base))
    for changed in (arguments(seed=1), arguments(held=1.1), arguments(noise=1.2)):
        assert not np.allclose(cost(changed), base, rtol=1e-9, atol=0.0)


@pytest.mark.slow
def test_fit_residuals_match_the_sensor_noise(recovered):
    """With the driving inputs denoised (likelihood.prepare), the residuals are sensor noise; with the raw
    noisy inputs they were 0.46 N per sample against 0.2 N."""
    _, _, _, truth, fitted = recovered
    assert fitted.noise_estimate["noise_load_cycle_force_n"] == pytest.approx(0.2, rel=0.15)


@pytest.mark.slow
def test_sampler_converges_and_posterior_mean_is_within_4_sd_of_the_truth(recovered):
    posterior, result, draws, truth, _ = recovered
    assert result.convergence.converged, result.convergence.problems
    for name in posterior.names:
        x = np.asarray(draws[name]).ravel()
        assert abs(x.mean() - truth[name]) < 4.0 * x.std(), (name, x.mean(), x.std(), truth[name])


@pytest.mark.slow
def test_truth_inside_every_94_percent_interval(recovered):
    posterior, _, draws, truth, _ = recovered
    for name in posterior.names:
        x = np.asarray(draws[name]).ravel()
        low, high = az.hdi(x, hdi_prob=0.94)
        assert low <= truth[name] <= high, (name, low, high, truth[name])


def test_starts_agree_needs_three_converged_starts_at_the_best_cost():
    from peano_bayes.inference.fit import starts_agree

    yes = np.array([10.0, 10.05, 10.02, 55.0])
    assert starts_agree(yes, np.array([True, True, True, True]))
    assert not starts_agree(yes, np.array([True, True, False, True]))  # only two converged at the best
    assert not starts_agree(np.array([10.0, 10.5, 11.0, 10.01]), np.ones(4, bool))  # two within 0.1 of the best
    assert not starts_agree(np.array([10.0, np.inf, 10.0]), np.array([True, True, True]))  # a failed start
    assert starts_agree(np.array([np.inf, 3.0, 3.0, 3.0]), np.array([False, True, True, True]))
