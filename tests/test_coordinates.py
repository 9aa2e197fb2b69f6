"""Sampler coordinates: the tensile-stretch map is a bijection onto the parameters' support with the right
Jacobian, and a run in those coordinates samples the theta posterior (draws reported in theta)."""

from types import SimpleNamespace

import numpy as np
import pytest

from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.coordinates import KA, KB, Identity, TensileStretch, sampler_coordinates
from peano_bayes.inference.priors import prior_for
from peano_bayes.inference.sample import sample
from tests.test_sample import Gaussian


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
    h = 1e-5
    for k in range(theta.shape[0]):
        jac = np.empty((2, 2))
        for col in range(2):
            step = np.zeros(2)
            step[col] = h
            jac[:, col] = (coords.to_theta(z[k] + step)[0][0] - coords.to_theta(z[k] - step)[0][0]) / (2 * h)
        assert log_jacobian[k] == pytest.approx(np.log(abs(np.linalg.det(jac))), abs=1e-4)


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
