"""Simulation-based calibration (Talts et al. 2018, arXiv:1804.06788) of the whole inference chain.

One replicate: draw ``theta`` from the prior, run the virtual rig with it (the data-generating process, sensor
and input noise included), infer with the same posterior-mode start and sampler as ``peano-bayes fit``, and
record where the truth falls among the posterior draws (its rank) and whether each central interval covers
it. Over many replicates the ranks of a calibrated inference are uniform and a 90 % interval covers 90 % of
the truths. Every replicate shares one compiled log posterior (:meth:`Posterior.with_observations`), so a
study of hundreds of datasets compiles once.

The problem is deliberately reduced so a study of 100+ replicates runs in an hour or two: TP load cycles (one
repeat per specimen, at 0 kPa and the test pressure), three free model parameters (:data:`SBC_FREE`) and the
load cell's noise scale; the rest at nominal values.

**Specimens.** With one specimen (the default) theta is the prior's parameters. With ``specimens >= 2`` the
study is the specimen hierarchy of :mod:`peano_bayes.inference.posterior`: the prior adds the spread
``specimen_log_sd`` and theta the specimens' log contrasts of each free parameter that differs between
specimens, drawn ``N(0, spread^2)`` as the posterior's own prior says; each specimen is simulated with its own
values (``simulate_dataset(specimen_values=...)``). Beside theta the study ranks the two derived levels a
designer reads (:meth:`Posterior.levels`): the **population** value and a **new specimen**. Their truths come
from the generative hierarchy (population value from the prior, specimens around it, :func:`draw_truth`), not
from the levels' own rule, so their ranks test that rule and its approximation as well.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from ..defaults import DEFAULT_CHUNK, DEFAULT_STARTS, DEFAULT_WARMUP
from ..errors import PeanoBayesInputError
from ..inference.driver import least_squares, posterior_at_mode, walker_start
from ..inference.posterior import SPECIMEN_SD, Posterior, build_posterior, helmert
from ..inference.prior_files import prior_for
from ..inference.reduce import INPUT_ERROR_TESTS, prepare
from ..inference.sample import sample, walker_count
from ..physics import DEFAULT_CONFIG
from ..rig import RigNoise, RigSimulationError, simulate_dataset
from ..stats import holm, wilson_interval

SBC_MATERIAL = "TP"
SBC_FREE = ("tensile_ka_n_per_m", "bending_k1_n", "friction_pressure_fraction")
NOISE_NAME = "noise_load_cycle_force_n"
#: Central interval probabilities whose coverage is reported.
LEVELS = (0.5, 0.9, 0.94)
#: Posterior draws the truth is ranked among (ranks 0..RANK_DRAWS).
RANK_DRAWS = 99
#: The derived levels ranked per varying parameter in the hierarchical study, in order.
DERIVED_LEVELS = ("population", "new_specimen")


def simulate(params: dict, seed: int, exact_inputs: bool = False, specimen_values=None):
    """The SBC protocol's rig dataset from model and noise parameters [SI] (``NOISE_NAME`` sets the load
    cell's noise; the other sensors keep the rig's defaults, or with ``exact_inputs`` the strain and pressure
    sensors are noiseless, so the denoised driving inputs are exact). ``specimen_values``: one mapping per
    specimen of its own values [SI], overriding ``params`` for those names (default: one specimen with
    ``params`` itself). The spread ``specimen_log_sd`` is a parameter of the inference, not of the rig, and
    is not passed on."""
    model = {k: v for k, v in params.items() if k not in (NOISE_NAME, SPECIMEN_SD)}
    noise = RigNoise(force_sd_n=float(params[NOISE_NAME]))
    if exact_inputs:
        noise = replace(noise, strain_sd=0.0, pressure_sd_pa=0.0)
    return simulate_dataset(
        SBC_MATERIAL,
        model,
        seed=seed,
        specimens=1 if specimen_values is None else len(specimen_values),
        repeats=1,
        specimen_spread=0.0,
        specimen_values=specimen_values,
        tests=("load_cycle",),
        noise=noise,
    )


def base_posterior(specimens: int = 1, input_errors=INPUT_ERROR_TESTS) -> Posterior:
    """The SBC posterior of ``specimens`` specimens (on data at the prior median; replicates swap the data
    in). With two or more it is hierarchical (see the module docstring)."""
    if specimens < 1:
        raise ValueError(f"specimens must be >= 1, got {specimens}")
    data = prepare(simulate_median(specimens), input_errors=input_errors)
    return build_posterior(data, prior_for(SBC_MATERIAL), config=DEFAULT_CONFIG, fixed=_fixed())


def _fixed() -> dict:
    """The model parameters the study holds at their nominal values [SI]."""
    return {k: v for k, v in DEFAULT_CONFIG.nominal_parameters().items() if k not in SBC_FREE}


def simulate_median(specimens: int = 1):
    """The protocol's rig data at the prior median (seed 0), alike for every specimen: what the base posterior
    is built on before replicates swap their own data in."""
    free = {k: v for k, v in prior_for(SBC_MATERIAL).median().items() if k in (*SBC_FREE, NOISE_NAME)}
    median = {**_fixed(), **free}
    return simulate(median, seed=0, specimen_values=None if specimens == 1 else [{}] * specimens)


def rank_names(base: Posterior) -> tuple[str, ...]:
    """The quantities a replicate ranks: theta's entries, then (hierarchical study) ``population__<p>`` and
    ``new_specimen__<p>`` of each parameter ``p`` that differs between specimens."""
    derived = tuple(f"{level}__{p}" for p in base.varying for level in DERIVED_LEVELS)
    return base.names + derived


@dataclass(frozen=True)
class Truth:
    """One replicate's generating values: ``theta`` (D,) in the posterior's coordinates; ``ranked`` (K,) the
    quantities of :func:`rank_names` (theta, then the log of the derived levels [ln SI]);
    ``specimen_values`` each specimen's values [SI] of the varying parameters (``None`` with one specimen)."""

    theta: np.ndarray
    ranked: np.ndarray
    specimen_values: list[dict] | None


def draw_truth(base: Posterior, rng: np.random.Generator) -> Truth | None:
    """A truth drawn by the generative hierarchy (``None`` when it falls outside the prior's support, to be
    redrawn).

    With one specimen theta is a prior draw. With ``n`` specimens the prior's entry of each varying
    parameter is read as the **population** value ``mu`` (not the specimens' geometric mean ``m`` the
    posterior samples): specimen ``s`` has ``x_s = mu exp(tau z_s)``, a new specimen ``mu exp(tau z_new)``,
    ``z ~ N(0, 1)``; theta then holds ``m`` and the contrasts ``c = H^T ln(x / m)``. So the population and
    new-specimen ranks test :meth:`Posterior.levels` and its approximation (a prior flat in ``ln x`` over a few
    ``tau``; the prior on ``m`` that the posterior assumes is the population prior, while this draw's ``m`` is
    that prior widened by ``N(0, tau^2 / n)``) rather than repeat its own rule."""
    prior = base.prior
    u = prior.sample(rng, 1)[0]
    if not base.n_contrasts:
        return Truth(u, u, None)
    values = {k: float(v) for k, v in prior.from_unconstrained(u).items()}
    tau, n = values[SPECIMEN_SD], len(base.observations.specimens)
    z = rng.standard_normal((len(base.varying), n))
    z_new = rng.standard_normal(len(base.varying))
    h = helmert(n)
    sampled, contrasts, derived = dict(values), [], []
    specimen_values: list[dict] = [{} for _ in range(n)]
    for i, p in enumerate(base.varying):
        log_x = math.log(values[p]) + tau * z[i]
        sampled[p] = float(np.exp(log_x.mean()))
        contrasts.append(h.T @ (log_x - log_x.mean()))
        for s in range(n):
            specimen_values[s][p] = float(np.exp(log_x[s]))
        derived += [math.log(values[p]), math.log(values[p]) + tau * z_new[i]]
    theta = np.concatenate([np.asarray(prior.to_unconstrained(sampled), dtype=float), *contrasts])
    if not np.all(np.isfinite(theta)):
        return None
    return Truth(theta, np.concatenate([theta, derived]), specimen_values)


def replicate_data(base: Posterior, index: int, *, seed: int, exact_inputs: bool = False):
    """Replicate ``index``'s truth and rig data: ``(truth, dataset, redraws, rng)``, the replicate's random
    stream (``[seed, index]``) left where the data drew from it (the derived levels of the posterior draws
    continue it). A draw outside the prior's or the rig's bounds, or one whose simulation the rig refuses, is
    redrawn (``redraws`` counts them; more than 20 raise)."""
    rng = np.random.default_rng([seed, index])
    redraws = 0
    while True:
        truth = draw_truth(base, rng)
        if truth is not None:
            theta = truth.theta
            params = {
                **base.fixed,
                **{k: float(v) for k, v in base.prior.from_unconstrained(theta[: base.prior.ndim]).items()},
            }
            try:
                data = simulate(
                    params,
                    seed=int(rng.integers(2**31)),
                    exact_inputs=exact_inputs,
                    specimen_values=truth.specimen_values,
                )
                return truth, data, redraws, rng
            except (RigSimulationError, PeanoBayesInputError):  # a solver miss, or a value past the rig's bounds
                pass
        redraws += 1
        if redraws > 20:
            raise RuntimeError(f"replicate {index}: 20 truths in a row could not be simulated")


def derived_levels(base: Posterior, thetas: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(n, len(rank_names)) theta and the derived levels of ``thetas`` (n, D), as :func:`rank_names` orders
    them (log of the derived values, so they rank as the unconstrained entries do)."""
    if not base.varying:
        return thetas
    levels = base.levels(thetas, rng)
    derived = [
        np.log(levels[p if level == "population" else f"new_specimen__{p}"])
        for p in base.varying
        for level in DERIVED_LEVELS
    ]
    return np.column_stack([thetas, *derived])


@dataclass(frozen=True)
class Replicate:
    """One SBC replicate: ``index``; ``truth`` (K,) the ranked quantities of :func:`rank_names` (theta in
    the posterior's coordinates, then the derived levels as ln of their SI values); ``rank`` (K,) of the truth
    among :data:`RANK_DRAWS` thinned draws; ``covered`` level -> (K,) bool; ``converged``; ``steps``;
    ``tau_max``; ``seconds``; ``redraws`` truths that could not be simulated before this one; ``ar1`` test ->
    lag-1 correlation of each test sampled with AR(1) residuals (its residuals at the mode failed the structure
    check, :func:`~peano_bayes.inference.fit.structured_lag1`; empty when none did)."""

    index: int
    truth: list
    rank: list
    covered: dict
    converged: bool
    steps: int
    tau_max: float
    seconds: float
    redraws: int
    ar1: dict

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def mode_start(base: Posterior) -> tuple[np.ndarray, np.ndarray]:
    """Where every replicate's mode search starts: ``(start, spread)`` (D,), the prior median with the contrasts
    at 0, and the sd of each entry's prior (a contrast's: that of tau N(0, 1), about 0.2)."""
    prior = base.prior
    prior_draws = prior.sample(np.random.default_rng(0), 2000)
    start = np.concatenate([np.asarray(prior.median_unconstrained()), np.zeros(base.n_contrasts)])
    spread = np.std(prior_draws, axis=0)
    if base.n_contrasts:
        tau = np.asarray(prior.from_unconstrained(prior_draws)[SPECIMEN_SD])
        contrast_sd = np.std(tau * np.random.default_rng(1).standard_normal(tau.shape))
        spread = np.concatenate([spread, np.full(base.n_contrasts, contrast_sd)])
    return start, spread


def run_replicate(
    base: Posterior,
    index: int,
    *,
    seed: int = 0,
    n_walkers: int = 8,
    warmup: int = 200,
    chunk: int = 250,
    max_steps: int = 4000,
    exact_inputs: bool = False,
    as_fit: bool = False,
) -> Replicate:
    """Replicate ``index`` of the study with root ``seed``: truth and rig data from :func:`replicate_data`,
    inference from the prior median (never the truth), ranks and coverage of every quantity of
    :func:`rank_names`.

    ``as_fit``: the inference ``peano-bayes fit`` runs instead: the mode search starts from the multi-start
    least squares (:func:`~peano_bayes.inference.driver.least_squares`, the fit's starts, seeded by ``index``)
    and :func:`~peano_bayes.inference.driver.walker_start`, and the sampler takes the fit's defaults (walkers
    :func:`~peano_bayes.inference.sample.walker_count`, the adaptive warm-up, its chunks and convergence rule);
    ``n_walkers``, ``warmup`` and ``chunk`` are then ignored."""
    t0 = time.perf_counter()
    truth, data, redraws, rng = replicate_data(base, index, seed=seed, exact_inputs=exact_inputs)
    try:  # same protocol: reuse the compiled log posterior
        posterior = base.with_observations(prepare(data))
    except ValueError:  # the replicate's inputs were cut into other segments (other bin shapes): its own
        posterior = replace(base, observations=prepare(data))
    if as_fit:
        fitted = least_squares(posterior, posterior.prior, n_starts=DEFAULT_STARTS, seed=index)
        start, covariance = walker_start(posterior, fitted)
        n_walkers, warmup, chunk = walker_count(None, posterior.ndim), DEFAULT_WARMUP, DEFAULT_CHUNK
    else:
        start, spread = mode_start(base)
        covariance = np.diag(spread**2)
    posterior = posterior.with_batch_rows(n_walkers // 2)  # the sampler's batch size: one compilation
    # the driver's own stages from a start to the sampler, as peano-bayes fit runs them (AR(1) residuals included)
    mode = posterior_at_mode(posterior, start, covariance)
    posterior, ar1 = mode.posterior, mode.lag1
    result = sample(
        posterior,
        mode.laplace.mode,
        mode.laplace.covariance,
        n_walkers=n_walkers,
        seed=index,
        warmup=warmup,
        chunk=chunk,
        max_steps=max_steps,
        progress=False,
        log=lambda message: None,
    )
    draws = derived_levels(base, result.kept().reshape(-1, posterior.ndim), rng)
    truth = truth.ranked
    rank, covered = rank_and_coverage(draws, truth)
    return Replicate(
        index,
        truth.tolist(),
        rank.tolist(),
        covered,
        bool(result.convergence.converged),
        int(result.chain.shape[0]),
        float(np.max(result.convergence.tau)),
        time.perf_counter() - t0,
        redraws,
        ar1,
    )


@functools.cache
def _process_base(specimens: int = 1) -> Posterior:
    return base_posterior(specimens)


def replicate_unit(index: int, *, seed: int, **settings) -> dict:
    """Replicate ``index`` as a work unit of :func:`peano_bayes.app.fanout.run_units`: :func:`run_replicate` with
    ``settings`` (its keyword arguments, and ``specimens``, default 1) on the base posterior, built once per
    process (so every replicate a worker runs shares its compiled log posterior). The result is a JSON-ready
    row: ``seed``, ``exact_inputs``, ``specimens``, ``names`` (:func:`rank_names`, the order of ``truth`` and
    ``rank``) and :class:`Replicate`'s fields. The same arguments give the same row in any process."""
    specimens = settings.pop("specimens", 1)
    base = _process_base(specimens)
    rep = run_replicate(base, index, seed=seed, **settings)
    exact_inputs = settings.get("exact_inputs", False)
    row = {"seed": seed, "exact_inputs": exact_inputs, "names": list(rank_names(base)), **rep.as_dict()}
    row = {"as_fit": True, **row} if settings.get("as_fit") else row
    return row if specimens == 1 else {"specimens": specimens, **row}


def rank_and_coverage(draws: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, dict[str, list[bool]]]:
    """The SBC statistics of one replicate: per quantity (draws (n, d), truth (d,)), the rank of the truth among
    :data:`RANK_DRAWS` draws evenly spaced over ``draws`` (how many lie below it: uniform on 0..RANK_DRAWS for
    a calibrated posterior with independent draws), and for each level of :data:`LEVELS` whether the truth lies
    in the central interval of all the draws (``str(level)`` -> (d,) flags)."""
    draws, truth = np.asarray(draws, float), np.asarray(truth, float)
    thinned = draws[np.linspace(0, len(draws) - 1, RANK_DRAWS).round().astype(int)]
    rank = (thinned < truth).sum(axis=0)
    covered = {}
    for level in LEVELS:
        low, high = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2], axis=0)
        covered[str(level)] = ((truth >= low) & (truth <= high)).tolist()
    return rank, covered


def coverage_table(replicates: list[dict], names) -> list[dict]:
    """Per parameter: coverage of each central interval with its 95 % Wilson interval, and the chi-square
    p-value of the rank histogram (10 bins) against uniform."""
    rows = []
    n = len(replicates)
    ranks = np.array([r["rank"] for r in replicates])
    for j, name in enumerate(names):
        row = {"parameter": name, "replicates": n}
        for level in LEVELS:
            k = int(sum(r["covered"][str(level)][j] for r in replicates))
            low, high = wilson_interval(k, n)
            row[f"coverage_{level:g}"] = k / n
            row[f"wilson95_{level:g}"] = [low, high]
        counts = np.histogram(ranks[:, j], bins=10, range=(0, RANK_DRAWS + 1))[0]
        row["rank_chi2_p"] = float(stats.chisquare(counts).pvalue)
        rows.append(row)
    return rows


#: The pooled acceptance rule of the SBC of what users run (pre-registered in docs/validation.md, *SBC of what
#: users run*): the 90 % intervals' coverage pooled over every quantity and replicate within this band, and no
#: quantity's rank histogram (10 bins) rejected by a chi-square test at Holm-corrected :data:`RANK_ALPHA`. A
#: calibrated sampler passes it with probability 0.986 on that study's 11 quantities and 100 replicates
#: (``experiments/sbc_acceptance_power.py``).
POOLED_BAND = (0.87, 0.93)
RANK_ALPHA = 0.01


def pooled_rule(rows: list[dict], replicates: list[dict], level: float = 0.9) -> dict:
    """The pooled rule on a finished study: ``rows`` from :func:`coverage_table`, ``replicates`` its rows (every
    replicate, converged or not). Returns the pooled coverage at ``level`` with its 95 % Wilson interval, each
    quantity's Holm-adjusted rank p-value, which are rejected, how many replicates did not converge, and
    ``passed``."""
    covered = np.array([r["covered"][str(level)] for r in replicates], dtype=bool)  # (replicates, quantities)
    k, n = int(covered.sum()), covered.size
    adjusted = holm({row["parameter"]: row["rank_chi2_p"] for row in rows})
    pooled = k / n
    rejected = sorted(name for name, a in adjusted.items() if a <= RANK_ALPHA)
    return {
        "level": level,
        "pooled_coverage": pooled,
        "pooled_wilson95": list(wilson_interval(k, n)),
        "band": list(POOLED_BAND),
        "rank_p_holm": adjusted,
        "rank_rejected": rejected,
        "unconverged": int(sum(not r["converged"] for r in replicates)),
        "passed": bool(POOLED_BAND[0] <= pooled <= POOLED_BAND[1] and not rejected),
    }


__all__ = [
    "POOLED_BAND",
    "RANK_ALPHA",
    "pooled_rule",
    "rank_and_coverage",
    "LEVELS",
    "RANK_DRAWS",
    "SBC_FREE",
    "SBC_MATERIAL",
    "Replicate",
    "Truth",
    "base_posterior",
    "coverage_table",
    "derived_levels",
    "draw_truth",
    "rank_names",
    "replicate_data",
    "replicate_unit",
    "run_replicate",
    "simulate",
]
