"""Priors as data: a :class:`Prior` (JAX log-density, numpy sampling) of per-parameter :class:`Marginal`
distributions, read from the bundled ``priors/*.toml`` or a user's file by :mod:`~.prior_files`.

**Unconstrained space** (what samplers and optimizers see), per parameter with support [a, b]:

- ``a > 0``, ``b`` finite, log-scale distribution (lognormal, loguniform): ``u = logit((ln x - ln a)/(ln b - ln a))``;
- ``a``, ``b`` finite otherwise: ``u = ln(x - a) - ln(b - x)`` (log-odds; for a = 0 this is ``~ln x`` near 0);
- ``a`` finite, ``b = inf``: ``u = ln(x - a)``;  ``a = -inf``, ``b = inf``: ``u = x``.

:meth:`Prior.log_prob` is the density of ``u``: the density of ``x`` plus ``ln |dx/du|``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np
from scipy import special

from ..errors import PeanoBayesInputError
from ..physics.model import PARAMETERS, ModelConfig, Parameter

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
_LOG_SCALE = ("lognormal", "loguniform")
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

    def _sf(self, x: np.ndarray) -> np.ndarray:
        """1 - CDF of the *untruncated* distribution at x [SI], accurate far into the upper tail."""
        x = np.asarray(x, dtype=float)
        d = self.distribution
        if d == "lognormal":
            with np.errstate(divide="ignore"):
                return special.ndtr(-(np.log(x) - self.loc) / self.scale)
        if d in ("normal", "truncnormal"):
            return special.ndtr(-(x - self.loc) / self.scale)
        if d == "halfnormal":
            return 2.0 * special.ndtr(-np.maximum(x, 0.0) / self.scale)
        return 1.0 - self._cdf(x)  # the uniform families: no tail to lose

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

    def position(self, x) -> np.ndarray:
        """Where ``x`` [SI] sits in this truncated prior, in prior sd [-] (any shape, NumPy).

        The standard-normal score of the prior's own CDF at ``x``: 0 at the prior median, -2 and +2 where a
        normal prior has its 2.3 % and 97.7 % quantiles, whatever the distribution (for a lognormal it is the
        distance from the median in sigma_log; for a truncated prior the truncation is accounted for). The upper
        half is read from the tail's own mass, so it stays finite far out. The support's ends map to -inf and
        +inf; values beyond them are clipped onto them.
        """
        c_low, c_high = self._cdf(self.low), self._cdf(self.high)
        x = np.clip(np.asarray(x, dtype=float), self.low, self.high)
        below = np.clip((self._cdf(x) - c_low) / (c_high - c_low), 0.0, 1.0)
        above = np.clip((self._sf(x) - self._sf(self.high)) / (c_high - c_low), 0.0, 1.0)  # the upper tail's mass
        return np.where(below < 0.5, special.ndtri(below), -special.ndtri(above))

    def in_tail(self, z, sd: float) -> np.ndarray:
        """True where a position ``z`` [prior sd] (:meth:`position`) lies more than ``sd`` into a tail of this prior.

        A halfnormal's lower end is its mode, not a tail, so only its upper end counts. For a (log)uniform prior,
        which has no tails, a position this far out means a value pressed against a bound of its support: the
        data ask for values the prior excludes, a conflict of the same kind."""
        z = np.asarray(z, dtype=float)
        if self.distribution == "halfnormal":
            return z > sd
        return np.abs(z) > sd

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


__all__ = ["ALL_PARAMETERS", "LIKELIHOOD_PARAMETERS", "Marginal", "Prior"]
