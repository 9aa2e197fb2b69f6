"""What both virtual rigs share: a specimen's noise-free signals (:class:`_Truth`) measured with seeded sensor
noise into runs, the checks of a simulation's arguments, and the dataset's provenance."""

from __future__ import annotations

import dataclasses
import json
import math
import string
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..data import Dataset, Run
from ..data.dataset import OPTIONAL_SIGNALS
from ..errors import PeanoBayesError, PeanoBayesInputError, did_you_mean
from .protocol import _NOISE_STREAM, _SPECIMEN_STREAM, RIG_TESTS, RigNoise, check_parameter

# --- physics drivers (jitted once per configuration) ----------------------------------------------------------


#: Largest equilibrium error the rig accepts from the physics: position [m] in strain-controlled tests (the strain
#: noise is 12 um), force [N] in load-controlled ones (the force noise is 0.2 N).
MAX_POSITION_ERROR_M = 1e-6
MAX_FORCE_ERROR_N = 1e-2


class RigSimulationError(PeanoBayesError, RuntimeError):
    """The physics gave non-finite signals or did not converge for the given parameters (not an input error:
    the parameters may be valid and the solver's tolerance out of reach for them)."""


def _sample_times(rate_hz: float, duration_s: float) -> np.ndarray:
    """Sample times [s] (n,) from 0 to ``duration_s`` at ``rate_hz``."""
    return np.arange(round(duration_s * rate_hz) + 1) / rate_hz


def _checked(what: str, output, tolerance: float, unit: str) -> list[np.ndarray]:
    """The signals of a driver's ``(signals, max_residual)`` as NumPy arrays, after checking them."""
    signals, residual = output
    arrays = [np.asarray(a, dtype=np.float64) for a in signals]
    residual = float(residual)
    if not all(np.all(np.isfinite(a)) for a in arrays):
        raise RigSimulationError(f"{what}: the physics gave non-finite signals for these parameters")
    if not residual <= tolerance:
        raise RigSimulationError(
            f"{what}: the physics did not converge for these parameters (equilibrium error {residual:.3g} {unit}, "
            f"tolerance {tolerance:g} {unit})"
        )
    return arrays


# --- one specimen ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Truth:
    """Noise-free signals of one test condition, SI units; ``None`` where the test does not measure it.
    ``condition`` numbers the conditions of one test (load cycles: 0 at 0 kPa, 1 at the test pressure)."""

    test: str
    condition: int
    time_s: np.ndarray
    pressure_pa: np.ndarray
    strain: np.ndarray
    force_n: np.ndarray | None = None
    supply_pa: np.ndarray | None = None
    flow_m3_per_s: np.ndarray | None = None
    load_n: float | None = None
    added_compliance_m_per_n: float | None = None


def _measure(truth: _Truth, rng: np.random.Generator, noise: RigNoise, drift_offset_s: float | None):
    """Signals of one repeat: the truth plus sensor noise (and force drift from ``drift_offset_s`` on).

    Draws normals in a fixed order (strain, pressure, force, supply, flow), whether or not a signal exists.
    """
    n = truth.time_s.shape[0]
    draws = rng.standard_normal((5, n))
    signals = {
        "time_s": truth.time_s,
        "strain": truth.strain + noise.strain_sd * draws[0],
        "pressure_pa": truth.pressure_pa + noise.pressure_sd_pa * draws[1],
        "force_n": np.full(n, np.nan),
    }
    if truth.force_n is not None:
        force = truth.force_n + noise.force_sd_n * draws[2]
        if drift_offset_s is not None:
            force = force + noise.force_drift_n_per_s * (drift_offset_s + truth.time_s)
        signals["force_n"] = force
    if truth.supply_pa is not None:
        signals["supply_pa"] = truth.supply_pa + noise.pressure_sd_pa * draws[3]
    if truth.flow_m3_per_s is not None:
        signals["flow_m3_per_s"] = truth.flow_m3_per_s + noise.flow_sd_m3_per_s * draws[4]
    if truth.load_n is not None:
        signals["load_n"] = np.full(n, truth.load_n)
    if truth.added_compliance_m_per_n is not None:
        signals["added_compliance_m_per_n"] = np.full(n, truth.added_compliance_m_per_n)
    return signals


def _check_count(name: str, value, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not low <= value <= high:
        raise PeanoBayesInputError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    return int(value)


def _check_tests(tests: Iterable[str]) -> tuple[str, ...]:
    tests = (tests,) if isinstance(tests, str) else tuple(tests)
    for test in tests:
        if test not in RIG_TESTS:
            raise PeanoBayesInputError(
                f"unknown test {test!r}{did_you_mean(test, RIG_TESTS)}; expected some of {', '.join(RIG_TESTS)}"
            )
    if not tests:
        raise PeanoBayesInputError(f"no tests to run; expected some of {', '.join(RIG_TESTS)}")
    return tuple(t for t in RIG_TESTS if t in tests)


def _check_run(seed, repeats, specimens, tests, specimen_spread) -> tuple[int, int, int, tuple[str, ...]]:
    """The checked ``(seed, repeats, specimens, tests)`` of a simulated session, and a valid ``specimen_spread``."""
    checked = (
        _check_count("seed", seed, 0, 2**63 - 1),
        _check_count("repeats", repeats, 1, 100),
        _check_count("specimens", specimens, 1, len(string.ascii_uppercase)),
        _check_tests(tests),
    )
    if not (isinstance(specimen_spread, int | float) and 0 <= specimen_spread <= 1):
        raise PeanoBayesInputError(f"specimen_spread must be a number in [0, 1], got {specimen_spread!r}")
    return checked


def _check_specimen_values(specimen_values, specimens: int) -> list[dict[str, float]]:
    """The checked per-specimen overrides of :func:`simulate_dataset` (empty mappings when none are given)."""
    if specimen_values is None:
        return [{}] * specimens
    values = list(specimen_values)
    if len(values) != specimens:
        raise PeanoBayesInputError(
            f"specimen_values: expected one mapping per specimen ({specimens}), got {len(values)}"
        )
    checked = []
    for index, mapping in enumerate(values):
        if not isinstance(mapping, Mapping):
            raise PeanoBayesInputError(
                f"specimen_values[{index}]: expected a mapping of parameter name to value, got {type(mapping).__name__}"
            )
        try:
            checked.append({name: check_parameter(name, value) for name, value in mapping.items()})
        except PeanoBayesInputError as err:
            raise PeanoBayesInputError(f"specimen_values[{index}]: {err}") from None
    return checked


#: Signals a contribution may be added to before the sensor noise (see :func:`_check_added`).
ADDABLE_SIGNALS: tuple[str, ...] = ("strain", "pressure_pa", "force_n")


def _check_added(added, tests: tuple[str, ...], repeats: int) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """The checked ``added`` of a rig on another physics: ``(test, run) -> {signal: (n,) array}``, a contribution
    added to that run's noise-free signals before the sensor noise (for a benchmark that transplants an effect
    onto another physics). Every key must name a run the session makes (load cycles: runs ``0 .. 2 repeats-1``,
    other tests ``0 .. repeats-1``) and every signal one of :data:`ADDABLE_SIGNALS`; lengths and whether the test
    measures the signal are checked where the signals are made (:func:`_with_added`)."""
    if added is None:
        return {}
    checked = {}
    for key, signals in dict(added).items():
        if not (isinstance(key, tuple) and len(key) == 2 and key[0] in tests and isinstance(key[1], int | np.integer)):
            raise PeanoBayesInputError(
                f"added: expected keys (test, run) with a test among {', '.join(tests)}, got {key!r}"
            )
        test, run = key[0], int(key[1])
        last = (2 if test == "load_cycle" else 1) * repeats - 1
        if not 0 <= run <= last:
            raise PeanoBayesInputError(f"added: the session has {test} runs 0-{last}, got run {run}")
        unknown = [name for name in signals if name not in ADDABLE_SIGNALS]
        if unknown:
            raise PeanoBayesInputError(
                f"added[{key!r}]: cannot add to {', '.join(map(repr, unknown))}; expected some of "
                + ", ".join(ADDABLE_SIGNALS)
            )
        checked[(test, run)] = {name: np.asarray(value, dtype=np.float64) for name, value in signals.items()}
    return checked


def _with_added(truth: _Truth, number: int, added: Mapping) -> _Truth:
    """``truth`` with run ``number``'s contribution from :func:`_check_added` added (itself where there is none)."""
    extra = added.get((truth.test, number))
    if not extra:
        return truth
    changes = {}
    for name, delta in extra.items():
        base = getattr(truth, name)
        if base is None:
            raise PeanoBayesInputError(
                f"added[{(truth.test, number)!r}]: the {truth.test} test does not measure {name}"
            )
        if delta.shape != base.shape:
            raise PeanoBayesInputError(
                f"added[{(truth.test, number)!r}][{name!r}]: expected shape {base.shape}, got {delta.shape}"
            )
        changes[name] = base + delta
    return dataclasses.replace(truth, **changes)


def _other_physics_runs(params, varying, truths_of, *, seed, specimens, spread, noise, repeats, added):
    """The sessions of ``specimens`` specimens of another physics' model: each specimen multiplies the fields of
    ``params`` (a parameter dataclass) named in ``varying`` by its own log-normal factor of sigma ``spread``
    (stream ``[seed, _SPECIMEN_STREAM, index]``), ``truths_of(own parameters)`` gives its noise-free truths, and
    :func:`_session_runs` measures them. Returns ``(base, runs, per_specimen)``: the parameters as a dict, the
    runs, and label -> that specimen's parameters."""
    base = {f.name: float(getattr(params, f.name)) for f in dataclasses.fields(params)}
    runs, per_specimen = [], {}
    for index in range(specimens):
        label = string.ascii_uppercase[index]
        rng = np.random.default_rng([seed, _SPECIMEN_STREAM, index])
        own = {k: v * float(np.exp(spread * rng.standard_normal())) if k in varying else v for k, v in base.items()}
        per_specimen[label] = own
        truths = truths_of(type(params)(**own))
        runs += _session_runs(label, index, truths, seed=seed, noise=noise, repeats=repeats, drift=False, added=added)
    return base, runs, per_specimen


def _static_truths(force, strain_at_force, blocking_force, spec, protocol, tests, cycle_pressures=None) -> list[_Truth]:
    """The noise-free load-cycle, blocking and stroke signals of one specimen of a static model (no hysteresis,
    no dynamics), in session order: ``force(p, strain)`` [N] at pressure p [Pa], ``strain_at_force(p, force)``
    its inverse in strain, ``blocking_force(p)`` [N] at zero strain; load cycles at ``cycle_pressures`` [Pa]
    (default: 0 and the test pressure) from the strain at the start tension down to ``stretch_strain`` (at least
    ``min_stretch`` below the start) and back,
    the blocking force along the pressure ramp, the stroke test's strain where the model carries the hanging
    load. ``spec``: a :class:`~peano_bayes.materials.MaterialSpec`; ``protocol``: a
    :class:`~peano_bayes.rig.RigProtocol`."""
    p_test = spec.test_pressure_pa
    slow = partial(_sample_times, protocol.quasi_static_rate_hz)
    truths = []
    if "load_cycle" in tests:
        t = slow(protocol.cycle_duration_s)
        for condition, p in enumerate((0.0, p_test) if cycle_pressures is None else cycle_pressures):
            start = float(strain_at_force(p, spec.start_tension_n))
            low = min(protocol.stretch_strain, start - protocol.min_stretch)
            strain = np.interp(t, [0.0, 0.5 * t[-1], t[-1]], [start, low, start])
            load = np.asarray(force(p, strain), dtype=float)
            truths.append(_Truth("load_cycle", condition, t, np.full_like(t, p), strain, load))
    if "blocking" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        truths.append(_Truth("blocking", 0, t, ramp, np.zeros_like(t), np.asarray(blocking_force(ramp), dtype=float)))
    if "stroke" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        strain = np.asarray(strain_at_force(ramp, protocol.stroke_load_n), dtype=float)
        truths.append(_Truth("stroke", 0, t, ramp, strain, load_n=protocol.stroke_load_n))
    return truths


def _check_signals(model: str, truths: list[_Truth]) -> None:
    """Check the noise-free signals of a model without a solver residual (explicit formulas, a fixed-step
    integration): finite everywhere, named ``model`` in the error."""
    for truth in truths:
        signals = [x for x in (truth.strain, truth.force_n) if x is not None]
        _checked(f"{model}, {truth.test} test", (signals, 0.0), 0.0, "")


def _other_physics_dataset(
    spec, geometry, runs, *, source, model, per_specimen, seed, noise, spread, protocol, repeats, added, runs_note=None
) -> Dataset:
    """The :class:`~peano_bayes.data.Dataset` of another physics' ``runs`` on ``geometry``, its provenance naming
    the generating ``model`` (:func:`_provenance`), the load cycles' pressures where ``runs_note`` says them, and
    the runs that ``added`` (:func:`_check_added`) changed."""
    provenance = _provenance(
        source=source,
        seed=seed,
        model=model,
        per_specimen=per_specimen,
        noise=noise,
        drift=False,
        spread=spread,
        protocol=protocol,
        repeats=repeats,
    )
    if runs_note is not None:
        provenance["runs"] = runs_note
    if added:
        provenance["added"] = json.dumps({f"{test} {run}": sorted(signals) for (test, run), signals in added.items()})
    return Dataset(
        material=spec.data_material(),
        geometry=geometry,
        conditions=spec.conditions(),
        runs=_fill_optional(runs),
        provenance=provenance,
    )


def _session_runs(label: str, index: int, truths, *, seed: int, noise: RigNoise, repeats: int, drift: bool, added=None):
    """Specimen ``label``'s measured runs: ``repeats`` noisy repeats of each noise-free truth, in session order
    (noise streams keyed by specimen ``index``, test and run number; drift grows over the session). ``added``:
    the checked contributions of :func:`_check_added`, added to a run's truth before its noise (which they do
    not change)."""
    runs, session_s = [], 0.0
    for truth in truths:
        first_run = truth.condition * repeats
        for number in range(first_run, first_run + repeats):
            rng = np.random.default_rng([seed, _NOISE_STREAM, index, RIG_TESTS.index(truth.test), number])
            measured = _with_added(truth, number, added) if added else truth
            runs.append(Run(label, truth.test, number, **_measure(measured, rng, noise, session_s if drift else None)))
            session_s += float(truth.time_s[-1])
    return runs


def _fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


def _check_mounts(added_compliances) -> tuple[float, ...]:
    mounts = tuple(added_compliances)
    if not 1 <= len(mounts) <= 4 or not all(
        isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c) and 0 <= c <= 1e-3 for c in mounts
    ):
        raise PeanoBayesInputError(
            f"added_compliances must be 1 to 4 numbers in [0, 1e-3] m/N (one per mount), got {added_compliances!r}"
        )
    return tuple(float(c) for c in mounts)


def _fill_optional(runs: list[Run]) -> tuple[Run, ...]:
    """Give every run the optional signals any run has (NaN where it does not measure them)."""
    present = [name for name in OPTIONAL_SIGNALS if any(getattr(r, name) is not None for r in runs)]
    filled = []
    for run in runs:
        missing = {name: np.full(len(run), np.nan) for name in present if getattr(run, name) is None}
        filled.append(dataclasses.replace(run, **missing) if missing else run)
    return tuple(filled)


def _model_provenance(quirks, config, params, fallback, ignored) -> dict[str, str]:
    """The provenance entries of data from the package's own physics: quirks, configuration and parameters."""
    return {
        "quirks": ", ".join(quirks) if quirks else "none",
        "config": json.dumps(_fields(config)),
        "parameters": json.dumps(params),
        "nominal_fallback": ", ".join(fallback) if fallback else "none",
        "ignored_parameters": ", ".join(ignored) if ignored else "none",
    }


def _provenance(*, source, seed, model, per_specimen, noise, drift, spread, protocol, repeats) -> dict[str, str]:
    """The sidecar's ``[provenance]``: every fact needed to regenerate the data, as strings (JSON for tables);
    ``model``: the generating model's own entries, placed after the seed."""
    from .. import __version__

    return {
        "source": source,
        "synthetic": "true",
        "generator": f"peano_bayes {__version__}",
        "seed": str(seed),
        **model,
        "specimen_spread": repr(float(spread)),
        "specimen_parameters": json.dumps(per_specimen),
        "noise": json.dumps(_fields(noise)),
        "drift": "true" if drift else "false",
        "protocol": json.dumps(_fields(protocol)),
        "runs": f"load_cycle runs 0-{repeats - 1} at 0 kPa, {repeats}-{2 * repeats - 1} at the test pressure",
    }


__all__ = ["MAX_FORCE_ERROR_N", "MAX_POSITION_ERROR_M", "RigSimulationError"]
