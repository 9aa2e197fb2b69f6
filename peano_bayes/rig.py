"""Virtual test rig: runs the paper's test protocol on the JAX physics and returns a rig :class:`Dataset`.

The protocol follows Veale, Xie, Anderson (2016), sections 3-4 and Table 4: two specimens of a material, three
repeats of every test on each; load cycles at 0 kPa and at the material's test pressure, starting at the strain
where the relaxed muscle carries the Table 4 start tension and stretching to -1.5 % strain and back; a blocking
test (pressure ramp at zero strain); a stroke test (pressure ramp lifting 5.5 N); a step response (supply step
through the inlet restriction lifting the Table 4 step load). Specimens differ by a seeded log-normal factor on
their stiffness-like parameters; repeats differ by sensor noise only (and by the force sensor's drift, if on).

Sampling (the paper does not state its rates; these are typical of such a rig): **20 Hz** for the quasi-static
tests (load cycles of 40 s: 801 samples; ramps of 20 s: 401 samples), which resolves a 40 s cycle far better
than the few-percent features a fit needs, and **1 kHz** for the 0.8 s step response (801 samples), ten to a
hundred samples per period of the 10-100 Hz load oscillation (two integration substeps per sample).

The physics is pure JAX (:mod:`peano_bayes.physics`); this module only drives it, adds seeded sensor noise
with NumPy, and builds the dataset. Write it with :func:`peano_bayes.data.save`.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
import string
import tomllib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import materials
from .data import Dataset, Run
from .data.dataset import OPTIONAL_SIGNALS
from .data.format import TESTS
from .defaults import MAX_PRESSURE_KPA
from .errors import PeanoBayesError, PeanoBayesInputError, did_you_mean
from .materials import GEOMETRY, MaterialSpec
from .physics import (
    DEFAULT_CONFIG,
    PARAMETERS,
    Blocking,
    LoadCycle,
    ModelConfig,
    Step,
    Stroke,
    simulate_blocking,
    simulate_load_cycle,
    simulate_step,
    simulate_stroke,
    static_strain,
)
from .physics.reference import VEALE_TABLE2, veale_blocking_force, veale_force, veale_free_strain

# --- settings -------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RigNoise:
    """Sensor noise (independent Gaussian, standard deviations) and force-sensor drift of the virtual rig.

    **Fields:** ``force_sd_n`` [N] (load cell; about 1 % of a 30 kPa muscle's load-cycle force range, less at
    200 kPa); ``strain_sd`` [-] (2e-4 of l0 = 0.06 m is 12 um of position noise); ``pressure_sd_pa`` [Pa]
    (0.5 kPa, a 1 MPa transducer at 0.05 % of full scale; also applied to the supply pressure); ``flow_sd_m3_per_s``
    [m^3/s] (0.5 mL/s, against step flows of tens of mL/s); ``force_drift_n_per_s`` [N/s], the slope of the
    load cell's zero drift when ``drift`` is on (0.002 N/s: about 0.1 N over a load cycle, 0.7 N over a
    specimen's whole session).
    """

    force_sd_n: float = 0.2
    strain_sd: float = 2e-4
    pressure_sd_pa: float = 500.0
    flow_sd_m3_per_s: float = 5e-7
    force_drift_n_per_s: float = 0.002

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise PeanoBayesInputError(f"RigNoise.{f.name} must be a finite number, got {value!r}")
            if f.name != "force_drift_n_per_s" and value < 0:
                raise PeanoBayesInputError(f"RigNoise.{f.name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class RigProtocol:
    """Timing and amplitudes of the rig tests, SI units.

    **Fields:** ``quasi_static_rate_hz`` [Hz], sampling of load cycles, blocking and stroke tests;
    ``cycle_duration_s`` [s], one load cycle (stretch then relax, linear in time); ``ramp_duration_s`` [s], the
    pressure ramp of blocking and stroke tests; ``stretch_strain`` [-], the lowest strain of a load cycle (the
    paper quotes stiffness at -1.5 %); ``min_stretch`` [-], the least a cycle stretches below its start strain
    (used when the start tension already stretches the muscle past ``stretch_strain``); ``stroke_load_n`` [N],
    the stroke test's hanging load (Table 3: 5.5 N); ``step_rate_hz`` [Hz] and ``step_duration_s`` [s] of the
    step response; ``step_delay_s`` [s], the time before the supply steps; ``step_substeps``, integration
    steps per sample interval.
    """

    quasi_static_rate_hz: float = 20.0
    cycle_duration_s: float = 40.0
    ramp_duration_s: float = 20.0
    stretch_strain: float = -0.015
    min_stretch: float = 0.005
    stroke_load_n: float = 5.5
    step_rate_hz: float = 1000.0
    step_duration_s: float = 0.8
    step_delay_s: float = 0.05
    step_substeps: int = 2

    def __post_init__(self):
        for name in ("quasi_static_rate_hz", "cycle_duration_s", "ramp_duration_s", "step_rate_hz", "step_duration_s"):
            if not getattr(self, name) > 0:
                raise PeanoBayesInputError(f"RigProtocol.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 <= self.step_delay_s < self.step_duration_s:
            raise PeanoBayesInputError(
                f"RigProtocol.step_delay_s must be in [0, step_duration_s), got {self.step_delay_s!r}"
            )
        if not (isinstance(self.step_substeps, int) and self.step_substeps >= 1):
            raise PeanoBayesInputError(f"RigProtocol.step_substeps must be an integer >= 1, got {self.step_substeps!r}")


DEFAULT_NOISE = RigNoise()
DEFAULT_PROTOCOL = RigProtocol()
#: The rig tests in the order a specimen's session runs them.
RIG_TESTS: tuple[str, ...] = tuple(TESTS)

# --- quirks ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Quirk:
    """A physical effect the rig can switch on: its ``name`` (as in :data:`peano_bayes.discovery.effects.LIBRARY`),
    what it is, and ``switch``, which returns the model configuration with the element on (unchanged if it
    already is)."""

    name: str
    meaning: str
    switch: Callable[[ModelConfig], ModelConfig]


def _replace(**changes) -> Callable[[ModelConfig], ModelConfig]:
    return lambda config: dataclasses.replace(config, **changes)


_QUIRK_LIST = (
    Quirk("series_compliance", "compliant mount tab in series (mount_compliance_m_per_n)", _replace(mount=True)),
    Quirk(
        "hysteresis",
        "rate-independent Dahl friction across the contractile unit (friction_*)",
        lambda c: c if c.friction != "none" else dataclasses.replace(c, friction="parallel"),
    ),
    Quirk(
        "viscoelastic_relaxation",
        "a Maxwell branch across the contractile unit (parallel_maxwell1_*)",
        lambda c: dataclasses.replace(c, parallel_maxwell=max(c.parallel_maxwell, 1)),
    ),
    Quirk(
        "series_viscoelastic",
        "a Kelvin-Voigt unit in series with the tensile spring (series_kelvin1_*)",
        lambda c: dataclasses.replace(c, series_kelvin=max(c.series_kelvin, 1)),
    ),
    Quirk("strain_stiffening", "passive stiffening in extension (extension_*)", _replace(extension=True)),
    Quirk(
        "threshold_pressure",
        "pressure below which the tubes stay shut (threshold_pressure_pa)",
        _replace(threshold=True),
    ),
    Quirk("nonlinear_damping", "direction-dependent and quadratic load damping (damping_*)", _replace(damping=True)),
)
#: name -> :class:`Quirk`, the effects that map onto a switch of :class:`ModelConfig`.
QUIRKS: dict[str, Quirk] = {q.name: q for q in _QUIRK_LIST}
#: Effects that are parameter values of every model rather than switches.
_NOT_SWITCHES = {
    "bending_stiffness": "set bending_k1_n / bending_k2_n instead",
    "tensile_stiffness": "set tensile_ka_n_per_m / tensile_kb_n_per_m2 instead",
    "flow_restriction": 'set orifice_area_m2 (or [config] flow = "laminar") instead',
    "cyclic_softening": "the physics has no such element yet",
}


def check_quirks(quirks: Iterable[str]) -> tuple[str, ...]:
    """Quirk names in order, duplicates removed; an unknown name raises :class:`PeanoBayesInputError`."""
    if isinstance(quirks, str):
        quirks = (quirks,)
    names = tuple(dict.fromkeys(quirks))
    for name in names:
        if name in QUIRKS:
            continue
        known = ", ".join(QUIRKS)
        if name in _NOT_SWITCHES:
            raise PeanoBayesInputError(
                f"effect {name!r} is not a quirk the rig can switch on ({_NOT_SWITCHES[name]}); known quirks: {known}"
            )
        raise PeanoBayesInputError(f"unknown quirk {name!r}{did_you_mean(name, QUIRKS)}; known quirks: {known}")
    return names


def apply_quirks(config: ModelConfig, quirks: Iterable[str]) -> ModelConfig:
    """``config`` with the elements of ``quirks`` (names of :data:`QUIRKS`) switched on."""
    for name in check_quirks(quirks):
        config = QUIRKS[name].switch(config)
    return config


# --- parameters -----------------------------------------------------------------------------------------------


def check_parameter(name: str, value) -> float:
    """``value`` of parameter ``name`` as a float [SI unit of :data:`PARAMETERS`]; raises
    :class:`PeanoBayesInputError` for an unknown name (with a did-you-mean), a non-number or a value outside
    the parameter's physical bounds."""
    if name not in PARAMETERS:
        raise PeanoBayesInputError(
            f"unknown parameter {name!r}{did_you_mean(name, PARAMETERS)}; expected names of "
            "peano_bayes.physics.PARAMETERS, in SI units (e.g. tensile_ka_n_per_m)"
        )
    spec = PARAMETERS[name]
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise PeanoBayesInputError(f"parameter {name!r} must be a number ({spec.unit}), got {value!r}")
    value = float(value)
    low, high = spec.bounds
    if not (math.isfinite(value) and low <= value <= high):
        raise PeanoBayesInputError(
            f"parameter {name!r} = {value!r} is outside its physical bounds [{low:g}, {high:g}] ({spec.unit})"
        )
    return value


def resolve_parameters(true_params: Mapping[str, float] | None, config: ModelConfig) -> tuple[dict, tuple]:
    """The parameters ``config`` reads, in its order: from ``true_params``, else ``PARAMETERS[name].nominal``.

    Every given name is checked (:func:`check_parameter`); names the configuration does not read are ignored.
    Returns ``(params, fallback_names)``, the floats [SI] and the names that took their nominal value.
    """
    given = {name: check_parameter(name, value) for name, value in (true_params or {}).items()}
    names = config.parameter_names()
    params = {name: given.get(name, PARAMETERS[name].nominal) for name in names}
    return params, tuple(name for name in names if name not in given)


def _stiffness_sign(name: str) -> int:
    """+1 for a stiffness-like parameter (scaled by the specimen factor), -1 for a compliance, 0 otherwise."""
    if name.endswith(("_n_per_m", "_n_per_m2")) or name in ("bending_k1_n", "bending_k2_n"):
        return 1
    return -1 if name == "mount_compliance_m_per_n" else 0


def specimen_parameters(params: Mapping[str, float], spread: float, rng: np.random.Generator) -> dict[str, float]:
    """One specimen's parameters: each stiffness-like parameter (units N/m, N/m^2, and the bending
    stiffnesses in N) times its own log-normal factor ``exp(spread z)``, ``z ~ N(0, 1)``; the mount compliance
    divided by one; the result clipped to the parameter bounds. Other parameters are shared by all specimens.
    Draws one normal per parameter, in the order of ``params``."""
    out = {}
    for name, value in params.items():
        z = rng.standard_normal()
        sign = _stiffness_sign(name)
        if sign:
            value = float(np.clip(value * math.exp(sign * spread * z), *PARAMETERS[name].bounds))
        out[name] = value
    return out


def read_parameter_file(path: str | Path) -> tuple[dict[str, float], ModelConfig]:
    """Read ``PARAMS.toml``: ``[parameters]`` name = value (SI units, names of :data:`PARAMETERS`) and an
    optional ``[config]`` with :class:`ModelConfig` fields (missing fields take their defaults).

    Returns ``(parameters, config)``; parameters not in the file are absent (the rig uses nominal values).
    **Raises:** :class:`PeanoBayesInputError` naming the file and the key for any problem.
    """
    path = Path(path)
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PeanoBayesInputError(f"{path}: file not found; expected a TOML file with a [parameters] table") from None
    except (OSError, UnicodeDecodeError) as err:
        raise PeanoBayesInputError(f"{path}: cannot read the file ({err})") from None
    except tomllib.TOMLDecodeError as err:
        raise PeanoBayesInputError(f"{path}: not valid TOML ({err})") from None
    for section, content in document.items():
        if section not in ("parameters", "config"):
            raise PeanoBayesInputError(
                f"{path}: unknown section [{section}]{did_you_mean(section, ('parameters', 'config'), brackets=True)}; "
                "expected [parameters] and optionally [config]"
            )
        if not isinstance(content, dict):
            raise PeanoBayesInputError(f"{path}: {section} must be a [{section}] table, got {content!r}")
    try:
        params = {name: check_parameter(name, v) for name, v in document.get("parameters", {}).items()}
    except PeanoBayesInputError as err:
        raise PeanoBayesInputError(f"{path}: [parameters]: {err}") from None
    return params, _config_from_table(document.get("config", {}), path)


def _config_from_table(table: Mapping, path: Path) -> ModelConfig:
    defaults = {f.name: f.default for f in dataclasses.fields(ModelConfig)}
    for key, value in table.items():
        if key not in defaults:
            raise PeanoBayesInputError(
                f"{path}: [config]: unknown field {key!r}{did_you_mean(key, defaults)}; "
                f"expected ModelConfig fields: {', '.join(defaults)}"
            )
        kind = type(defaults[key])
        if type(value) is not kind:
            raise PeanoBayesInputError(
                f"{path}: [config]: {key} must be {kind.__name__} like the default {defaults[key]!r}, got {value!r}"
            )
    try:
        return ModelConfig(**table)
    except ValueError as err:
        raise PeanoBayesInputError(f"{path}: [config]: {err}") from None


# --- physics drivers (jitted once per configuration) ----------------------------------------------------------


#: Largest equilibrium error the rig accepts from the physics: position [m] in strain-controlled tests (the strain
#: noise is 12 um), force [N] in load-controlled ones (the force noise is 0.2 N).
MAX_POSITION_ERROR_M = 1e-6
MAX_FORCE_ERROR_N = 1e-2


class RigSimulationError(PeanoBayesError, RuntimeError):
    """The physics gave non-finite signals or did not converge for the given parameters (not an input error:
    the parameters may be valid and the solver's tolerance out of reach for them)."""


@partial(jax.jit, static_argnames="config")
def _load_cycle(params, time_s, pressure_pa, start_tension_n, stretch_strain, min_stretch, *, config):
    """Imposed strain (n,) and force [N] (n,) of a cycle from the start-tension strain down and back."""
    start = static_strain(params, pressure_pa, start_tension_n, config=config)
    low = jnp.minimum(stretch_strain, start - min_stretch)
    end_s = time_s[-1]
    strain = jnp.interp(time_s, jnp.stack([0.0, 0.5 * end_s, end_s]), jnp.stack([start, low, start]))
    result = simulate_load_cycle(params, LoadCycle(time_s, strain, jnp.full_like(time_s, pressure_pa)), config=config)
    return (strain, result.force_n), result.max_residual


@partial(jax.jit, static_argnames="config")
def _blocking(params, time_s, pressure_pa, *, config):
    result = simulate_blocking(params, Blocking(time_s, pressure_pa), config=config)
    return (result.force_n,), result.max_residual


@partial(jax.jit, static_argnames="config")
def _stroke(params, time_s, pressure_pa, load_n, *, config):
    result = simulate_stroke(params, Stroke(time_s, pressure_pa, load_n), config=config)
    return (result.strain,), result.max_residual


@partial(jax.jit, static_argnames=("config", "substeps"))
def _step(params, time_s, supply_pa, load_n, *, config, substeps):
    result = simulate_step(params, Step(time_s, supply_pa, load_n, substeps), config=config)
    return (result.strain, result.pressure_pa, result.flow_m3_per_s), result.max_residual


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


def _specimen_truths(params, spec: MaterialSpec, config, protocol: RigProtocol, tests, progress, label):
    """The noise-free signals of every test condition of one specimen, in session order."""
    jparams = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in params.items()}
    p_test = spec.test_pressure_pa
    slow = partial(_sample_times, protocol.quasi_static_rate_hz)
    truths = []
    if "load_cycle" in tests:
        t = slow(protocol.cycle_duration_s)
        for condition, p in enumerate((0.0, p_test)):
            output = _load_cycle(
                jparams, t, p, spec.start_tension_n, protocol.stretch_strain, protocol.min_stretch, config=config
            )
            strain, force = _checked(f"{label}: load cycle at {p / 1e3:g} kPa", output, MAX_POSITION_ERROR_M, "m")
            truths.append(_Truth("load_cycle", condition, t, np.full_like(t, p), strain, force))
            progress(f"{label}: load cycle at {p / 1e3:g} kPa")
    if "blocking" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        output = _blocking(jparams, t, ramp, config=config)
        (force,) = _checked(f"{label}: blocking", output, MAX_POSITION_ERROR_M, "m")
        truths.append(_Truth("blocking", 0, t, ramp, np.zeros_like(t), force))
        progress(f"{label}: blocking to {p_test / 1e3:g} kPa")
    if "stroke" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        output = _stroke(jparams, t, ramp, protocol.stroke_load_n, config=config)
        (strain,) = _checked(f"{label}: stroke", output, MAX_FORCE_ERROR_N, "N")
        truths.append(_Truth("stroke", 0, t, ramp, strain, load_n=protocol.stroke_load_n))
        progress(f"{label}: stroke lifting {protocol.stroke_load_n:g} N")
    if "step" in tests:
        t = _sample_times(protocol.step_rate_hz, protocol.step_duration_s)
        supply = np.where(t >= protocol.step_delay_s, p_test, 0.0)
        output = _step(jparams, t, supply, spec.step_load_n, config=config, substeps=protocol.step_substeps)
        strain, pressure, flow = _checked(f"{label}: step", output, MAX_FORCE_ERROR_N, "N")
        truths.append(_Truth("step", 0, t, pressure, strain, None, supply, flow, spec.step_load_n))
        progress(f"{label}: step to {p_test / 1e3:g} kPa lifting {spec.step_load_n:g} N")
    return truths


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


# --- the dataset ----------------------------------------------------------------------------------------------

_SPECIMEN_STREAM, _NOISE_STREAM = 0, 1


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


def _session_runs(label: str, index: int, truths, *, seed: int, noise: RigNoise, repeats: int, drift: bool):
    """Specimen ``label``'s measured runs: ``repeats`` noisy repeats of each noise-free truth, in session order
    (noise streams keyed by specimen ``index``, test and run number; drift grows over the session)."""
    runs, session_s = [], 0.0
    for truth in truths:
        first_run = truth.condition * repeats
        for number in range(first_run, first_run + repeats):
            rng = np.random.default_rng([seed, _NOISE_STREAM, index, RIG_TESTS.index(truth.test), number])
            runs.append(Run(label, truth.test, number, **_measure(truth, rng, noise, session_s if drift else None)))
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


def simulate_dataset(
    material: str | MaterialSpec,
    true_params: Mapping[str, float] | None = None,
    *,
    config: ModelConfig = DEFAULT_CONFIG,
    quirks: Iterable[str] = (),
    seed: int = 0,
    noise: RigNoise = DEFAULT_NOISE,
    drift: bool = False,
    specimen_spread: float = 0.05,
    repeats: int = 3,
    specimens: int = 2,
    tests: Iterable[str] = RIG_TESTS,
    protocol: RigProtocol = DEFAULT_PROTOCOL,
    progress: Callable[[str], None] | None = None,
    added_compliances: Iterable[float] = (0.0,),
    specimen_values: Sequence[Mapping[str, float]] | None = None,
) -> Dataset:
    """Run the paper's test protocol on virtual specimens of a material; return the rig dataset.

    **Arguments:**
    - ``material``: a Table 4 code (``"FC"``) or a :class:`~peano_bayes.materials.MaterialSpec`; it sets
      the test pressure, step load and start tension (:mod:`peano_bayes.materials`).
    - ``true_params``: parameter values [SI units, names of :data:`~peano_bayes.physics.PARAMETERS`]. Every
      parameter the final configuration reads and ``true_params`` lacks takes ``PARAMETERS[name].nominal``,
      also for quirks (note: the nominal load damping is 0, so ``nonlinear_damping`` needs
      ``damping_*`` values to have an effect). Names the configuration does not read are ignored.
    - ``config``: the model the data come from; ``quirks``: names of :data:`QUIRKS` (effects) whose elements
      are switched on in ``config`` (``series_compliance`` -> ``mount``, ``hysteresis`` -> Dahl friction,
      ``viscoelastic_relaxation`` -> one parallel Maxwell branch, ``series_viscoelastic`` -> one series
      Kelvin-Voigt unit, ``strain_stiffening`` -> ``extension``,
      ``threshold_pressure`` -> ``threshold``, ``nonlinear_damping`` -> ``damping``).
    - ``seed``: every random draw derives from it; the same arguments give the same dataset, and the same bytes
      through :func:`peano_bayes.data.save`. Streams are keyed by (specimen, test, run), so a
      smaller run reproduces the matching part of a larger one.
    - ``noise``: :class:`RigNoise`; ``drift``: add the force sensor's linear drift, zeroed at the start of each
      specimen's session and growing through the runs in session order (runs follow without pauses).
    - ``specimen_spread``: sigma of the log-normal factor on each stiffness-like parameter per specimen
      (:func:`specimen_parameters`); ``specimens`` (named A, B, ...) and ``repeats`` per test (paper: 2 and 3).
    - ``tests``: which of ``load_cycle``, ``blocking``, ``stroke``, ``step`` to run (default: all);
      ``protocol``: :class:`RigProtocol`; ``progress``: called with a line of text after each simulated test.
    - ``added_compliances`` [m/N]: the mounts each specimen is tested on, as the known compliance each adds in
      series with the specimen's own mount (default one mount, nothing added). With several, the whole
      protocol runs once per mount, in this order, and every run records its mount in
      ``added_compliance_m_per_n``; run numbers continue across mounts (the second mount's load cycles at
      0 kPa are runs ``2 repeats .. 3 repeats-1``). A positive one switches the mount element on (the
      specimen's own mount then defaults to 0, rigid).
    - ``specimen_values``: one mapping per specimen (``specimens`` of them) of parameter values [SI] that
      specimen has, replacing its drawn value of each name given (for studies that draw the specimens
      themselves, such as the hierarchical simulation-based calibration); every name and value is checked as
      in ``true_params``, and every name must be one the final configuration reads. ``true_params`` (the
      provenance's ``parameters``) then holds the values the specimens were not given.

    **Returns:** a :class:`~peano_bayes.data.Dataset` on :data:`~peano_bayes.physics.PAPER_GEOMETRY`. Load cycle
    runs ``0 .. repeats-1`` are at 0 kPa, ``repeats .. 2 repeats-1`` at the test pressure. ``force_n`` is NaN in
    stroke and step runs (the format does not need it there); ``load_n`` holds the stroke and step loads;
    ``supply_pa`` and ``flow_m3_per_s`` are filled in step runs; an optional signal present in some run is NaN
    in the others, exactly as :func:`peano_bayes.data.load` reads it back. The provenance records that the data
    is synthetic, the seed, quirks, configuration, true and per-specimen parameters, noise and protocol.

    **Raises:** :class:`~peano_bayes.errors.PeanoBayesInputError` for an unknown material, quirk, parameter or
    test, a parameter outside its bounds, or bad counts; nothing is simulated before all inputs are checked.
    """
    spec = materials.material(material)
    quirk_names = check_quirks(quirks)
    final_config = apply_quirks(config, quirk_names)
    mounts = _check_mounts(added_compliances)
    if any(c > 0 for c in mounts) and not final_config.mount:
        final_config = dataclasses.replace(final_config, mount=True)
        true_params = {"mount_compliance_m_per_n": PARAMETERS["mount_compliance_m_per_n"].off, **(true_params or {})}
    params, fallback = resolve_parameters(true_params, final_config)
    seed, repeats, specimens, tests = _check_run(seed, repeats, specimens, tests, specimen_spread)
    overrides = _check_specimen_values(specimen_values, specimens)
    for index, mapping in enumerate(overrides):
        unread = [name for name in mapping if name not in params]
        if unread:
            raise PeanoBayesInputError(
                f"specimen_values[{index}]: the simulated model does not read {', '.join(map(repr, unread))}; "
                "switch its element on (config or quirks) or leave the name out"
            )
    report = progress or (lambda line: None)

    runs, per_specimen = [], {}
    for index in range(specimens):
        label = string.ascii_uppercase[index]
        own = specimen_parameters(params, specimen_spread, np.random.default_rng([seed, _SPECIMEN_STREAM, index]))
        own.update(overrides[index])
        per_specimen[label] = own
        truths, earlier = [], collections.Counter()  # conditions per test on the mounts before
        for added in mounts:
            mounted = dict(own)
            if added > 0:
                mounted["mount_compliance_m_per_n"] = own["mount_compliance_m_per_n"] + added
            batch = _specimen_truths(mounted, spec, final_config, protocol, tests, report, label)
            truths += [
                dataclasses.replace(
                    t,
                    condition=t.condition + earlier[t.test],
                    added_compliance_m_per_n=added if mounts != (0.0,) else None,
                )
                for t in batch
            ]
            earlier.update(t.test for t in batch)
        runs += _session_runs(label, index, truths, seed=seed, noise=noise, repeats=repeats, drift=drift)
    return Dataset(
        material=spec.data_material(),
        geometry=GEOMETRY,
        conditions=spec.conditions(),
        runs=_fill_optional(runs),
        provenance=_provenance(
            source="synthetic: peano_bayes virtual rig (peano_bayes.rig.simulate_dataset), not a measurement",
            seed=seed,
            model=_model_provenance(
                quirk_names, final_config, params, fallback, tuple(n for n in (true_params or {}) if n not in params)
            ),
            per_specimen=per_specimen,
            noise=noise,
            drift=drift,
            spread=specimen_spread,
            protocol=protocol,
            repeats=repeats,
        ),
    )


# --- the same protocol on another physics: Veale's force-balance model ------------------------------------------

#: The tests Veale's static model can run (it has no dynamics, so no step response).
VEALE_TESTS: tuple[str, ...] = ("load_cycle", "blocking", "stroke")
#: Fields of :class:`~peano_bayes.physics.reference.VealeParameters` that vary between specimens (stiffnesses).
VEALE_VARYING = ("tensile_ka_n_per_m", "tensile_kb_n_per_m2", "bending_quartic_n_per_m5", "bending_linear_n_per_m2")
#: Halvings of the strain bracket in :func:`_veale_strain_at_force` (0.5 in strain to below 1e-15).
_VEALE_BISECTIONS = 60


@jax.jit
def _veale_strain_at_force(pressure_pa, force_n, params):
    """Strain [-] at which Veale's muscle carries ``force_n`` [N] at each ``pressure_pa`` [Pa] (any shape).

    The force falls monotonically with strain between a strongly stretched muscle (-0.3) and the free strain
    (force 0), so bisection over that bracket finds the one root of a positive ``force_n``."""
    pressure_pa = jnp.asarray(pressure_pa, dtype=jnp.float64)

    def halve(_, bracket):
        low, high = bracket
        mid = 0.5 * (low + high)
        above = veale_force(pressure_pa, mid, params) > force_n
        return jnp.where(above, mid, low), jnp.where(above, high, mid)

    start = (jnp.full(pressure_pa.shape, -0.3), veale_free_strain(pressure_pa, params))
    low, high = jax.lax.fori_loop(0, _VEALE_BISECTIONS, halve, start)
    return 0.5 * (low + high)


_veale_force = jax.jit(veale_force)
_veale_blocking_force = jax.jit(veale_blocking_force)


def _veale_truths(params, spec: MaterialSpec, protocol: RigProtocol, tests, cycle_pressures=None) -> list[_Truth]:
    """The noise-free signals of every test condition of one specimen of Veale's model, in session order; load
    cycles at ``cycle_pressures`` [Pa] (default: 0 and the test pressure)."""
    p_test = spec.test_pressure_pa
    slow = partial(_sample_times, protocol.quasi_static_rate_hz)
    truths = []
    if "load_cycle" in tests:
        t = slow(protocol.cycle_duration_s)
        for condition, p in enumerate((0.0, p_test) if cycle_pressures is None else cycle_pressures):
            start = float(_veale_strain_at_force(p, spec.start_tension_n, params))
            low = min(protocol.stretch_strain, start - protocol.min_stretch)
            strain = np.interp(t, [0.0, 0.5 * t[-1], t[-1]], [start, low, start])
            force = np.asarray(_veale_force(p, strain, params), dtype=float)
            truths.append(_Truth("load_cycle", condition, t, np.full_like(t, p), strain, force))
    if "blocking" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        force = np.asarray(_veale_blocking_force(ramp, params), dtype=float)
        truths.append(_Truth("blocking", 0, t, ramp, np.zeros_like(t), force))
    if "stroke" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        strain = np.asarray(_veale_strain_at_force(ramp, protocol.stroke_load_n, params), dtype=float)
        truths.append(_Truth("stroke", 0, t, ramp, strain, load_n=protocol.stroke_load_n))
    for truth in truths:  # a static model has no solver residual: only the signals are checked
        signals = [x for x in (truth.strain, truth.force_n) if x is not None]
        _checked(f"Veale's model, {truth.test} test", (signals, 0.0), 0.0, "")
    return truths


def simulate_veale_dataset(
    material: str | MaterialSpec,
    params=None,
    *,
    seed: int = 0,
    noise: RigNoise = DEFAULT_NOISE,
    specimen_spread: float = 0.05,
    repeats: int = 3,
    specimens: int = 2,
    tests: Iterable[str] = VEALE_TESTS,
    protocol: RigProtocol = DEFAULT_PROTOCOL,
    cycle_pressures_pa: Iterable[float] | None = None,
) -> Dataset:
    """The rig's quasi-static protocol run on Veale's force-balance model instead of peano_bayes' own physics:
    data from another model of the same muscle, for checks that must not share the fitted model's assumptions
    (an inference on it cannot succeed by construction).

    Same protocol, conditions, sensor noise, seeding and file layout as :func:`simulate_dataset`, with the
    signals of :func:`~peano_bayes.physics.reference.veale_force`: load cycles from the strain at the start
    tension down to ``stretch_strain`` and back (static: no hysteresis), the blocking force along the pressure
    ramp, and the stroke test's strain where the muscle carries the hanging load. ``params``: a
    :class:`~peano_bayes.physics.reference.VealeParameters` (default: the paper's Table 2); each specimen
    multiplies the stiffnesses of :data:`VEALE_VARYING` by its own log-normal factor of sigma
    ``specimen_spread``. ``tests``: some of :data:`VEALE_TESTS`. ``cycle_pressures_pa``: the load cycles'
    pressures [Pa], one condition each (default: 0 and the material's test pressure; each in [0, 1 MPa]). The
    provenance names the generating model and
    every specimen's parameters. Raises :class:`~peano_bayes.errors.PeanoBayesInputError` for bad input
    (a step test among them: the static model has no dynamics), before anything is simulated.
    """
    params = VEALE_TABLE2 if params is None else params
    spec = materials.material(material)
    seed, repeats, specimens, tests = _check_run(seed, repeats, specimens, tests, specimen_spread)
    if "step" in tests:
        raise PeanoBayesInputError(
            "Veale's force-balance model is static and cannot run a step test; expected some of "
            + ", ".join(VEALE_TESTS)
        )
    if cycle_pressures_pa is not None:
        cycle_pressures_pa = tuple(float(p) for p in cycle_pressures_pa)
        limit_pa = MAX_PRESSURE_KPA * 1e3
        if not cycle_pressures_pa or not all(math.isfinite(p) and 0 <= p <= limit_pa for p in cycle_pressures_pa):
            raise PeanoBayesInputError(
                f"cycle_pressures_pa must be one or more pressures in [0, {limit_pa:g}] Pa, got "
                f"{cycle_pressures_pa!r}"
            )
    base = {f.name: float(getattr(params, f.name)) for f in dataclasses.fields(params)}
    runs, per_specimen = [], {}
    for index in range(specimens):
        label = string.ascii_uppercase[index]
        rng = np.random.default_rng([seed, _SPECIMEN_STREAM, index])
        own = {k: v * float(np.exp(specimen_spread * rng.standard_normal())) if k in VEALE_VARYING else v
               for k, v in base.items()}  # fmt: skip
        per_specimen[label] = own
        truths = _veale_truths(type(params)(**own), spec, protocol, tests, cycle_pressures_pa)
        runs += _session_runs(label, index, truths, seed=seed, noise=noise, repeats=repeats, drift=False)
    provenance = _provenance(
        source="synthetic: Veale's force-balance model (peano_bayes.rig.simulate_veale_dataset), not a "
        "measurement and not peano_bayes' own physics",
        seed=seed,
        model={"model": "veale_force_balance", "parameters": json.dumps(base)},
        per_specimen=per_specimen,
        noise=noise,
        drift=False,
        spread=specimen_spread,
        protocol=protocol,
        repeats=repeats,
    )
    if cycle_pressures_pa is not None:
        provenance["runs"] = "; ".join(
            f"load_cycle runs {c * repeats}-{(c + 1) * repeats - 1} at {p / 1e3:g} kPa"
            for c, p in enumerate(cycle_pressures_pa)
        )
    return Dataset(
        material=spec.data_material(),
        geometry=GEOMETRY,
        conditions=spec.conditions(),
        runs=_fill_optional(runs),
        provenance=provenance,
    )


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
    from . import __version__

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


__all__ = [
    "DEFAULT_NOISE",
    "DEFAULT_PROTOCOL",
    "QUIRKS",
    "RIG_TESTS",
    "Quirk",
    "RigNoise",
    "RigProtocol",
    "RigSimulationError",
    "apply_quirks",
    "check_parameter",
    "check_quirks",
    "read_parameter_file",
    "resolve_parameters",
    "simulate_dataset",
    "simulate_veale_dataset",
    "specimen_parameters",
    "VEALE_TESTS",
]
