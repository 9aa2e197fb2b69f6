"""The walkers' start: the posterior mode by BFGS and the Laplace covariance by differences of the gradient."""

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import optimize

from peano_bayes.inference.laplace import (
    Laplace,
    NonCentred,
    finite_difference_hessian,
    posterior_mode,
    refine_mode,
)
from peano_bayes.inference.status import ModeStatus


@dataclass
class Quadratic:
    """A Gaussian log density (duck type of ``Posterior.log_prob``), flat along ``flat`` axes if given."""

    mean: np.ndarray
    precision: np.ndarray

    def log_prob(self, theta):
        d = theta - jnp.asarray(self.mean)
        return -0.5 * d @ jnp.asarray(self.precision) @ d


def test_mode_and_covariance_of_a_gaussian():
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, -0.02], [0.0, -0.02, 0.25]])
    target = Quadratic(np.array([1.0, -3.0, 0.5]), np.linalg.inv(cov))
    laplace = posterior_mode(target, np.zeros(3), np.eye(3))
    assert laplace.succeeded, laplace.status
    np.testing.assert_allclose(laplace.mode, target.mean, atol=1e-6)
    np.testing.assert_allclose(laplace.covariance, cov, rtol=1e-6, atol=1e-9)
    assert laplace.log_prob > -1e-10


def test_a_flat_direction_takes_the_fallback_variance_and_the_cap():
    precision = np.diag([4.0, 0.0])  # nothing pins down the second coordinate
    target = Quadratic(np.array([0.5, 0.0]), precision)
    laplace = posterior_mode(target, np.array([0.0, 0.0]), np.diag([1.0, 0.7**2]))
    np.testing.assert_allclose(laplace.covariance, np.diag([0.25, 0.49]), atol=1e-8)
    weak = posterior_mode(Quadratic(np.zeros(1), np.array([[1e-4]])), np.ones(1), np.eye(1), max_sd=3.0)
    np.testing.assert_allclose(weak.covariance, [[9.0]])


def test_a_start_better_than_where_bfgs_ends_is_kept():
    class Cliff:
        """-inf everywhere except at the start: the optimiser cannot improve on it."""

        def log_prob(self, theta):
            return jnp.where(jnp.all(theta == 0.0), 0.0, -jnp.inf)

    fallback = np.diag([0.3, 0.2])
    laplace = posterior_mode(Cliff(), np.zeros(2), fallback)
    np.testing.assert_array_equal(laplace.mode, np.zeros(2))
    np.testing.assert_array_equal(laplace.covariance, fallback)
    outside = posterior_mode(Cliff(), np.ones(2), fallback)  # a start where the density is 0
    assert outside.status is ModeStatus.START_NOT_FINITE and not outside.succeeded
    assert outside.describe() == "the start's log posterior or its gradient is not finite"
    np.testing.assert_array_equal(outside.mode, np.ones(2))


def test_finite_difference_hessian_of_a_cubic():
    # f = x^3 + x y^2: H = [[6x, 2y], [2y, 2x]]
    grad = lambda v: np.array([3 * v[0] ** 2 + v[1] ** 2, 2 * v[0] * v[1]])  # noqa: E731
    np.testing.assert_allclose(finite_difference_hessian(grad, np.array([1.0, 2.0])), [[6, 4], [4, 2]], atol=1e-6)


def gaussian_batch(mean, cov):
    """``f(thetas (n, D)) -> (n,)`` Gaussian log density (the batched contract :func:`refine_mode` reads)."""
    precision = np.linalg.inv(cov)
    return lambda x: -0.5 * np.einsum("ni,ij,nj->n", x - mean, precision, x - mean)


def test_refine_moves_a_mode_of_the_wrong_posterior_to_the_right_one():
    # The start: the mode and covariance of a narrower posterior centred elsewhere (what exact inputs give).
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, -0.02], [0.0, -0.02, 0.25]])
    mean = np.array([1.0, -3.0, 0.5])
    start = Laplace(mean + np.array([0.8, -0.9, 1.5]), 0.2 * np.eye(3) * 0.05, 0.0, 0, ModeStatus.SUCCESSFUL, 0.0)
    refined = refine_mode(gaussian_batch(mean, cov), start)
    assert refined.succeeded, refined.status
    # BFGS stops at a whitened gradient norm <= gtol (1e-3), so the Mahalanobis distance to the mode is at most
    # gtol * sqrt(largest eigenvalue of cov in the start's whitened units) = 1e-3 * sqrt(0.25 / 0.01) = 5e-3.
    offset = refined.mode - mean
    assert np.sqrt(offset @ np.linalg.solve(cov, offset)) < 5e-3
    np.testing.assert_allclose(refined.covariance, cov, rtol=1e-5, atol=1e-8)
    assert abs(refined.log_prob) < 1e-6


def test_refine_keeps_a_start_it_cannot_improve():
    start = Laplace(np.zeros(2), np.diag([0.3, 0.2]), -5.0, 7, ModeStatus.SUCCESSFUL, 1.0)
    cliff = lambda x: np.where(np.all(x == 0.0, axis=1), 0.0, -np.inf)  # noqa: E731
    refined = refine_mode(cliff, start)
    np.testing.assert_array_equal(refined.mode, start.mode)
    np.testing.assert_array_equal(refined.covariance, start.covariance)
    assert refined.log_prob == 0.0  # the full posterior's value at the start, not the start's own
    assert refined.status is ModeStatus.HESSIAN_NOT_FINITE and not refined.succeeded  # a cliff all round
    assert not refined.succeeded


def test_refine_keeps_the_start_covariance_when_the_hessian_leaves_the_support():
    mean, cov = np.array([0.0, 0.0]), np.diag([1.0, 1.0])
    inner = gaussian_batch(mean, cov)
    # support x0 <= 0.01: the mode lies on its edge, so a Hessian point past it is -inf
    walled = lambda x: np.where(x[:, 0] <= 0.01, inner(x), -np.inf)  # noqa: E731
    start = Laplace(np.array([-0.3, 0.4]), np.diag([0.5, 0.5]), 0.0, 0, ModeStatus.SUCCESSFUL, 0.0)
    refined = refine_mode(walled, start)
    np.testing.assert_array_equal(refined.covariance, start.covariance)
    assert refined.log_prob > float(inner(start.mode[None])[0])


class Funnel:
    """A two-specimen hierarchy in miniature (duck type of :class:`Posterior`): theta = (u, c1, c2), the spread
    tau from u by the bundled prior's ``specimen_log_sd`` marginal (half-normal, log transform), centred
    contrasts c ~ N(0, tau^2) and one measurement of each, y = c + N(0, 0.05^2), that says the specimens are
    alike (y = 0.01, -0.005). Its joint density is unbounded along c -> 0, tau -> 0."""

    def __init__(self):
        from peano_bayes.inference.prior_files import prior_for

        self.marginal = prior_for("TP").marginals["specimen_log_sd"]
        self.prior = type(
            "P", (), {"ndim": 1, "names": ("specimen_log_sd",), "marginals": {"specimen_log_sd": self.marginal}}
        )
        self.n_contrasts = 2
        self.y = jnp.array([0.01, -0.005])

    def log_prob(self, theta):
        tau, log_jac = self.marginal.from_unconstrained(theta[0])
        c = theta[1:]
        prior = -0.5 * (tau / 0.2) ** 2 + log_jac  # half-normal(0.2) in u, up to a constant
        pooled = jnp.sum(-0.5 * (c / tau) ** 2 - jnp.log(tau))
        return prior + pooled + jnp.sum(-0.5 * ((self.y - c) / 0.05) ** 2)


@pytest.mark.parametrize("transform", ["log", "logit"])
def test_the_non_centred_map_and_its_jacobian_match_finite_differences(transform):
    """Under a log transform dtau/du equals tau, so the logit case (a spread bounded above, 0-0.5) is what tells
    a Jacobian using tau from one using dtau/du."""
    funnel = Funnel()
    coords = NonCentred.of(funnel)
    if transform == "logit":
        from peano_bayes.inference.prior_files import prior_for

        marginal = prior_for("TP").marginals["friction_pressure_fraction"]
        assert marginal.transform == "logit"
        coords = NonCentred(1, 0, marginal)
    eta = np.array([-2.3, 0.7, -1.1])
    np.testing.assert_allclose(coords.to_eta(coords.to_theta(eta)), eta, rtol=1e-12)
    h = 1e-6
    numeric = np.column_stack(
        [(coords.to_theta(eta + h * e) - coords.to_theta(eta - h * e)) / (2 * h) for e in np.eye(3)]
    )
    np.testing.assert_allclose(coords.jacobian(eta), numeric, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(coords.log_jacobian(eta), np.log(np.linalg.det(coords.jacobian(eta))), rtol=1e-12)
    numeric_grad = [(coords.log_jacobian(eta + h * e) - coords.log_jacobian(eta - h * e)) / (2 * h) for e in np.eye(3)]
    np.testing.assert_allclose(coords.log_jacobian_gradient(eta), numeric_grad, rtol=1e-7, atol=1e-10)
    assert NonCentred.of(Quadratic(np.zeros(2), np.eye(2))) is None  # no contrasts: theta itself


def test_the_mode_of_a_hierarchy_whose_specimens_are_alike_is_sought_where_it_exists():
    """In theta BFGS runs down the funnel (tau -> 0, the Hessian overflows); in eta it stops at a finite
    spread, where the gradient of ln p(eta) vanishes, and both searches return finite covariances."""
    funnel = Funnel()
    coords = NonCentred.of(funnel)
    start = np.array([np.log(0.1), 0.0, 0.0])
    laplace = posterior_mode(funnel, start, np.diag([1.0, 0.04, 0.04]))
    assert laplace.succeeded, laplace.status
    tau = float(funnel.marginal.from_unconstrained(laplace.mode[0])[0])
    assert 0.05 < tau < 0.5, tau  # the data barely inform the spread: near the prior's mode in u, 0.2
    assert laplace.log_prob == pytest.approx(float(funnel.log_prob(jnp.asarray(laplace.mode))), abs=1e-9)  # in theta
    # the same search in theta collapses the spread
    minus = jax.jit(jax.value_and_grad(lambda t: -funnel.log_prob(t)))
    in_theta = optimize.minimize(
        lambda t: tuple(np.asarray(v, dtype=float) for v in minus(jnp.asarray(t))), start, jac=True, method="BFGS"
    )
    assert float(funnel.marginal.from_unconstrained(in_theta.x[0])[0]) < 1e-3
    eta = coords.to_eta(laplace.mode)
    log_p_eta = lambda e: float(funnel.log_prob(jnp.asarray(coords.to_theta(e)))) + coords.log_jacobian(e)  # noqa: E731
    h = 1e-5
    gradient = [(log_p_eta(eta + h * e) - log_p_eta(eta - h * e)) / (2 * h) for e in np.eye(3)]
    np.testing.assert_allclose(gradient, 0.0, atol=1e-4)
    # the covariance is the inverse Hessian of -ln p(eta), carried to theta by d theta / d eta
    h = 1e-3
    eye = np.eye(3)
    hessian = np.array(
        [
            [
                (log_p_eta(eta + h * (a + b)) - log_p_eta(eta + h * (a - b)) - log_p_eta(eta - h * (a - b))
                 + log_p_eta(eta - h * (a + b))) / (4 * h * h)
                for b in eye
            ]
            for a in eye
        ]
    )  # fmt: skip
    jac = coords.jacobian(eta)
    np.testing.assert_allclose(laplace.covariance, jac @ np.linalg.inv(-hessian) @ jac.T, rtol=1e-3, atol=1e-9)
    batched = jax.jit(jax.vmap(funnel.log_prob))
    refined = refine_mode(lambda thetas: np.asarray(batched(jnp.asarray(thetas))), laplace, coordinates=coords)
    np.testing.assert_allclose(refined.mode, laplace.mode, atol=1e-3)  # the same posterior: already there
    np.testing.assert_allclose(refined.covariance, laplace.covariance, rtol=0.02, atol=1e-9)
    assert refined.log_prob == pytest.approx(float(funnel.log_prob(jnp.asarray(refined.mode))), abs=1e-9)
