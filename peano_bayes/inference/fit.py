"""Multi-start least squares: optimistix Levenberg-Marquardt vmapped over starts drawn from the prior.

The residual vector of one parameter point ``u`` (unconstrained, see :class:`~peano_bayes.inference.Prior`) is
every measured bin's ``(observed - predicted) / (sigma / sqrt(count))`` with the noise scales held at given
values, followed by a Gaussian stand-in for the prior, ``(u - prior median) / prior spread`` (the spread is the
standard deviation of prior draws in u). Its minimum is a MAP-like point; the Laplace covariance
``(J^T J)^-1`` at the best start seeds the sampler. Noise scales are then re-estimated from the residuals.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from types import MappingProxyType

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..defaults import DEFAULT_STARTS
from ..errors import PeanoBayesInputError
from ..physics import ModelConfig
from .denoise import noise_sd
from .likelihood import SOLVER_TOLERANCE, bin_noise_sd, predict, whitened_residuals
from .priors import Prior
from .reduce import OBSERVED, Observations
from .status import FitStatus

#: Noise scales [per raw sample] used to weight the residuals when none are given.
DEFAULT_NOISE = {
    "noise_load_cycle_force_n": 0.5,
    "noise_blocking_force_n": 0.5,
    "noise_stroke_strain": 5e-4,
    "noise_step_strain": 5e-4,
}


def dense_jacobian(residuals, basis=None):
    """``residuals(u, args)`` (u (d,) -> (n,)) whose derivative in ``u`` is its forward-mode Jacobian (n, d),
    materialized once per point; ``args`` are not differentiated. ``basis(u, args)``, if given, returns a (d, k)
    matrix whose columns span every direction in which the residuals can change (for a fit that holds some of
    ``u`` fixed, the unit vectors of the free entries, padded with zero columns): the Jacobian is then pushed
    forward along those k directions only and mapped back, ``J_k B^T``, exact where the columns span the free
    directions and k forward tangents cheaper than d. The tangents of ``args`` are dropped: a derivative with
    respect to anything in ``args`` (held values, noise scales) comes out zero.

    Why: optimistix's Levenberg-Marquardt linearizes the residual function and transposes that linearization for
    the gradient of its trust-region test. Through the physics' scans and root solves that builds the model's
    primal, tangent and transposed programs, and compiling them dominates a fit. With the Jacobian materialized
    by ``jax.jacfwd`` (which the solver's QR needs anyway), the transpose is a matrix's and only the tangent
    program is built (``experiments/bench_fit_compile.py`` measures both).
    """

    @jax.custom_jvp
    def wrapped(u, args):
        return residuals(u, args)

    @wrapped.defjvp
    def _jvp(primals, tangents):
        u, args = primals

        def both(v):
            r = residuals(v, args)
            return r, r

        if basis is None:
            jac, r = jax.jacfwd(both, has_aux=True)(u)
        else:
            b = basis(u, args)
            jac_k, r = jax.jacfwd(lambda z: both(u + b @ z), has_aux=True)(jnp.zeros(b.shape[1], u.dtype))
            jac = jac_k @ b.T
        return r, jac @ tangents[0]

    return wrapped


@dataclass(frozen=True, eq=False)
class FitResult:
    """Best of the multi-start least squares.

    **Fields:** ``names`` (d,); ``u`` (d,) best point, unconstrained; ``params`` name -> value [SI];
    ``covariance`` (d, d) Laplace covariance in u; ``cost`` half the sum of squared residuals at ``u``;
    ``n_starts`` the starts that ran (:func:`fit` stops adding starts once the best few agree); ``n_failed``
    starts that ended non-finite or where the physics solver misses its tolerance, in any round;
    ``n_step_limit`` starts, not failed, that the solver had not finished in their last round (mostly stopped by
    ``max_steps``; kept: their point is valid, only not polished); ``converged`` whether the best start met the
    solver's tolerance (``None``: not recorded); ``rounds`` how many rounds of at most ``max_steps`` steps the
    best start's batch ran;
    ``start_costs`` (n_starts,) of the last round (inf where failed); ``noise`` the weighting noise scales;
    ``noise_estimate`` noise scales re-estimated from the residuals; ``quality`` per test: RMSE, max |error|
    and R^2 of the observed signal; ``seconds`` wall time (compile included); ``optima`` other local optima the
    starts converged to (:func:`distinct_optima`), name -> value [SI] each, best first: where the sampler's
    independently started ensembles begin.
    """

    names: tuple[str, ...]
    u: np.ndarray
    params: dict
    covariance: np.ndarray
    cost: float
    n_starts: int
    n_failed: int
    n_step_limit: int
    start_costs: np.ndarray
    noise: dict
    noise_estimate: dict
    quality: dict = field(default_factory=dict)
    seconds: float = 0.0
    converged: bool | None = None
    rounds: int = 1
    optima: tuple[dict, ...] = ()

    @property
    def status(self) -> FitStatus | None:
        """How the least squares ended (:class:`~peano_bayes.inference.status.FitStatus`); ``None`` where not
        recorded."""
        if self.converged is None:
            return None
        return FitStatus.SUCCESSFUL if self.converged else FitStatus.STEP_LIMIT

    def outcome(self) -> str:
        """One phrase on how the multi-start least squares ended, for a log line."""
        in_rounds = f"{self.rounds} round{'s' if self.rounds != 1 else ''}"
        best = (
            ""
            if self.converged is None
            else f"best start converged in {in_rounds}; "
            if self.converged
            else f"best start NOT converged after {in_rounds}; "
        )
        return f"{best}of {self.n_starts} starts {self.n_failed} failed and {self.n_step_limit} stopped unfinished"

    def to_json(self) -> dict:
        """The JSON-ready record ``fit.json`` holds (arrays as lists; ``status`` the code of :attr:`status`);
        :meth:`from_json` reads it back to an equal result."""
        return {
            "names": list(self.names),
            "u": np.asarray(self.u).tolist(),
            "params": dict(self.params),
            "covariance": np.asarray(self.covariance).tolist(),
            "noise": dict(self.noise),
            "noise_estimate": dict(self.noise_estimate),
            "cost": self.cost,
            "n_starts": self.n_starts,
            "n_failed": self.n_failed,
            "n_step_limit": self.n_step_limit,
            "converged": self.converged,
            "status": None if self.status is None else self.status.value,
            "rounds": self.rounds,
            "optima": [dict(o) for o in self.optima],
            "start_costs": np.asarray(self.start_costs).tolist(),
            "quality": self.quality,
            "seconds": self.seconds,
        }

    @classmethod
    def from_json(cls, record: dict, *, where: str = "fit.json") -> FitResult:
        """The result a :meth:`to_json` record describes; a record lacking a field this version needs is refused
        naming ``where`` and the fields (it was written by an earlier version: fit again without resuming)."""
        missing = [k for k in _RECORD_FIELDS if k not in record]
        if missing:
            raise PeanoBayesInputError(
                f"{where}: no {', '.join(missing)}: written by an earlier version of peano-bayes; run again "
                "without --resume"
            )
        return cls(
            names=tuple(record["names"]),
            u=np.asarray(record["u"], dtype=float),
            params=dict(record["params"]),
            covariance=np.asarray(record["covariance"], dtype=float),
            cost=float(record["cost"]),
            n_starts=int(record["n_starts"]),
            n_failed=int(record["n_failed"]),
            n_step_limit=int(record["n_step_limit"]),
            start_costs=np.asarray(record["start_costs"], dtype=float),
            noise=dict(record["noise"]),
            noise_estimate=dict(record["noise_estimate"]),
            quality=dict(record.get("quality", {})),
            seconds=float(record.get("seconds", 0.0)),
            converged=record.get("converged"),
            rounds=int(record.get("rounds", 1)),
            optima=tuple(dict(o) for o in record.get("optima", ())),
        )


#: The fields :meth:`FitResult.from_json` cannot do without.
_RECORD_FIELDS = ("names", "u", "params", "covariance", "noise", "noise_estimate", "cost", "n_starts", "n_failed",
                  "n_step_limit", "start_costs")  # fmt: skip


def prior_spread(prior: Prior, seed: int) -> jnp.ndarray:
    """(d,) standard deviation of 4000 prior draws in u (at least 1e-3): the scale of the fit's prior term."""
    draws = prior.sample(np.random.default_rng(seed), 4000)
    return jnp.asarray(np.maximum(np.std(draws, axis=0), 1e-3))


def _residuals_and_solver_ok(observations: Observations, prior: Prior, config: ModelConfig):
    """``evaluate(u, args) -> (residuals (n,), solver_ok, predictions)`` with ``args = (groups, spread, fixed,
    noise)`` (:func:`program_arguments`): the weighted residuals of the run ``groups`` (those of ``observations``
    or others of the same shapes), whether every simulation met its solver tolerance (:data:`SOLVER_TOLERANCE`)
    and each group's prediction (r, m), from one simulation. The groups, the prior term's ``spread`` (d,), the
    ``fixed`` parameters and the ``noise`` scales are arguments, not constants of the compiled program, so fits
    whose data shapes, prior and configuration agree (materials, seeds, drawn constants) share one program
    through the persistent compilation cache."""
    centre = prior.median_unconstrained()

    def evaluate(u, args):
        groups, spread, fixed, noise = args
        params = {**fixed, **prior.from_unconstrained(u)}
        parts, ok, predictions = [], jnp.asarray(True), []
        for group in groups:
            predicted, errors = predict(params, group, config=config, geometry=observations.geometry)
            scale = bin_noise_sd(noise[OBSERVED[group.test][1]], group)
            observed = jnp.asarray(group.observed)
            measured = jnp.isfinite(observed)
            parts.append(jnp.where(measured, (jnp.where(measured, observed, 0.0) - predicted) / scale, 0.0).ravel())
            ok = ok & jnp.all(errors <= SOLVER_TOLERANCE[group.test])
            predictions.append(predicted)
        parts.append((u - centre) / spread)
        return jnp.concatenate(parts), ok, predictions

    return evaluate


def program_arguments(groups, spread, fixed: dict, noise: dict) -> tuple:
    """``(groups, spread, fixed, noise)`` as the arguments of :func:`_residuals_and_solver_ok`'s ``evaluate``: the
    numbers as arrays (traced, so they do not enter the compiled program as constants). The held values keep
    ``jnp.asarray``'s weak type, as :meth:`Posterior.params` gives them: the physics' traced program
    (``likelihood._traced_predict_sets``) keys on it, and one type lets the fit and the posterior share it."""
    as_array = lambda v: jnp.asarray(v, dtype=jnp.float64)  # noqa: E731
    return (
        groups,
        as_array(spread),
        {k: jnp.asarray(v) for k, v in fixed.items()},
        {k: as_array(v) for k, v in noise.items()},
    )


def residual_function(observations: Observations, prior: Prior, config: ModelConfig, noise, spread, fixed):
    """``fn(u, args) -> residuals (n,)`` for optimistix, over the parameters of ``prior`` (the rest ``fixed``)."""
    evaluate = _residuals_and_solver_ok(observations, prior, config)
    args = program_arguments(observations.groups, spread, fixed, noise)
    return lambda u, _: evaluate(u, args)[0]


def least_squares_program(observations: Observations, prior: Prior, config: ModelConfig, *, max_steps: int,
                          rtol: float, atol: float):  # fmt: skip
    """The jitted multi-start least squares of :func:`fit`: ``run(starts (k, d), args)`` with ``args`` from
    :func:`program_arguments` returns per start the end point (k, d), whether it is usable (finite cost, physics
    solver within tolerance), whether the solver converged, the cost (k,) (inf where unusable), the Jacobian
    (k, n, d) and each group's prediction. Data shapes, geometry, prior, configuration and the solver settings
    make the program; the numbers in ``args`` do not, so every seed and held value lowers to the same program,
    which the persistent compilation cache (:func:`~peano_bayes.enable_compilation_cache`) compiles once; each
    call still traces and lowers it."""
    evaluate = _residuals_and_solver_ok(observations, prior, config)
    fn = dense_jacobian(lambda u, args: evaluate(u, args)[0])
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)

    def one(u0, args):
        sol = optx.least_squares(fn, solver, u0, args, max_steps=max_steps, throw=False)
        r, solver_ok, predictions = evaluate(sol.value, args)
        cost = 0.5 * jnp.sum(r**2)
        # A point where the physics solver misses its tolerance has likelihood zero (see likelihood.py).
        ok = jnp.isfinite(cost) & solver_ok
        # The end point's Jacobian and predictions come out of the same program: tracing the physics again
        # in programs of their own costs seconds, evaluating them for every start costs little.
        jac = jax.jacfwd(fn)(sol.value, args)
        return sol.value, ok, sol.result == optx.RESULTS.successful, jnp.where(ok, cost, jnp.inf), jac, predictions

    return jax.jit(jax.vmap(one, in_axes=(0, None)))


@eqx.filter_jit
def _all_predictions(params, groups, config: ModelConfig, geometry):
    return [predict(params, g, config=config, geometry=geometry)[0] for g in groups]


def predictions(params, observations: Observations, config: ModelConfig) -> list[np.ndarray]:
    """Each group's predicted signal at ``params``, from one compiled program over all groups, kept for the
    process per configuration, geometry and data shapes (the groups are its argument, so another material's data
    of the same shapes reuses it); evaluated op by op, each simulation's scan and root solve would compile on
    its own."""
    params = jax.tree_util.tree_map(jnp.asarray, params)
    return [np.asarray(x) for x in _all_predictions(params, observations.groups, config, observations.geometry)]


#: Residuals are called consistent with the noise when their mean square over the noise floor's is within this
#: many standard errors of 1 (chi-square: sd sqrt(2 / n_eff), n_eff from the lag-one autocorrelation).
NOISE_CONSISTENCY_SE = 3.0

#: Per observed signal, the tests whose signal changes slowly against the sampling rate: that sensor's noise is
#: estimated there (a step response rings faster than it is sampled, so second differences overstate it).
QUIET_TESTS = MappingProxyType({"force_n": ("load_cycle", "blocking"), "strain": ("stroke", "load_cycle", "blocking")})


def sensor_noise(runs) -> dict[str, float]:
    """test -> model-free sd of one raw sample of its observed signal [signal unit], for every test in ``runs``
    (:class:`~peano_bayes.data.Run`): the median over runs of :func:`~peano_bayes.inference.denoise.noise_sd`
    (second differences), taken where that sensor's signal is slow (:data:`QUIET_TESTS`), else on the test's
    own runs. Known before any model is fitted, so it is the floor a correct model's residuals reach."""
    noise = {}
    for test in {run.test for run in runs}:
        signal = OBSERVED[test][0]
        quiet = [r for r in runs if r.test in QUIET_TESTS[signal] and np.all(np.isfinite(getattr(r, signal)))]
        source = quiet or [r for r in runs if r.test == test]
        noise[test] = float(np.median([noise_sd(getattr(r, signal)) for r in source]))
    return noise


def lag1_effective_size(r: np.ndarray) -> float:
    """Effective number of independent values in the sequence ``r`` (n,): n (1 - rho) / (1 + rho), rho its lag-1
    correlation clipped to [0, 0.99] (exact for the variance of the mean of AR(1) values)."""
    n = r.size
    rho = float(np.corrcoef(r[:-1], r[1:])[0, 1]) if n > 2 and np.std(r) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.99)
    return n * (1 - rho) / (1 + rho)


def noise_excess(error: np.ndarray, floor: np.ndarray) -> dict:
    """How far residuals ``error`` (n,) [signal unit] are above their noise ``floor`` (n,) (each bin's sd from
    the sensor noise alone): the noise floor's RMSE, the **excess RMSE** sqrt(max(RMSE^2 - floor^2, 0)) (what
    the model misses beyond the noise, in the signal's unit) and whether the residuals are consistent with
    noise (:data:`NOISE_CONSISTENCY_SE`)."""
    ok = np.isfinite(error) & np.isfinite(floor) & (floor > 0)
    if not ok.any():
        return {"noise_floor_rmse": float("nan"), "excess_rmse": float("nan"), "consistent_with_noise": False}
    e, f = error[ok], floor[ok]
    ratio = float(np.mean((e / f) ** 2))
    tolerance = NOISE_CONSISTENCY_SE * np.sqrt(2.0 / max(lag1_effective_size(e / f), 1.0))
    return {
        "noise_floor_rmse": float(np.sqrt(np.mean(f**2))),
        "excess_rmse": float(np.sqrt(max(np.mean(e**2) - np.mean(f**2), 0.0))),
        "consistent_with_noise": bool(abs(ratio - 1.0) <= tolerance),
    }


def fit_quality(params, observations: Observations, config: ModelConfig, predicted=None, noise=None) -> dict:
    """Per test: RMSE, max |error| (in the observed signal's unit) and R^2 over the binned data. ``predicted``:
    each group's prediction at ``params``, if already computed. ``noise``: test -> model-free sd of one raw
    sample (:func:`sensor_noise`); with it each test whose sd is positive also carries :func:`noise_excess`'s
    ``noise_floor_rmse`` and ``excess_rmse`` (each bin's floor that sd over sqrt(samples in the bin)): the size
    of what the model misses beyond the sensor noise (the fitted inputs' error carried through included), a
    rough size of the discrepancy a prediction read off this test carries."""
    quality = {}
    predicted = predictions(params, observations, config) if predicted is None else predicted
    for group, prediction in zip(observations.groups, predicted, strict=True):
        observed = np.asarray(group.observed)
        measured = np.isfinite(observed)
        entry = quality.setdefault(group.test, {"errors": [], "values": [], "floors": []})
        entry["errors"].append((observed - prediction)[measured])
        entry["values"].append(observed[measured])
        if noise is not None and noise.get(group.test, 0.0) > 0:  # a signal without measurable noise has no floor
            floor = noise[group.test] / np.sqrt(np.maximum(np.asarray(group.counts, float), 1.0))
            entry["floors"].append(np.broadcast_to(floor, observed.shape)[measured])
    out = {}
    for test, entry in quality.items():
        error, values = np.concatenate(entry["errors"]), np.concatenate(entry["values"])
        unit = "N" if OBSERVED[test][0] == "force_n" else "-"
        out[test] = {
            "unit": unit,
            "rmse": float(np.sqrt(np.mean(error**2))),
            "max_error": float(np.max(np.abs(error))),
            "r2": float(1.0 - np.sum(error**2) / np.sum((values - values.mean()) ** 2)),
            "bins": int(error.size),
        }
        if entry["floors"]:
            excess = noise_excess(error, np.concatenate(entry["floors"]))
            out[test].update(noise_floor_rmse=excess["noise_floor_rmse"], excess_rmse=excess["excess_rmse"])
    return out


#: Lag-1 correlation of the whitened residuals above which a test's misfit counts as structured: the mean of
#: AR(1) residuals of that correlation is sqrt((1 + 0.2) / (1 - 0.2)) = 1.22 times as uncertain as independent
#: noise of the same size would make it.
CORRELATION_LIMIT = 0.2


def lag1_sums(z: np.ndarray) -> np.ndarray:
    """(r, 4) per row of ``z`` (r, m) (NaN where unmeasured), over its neighbouring bins that are both measured:
    sum z_i z_(i-1), sum z_i^2, sum z_(i-1)^2 and the number of such pairs; their lag-1 correlation is
    ``cross / sqrt(later earlier)``, pooled over rows by summing first (:func:`residual_correlation`)."""
    z = np.asarray(z, float)
    both = np.isfinite(z[:, 1:]) & np.isfinite(z[:, :-1])
    later, earlier = np.where(both, z[:, 1:], 0.0), np.where(both, z[:, :-1], 0.0)
    return np.stack([np.sum(later * earlier, 1), np.sum(later**2, 1), np.sum(earlier**2, 1), np.sum(both, 1)], 1)


def residual_correlation(params, observations: Observations, config: ModelConfig, predicted=None) -> dict:
    """Per test: is what the model leaves over noise? The pooled lag-1 correlation ``rho`` of the whitened
    residuals (:func:`~peano_bayes.inference.likelihood.whitened_residuals`, sequential within each run, each
    run's fitted inputs' error integrated as the likelihood does) over the neighbouring bins of every run that
    are both measured: sum z_i z_(i-1) / sqrt(sum z_i^2 sum z_(i-1)^2), each sum over those pairs. The residuals are
    independent standard normals when the model is right, so ``rho`` is within a few 1/sqrt(pairs) of 0; a
    smooth misfit the likelihood spreads over its noise scale gives ``rho`` near 1.
    ``interval_factor`` = sqrt((1 + rho) / (1 - rho)) (1 where rho <= 0): a rough indication of how much too
    narrow the intervals this test informs are (exact for the mean of AR(1) residuals with that correlation).
    ``consistent_with_noise``: rho at most :data:`CORRELATION_LIMIT` or within 4 / sqrt(pairs) of 0. A test
    with no two consecutive measured bins has ``lag1`` None and passes. ``params`` must hold the noise scales;
    ``predicted``: each group's prediction at ``params``, if already computed."""
    predicted = predictions(params, observations, config) if predicted is None else predicted
    sums: dict[str, np.ndarray] = {}
    for group, prediction in zip(observations.groups, predicted, strict=True):
        z = whitened_residuals(params, group, config=config, geometry=observations.geometry, predicted=prediction)
        sums[group.test] = sums.get(group.test, 0.0) + lag1_sums(z).sum(axis=0)
    out = {}
    for test, (cross, later, earlier, pairs) in sums.items():
        if pairs == 0 or later * earlier == 0:  # no two consecutive measured bins: nothing to judge
            out[test] = {"lag1": None, "pairs": int(pairs), "interval_factor": 1.0, "consistent_with_noise": True}
            continue
        rho = float(cross / np.sqrt(later * earlier))  # in [-1, 1] (Cauchy-Schwarz)
        positive = min(max(rho, 0.0), 1.0 - 1e-12)
        out[test] = {
            "lag1": rho,
            "pairs": int(pairs),
            "interval_factor": float(np.sqrt((1.0 + positive) / (1.0 - positive))),
            "consistent_with_noise": bool(rho <= max(CORRELATION_LIMIT, 4.0 / np.sqrt(pairs))),
        }
    return out


def structured_tests(correlation: dict) -> tuple[str, ...]:
    """Tests whose misfit has structure in a result's ``residual_correlation`` (``summary.json``): found not
    consistent with noise at the posterior mean, or sampled with AR(1) residuals (structured at the mode)."""
    return tuple(
        t for t, c in correlation.items() if not c["consistent_with_noise"] or c.get("likelihood_lag1") is not None
    )


def structured_lag1(correlation: dict) -> dict[str, float]:
    """test -> lag-1 correlation of every test that :func:`residual_correlation` found structured: what the
    likelihood then takes as its residuals' AR(1) correlation
    (:meth:`~peano_bayes.inference.posterior.Posterior.with_residual_lag1`). Tests consistent with noise keep
    independent bins, so data the model explains are sampled exactly as before."""
    return {t: float(c["lag1"]) for t, c in correlation.items() if not c["consistent_with_noise"]}


def _noise_from_residuals(observations: Observations, predicted) -> dict:
    """Per raw sample: sqrt(mean(count * error^2)) over each noise parameter's tests; ``predicted``: each
    group's prediction."""
    sums: dict[str, list] = {}
    for group, prediction in zip(observations.groups, predicted, strict=True):
        error = np.asarray(group.observed) - prediction
        ok = np.isfinite(error)
        sums.setdefault(OBSERVED[group.test][1], []).append((group.counts * error**2)[ok])
    return {k: float(np.sqrt(np.mean(np.concatenate(v)))) for k, v in sums.items()}


#: A converged start is another optimum when its cost (half the sum of squared whitened residuals, i.e. minus
#: the log likelihood up to a constant) is within OPTIMUM_COST_PER_PARAMETER x d of the best, so that it can
#: hold posterior mass comparable to the best's (a Gaussian peak's mass scales with its height times its
#: volume, and d parameters' volumes can differ by that order), and lies more than OPTIMUM_DISTANCE Laplace
#: standard deviations (Mahalanobis, at the best) from the best and from every optimum already taken.
OPTIMUM_COST_PER_PARAMETER = 1.0
OPTIMUM_DISTANCE = 3.0


#: Starts are solved in vmapped batches of this many (one compilation); a batch's run time grows with its size,
#: since a vmapped solve steps every start until the slowest one finishes.
START_BATCH = 4
#: The multi-start stops adding batches once this many converged starts reach the best cost within
#: :data:`AGREE_COST` (half the sum of squared whitened residuals, i.e. log-likelihood units): further starts
#: would most likely find that optimum again.
AGREE_STARTS = 3
AGREE_COST = 0.1


def starts_agree(costs: np.ndarray, converged: np.ndarray) -> bool:
    """Whether at least :data:`AGREE_STARTS` of the converged starts (``costs`` (n,), ``converged`` (n,) bool)
    reached the lowest converged cost within :data:`AGREE_COST`."""
    done = np.asarray(costs)[np.asarray(converged) & np.isfinite(costs)]
    return bool(done.size >= AGREE_STARTS and np.sum(done <= done.min() + AGREE_COST) >= AGREE_STARTS)


def distinct_optima(values: np.ndarray, costs: np.ndarray, converged: np.ndarray, covariance: np.ndarray,
                    best: np.ndarray, best_cost: float) -> list[int]:  # fmt: skip
    """Indices into ``values`` (n, d) of the starts that reached optima other than ``best`` (d,): converged,
    cost within ``OPTIMUM_COST_PER_PARAMETER d`` of ``best_cost``, and each more than :data:`OPTIMUM_DISTANCE`
    from the best and from the others already taken (Mahalanobis in ``covariance`` (d, d)); cheapest first."""
    d = values.shape[1]
    whiten = np.linalg.pinv(np.linalg.cholesky(covariance + 1e-12 * np.eye(d)))
    taken = [np.asarray(best)]
    out = []
    for i in np.argsort(costs):
        if not (converged[i] and np.isfinite(costs[i]) and costs[i] <= best_cost + OPTIMUM_COST_PER_PARAMETER * d):
            continue
        if all(np.linalg.norm(whiten @ (values[i] - t)) > OPTIMUM_DISTANCE for t in taken):
            taken.append(values[i])
            out.append(int(i))
    return out


def fit(
    observations: Observations,
    prior: Prior,
    *,
    config: ModelConfig | None = None,
    n_starts: int = DEFAULT_STARTS,
    seed: int = 0,
    max_steps: int = 80,
    max_rounds: int = 4,
    noise: dict | None = None,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    fixed: dict | None = None,
) -> FitResult:
    """Levenberg-Marquardt from up to ``n_starts`` points (the prior median, then prior draws), best kept.

    The starts are solved in vmapped batches of :data:`START_BATCH`, and no further batch is started once the
    best few agree (:func:`starts_agree`): ``n_starts`` of the result counts the starts that ran. Within a batch
    the starts run in rounds of at most ``max_steps`` steps. While the batch's best start has not met the
    solver's tolerance, another round continues every start from where it stopped (a failed start stays
    failed), up to ``max_rounds`` rounds; the compiled program is reused, so a round costs its run time only.
    Each round restarts the damping, so a round must be long enough to get past the first rejected steps (on
    the test suite's recovery problem, rounds of 6 steps never moved; of 8 steps, three rounds converged).
    ``prior`` covers the model parameters to fit (see :meth:`Prior.for_config` with ``likelihood=False``);
    parameters of ``config`` (default ``prior.config``) that it lacks are held at ``fixed`` or their nominal
    values. ``params`` of the result holds every model parameter.
    """
    start_time = time.perf_counter()
    config = prior.config if config is None else config
    noise = {**DEFAULT_NOISE, **(noise or {})}
    fixed = {k: jnp.asarray(v) for k, v in {**config.nominal_parameters(), **(fixed or {})}.items()}
    fixed = {k: v for k, v in fixed.items() if k not in prior.names}
    run = least_squares_program(observations, prior, config, max_steps=max_steps, rtol=rtol, atol=atol)
    if max_rounds < 1:
        raise ValueError(f"max_rounds must be >= 1, got {max_rounds!r}")
    if n_starts < 1:
        raise ValueError(f"n_starts must be >= 1, got {n_starts!r}")
    all_starts = np.vstack([np.asarray(prior.median_unconstrained())[None], prior.sample(seed, n_starts - 1)])
    args = program_arguments(observations.groups, prior_spread(prior, seed), fixed, noise)
    size = min(n_starts, START_BATCH)
    best = None  # (cost, u, jacobian, predictions, converged, rounds) of the best start so far
    values, costs, converged, failed = (np.zeros((0, all_starts.shape[1])), np.zeros(0), np.zeros(0, bool),
                                        np.zeros(0, bool))  # fmt: skip
    for first in range(0, n_starts, size):
        # One batch shape, one compilation: a last batch short of starts is padded with copies of its last start.
        taken = all_starts[first : first + size]
        starts = np.vstack([taken, np.repeat(taken[-1:], size - len(taken), axis=0)])
        batch_failed = np.zeros(size, bool)  # a start that failed in any round stays failed
        rounds = 0
        while rounds < max_rounds:
            rounds += 1
            v, ok, conv, c, jacs, predictions = run(jnp.asarray(starts), args)
            v, conv = np.asarray(v), np.asarray(conv)
            batch_failed |= ~np.asarray(ok)
            c = np.where(batch_failed, np.inf, np.asarray(c))
            i = int(np.argmin(c))
            if np.isfinite(c[i]) and (best is None or c[i] <= best[0]):
                best = (float(c[i]), v[i], np.asarray(jacs[i]), [np.asarray(q[i]) for q in predictions],
                        bool(conv[i]), rounds)  # fmt: skip
            if conv[i] or batch_failed.all():
                break
            # Every start that has not failed continues from where it stopped; a failed one reruns its last start.
            starts = np.where(batch_failed[:, None], starts, v)
        n = len(taken)
        values = np.vstack([values, v[:n]])
        costs, converged = np.concatenate([costs, c[:n]]), np.concatenate([converged, conv[:n]])
        failed = np.concatenate([failed, batch_failed[:n]])
        if starts_agree(costs, converged & ~failed):
            break
    if best is None:
        raise RuntimeError(f"all {len(costs)} least-squares starts failed (non-finite, or the physics solver missed)")
    cost, u, jac, predicted, best_converged, rounds = best
    covariance = np.linalg.pinv(jac.T @ jac)
    params = {k: float(v) for k, v in {**fixed, **prior.from_unconstrained(u)}.items()}
    others = distinct_optima(values, costs, converged & ~failed, covariance, u, cost)
    optima = tuple({k: float(v) for k, v in prior.from_unconstrained(values[i]).items()} for i in others)
    return FitResult(
        names=prior.names,
        u=u,
        params=params,
        covariance=covariance,
        cost=cost,
        n_starts=len(costs),
        n_failed=int(failed.sum()),
        n_step_limit=int(np.sum(~failed & ~converged)),
        converged=best_converged,
        rounds=rounds,
        optima=optima,
        start_costs=costs,
        noise=noise,
        noise_estimate=_noise_from_residuals(observations, predicted),
        quality=fit_quality(params, observations, config, predicted),
        seconds=time.perf_counter() - start_time,
    )


__all__ = [
    "CORRELATION_LIMIT",
    "DEFAULT_NOISE",
    "FitResult",
    "NOISE_CONSISTENCY_SE",
    "QUIET_TESTS",
    "AGREE_COST",
    "AGREE_STARTS",
    "START_BATCH",
    "dense_jacobian",
    "distinct_optima",
    "fit",
    "fit_quality",
    "lag1_effective_size",
    "lag1_sums",
    "least_squares_program",
    "noise_excess",
    "prior_spread",
    "predictions",
    "program_arguments",
    "residual_correlation",
    "structured_tests",
    "residual_function",
    "sensor_noise",
    "starts_agree",
    "structured_lag1",
]
