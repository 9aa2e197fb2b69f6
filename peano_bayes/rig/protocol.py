"""The virtual rig's settings: sensor noise and protocol (:class:`RigNoise`, :class:`RigProtocol`), the
effects a virtual muscle may carry that a fit's model may lack (quirks), and the generating parameters (checked,
read from a parameter file, drawn per specimen)."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.format import TESTS
from ..effects import LIBRARY, Effect, switchable
from ..errors import PeanoBayesInputError, did_you_mean
from ..physics import (
    PARAMETERS,
    ModelConfig,
)

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


class _Quirks(Mapping):
    """name -> :class:`~peano_bayes.effects.Effect` of every effect the rig can switch on, read from the effect
    registry at each use (:func:`peano_bayes.effects.switchable`), so a registered effect is a quirk at once."""

    def __getitem__(self, name: str) -> Effect:
        return switchable()[name]

    def __iter__(self):
        return iter(switchable())

    def __len__(self) -> int:
        return len(switchable())


#: name -> :class:`~peano_bayes.effects.Effect`: the effects whose element the rig can switch on (quirks).
QUIRKS: Mapping[str, Effect] = _Quirks()


def check_quirks(quirks: Iterable[str]) -> tuple[str, ...]:
    """Quirk names in order, duplicates removed; an unknown name, or an effect the rig cannot switch on (with
    the reason the registry gives), raises :class:`PeanoBayesInputError`."""
    if isinstance(quirks, str):
        quirks = (quirks,)
    names = tuple(dict.fromkeys(quirks))
    for name in names:
        if name in QUIRKS:
            continue
        known = ", ".join(QUIRKS)
        effect = LIBRARY.get(name)
        if effect is not None:
            why = effect.not_a_switch or f"a {effect.kind} effect has no element of the physics to switch on"
            raise PeanoBayesInputError(
                f"effect {name!r} is not a quirk the rig can switch on ({why}); known quirks: {known}"
            )
        raise PeanoBayesInputError(f"unknown quirk {name!r}{did_you_mean(name, QUIRKS)}; known quirks: {known}")
    return names


def apply_quirks(config: ModelConfig, quirks: Iterable[str]) -> ModelConfig:
    """``config`` with the elements of ``quirks`` (names of :data:`QUIRKS`) switched on."""
    for name in check_quirks(quirks):
        config = QUIRKS[name].switch_on(config)
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


#: Seed streams of a simulated dataset: each specimen's parameters draw from ``[seed, _SPECIMEN_STREAM, specimen]``,
#: each run's sensor noise from ``[seed, _NOISE_STREAM, ...]``, so adding a test leaves the others' draws alone.
_SPECIMEN_STREAM, _NOISE_STREAM = 0, 1


__all__ = [
    "DEFAULT_NOISE",
    "DEFAULT_PROTOCOL",
    "QUIRKS",
    "RIG_TESTS",
    "RigNoise",
    "RigProtocol",
    "apply_quirks",
    "check_parameter",
    "check_quirks",
    "read_parameter_file",
    "resolve_parameters",
    "specimen_parameters",
]
