"""The sampler's log posterior: specimen contrasts, which parameters are sampled, never NaN; and that denoising
the driving inputs removes the errors-in-variables excess from the stroke residuals."""

import jax.numpy as jnp
import numpy as np
import pytest

from peano_bayes.inference import prepare, prior_for
from peano_bayes.inference.likelihood import predict
from peano_bayes.inference.posterior import STEP_ONLY_PARAMETERS, build_posterior, helmert
from peano_bayes.physics import DEFAULT_CONFIG
from peano_bayes.rig import RigNoise, simulate_dataset

from .helpers import jit_lean


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_helmert_contrasts_are_orthonormal_and_sum_to_zero(n):
    h = helmert(n)
    assert h.shape == (n, n - 1)
    np.testing.assert_allclose(h.T @ h, np.eye(n - 1), atol=1e-14)
    np.testing.assert_allclose(h.sum(axis=0), 0.0, atol=1e-14)


@pytest.fixture(scope="module")
def stroke_data():
    return simulate_dataset("TP", None, seed=21, specimens=2, repeats=2, tests=("stroke",), noise=RigNoise())


def test_sampled_parameters_follow_the_tests_and_specimens(stroke_data):
    post = build_posterior(prepare(stroke_data), prior_for("TP"))
    assert not STEP_ONLY_PARAMETERS & set(post.names)
    assert "orifice_area_m2" in post.fixed
    assert {"noise_stroke_strain", "specimen_log_sd", "specimen_contrast_tensile_ka_n_per_m_1"} <= set(post.names)
    assert "noise_load_cycle_force_n" not in post.names
    # one contrast (two specimens) per sampled parameter that differs between specimens
    varying = {"tensile_ka_n_per_m", "tensile_kb_n_per_m2", "bending_k1_n", "bending_k2_n", "extension_k_n_per_m"}
    varying |= {"friction_stiffness_n_per_m"}  # the rig draws it per specimen too
    assert set(post.varying) == varying & set(post.prior.names)
    assert "friction_stiffness_n_per_m" in post.varying
    assert post.ndim == post.prior.ndim + len(post.varying)
    one = simulate_dataset("TP", None, seed=1, specimens=1, repeats=1, tests=("stroke",))
    single = build_posterior(prepare(one), prior_for("TP"))
    assert "specimen_log_sd" not in single.names and single.n_contrasts == 0


def test_log_posterior_is_finite_or_minus_inf_never_nan(stroke_data):
    post = build_posterior(prepare(stroke_data), prior_for("TP"))
    rng = np.random.default_rng(4)
    thetas = np.zeros((24, post.ndim))
    thetas[:, : post.prior.ndim] = post.prior.sample(rng, 24)
    thetas[:, post.prior.ndim :] = rng.normal(0.0, 0.3, (24, post.n_contrasts))
    thetas[0, 0] = np.nan
    thetas[1, 3] = np.inf
    thetas[2, -1] = -np.inf
    values = post.batched(thetas)
    assert not np.any(np.isnan(values))
    assert values[0] == -np.inf and values[1] == -np.inf and values[2] == -np.inf
    assert np.sum(np.isfinite(values)) >= 12


def test_each_varying_parameter_has_its_own_specimen_offset(stroke_data):
    """A contrast moves one parameter of the two specimens apart (geometric mean kept) and no other: the
    prediction equals one made with each specimen's own values passed directly."""
    obs = prepare(stroke_data)
    post = build_posterior(obs, prior_for("TP"))
    theta = np.zeros(post.ndim)
    theta[: post.prior.ndim] = np.asarray(post.prior.median_unconstrained())
    theta[post.names.index("specimen_contrast_tensile_ka_n_per_m_1")] = 0.2
    theta[post.names.index("specimen_contrast_bending_k2_n_1")] = -0.1
    params = post.params(theta)
    offsets = {k: np.asarray(v) for k, v in params["specimen_log_offset"].items()}
    np.testing.assert_allclose(offsets["tensile_ka_n_per_m"], [-0.2 / np.sqrt(2), 0.2 / np.sqrt(2)], rtol=1e-12)
    np.testing.assert_allclose(offsets["bending_k2_n"], [0.1 / np.sqrt(2), -0.1 / np.sqrt(2)], rtol=1e-12)
    assert all(np.all(v == 0.0) for k, v in offsets.items() if k not in ("tensile_ka_n_per_m", "bending_k2_n"))
    group = obs.groups[0]
    shifted, _ = predict(params, group, config=post.config, geometry=obs.geometry)
    base = {k: v for k, v in params.items() if k != "specimen_log_offset"}
    b = np.asarray(group.run_specimen_index)
    for s in range(2):
        own = {k: v * np.exp(offsets[k][s]) if k in offsets else v for k, v in base.items()}
        direct, _ = predict(own, group, config=post.config, geometry=obs.geometry)
        np.testing.assert_allclose(np.asarray(shifted)[b == s], np.asarray(direct)[b == s], rtol=1e-12)


def test_levels_population_and_new_specimen_have_the_hierarchys_spread(stroke_data):
    """From one theta repeated, the population value scatters around the specimens' geometric mean with sd
    tau / sqrt(n) in log, a new specimen with sd tau sqrt(1 + 1/n); each specimen's value is the mean times its
    offset. Checked against the closed forms on 200 000 draws."""
    post = build_posterior(prepare(stroke_data), prior_for("TP"))
    theta = np.zeros(post.ndim)
    u = dict(post.prior.median())
    u["specimen_log_sd"] = 0.1
    theta[: post.prior.ndim] = np.asarray(post.prior.to_unconstrained(u))
    theta[post.names.index("specimen_contrast_tensile_ka_n_per_m_1")] = 0.3
    levels = post.levels(np.tile(theta, (200_000, 1)), np.random.default_rng(0))
    m = u["tensile_ka_n_per_m"]
    pop = np.log(levels["tensile_ka_n_per_m"] / m)
    new = np.log(levels["new_specimen__tensile_ka_n_per_m"] / m)
    assert abs(pop.mean()) < 0.001 and abs(new.mean()) < 0.001
    np.testing.assert_allclose(pop.std(), 0.1 / np.sqrt(2), rtol=0.01)
    np.testing.assert_allclose(new.std(), 0.1 * np.sqrt(1.5), rtol=0.01)
    np.testing.assert_allclose(
        levels["specimen__tensile_ka_n_per_m"][0], m * np.exp([-0.3 / np.sqrt(2), 0.3 / np.sqrt(2)]), rtol=1e-10
    )
    np.testing.assert_allclose(levels["noise_stroke_strain"], u["noise_stroke_strain"], rtol=1e-10)


def test_bundled_priors_of_varying_parameters_are_flat_on_the_spread_scale():
    """The population draw of :meth:`Posterior.levels` is exact when the population prior is flat in log over
    a few tau / sqrt(n): every bundled prior of a varying parameter is loguniform or lognormal with
    sigma_log >= 1 (tau near 0.05-0.2)."""
    from peano_bayes.bundled import MATERIALS
    from peano_bayes.inference.reduce import SPECIMEN_VARYING

    for code in MATERIALS:
        prior = prior_for(code)
        for name in SPECIMEN_VARYING & set(prior.names):
            marginal = prior.marginals[name]
            assert marginal.distribution in ("loguniform", "lognormal"), (code, name)
            if marginal.distribution == "lognormal":
                assert marginal.scale >= 1.0, (code, name)


def test_denoised_inputs_bring_stroke_residuals_down_to_the_sensor_noise():
    """At the true parameters, raw noisy pressure driving the model inflates the stroke residual several
    times over the strain noise (errors in variables); the piecewise-linear inputs bring it to ~1."""
    data = simulate_dataset("TP", None, seed=8, specimens=1, repeats=3, specimen_spread=0.0, tests=("stroke",))
    truth = {k: jnp.asarray(v) for k, v in DEFAULT_CONFIG.nominal_parameters().items()}
    sigma = RigNoise().strain_sd

    def z(obs):
        group = obs.groups[0]
        pred, _ = jit_lean(lambda p: predict(p, group))(truth)
        z = (group.observed - np.asarray(pred)) / (sigma / np.sqrt(group.counts))
        return float(np.sqrt(np.nanmean(z**2)))

    raw, denoised = z(prepare(data, denoise_inputs=False)), z(prepare(data))
    assert raw > 3.0
    assert denoised < 1.5
    assert prepare(data).groups[0].time_s.shape[0] == 1  # three repeats share one simulation


def test_fit_quality_reads_a_two_specimen_posteriors_parameters(stroke_data):
    """The posterior mean's fit quality (what every fit reports) takes the specimen offsets of a hierarchy, a
    mapping inside the parameters, and agrees with the prediction it is computed from: the specimens' own
    values (that prediction equals one made with each specimen's values passed directly, checked in
    ``test_each_varying_parameter_has_its_own_specimen_offset``). The contrast moves the two specimens apart, so
    a fit quality that dropped the offsets would differ."""
    from peano_bayes.inference.fit import fit_quality

    post = build_posterior(prepare(stroke_data), prior_for("TP"))
    theta = np.zeros(post.ndim)
    theta[: post.prior.ndim] = np.asarray(post.prior.median_unconstrained())
    theta[post.names.index("specimen_contrast_tensile_ka_n_per_m_1")] = 0.3
    params = post.params(theta)
    assert isinstance(params["specimen_log_offset"], dict)
    quality = fit_quality(params, post.observations, post.config)
    group = post.observations.groups[0]

    def rmse(p):
        predicted, _ = predict(p, group, config=post.config, geometry=post.observations.geometry)
        error = (np.asarray(group.observed) - np.asarray(predicted))[np.isfinite(group.observed)]
        return float(np.sqrt(np.mean(error**2)))

    assert set(quality) == {"stroke"}
    assert quality["stroke"]["rmse"] == pytest.approx(rmse(params), rel=1e-9)
    without = {k: v for k, v in params.items() if k != "specimen_log_offset"}
    assert rmse(without) != pytest.approx(quality["stroke"]["rmse"], rel=1e-6)  # far outside the check's 1e-9


def test_excess_over_the_sensor_noise_measures_a_missing_offset_and_not_the_noise():
    """The model-free sensor noise (second differences of the raw signals) recovers the rig's noise; at the
    true parameters the residuals' RMSE beyond that floor stays below it (blocking: small; stroke: most of the
    floor, the fitted driving pressure's error carried through), and a 0.5 N offset the model cannot take comes
    out as about 0.5 N beyond the noise. A signal without measurable noise gets no floor."""
    import dataclasses

    from peano_bayes.inference.fit import fit_quality, sensor_noise

    data = simulate_dataset(
        "TP", None, seed=8, specimens=1, repeats=3, specimen_spread=0.0, tests=("blocking", "stroke")
    )
    truth = {k: jnp.asarray(v) for k, v in DEFAULT_CONFIG.nominal_parameters().items()}
    noise = sensor_noise(data.runs)
    assert noise["blocking"] == pytest.approx(RigNoise().force_sd_n, rel=0.05)
    assert noise["stroke"] == pytest.approx(RigNoise().strain_sd, rel=0.05)
    observations = prepare(data)
    exact = fit_quality(truth, observations, DEFAULT_CONFIG, noise=noise)
    assert exact["blocking"]["noise_floor_rmse"] == pytest.approx(exact["blocking"]["rmse"], rel=0.1)
    assert exact["blocking"]["excess_rmse"] < 0.2 * exact["blocking"]["noise_floor_rmse"]
    assert exact["stroke"]["excess_rmse"] < exact["stroke"]["noise_floor_rmse"]
    shifted = [dataclasses.replace(g, observed=g.observed + 0.5 * (g.test == "blocking")) for g in observations.groups]
    offset = fit_quality(truth, dataclasses.replace(observations, groups=tuple(shifted)), DEFAULT_CONFIG, noise=noise)
    assert offset["blocking"]["excess_rmse"] == pytest.approx(0.5, rel=0.05)
    assert offset["stroke"]["excess_rmse"] == exact["stroke"]["excess_rmse"]
    assert "excess_rmse" not in fit_quality(truth, observations, DEFAULT_CONFIG)["blocking"]
    silent = fit_quality(truth, observations, DEFAULT_CONFIG, noise={**noise, "stroke": 0.0})
    assert "excess_rmse" not in silent["stroke"] and "excess_rmse" in silent["blocking"]


def test_batches_in_fixed_rows_equal_one_call_and_compile_once(stroke_data):
    """with_batch_rows pads and splits any batch into calls of one size: the same values as one call per
    batch, one compiled program for every batch size. (24 rows in one call, as in
    ``test_log_posterior_is_finite_or_minus_inf_never_nan``, so the suite's compilation cache serves both.)"""
    post = build_posterior(prepare(stroke_data), prior_for("TP"))
    rng = np.random.default_rng(3)
    theta = np.zeros((24, post.ndim))
    theta[:, : post.prior.ndim] = np.asarray(post.prior.median_unconstrained()) + 0.05 * rng.standard_normal(
        (24, post.prior.ndim)
    )
    whole = post.batched(theta)
    rows = post.with_batch_rows(3)
    assert rows._compiled is post._compiled
    f = rows._shared("batched", None)
    before = f._cache_size()
    for n in (7, 3, 2, 1):
        np.testing.assert_allclose(rows.batched(theta[:n]), whole[:n], rtol=1e-12)
    assert f._cache_size() == before + 1  # the (3, D) program only, whatever the batch
    with pytest.raises(ValueError, match="batch_rows must be >= 1"):
        post.with_batch_rows(0)


def test_compiled_functions_are_shared_with_new_data_only(stroke_data):
    """with_observations reuses the compiled log posterior on other data of the protocol; any other change
    (here the likelihood family) gets its own, so it never evaluates the old posterior. (In rows of 3, as
    ``test_batches_in_fixed_rows_equal_one_call_and_compile_once``, so the compilation cache serves both.)"""
    import dataclasses

    post = build_posterior(prepare(stroke_data), prior_for("TP")).with_batch_rows(3)
    theta = np.zeros((2, post.ndim))
    theta[:, : post.prior.ndim] = np.asarray(post.prior.median_unconstrained())
    base = post.batched(theta)
    obs = post.observations
    shifted = tuple(dataclasses.replace(g, observed=g.observed + 1e-3) for g in obs.groups)  # other measurements
    moved = post.with_observations(dataclasses.replace(obs, groups=shifted))
    assert moved._compiled is post._compiled
    np.testing.assert_allclose(moved.batched(theta), [float(moved.log_prob(theta[0]))] * 2, rtol=1e-12)
    assert not np.allclose(moved.batched(theta), base)
    student = dataclasses.replace(post, family="student_t")
    assert student._compiled is not post._compiled
    np.testing.assert_allclose(student.batched(theta), [float(student.log_prob(theta[0]))] * 2, rtol=1e-12)
    assert not np.allclose(student.batched(theta), base)
