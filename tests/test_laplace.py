"""The walkers' start: the posterior mode by BFGS and the Laplace covariance by differences of the gradient."""

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from peano_bayes.inference.laplace import Laplace, finite_difference_hessian, posterior_mode, refine_mode


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
    start = Laplace(mean + np.array([0.8, -0.9, 1.5]), 0.2 * np.eye(3) * 0.05, 0.0, 0, "", 0.0)
    refined = refine_mode(gaussian_batch(mean, cov), start)
    assert refined.succeeded, refined.status
    # BFGS stops at a whitened gradient norm <= gtol (1e-3), so the Mahalanobis distance to the mode is at most
    # gtol * sqrt(largest eigenvalue of cov in the start's whitened units) = 1e-3 * sqrt(0.25 / 0.01) = 5e-3.
    offset = refined.mode - mean
    assert np.sqrt(offset @ np.linalg.solve(cov, offset)) < 5e-3
    np.testing.assert_allclose(refined.covariance, cov, rtol=1e-5, atol=1e-8)
    assert abs(refined.log_prob) < 1e-6


def test_refine_keeps_a_start_it_cannot_improve():
    start = Laplace(np.zeros(2), np.diag([0.3, 0.2]), -5.0, 7, "", 1.0)
    cliff = lambda x: np.where(np.all(x == 0.0, axis=1), 0.0, -np.inf)  # noqa: E731
    refined = refine_mode(cliff, start)
    np.testing.assert_array_equal(refined.mode, start.mode)
    np.testing.assert_array_equal(refined.covariance, start.covariance)
    assert refined.log_prob == 0.0  # the full posterior's value at the start, not the start's own
    assert not refined.succeeded


def test_refine_keeps_the_start_covariance_when_the_hessian_leaves_the_support():
    mean, cov = np.array([0.0, 0.0]), np.diag([1.0, 1.0])
    inner = gaussian_batch(mean, cov)
    # support x0 <= 0.01: the mode lies on its edge, so a Hessian point past it is -inf
    walled = lambda x: np.where(x[:, 0] <= 0.01, inner(x), -np.inf)  # noqa: E731
    start = Laplace(np.array([-0.3, 0.4]), np.diag([0.5, 0.5]), 0.0, 0, "", 0.0)
    refined = refine_mode(walled, start)
    np.testing.assert_array_equal(refined.covariance, start.covariance)
    assert refined.log_prob > float(inner(start.mode[None])[0])
