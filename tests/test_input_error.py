"""The fitted driving inputs' own error, integrated out of the likelihood (likelihood module docstring)."""

import json
from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from peano_bayes.inference.denoise import fit_error_basis, piecewise_linear_segments
from peano_bayes.inference.fit import residual_correlation, structured_lag1
from peano_bayes.inference.likelihood import (
    _input_error_correction,
    bin_noise_sd,
    group_log_likelihood,
    input_error_jacobian,
    linearise_input_error,
    whitened_residuals,
    with_residual_lag1,
)
from peano_bayes.inference.reduce import prepare
from peano_bayes.physics import DEFAULT_CONFIG
from peano_bayes.rig import RigNoise, simulate_dataset


def test_error_basis_is_the_covariance_of_a_ramps_fit():
    """The stroke test's input, one ramp with white noise, 2000 noise draws: at least 95 % are denoised as one
    ramp (measured: 98 %; the rest split it, and their error is larger than the basis says), and over those the
    covariance of the fit minus the truth is B B^T (diagonal within 10 %; the sd of a variance estimate is 3 %)."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 20.0, 100)
    truth, sd = 1.5e3 * t, 500.0
    fits = [piecewise_linear_segments(t, truth + sd * rng.standard_normal(t.size), sd) for _ in range(2000)]
    errors = [fitted - truth for fitted, segments in fits if len(segments) == 1]
    assert len(errors) >= 0.95 * len(fits)
    basis = fit_error_basis(t, truth, [(0, t.size, True)], sd)
    assert basis.shape == (100, 2)  # offset and slope
    empirical = np.cov(np.array(errors).T)
    predicted = basis @ basis.T
    np.testing.assert_allclose(np.diag(empirical), np.diag(predicted), rtol=0.1)
    np.testing.assert_allclose(empirical[0, [25, 50, 99]], predicted[0, [25, 50, 99]], atol=0.1 * predicted[0, 0])


def test_error_basis_of_a_ramp_and_a_hold_given_their_segments():
    """Segments fixed (a ramp of 70 samples, a hold of 50): each fitted by hand (numpy polyfit, a mean), the
    covariance of the fit's error over 4000 draws is B B^T, and the two segments' errors are independent."""
    rng = np.random.default_rng(6)
    t = np.linspace(0.0, 10.0, 120)
    sd = 2.0
    segments = [(0, 70, True), (70, 120, False)]

    def by_hand(noise):
        ramp = np.polyval(np.polyfit(t[:70], noise[:70], 1), t[:70])
        return np.concatenate([ramp, np.full(50, noise[70:].mean())])

    errors = np.array([by_hand(sd * rng.standard_normal(t.size)) for _ in range(4000)])
    basis = fit_error_basis(t, np.zeros_like(t), segments, sd)
    assert basis.shape == (120, 3)
    predicted = basis @ basis.T
    empirical = np.cov(errors.T)
    np.testing.assert_allclose(np.diag(empirical), np.diag(predicted), rtol=0.1)
    assert np.all(predicted[:70, 70:] == 0.0) and np.all(np.abs(empirical[:70, 70:]) < 0.1 * predicted[0, 0])


def test_woodbury_correction_is_the_dense_gaussian():
    """Independent bins plus the correction equal, per simulated input, scipy's multivariate normal of the
    stacked residuals of the runs sharing it, with covariance diag(1 / w) + (1 J)(1 J)^T."""
    rng = np.random.default_rng(0)
    shared = np.array([0, 0, 1, 0])
    r, m, q = 4, 15, 2
    residual = rng.normal(size=(r, m)) * 0.3
    weight = rng.uniform(2.0, 10.0, size=(r, m))
    weight[1, 3] = 0.0  # an unmeasured bin
    residual[1, 3] = 0.0
    jac = rng.normal(size=(2, q, m)) * 0.4
    correction = np.asarray(_input_error_correction(residual, weight, jac[shared], jnp.asarray(shared), 2))
    for j in range(2):
        rows = np.flatnonzero(shared == j)
        mask = weight[rows].ravel() > 0
        res = residual[rows].ravel()[mask]
        var = 1.0 / weight[rows].ravel()[mask]
        u = np.concatenate([jac[j].T] * rows.size)[mask]
        independent = np.sum(stats.norm.logpdf(res, scale=np.sqrt(var)))
        joint = stats.multivariate_normal(np.zeros(res.size), np.diag(var) + u @ u.T).logpdf(res)
        assert independent + correction[j] == pytest.approx(joint, rel=1e-10)


@pytest.fixture(scope="module")
def stroke():
    """TP stroke tests at the nominal parameters, one specimen, three repeats sharing one simulation, 30 bins
    per segment."""
    dataset = simulate_dataset("TP", None, seed=4, specimens=1, repeats=3, noise=RigNoise(), tests=("stroke",))
    obs = prepare(dataset, bins_per_segment={"stroke": 30})
    (group,) = obs.groups
    (own,) = json.loads(dataset.provenance["specimen_parameters"]).values()  # the specimen's generating values
    params = {k: jnp.asarray(v) for k, v in own.items()}
    return obs, group, {**params, "noise_stroke_strain": jnp.asarray(RigNoise().strain_sd)}


def test_input_jacobian_matches_finite_differences_and_whitens_the_truths_residuals(stroke):
    obs, group, params = stroke
    assert group.has_input_error and group.pressure_error.shape[:2] == (1, 2)  # one shared ramp: offset, slope
    model = {k: v for k, v in params.items() if k != "noise_stroke_strain"}
    _, _, jac = input_error_jacobian(model, group, geometry=obs.geometry)
    h = 1e-3  # of one column: ~0.03 Pa on a 30 kPa ramp

    def moved(sign):  # the prediction (same compiled function, inputs moved along the first column)
        g = replace(group, pressure_pa=group.pressure_pa + sign * h * group.pressure_error[:, 0])
        return np.asarray(input_error_jacobian(model, g, geometry=obs.geometry)[0])

    fd = (moved(1.0) - moved(-1.0)) / (2.0 * h)
    np.testing.assert_allclose(np.asarray(jac)[0, 0], fd[0], rtol=1e-4, atol=1e-6 * np.abs(fd).max())

    # At the generating values the whitened residuals are standard normal: 90 of them, rms sd 0.075.
    white = whitened_residuals(params, group, geometry=obs.geometry)
    assert np.all(np.isfinite(white))
    assert 0.8 < float(np.sqrt(np.mean(white**2))) < 1.2
    # The group's log-likelihood sums to the dense Gaussian of the stacked runs, covariance D + (1 J)(1 J)^T.
    predicted, scale, ll = (np.asarray(a) for a in group_log_likelihood(params, group, geometry=obs.geometry))
    residual = (np.asarray(group.observed) - predicted).ravel()
    u = np.concatenate([np.asarray(jac)[0].T] * 3)
    dense = stats.multivariate_normal(np.zeros(residual.size), np.diag(scale.ravel() ** 2) + u @ u.T)
    assert float(ll.sum()) == pytest.approx(dense.logpdf(residual), rel=1e-9)


@pytest.fixture(scope="module")
def load_cycles():
    """TP load cycles at the nominal parameters, one specimen, two repeats of each pressure (sharing a
    simulation), 20 bins per segment."""
    dataset = simulate_dataset("TP", None, seed=8, specimens=1, repeats=2, noise=RigNoise(), tests=("load_cycle",))
    obs = prepare(dataset, bins_per_segment={"load_cycle": 20})
    (own,) = json.loads(dataset.provenance["specimen_parameters"]).values()
    params = {k: jnp.asarray(v) for k, v in own.items()}
    return obs, {**params, "noise_load_cycle_force_n": jnp.asarray(RigNoise().force_sd_n)}


def test_load_cycles_carry_their_strain_and_pressure_error_and_integrate_it_exactly(load_cycles):
    """The load cycle's imposed strain and its pressure are both fitted inputs: both carry error columns, the
    Jacobian along a strain column is the finite difference of the simulation, and the group's log-likelihood
    is the dense Gaussian of each shared simulation's runs (covariance D + (1 J)(1 J)^T)."""
    obs, params = load_cycles
    model = {k: v for k, v in params.items() if k != "noise_load_cycle_force_n"}
    for group in obs.groups:
        assert group.has_input_error
        strain_cols = np.abs(np.asarray(group.strain_error)).max(axis=2) > 0  # (u, q)
        pressure_cols = np.abs(np.asarray(group.pressure_error)).max(axis=2) > 0
        assert strain_cols.any(axis=1).all() and pressure_cols.any(axis=1).all()
        assert not (strain_cols & pressure_cols).any()  # each column perturbs one input
    group = obs.groups[0]
    _, _, jac = input_error_jacobian(model, group, geometry=obs.geometry)
    column = int(np.flatnonzero(np.abs(np.asarray(group.strain_error[0])).max(axis=1) > 0)[0])
    h = 1e-2  # a hundredth of one sd of the fit's error along this column

    def moved(sign):
        g = replace(group, strain=group.strain + sign * h * group.strain_error[:, column])
        return np.asarray(input_error_jacobian(model, g, geometry=obs.geometry)[0])

    fd = (moved(1.0) - moved(-1.0)) / (2.0 * h)
    np.testing.assert_allclose(np.asarray(jac)[:, column], fd, rtol=1e-3, atol=1e-4 * np.abs(fd).max())
    assert np.abs(fd).max() > 0.0

    white = whitened_residuals(params, group, geometry=obs.geometry)
    assert np.all(np.isfinite(white)) and 0.8 < float(np.sqrt(np.mean(white**2))) < 1.2
    predicted, scale, ll = (np.asarray(a) for a in group_log_likelihood(params, group, geometry=obs.geometry))
    shared = np.asarray(group.shared)
    for j in range(group.specimen_index.shape[0]):
        rows = np.flatnonzero(shared == j)
        residual = (np.asarray(group.observed)[rows] - predicted[rows]).ravel()
        u = np.concatenate([np.asarray(jac)[j].T] * rows.size)
        dense = stats.multivariate_normal(np.zeros(residual.size), np.diag(scale[rows].ravel() ** 2) + u @ u.T)
        assert float(ll[rows].sum()) == pytest.approx(dense.logpdf(residual), rel=1e-9)


def test_the_input_error_linearised_once_is_the_live_one_there_and_a_fixed_covariance_elsewhere(load_cycles):
    """``linearise_input_error`` at the generating values: its central-difference ``J`` is the forward-mode one,
    so there the likelihood equals the one that differentiates the simulation at every point; at other
    parameters it is the dense Gaussian of the residuals there with the covariance D + (1 J0)(1 J0)^T of the
    linearisation point."""
    obs, params = load_cycles
    frozen = linearise_input_error(params, obs)
    model = {k: v for k, v in params.items() if k != "noise_load_cycle_force_n"}
    for live_group, frozen_group in zip(obs.groups, frozen.groups, strict=True):
        forward = np.asarray(input_error_jacobian(model, live_group, geometry=obs.geometry)[2])
        held = np.asarray(frozen_group.input_jacobian)
        np.testing.assert_allclose(held, forward, rtol=1e-6, atol=1e-6 * np.abs(forward).max())
        live = np.asarray(group_log_likelihood(params, live_group, geometry=obs.geometry)[2]).sum()
        fixed = np.asarray(group_log_likelihood(params, frozen_group, geometry=obs.geometry)[2]).sum()
        assert fixed == pytest.approx(live, rel=1e-9)
    moved = {**params, "tensile_ka_n_per_m": params["tensile_ka_n_per_m"] * 1.03}
    group = frozen.groups[0]
    jac = np.asarray(group.input_jacobian)
    predicted, scale, ll = (np.asarray(a) for a in group_log_likelihood(moved, group, geometry=obs.geometry))
    live_ll = np.asarray(group_log_likelihood(moved, obs.groups[0], geometry=obs.geometry)[2])
    assert abs(float(ll.sum()) - float(live_ll.sum())) > 1e-9  # a different covariance there
    shared = np.asarray(group.shared)
    for j in range(group.specimen_index.shape[0]):
        rows = np.flatnonzero(shared == j)
        residual = (np.asarray(group.observed)[rows] - predicted[rows]).ravel()
        u = np.concatenate([jac[j].T] * rows.size)
        dense = stats.multivariate_normal(np.zeros(residual.size), np.diag(scale[rows].ravel() ** 2) + u @ u.T)
        assert float(ll[rows].sum()) == pytest.approx(dense.logpdf(residual), rel=1e-9)


def test_residual_correlation_tells_noise_from_a_misfit_with_structure(load_cycles):
    """At the generating values the whitened load-cycle residuals are uncorrelated from bin to bin (the check
    passes); a smooth misfit of three bin sds added to the data (what a model that cannot take the data's shape
    leaves) gives a lag-1 correlation near 1 and fails it. The held Jacobian (as the sampler uses it) whitens
    as the live one does."""
    obs, params = load_cycles
    quiet = residual_correlation(params, obs, DEFAULT_CONFIG)["load_cycle"]
    assert quiet["pairs"] > 100
    assert abs(quiet["lag1"]) < 4.0 / np.sqrt(quiet["pairs"]) and quiet["consistent_with_noise"]

    def bent(group):
        scale = np.asarray(bin_noise_sd(params["noise_load_cycle_force_n"], group))
        phase = np.linspace(0.0, 2.0 * np.pi, group.observed.shape[1])
        return replace(group, observed=np.asarray(group.observed) + 3.0 * scale * np.sin(phase))

    misfit = residual_correlation(params, replace(obs, groups=tuple(bent(g) for g in obs.groups)), DEFAULT_CONFIG)
    assert misfit["load_cycle"]["lag1"] > 0.5 and not misfit["load_cycle"]["consistent_with_noise"]
    assert misfit["load_cycle"]["interval_factor"] > 1.7

    def gapped(group):  # every other bin unmeasured: no consecutive pair to judge
        observed = np.asarray(group.observed).copy()
        observed[:, 1::2] = np.nan
        return replace(group, observed=observed)

    none = residual_correlation(params, replace(obs, groups=tuple(gapped(g) for g in obs.groups)), DEFAULT_CONFIG)
    assert none["load_cycle"] == {"lag1": None, "pairs": 0, "interval_factor": 1.0, "consistent_with_noise": True}

    held = linearise_input_error(params, obs).groups[0]
    assert held.input_jacobian is not None
    live = whitened_residuals(params, obs.groups[0], geometry=obs.geometry)
    np.testing.assert_allclose(whitened_residuals(params, held, geometry=obs.geometry), live, rtol=0, atol=1e-5)


def ar1_correlation(measured: np.ndarray, restart: np.ndarray, lag1: float) -> np.ndarray:
    """(n, n) correlation of a run's measured bins (``measured`` (m,) bool) under AR(1) from bin to bin, each
    stretch of consecutive measured bins on its own (an unmeasured bin, or a bin where ``restart`` (m,) is set,
    breaks the chain): lag1^|i - j| within a stretch, 0 across."""
    stretch = np.cumsum(~measured | restart)[measured]  # bins of one stretch share the count of breaks before them
    index = np.flatnonzero(measured)
    same = stretch[:, None] == stretch[None, :]
    return np.where(same, lag1 ** np.abs(index[:, None] - index[None, :]), 0.0)


def test_ar1_residuals_are_the_dense_gaussian_with_the_inputs_error(load_cycles):
    """With ``residual_lag1`` set, each shared simulation's runs have the dense Gaussian density with covariance
    S R S + (1 J)(1 J)^T, R block-diagonal over runs and over the stretches between unmeasured bins and segment
    starts of the inputs, with entries lag1^|i - j| (built here from that formula, not from the likelihood's
    filter); without the inputs' error, S R S alone. Lag-1 0 is the independent likelihood."""
    obs, params = load_cycles
    frozen = linearise_input_error(params, obs)
    group = frozen.groups[0]
    restart = np.asarray(group.segment_start)
    assert restart.shape == group.observed.shape and restart[:, 0].all() and restart[:, 1:].any(axis=1).all()
    assert np.ptp(np.asarray(group.counts)) > 0  # bins of unequal size: the per-bin scale matters
    observed = np.asarray(group.observed).copy()
    observed[0, 7] = np.nan  # a gap inside the first run
    group = replace(group, observed=observed)
    moved = {**params, "tensile_ka_n_per_m": params["tensile_ka_n_per_m"] * 1.02}  # residuals with some shape
    for lag1 in (0.0, 0.6, 0.97):
        ar = with_residual_lag1(replace(frozen, groups=(group,)), {"load_cycle": lag1}).groups[0]
        assert float(ar.residual_lag1) == lag1
        for with_error in (True, False):
            g = ar if with_error else replace(ar, strain_error=None, pressure_error=None, input_jacobian=None)
            predicted, scale, ll = (np.asarray(a) for a in group_log_likelihood(moved, g, geometry=obs.geometry))
            shared = np.asarray(g.shared)
            for j in range(g.specimen_index.shape[0]):
                rows = np.flatnonzero(shared == j)
                measured = np.isfinite(observed[rows])
                residual = (observed[rows] - predicted[rows])[measured]
                sd = scale[rows][measured]
                blocks = [ar1_correlation(measured[i], restart[rows][i], lag1) for i in range(rows.size)]
                size = sum(b.shape[0] for b in blocks)
                corr, at = np.zeros((size, size)), 0
                for b in blocks:
                    corr[at : at + b.shape[0], at : at + b.shape[0]] = b
                    at += b.shape[0]
                cov = sd[:, None] * corr * sd[None, :]
                if with_error:
                    u = np.concatenate([np.asarray(g.input_jacobian)[j].T] * rows.size)[measured.ravel()]
                    cov = cov + u @ u.T
                dense = stats.multivariate_normal(np.zeros(residual.size), cov).logpdf(residual)
                assert float(ll[rows].sum()) == pytest.approx(dense, rel=1e-9), (lag1, with_error, j)
    independent = np.asarray(group_log_likelihood(moved, group, geometry=obs.geometry)[2])
    zero = with_residual_lag1(replace(frozen, groups=(group,)), {"load_cycle": 0.0}).groups[0]
    np.testing.assert_allclose(np.asarray(group_log_likelihood(moved, zero, geometry=obs.geometry)[2]), independent,
                               rtol=1e-12, atol=1e-9)  # fmt: skip


def test_only_a_structured_test_gets_ar1_residuals_and_its_correlation_is_capped(load_cycles):
    """``structured_lag1`` names the tests whose residual check fails and nothing else (data the model explains
    keep independent bins); ``with_residual_lag1`` clips what it is given to [0, 0.99]."""
    obs, params = load_cycles
    assert structured_lag1(residual_correlation(params, obs, DEFAULT_CONFIG)) == {}
    flagged = {"load_cycle": {"lag1": 0.995, "consistent_with_noise": False}, "stroke": {"lag1": 0.1,
               "consistent_with_noise": True}}  # fmt: skip
    assert structured_lag1(flagged) == {"load_cycle": 0.995}
    capped = with_residual_lag1(obs, structured_lag1(flagged))
    assert all(float(g.residual_lag1) == 0.99 for g in capped.groups)
    assert all(g.residual_lag1 is None for g in with_residual_lag1(obs, {"stroke": 0.5}).groups)
