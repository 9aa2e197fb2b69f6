"""Likelihood of rig data under the physics model: data reduction, predictions, pointwise log-likelihood.

Knows nothing about files (it takes a validated :class:`~peano_bayes.data.Dataset`) or priors. The physics is
called through the four test simulations; runs of one test are stacked and simulated in one ``vmap``.

**Observed signal per test:** force [N] in the load cycle and blocking tests (strain-controlled), strain [-] in
the stroke and step tests (load-controlled). Each gets its own noise scale: ``noise_force_n`` [N] or
``noise_strain`` [-], the standard deviation of one raw sample.

**Data reduction (binning):** a rig samples far faster than quasi-static physics changes, and the cost of a
likelihood evaluation grows with the number of simulated samples. Consecutive samples are averaged in bins of
``k`` (inputs and outputs alike); the simulation runs on the binned inputs and a bin mean of ``k`` samples
carries noise ``sigma / sqrt(k)``. This is exact for signals linear within a bin and otherwise biased by the
signal's curvature times the bin width squared, negligible at the default of 4 samples (0.2 s at 20 Hz, see
``tests/test_likelihood.py``). Binning also averages the noise of the measured strain that drives a load
cycle, which would otherwise make the friction element see spurious reversals. The step response is not
binned by default (its dynamics need every sample).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np

from ..data import Dataset
from ..physics import (
    DEFAULT_CONFIG,
    PAPER_GEOMETRY,
    Blocking,
    Geometry,
    LoadCycle,
    ModelConfig,
    Step,
    Stroke,
    simulate_blocking,
    simulate_load_cycle,
    simulate_step,
    simulate_stroke,
)

#: Samples averaged per bin, by test (see the module docstring).
DEFAULT_BIN_SIZES = MappingProxyType({"load_cycle": 4, "blocking": 4, "stroke": 4, "step": 1})
#: The observed signal and its noise parameter, by test.
OBSERVED = MappingProxyType(
    {
        "load_cycle": ("force_n", "noise_force_n"),
        "blocking": ("force_n", "noise_force_n"),
        "stroke": ("strain", "noise_strain"),
        "step": ("strain", "noise_strain"),
    }
)
NOISE_PARAMETERS = ("noise_force_n", "noise_strain")
#: Integration substeps per (binned) sample interval of the step test.
STEP_SUBSTEPS = 2
#: Largest solver equilibrium error (``max_residual`` of a simulation) accepted, by test: [m] where strain is
#: imposed, [N] where force is (the step's inertial residual sits near 1e-5 N when converged).
SOLVER_TOLERANCE = MappingProxyType({"load_cycle": 1e-6, "blocking": 1e-6, "stroke": 1e-2, "step": 1e-2})
#: Degrees of freedom of the Student-t option.
STUDENT_T_DOF = 4.0


@dataclass(frozen=True, eq=False)
class RunGroup:
    """Runs of one test with equal reduced length, stacked for one vmapped simulation.

    **Fields:** ``test``; ``keys`` (r,) of ``(specimen, test, run)``; ``specimen_index`` (r,) int into
    :attr:`Observations.specimens`; ``time_s``, ``strain``, ``pressure_pa``, ``supply_pa`` (r, m) binned inputs
    (``supply_pa`` only for steps); ``load_n`` (r,) hanging or inertial load [N]; ``observed`` (r, m) bin means
    of the observed signal; ``counts`` (r, m) raw samples per bin.
    """

    test: str
    keys: tuple
    specimen_index: np.ndarray
    time_s: np.ndarray
    strain: np.ndarray
    pressure_pa: np.ndarray
    supply_pa: np.ndarray | None
    load_n: np.ndarray
    observed: np.ndarray
    counts: np.ndarray

    @property
    def n_bins(self) -> int:
        return int(self.observed.size)


@dataclass(frozen=True, eq=False)
class Observations:
    """A dataset reduced for the likelihood: run groups and the specimen names they index."""

    specimens: tuple[str, ...]
    groups: tuple[RunGroup, ...]
    bin_sizes: MappingProxyType
    geometry: Geometry

    @property
    def n_bins(self) -> int:
        return sum(g.n_bins for g in self.groups)


def bin_means(values: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Means of consecutive bins of ``k`` samples of ``values`` (n,), the last bin possibly shorter.

    Returns ``(means (m,), counts (m,))``; NaN samples are left out of their bin's mean and count.
    """
    values = np.asarray(values, dtype=float)
    n = values.shape[0]
    starts = np.arange(0, n, k)
    finite = np.isfinite(values)
    sums = np.add.reduceat(np.where(finite, values, 0.0), starts)
    counts = np.add.reduceat(finite.astype(float), starts)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1.0), np.nan), counts


def _reduce_run(run, k: int):
    signal, _ = OBSERVED[run.test]
    time_s, _ = bin_means(run.time_s, k)
    strain, _ = bin_means(run.strain, k)
    pressure, _ = bin_means(run.pressure_pa, k)
    supply = bin_means(run.supply_pa, k)[0] if run.supply_pa is not None else None
    observed, counts = bin_means(getattr(run, signal), k)
    if run.test == "step" and supply is None:
        raise ValueError(f"step run {run.key} has no supply pressure; the step likelihood needs supply_kpa")
    load = float(np.nanmedian(run.load_n)) if run.load_n is not None and np.any(np.isfinite(run.load_n)) else None
    return time_s, strain, pressure, supply, load, observed, counts


def prepare(dataset: Dataset, bin_sizes=DEFAULT_BIN_SIZES, *, stroke_load_n: float = 5.5) -> Observations:
    """Reduce ``dataset`` for the likelihood: bin every run (``bin_sizes`` by test) and stack runs of a test
    that have the same number of bins. ``stroke_load_n`` [N] is used where a stroke run records no load."""
    bin_sizes = MappingProxyType({**DEFAULT_BIN_SIZES, **dict(bin_sizes)})
    specimens = tuple(dataset.specimens)
    buckets: dict[tuple[str, int], list] = {}
    for run in dataset.runs:
        reduced = _reduce_run(run, bin_sizes[run.test])
        buckets.setdefault((run.test, reduced[0].shape[0]), []).append((run, reduced))
    groups = []
    for (test, _), members in sorted(buckets.items()):
        loads = []
        for run, (*_, load, _obs, _counts) in members:
            if load is None and test == "step":
                raise ValueError(f"step run {run.key} records no load; the step likelihood needs load_n")
            loads.append(stroke_load_n if load is None else load)
        stack = lambda i, members=members: np.stack([m[1][i] for m in members])  # noqa: E731
        groups.append(
            RunGroup(
                test=test,
                keys=tuple(run.key for run, _ in members),
                specimen_index=np.array([specimens.index(run.specimen) for run, _ in members]),
                time_s=stack(0),
                strain=stack(1),
                pressure_pa=stack(2),
                supply_pa=stack(3) if test == "step" else None,
                load_n=np.array(loads),
                observed=stack(5),
                counts=stack(6),
            )
        )
    return Observations(specimens, tuple(groups), bin_sizes, dataset.geometry)


def _simulate(test: str, params, time_s, strain, pressure_pa, supply_pa, load_n, config, geometry):
    """The observed signal of one run (m,) and the solver's equilibrium error."""
    kw = dict(config=config, geometry=geometry)
    if test == "load_cycle":
        result = simulate_load_cycle(params, LoadCycle(time_s, strain, pressure_pa), **kw)
        return result.force_n, result.max_residual
    if test == "blocking":
        result = simulate_blocking(params, Blocking(time_s, pressure_pa), **kw)
        return result.force_n, result.max_residual
    if test == "stroke":
        result = simulate_stroke(params, Stroke(time_s, pressure_pa, load_n), **kw)
        return result.strain, result.max_residual
    result = simulate_step(params, Step(time_s, supply_pa, load_n, STEP_SUBSTEPS), **kw)
    return result.strain, result.max_residual


def predict(params, group: RunGroup, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY):
    """Predicted observed signal (r, m) of every run in ``group`` and each run's solver error (r,).

    ``params``: model parameters by name, each a scalar (shared) or an array of shape (n_specimens,).
    """

    def one(specimen, time_s, strain, pressure, supply, load):
        p = {k: (v[specimen] if jnp.ndim(v) else v) for k, v in params.items()}
        return _simulate(group.test, p, time_s, strain, pressure, supply, load, config, geometry)

    supply = group.supply_pa if group.supply_pa is not None else group.pressure_pa
    return jax.vmap(one)(
        jnp.asarray(group.specimen_index),
        jnp.asarray(group.time_s),
        jnp.asarray(group.strain),
        jnp.asarray(group.pressure_pa),
        jnp.asarray(supply),
        jnp.asarray(group.load_n),
    )


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


def pointwise_log_likelihood(
    params,
    observations: Observations,
    *,
    config: ModelConfig = DEFAULT_CONFIG,
    family: str = "gaussian",
    solver_tolerance=SOLVER_TOLERANCE,
):
    """Log-likelihood of every bin: a tuple of (r, m) arrays, one per run group (NaN bins give 0).

    ``params`` holds the model parameters (scalars or (n_specimens,) arrays) and the noise scales
    ``noise_force_n`` [N] and ``noise_strain`` [-] of one raw sample. ``family``: ``"gaussian"`` or
    ``"student_t"`` (4 degrees of freedom, for outliers). A run whose solver error exceeds its
    ``solver_tolerance`` (by test, see :data:`SOLVER_TOLERANCE`) gets -inf in every bin.
    """
    if family not in ("gaussian", "student_t"):
        raise ValueError(f"family must be 'gaussian' or 'student_t', got {family!r}")
    model = {k: v for k, v in params.items() if k not in NOISE_PARAMETERS}
    out = []
    for group in observations.groups:
        predicted, solver_error = predict(model, group, config=config, geometry=observations.geometry)
        _, noise_name = OBSERVED[group.test]
        counts = jnp.asarray(group.counts)
        scale = params[noise_name] / jnp.sqrt(jnp.maximum(counts, 1.0))
        observed = jnp.asarray(group.observed)
        measured = jnp.isfinite(observed)
        ll = jnp.where(measured, _log_density(jnp.where(measured, observed, 0.0) - predicted, scale, family), 0.0)
        bad = ~jnp.all(jnp.isfinite(predicted), axis=1) | ~(solver_error <= solver_tolerance[group.test])
        out.append(jnp.where(bad[:, None] | ~jnp.isfinite(ll), -jnp.inf, ll))
    return tuple(out)


def log_likelihood(params, observations: Observations, **kwargs):
    """Total log-likelihood (scalar); never NaN: anything non-finite becomes -inf. Keywords as
    :func:`pointwise_log_likelihood`."""
    total = sum(jnp.sum(ll) for ll in pointwise_log_likelihood(params, observations, **kwargs))
    return jnp.where(jnp.isnan(total), -jnp.inf, total)


__all__ = [
    "DEFAULT_BIN_SIZES",
    "NOISE_PARAMETERS",
    "OBSERVED",
    "SOLVER_TOLERANCE",
    "Observations",
    "RunGroup",
    "bin_means",
    "log_likelihood",
    "pointwise_log_likelihood",
    "predict",
    "prepare",
]
