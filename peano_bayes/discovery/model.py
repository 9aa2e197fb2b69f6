"""The discovery model: one superset of every library effect, with inactive effects pinned to their ``off`` values.

All candidate models are the superset :data:`SUPERSET_CONFIG` with a 0/1 mask over its parameters: a masked
parameter takes its ``off`` (or ``hold``) value whatever the optimizer proposes, so one compiled function serves
the base model and every candidate, and the data enter as arguments (a pytree), so it serves every dataset of the
same shape too.

Parameters are fitted on an unconstrained scale ``u``: ``log``-``logit`` between the bounds of positive
parameters (a zero lower bound is replaced by ``1e-9`` times the upper), ``tanh`` between the bounds of signed
ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..effects import BASELINE_PARAMETERS, EXTRA_PARAMETERS, LIBRARY, check_effects, parameter_spec, superset_config
from ..inference.likelihood import SOLVER_TOLERANCE, input_error_jacobian, predict
from ..inference.reduce import OBSERVED, SPECIMEN_OFFSET, RunGroup
from ..physics import Geometry

#: Every element any registered effect needs, switched on (:func:`~peano_bayes.effects.superset_config`, read
#: when this module is first imported); inactive ones are pinned at their off values.
SUPERSET_CONFIG = superset_config()
#: Parameter order of every vector in this package.
NAMES: tuple[str, ...] = SUPERSET_CONFIG.parameter_names() + tuple(EXTRA_PARAMETERS)
#: Free in every model: the effective length fraction of the contractile unit.
ALWAYS_FREE = ("length_fraction",)
#: The default base model: Veale's elastic model, the ideal Peano geometry with tensile compliance (without it
#: the ideal model has an infinite blocking force, and a load cycle that stretches the muscle cannot be
#: simulated) and bending stiffness (without it the step response's solver fails at an open inlet).
DEFAULT_BASE = ("tensile_stiffness", "bending_stiffness")
_ZERO_FLOOR = 1e-9
FORCE_TESTS = frozenset(t for t, (signal, _) in OBSERVED.items() if signal == "force_n")


def _bounds(name: str) -> tuple[float, float, bool]:
    low, high = parameter_spec(name).bounds
    signed = low < 0
    if not signed and low == 0:
        low = high * _ZERO_FLOOR
    return low, high, signed


_LOW, _HIGH, _SIGNED = (np.array(v) for v in zip(*(_bounds(n) for n in NAMES), strict=True))


def to_values(u):
    """Parameter values [SI] (..., d) from unconstrained ``u`` (..., d)."""
    u = jnp.asarray(u)
    s = jax.nn.sigmoid(u)
    positive = jnp.exp(jnp.log(_LOW) + (jnp.log(_HIGH) - jnp.log(_LOW)) * s)
    signed = 0.5 * (_LOW + _HIGH) + 0.5 * (_HIGH - _LOW) * jnp.tanh(u)
    return jnp.where(_SIGNED, signed, positive)


def to_unconstrained(values) -> np.ndarray:
    """Inverse of :func:`to_values`; values are clipped just inside their bounds."""
    x = np.clip(np.asarray(values, dtype=float), _LOW * (1 + 1e-9), _HIGH * (1 - 1e-9) + (_SIGNED * 2e-9 * _HIGH))
    with np.errstate(invalid="ignore", divide="ignore"):  # the positive branch of signed parameters is unused
        s = (np.log(np.abs(x)) - np.log(_LOW)) / (np.log(_HIGH) - np.log(_LOW))
    s = np.clip(s, 1e-9, 1 - 1e-9)
    positive = np.log(s / (1 - s))
    t = np.clip((x - 0.5 * (_LOW + _HIGH)) / (0.5 * (_HIGH - _LOW)), -1 + 1e-9, 1 - 1e-9)
    return np.where(_SIGNED, np.arctanh(t), positive)


@dataclass(frozen=True)
class ModelSpec:
    """A member of the superset family: which effects are active, and the values of every parameter."""

    active: tuple[str, ...]
    mask: np.ndarray  # (d,) bool, free parameters
    pinned: np.ndarray  # (d,) values of the parameters that are not free

    @property
    def free_names(self) -> tuple[str, ...]:
        return tuple(n for n, m in zip(NAMES, self.mask, strict=True) if m)


def model_spec(active, base_values: dict | None = None) -> ModelSpec:
    """The model with effects ``active`` on; parameters that are not free take their ``off`` / ``hold`` value
    from the inactive effects, else ``base_values``, else nominal."""
    active = check_effects(active)
    free = set(ALWAYS_FREE)
    for name in active:
        free |= set(LIBRARY[name].params)
    pinned = {n: parameter_spec(n).nominal for n in NAMES}
    pinned.update(base_values or {})
    for effect in LIBRARY.values():
        if effect.name not in active:
            pinned.update(effect.hold)
            pinned.update(effect.off)
    mask = np.array([n in free for n in NAMES])
    return ModelSpec(active, mask, np.array([pinned[n] for n in NAMES], dtype=float))


def values(u, mask, pinned):
    """Parameter values (d,) of unconstrained ``u`` with the masked-out ones pinned."""
    return jnp.where(mask, to_values(u), pinned)


@dataclass(frozen=True, eq=False)
class DiscoveryData:
    """Binned runs of one specimen, as a pytree (one compiled model serves every dataset of the same shape).

    **Fields:** ``groups`` run groups whose ``specimen_index`` is the run's cycle index (0 = first run of its
    condition), ``sd`` per group (r, m) the noise sd of each bin mean [signal unit], ``session`` per group
    (r, m) each bin's time in the specimen's session scaled to [-1, 1] (the session baseline's argument),
    ``geometry``. The fitted inputs' error (groups with :attr:`RunGroup.has_input_error`, whose rows carry the
    (q, L) error columns of their condition's shared pressure): ``error_set`` per group (r,) int, the input
    error set of each run (-1: none), ``informs`` per group (r,) 1 where the run's residuals estimate its set's
    error (fitted runs) and 0 where they only take the estimate (held-out runs), ``n_error_sets`` the number of
    sets (conditions whose shared input carries an error; 0: inputs taken as exact). Held-out runs are
    therefore evaluated together with the fitted ones (:attr:`~.data.SplitData.both`); alone, nothing informs
    their estimate and they are predicted at the fitted input itself.
    """

    groups: tuple[RunGroup, ...]
    sd: tuple
    session: tuple
    n_cycles: int
    geometry: Geometry
    error_set: tuple = ()
    informs: tuple = ()
    n_error_sets: int = 0


jax.tree_util.register_dataclass(
    DiscoveryData,
    data_fields=["groups", "sd", "session", "error_set", "informs"],
    meta_fields=["n_cycles", "geometry", "n_error_sets"],
)


def _legendre(s):
    """Legendre polynomials of degree 1, 2, 3 of ``s`` in [-1, 1]."""
    return s, 0.5 * (3.0 * s**2 - 1.0), 0.5 * (5.0 * s**3 - 3.0 * s)


def predictions(x, data: DiscoveryData):
    """Per group: predicted signal (r, m) at the fitted inputs, bin noise sd (r, m), solver error (r,) and the
    prediction's derivative (r, q, m) along each column of its inputs' error (``None`` for groups without, or
    when ``data`` has no input error sets), at values ``x`` (d,). Every run of discovery data is its own
    simulated row, so the derivative has one row per run."""
    params = dict(zip(NAMES, x, strict=True))
    a = params.pop("cyclic_softening_fraction")
    offset, gain = params.pop("sensor_offset_n"), params.pop("sensor_gain")
    slope = params.pop("noise_slope_per_n")
    baseline = [params.pop(name) for name in BASELINE_PARAMETERS]
    params[SPECIMEN_OFFSET] = jnp.log1p(a * jnp.exp(-jnp.arange(data.n_cycles, dtype=float)))
    out = []
    for group, sd, session in zip(data.groups, data.sd, data.session, strict=True):
        jac = None
        if group.has_input_error and data.n_error_sets:
            predicted, error, jac = input_error_jacobian(params, group, config=SUPERSET_CONFIG, geometry=data.geometry)
        else:
            predicted, error = predict(params, group, config=SUPERSET_CONFIG, geometry=data.geometry)
        if group.test in FORCE_TESTS:
            drift = sum(c * p for c, p in zip(baseline, _legendre(jnp.asarray(session)), strict=True))
            predicted = gain * predicted + offset + drift
            jac = None if jac is None else gain * jac
            sd = sd * (1.0 + slope * jnp.abs(predicted))
        out.append((predicted, sd, error, jac))
    return out


def _input_error_estimate(data: DiscoveryData, parts):
    """The most probable correction ``a`` (S, q) of each input error set's fitted input, in units of its error
    columns (the input is taken as the fitted one plus ``B a``, ``a ~ N(0, I_q)``), given the informing runs'
    residuals: ``a = A^-1 b``, ``A = I + sum J^T W J``, ``b = sum J^T W e`` over the informing runs of the set
    (``W`` inverse bin variances, ``e`` observed minus predicted at the fitted input). ``parts``: per group
    ``(predicted, sd, solver error, jac)`` as from :func:`predictions`."""
    q = max((jac.shape[1] for *_, jac in parts if jac is not None), default=0)
    gram = jnp.zeros((data.n_error_sets, q, q))
    proj = jnp.zeros((data.n_error_sets, q))
    rows = zip(data.groups, parts, data.error_set, data.informs, strict=True)
    for group, (predicted, sd, _, jac), labels, informs in rows:
        if jac is None:
            continue
        observed = jnp.asarray(group.observed)
        measured = jnp.isfinite(observed)
        weight = jnp.where(measured, 1.0 / sd**2, 0.0) * jnp.asarray(informs)[:, None]
        residual = jnp.where(measured, observed - predicted, 0.0)
        gram = gram.at[labels].add(jnp.einsum("rqm,rm,rpm->rqp", jac, weight, jac))
        proj = proj.at[labels].add(jnp.einsum("rqm,rm,rm->rq", jac, weight, residual))
    return jnp.linalg.solve(jnp.eye(q) + gram, proj[..., None])[..., 0]


_LOG_2PI = math.log(2 * math.pi)


class Flat(NamedTuple):
    """A model evaluated on every flat bin (n,) of a :class:`DiscoveryData`, in its residual order.

    ``r`` standardized residual and ``log_sd`` log bin noise sd (both 0 where unmeasured); ``predicted`` signal
    and ``error`` observed minus predicted [signal unit] (NaN where unmeasured); ``loglik`` Gaussian
    log-likelihood (0 where unmeasured); ``solver_error`` () the largest solver error over all runs, in units
    of its tolerance; ``input_error`` (S q,) the estimated correction of each input error set's fitted input,
    in its N(0, 1) units (:func:`_input_error_estimate`; empty without).

    Where runs carry their fitted inputs' error, predictions are made at the estimated input (the prediction
    plus ``J a``), so residuals are what is left after the input's own error, and the estimate's cost
    ``|a|^2 / 2`` is spread evenly over the informing runs' measured bins of ``loglik`` (so the fitted runs'
    sum is the profile log-likelihood over ``a``). This is the profile of the inference's likelihood, which
    integrates ``a`` out exactly: the quadratic forms agree, and the profile leaves out ``ln det A / 2``, which
    depends on the parameters only through ``J``. Held-out runs are predicted at the estimate, without its own
    uncertainty ``J A^-1 J^T``.
    """

    r: jax.Array
    log_sd: jax.Array
    predicted: jax.Array
    error: jax.Array
    loglik: jax.Array
    solver_error: jax.Array
    input_error: jax.Array


def evaluate_flat(x, data: DiscoveryData) -> Flat:
    """Everything the fits and their scores read, from one simulation of every run at values ``x`` (d,)."""
    parts = predictions(x, data)
    estimate = _input_error_estimate(data, parts) if data.n_error_sets else jnp.zeros((0, 0))
    # The cost |a|^2 / 2 of each set's estimate, per informing measured bin of that set.
    bins = jnp.zeros(data.n_error_sets)
    for (*_, jac), group, labels, informs in zip(parts, data.groups, data.error_set, data.informs, strict=True):
        if jac is not None:
            bins = bins.at[labels].add(jnp.sum(jnp.isfinite(jnp.asarray(group.observed)), axis=1) * informs)
    per_bin = 0.5 * jnp.sum(estimate**2, axis=1) / jnp.maximum(bins, 1.0) if data.n_error_sets else bins
    rs, logs, preds, errors, measured_all, costs, errs = [], [], [], [], [], [], []
    for i, (group, (predicted, sd, error, jac)) in enumerate(zip(data.groups, parts, strict=True)):
        observed = jnp.asarray(group.observed)
        measured = jnp.isfinite(observed)
        cost = jnp.zeros(observed.shape)
        if jac is not None:
            labels = jnp.asarray(data.error_set[i])
            predicted = predicted + jnp.einsum("rqm,rq->rm", jac, estimate[labels])
            cost = jnp.broadcast_to((per_bin[labels] * jnp.asarray(data.informs[i]))[:, None], observed.shape)
        rs.append(jnp.where(measured, (jnp.where(measured, observed, 0.0) - predicted) / sd, 0.0).ravel())
        logs.append(jnp.where(measured, jnp.log(sd), 0.0).ravel())
        preds.append(predicted.ravel())
        errors.append((observed - predicted).ravel())
        measured_all.append(measured.ravel())
        costs.append(cost.ravel())
        errs.append(jnp.max(error / SOLVER_TOLERANCE[group.test]))
    r, log_sd, measured = jnp.concatenate(rs), jnp.concatenate(logs), jnp.concatenate(measured_all)
    loglik = jnp.where(measured, -0.5 * r**2 - log_sd - 0.5 * _LOG_2PI - jnp.concatenate(costs), 0.0)
    return Flat(
        r, log_sd, jnp.concatenate(preds), jnp.concatenate(errors), loglik, jnp.max(jnp.stack(errs)), estimate.ravel()
    )


__all__ = [
    "ALWAYS_FREE",
    "DEFAULT_BASE",
    "DiscoveryData",
    "ModelSpec",
    "NAMES",
    "SUPERSET_CONFIG",
    "Flat",
    "evaluate_flat",
    "model_spec",
    "predictions",
    "to_unconstrained",
    "to_values",
    "values",
]
