"""The posterior's mode and a Laplace approximation around it: where the sampler's walkers start.

The least-squares fit (:mod:`.fit`) weights residuals with fixed noise scales and has no specimen contrasts,
so its point is not the posterior's mode: on the bundled TP data the log posterior there is 2041 against
6745 at the mode, and walkers started around it spend hundreds of steps climbing (the noise scales alone sit
at 2-4 times their posterior values). :func:`posterior_mode` therefore polishes the start with BFGS (scipy)
on the negative log posterior over the whole theta (noise scales, pooling scale and contrasts included),
then takes the covariance as the inverse Hessian, by central differences of the JAX gradient. One compiled
``value_and_grad`` serves the optimiser, the values and the Hessian: a second compiled program (optimistix's
own loop, or a compiled Hessian) cost more compile time than the whole optimisation.

**Several specimens: the mode is sought in non-centred coordinates.** With centred contrasts ``c ~ N(0,
tau^2)`` (:mod:`.posterior`) the joint density has no mode when the data allow the specimens to be alike: along
``c -> 0`` it grows like ``tau^(1-v)`` as the spread ``tau -> 0`` (``v`` contrasts; the 1 is the spread's own
log-transform Jacobian), so BFGS runs down the funnel (on an SBC replicate with spread 0.016 it reached
``ln tau = -344``, where the Hessian overflowed). Both mode searches therefore move ``eta = (u, z)``, ``c =
tau z``, whose density ``p(theta(eta)) tau^v`` is bounded there (:class:`NonCentred`); the mode and covariance
are reported in theta. With one specimen ``eta`` is theta.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize

from .posterior import SPECIMEN_SD, Posterior
from .status import ModeStatus


@dataclass(frozen=True, eq=False)
class Laplace:
    """``mode`` (D,) theta at the optimum; ``covariance`` (D, D) inverse Hessian of -log posterior there
    (eigenvalues floored and capped, see :func:`posterior_mode`); ``log_prob`` at the mode; ``steps`` of
    BFGS; ``status`` how it ended (:class:`~peano_bayes.inference.status.ModeStatus`); ``seconds`` wall, compile
    included; ``detail`` the optimiser's own message where it stopped short ("" otherwise)."""

    mode: np.ndarray
    covariance: np.ndarray
    log_prob: float
    steps: int
    status: ModeStatus
    seconds: float
    detail: str = ""

    @property
    def succeeded(self) -> bool:
        return self.status.ok

    def describe(self) -> str:
        """How the mode ended, in words: the status's message and the optimiser's detail."""
        return self.status.message + (f" ({self.detail})" if self.detail else "")


@dataclass(frozen=True, eq=False)
class NonCentred:
    """The map ``eta = (u, z) -> theta = (u, c)``, ``c = tau(u) z``, of a posterior with ``v`` specimen
    contrasts (``tau`` the spread ``specimen_log_sd`` at entry ``index`` of ``u``, ``d`` entries of ``u``).
    ``marginal``: the spread's prior marginal (its transform gives ``tau`` and ``d tau / d u``). Every method
    takes points of shape (..., D)."""

    d: int
    index: int
    marginal: object

    @classmethod
    def of(cls, posterior) -> NonCentred | None:
        """The map for ``posterior``; ``None`` when it has no contrasts (then eta is theta)."""
        if not getattr(posterior, "n_contrasts", 0):
            return None
        prior = posterior.prior
        return cls(prior.ndim, prior.names.index(SPECIMEN_SD), prior.marginals[SPECIMEN_SD])

    def _tau(self, x):
        tau, log_dtau = self.marginal.from_unconstrained(np.asarray(x)[..., self.index])
        return np.asarray(tau, dtype=float), np.exp(np.asarray(log_dtau, dtype=float))

    def to_theta(self, eta):
        eta = np.asarray(eta, dtype=float)
        tau = self._tau(eta)[0]
        return np.concatenate([eta[..., : self.d], tau[..., None] * eta[..., self.d :]], axis=-1)

    def to_eta(self, theta):
        theta = np.asarray(theta, dtype=float)
        tau = self._tau(theta)[0]
        return np.concatenate([theta[..., : self.d], theta[..., self.d :] / tau[..., None]], axis=-1)

    def log_jacobian(self, eta):
        """ln|det d theta / d eta| = v ln tau, shape (...)."""
        eta = np.asarray(eta, dtype=float)
        return (eta.shape[-1] - self.d) * np.log(self._tau(eta)[0])

    def jacobian(self, eta):
        """(D, D) d theta / d eta at one point ``eta`` (D,)."""
        eta = np.asarray(eta, dtype=float)
        tau, dtau = self._tau(eta)
        jac = np.eye(eta.size)
        jac[self.d :, self.d :] *= tau
        jac[self.d :, self.index] = eta[self.d :] * dtau
        return jac

    def log_jacobian_gradient(self, eta):
        """(D,) gradient of :meth:`log_jacobian` at one point ``eta`` (D,)."""
        eta = np.asarray(eta, dtype=float)
        tau, dtau = self._tau(eta)
        grad = np.zeros(eta.size)
        grad[self.index] = (eta.size - self.d) * dtau / tau
        return grad


class _Same:
    """Eta is theta (a posterior without specimen contrasts)."""

    def to_theta(self, eta):
        return np.asarray(eta, dtype=float)

    to_eta = to_theta

    def log_jacobian(self, eta):
        return np.zeros(np.shape(eta)[:-1])

    def jacobian(self, eta):
        return np.eye(np.size(eta))

    def log_jacobian_gradient(self, eta):
        return np.zeros(np.size(eta))


def _theta_log_prob(coords, eta, log_prob_eta: float) -> float:
    """ln p(theta(eta)) from the searched density ln p(eta) = ln p(theta) + ln|d theta / d eta|."""
    return float(log_prob_eta - coords.log_jacobian(eta))


def _in_theta(jac: np.ndarray, covariance_eta: np.ndarray) -> np.ndarray:
    return jac @ covariance_eta @ jac.T


def covariance_in_eta(jac: np.ndarray, covariance_theta: np.ndarray) -> np.ndarray:
    """A covariance in theta (D, D) carried to eta through ``jac`` = d theta / d eta (D, D) at the point."""
    inverse = np.linalg.inv(jac)
    return inverse @ covariance_theta @ inverse.T


def finite_difference_hessian(grad, x: np.ndarray, step: float = 1e-4) -> np.ndarray:
    """(D, D) symmetric Hessian of a function at ``x`` from central differences of its gradient ``grad``."""
    d = x.size
    h = np.empty((d, d))
    for i in range(d):
        e = np.zeros(d)
        e[i] = step
        h[i] = (np.asarray(grad(x + e)) - np.asarray(grad(x - e))) / (2.0 * step)
    return 0.5 * (h + h.T)


def posterior_mode(
    posterior: Posterior,
    start: np.ndarray,
    fallback_covariance: np.ndarray,
    *,
    max_steps: int = 1000,
    max_sd: float = 3.0,
) -> Laplace:
    """BFGS from ``start`` (D,) to the mode of ``posterior``; the Laplace covariance there.

    Directions the Hessian does not pin down (non-positive or tiny curvature) get the variance of
    ``fallback_covariance`` instead, and no direction's standard deviation exceeds ``max_sd`` (in the
    coordinates searched: theta, i.e. log units for positive parameters, with specimen contrasts divided by the
    spread, see the module docstring). If BFGS ends somewhere worse than ``start`` or non-finite, ``start`` and
    ``fallback_covariance`` are returned with the reason in ``status`` (and ``detail``).
    """
    t0 = time.perf_counter()
    start = np.asarray(start, dtype=float)
    value_and_grad = getattr(posterior, "value_and_grad", None)  # a Posterior's is compiled once per protocol
    if value_and_grad is None:
        value_and_grad = jax.jit(jax.value_and_grad(lambda theta: -posterior.log_prob(theta)))
    coords = NonCentred.of(posterior) or _Same()

    def objective(eta):  # -ln p(eta) = -ln p(theta(eta)) - ln|d theta / d eta|, and its gradient in eta
        theta = coords.to_theta(eta)
        value, grad = value_and_grad(jnp.asarray(theta))
        value = float(value) - float(coords.log_jacobian(eta))
        if not np.isfinite(value) or not np.all(np.isfinite(grad)):  # outside the support: a wall
            return np.inf, np.zeros_like(eta)
        return value, coords.jacobian(eta).T @ np.asarray(grad) - coords.log_jacobian_gradient(eta)

    start_eta = coords.to_eta(start)
    lp_start = -objective(start_eta)[0]
    if not np.isfinite(lp_start):  # nothing to climb from: say so rather than "ended below its start"
        status = ModeStatus.START_NOT_FINITE
        return Laplace(start, np.asarray(fallback_covariance), lp_start, 0, status, time.perf_counter() - t0)
    found = optimize.minimize(
        objective, start_eta, jac=True, method="BFGS", options={"maxiter": max_steps, "gtol": 1e-6}
    )
    mode_eta, lp_mode, steps = np.asarray(found.x), -float(found.fun), int(found.nit)
    # BFGS's own "precision loss" stop at a flat optimum is not a failure; the gradient norm says how close.
    flat = found.success or np.linalg.norm(found.jac) < 1e-2
    status, detail = (ModeStatus.SUCCESSFUL, "") if flat else (ModeStatus.STOPPED, str(found.message))
    if not np.isfinite(lp_mode) or lp_mode < lp_start:
        lp = _theta_log_prob(coords, start_eta, lp_start)
        cov = np.asarray(fallback_covariance)
        return Laplace(start, cov, lp, steps, ModeStatus.BELOW_START, time.perf_counter() - t0, detail)
    jac = coords.jacobian(mode_eta)
    hessian = finite_difference_hessian(lambda x: objective(x)[1], mode_eta)
    covariance = capped_covariance(hessian, covariance_in_eta(jac, np.asarray(fallback_covariance)), max_sd)
    lp = _theta_log_prob(coords, mode_eta, lp_mode)
    cov = _in_theta(jac, covariance)
    return Laplace(coords.to_theta(mode_eta), cov, lp, steps, status, time.perf_counter() - t0, detail)


def capped_covariance(hessian: np.ndarray, fallback_covariance: np.ndarray, max_sd: float) -> np.ndarray:
    """(D, D) inverse of the Hessian of -log posterior; a direction with no curvature (eigenvalue <= 1e-8) gets
    the fallback's variance along it, and no direction's standard deviation exceeds ``max_sd``."""
    hessian = np.array(hessian, dtype=float)
    bad = ~np.all(np.isfinite(hessian), axis=0) | ~np.all(np.isfinite(hessian), axis=1)
    hessian[bad, :] = hessian[:, bad] = 0.0  # an overflowed row: no curvature known there, use the fallback
    values, vectors = np.linalg.eigh(0.5 * (hessian + hessian.T))
    fallback = np.asarray(fallback_covariance)
    fallback_var = np.einsum("id,ij,jd->d", vectors, fallback, vectors)
    variance = np.where(values > 1e-8, 1.0 / np.where(values > 1e-8, values, 1.0), fallback_var)
    variance = np.minimum(variance, max_sd**2)
    return (vectors * variance) @ vectors.T


def refine_mode(
    batched,
    start: Laplace,
    *,
    step: float = 1e-3,
    hessian_step: float = 0.05,
    gtol: float = 1e-3,
    max_steps: int = 300,
    max_sd: float = 3.0,
    coordinates: NonCentred | None = None,
) -> Laplace:
    """The mode and Laplace covariance of the full log posterior ``batched`` (``f(thetas (n, D)) -> (n,)``,
    the sampler's own compiled function), from ``start``, the mode of the posterior with exact inputs.

    :func:`posterior_mode` optimises the posterior with the fitted driving inputs taken as exact
    (:attr:`~peano_bayes.inference.posterior.Posterior.value_and_grad`), whose gradient compiles in a third of
    the time. Where the inputs' error matters that mode is not the sampled posterior's: on the bundled PR data
    it lay 4-6 posterior standard deviations off in five parameters, log posterior 6667 against 6747, and the
    walkers started there needed about 800 steps to reach the posterior. This step moves it there: BFGS in
    coordinates whitened by ``start.covariance`` (``theta = mode + L u``), each gradient by central differences
    of step ``step`` (in those units) from one batched call of 2D + 1 points, so no other program is
    compiled; then the Hessian by central differences of values (step ``hessian_step``, 2D^2 + 1 points) and
    the covariance as in :func:`posterior_mode`, ``start.covariance`` standing in for directions without
    curvature. If the optimiser ends non-finite or below its start, ``start`` is returned with the full
    posterior's value at its mode and the reason in ``status``. ``coordinates``: :class:`NonCentred` for a
    posterior with specimen contrasts (``NonCentred.of(posterior)``; the search then moves eta, as
    :func:`posterior_mode` does), ``None`` for theta itself.
    """
    t0 = time.perf_counter()
    coords = coordinates or _Same()
    d = start.mode.size
    eta0 = coords.to_eta(start.mode)
    start_eta = covariance_in_eta(coords.jacobian(eta0), start.covariance)
    chol = np.linalg.cholesky(start_eta)
    to_eta = lambda u: eta0 + chol @ u  # noqa: E731
    eye = np.eye(d)

    def minus_log_p(etas):  # -ln p(eta) of each row
        return -np.asarray(batched(coords.to_theta(etas)), dtype=float) - coords.log_jacobian(etas)

    def objective(u):
        x = to_eta(u)
        points = np.concatenate([x[None], x + step * chol.T, x - step * chol.T])
        values = minus_log_p(points)
        if not np.all(np.isfinite(values)):  # at the support's edge: a wall the line search backs off
            return (values[0] if np.isfinite(values[0]) else np.inf), np.zeros(d)
        return values[0], (values[1 : d + 1] - values[d + 1 :]) / (2.0 * step)

    lp_start = -objective(np.zeros(d))[0]
    found = optimize.minimize(
        objective, np.zeros(d), jac=True, method="BFGS", options={"maxiter": max_steps, "gtol": gtol}
    )
    lp_mode = -float(found.fun)
    flat = found.success or np.linalg.norm(found.jac) < 10 * gtol
    status, detail = (ModeStatus.SUCCESSFUL, "") if flat else (ModeStatus.STOPPED, str(found.message))
    if not np.isfinite(lp_mode) or lp_mode < lp_start:
        lp = _theta_log_prob(coords, eta0, lp_start)
        seconds = time.perf_counter() - t0
        return dataclasses.replace(start, log_prob=lp, status=ModeStatus.BELOW_START, seconds=seconds, detail=detail)
    u0 = np.asarray(found.x)
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    h = hessian_step
    points = [u0, *(u0 + h * eye), *(u0 - h * eye)]
    for i, j in pairs:
        points += [
            u0 + h * (eye[i] + eye[j]),
            u0 + h * (eye[i] - eye[j]),
            u0 - h * (eye[i] - eye[j]),
            u0 - h * (eye[i] + eye[j]),
        ]
    values = minus_log_p(np.array([to_eta(u) for u in points]))
    mode_eta = to_eta(u0)
    mode, lp = coords.to_theta(mode_eta), _theta_log_prob(coords, mode_eta, lp_mode)
    if not np.all(np.isfinite(values)):  # a Hessian point beyond the support: keep the start's shape
        seconds = time.perf_counter() - t0
        return Laplace(mode, start.covariance, lp, int(found.nit), ModeStatus.HESSIAN_NOT_FINITE, seconds, detail)
    centre, plus, minus = values[0], values[1 : d + 1], values[d + 1 : 2 * d + 1]
    hessian_u = np.diag((plus - 2.0 * centre + minus) / h**2)
    corners = values[2 * d + 1 :].reshape(-1, 4)
    for (i, j), (pp, pm, mp, mm) in zip(pairs, corners, strict=True):
        hessian_u[i, j] = hessian_u[j, i] = (pp - pm - mp + mm) / (4.0 * h * h)
    inverse = np.linalg.inv(chol)
    covariance = capped_covariance(inverse.T @ hessian_u @ inverse, start_eta, max_sd)
    covariance = _in_theta(coords.jacobian(mode_eta), covariance)
    return Laplace(mode, covariance, lp, int(found.nit), status, time.perf_counter() - t0, detail)


__all__ = [
    "Laplace",
    "NonCentred",
    "capped_covariance",
    "covariance_in_eta",
    "finite_difference_hessian",
    "posterior_mode",
    "refine_mode",
]
