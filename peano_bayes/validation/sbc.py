"""Simulation-based calibration (Talts et al. 2018, arXiv:1804.06788) of the whole inference chain.

One replicate: draw ``theta`` from the prior, run the virtual rig with it (the data-generating process, sensor
and input noise included), infer with the same posterior-mode start and sampler as ``peano-bayes fit``, and
record where the truth falls among the posterior draws (its rank) and whether each central interval covers
it. Over many replicates the ranks of a calibrated inference are uniform and a 90 % interval covers 90 % of
the truths. Every replicate shares one compiled log posterior (:meth:`Posterior.with_observations`), so a
study of hundreds of datasets compiles once.

The problem is deliberately reduced so a study of 100+ replicates runs in minutes: TP load cycles (one
specimen, one repeat, at 0 kPa and the test pressure), three free model parameters (:data:`SBC_FREE`) and
the load cell's noise scale; the rest at nominal values.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from ..inference.laplace import posterior_mode, refine_mode
from ..inference.likelihood import prepare
from ..inference.posterior import Posterior, build_posterior
from ..inference.priors import prior_for
from ..inference.sample import sample
from ..physics import DEFAULT_CONFIG
from ..rig import RigNoise, RigSimulationError, simulate_dataset

SBC_MATERIAL = "TP"
SBC_FREE = ("tensile_ka_n_per_m", "bending_k1_n", "friction_pressure_fraction")
NOISE_NAME = "noise_load_cycle_force_n"
#: Central interval probabilities whose coverage is reported.
LEVELS = (0.5, 0.9, 0.94)
#: Posterior draws the truth is ranked among (ranks 0..RANK_DRAWS).
RANK_DRAWS = 99


def simulate(params: dict, seed: int, exact_inputs: bool = False):
    """The SBC protocol's rig dataset from model and noise parameters [SI] (``NOISE_NAME`` sets the load
    cell's noise; the other sensors keep the rig's defaults, or with ``exact_inputs`` the strain and pressure
    sensors are noiseless, so the denoised driving inputs are exact)."""
    model = {k: v for k, v in params.items() if k != NOISE_NAME}
    noise = RigNoise(force_sd_n=float(params[NOISE_NAME]))
    if exact_inputs:
        noise = replace(noise, strain_sd=0.0, pressure_sd_pa=0.0)
    return simulate_dataset(
        SBC_MATERIAL,
        model,
        seed=seed,
        specimens=1,
        repeats=1,
        specimen_spread=0.0,
        tests=("load_cycle",),
        noise=noise,
    )


def base_posterior() -> Posterior:
    """The SBC posterior (on data at the prior median; replicates swap the data in)."""
    prior = prior_for(SBC_MATERIAL)
    fixed = {k: v for k, v in DEFAULT_CONFIG.nominal_parameters().items() if k not in SBC_FREE}
    median = {**fixed, **{k: v for k, v in prior.median().items() if k in (*SBC_FREE, NOISE_NAME)}}
    data = simulate(median, seed=0)
    return build_posterior(prepare(data), prior, config=DEFAULT_CONFIG, fixed=fixed)


@dataclass(frozen=True)
class Replicate:
    """One SBC replicate: ``index``; ``truth`` (D,) theta; ``rank`` (D,) of the truth among
    :data:`RANK_DRAWS` thinned draws; ``covered`` level -> (D,) bool; ``converged``; ``steps``; ``tau_max``;
    ``seconds``; ``redraws`` prior draws the rig could not simulate before this one."""

    index: int
    truth: list
    rank: list
    covered: dict
    converged: bool
    steps: int
    tau_max: float
    seconds: float
    redraws: int

    def as_dict(self) -> dict:
        return dict(self.__dict__)


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
) -> Replicate:
    """Replicate ``index`` of the study with root ``seed``: truth from the prior, data from the rig (see
    :func:`simulate` for ``exact_inputs``), inference from the prior median (never the truth), ranks and
    coverage."""
    t0 = time.perf_counter()
    rng = np.random.default_rng([seed, index])
    prior = base.prior
    redraws = 0
    while True:
        truth = prior.sample(rng, 1)[0]
        params = {**base.fixed, **{k: float(v) for k, v in prior.from_unconstrained(truth).items()}}
        try:
            data = simulate(params, seed=int(rng.integers(2**31)), exact_inputs=exact_inputs)
            break
        except RigSimulationError:  # the rig refuses a simulation whose solver misses its tolerance
            redraws += 1
            if redraws > 20:
                raise
    try:  # same protocol: reuse the compiled log posterior
        posterior = base.with_observations(prepare(data))
    except ValueError:  # the replicate's inputs were cut into other segments (other bin shapes): its own
        posterior = replace(base, observations=prepare(data))
    start = np.asarray(prior.median_unconstrained())
    spread = np.std(prior.sample(np.random.default_rng(0), 2000), axis=0)
    posterior = posterior.with_batch_rows(n_walkers // 2)  # the sampler's batch size: one compilation
    laplace = refine_mode(posterior.batched, posterior_mode(posterior, start, np.diag(spread**2)))
    result = sample(
        posterior,
        laplace.mode,
        laplace.covariance,
        n_walkers=n_walkers,
        seed=index,
        warmup=warmup,
        chunk=chunk,
        max_steps=max_steps,
        progress=False,
        log=lambda message: None,
    )
    draws = result.kept().reshape(-1, posterior.ndim)
    thinned = draws[np.linspace(0, len(draws) - 1, RANK_DRAWS).round().astype(int)]
    rank = (thinned < truth).sum(axis=0)
    covered = {}
    for level in LEVELS:
        low, high = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2], axis=0)
        covered[str(level)] = ((truth >= low) & (truth <= high)).tolist()
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
    )


@functools.cache
def _process_base() -> Posterior:
    return base_posterior()


def replicate_unit(index: int, *, seed: int, **settings) -> dict:
    """Replicate ``index`` as a work unit of :func:`peano_bayes.fanout.run_units`: :func:`run_replicate` with
    ``settings`` (its keyword arguments) on the base posterior, built once per process (so every replicate a
    worker runs shares its compiled log posterior). The result is a JSON-ready row: ``seed``, ``exact_inputs``,
    ``names`` (theta's entries, the order of ``truth`` and ``rank``) and :class:`Replicate`'s fields. The same
    arguments give the same row in any process."""
    base = _process_base()
    rep = run_replicate(base, index, seed=seed, **settings)
    exact_inputs = settings.get("exact_inputs", False)
    return {"seed": seed, "exact_inputs": exact_inputs, "names": list(base.names), **rep.as_dict()}


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


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


__all__ = [
    "LEVELS",
    "RANK_DRAWS",
    "SBC_FREE",
    "SBC_MATERIAL",
    "Replicate",
    "base_posterior",
    "coverage_table",
    "replicate_unit",
    "run_replicate",
    "simulate",
    "wilson_interval",
]
