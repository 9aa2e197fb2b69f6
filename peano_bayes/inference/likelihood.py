"""Likelihood of rig data under the physics model: predictions and the pointwise log-likelihood of the reduced
data (:mod:`~peano_bayes.inference.reduce`).

Knows nothing about files (it takes a validated :class:`~peano_bayes.data.Dataset`) or priors. The physics is
called through the four test simulations; runs of one test are stacked and simulated in one ``vmap``.

**The fitted inputs' own error** (tests in :data:`INPUT_ERROR_TESTS`): the fit of a ramp from noisy samples is
itself off by a random offset and slope, and the runs that share a simulation share that error, so it shows as
one smooth residual common to all repeats, which a likelihood of independent bins reads as signal. Given the
fit's segments, that error is ``B a`` with ``a ~ N(0, I)`` (:func:`~peano_bayes.inference.denoise.fit_error_basis`;
for repeats averaged, the exact low-rank factor of their mean's covariance). Linearised through the simulation
(``J = d prediction / d a``, one forward-mode derivative per column), it adds ``J J^T`` to the covariance of the
bins of every run sharing the simulation; :func:`group_log_likelihood` integrates ``a`` out exactly (Woodbury
identity, a q x q solve per simulated input; q = 2 per ramp and 1 per hold of each fitted input, a load cycle's
strain and pressure each with their own columns). Its Jacobian can be computed once, at a point, and held
(:func:`linearise_input_error`; ``fit`` does so at the exact-input mode).

**Residuals with structure (AR(1) from bin to bin):** the bins are independent given the model, unless a test's
group carries ``residual_lag1`` (:func:`with_residual_lag1`): then each run's standardized residuals are a
stationary AR(1) sequence in bin order with that lag-1 correlation (each bin's marginal sd is still its noise sd),
and each bin's log-likelihood is its density given the bin before it (:func:`ar1_innovations`; a chain starts
afresh at each segment of the commanded inputs, where a misfit may jump, and after an unmeasured bin). Whitening by
that filter is linear, so the inputs' error is integrated as above on the whitened residuals and error columns.
``fit`` sets it only for a test whose residuals at the mode fail the check of
:func:`~peano_bayes.inference.fit.residual_correlation`: a model that cannot take the data's shape leaves a smooth
misfit that independent bins would count as hundreds of independent pieces of evidence.
"""

from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..physics import DEFAULT_CONFIG, PAPER_GEOMETRY, Geometry, ModelConfig, simulate
from .reduce import NOISE_PARAMETERS, OBSERVED, SPECIMEN_OFFSET, SPECIMEN_SCALED, Observations, RunGroup

#: Integration substeps per (binned) sample interval of the step test.
STEP_SUBSTEPS = 2
#: Largest solver equilibrium error (``max_residual`` of a simulation) accepted, by test: [m] where strain is
#: imposed, [N] where force is (the step's inertial residual sits near 1e-5 N when converged).
SOLVER_TOLERANCE = MappingProxyType({"load_cycle": 1e-6, "blocking": 1e-6, "stroke": 1e-2, "step": 1e-2})
#: Degrees of freedom of the Student-t option.
STUDENT_T_DOF = 4.0


# A pytree (arrays as leaves, ``test`` and ``keys`` as structure): groups can be jit arguments, so one compiled
# log posterior serves every dataset of the same protocol (see :meth:`Posterior.with_observations`).
jax.tree_util.register_dataclass(
    RunGroup,
    data_fields=[
        "specimen_index",
        "time_s",
        "strain",
        "pressure_pa",
        "supply_pa",
        "load_n",
        "observed",
        "counts",
        "shared",
        "bin_time_s",
        "strain_error",
        "pressure_error",
        "bin_nodes",
        "added_compliance_m_per_n",
        "input_jacobian",
        "residual_lag1",
        "segment_start",
    ],
    meta_fields=["test", "keys"],
)


def simulate_test(test: str, params, time_s, strain, pressure_pa, supply_pa, load_n, config, geometry):
    """The observed signal of one run (m,) and the solver's equilibrium error."""
    kw = dict(config=config, geometry=geometry)
    if test == "load_cycle":
        result = simulate.simulate_load_cycle(params, simulate.LoadCycle(time_s, strain, pressure_pa), **kw)
        return result.force_n, result.max_residual
    if test == "blocking":
        result = simulate.simulate_blocking(params, simulate.Blocking(time_s, pressure_pa), **kw)
        return result.force_n, result.max_residual
    if test == "stroke":
        result = simulate.simulate_stroke(params, simulate.Stroke(time_s, pressure_pa, load_n), **kw)
        return result.strain, result.max_residual
    result = simulate.simulate_step(params, simulate.Step(time_s, supply_pa, load_n, STEP_SUBSTEPS), **kw)
    return result.strain, result.max_residual


def _per_specimen(params):
    """``(model, offset)``: ``params`` without the specimen offsets, and the offsets as a mapping name ->
    (n_specimens,) log factor (or ``None``)."""
    offset = params.get(SPECIMEN_OFFSET)
    model = {k: v for k, v in params.items() if k != SPECIMEN_OFFSET}
    if offset is not None and not isinstance(offset, dict):
        offset = {k: offset for k in SPECIMEN_SCALED if k in model}
    return model, offset


def predict_sets(params, group: RunGroup, strain, pressure_pa, config: ModelConfig, geometry: Geometry):
    """Predicted bin means (u, m) of every simulated input row of ``group``, driven by ``strain`` and
    ``pressure_pa`` (u, p m), and each row's solver error (u,)."""
    model, offset = _per_specimen(params)

    def one(specimen, time_s, strain, pressure, supply, load, added):
        p = {k: (v[specimen] if jnp.ndim(v) else v) for k, v in model.items()}
        if offset is not None:
            p = {k: v * jnp.exp(offset[k][specimen]) if k in offset else v for k, v in p.items()}
        if config.mount:  # a known added mount in series with the specimen's own
            p["mount_compliance_m_per_n"] = p["mount_compliance_m_per_n"] + added
        return simulate_test(group.test, p, time_s, strain, pressure, supply, load, config, geometry)

    supply = group.supply_pa if group.supply_pa is not None else pressure_pa
    added = group.added_compliance_m_per_n
    predicted, error = jax.vmap(one)(
        jnp.asarray(group.specimen_index),
        jnp.asarray(group.time_s),
        strain,
        pressure_pa,
        jnp.asarray(supply),
        jnp.asarray(group.load_n),
        jnp.zeros(len(group.load_n)) if added is None else jnp.asarray(added),
    )
    return group.per_bin(predicted).mean(axis=-1), error


#: :func:`predict_sets` behind one stable ``jax.jit``: every program that contains a prediction (least
#: squares, its Jacobian, the mode search, the batched log posterior, the pointwise values and predictive
#: draws) reuses its traced program, and differentiates or vectorizes that program instead of running the
#: physics' Python again (tracing it costs seconds). The program is kept per configuration, geometry, run
#: group structure (test, run keys) and the names, shapes and dtypes of the parameters.
_traced_predict_sets = jax.jit(predict_sets, static_argnums=(4, 5))


def _sets_function(geometry: Geometry):
    """:data:`_traced_predict_sets`, or :func:`predict_sets` itself for a geometry that cannot be a static
    argument (array-valued fields are allowed, but not hashable)."""
    try:
        hash(geometry)
    except TypeError:
        return predict_sets
    return _traced_predict_sets


def predict(params, group: RunGroup, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY):
    """Predicted observed signal (r, m) of every run in ``group`` and each run's solver error (r,).

    ``params``: model parameters by name, each a scalar (shared) or an array of shape (n_specimens,). With
    ``specimen_log_offset`` (n_specimens,) the :data:`SPECIMEN_SCALED` parameters of specimen ``s`` are
    multiplied by ``exp(specimen_log_offset[s])`` (one stiffness factor per specimen); with a mapping
    ``{name: (n_specimens,)}`` each named parameter of specimen ``s`` is multiplied by its own
    ``exp(offset[name][s])`` (the hierarchical model of :class:`~peano_bayes.inference.posterior.Posterior`).
    """
    strain, pressure = jnp.asarray(group.strain), jnp.asarray(group.pressure_pa)
    predicted, error = _sets_function(geometry)(params, _as_simulated(group), strain, pressure, config, geometry)
    shared = jnp.asarray(group.shared)
    return predicted[shared], error[shared]


def _as_simulated(group: RunGroup) -> RunGroup:
    """``group`` without what only the likelihood reads (its held Jacobian and AR(1) residual correlation), so a
    linearised or AR(1) group reuses the compiled prediction of the plain one."""
    if group.input_jacobian is None and group.residual_lag1 is None:
        return group
    return replace(group, input_jacobian=None, residual_lag1=None)


@eqx.filter_jit
def input_error_jacobian(
    params, group: RunGroup, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
):
    """``(predicted (u, m), solver error (u,), J (u, q, m))``: the prediction of every simulated input row and
    its derivative along each column of the fitted inputs' error (:attr:`RunGroup.strain_error`,
    :attr:`RunGroup.pressure_error`), by forward-mode differentiation of the simulation. Compiled once per
    protocol (shapes) and configuration; inside a traced function it is inlined."""
    strain, pressure = jnp.asarray(group.strain), jnp.asarray(group.pressure_pa)
    sets = _sets_function(geometry)
    fn = lambda s, p: sets(params, group, s, p, config, geometry)  # noqa: E731

    def along(ds, dp):
        (predicted, error), (tangent, _) = jax.jvp(fn, (strain, pressure), (ds, dp))
        return predicted, error, tangent

    d_strain, d_pressure = _error_columns(group)
    predicted, error, jac = jax.vmap(along, in_axes=(1, 1), out_axes=(None, None, 1))(d_strain, d_pressure)
    return predicted, error, jac


def _error_columns(group: RunGroup):
    """``(strain, pressure)`` (u, q, L) error columns of ``group``'s fitted inputs (strain zeros where the test
    has no strain error); JAX arrays, traced or not."""
    d_pressure = jnp.asarray(group.pressure_error)
    return (jnp.zeros_like(d_pressure) if group.strain_error is None else jnp.asarray(group.strain_error)), d_pressure


#: Step [sd of the fitted inputs' error] of the central differences that :func:`linearise_input_error` takes along
#: each error column: deep in the linear range, and far above the simulation's solver error.
LINEARISATION_STEP = 1e-2


def linearise_input_error(params, observations: Observations, *, config: ModelConfig = DEFAULT_CONFIG) -> Observations:
    """``observations`` whose groups carry the fitted inputs' error Jacobian ``J`` (u, q, m) at ``params``
    (:attr:`RunGroup.input_jacobian`), so the likelihood uses that ``J`` instead of differentiating the
    simulation at every evaluation (which costs one forward-mode derivative per error column). ``J`` is taken by
    central differences (:data:`LINEARISATION_STEP`) of the prediction, 2 q calls of the program that every fit
    compiles anyway, rather than by a forward-mode program of its own, whose compilation cost more than the
    whole linearisation saves on a short fit. A group whose ``J`` is not finite at ``params`` (a simulation
    that fails there) keeps computing it at every evaluation."""
    model = _model_parameters(params)
    sets, geometry, h = _sets_function(observations.geometry), observations.geometry, LINEARISATION_STEP
    groups = []
    for group in observations.groups:
        if group.has_input_error:
            plain = _as_simulated(group)
            strain, pressure = np.asarray(group.strain), np.asarray(group.pressure_pa)
            columns = []
            for ds, dp in zip(*(np.swapaxes(np.asarray(d), 0, 1) for d in _error_columns(group)), strict=True):
                up = sets(model, plain, strain + h * ds, pressure + h * dp, config, geometry)[0]
                down = sets(model, plain, strain - h * ds, pressure - h * dp, config, geometry)[0]
                columns.append((np.asarray(up) - np.asarray(down)) / (2.0 * h))
            jac = np.stack(columns, axis=1)
            if np.all(np.isfinite(jac)):
                group = replace(group, input_jacobian=jac)
        groups.append(group)
    return replace(observations, groups=tuple(groups))


def _input_error_correction(residual, weight, per_run, shared, n_sets: int):
    """Per simulated row (u,): the change of the log-likelihood of its runs' residuals when the fitted inputs'
    error ``J a``, ``a ~ N(0, I_q)``, is integrated out, ``b^T A^-1 b / 2 - ln det A / 2`` with
    ``A = I + sum_runs J^T W J`` and ``b = sum_runs J^T W r`` (Woodbury; ``W`` = ``weight`` (r, m), the inverse
    bin variances, zero where unmeasured; ``residual`` (r, m); ``per_run`` (r, q, m), each run's ``J``; its
    simulated row ``shared`` (r,)). Residuals and ``J`` whitened by the same linear map, with weight 1, give the
    integral under that map's covariance."""
    gram = jnp.einsum("rqm,rm,rpm->rqp", per_run, weight, per_run)
    proj = jnp.einsum("rqm,rm,rm->rq", per_run, weight, residual)
    gram = jax.ops.segment_sum(gram, shared, num_segments=n_sets)
    proj = jax.ops.segment_sum(proj, shared, num_segments=n_sets)
    a = jnp.eye(per_run.shape[1]) + gram
    chol = jnp.linalg.cholesky(a)
    solved = jax.scipy.linalg.cho_solve((chol, True), proj[..., None])[..., 0]
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    return 0.5 * jnp.sum(proj * solved, axis=-1) - 0.5 * log_det


def ar1_innovations(x, measured, lag1, restart=None):
    """Whiten ``x`` (r, m) or (r, q, m), bins of each run in time order along the last axis, under AR(1)
    correlation ``lag1`` from bin to bin: ``(x_t - lag1 x_(t-1)) / sqrt(1 - lag1^2)`` where bin ``t - 1`` of the
    run is measured too, else ``x_t``. A run's first bin, a bin after an unmeasured one and a bin where
    ``restart`` (r, m) bool is set (the start of a segment of the commanded inputs) start afresh: the chain
    before them is taken as independent of them. ``measured`` (r, m) bool. Returns ``(innovations,
    factor)``, ``factor`` (r, m) the sd of each innovation over that of its bin: ``sqrt(1 - lag1^2)`` or 1. For
    standardized residuals (unit marginal variance, AR(1) correlation) the innovations are independent standard
    normals, and the Jacobian of the map is ``1 / prod(factor)``."""
    paired = jnp.concatenate([jnp.zeros_like(measured[:, :1]), measured[:, 1:] & measured[:, :-1]], axis=1)
    if restart is not None:
        paired = paired & ~jnp.asarray(restart, dtype=bool)
    factor = jnp.where(paired, jnp.sqrt(1.0 - lag1**2), 1.0)
    expand = lambda a: a.reshape(a.shape[:1] + (1,) * (x.ndim - 2) + a.shape[1:])  # noqa: E731
    earlier = jnp.concatenate([jnp.zeros_like(x[..., :1]), x[..., :-1]], axis=-1)
    return (x - expand(jnp.where(paired, lag1, 0.0)) * earlier) / expand(factor), factor


def _log_density(residual, scale, family: str):
    if family == "gaussian":
        return -0.5 * (residual / scale) ** 2 - jnp.log(scale) - 0.5 * jnp.log(2.0 * jnp.pi)
    nu = STUDENT_T_DOF
    return (
        jax.scipy.special.gammaln(0.5 * (nu + 1.0))
        - jax.scipy.special.gammaln(0.5 * nu)
        - 0.5 * jnp.log(nu * jnp.pi)
        - jnp.log(scale)
        - 0.5 * (nu + 1.0) * jnp.log1p((residual / scale) ** 2 / nu)
    )


def bin_noise_sd(noise_sd, group: RunGroup):
    """(r, m) sd of each bin mean of ``group``: ``noise_sd`` of one raw sample over sqrt(samples in the bin)."""
    return noise_sd / jnp.sqrt(jnp.maximum(jnp.asarray(group.counts), 1.0))


def _model_parameters(params) -> dict:
    """``params`` without the noise scales and the specimen spread (what the simulation takes)."""
    return {k: v for k, v in params.items() if k not in NOISE_PARAMETERS and k != "specimen_log_sd"}


def group_log_likelihood(
    params,
    group: RunGroup,
    *,
    config: ModelConfig = DEFAULT_CONFIG,
    geometry: Geometry = PAPER_GEOMETRY,
    family: str = "gaussian",
    solver_tolerance=SOLVER_TOLERANCE,
):
    """``(predicted, scale, ll)``, each (r, m), of one run group: the prediction, each bin's noise sd and its
    log-likelihood (see :func:`pointwise_log_likelihood`). Where the group carries its fitted inputs' error
    (:attr:`RunGroup.has_input_error`), the log-likelihood of each simulated input's runs is their joint
    density with that error integrated out, apportioned evenly over their measured bins (so per-bin values
    are exact only in their sum over those runs). The Student-t family treats the fitted inputs as exact (the
    integral is Gaussian)."""
    if family not in ("gaussian", "student_t"):
        raise ValueError(f"family must be 'gaussian' or 'student_t', got {family!r}")
    model = _model_parameters(params)
    scale = bin_noise_sd(params[OBSERVED[group.test][1]], group)
    observed = jnp.asarray(group.observed)
    measured = jnp.isfinite(observed)
    with_input_error = group.has_input_error and family == "gaussian"
    if with_input_error and group.input_jacobian is not None:  # linearised once (linearise_input_error)
        predicted, solver_error = predict(model, group, config=config, geometry=geometry)
        jac, shared = jnp.asarray(group.input_jacobian), jnp.asarray(group.shared)
    elif with_input_error:
        sets, solver_error, jac = input_error_jacobian(model, _as_simulated(group), config=config, geometry=geometry)
        shared = jnp.asarray(group.shared)
        predicted, solver_error = sets[shared], solver_error[shared]
    else:
        predicted, solver_error = predict(model, group, config=config, geometry=geometry)
    residual = jnp.where(measured, observed, 0.0) - predicted
    n_sets = group.specimen_index.shape[0]
    if group.residual_lag1 is None:  # independent bins
        ll = jnp.where(measured, _log_density(residual, scale, family), 0.0)
        if with_input_error:
            weight = jnp.where(measured, 1.0 / scale**2, 0.0)
            masked = jnp.where(measured, residual, 0.0)
            correction = _input_error_correction(masked, weight, jac[shared], shared, n_sets)
    else:  # AR(1) within each segment of a run: each bin's density given the bin before it
        lag1, restart = jnp.asarray(group.residual_lag1), group.segment_start
        standardized, factor = ar1_innovations(jnp.where(measured, residual / scale, 0.0), measured, lag1, restart)
        ll = jnp.where(measured, _log_density(standardized * scale * factor, scale * factor, family), 0.0)
        if with_input_error:  # the same whitening on the error's columns, then weight 1 where measured
            per_run = ar1_innovations(jac[shared] / scale[:, None, :], measured, lag1, restart)[0]
            per_run = jnp.where(measured[:, None, :], per_run, 0.0)
            correction = _input_error_correction(standardized, measured.astype(scale.dtype), per_run, shared, n_sets)
    if with_input_error:
        # Apportioned evenly over the measured bins of the runs sharing the input, so sums are exact.
        bins = jax.ops.segment_sum(jnp.sum(measured, axis=1), shared, num_segments=n_sets)
        ll = ll + jnp.where(measured, (correction / jnp.maximum(bins, 1))[shared][:, None], 0.0)
    bad = ~jnp.all(jnp.isfinite(predicted), axis=1) | ~(solver_error <= solver_tolerance[group.test])
    return predicted, scale, jnp.where(bad[:, None] | ~jnp.isfinite(ll), -jnp.inf, ll)


def whitened_residuals(
    params,
    group: RunGroup,
    *,
    config: ModelConfig = DEFAULT_CONFIG,
    geometry: Geometry = PAPER_GEOMETRY,
    predicted=None,
) -> np.ndarray:
    """(r, m) residuals of ``group`` at ``params`` in units of their noise, NaN where unmeasured: (observed -
    predicted) / bin sd, or, where the fitted inputs' error enters the likelihood, the residuals of the runs
    sharing an input whitened by the Cholesky factor of their joint covariance (in run, bin order). Either way
    they are independent standard normals when the model is right, so their rms is the fit in noise units;
    being sequential (each bin's innovation given the bins before it), their correlation from bin to bin shows
    misfit with structure (:func:`~peano_bayes.inference.fit.residual_correlation`). The error's Jacobian is
    the group's held one where set (:func:`linearise_input_error`, as the likelihood uses it), else computed at
    ``params``; ``predicted`` (r, m), the group's prediction at ``params``, saves a simulation where given and
    the Jacobian is held."""
    model = _model_parameters(params)
    scale = np.asarray(bin_noise_sd(params[OBSERVED[group.test][1]], group))
    if group.has_input_error and group.input_jacobian is None:
        sets, _, jac = input_error_jacobian(model, _as_simulated(group), config=config, geometry=geometry)
        predicted = np.asarray(sets)[group.shared]
    else:
        jac = group.input_jacobian
        if predicted is None:
            predicted = predict(model, group, config=config, geometry=geometry)[0]
    residual = np.asarray(group.observed) - np.asarray(predicted)
    if not group.has_input_error:
        return residual / scale
    jac = np.asarray(jac)
    out = np.full(residual.shape, np.nan)
    for j in range(jac.shape[0]):
        rows = np.flatnonzero(group.shared == j)
        measured = np.isfinite(residual[rows]).ravel()
        u = np.concatenate([jac[j].T] * rows.size)[measured]
        cov = np.diag((scale[rows] ** 2).ravel()[measured]) + u @ u.T
        z = np.full(measured.size, np.nan)
        z[measured] = np.linalg.solve(np.linalg.cholesky(cov), residual[rows].ravel()[measured])
        out[rows] = z.reshape(rows.size, -1)
    return out


#: Largest lag-1 correlation the likelihood takes for a test's residuals (:func:`with_residual_lag1`): at 0.99 the
#: mean of a long AR(1) sequence is sqrt(199) = 14 times as uncertain as that of independent bins of the same size
#: (less over a segment of ~100 bins, about 1 / (1 - lag1) bins long); nearer 1 the AR(1) model turns into a random
#: walk whose level the data no longer fix.
MAX_RESIDUAL_LAG1 = 0.99


def with_residual_lag1(observations: Observations, lag1) -> Observations:
    """``observations`` whose groups of each test in ``lag1`` (test -> lag-1 correlation) take their residuals as
    AR(1) from bin to bin within a run with that correlation, clipped to [0, :data:`MAX_RESIDUAL_LAG1`]
    (:attr:`RunGroup.residual_lag1`); the other groups are unchanged. The marginal sd of every bin stays the
    test's noise scale over sqrt(samples); what changes is how much independent evidence neighbouring bins
    carry (see ``docs/inference.md``, *Misfit with structure*)."""
    groups = []
    for group in observations.groups:
        if group.test in lag1:
            rho = float(np.clip(lag1[group.test], 0.0, MAX_RESIDUAL_LAG1))
            group = replace(group, residual_lag1=np.asarray(rho))
        groups.append(group)
    return replace(observations, groups=tuple(groups))


def pointwise_log_likelihood(
    params,
    observations: Observations,
    *,
    config: ModelConfig = DEFAULT_CONFIG,
    family: str = "gaussian",
    solver_tolerance=SOLVER_TOLERANCE,
):
    """Log-likelihood of every bin: a tuple of (r, m) arrays, one per run group (NaN bins give 0).

    ``params`` holds the model parameters (scalars or (n_specimens,) arrays) and the noise scale of each test
    present (:data:`OBSERVED`) per raw sample. ``family``: ``"gaussian"`` or
    ``"student_t"`` (4 degrees of freedom, for outliers). A run whose solver error exceeds its
    ``solver_tolerance`` (by test, see :data:`SOLVER_TOLERANCE`) gets -inf in every bin.
    """
    kw = dict(config=config, geometry=observations.geometry, family=family, solver_tolerance=solver_tolerance)
    return tuple(group_log_likelihood(params, group, **kw)[2] for group in observations.groups)


def log_likelihood(params, observations: Observations, **kwargs):
    """Total log-likelihood (scalar); never NaN: anything non-finite becomes -inf. Keywords as
    :func:`pointwise_log_likelihood`."""
    total = sum(jnp.sum(ll) for ll in pointwise_log_likelihood(params, observations, **kwargs))
    return jnp.where(jnp.isnan(total), -jnp.inf, total)


__all__ = [
    "LINEARISATION_STEP",
    "MAX_RESIDUAL_LAG1",
    "SOLVER_TOLERANCE",
    "STEP_SUBSTEPS",
    "STUDENT_T_DOF",
    "ar1_innovations",
    "bin_noise_sd",
    "group_log_likelihood",
    "input_error_jacobian",
    "linearise_input_error",
    "log_likelihood",
    "pointwise_log_likelihood",
    "predict",
    "predict_sets",
    "simulate_test",
    "whitened_residuals",
    "with_residual_lag1",
]
