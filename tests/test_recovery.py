"""Parameter recovery on virtual-rig data with known truth: the multi-start least squares (optimistix LM),
then emcee from its Laplace approximation. One dataset and one fit serve every check (they are the slow
part of the suite)."""

import arviz as az
import numpy as np
import pytest

from peano_bayes.inference import build_posterior, prepare, prior_for, sample
from peano_bayes.inference.results import physical_draws
from peano_bayes.physics import DEFAULT_CONFIG
from peano_bayes.pipeline import least_squares, walker_start
from peano_bayes.rig import RigNoise, simulate_dataset

FREE = ("tensile_ka_n_per_m", "bending_k1_n", "friction_pressure_fraction")
TRUTH = dict(DEFAULT_CONFIG.nominal_parameters(), tensile_ka_n_per_m=8e3, bending_k1_n=1.0)


@pytest.fixture(scope="module")
def recovered():
    data = simulate_dataset(
        "TP", TRUTH, seed=31, specimens=1, repeats=1, specimen_spread=0.0, tests=("load_cycle",), noise=RigNoise()
    )
    prior = prior_for("TP")
    fixed = {k: v for k, v in TRUTH.items() if k not in FREE}
    posterior = build_posterior(prepare(data), prior, config=DEFAULT_CONFIG, fixed=fixed)
    assert set(posterior.names) == {*FREE, "noise_load_cycle_force_n"}
    fitted = least_squares(posterior, prior, n_starts=8, seed=0)
    centre, covariance = walker_start(posterior, fitted)
    result = sample(
        posterior,
        centre,
        covariance,
        n_walkers=16,
        seed=2,
        chunk=500,
        max_steps=6000,
        progress=False,
        log=lambda m: None,
    )
    truth = {**TRUTH, "noise_load_cycle_force_n": RigNoise().force_sd_n}
    return posterior, result, physical_draws(posterior, result.kept()), truth, fitted


@pytest.mark.slow
def test_multistart_fit_recovers_the_generating_parameters(recovered):
    _, _, _, truth, fitted = recovered
    assert fitted["n_starts"] == 8 and 0 <= fitted["n_failed"] < 8
    assert np.isfinite(fitted["start_costs"]).sum() == 8 - fitted["n_failed"]
    cov = np.asarray(fitted["covariance"])
    for i, name in enumerate(fitted["names"]):
        sd = np.sqrt(cov[i, i])
        # Within 4 Laplace standard deviations (in log units) and within 10 % of the truth.
        assert abs(np.log(fitted["params"][name] / truth[name])) < max(4 * sd, 1e-3), (name, fitted["params"][name])
        assert fitted["params"][name] == pytest.approx(truth[name], rel=0.1), name
    assert fitted["quality"]["load_cycle"]["r2"] > 0.99


@pytest.mark.slow
def test_fit_residuals_match_the_sensor_noise(recovered):
    """With the driving inputs denoised (likelihood.prepare), the residuals are sensor noise; with the raw
    noisy inputs they were 0.46 N per sample against 0.2 N."""
    _, _, _, truth, fitted = recovered
    assert fitted["noise_estimate"]["noise_load_cycle_force_n"] == pytest.approx(0.2, rel=0.15)


@pytest.mark.slow
def test_sampler_converges_and_posterior_mean_is_within_4_sd_of_the_truth(recovered):
    posterior, result, draws, truth, _ = recovered
    assert result.convergence.converged, result.convergence.problems
    for name in posterior.names:
        x = np.asarray(draws[name]).ravel()
        assert abs(x.mean() - truth[name]) < 4.0 * x.std(), (name, x.mean(), x.std(), truth[name])


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="KNOWN (issue 4, open): bending_k1_n's truth sits 2.5 posterior sd below the mean (-0.27 %), outside "
    "its 94 % HDI; the least-squares optimum agrees, and with noise-free inputs the offset is 0.03 %, so it comes "
    "from the denoised inputs' own error (e.g. ~20 Pa on the held pressure), which the posterior does not carry",
)
def test_truth_inside_every_94_percent_interval(recovered):
    posterior, _, draws, truth, _ = recovered
    for name in posterior.names:
        low, high = az.hdi(np.asarray(draws[name]).ravel(), hdi_prob=0.94)
        assert low <= truth[name] <= high, (name, low, high, truth[name])
