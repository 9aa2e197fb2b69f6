"""The log posterior the sampler sees: prior (file) + specimen hierarchy + likelihood, over one flat vector.

``theta = [u (d,), c (v (n_specimens - 1),)]``: ``u`` the prior's parameters in unconstrained space (see
:class:`~peano_bayes.inference.Prior`), ``c`` the specimens' log contrasts, ``n_specimens - 1`` for each of the
``v`` sampled parameters that differ between specimens (:data:`~peano_bayes.inference.reduce.SPECIMEN_VARYING`:
the wall stiffnesses, the friction's pre-sliding stiffness and the mount compliance).

**Specimens as a hierarchy.** Specimen ``s`` of a material has ``ln x_s = mu + tau z_s`` for each varying
parameter ``x``, ``z_s ~ N(0, 1)`` independent across specimens and parameters, ``tau = specimen_log_sd`` (one
spread for all varying parameters, so that with two specimens the spread is estimated from ``v`` contrasts,
not one). The likelihood depends only on the specimens' values, that is on their geometric mean ``m = mu +
tau z_bar`` and their contrasts ``o = H c`` (``H`` (n, n-1) orthonormal Helmert contrasts, ``c_j ~ N(0,
tau^2)``). The sampler therefore samples ``m`` (the prior's entry of ``x``) and ``c``, and the population value
follows exactly, given ``m`` and ``tau``: ``mu = m - tau z_bar``, ``z_bar ~ N(0, 1/n)``, when the population
prior is flat in ``ln x`` over a few ``tau`` (loguniform priors are; the bundled lognormal ones have
``sigma_log >= 1``, against ``tau / sqrt(n)`` near 0.05). A new specimen is ``mu + tau z_new``.
:meth:`Posterior.levels` turns draws into these three levels.

Why contrasts are centred (``c ~ N(0, tau^2)``) rather than non-centred (``c = tau z``): the rig's tests pin
the specimens' differences far more tightly than their spread (on the bundled TP data the stiffness contrast's
posterior sd is 0.0003 against a spread near 0.07), and with data that strong the non-centred form turns each
contrast into a curved ridge ``tau z = o`` that an ensemble sampler crosses slowly.

With one specimen there is no ``c`` and no spread. Parameters the chosen tests cannot inform (the inlet flow
and load damping without a step test) are held at their nominal values instead of being sampled.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ..physics import ModelConfig
from .fit import residual_correlation, structured_lag1
from .likelihood import linearise_input_error, pointwise_log_likelihood, with_residual_lag1
from .priors import Prior
from .reduce import OBSERVED, SPECIMEN_OFFSET, SPECIMEN_VARYING, Observations

#: Parameters only the step response informs: the inlet restriction and the load's damping.
STEP_ONLY_PARAMETERS = frozenset(
    {
        "orifice_area_m2",
        "laminar_conductance_m3_per_s_pa",
        "damping_up_ns_per_m",
        "damping_down_ns_per_m",
        "damping_quadratic_ns2_per_m2",
    }
)
#: Held at their nominal values unless asked otherwise: shape constants the paper's four tests cannot separate
#: from the amplitudes they shape (the seal length fraction, the bending stiffening exponent, the extension
#: stiffening rate). Sampled, they wandered along curved ridges of the posterior (tau grew with the chain, 68 ->
#: 212 steps over 1500, on TP). The bundled datasets were generated with these three at nominal. The friction
#: element's pre-sliding stiffness is not held: the rig draws it per specimen like the wall stiffnesses, and
#: where friction is strong the load cycles and blocking tests resolve it (see
#: :data:`~peano_bayes.inference.reduce.SPECIMEN_VARYING`).
DEFAULT_HELD = ("length_fraction", "bending_exponent", "extension_rate")
SPECIMEN_SD = "specimen_log_sd"
CONTRAST_PREFIX = "specimen_contrast_"


def fixed_batches(thetas: np.ndarray, rows: int) -> list[np.ndarray]:
    """``thetas`` (n, D) split into batches of exactly ``rows`` points, the last padded with copies of the last
    point, so a compiled function sees one batch shape; the caller keeps the first n results."""
    padded = np.concatenate([thetas, np.repeat(thetas[-1:], -thetas.shape[0] % rows, axis=0)])
    return [padded[i : i + rows] for i in range(0, padded.shape[0], rows)]


def helmert(n: int) -> np.ndarray:
    """(n, n-1) orthonormal contrasts: columns orthogonal to each other and to the ones vector."""
    h = np.zeros((n, max(n - 1, 0)))
    for j in range(1, n):
        h[:j, j - 1] = -1.0 / math.sqrt(j * (j + 1))
        h[j, j - 1] = j / math.sqrt(j * (j + 1))
    return h


@dataclass(frozen=True, eq=False)
class Posterior:
    """Log posterior of one dataset. Build with :func:`build_posterior`.

    **Fields:** ``prior`` over the sampled parameters; ``observations``; ``config``; ``fixed`` values of the
    model parameters not sampled [SI]; ``family`` of the likelihood; ``batch_rows``: the number of parameter
    points per call of the compiled batched log posterior (:attr:`batched` pads and splits every batch into
    calls of this size, so one compilation serves every batch size; ``None``: one call, and one compilation, per
    batch size).
    """

    prior: Prior
    observations: Observations
    config: ModelConfig
    fixed: dict
    family: str = "gaussian"
    batch_rows: int | None = None
    # Compiled functions, shared (by reference) with the posteriors made by :meth:`with_observations`,
    # :meth:`with_batch_rows`, :meth:`with_input_error_at` and :meth:`with_residual_lag1`; any other
    # ``dataclasses.replace`` (another prior, fixed values or family) starts an empty one.
    _compiled: dict = field(default_factory=dict, repr=False, init=False)

    @property
    def varying(self) -> tuple[str, ...]:
        """The sampled parameters that differ between specimens (none with one specimen), in prior order."""
        if len(self.observations.specimens) < 2 or SPECIMEN_SD not in self.prior.names:
            return ()
        return tuple(n for n in self.prior.names if n in SPECIMEN_VARYING)

    @property
    def contrast_names(self) -> tuple[str, ...]:
        """(v (n_specimens - 1),) names of the contrasts in theta: ``specimen_contrast_<parameter>_<j>``."""
        n = len(self.observations.specimens)
        return tuple(f"{CONTRAST_PREFIX}{p}_{j + 1}" for p in self.varying for j in range(n - 1))

    @property
    def names(self) -> tuple[str, ...]:
        """(D,) theta's entries: the prior's parameters, then the specimen contrasts."""
        return self.prior.names + self.contrast_names

    @property
    def units(self) -> dict[str, str]:
        """name -> SI unit of every entry of theta (contrasts are log factors, "-")."""
        return {**dict(self.prior.units), **{n: "-" for n in self.names[self.prior.ndim :]}}

    @property
    def ndim(self) -> int:
        return len(self.names)

    @property
    def n_contrasts(self) -> int:
        return len(self.contrast_names)

    def offsets(self, theta) -> dict:
        """name -> (..., n_specimens) log factor of each specimen's value over the specimens' geometric mean,
        for every varying parameter, from theta (..., D)."""
        theta = jnp.asarray(theta)
        n = len(self.observations.specimens)
        c = theta[..., self.prior.ndim :].reshape(theta.shape[:-1] + (len(self.varying), n - 1))
        o = c @ jnp.asarray(helmert(n)).T
        return {p: o[..., i, :] for i, p in enumerate(self.varying)}

    def params(self, theta) -> dict:
        """Everything the likelihood reads, from theta (D,): model and noise parameters [SI] and, with
        several specimens, ``specimen_log_offset`` (name -> (n_specimens,) log factors)."""
        theta = jnp.asarray(theta, dtype=jnp.float64)
        d = self.prior.ndim
        params = {**{k: jnp.asarray(v) for k, v in self.fixed.items()}, **self.prior.from_unconstrained(theta[:d])}
        if self.n_contrasts:
            params[SPECIMEN_OFFSET] = self.offsets(theta)
        return params

    def levels(self, thetas: np.ndarray, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """The hierarchy's three levels from draws ``thetas`` (..., D), in SI units (see the module docstring).

        Returns, for every parameter of the prior: ``name`` (...,) the **population** value ``mu`` (for a
        varying parameter the specimens' geometric mean moved by ``-tau z_bar``, ``z_bar ~ N(0, 1/n)`` drawn
        with ``rng``; otherwise the sampled value); and for each varying one ``specimen__<name>`` (...,
        n_specimens) every specimen's own value and ``new_specimen__<name>`` (...,) a specimen not yet made,
        ``mu exp(tau z_new)``. The contrasts are passed through under their names."""
        thetas = np.asarray(thetas, dtype=float)
        d = self.prior.ndim
        values = {k: np.asarray(v) for k, v in self.prior.from_unconstrained(thetas[..., :d]).items()}
        out = dict(values)
        for j, name in enumerate(self.contrast_names):
            out[name] = thetas[..., d + j]
        if not self.varying:
            return out
        n = len(self.observations.specimens)
        tau = values[SPECIMEN_SD]
        offsets = {k: np.asarray(v) for k, v in self.offsets(thetas).items()}
        shape = thetas.shape[:-1]
        for p in self.varying:
            m = values[p]
            mu = m * np.exp(-tau * rng.standard_normal(shape) / math.sqrt(n))
            out[p] = mu
            out[f"specimen__{p}"] = m[..., None] * np.exp(offsets[p])
            out[f"new_specimen__{p}"] = mu * np.exp(tau * rng.standard_normal(shape))
        return out

    def log_prior(self, theta):
        theta = jnp.asarray(theta, dtype=jnp.float64)
        d = self.prior.ndim
        total = self.prior.log_prob(theta[:d])
        if self.n_contrasts:
            sd = self.prior.from_unconstrained(theta[:d])[SPECIMEN_SD]
            c = theta[d:]  # every contrast of every varying parameter ~ N(0, sd^2)
            total = total + jnp.sum(-0.5 * (c / sd) ** 2 - jnp.log(sd) - 0.5 * math.log(2.0 * math.pi))
        return total

    def pointwise(self, theta):
        """(n_bins,) log-likelihood of every measured bin, groups concatenated in ``observations`` order
        (unmeasured bins excluded, see :meth:`observed`)."""
        parts = pointwise_log_likelihood(self.params(theta), self.observations, config=self.config, family=self.family)
        return jnp.concatenate(
            [p[np.isfinite(g.observed)] for p, g in zip(parts, self.observations.groups, strict=True)]
        )

    def log_prob(self, theta, groups=None, *, exact_inputs: bool = False):
        """ln p(theta | data) up to a constant; ``-inf``, never NaN, for any theta. ``groups`` (default this
        posterior's) may be traced: unmeasured bins contribute 0, so no data-dependent masking is needed.
        ``exact_inputs``: treat the fitted driving inputs as exact (leave their error out of the likelihood,
        see :data:`~peano_bayes.inference.reduce.INPUT_ERROR_TESTS`)."""
        observations = self.observations
        if groups is not None:
            observations = dataclasses.replace(observations, groups=tuple(groups))
        if exact_inputs:
            exact = tuple(dataclasses.replace(g, strain_error=None, pressure_error=None) for g in observations.groups)
            observations = dataclasses.replace(observations, groups=exact)
        lp = self.log_prior(theta)
        parts = pointwise_log_likelihood(self.params(theta), observations, config=self.config, family=self.family)
        ll = sum(jnp.sum(p) for p in parts)
        total = jnp.where(jnp.isfinite(lp), lp + ll, -jnp.inf)
        return jnp.where(jnp.isnan(total), -jnp.inf, total)

    def _shared(self, name: str, build):
        """The compiled function ``name`` of this posterior's family, compiled on first use; it takes the run
        groups as its last argument."""
        if name not in self._compiled:
            self._compiled[name] = build()
        return self._compiled[name]

    @property
    def batched(self):
        """``f(thetas (n, D)) -> (n,)`` numpy log posterior, jit+vmap (one compilation per batch size, shared
        with every posterior from :meth:`with_observations`)."""
        f = self._shared("batched", lambda: jax.jit(jax.vmap(self.log_prob, in_axes=(0, None))))
        groups, rows = self.observations.groups, self.batch_rows

        def call(thetas):
            thetas = np.asarray(thetas, dtype=np.float64)
            n = thetas.shape[0]
            if not rows or n == rows:
                return np.asarray(f(jnp.asarray(thetas), groups))
            parts = [np.asarray(f(jnp.asarray(batch), groups)) for batch in fixed_batches(thetas, rows)]
            return np.concatenate(parts)[:n]

        return call

    def with_batch_rows(self, rows: int | None) -> Posterior:
        """This posterior evaluating batches in calls of ``rows`` points (see ``batch_rows``); the compiled
        functions are shared (the batch size is not part of them)."""
        if rows is not None and rows < 1:
            raise ValueError(f"batch_rows must be >= 1, got {rows}")
        other = dataclasses.replace(self, batch_rows=rows)
        object.__setattr__(other, "_compiled", self._compiled)
        return other

    @property
    def value_and_grad(self):
        """``f(theta (D,)) -> (-ln p, gradient)`` of the negative log posterior, compiled once per family, with
        the fitted driving inputs treated as exact (``log_prob(..., exact_inputs=True)``). It serves the mode and
        the Laplace covariance that start the sampler, and its gradient through the input error's forward-mode
        derivatives would cost a second-order compilation (measured on TP: 95-102 s against 38-41 s,
        ``experiments/bench_input_error.py``) for a start point that the overdispersed start absorbs."""
        f = self._shared(
            "value_and_grad",
            lambda: jax.jit(jax.value_and_grad(lambda t, g: -self.log_prob(t, g, exact_inputs=True))),
        )
        groups = self.observations.groups
        return lambda theta: f(jnp.asarray(theta, dtype=jnp.float64), groups)

    def with_observations(self, observations: Observations) -> Posterior:
        """This posterior on other data of the same protocol (same tests, specimens, run keys and bin counts):
        it reuses the compiled functions, so a study over many simulated datasets compiles once."""
        mine = jax.tree_util.tree_structure(self.observations.groups)
        theirs = jax.tree_util.tree_structure(observations.groups)
        shapes = lambda o: [np.shape(x) for x in jax.tree_util.tree_leaves(o.groups)]  # noqa: E731
        if mine != theirs or shapes(self.observations) != shapes(observations) or (
            self.observations.specimens != observations.specimens
        ):
            raise ValueError("with_observations needs data of the same protocol: tests, specimens, runs and bins")
        other = dataclasses.replace(self, observations=observations)
        object.__setattr__(other, "_compiled", self._compiled)
        return other

    def with_input_error_at(self, theta) -> Posterior:
        """This posterior with the fitted inputs' error linearised once, at ``theta`` (D,), instead of at every
        evaluation (:func:`~peano_bayes.inference.likelihood.linearise_input_error`): the Jacobian of the
        predictions along the error's columns changes little over the posterior, and computing it at every
        evaluation costs one forward-mode derivative of the simulation per column. On the bundled TP data around the
        exact-input mode, over 38 draws of the Laplace approximation the log posterior differs from the one with the
        Jacobian at each point by 0.009 in sd (its own spread there: 5.5), and an evaluation costs 0.56-0.63 times
        as much (``experiments/input_error_linearisation.py``). The compiled functions are shared (they are traced
        again for the new group structure once)."""
        observations = linearise_input_error(self.params(jnp.asarray(theta)), self.observations, config=self.config)
        other = dataclasses.replace(self, observations=observations)
        object.__setattr__(other, "_compiled", self._compiled)
        return other

    def residual_lag1_at(self, theta) -> dict[str, float]:
        """test -> lag-1 correlation of each test whose residuals at ``theta`` (D,) fail the structure check
        (:func:`~peano_bayes.inference.fit.residual_correlation`, :func:`~peano_bayes.inference.fit.structured_lag1`):
        what :meth:`with_residual_lag1` takes, the rule ``fit`` and the SBC apply at the exact-input mode, after
        :meth:`with_input_error_at` (the whitening uses the held Jacobian)."""
        return structured_lag1(residual_correlation(self.params(theta), self.observations, self.config))

    @property
    def residual_lag1(self) -> dict[str, float]:
        """test -> the lag-1 correlation its residuals are sampled with (AR(1)); tests with independent bins are
        absent."""
        return {g.test: float(g.residual_lag1) for g in self.observations.groups if g.residual_lag1 is not None}

    def with_residual_lag1(self, lag1) -> Posterior:
        """This posterior with the residuals of each test in ``lag1`` (test -> lag-1 correlation) taken as AR(1)
        from bin to bin (:func:`~peano_bayes.inference.likelihood.with_residual_lag1`); ``{}`` returns it
        unchanged. The compiled functions are shared (traced again for the new group structure once)."""
        if not lag1:
            return self
        other = dataclasses.replace(self, observations=with_residual_lag1(self.observations, lag1))
        object.__setattr__(other, "_compiled", self._compiled)
        return other

    def observed(self) -> dict[str, np.ndarray]:
        """The measured bins, in :meth:`pointwise` order: ``value``, ``test``, ``specimen``, ``run``,
        ``time_s``, ``count``, ``unit``, and the inputs the simulation was driven with, averaged over each bin:
        ``strain`` [-] (imposed in a load cycle; the measured strain in the other tests) and ``pressure_pa``."""
        numeric = ("value", "time_s", "count", "strain", "pressure_pa")
        cols: dict[str, list] = {k: [] for k in (*numeric, "test", "specimen", "run", "unit")}
        for g in self.observations.groups:
            ok = np.isfinite(g.observed)
            time_s = g.bin_time_s[g.shared]
            per_bin = lambda x, g=g: g.per_bin(np.asarray(x)).mean(axis=-1)[g.shared]  # noqa: E731
            strain, pressure = per_bin(g.strain), per_bin(g.pressure_pa)
            for r, key in enumerate(g.keys):
                n = int(ok[r].sum())
                cols["value"].append(g.observed[r][ok[r]])
                cols["time_s"].append(time_s[r][ok[r]])
                cols["count"].append(g.counts[r][ok[r]])
                cols["strain"].append(strain[r][ok[r]])
                cols["pressure_pa"].append(pressure[r][ok[r]])
                cols["test"] += [g.test] * n
                cols["specimen"] += [key[0]] * n
                cols["run"] += [int(key[2])] * n
                cols["unit"] += ["N" if OBSERVED[g.test][0] == "force_n" else "-"] * n
        return {k: (np.concatenate(v) if k in numeric else np.asarray(v)) for k, v in cols.items()}


def build_posterior(
    observations: Observations,
    prior: Prior,
    *,
    config: ModelConfig | None = None,
    family: str = "gaussian",
    fixed: dict | None = None,
    held=DEFAULT_HELD,
) -> Posterior:
    """The posterior of ``observations`` under ``prior`` (a full prior, e.g. ``prior_for(code)``).

    Samples every parameter ``config`` (default ``prior.config``) reads that the tests present inform, the
    noise scale of each test present and, with several specimens, ``specimen_log_sd`` and the contrasts of each
    sampled parameter of :data:`~peano_bayes.inference.reduce.SPECIMEN_VARYING`; the
    rest, and the ``held`` names (default :data:`DEFAULT_HELD`; ``()`` samples them too), are held at ``fixed``
    or nominal values.
    """
    config = prior.config if config is None else config
    tests = {g.test for g in observations.groups}
    if not tests:
        raise ValueError("the dataset has no runs to fit")
    added = [
        key
        for g in observations.groups
        if g.added_compliance_m_per_n is not None
        for key, c in zip(g.keys, g.added_compliance_m_per_n[g.shared], strict=True)
        if c > 0
    ]
    if added and not config.mount:
        raise ValueError(
            f"{len(added)} runs (first {added[0]}) carry an added mount compliance, but the model has no mount "
            "element to add it to: use a configuration with mount=True"
        )
    model = [n for n in config.parameter_names() if "step" in tests or n not in STEP_ONLY_PARAMETERS]
    noise = [OBSERVED[t][1] for t in OBSERVED if t in tests]
    pooling = [SPECIMEN_SD] if len(observations.specimens) > 1 else []
    fixed = dict(fixed or {})
    sampled = prior.select([n for n in model + noise + pooling if n not in fixed and n not in held])
    held = {k: float(v) for k, v in {**config.nominal_parameters(), **fixed}.items() if k not in sampled.names}
    return Posterior(sampled, observations, config, held, family)


__all__ = [
    "CONTRAST_PREFIX",
    "DEFAULT_HELD",
    "SPECIMEN_SD",
    "STEP_ONLY_PARAMETERS",
    "Posterior",
    "build_posterior",
    "fixed_batches",
    "helmert",
]
