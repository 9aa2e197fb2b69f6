"""Sampler coordinates: the tensile-stretch map is a bijection onto the parameters' support with the right
Jacobian, and a run in those coordinates samples the theta posterior (draws reported in theta)."""

from types import SimpleNamespace

import numpy as np
import pytest

from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.coordinates import KA, KB, Identity, TensileStretch, sampler_coordinates
from peano_bayes.inference.prior_files import prior_for
from peano_bayes.inference.sample import sample
from tests.test_sample import Gaussian


def finite_difference_log_det(coords, z: np.ndarray, h: float) -> float:
    """ln|det d theta / d z| at ``z`` (D,) by central differences of ``coords.to_theta``."""
    jac = np.empty((z.size, z.size))
    for col in range(z.size):
        step = np.zeros(z.size)
        step[col] = h
        jac[:, col] = (coords.to_theta(z + step)[0][0] - coords.to_theta(z - step)[0][0]) / (2 * h)
    return float(np.log(abs(np.linalg.det(jac))))


def _coordinates(material: str) -> tuple[TensileStretch, object]:
    prior = prior_for(material).select([KA, KB])
    return sampler_coordinates(SimpleNamespace(prior=prior), "tensile_stretch"), prior


@pytest.mark.parametrize("material", ["PR", "FC"])  # a loguniform and a lognormal ka prior
def test_tensile_stretch_round_trips_and_its_log_jacobian_matches_finite_differences(material):
    coords, prior = _coordinates(material)
    assert isinstance(coords, TensileStretch) and coords.index == (0, 1)
    theta = prior.sample(np.random.default_rng(4), 20)
    z = coords.to_sampler(theta)
    ka, kb = (np.asarray(prior.marginals[n].from_unconstrained(theta[:, i])[0]) for i, n in enumerate((KA, KB)))
    np.testing.assert_allclose(np.exp(z[:, 1]) * ka + kb * np.exp(2 * z[:, 1]), 20.0, rtol=1e-9)  # d(20 N)
    back, log_jacobian = coords.to_theta(z)
    np.testing.assert_allclose(back, theta, rtol=1e-8, atol=1e-8)
    for k in range(theta.shape[0]):
        assert log_jacobian[k] == pytest.approx(finite_difference_log_det(coords, z[k], 1e-5), abs=1e-4)


def test_stretches_outside_the_wedge_have_no_density():
    coords, _ = _coordinates("PR")
    d1 = 1e-4
    # d2/d1 above F2/F1 needs kb < 0; below sqrt(F2/F1) needs ka < 0
    for ratio in (25.0, 3.0):
        _, log_jacobian = coords.to_theta(np.log([[d1, ratio * d1]]))
        assert log_jacobian[0] == -np.inf
    _, inside = coords.to_theta(np.log([[d1, 10.0 * d1]]))
    assert np.isfinite(inside[0])


def test_only_a_sampled_pair_is_reparameterized_and_unknown_kinds_are_refused():
    ka_only = SimpleNamespace(prior=prior_for("PR").select([KA]))
    assert isinstance(sampler_coordinates(ka_only, "tensile_stretch"), Identity)
    assert isinstance(sampler_coordinates(ka_only, "theta"), Identity)
    with pytest.raises(ValueError, match="tensile_stretch"):
        sampler_coordinates(ka_only, "stretch")


class _GaussianInTheta(Gaussian):
    """A correlated Gaussian over theta = (u_ka, u_kb, c) centred at ``mean``."""

    names = (KA, KB, "c")
    cov = np.array([[0.04, 0.03, 0.0], [0.03, 0.09, 0.01], [0.0, 0.01, 0.25]])

    def __init__(self, mean):
        self.mean = mean


def test_a_run_in_stretch_coordinates_samples_the_theta_posterior():
    """The sampler moves the log stretches; the reported chain is theta and has the target's moments (means within
    5 Monte Carlo standard errors, sd within 10 %), and its log posterior is theta's."""
    coords, prior = _coordinates("PR")
    mean = np.append(np.asarray(prior.to_unconstrained({KA: 2e3, KB: 1e8})), 0.5)
    target = _GaussianInTheta(mean)
    result = sample(
        target,
        mean + 0.05,
        0.01 * np.eye(3),
        n_walkers=16,
        seed=5,
        chunk=1000,
        max_steps=20_000,
        progress=False,
        log=lambda m: None,
        coordinates=coords,
    )
    conv = result.convergence
    assert conv.converged, conv.problems
    draws = result.kept().reshape(-1, 3)
    se = np.sqrt(np.diag(target.cov) / conv.ess_bulk)
    assert np.all(np.abs(draws.mean(axis=0) - mean) < 5 * se)
    np.testing.assert_allclose(draws.std(axis=0), np.sqrt(np.diag(target.cov)), rtol=0.1)
    np.testing.assert_allclose(result.log_prob[-1], target.batched(result.chain[-1]), atol=1e-9)


def test_a_resume_refuses_a_state_written_in_other_coordinates_and_says_which(tmp_path):
    coords, prior = _coordinates("PR")
    mean = np.append(np.asarray(prior.to_unconstrained({KA: 2e3, KB: 1e8})), 0.5)
    target, state = _GaussianInTheta(mean), tmp_path / "state.npz"
    options = dict(n_walkers=16, seed=5, warmup=10, max_steps=20, progress=False, log=lambda m: None)
    sample(target, mean, 0.01 * np.eye(3), state_path=state, **options)
    says = r"another run: --coordinates: saved theta, now tensile_stretch \(forces \["
    with pytest.raises(PeanoBayesInputError, match=says):
        sample(target, mean, 0.01 * np.eye(3), state_path=state, resume=True, coordinates=coords, **options)
    resumed = sample(target, mean, 0.01 * np.eye(3), state_path=state, resume=True, **options)
    assert resumed.resumed_from == 20


def _with_contrasts(n_contrasts: int):
    """A stub posterior: PR's tensile pair and the spread as population parameters, then ``n_contrasts``
    contrasts."""
    from peano_bayes.inference.posterior import SPECIMEN_SD

    prior = prior_for("PR")
    prior = prior.select([KA, KB, SPECIMEN_SD]) if SPECIMEN_SD in prior.names else None
    assert prior is not None
    names = tuple(f"specimen_contrast_x_{k + 1}" for k in range(n_contrasts))
    return SimpleNamespace(prior=prior, n_contrasts=n_contrasts, contrast_names=names)


def test_noncentred_contrasts_compose_with_the_stretches_round_trip_and_have_the_right_jacobian():
    from peano_bayes.inference.coordinates import Composed, NonCentredContrasts

    post = _with_contrasts(3)
    coords = sampler_coordinates(post, "tensile_stretch", (True, False, True))
    assert isinstance(coords, Composed) and isinstance(coords.inner, NonCentredContrasts)
    rng = np.random.default_rng(9)
    theta = np.column_stack([post.prior.sample(rng, 10), 0.05 * rng.normal(size=(10, 3))])
    z = coords.to_sampler(theta)
    tau = np.asarray(post.prior.marginals["specimen_log_sd"].from_unconstrained(theta[:, 2])[0])
    np.testing.assert_allclose(z[:, 3], theta[:, 3] / tau)  # non-centred: in units of the spread
    np.testing.assert_array_equal(z[:, 4], theta[:, 4])  # centred: as it is
    back, log_jacobian = coords.to_theta(z)
    np.testing.assert_allclose(back, theta, rtol=1e-8, atol=1e-10)
    for k in range(theta.shape[0]):
        assert log_jacobian[k] == pytest.approx(finite_difference_log_det(coords, z[k], 1e-6), abs=1e-4)
    assert coords.describe()["parts"][1] == {"kind": "noncentred_contrasts", "noncentred": [True, False, True]}
    with pytest.raises(ValueError, match="2 non-centring flags for 3 contrasts"):
        sampler_coordinates(post, "theta", (True, False))


def test_a_contrast_is_non_centred_where_the_data_pin_it_little_against_the_spread():
    from peano_bayes.inference.coordinates import NONCENTRE_RATIO, choose_noncentred

    post = _with_contrasts(2)
    mode = np.zeros(5)
    mode[2] = post.prior.marginals["specimen_log_sd"].to_unconstrained(0.1)  # spread 0.1 at the mode
    cov = np.diag([0.1, 0.1, 0.1, (0.9 * NONCENTRE_RATIO * 0.1) ** 2, (1.1 * NONCENTRE_RATIO * 0.1) ** 2])
    assert choose_noncentred(post, mode, cov) == (False, True)
    assert choose_noncentred(SimpleNamespace(n_contrasts=0), mode, cov) == ()


def test_the_contrasts_choice_names_which_contrasts_are_non_centred():
    from peano_bayes.inference.coordinates import NONCENTRE_RATIO, contrast_flags

    post = _with_contrasts(2)
    mode = np.zeros(5)
    mode[2] = post.prior.marginals["specimen_log_sd"].to_unconstrained(0.1)
    cov = np.diag([0.1, 0.1, 0.1, (0.9 * NONCENTRE_RATIO * 0.1) ** 2, (1.1 * NONCENTRE_RATIO * 0.1) ** 2])
    assert contrast_flags("auto", post, mode, cov) == (False, True)
    assert contrast_flags("centred", post, mode, cov) == ()
    assert contrast_flags("noncentred", post, mode, cov) == (True, True)
    assert contrast_flags("noncentred", SimpleNamespace(n_contrasts=0), mode, cov) == ()
    with pytest.raises(ValueError, match="unknown contrasts choice 'sideways'"):
        contrast_flags("sideways", post, mode, cov)
