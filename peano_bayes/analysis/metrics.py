"""The paper's Table 3 metrics: measured from a rig dataset, and predicted by a posterior.

**Measured** (:func:`dataset_metrics`, :func:`run_metrics`): every metric uses
:mod:`peano_bayes.analysis.readouts` (the paper's Table 3 definitions) on each run and is averaged over specimens
and repeats. Interpretation choices, stated once:

- stiffness: tangent of the stretching branch of the 0 kPa load cycles at -1.5 % strain [N/m], from a
  quadratic fitted over +-0.3 % strain around it (a plain finite difference of noisy data is meaningless);
  NaN when the cycle does not cover -1.5 % (the start tension already stretches the muscle past it);
- hysteresis loss, free strain and energy: the load cycles at the test pressure (Figure 9 uses the
  pressurized cycles of Figure 8(b)(d));
- step metrics (:func:`smoothed_step_metrics`): :func:`peano_bayes.analysis.readouts.step_metrics` (rms speed,
  rms power ``m (g + a) v``, rms mechanical over rms fluid power) on strain and flow smoothed with a zero-phase
  Savitzky-Golay filter (``STEP_SMOOTHING_S``, as any rig must before taking a speed and an acceleration from
  a 1 kHz position signal), over a window from the supply edge to the first maximum of the smoothed strain
  after it has risen halfway to its final value (the first overshoot peak; sensor noise makes earlier local
  maxima), or, for a response without overshoot (over 1 % of the rise), to 99 % of the rise (its
  ``overshoot_fraction`` rule). For an overshooting response on noise-free signals this equals the rule
  without ``overshoot_fraction`` to within a percent.

**Predicted** (:func:`model_metrics`, :func:`posterior_metrics`): the same definitions on noise-free virtual-rig
signals of one specimen (:func:`peano_bayes.rig.simulate_dataset`, the paper's protocol for the material), one
simulation per parameter draw (by default a new specimen's, see :func:`posterior_metrics`); the stiffness from a
dedicated 0 kPa stretch from 0 to -3 % strain (:func:`zero_kpa_stiffness`), because the rig's 0 kPa cycle starts at
the start tension, which stretches soft muscles past -1.5 %.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
from scipy.signal import savgol_filter

from .. import bundled
from ..defaults import DEFAULT_DRAWS
from ..errors import PeanoBayesError, PeanoBayesInputError
from ..formatting import format_number
from ..inference.fit import structured_tests
from ..inference.posterior import STEP_ONLY_PARAMETERS
from ..inference.results import load_result, parameter_draws, result_config
from ..inference.summary import read_summary
from ..materials import MATERIALS, MaterialSpec
from ..materials import material as material_spec
from ..physics import DEFAULT_CONFIG, PAPER_GEOMETRY, Geometry, LoadCycle, ModelConfig, free_strain, simulate_load_cycle
from ..rig import RigNoise, RigSimulationError, apply_quirks, simulate_dataset
from . import readouts as m

#: Version of what ``metrics.json`` holds, raised when the same result would give other metrics (2: the model
#: discrepancy of misfit tests added, one normal per test, growing above the tested pressure; 3: ``free_strain``
#: is the muscle's own, :func:`~peano_bayes.physics.free_strain`, and the paper's extrapolated reading is
#: ``free_strain_paper_reading``).
METRICS_VERSION = 4

#: Savitzky-Golay window of the step-response smoothing [s] (order 3); 15 ms at 1 kHz is 15 samples.
STEP_SMOOTHING_S = 0.015

#: Metric name -> SI unit, in report order.
METRIC_UNITS = {
    "stiffness_at_minus_1.5pct_0kPa": "N/m",
    "hysteresis_loss": "fraction",
    "free_strain": "fraction",
    "free_strain_paper_reading": "fraction",
    "energy_per_pressure": "J/MPa",
    "blocking_force_per_pressure": "N/MPa",
    "stroke": "fraction",
    "speed": "m/s",
    "power_per_pressure": "W/MPa",
    "efficiency": "fraction",
    "overshoot": "fraction",
}


#: Half-width of the strain window of the stiffness fit [-].
STIFFNESS_HALF_WINDOW = 0.003
STIFFNESS_STRAIN = -0.015


def _smooth(signal, time_s):
    """Zero-phase Savitzky-Golay smoothing (order 3) over ``STEP_SMOOTHING_S``."""
    dt = float(np.median(np.diff(time_s)))
    window = int(round(STEP_SMOOTHING_S / dt)) | 1
    if window < 5 or len(signal) <= window:
        return np.asarray(signal, float)
    return savgol_filter(np.asarray(signal, float), window, 3)


def stiffness(strain, force_n, flat_length_m, at_strain: float = STIFFNESS_STRAIN) -> float:
    """Tangent stiffness -dF/dy of the stretching branch at ``at_strain`` [N/m] from a quadratic fitted to the
    branch within ``STIFFNESS_HALF_WINDOW`` of it (one-sided where the branch turns there); NaN if the branch
    does not reach ``at_strain`` or starts less than ``STIFFNESS_HALF_WINDOW`` above it."""
    strain, force_n = np.asarray(strain, float), np.asarray(force_n, float)
    turn = int(np.argmin(strain))
    s, f = strain[: turn + 1], force_n[: turn + 1]
    if s.max() < at_strain + STIFFNESS_HALF_WINDOW or s.min() > at_strain + 1e-4:
        return float("nan")
    near = np.abs(s - at_strain) <= STIFFNESS_HALF_WINDOW
    coef = np.polyfit(s[near] - at_strain, f[near], 2)
    return float(-coef[1] / flat_length_m)


def smoothed_step_metrics(time_s, strain, supply_pa, flow_m3_per_s, load_n, flat_length_m, test_pressure_pa):
    """Table 3 step metrics of a measured step response: :func:`peano_bayes.analysis.readouts.step_metrics` with
    ``overshoot_fraction`` :data:`~peano_bayes.analysis.readouts.OVERSHOOT_FRACTION` on strain and flow smoothed
    over ``STEP_SMOOTHING_S``."""
    flow = None if flow_m3_per_s is None else _smooth(flow_m3_per_s, time_s)
    return m.step_metrics(
        time_s,
        _smooth(strain, time_s),
        supply_pa,
        flow,
        load_n,
        flat_length_m,
        test_pressure_pa,
        overshoot_fraction=m.OVERSHOOT_FRACTION,
    )


def run_metrics(dataset) -> dict[str, list[float]]:
    """Every Table 3 metric of every run of ``dataset``: metric name -> list of per-run values (SI units)."""
    l0 = dataset.geometry.flat_length_m
    p_test = dataset.conditions.test_pressure_pa
    out: dict[str, list[float]] = {name: [] for name in METRIC_UNITS}
    for run in dataset.runs:
        if run.test == "load_cycle":
            if np.median(run.pressure_pa) < 0.5 * p_test:
                out["stiffness_at_minus_1.5pct_0kPa"].append(stiffness(run.strain, run.force_n, l0))
            else:
                out["hysteresis_loss"].append(m.hysteresis_loss(run.strain, run.force_n))
                # the muscle's own free strain needs zero force, which the rig never reaches: only the paper's
                # extrapolated reading is measured (the model's free_strain is predicted, see model_metrics)
                out["free_strain_paper_reading"].append(m.extrapolated_free_strain(run.strain, run.force_n))
                out["energy_per_pressure"].append(m.energy_per_pressure(run.strain, run.force_n, run.pressure_pa, l0))
        elif run.test == "blocking":
            out["blocking_force_per_pressure"].append(m.blocking_force_per_pressure(run.pressure_pa, run.force_n))
        elif run.test == "stroke":
            out["stroke"].append(m.stroke(run.strain))
        elif run.test == "step":
            load = float(np.nanmedian(run.load_n))
            for name, value in smoothed_step_metrics(
                run.time_s, run.strain, run.supply_pa, run.flow_m3_per_s, load, l0, p_test
            ).items():
                out[name].append(value)
    return out


def dataset_metrics(dataset) -> dict[str, float]:
    """Table 3 metrics of ``dataset``, each the mean over specimens and repeats (SI units, per MPa where the
    paper normalizes); NaN for a metric no run measures or that a run cannot measure."""
    return {name: float(np.mean(v)) if v else float("nan") for name, v in run_metrics(dataset).items()}


# --- predicted: noise-free virtual-rig signals of one specimen -----------------------------------------------

STIFFNESS = "stiffness_at_minus_1.5pct_0kPa"
#: Metrics that need the step test (the rest come from load cycles, blocking and stroke).
STEP_METRICS = ("speed", "power_per_pressure", "efficiency", "overshoot")
NOISELESS = RigNoise(0.0, 0.0, 0.0, 0.0, 0.0)


def _config_params(params: dict, config: ModelConfig) -> dict:
    """``params`` [SI] as float64 arrays, with the nominal value of every parameter ``config`` reads that they
    lack."""
    return {k: jnp.asarray(v, jnp.float64) for k, v in {**config.nominal_parameters(), **params}.items()}


@partial(jax.jit, static_argnames="config")
def _zero_kpa_stretch(params, time_s, *, config):
    strain = jnp.interp(time_s, jnp.array([0.0, 20.0, 40.0]), jnp.array([0.0, -0.03, 0.0]))
    result = simulate_load_cycle(params, LoadCycle(time_s, strain, jnp.zeros_like(time_s)), config=config)
    return strain, result.force_n


def zero_kpa_stiffness(params: dict, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY):
    """Tangent stiffness at -1.5 % strain and 0 kPa [N/m] of a noise-free stretch from 0 to -3 % strain and back
    over 40 s (20 Hz); ``params`` [SI] missing a name the ``config`` reads take its nominal value."""
    jparams = _config_params(params, config)
    strain, force = _zero_kpa_stretch(jparams, jnp.arange(801) / 20.0, config=config)
    return stiffness(np.asarray(strain), np.asarray(force), geometry.flat_length_m)


_free_strain = jax.jit(free_strain, static_argnames=("config", "geometry"))


def model_free_strain(
    params: dict, pressure_pa: float, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
) -> float:
    """The muscle's own free strain [-] at ``pressure_pa`` [Pa] (:func:`peano_bayes.physics.free_strain`: the
    contracting branch at that pressure followed to zero force); ``params`` [SI] missing a name the ``config``
    reads take its nominal value."""
    jparams = _config_params(params, config)
    return float(_free_strain(jparams, jnp.asarray(pressure_pa, jnp.float64), config=config, geometry=geometry))


def model_metrics(material, params: dict, *, config: ModelConfig = DEFAULT_CONFIG, quirks=()) -> dict[str, float]:
    """Table 3 metrics [SI, see :data:`METRIC_UNITS`] of noise-free rig signals of one specimen of ``material``
    (a Table 4 code or :class:`~peano_bayes.materials.MaterialSpec`) with ``params`` [SI], under the paper's
    protocol for that material; the stiffness from :func:`zero_kpa_stiffness`, the free strain the muscle's own
    at the material's test pressure (:func:`model_free_strain`), beside the paper's reading of the simulated load
    cycles (``free_strain_paper_reading``). Raises
    :class:`~peano_bayes.rig.RigSimulationError` where the physics does not converge."""
    dataset = simulate_dataset(
        material, params, config=config, quirks=quirks, noise=NOISELESS, specimen_spread=0.0, repeats=1, specimens=1
    )
    values = dataset_metrics(dataset)
    config = apply_quirks(config, quirks)
    values[STIFFNESS] = zero_kpa_stiffness(params, config, dataset.geometry)
    values["free_strain"] = model_free_strain(params, dataset.conditions.test_pressure_pa, config, dataset.geometry)
    return values


# --- model discrepancy: what a misfit of the fitted tests adds to a prediction read off them -----------------


@dataclass(frozen=True)
class ReadOff:
    """One fitted ``test`` a Table 3 metric is read off, and ``per_signal``, the metric's change per unit change of
    that test's signal [metric unit per N, or per unit strain], as a function ``(values, pressure_pa,
    flat_length_m) -> scalar or (n,)`` of the draws' metrics ``values`` (metric -> (n,) [SI]), the pressure the
    metrics are simulated at [Pa] and the muscle's flat length [m]; None where a misfit's size says nothing of the
    metric (a slope, a ratio of areas, a quantity of an unfitted test)."""

    test: str
    per_signal: Callable | None = None


def _per_mpa(values, pressure_pa, flat_length_m):
    """[1/MPa]: a force per MPa moves by 1 / p [MPa] per newton of force."""
    return m.PA_PER_MPA / pressure_pa


def _strain(values, pressure_pa, flat_length_m):
    """[-]: a strain the test measures directly moves with it."""
    return 1.0


def _free_strain_per_newton(values, pressure_pa, flat_length_m):
    """[1/N]: where the relaxing load cycle crosses zero force, a force misfit moves the crossing by itself over
    the branch's slope, taken as the secant from the blocking force at zero strain to zero force at the free
    strain (rough: the branch is curved)."""
    blocking_n = values["blocking_force_per_pressure"] * pressure_pa / m.PA_PER_MPA
    return np.abs(values["free_strain"]) / blocking_n


def _energy(values, pressure_pa, flat_length_m):
    """[J/MPa per N]: a force error of mean d over the contraction from 0 to the free strain moves the work by
    d eps L0; d is taken as the size of the test's misfit (rough: that is one RMS over all the load cycles)."""
    return np.abs(values["free_strain"]) * flat_length_m * m.PA_PER_MPA / pressure_pa


#: Metric -> the :class:`ReadOff` of each fitted test it is read off. The blocking force is the blocking test's
#: force at its top pressure, the stroke the stroke test's strain; the free strain is where the load cycle's force
#: reaches zero, a static contraction at low load that the stroke test also measures as strain; the energy
#: integrates the load cycle's force over the contraction. Stiffness and hysteresis (a slope, a ratio of areas)
#: and the step metrics are not carried.
READ_OFF = {
    STIFFNESS: (ReadOff("load_cycle"),),
    "hysteresis_loss": (ReadOff("load_cycle"),),
    "free_strain": (ReadOff("load_cycle", _free_strain_per_newton), ReadOff("stroke", _strain)),
    "free_strain_paper_reading": (ReadOff("load_cycle", _free_strain_per_newton), ReadOff("stroke", _strain)),
    "energy_per_pressure": (ReadOff("load_cycle", _energy),),
    "blocking_force_per_pressure": (ReadOff("blocking", _per_mpa),),
    "stroke": (ReadOff("stroke", _strain),),
    **{name: (ReadOff("step"),) for name in STEP_METRICS},
}


def misfit_discrepancy(summary: dict) -> dict[str, float]:
    """test -> sd of the model discrepancy a prediction read off it carries [the test's signal unit: N or
    strain]: its RMSE beyond the sensor noise at the posterior mean (``excess_rmse`` of ``summary.json``'s
    ``fit_quality_posterior_mean``), for every test whose misfit has structure
    (:func:`~peano_bayes.inference.fit.structured_tests`; a misfit consistent with noise is noise, not a
    discrepancy) and whose excess is a positive number. Empty for a result whose model explains its data."""
    quality = summary.get("fit_quality_posterior_mean", {})
    out = {}
    for test in structured_tests(summary.get("residual_correlation", {})):
        excess = quality.get(test, {}).get("excess_rmse")
        if excess is not None and math.isfinite(excess) and excess > 0:
            out[test] = float(excess)
    return out


def add_discrepancy(
    values: dict, discrepancy: dict, pressure_pa: float, flat_length_m: float, rng: np.random.Generator
) -> tuple[dict, dict, tuple]:
    """Posterior predictive draws with the model discrepancy of the tests they are read off.

    ``values``: metric -> (n,) parameter-only draws [SI]; ``discrepancy``: test -> sd [signal unit]
    (:func:`misfit_discrepancy`); ``pressure_pa`` [Pa] and ``flat_length_m`` [m]: the pressure the metrics were
    simulated at and the muscle's length (:data:`READ_OFF`'s scales). A metric :data:`READ_OFF` maps onto a
    misfit test gets, per draw, ``per_signal * sd`` times a standard normal value: the marginal predictive of an
    unknown smooth misfit of that size where the metric is read. One normal value per test and draw, so metrics
    read off one test move together; a metric read off several misfit tests takes the one whose sd is largest
    (median over draws); a draw whose scale is not finite (e.g. its blocking force failed) takes the median sd
    of the others. Returns (metric -> (n,) draws, metric -> (test, (n,) sd added [metric unit]) for the
    metrics that got one, metrics whose tests misfit but whose discrepancy none of them sizes)."""
    n = len(next(iter(values.values())))
    z = {test: rng.standard_normal(n) for test in sorted(discrepancy)}
    draws, added, not_carried = dict(values), {}, []
    for name, sources in READ_OFF.items():
        applicable = [r for r in sources if r.test in discrepancy] if name in values else []
        sized = []
        for r in applicable:
            if r.per_signal is None:
                continue
            with np.errstate(divide="ignore", invalid="ignore"):
                sd = (
                    np.broadcast_to(np.abs(r.per_signal(values, pressure_pa, flat_length_m)), (n,))
                    * discrepancy[r.test]
                )
            finite = np.isfinite(sd)
            if finite.any():  # a draw whose scale is undefined (a failed blocking force) takes the median's
                sized.append((r.test, np.where(finite, sd, np.median(sd[finite]))))
        if sized:
            test, sd = max(sized, key=lambda item: np.median(item[1]))
            draws[name] = values[name] + sd * z[test]
            added[name] = (test, sd)
        elif applicable:
            not_carried.append(name)
    return draws, added, tuple(not_carried)


@dataclass(frozen=True)
class PosteriorMetrics:
    """Posterior predictive Table 3 metrics of one material.

    **Fields:** ``material`` code; ``draws`` metric -> (n,) predictive values [SI, :data:`METRIC_UNITS`]: the
    parameter draws' metrics plus, where the fitted test a metric is read off misfits with structure, that
    test's model discrepancy (:func:`add_discrepancy`); NaN where a draw's simulation failed or the metric is
    undefined; ``n_failed`` draws whose physics did not converge; ``prior_only`` parameters the posterior does
    not hold (not informed by the fitted tests), drawn from the prior; ``from_prior`` metrics that depend on
    them (e.g. the step metrics when the step test was not fitted); ``parameter_draws`` metric -> (n,) the
    parameter draws' metrics alone; ``discrepancy`` metric -> (test, (n,) sd added [metric unit]);
    ``not_carried`` metrics whose fitted test misfits but whose discrepancy has no size in the metric.
    """

    material: str
    draws: dict
    n_failed: int
    prior_only: tuple
    from_prior: tuple
    parameter_draws: dict
    discrepancy: dict
    not_carried: tuple

    def summary(self, hdi_prob: float = 0.94) -> dict:
        """metric -> ``median``, ``hdi_low``, ``hdi_high`` (arviz HDI of ``draws``: what a designer reads),
        ``parameter_median``, ``parameter_hdi_low``, ``parameter_hdi_high`` (of ``parameter_draws``),
        ``discrepancy_sd`` (median sd added [metric unit], None if none), ``discrepancy_test`` (the test it
        comes from, None if none), ``misfit_not_carried``, ``unit``, ``n`` (finite draws) and ``from_prior``."""
        out = {}
        for name, values in self.draws.items():
            median, low, high = _median_hdi(values, hdi_prob)
            p_median, p_low, p_high = _median_hdi(self.parameter_draws[name], hdi_prob)
            test, sd = self.discrepancy.get(name, (None, None))
            out[name] = {
                "median": median,
                "hdi_low": low,
                "hdi_high": high,
                "parameter_median": p_median,
                "parameter_hdi_low": p_low,
                "parameter_hdi_high": p_high,
                "discrepancy_sd": None if sd is None else float(np.median(sd)),
                "discrepancy_test": test,
                "misfit_not_carried": name in self.not_carried,
                "unit": METRIC_UNITS[name],
                "n": int(np.isfinite(values).sum()),
                "from_prior": name in self.from_prior,
            }
        return out


def _median_hdi(values, hdi_prob: float) -> tuple[float, float, float]:
    """Median and arviz HDI of the finite ``values``; NaN for fewer than two."""
    finite = np.asarray(values, float)
    finite = finite[np.isfinite(finite)]
    if finite.size < 2:
        return float("nan"), float("nan"), float("nan")
    low, high = (float(x) for x in az.hdi(finite, hdi_prob=hdi_prob))
    return float(np.median(finite)), low, high


def protocol_material(idata) -> str | MaterialSpec:
    """The material whose test protocol a result's metrics are simulated under: its Table 4 code, or, for a
    material of one's own, a :class:`~peano_bayes.materials.MaterialSpec` at the conditions of its data file
    (the result's ``conditions`` attribute: test pressure, step load, start tension)."""
    attrs = idata.posterior.attrs
    code = attrs["material"]
    if code in MATERIALS or "conditions" not in attrs:
        return code
    c = json.loads(attrs["conditions"])
    return MaterialSpec(
        code,
        code,
        code,
        "a material of one's own",
        matrix="unknown",
        test_pressure_pa=c["test_pressure_pa"],
        step_load_n=c["step_load_n"],
        start_tension_n=c["start_tension_n"],
    )


def at_test_pressure(protocol: str | MaterialSpec, test_pressure_pa: float | None) -> str | MaterialSpec:
    """``protocol`` (a Table 4 code or a :class:`MaterialSpec`) with its test pressure [Pa] replaced; unchanged
    for ``None``. Where a material's metrics are simulated away from the pressure it was tested at, they
    extrapolate its fitted model."""
    if test_pressure_pa is None:
        return protocol
    if not (math.isfinite(test_pressure_pa) and test_pressure_pa > 0):
        raise PeanoBayesInputError(f"a test pressure must be a positive number of Pa, got {test_pressure_pa}")
    return replace(material_spec(protocol), test_pressure_pa=float(test_pressure_pa))


def metrics_file(directory: str | Path, test_pressure_kpa: float | None = None) -> Path:
    """Where a result's metrics live: ``metrics.json`` at its own test pressure, ``metrics_at_<P>kPa.json`` at
    a common one."""
    name = "metrics.json" if test_pressure_kpa is None else f"metrics_at_{test_pressure_kpa:g}kPa.json"
    return Path(directory) / name


def posterior_metrics(
    idata,
    *,
    n_draws: int = DEFAULT_DRAWS,
    seed: int = 0,
    progress: Callable | None = None,
    level: str = "new_specimen",
    test_pressure_pa: float | None = None,
    discrepancy: dict | None = None,
) -> PosteriorMetrics:
    """Posterior predictive Table 3 metrics of a result (``posterior.nc`` as arviz InferenceData): the paper's
    protocol simulated noise-free for ``n_draws`` posterior draws
    (:func:`~peano_bayes.inference.results.parameter_draws`), each measured as
    the rig would be (:func:`model_metrics`). ``level``: ``"new_specimen"`` (default: a muscle not yet made,
    so the intervals include the between-specimen spread) or ``"population"``. ``progress`` wraps the draw
    iterator (e.g. ``tqdm``). ``test_pressure_pa``: simulate the protocol at this pressure instead of the
    material's own test pressure (to compare materials at one pressure). ``discrepancy``: test -> sd of its
    model discrepancy [signal unit] (:func:`misfit_discrepancy` of the result's ``summary.json``), added to the
    metrics read off it (:func:`add_discrepancy`; the normal values from ``seed``): one RMS over the pressures
    the test ran through, so taken as the same size in the test's signal at a pressure up to the material's
    test pressure, and as growing in proportion to pressure above it, where the model extrapolates. None or
    empty: parameter draws alone."""
    own = protocol_material(idata)
    protocol = at_test_pressure(own, test_pressure_pa)
    config = result_config(idata)
    sets, prior_only = parameter_draws(idata, n_draws, seed, level=level)
    values = {name: np.full(n_draws, np.nan) for name in METRIC_UNITS}
    failed = 0
    for i, params in enumerate(progress(sets) if progress else sets):
        try:
            metrics = model_metrics(protocol, params, config=config)
        except RigSimulationError:
            failed += 1
            continue
        for name, value in metrics.items():
            values[name][i] = value
    from_prior = STEP_METRICS if any(n in STEP_ONLY_PARAMETERS for n in prior_only) else ()
    draws, added, not_carried = values, {}, ()
    if discrepancy:
        pressure_pa, tested_pa = (material_spec(p).test_pressure_pa for p in (protocol, own))
        growth = max(1.0, pressure_pa / tested_pa)
        at_pressure = {test: sd * growth for test, sd in discrepancy.items()}
        rng = np.random.default_rng([seed, 1])
        draws, added, not_carried = add_discrepancy(values, at_pressure, pressure_pa, PAPER_GEOMETRY.flat_length_m, rng)
    material = idata.posterior.attrs["material"]
    return PosteriorMetrics(material, draws, failed, prior_only, from_prior, values, added, not_carried)


#: Published metrics the paper read off its curves in a way the muscle's own value differs from: compared with
#: the same reading of the predicted signals, not with the muscle's own (its free strain extrapolated the
#: relaxing load cycle to zero force).
PAPER_READINGS = {"free_strain": "free_strain_paper_reading"}


def published_metrics(material: str, path: str | Path | None = None) -> list[dict]:
    """Rows of ``published_metrics.csv`` for ``material`` whose metric this module predicts: ``metric``,
    ``value`` [SI, :data:`METRIC_UNITS`], ``kind`` (explicit / approximate / ambiguous) and ``source``."""
    path = Path(path) if path else bundled.DATA_DIR / "published_metrics.csv"
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["material"] == material]
    out = []
    for r in rows:
        metric = PAPER_READINGS.get(r["metric"], r["metric"])
        if metric in METRIC_UNITS:
            kind = r["kind"].split()[0]
            out.append({"metric": metric, "value": float(r["value"]), "kind": kind, "source": r["source"]})
    return out


def compare_published(material: str, summary: dict, path: str | Path | None = None) -> list[dict]:
    """Each published metric of ``material`` beside the posterior ``summary`` (:meth:`PosteriorMetrics.summary`):
    the row of :func:`published_metrics` plus ``median``, ``hdi_low``, ``hdi_high`` and ``inside`` (does the
    interval contain the published value; None when the prediction is undefined)."""
    rows = []
    for row in published_metrics(material, path):
        if row["metric"] not in summary:
            continue
        got = summary[row["metric"]]
        defined = math.isfinite(got["hdi_low"])
        inside = bool(got["hdi_low"] <= row["value"] <= got["hdi_high"]) if defined else None
        rows.append({**row, **{k: got[k] for k in ("median", "hdi_low", "hdi_high", "from_prior")}, "inside": inside})
    return rows


def metrics_markdown(material: str, summary: dict, comparison: list[dict]) -> str:
    """A markdown table of a material's posterior metrics with the published values beside them, and the model
    discrepancy each interval carries (:func:`add_discrepancy`)."""
    published = {row["metric"]: row for row in comparison}
    lines = [
        "| metric | unit | median | 94 % interval | published | inside | model misfit |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, s in summary.items():
        row = published.get(name)
        pub = f"{row['value']:.3g} ({row['kind']})" if row else "-"
        inside = "-" if not row or row["inside"] is None else ("yes" if row["inside"] else "**no**")
        flag = " (prior: step not fitted)" if s["from_prior"] else ""
        misfit = "-"
        if s.get("discrepancy_sd") is not None:
            misfit = f"included: sd {format_number(s['discrepancy_sd'])} from {s['discrepancy_test']}"
        elif s.get("misfit_not_carried"):
            tests = ", ".join(r.test for r in READ_OFF[name])
            misfit = f"**not included** ({tests} misfits)"
        lines.append(
            f"| {name}{flag} | {s['unit']} | {format_number(s['median'])} | "
            f"{format_number(s['hdi_low'])} to {format_number(s['hdi_high'])} | {pub} | {inside} | {misfit} |"
        )
    if any(s.get("discrepancy_sd") is not None or s.get("misfit_not_carried") for s in summary.values()):
        lines += [
            "",
            "Where a fitted test misfits with structure, a metric read off it can be off the model by about that "
            "test's RMSE beyond the sensor noise: its interval includes that discrepancy (*included*; the "
            "parameter-only interval is `parameter_hdi_*` in `metrics.json`). A metric marked **not included** "
            "depends on such a test in a way the misfit's size does not set (a slope, a ratio of areas): its "
            "interval is the parameters' alone and too narrow.",
        ]
    return "\n".join(lines)


def evaluate_result(
    path: str | Path,
    *,
    n_draws: int = DEFAULT_DRAWS,
    seed: int = 0,
    hdi_prob: float = 0.94,
    progress: bool = True,
    test_pressure_kpa: float | None = None,
) -> dict:
    """Posterior metrics of one result (``posterior.nc`` or its directory), compared with the paper, written
    beside the result (atomically, :func:`metrics_file`); returns what it wrote: ``material``,
    ``test_pressure_kpa`` (the pressure its metrics are simulated at; ``None`` if unknown),
    ``own_test_pressure_kpa`` (the material's), ``draws`` (posterior draws simulated), ``n_failed``,
    ``prior_only``, ``summary``
    (:meth:`PosteriorMetrics.summary`), ``published`` (:func:`compare_published`, empty away from the own test
    pressure: the paper's values are at that pressure), ``discrepancy`` (test -> the misfit beyond the sensor
    noise [signal unit] that :func:`posterior_metrics` adds to the metrics read off it, as measured, before any
    growth above the tested pressure: :func:`misfit_discrepancy` of the ``summary.json`` beside the result;
    empty without one or where the model explains the data), ``version`` (:data:`METRICS_VERSION`) and
    ``draw_values`` (metric -> list of predictive values, for :mod:`peano_bayes.analysis.ranking`).
    ``test_pressure_kpa``: a common pressure [kPa] instead of the material's own."""
    from tqdm.auto import tqdm

    from ..atomic import write_text

    idata = load_result(path)
    total = idata.posterior.sizes["chain"] * idata.posterior.sizes["draw"]
    n_draws = min(n_draws, total)
    material = idata.posterior.attrs["material"]
    bar = (lambda it: tqdm(it, desc=f"{material} metrics", unit="draw")) if progress else None
    spec = protocol_material(idata)
    spec = spec if isinstance(spec, MaterialSpec) else MATERIALS.get(spec)
    own = None if spec is None else spec.test_pressure_pa / 1e3
    common = None if test_pressure_kpa is None else float(test_pressure_kpa)
    pressure_pa = None if common is None else 1e3 * common
    directory = Path(path) if Path(path).is_dir() else Path(path).parent
    discrepancy = result_discrepancy(directory)
    result = posterior_metrics(
        idata, n_draws=n_draws, seed=seed, progress=bar, test_pressure_pa=pressure_pa, discrepancy=discrepancy
    )
    if n_draws - result.n_failed < 2:  # no interval to give: say so rather than write a file of NaN
        where = f" at {common:g} kPa" if common is not None else ""
        raise PeanoBayesError(
            f"{material}: {n_draws - result.n_failed} of the {n_draws} posterior draws could be simulated{where} "
            "(the physics did not converge), too few for an interval; nothing written"
        )
    summary = result.summary(hdi_prob)
    out = {
        "version": METRICS_VERSION,
        "material": material,
        "test_pressure_kpa": own if common is None else common,
        "own_test_pressure_kpa": own,
        "draws": n_draws,
        "n_failed": result.n_failed,
        "prior_only": list(result.prior_only),
        "hdi_prob": hdi_prob,
        "summary": summary,
        "published": compare_published(material, summary) if common in (None, own) else [],
        "discrepancy": discrepancy,
        "draw_values": {name: [float(x) for x in values] for name, values in result.draws.items()},
    }
    write_text(metrics_file(directory, common), json.dumps(out, indent=1, default=float))
    return out


def result_discrepancy(directory: str | Path) -> dict[str, float]:
    """:func:`misfit_discrepancy` of the ``summary.json`` in a result ``directory``; empty without one (a result
    written before fits reported it). Raises :class:`PeanoBayesInputError` naming a malformed file."""
    file = Path(directory) / "summary.json"
    if not file.exists():
        return {}
    try:
        return misfit_discrepancy(read_summary(file))
    except (KeyError, TypeError, AttributeError) as err:
        raise PeanoBayesInputError(
            f"{file}: its fit quality or residual correlation is malformed ({err!r}); "
            "expected the summary.json that 'peano-bayes fit' wrote"
        ) from None


def _read_json(file: Path) -> dict:
    """A JSON object from ``file``, or a :class:`PeanoBayesInputError` naming it."""
    try:
        out = json.loads(file.read_text())
    except json.JSONDecodeError as err:
        raise PeanoBayesInputError(f"{file}: not valid JSON ({err})") from None
    if not isinstance(out, dict):
        raise PeanoBayesInputError(f"{file}: expected a JSON object, got {type(out).__name__}")
    return out


def _stored_metrics(directory: str | Path, test_pressure_kpa: float | None) -> dict:
    """The metrics file of ``directory`` (:func:`metrics_file`) as a dict; empty when missing or unreadable."""
    try:
        out = json.loads(metrics_file(directory, test_pressure_kpa).read_text())
    except (OSError, ValueError):  # ValueError: bad JSON or bytes that are not text
        return {}
    return out if isinstance(out, dict) else {}


def metrics_current(directory: str | Path, test_pressure_kpa: float | None = None) -> bool:
    """Whether a result directory holds metrics (:func:`metrics_file`) of this :data:`METRICS_VERSION`; callers
    that keep metrics across runs recompute the others (an older file's intervals may be the parameters'
    alone)."""
    return _stored_metrics(directory, test_pressure_kpa).get("version") == METRICS_VERSION


def previous_draws(
    directory: str | Path, test_pressure_kpa: float | None = None, default: int = DEFAULT_DRAWS
) -> int:
    """The number of draws an existing metrics file of ``directory`` was made with (to recompute it alike), or
    ``default`` without a readable one."""
    stored = _stored_metrics(directory, test_pressure_kpa)
    n = stored.get("draws") if isinstance(stored.get("draws"), int) else stored.get("n_draws", default)
    return n if isinstance(n, int) and n >= 2 else default


def read_metrics(path: str | Path, test_pressure_kpa: float | None = None) -> dict:
    """The metrics of a result directory (see :func:`evaluate_result`; :func:`metrics_file` for which file), or
    of the metrics file ``path``."""
    path = Path(path)
    file = metrics_file(path, test_pressure_kpa) if path.is_dir() else path
    if not file.exists():
        raise PeanoBayesInputError(f"{file}: no such file; run 'peano-bayes metrics {path}' first")
    out = _read_json(file)
    if "draw_values" not in out or "material" not in out:
        raise PeanoBayesInputError(
            f"{file}: lacks 'material' or 'draw_values' (written by an earlier version?); rerun "
            f"'peano-bayes metrics {path}'"
        )
    return out
