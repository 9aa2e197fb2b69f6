"""Priors as data: the bundled ``priors/*.toml`` --load_prior--> :class:`Prior` (JAX log-density, numpy sampling).

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

**Unconstrained space** (what samplers and optimizers see), per parameter with support [a, b]:

- ``a > 0``, ``b`` finite, log-scale distribution (lognormal, loguniform): ``u = logit((ln x - ln a)/(ln b - ln a))``;
- ``a``, ``b`` finite otherwise: ``u = ln(x - a) - ln(b - x)`` (log-odds; for a = 0 this is ``~ln x`` near 0);
- ``a`` finite, ``b = inf``: ``u = ln(x - a)``;  ``a = -inf``, ``b = inf``: ``u = x``.

:meth:`Prior.log_prob` is the density of ``u``: the density of ``x`` plus ``ln |dx/du|``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np
from scipy import special

from .. import bundled
from ..errors import PeanoBayesInputError, did_you_mean
from ..materials import MATERIALS
from ..physics.model import PARAMETERS, ModelConfig, Parameter

#: The bundled priors directory (inside the package).
DEFAULT_PRIORS_DIR = bundled.PRIORS_DIR
#: The root prior every other prior file extends.
DEFAULT_FILE = "default.toml"

#: Parameters of the likelihood (not of the physics): a noise scale per test and the specimen-pooling scale.
LIKELIHOOD_PARAMETERS: dict[str, Parameter] = {
    "noise_load_cycle_force_n": Parameter("N", "sd of one force sample's residual, load cycles", 2.0, (0.0, math.inf)),
    "noise_blocking_force_n": Parameter("N", "sd of one force sample's residual, blocking tests", 2.0, (0.0, math.inf)),
    "noise_stroke_strain": Parameter("-", "sd of one strain sample's residual, stroke tests", 0.01, (0.0, math.inf)),
    "noise_step_strain": Parameter("-", "sd of one strain sample's residual, step responses", 0.01, (0.0, math.inf)),
    "specimen_log_sd": Parameter(
        "-", "sd of the log stiffness difference between the two specimens of a material", 0.1, (0.0, math.inf)
    ),
}
#: Every name a prior file may set: the physics (:data:`PARAMETERS`) then the likelihood.
ALL_PARAMETERS: Mapping[str, Parameter] = MappingProxyType({**PARAMETERS, **LIKELIHOOD_PARAMETERS})

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
_LOG_SCALE = ("lognormal", "loguniform")
_COMMON_FIELDS = ("distribution", "unit", "provenance", "low", "high")
_META_KEYS = ("family", "material", "materials", "extends", "citation", "description")
_SECTIONS = ("meta", "config", "parameters")
_CONFIG_FIELDS = tuple(f.name for f in dataclasses.fields(ModelConfig))
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


class _NumpyOps:
    """The few array functions the transforms use, in NumPy: values that are not JAX arrays (prior draws,
    stored posterior draws) are transformed without dispatching, and compiling, one XLA program per operation
    and shape."""

    log, exp, where, zeros_like, stack = np.log, np.exp, np.where, np.zeros_like, np.stack
    sigmoid = staticmethod(special.expit)

    @staticmethod
    def log_sigmoid(u):
        return -np.logaddexp(0.0, -u)


class _JaxOps:
    log, exp, where, zeros_like, stack = jnp.log, jnp.exp, jnp.where, jnp.zeros_like, jnp.stack
    sigmoid, log_sigmoid = staticmethod(jax.nn.sigmoid), staticmethod(jax.nn.log_sigmoid)


def _ops(*values):
    """JAX's functions where any value (or any leaf of a list or tuple of them) is a JAX array or tracer, else
    NumPy's (float64 either way)."""
    return _JaxOps if any(isinstance(v, jax.Array) for v in jax.tree_util.tree_leaves(values)) else _NumpyOps


def _as_array(x, ops):
    return jnp.asarray(x, dtype=jnp.float64) if ops is _JaxOps else np.asarray(x, dtype=np.float64)


# ----------------------------------------------------------------------------------------------- marginals


@dataclasses.dataclass(frozen=True, eq=False)
class Marginal:
    """One parameter's prior: distribution, support [low, high] in SI units, and where it came from.

    ``loc``/``scale`` are the distribution's location and scale in its own space: (ln median, sigma_log) for
    lognormal, (mean, sd) for (trunc)normal, (0, scale) for halfnormal, unused otherwise. ``log_norm`` is
    ln of the probability mass of the untruncated distribution inside the support.
    """

    name: str
    distribution: str
    low: float
    high: float
    loc: float
    scale: float
    log_norm: float
    unit: str
    provenance: str
    source: str
    spec: Mapping[str, object]

    @property
    def transform(self) -> str:
        """``"loglogit"``, ``"logit"``, ``"log"`` or ``"identity"`` (see the module docstring)."""
        finite_low, finite_high = math.isfinite(self.low), math.isfinite(self.high)
        if finite_low and finite_high:
            return "loglogit" if self.low > 0 and self.distribution in _LOG_SCALE else "logit"
        if finite_low:
            return "log"
        if finite_high:
            raise AssertionError("supports (-inf, b] are rejected at load time")
        return "identity"

    # -- numpy side: quantiles (sampling and medians) ---------------------------------------------------
    def _cdf(self, x: np.ndarray) -> np.ndarray:
        """CDF of the *untruncated* distribution at x [SI]."""
        x = np.asarray(x, dtype=float)
        d = self.distribution
        if d == "lognormal":
            with np.errstate(divide="ignore"):
                return special.ndtr((np.log(x) - self.loc) / self.scale)
        if d in ("normal", "truncnormal"):
            return special.ndtr((x - self.loc) / self.scale)
        if d == "halfnormal":
            return 2.0 * special.ndtr(np.maximum(x, 0.0) / self.scale) - 1.0
        if d == "loguniform":
            return np.clip(np.log(x / self.low) / math.log(self.high / self.low), 0.0, 1.0)
        return np.clip((x - self.low) / (self.high - self.low), 0.0, 1.0)  # uniform

    def _ppf(self, q: np.ndarray) -> np.ndarray:
        """Inverse CDF of the *untruncated* distribution, q in [0, 1]."""
        q = np.asarray(q, dtype=float)
        d = self.distribution
        if d == "lognormal":
            return np.exp(self.loc + self.scale * special.ndtri(q))
        if d in ("normal", "truncnormal"):
            return self.loc + self.scale * special.ndtri(q)
        if d == "halfnormal":
            return self.scale * special.ndtri(0.5 * (1.0 + q))
        if d == "loguniform":
            return self.low * np.exp(q * math.log(self.high / self.low))
        return self.low + q * (self.high - self.low)  # uniform

    def quantile(self, q) -> np.ndarray:
        """Quantile of the truncated prior at probability ``q`` in [0, 1] [SI], clipped into the support."""
        c_low, c_high = self._cdf(self.low), self._cdf(self.high)
        x = self._ppf(c_low + np.asarray(q, dtype=float) * (c_high - c_low))
        return np.clip(x, self.low, self.high)

    def median(self) -> float:
        """Median of the truncated prior [SI]."""
        return float(self.quantile(0.5))

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` draws [SI], shape (n,), strictly inside the support (inverse-CDF sampling)."""
        q = rng.uniform(1e-12, 1.0 - 1e-12, size=n)
        return self.quantile(q)

    # -- JAX side: transform and density ------------------------------------------------------------------
    def to_unconstrained(self, x):
        """u [-] from x [SI] (elementwise, any shape); NumPy in, NumPy out, otherwise JAX."""
        xp = _ops(x)
        with np.errstate(all="ignore"):  # silent like JAX: a value on a bound maps to an infinity
            return self._to_unconstrained(_as_array(x, xp), xp)

    def _to_unconstrained(self, x, xp):
        kind = self.transform
        if kind == "loglogit":
            return xp.log(xp.log(x / self.low)) - xp.log(xp.log(self.high / x))
        if kind == "logit":
            return xp.log(x - self.low) - xp.log(self.high - x)
        if kind == "log":
            return xp.log(x - self.low)
        return x

    def from_unconstrained(self, u):
        """``(x, ln|dx/du|)`` from u (elementwise). Stable for large |u|; x may round onto a bound. NumPy in,
        NumPy out, otherwise JAX."""
        xp = _ops(u)
        with np.errstate(all="ignore"):  # silent like JAX: a value on a bound maps to an infinity
            return self._from_unconstrained(_as_array(u, xp), xp)

    def _from_unconstrained(self, u, xp):
        kind = self.transform
        log_jac_logistic = xp.log_sigmoid(u) + xp.log_sigmoid(-u)
        if kind == "loglogit":
            span = math.log(self.high / self.low)
            y = xp.where(u < 0, math.log(self.low) + span * xp.sigmoid(u), math.log(self.high) - span * xp.sigmoid(-u))
            return xp.exp(y), y + math.log(span) + log_jac_logistic
        if kind == "logit":
            span = self.high - self.low
            # exp(log_sigmoid) keeps x = low + tiny representable where sigmoid(u) itself would underflow.
            x = xp.where(
                u < 0,
                self.low + xp.exp(math.log(span) + xp.log_sigmoid(u)),
                self.high - xp.exp(math.log(span) + xp.log_sigmoid(-u)),
            )
            return x, math.log(span) + log_jac_logistic
        if kind == "log":
            return self.low + xp.exp(u), u
        return u, xp.zeros_like(u)

    def inside(self, x):
        """True where x is in the support (closed; open at 0 for the log-scale distributions)."""
        ok = (x >= self.low) & (x <= self.high)
        if self.distribution in _LOG_SCALE:
            ok = ok & (x > 0)
        return ok

    def log_density(self, x):
        """ln p(x) [ln(1/unit)] of the truncated prior; -inf outside the support, never NaN."""
        x = jnp.asarray(x, dtype=jnp.float64)
        ok = self.inside(x)
        safe = jnp.where(ok, x, self.median())  # keeps values and gradients finite off the support
        d = self.distribution
        if d == "lognormal":
            z = (jnp.log(safe) - self.loc) / self.scale
            lp = -jnp.log(safe) - math.log(self.scale) - _LOG_SQRT_2PI - 0.5 * z**2
        elif d in ("normal", "truncnormal"):
            z = (safe - self.loc) / self.scale
            lp = -math.log(self.scale) - _LOG_SQRT_2PI - 0.5 * z**2
        elif d == "halfnormal":
            z = safe / self.scale
            lp = math.log(2.0) - math.log(self.scale) - _LOG_SQRT_2PI - 0.5 * z**2
        elif d == "loguniform":
            lp = -jnp.log(safe) - math.log(math.log(self.high / self.low))
        else:
            lp = jnp.full_like(safe, -math.log(self.high - self.low))
        return jnp.where(ok, lp - self.log_norm, -jnp.inf)


# ----------------------------------------------------------------------------------------------- the prior


@dataclasses.dataclass(frozen=True, eq=False)
class Prior:
    """A joint prior: independent marginals over named parameters, in a fixed order.

    **Fields:**
    - ``names``: parameter names, shape (d,); the order of every vector this object takes or returns.
    - ``marginals``: name -> :class:`Marginal` (read-only).
    - ``config_overrides``: :class:`~peano_bayes.physics.model.ModelConfig` fields this material's default
      model sets (read-only); ``config`` is the resulting ``ModelConfig``.
    - ``files``: the prior files used, root first; ``text``: their raw TOML text, each after a
      ``# ==> path <==`` header (store it with the results for provenance).
    - ``label``: the material code or file this prior was loaded for.

    All vector methods work under ``jit``/``vmap``/``grad`` (float64). The transforms
    (``to_unconstrained``, ``from_unconstrained``, ``median_unconstrained``) compute in NumPy and return NumPy
    when no input is a JAX array (prior draws, stored posterior draws), and in JAX otherwise.
    """

    names: tuple[str, ...]
    marginals: Mapping[str, Marginal]
    config_overrides: Mapping[str, object]
    files: tuple[Path, ...]
    text: str
    label: str

    @property
    def ndim(self) -> int:
        """Number of parameters d."""
        return len(self.names)

    @property
    def config(self) -> ModelConfig:
        """The material's default model: ``ModelConfig(**config_overrides)``."""
        return ModelConfig(**self.config_overrides)

    @property
    def provenance(self) -> Mapping[str, str]:
        """name -> where its range comes from (``"file: text"``)."""
        return MappingProxyType({n: f"{self.marginals[n].source}: {self.marginals[n].provenance}" for n in self.names})

    @property
    def units(self) -> Mapping[str, str]:
        """name -> SI unit."""
        return MappingProxyType({n: self.marginals[n].unit for n in self.names})

    def select(self, names) -> Prior:
        """The prior restricted to ``names`` (in that order); raises for a name this prior lacks."""
        names = tuple(names)
        missing = [n for n in names if n not in self.marginals]
        if missing:
            raise PeanoBayesInputError(f"prior {self.label!r} has no entry for {', '.join(missing)}")
        return dataclasses.replace(self, names=names)

    def for_config(self, config: ModelConfig | None = None, *, likelihood: bool = True) -> Prior:
        """The prior over the parameters ``config`` reads (default: :attr:`config`), plus the likelihood's."""
        config = self.config if config is None else config
        extra = tuple(LIKELIHOOD_PARAMETERS) if likelihood else ()
        return self.select(config.parameter_names() + extra)

    def to_unconstrained(self, params: Mapping[str, float]):
        """Unconstrained vector u, shape (d,), from a dict name -> value [SI] (extra keys ignored). NumPy in,
        NumPy out, otherwise JAX."""
        values = [params[n] for n in self.names]
        columns = [self.marginals[n].to_unconstrained(v) for n, v in zip(self.names, values, strict=True)]
        return _ops(*values).stack(columns)

    def from_unconstrained(self, u) -> dict:
        """dict name -> value [SI] from u of shape (..., d); values have shape (...). NumPy in, NumPy out,
        otherwise JAX."""
        u = _as_array(u, _ops(u))
        return {n: self.marginals[n].from_unconstrained(u[..., i])[0] for i, n in enumerate(self.names)}

    def log_prob(self, u):
        """ln p(u) of the prior in unconstrained space (density of x plus ln|dx/du|), u shape (d,) -> ().

        ``-inf`` (never NaN) where u is not finite or maps outside the support (rounding at huge |u|).
        """
        u = jnp.asarray(u, dtype=jnp.float64)
        total = jnp.zeros(u.shape[:-1])
        for i, n in enumerate(self.names):
            x, log_jac = self.marginals[n].from_unconstrained(u[..., i])
            total = total + self.marginals[n].log_density(x) + log_jac
        return jnp.where(jnp.isfinite(total), total, -jnp.inf)

    def log_density(self, params: Mapping[str, float]):
        """ln p(x) of the prior in SI space (no Jacobian); ``-inf`` outside the support. Pure JAX."""
        return sum(self.marginals[n].log_density(params[n]) for n in self.names)

    def median(self) -> dict[str, float]:
        """name -> median of each marginal [SI]."""
        return {n: self.marginals[n].median() for n in self.names}

    def median_unconstrained(self):
        """u at the marginal medians, shape (d,), NumPy."""
        return self.to_unconstrained(self.median())

    def sample(self, key_or_rng, n: int) -> np.ndarray:
        """``n`` independent prior draws in unconstrained space, shape (n, d), float64 numpy.

        ``key_or_rng``: a ``numpy.random.Generator`` or an int seed.
        """
        rng = key_or_rng if isinstance(key_or_rng, np.random.Generator) else np.random.default_rng(key_or_rng)
        columns = [
            np.asarray(self.marginals[name].to_unconstrained(self.marginals[name].sample(rng, n)))
            for name in self.names
        ]
        return np.stack(columns, axis=-1) if columns else np.zeros((n, 0))

    def sample_params(self, key_or_rng, n: int) -> dict[str, np.ndarray]:
        """``n`` prior draws as a dict name -> array (n,) [SI]."""
        u = self.sample(key_or_rng, n)
        return {k: np.asarray(v) for k, v in self.from_unconstrained(u).items()}


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
    "ALL_PARAMETERS",
    "DEFAULT_PRIORS_DIR",
    "LIKELIHOOD_PARAMETERS",
    "Marginal",
    "Prior",
    "load_prior",
    "parse_entry",
    "prior_files",
    "prior_for",
    "starting_prior",
]
