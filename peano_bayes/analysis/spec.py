"""Design specs: the TOML a designer writes for ``peano-bayes recommend`` (``[requirement]``, ``[candidates]``,
``[results]``, ``[limits.CODE]``), read and validated into a :class:`Spec` in SI units. A bad or impossible
requirement is refused naming the file, the key, the value seen and what was expected."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..defaults import DEFAULT_DRAWS, MAX_PRESSURE_KPA
from ..errors import PeanoBayesInputError, did_you_mean
from ..physics.pouch import IDEAL_FREE_STRAIN
from .limits import material_limits

_REQUIREMENT_KEYS = {
    "force_n": "minimum force [N]",
    "contraction": "contraction strain at which the force is needed [-]",
    "max_pressure_kpa": "maximum supply pressure [kPa]",
    "max_width_mm": "maximum muscle width, the tube length [mm]",
    "max_length_mm": "maximum flat muscle length n w [mm]",
    "max_thickness_mm": "maximum inflated thickness [mm]",
    "max_hysteresis": "maximum hysteresis loss [-]",
    "max_response_time_s": "maximum time to the required contraction after a pressure step [s]",
}
_REQUIRED = ("force_n", "contraction", "max_pressure_kpa")
_CANDIDATE_KEYS = ("materials", "n_tubes", "tube_width_mm", "tube_length_mm")
_SECTIONS = ("requirement", "candidates", "results", "limits")
_LIMIT_KEYS = ("burst_kpa",)


@dataclass(frozen=True)
class Requirement:
    """What the muscle must do (SI units); ``None`` where the spec sets no bound."""

    force_n: float
    contraction: float
    max_pressure_pa: float
    max_width_m: float | None = None
    max_length_m: float | None = None
    max_thickness_m: float | None = None
    max_hysteresis: float | None = None
    max_response_time_s: float | None = None


@dataclass(frozen=True)
class Spec:
    """A parsed spec: the requirement, the candidate grid and where the material results are."""

    requirement: Requirement
    materials: tuple[str, ...]
    n_tubes: tuple[int, ...]
    tube_width_m: tuple[float, ...]
    tube_length_m: tuple[float, ...]
    results_dir: Path
    n_draws: int
    source: Path
    #: code -> burst pressure [kPa] the spec states (``[limits.CODE] burst_kpa``).
    burst_kpa: dict = field(default_factory=dict)

    def limits(self, code: str, idata=None) -> dict | None:
        """The pressure limits of material ``code`` under this spec (:func:`~peano_bayes.analysis.limits.
        material_limits`, with the burst pressure the spec states for it)."""
        return material_limits(code, idata, self.burst_kpa.get(code), str(self.source))


def _number(value, where: str) -> float:
    """``value`` as a positive finite float, else an error naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise PeanoBayesInputError(f"{where}: expected a finite number, got {value!r}")
    if not value > 0:
        raise PeanoBayesInputError(f"{where}: expected a positive number, got {value!r}")
    return float(value)


def _list(value, where: str, kind) -> tuple:
    if not isinstance(value, list) or not value:
        raise PeanoBayesInputError(f"{where}: expected a non-empty list, got {value!r}")
    if kind is int:
        bad = [v for v in value if isinstance(v, bool) or not isinstance(v, int) or v < 1]
        if bad:
            raise PeanoBayesInputError(f"{where}: expected whole numbers of tubes >= 1, got {bad[0]!r}")
        return tuple(value)
    if kind is str:
        bad = [v for v in value if not isinstance(v, str) or not v]
        if bad:
            raise PeanoBayesInputError(f"{where}: expected material codes (strings), got {bad[0]!r}")
        return tuple(value)
    return tuple(_number(v, where) for v in value)


def _unknown(table: dict, known, where: str) -> None:
    for key in table:
        if key not in known:
            raise PeanoBayesInputError(
                f"{where}: unknown key {key!r}{did_you_mean(key, known)}; expected one of {', '.join(known)}"
            )


def load_spec(path: str | Path) -> Spec:
    """Read and validate a spec TOML; a bad or impossible requirement raises :class:`PeanoBayesInputError`
    naming the file, the key, the value seen and what was expected."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PeanoBayesInputError(
            f"{path}: no such spec file; expected a design spec TOML ([requirement], [candidates], [results]; "
            "examples in the repository's experiments/specs/)"
        ) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise PeanoBayesInputError(f"{path}: not valid TOML ({err})") from None
    _unknown(raw, _SECTIONS, str(path))
    req = raw.get("requirement")
    if not isinstance(req, dict):
        raise PeanoBayesInputError(f"{path}: missing table [requirement] (needs {', '.join(_REQUIRED)})")
    _unknown(req, _REQUIREMENT_KEYS, f"{path} [requirement]")
    for key in _REQUIRED:
        if key not in req:
            raise PeanoBayesInputError(f"{path} [requirement]: missing {key!r} ({_REQUIREMENT_KEYS[key]})")
    at = lambda key: f"{path} [requirement] {key}"  # noqa: E731
    contraction = _number(req["contraction"], at("contraction"))
    if contraction >= IDEAL_FREE_STRAIN:
        raise PeanoBayesInputError(
            f"{at('contraction')}: impossible: {contraction:g} asked, but a Peano muscle contracts at most "
            f"{float(IDEAL_FREE_STRAIN):.3f} (ideal tubes at zero load, 1 - 2/pi)"
        )
    pressure = _number(req["max_pressure_kpa"], at("max_pressure_kpa"))
    if pressure > MAX_PRESSURE_KPA:
        raise PeanoBayesInputError(
            f"{at('max_pressure_kpa')}: expected at most {MAX_PRESSURE_KPA:g} kPa (the model's range), got {pressure:g}"
        )
    hysteresis = req.get("max_hysteresis")
    if hysteresis is not None and not 0.0 < _number(hysteresis, at("max_hysteresis")) <= 1.0:
        raise PeanoBayesInputError(f"{at('max_hysteresis')}: expected a fraction in (0, 1], got {hysteresis!r}")
    response = req.get("max_response_time_s")
    mm = lambda key: None if key not in req else 1e-3 * _number(req[key], at(key))  # noqa: E731
    requirement = Requirement(
        force_n=_number(req["force_n"], at("force_n")),
        contraction=contraction,
        max_pressure_pa=1e3 * pressure,
        max_width_m=mm("max_width_mm"),
        max_length_m=mm("max_length_mm"),
        max_thickness_m=mm("max_thickness_mm"),
        max_hysteresis=None if hysteresis is None else float(hysteresis),
        max_response_time_s=None if response is None else _number(response, at("max_response_time_s")),
    )
    cand = raw.get("candidates", {})
    if not isinstance(cand, dict):
        raise PeanoBayesInputError(f"{path}: [candidates] must be a table, got {cand!r}")
    _unknown(cand, _CANDIDATE_KEYS, f"{path} [candidates]")
    res = raw.get("results", {})
    if not isinstance(res, dict):
        raise PeanoBayesInputError(f"{path}: [results] must be a table, got {res!r}")
    _unknown(res, ("dir", "n_draws"), f"{path} [results]")
    results_dir = res.get("dir", "results")
    if not isinstance(results_dir, str) or not results_dir:
        raise PeanoBayesInputError(f"{path} [results] dir: expected a folder path (string), got {results_dir!r}")
    n_draws = res.get("n_draws", DEFAULT_DRAWS)
    if isinstance(n_draws, bool) or not isinstance(n_draws, int) or n_draws < 1:
        raise PeanoBayesInputError(f"{path} [results] n_draws: expected a whole number >= 1, got {n_draws!r}")
    where = lambda key: f"{path} [candidates] {key}"  # noqa: E731
    limits = raw.get("limits", {})
    if not isinstance(limits, dict) or not all(isinstance(v, dict) for v in limits.values()):
        raise PeanoBayesInputError(
            f"{path}: [limits] must hold one table per material, e.g. [limits.VM] burst_kpa = 150; got {limits!r}"
        )
    burst = {}
    for code, table in limits.items():
        _unknown(table, _LIMIT_KEYS, f"{path} [limits.{code}]")
        if "burst_kpa" in table:
            burst[code] = _number(table["burst_kpa"], f"{path} [limits.{code}] burst_kpa")
    return Spec(
        requirement=requirement,
        materials=_list(cand["materials"], where("materials"), str) if "materials" in cand else (),
        n_tubes=_list(cand.get("n_tubes", [4]), where("n_tubes"), int),
        tube_width_m=tuple(1e-3 * w for w in _list(cand.get("tube_width_mm", [15.0]), where("tube_width_mm"), float)),
        tube_length_m=tuple(
            1e-3 * w for w in _list(cand.get("tube_length_mm", [49.5]), where("tube_length_mm"), float)
        ),
        results_dir=(path.parent / results_dir).resolve() if "dir" in res else Path(results_dir),
        n_draws=n_draws,
        source=path,
        burst_kpa=burst,
    )


__all__ = ["Requirement", "Spec", "load_spec"]
