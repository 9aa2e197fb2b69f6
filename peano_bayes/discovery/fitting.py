"""Least-squares fits of members of the superset model: optimistix Levenberg-Marquardt, vmapped over
(start, mask) pairs, with a Laplace covariance from the Jacobian.

The objective is the Gaussian negative log-likelihood of the binned data with the model-free noise scale of
:mod:`.data`, written as a sum of squares: standardized residuals, the estimated error of the fitted inputs in
its N(0, 1) units (profiled, see :class:`~.model.Flat`), ``sqrt(2 log(sd / sd0))`` for the
heteroscedastic noise option, and a weak ridge ``(u - start) / RIDGE_SD`` on the free parameters (numerical
stability on flat directions, not a prior). Every function is compiled once per data shape (the solve once per
Jacobian width it is called at, :data:`JACOBIAN_WIDTHS`); masks, pinned values and data are arguments.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..inference.fit import dense_jacobian
from .model import (
    NAMES,
    DiscoveryData,
    ModelSpec,
    evaluate_flat,
    to_unconstrained,
    values,
)

#: Spread of the ridge on the unconstrained scale (a log-logit unit spans a few percent to a decade).
RIDGE_SD = 10.0
#: Levenberg-Marquardt step limit per fit.
MAX_STEPS = 60
#: Fits are solved in vmapped batches of this size (padded), so the solver compiles once.
BATCH = 4
_SOLVER = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6)


def discovery_residuals(u, data: DiscoveryData, mask, pinned, centre):
    """The Levenberg-Marquardt residual vector of one superset point ``u`` (d,) with free entries ``mask`` (d,)
    and the rest ``pinned``: every flat bin's whitened residual, the input-error estimates, a penalty for noise
    scales above the base's, and a ridge of sd :data:`RIDGE_SD` about ``centre`` on the free entries; and the
    physics solver's worst equilibrium error."""
    flat = evaluate_flat(values(u, mask, pinned), data)
    log_sd = flat.log_sd
    base_log_sd = jnp.concatenate(
        [
            jnp.where(jnp.isfinite(jnp.asarray(g.observed)), jnp.log(sd), 0.0).ravel()
            for g, sd in zip(data.groups, data.sd, strict=True)
        ]
    )
    noise_penalty = jnp.sqrt(2.0 * jnp.maximum(log_sd - base_log_sd, 0.0) + 1e-12)
    ridge = jnp.where(mask, (u - centre) / RIDGE_SD, 0.0)
    return jnp.concatenate([flat.r, flat.input_error, noise_penalty, ridge]), flat.solver_error


def _n_data_residuals(data: DiscoveryData) -> int:
    """Entries of the objective's residual vector that the data set: every flat bin, then the estimated error
    of each input error set (q per set)."""
    q = max((g.pressure_error.shape[1] for g in data.groups if g.has_input_error), default=0)
    return sum(g.observed.size for g in data.groups) + data.n_error_sets * q


#: Widths of the Levenberg-Marquardt Jacobian, in forward tangents: a batch of fits is solved at the narrowest
#: that holds its largest number of free parameters (:func:`jacobian_width`). A base model frees 12-13 of the
#: 28 superset parameters and each candidate adds 1-3, so the base and its first screening fit in 16 tangents
#: instead of 28; each width used compiles once.
JACOBIAN_WIDTHS = (16, len(NAMES))


def jacobian_width(masks) -> int:
    """The narrowest of :data:`JACOBIAN_WIDTHS` that holds every mask's free parameters (masks (m, d) bool)."""
    most = int(np.max(np.sum(masks, axis=-1)))
    return next(w for w in JACOBIAN_WIDTHS if w >= most)


def free_basis(mask, width: int):
    """(d, width) unit vectors of the free entries of ``mask`` (d,) bool, in their order, then zero columns:
    the only directions in which the objective changes (values held fixed and their ridge terms ignore u)."""
    order = jnp.argsort(jnp.logical_not(mask).astype(jnp.int32), stable=True)[:width]
    used = jnp.arange(width) < jnp.sum(mask)
    return jnp.eye(mask.shape[0])[:, order] * used


@functools.cache
def _residuals(width: int):
    """The objective's residual vector with its Jacobian materialized in ``width`` forward tangents (all of
    ``NAMES`` at the full width)."""
    basis = None if width >= len(NAMES) else (lambda u, args: free_basis(args[1], width))
    return dense_jacobian(lambda u, args: discovery_residuals(u, *args)[0], basis=basis)


@functools.partial(jax.jit, static_argnames="width")
def solve_batch(starts, masks, pinned, data: DiscoveryData, width: int = len(NAMES)):
    """Levenberg-Marquardt from each ``starts`` row (m, d) with its mask and pinned values; ``width`` at least
    every mask's number of free parameters (:func:`jacobian_width`)."""
    objective = _residuals(width)

    def one(u0, mask, pin):
        sol = optx.least_squares(objective, _SOLVER, u0, (data, mask, pin, u0), max_steps=MAX_STEPS, throw=False)
        residuals, solver_error = discovery_residuals(sol.value, data, mask, pin, u0)
        cost = 0.5 * jnp.sum(residuals**2)
        ok = jnp.isfinite(cost) & (solver_error <= 1.0)
        return sol.value, jnp.where(ok, cost, jnp.inf), sol.result == optx.RESULTS.successful

    return jax.vmap(one)(starts, masks, pinned)


@jax.jit
def jacobian_of(u, mask, pinned, data: DiscoveryData):
    """Jacobian of the objective's residual vector at ``u``, and that vector."""

    def residuals(v):
        res = discovery_residuals(v, data, mask, pinned, u)[0]
        return res, res

    return jax.jacfwd(residuals, has_aux=True)(u)


#: :func:`evaluate_flat` compiled: a superset point's flat residuals, predictions and noise scales on one data set.
pointwise = jax.jit(evaluate_flat)


@dataclass(frozen=True, eq=False)
class ModelFit:
    """A fitted member of the superset.

    **Fields:** ``spec`` the model; ``u`` (d,) unconstrained point; ``x`` (d,) values [SI], ``NAMES`` order;
    ``cost``; ``converged``; ``sd`` name -> Laplace sd [SI] of each free parameter (delta method);
    ``correlation`` (k, k) Laplace correlation of the free parameters (``spec.free_names`` order);
    ``stationary`` (set by :func:`~.workflow.fit_base`) whether a further round from this point lowered the cost
    by less than :data:`~.workflow.BASE_MIN_GAIN` although the solver had not met its step tolerance.
    """

    spec: ModelSpec
    u: np.ndarray
    x: np.ndarray
    cost: float
    converged: bool
    sd: dict
    correlation: np.ndarray
    stationary: bool = False

    @property
    def params(self) -> dict:
        return dict(zip(NAMES, (float(v) for v in self.x), strict=True))

    @property
    def n_free(self) -> int:
        return int(self.spec.mask.sum())


def _laplace(u, spec: ModelSpec, data: DiscoveryData) -> tuple[dict, np.ndarray]:
    jac = np.asarray(jacobian_of(jnp.asarray(u), jnp.asarray(spec.mask), jnp.asarray(spec.pinned), data)[0])
    free = np.flatnonzero(spec.mask)
    j = jac[:, free]
    cov_u = np.linalg.pinv(j.T @ j)
    dxdu = np.asarray(jax.jacfwd(lambda v: values(v, spec.mask, spec.pinned))(jnp.asarray(u))).diagonal()[free]
    cov_x = cov_u * np.outer(dxdu, dxdu)
    sd = np.sqrt(np.maximum(np.diag(cov_x), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_u / np.sqrt(np.outer(np.diag(cov_u), np.diag(cov_u)))
    return {NAMES[i]: float(s) for i, s in zip(free, sd, strict=True)}, np.nan_to_num(corr)


def fit_models(specs, starts, data: DiscoveryData) -> list[ModelFit | None]:
    """Fit each ``specs[i]`` from ``starts[i]`` (values (d,) [SI]) in vmapped solves of :data:`BATCH` fits;
    ``None`` where the fit failed (non-finite, or the physics solver missed its tolerance)."""
    n = len(specs)
    pad = -n % BATCH  # one batch size, one compilation: pad with copies of the last fit
    specs, starts = list(specs) + [specs[-1]] * pad, list(starts) + [starts[-1]] * pad
    u0 = np.stack([to_unconstrained(s) for s in starts])
    masks = np.stack([s.mask for s in specs])
    pinned = np.stack([s.pinned for s in specs])
    # Batch by batch: a (BATCH, d) shape every call, where one call on all n would compile once per distinct n.
    solved = [
        solve_batch(
            *(jnp.asarray(a[i : i + BATCH]) for a in (u0, masks, pinned)),
            data,
            width=jacobian_width(masks[i : i + BATCH]),
        )
        for i in range(0, len(specs), BATCH)
    ]
    us, costs, converged = (np.concatenate([np.asarray(b[k]) for b in solved])[:n] for k in range(3))
    out = []
    for spec, u, cost, conv in zip(specs[:n], us, costs, converged, strict=True):
        if not np.isfinite(cost):
            out.append(None)
            continue
        sd, corr = _laplace(u, spec, data)
        x = np.asarray(values(jnp.asarray(u), spec.mask, spec.pinned))
        out.append(ModelFit(spec, u, x, float(cost), bool(conv), sd, corr))
    return out


@dataclass(frozen=True, eq=False)
class Evaluation:
    """A fit on some data, per flat bin (n,): ``loglik``, standardized residual ``r``, ``predicted`` signal and
    ``error`` observed minus predicted [signal unit]; ``solver_ok`` whether every simulation met its tolerance;
    ``input_error`` the estimated correction of the fitted inputs (:class:`~.model.Flat`), from the fitted runs.
    """

    loglik: np.ndarray
    r: np.ndarray
    predicted: np.ndarray
    error: np.ndarray
    solver_ok: bool
    input_error: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def cost(self) -> float:
        """Sum of squares the data set in the fit's objective: the standardized residuals and the input
        correction (what :func:`gauss_newton_gain` compares against)."""
        return float(np.sum(self.r**2) + np.sum(self.input_error**2))


def gauss_newton_gain(spec: ModelSpec, start, data: DiscoveryData, current_cost: float) -> float:
    """Decrease of the data's sum of squares (standardized residuals and the input correction,
    :attr:`Evaluation.cost`), from ``current_cost`` (the current model's), that
    one Gauss-Newton step of ``spec`` from ``start`` (values (d,) [SI], near the new effect's off values)
    promises: ``current_cost - (|r|^2 - |P r|^2)`` with ``r`` the residuals at ``start`` and ``P`` the projection
    onto the span of the free parameters' Jacobian columns (a score statistic, used to rank candidates)."""
    u = to_unconstrained(start)
    jac, res = jacobian_of(jnp.asarray(u), jnp.asarray(spec.mask), jnp.asarray(spec.pinned), data)
    n = _n_data_residuals(data)
    jac, r = np.asarray(jac), np.asarray(res)[:n]
    j = jac[: r.size, spec.mask]
    if not (np.all(np.isfinite(j)) and np.all(np.isfinite(r))):
        return -np.inf
    step, *_ = np.linalg.lstsq(j, r, rcond=1e-10)
    return float(current_cost - (np.sum(r**2) - np.sum((j @ step) ** 2)))


def matched_directions(fit: ModelFit, xs, split) -> np.ndarray:
    """(k, n) over ``split``'s fitted bins, one row per point of ``xs`` (k points, values (d,) [SI]; e.g. effects
    switched on at their screening starts): the standardized change of the predictions when ``fit``'s point moves
    there, with the span of ``fit``'s own Jacobian columns (its free parameters, on the fitted bins) projected out:
    what a refit of ``fit`` cannot absorb, the direction a one-step score test of that move reads the residuals
    along. NaN rows where a simulation is not finite, all NaN where the Jacobian is not. ``fit``'s residuals and
    Jacobian are evaluated once for all points, with the programs :func:`evaluate` and the Laplace step compiled."""
    n = split.n_fit_bins
    base = np.asarray(pointwise(jnp.asarray(fit.x), split.both).r)[:n]
    args = (jnp.asarray(fit.u), jnp.asarray(fit.spec.mask), jnp.asarray(fit.spec.pinned), split.fit)
    j = np.asarray(jacobian_of(*args)[0])[:n][:, fit.spec.mask]
    out = np.full((len(xs), n), np.nan)
    if not np.all(np.isfinite(j)):
        return out
    for row, x in enumerate(xs):
        d = base - np.asarray(pointwise(jnp.asarray(x, dtype=float), split.both).r)[:n]  # (with - at the fit) / sd
        if np.all(np.isfinite(d)):
            out[row] = d - j @ np.linalg.lstsq(j, d, rcond=1e-10)[0]
    return out


def evaluate(fit: ModelFit, split) -> tuple[Evaluation, Evaluation]:
    """Evaluate ``fit`` on the fitted and on the held-out runs of a :class:`~.data.SplitData`."""
    flat = pointwise(jnp.asarray(fit.x), split.both)
    loglik, r, predicted, error = (np.asarray(a) for a in (flat.loglik, flat.r, flat.predicted, flat.error))
    n, ok, a = split.n_fit_bins, bool(flat.solver_error <= 1.0), np.asarray(flat.input_error)
    part = lambda s: Evaluation(loglik[s], r[s], predicted[s], error[s], ok, a)  # noqa: E731
    return part(slice(None, n)), part(slice(n, None))


__all__ = [
    "BATCH",
    "Evaluation",
    "MAX_STEPS",
    "ModelFit",
    "RIDGE_SD",
    "discovery_residuals",
    "evaluate",
    "fit_models",
    "gauss_newton_gain",
    "jacobian_of",
    "matched_directions",
    "pointwise",
    "solve_batch",
]
