"""Prior files: TOML documents of per-parameter marginals (with ``extends`` chains onto the bundled priors), read,
checked and turned into a :class:`~.priors.Prior` (:func:`load_prior`, :func:`prior_for`); and a starting prior
for a user's own material (:func:`starting_prior`). Every error names the file, the entry and what was expected.

**File format.** A prior file is TOML with three kinds of tables::

    [meta]
    family = "textile_composite"            # or material = "PCS"
    materials = ["TPC", "PC", "PCS", "TFC", "FC"]   # codes this file is the prior of (family files)
    extends = "default.toml"                # parent file; omitted only in the root (default.toml)
    citation = "Veale, Xie, Anderson (2016), Smart Mater. Struct. 25"

    [config]                                # optional: ModelConfig fields of this material's default model
    mount = true

    [parameters.tensile_ka_n_per_m]         # one table per parameter
    distribution = "loguniform"
    low = 5e2
    high = 1e5
    unit = "N/m"                            # must equal PARAMETERS[name].unit
    provenance = "wide: spans film and textile muscles"

Distributions and their fields (``low``/``high`` give the support; for the unbounded families they truncate):

| distribution | required | optional (default) | natural support |
|---|---|---|---|
| ``lognormal`` | ``median``, ``sigma_log`` | ``low`` (0), ``high`` (inf) | (0, inf) |
| ``loguniform`` | ``low``, ``high`` (> 0) | | [low, high] |
| ``normal`` | ``mean``, ``sd`` | ``low`` (-inf), ``high`` (inf) | R |
| ``truncnormal`` | ``mean``, ``sd``, ``low``, ``high`` | | [low, high] |
| ``uniform`` | ``low``, ``high`` | | [low, high] |
| ``halfnormal`` | ``scale`` | ``low`` (0), ``high`` (inf) | [0, inf) |

The support must lie inside the parameter's physical bounds (``PARAMETERS[name].bounds``, or
:data:`LIKELIHOOD_PARAMETERS` for the noise scales); truncate with ``high`` where the bounds are finite. Every
density is normalized over its (truncated) support.

**Merging.** ``load_prior("FC")`` reads ``FC.toml`` if it exists, else the family file whose ``meta.materials``
lists ``FC``; then it follows ``extends`` up to the root. A child's parameter entry replaces the parent's entry
as a whole; ``[config]`` keys merge one by one (child wins). ``extends`` is resolved next to the file first,
then in the priors directory.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType

from scipy import special

from .. import bundled
from ..errors import PeanoBayesInputError, did_you_mean
from ..materials import MATERIALS
from ..physics.model import ModelConfig
from .priors import ALL_PARAMETERS, Marginal, Prior

#: The bundled priors directory (inside the package).
DEFAULT_PRIORS_DIR = bundled.PRIORS_DIR
#: The root prior every other prior file extends.
DEFAULT_FILE = "default.toml"

_REQUIRED = {
    "lognormal": ("median", "sigma_log"),
    "loguniform": ("low", "high"),
    "normal": ("mean", "sd"),
    "truncnormal": ("mean", "sd", "low", "high"),
    "uniform": ("low", "high"),
    "halfnormal": ("scale",),
}
_NATURAL_SUPPORT = {
    "lognormal": (0.0, math.inf),
    "loguniform": (0.0, math.inf),
    "normal": (-math.inf, math.inf),
    "truncnormal": (-math.inf, math.inf),
    "uniform": (-math.inf, math.inf),
    "halfnormal": (0.0, math.inf),
}
_COMMON_FIELDS = ("distribution", "unit", "provenance", "low", "high")
_META_KEYS = ("family", "material", "materials", "extends", "citation", "description")
_SECTIONS = ("meta", "config", "parameters")
_CONFIG_FIELDS = tuple(f.name for f in dataclasses.fields(ModelConfig))


# ----------------------------------------------------------------------------------------------- loading


def load_prior(material_code_or_path: str | Path, *, priors_dir: str | Path | None = None) -> Prior:
    """The merged prior of a material code (``"FC"``) or of a prior file path, over every declared parameter.

    ``priors_dir`` [directory] defaults to :data:`DEFAULT_PRIORS_DIR`. Parameter order: :data:`PARAMETERS`
    order, then :data:`LIKELIHOOD_PARAMETERS` order (names the files do not declare are left out). Use
    :meth:`Prior.for_config` for the parameters of one model.

    **Raises:** :class:`~peano_bayes.errors.PeanoBayesInputError` naming the file, the parameter and the
    problem (unknown name or field, unit mismatch, support outside the physical bounds, unknown
    distribution, missing field, bad value, unknown material, ``extends`` cycle or missing parent).
    """
    directory = Path(priors_dir) if priors_dir is not None else DEFAULT_PRIORS_DIR
    start = _resolve_start(material_code_or_path, directory)
    chain = _read_chain(start, directory)  # root first
    marginals: dict[str, Marginal] = {}
    config: dict[str, object] = {}
    for path, _text, doc in chain:
        config.update(_parse_config(path, doc.get("config", {})))
        for name, entry in doc.get("parameters", {}).items():
            marginals[name] = parse_entry(path, name, entry)
    _check_config(chain[-1][0], config)
    names = tuple(n for n in ALL_PARAMETERS if n in marginals)
    text = "\n".join(f"# ==> {path} <==\n{raw}" for path, raw, _ in chain)
    label = str(material_code_or_path)
    return Prior(
        names=names,
        marginals=MappingProxyType(marginals),
        config_overrides=MappingProxyType(config),
        files=tuple(p for p, _, _ in chain),
        text=text,
        label=label,
    )


def prior_for(material_code: str, *, priors_dir: str | Path | None = None, config: ModelConfig | None = None) -> Prior:
    """The prior of a material's model: :func:`load_prior` restricted to the parameters of ``config``
    (default: the material's own ``[config]``) plus the likelihood's noise and pooling scales."""
    return load_prior(material_code, priors_dir=priors_dir).for_config(config)


def prior_files(priors_dir: str | Path | None = None) -> tuple[Path, ...]:
    """Every ``*.toml`` prior file in ``priors_dir`` (default: the bundled ones), sorted."""
    directory = Path(priors_dir) if priors_dir is not None else DEFAULT_PRIORS_DIR
    return tuple(sorted(directory.glob("*.toml")))


def _fail(path, message: str, name: str | None = None) -> PeanoBayesInputError:
    """The error of a prior file ``path``, at the line of parameter ``name``'s table where the file has one."""
    line = _entry_line(path, name) if name is not None else None
    at = f"{path}, line {line}" if line is not None else f"{path}"
    where = f"{at}: parameter '{name}'" if name is not None else at
    return PeanoBayesInputError(f"{where}: {message}")


def _unknown_parameter(name: str) -> str:
    return f"unknown parameter{did_you_mean(name, ALL_PARAMETERS)}; expected one of {', '.join(ALL_PARAMETERS)}"


def _entry_line(path, name: str) -> int | None:
    """1-based line of ``[parameters.<name>]`` (or of a ``<name> = ...`` key) in the prior file ``path``."""
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError, TypeError):
        return None
    table = f"[parameters.{name}]"
    for number, text in enumerate(lines, start=1):
        stripped = text.strip()
        if stripped.replace(" ", "") == table or stripped.split("=")[0].strip() == name:
            return number
    return None


def _resolve_start(code_or_path: str | Path, directory: Path) -> Path:
    """The first file of a material code or path."""
    as_path = Path(code_or_path)
    if as_path.suffix == ".toml" or as_path.is_file():
        if not as_path.is_file():
            raise PeanoBayesInputError(
                f"{as_path}: prior file not found; expected an existing .toml prior file or a material code"
            )
        return as_path
    code = str(code_or_path).strip()
    code = code.upper() if code.upper() in MATERIALS else code
    own = directory / f"{code}.toml"
    if own.is_file():
        return own
    for path in prior_files(directory):
        meta = _read(path)[1].get("meta", {})
        if code in meta.get("materials", ()):
            return path
    if code.upper() in MATERIALS:
        raise PeanoBayesInputError(
            f"{directory}: no prior file for material {code!r}: "
            f"expected {code}.toml or a file listing it in meta.materials"
        )
    raise PeanoBayesInputError(
        f"unknown material code or prior file {code!r}{did_you_mean(code.upper(), MATERIALS)}; "
        f"expected one of {', '.join(MATERIALS)} or a path to a .toml prior file"
    )


def _read(path: Path) -> tuple[str, dict]:
    try:
        raw = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise _fail(path, f"cannot read prior file ({err})") from None
    try:
        return raw, tomllib.loads(raw)
    except tomllib.TOMLDecodeError as err:
        raise _fail(
            path, f"not valid TOML ({err}); expected a TOML prior file such as 'peano-bayes prior new' writes"
        ) from None


def _read_chain(start: Path, directory: Path) -> list[tuple[Path, str, dict]]:
    """The files from ``start`` up its ``extends`` links, returned root first."""
    chain: list[tuple[Path, str, dict]] = []
    seen: set[Path] = set()
    path = start
    while True:
        resolved = path.resolve()
        if resolved in seen:
            raise _fail(path, "'extends' forms a cycle: " + " -> ".join(str(p) for p, _, _ in chain))
        seen.add(resolved)
        raw, doc = _read(path)
        _check_document(path, doc)
        chain.append((path, raw, doc))
        parent = doc.get("meta", {}).get("extends")
        if parent is None:
            return chain[::-1]
        candidates = [path.parent / parent, directory / parent]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise _fail(path, f"meta.extends = {parent!r} not found next to the file or in {directory}")
        path = found


def _check_document(path: Path, doc: dict) -> None:
    for key, value in doc.items():
        if key not in _SECTIONS:
            hint = did_you_mean(key, _SECTIONS)
            if key in ALL_PARAMETERS:
                hint = f" (parameter tables go under [parameters.{key}])"
            raise _fail(path, f"unknown section [{key}]{hint}; expected {', '.join(_SECTIONS)}")
        if not isinstance(value, dict):
            raise _fail(path, f"[{key}] must be a table, got {type(value).__name__}")
    meta = doc.get("meta", {})
    for key in meta:
        if key not in _META_KEYS:
            raise _fail(
                path, f"unknown key meta.{key}{did_you_mean(key, _META_KEYS)}; expected {', '.join(_META_KEYS)}"
            )
    if "extends" in meta and not isinstance(meta["extends"], str):
        raise _fail(path, f"meta.extends must be a file name, got {meta['extends']!r}")
    if "materials" in meta and not (
        isinstance(meta["materials"], list) and all(isinstance(m, str) for m in meta["materials"])
    ):
        raise _fail(path, f"meta.materials must be a list of material codes, got {meta['materials']!r}")
    for name, entry in doc.get("parameters", {}).items():
        if name not in ALL_PARAMETERS:
            raise _fail(path, _unknown_parameter(name), name)
        if not isinstance(entry, dict):
            raise _fail(path, f"entry must be a table [parameters.{name}], got {entry!r}", name)


def _parse_config(path: Path, table: dict) -> dict:
    for key, value in table.items():
        if key not in _CONFIG_FIELDS:
            raise _fail(
                path,
                f"unknown ModelConfig field config.{key}{did_you_mean(key, _CONFIG_FIELDS)}; "
                f"expected one of {', '.join(_CONFIG_FIELDS)}",
            )
        expected = type(getattr(ModelConfig(), key))
        if type(value) is not expected:
            raise _fail(path, f"config.{key} must be a {expected.__name__}, got {value!r}")
    return dict(table)


def _check_config(path: Path, config: dict) -> None:
    try:
        ModelConfig(**config)
    except (ValueError, TypeError) as err:
        raise _fail(path, f"invalid [config]: {err}") from None


def _number(path, name: str, entry: dict, field: str, default: float | None = None) -> float:
    if field not in entry:
        if default is None:
            raise _fail(path, f"missing field '{field}' for distribution {entry.get('distribution')!r}", name)
        return default
    value = entry[field]
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise _fail(path, f"field '{field}' must be a number, got {value!r}", name)
    return float(value)


def parse_entry(path: Path | str, name: str, entry: Mapping[str, object]) -> Marginal:
    """Validate one ``[parameters.NAME]`` table of file ``path`` and build its :class:`Marginal`.

    **Raises:** :class:`~peano_bayes.errors.PeanoBayesInputError` naming ``path``, ``name`` and the problem.
    """
    if name not in ALL_PARAMETERS:
        raise _fail(path, _unknown_parameter(name), name)
    spec = ALL_PARAMETERS[name]
    for field in ("distribution", "unit", "provenance"):
        if field not in entry:
            raise _fail(path, f"missing field '{field}'", name)
        if not isinstance(entry[field], str) or not entry[field].strip():
            raise _fail(path, f"field '{field}' must be a non-empty string, got {entry[field]!r}", name)
    dist = entry["distribution"]
    if dist not in _REQUIRED:
        raise _fail(
            path,
            f"unknown distribution {dist!r}{did_you_mean(dist, _REQUIRED)}; expected one of {', '.join(_REQUIRED)}",
            name,
        )
    allowed = tuple(dict.fromkeys(_COMMON_FIELDS + _REQUIRED[dist]))
    for field in entry:
        if field not in allowed:
            raise _fail(
                path,
                f"unknown field '{field}'{did_you_mean(field, allowed)} for {dist}; expected {', '.join(allowed)}",
                name,
            )
    if entry["unit"] != spec.unit:
        raise _fail(
            path,
            f"unit mismatch: got {entry['unit']!r}, expected {spec.unit!r} (SI unit of PARAMETERS['{name}'])",
            name,
        )
    for field in _REQUIRED[dist]:
        _number(path, name, entry, field)
    natural_low, natural_high = _NATURAL_SUPPORT[dist]
    low = _number(path, name, entry, "low", natural_low)
    high = _number(path, name, entry, "high", natural_high)
    low, high = max(low, natural_low), min(high, natural_high)
    if not low < high:
        raise _fail(path, f"empty support: low = {low:g} must be below high = {high:g}", name)
    if dist == "loguniform" and low <= 0:
        raise _fail(path, f"loguniform needs low > 0, got low = {low:g}", name)
    if not math.isfinite(low) and math.isfinite(high):
        raise _fail(path, "a support (-inf, high] is not supported; give a finite low", name)
    b_low, b_high = spec.bounds
    if low < b_low or high > b_high:
        hint = " (truncate it with 'high')" if high > b_high and math.isfinite(b_high) else ""
        raise _fail(
            path,
            f"support [{low:g}, {high:g}] {spec.unit} lies outside the physical bounds [{b_low:g}, {b_high:g}]{hint}",
            name,
        )
    loc, scale = _loc_scale(path, name, entry, dist)
    marginal = Marginal(
        name=name,
        distribution=dist,
        low=low,
        high=high,
        loc=loc,
        scale=scale,
        log_norm=0.0,
        unit=spec.unit,
        provenance=entry["provenance"].strip(),
        source=str(path),
        spec=MappingProxyType(dict(entry)),
    )
    mass = 1.0 if dist in ("uniform", "loguniform") else float(marginal._cdf(high) - marginal._cdf(low))
    if dist in ("normal", "truncnormal") and low > loc:  # both ends in the upper tail: use the survival function
        mass = float(special.ndtr((loc - low) / scale) - special.ndtr((loc - high) / scale))
    if not mass > 1e-12:
        raise _fail(path, f"the distribution has (almost) no mass inside its support [{low:g}, {high:g}]", name)
    return dataclasses.replace(marginal, log_norm=math.log(mass))


def _loc_scale(path, name: str, entry: Mapping, dist: str) -> tuple[float, float]:
    def positive(field: str) -> float:
        value = float(entry[field])
        if not (value > 0 and math.isfinite(value)):
            raise _fail(path, f"field '{field}' must be positive and finite, got {value!r}", name)
        return value

    if dist == "lognormal":
        return math.log(positive("median")), positive("sigma_log")
    if dist in ("normal", "truncnormal"):
        mean = float(entry["mean"])
        if not math.isfinite(mean):
            raise _fail(path, f"field 'mean' must be finite, got {mean!r}", name)
        return mean, positive("sd")
    if dist == "halfnormal":
        return 0.0, positive("scale")
    return 0.0, 1.0


def starting_prior(like: str, *, material: str = "MY", out: str | os.PathLike = "MY.toml") -> str:
    """The text of a prior file to edit for a muscle of one's own: it ``extends`` the prior of ``like`` (a
    bundled material code, or a prior file) so it keeps that prior's ``[config]``, and writes out every parameter
    entry of the merged prior, each with its unit and provenance, so the user sees the whole prior and edits in
    place. ``material`` [str] is the code written into ``meta.material``; ``out``, the path the text will be
    saved as: a bundled prior is extended by its name (resolved among the bundled priors), a file of one's own
    by its path relative to ``out``'s folder. Raises :class:`PeanoBayesInputError` where ``out`` would extend
    itself or a file beside it would stand in for the bundled prior (``extends`` looks next to the file first)."""
    import tomli_w

    prior = load_prior(like)
    start, out = prior.files[-1], Path(out)
    bundled = start.resolve().parent == DEFAULT_PRIORS_DIR.resolve()
    extends = start.name if bundled else os.path.relpath(start.resolve(), out.parent.resolve())
    found = out.parent / extends
    if found.resolve() == out.resolve() or any(f.resolve() == out.resolve() for f in prior.files):
        raise PeanoBayesInputError(
            f"{out}: would extend itself ({out.name} is in the chain of the prior it starts from, {start}); "
            "choose another name"
        )
    if bundled and found.exists():
        raise PeanoBayesInputError(
            f"{out}: {found} would stand in for the bundled {start.name} it extends ('extends' is looked up next to "
            "the file first); write the new prior in another folder"
        )
    source = f"the bundled prior of {like}" if bundled else f"the prior file {start}"
    header = (
        f"# Prior for material {material}, started from {source} ({start.name}).\n"
        "# Edit the entries your material calls for (distribution, its fields, low/high, provenance); delete an\n"
        f"# entry to take {like}'s. Format: docs/inference.md#prior-files. Fit with\n"
        f"#   peano-bayes fit DATA.csv --prior THIS_FILE.toml --out results\n\n"
    )
    document = {
        "meta": {
            "material": material,
            "extends": Path(extends).as_posix(),
            "description": f"starting prior for {material}, from {source}",
        },
        "parameters": {name: dict(prior.marginals[name].spec) for name in prior.names},
    }
    return header + tomli_w.dumps(document)


__all__ = [
    "DEFAULT_FILE",
    "DEFAULT_PRIORS_DIR",
    "load_prior",
    "parse_entry",
    "prior_files",
    "prior_for",
    "starting_prior",
]
