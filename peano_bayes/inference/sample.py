"""Ensemble MCMC (emcee) over a :class:`~peano_bayes.inference.posterior.Posterior`, in resumable chunks.

One jit+vmap log posterior is handed to emcee with ``vectorize=True`` (emcee's red-blue moves evaluate half
ensembles, so it compiles for two batch sizes). Moves: differential evolution 80 %, snooker 20 %. Walkers start
from the Laplace approximation of the least-squares fit. The run proceeds in chunks of ``chunk`` steps until

- the kept chain (after discarding ``2 tau_max``) is at least ``50 tau_max`` long (emcee's own reliability
  rule for its integrated autocorrelation time ``tau``),
- R-hat <= 1.01 and bulk ESS >= 1000 for every parameter (arviz, walkers as chains, on the kept draws),

or until ``max_steps``; a run stopped by the limit is returned with ``converged=False``. After every chunk the
whole state (chain, log posterior, RNG state) is written atomically to ``state_path``; with ``resume=True`` a
run continues from it, and because the RNG state is restored it gives the same numbers as a run that was
never interrupted.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import arviz as az
import emcee
import numpy as np

from .posterior import Posterior

#: Convergence targets (DESIGN, issue 4).
TARGETS = {"min_tau_lengths": 50.0, "max_rhat": 1.01, "min_ess_bulk": 1000.0}
MOVES = ((emcee.moves.DEMove, 0.8), (emcee.moves.DESnookerMove, 0.2))


@dataclass(frozen=True, eq=False)
class Convergence:
    """Figures of a chain: ``tau`` (D,) integrated autocorrelation time [steps]; ``discard`` burn-in [steps];
    ``tau_lengths`` kept length over ``tau_max``; ``rhat``/``ess_bulk``/``ess_tail`` (D,) on the kept draws;
    ``converged`` whether every target of :data:`TARGETS` holds; ``problems`` what misses, in words."""

    tau: np.ndarray
    discard: int
    tau_lengths: float
    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    converged: bool
    problems: tuple[str, ...]

    def as_dict(self, names) -> dict:
        per = lambda a: {n: float(v) for n, v in zip(names, a, strict=True)}  # noqa: E731
        return {
            "converged": self.converged,
            "problems": list(self.problems),
            "discard_steps": self.discard,
            "tau_steps": per(self.tau),
            "tau_lengths": self.tau_lengths,
            "rhat": per(self.rhat),
            "ess_bulk": per(self.ess_bulk),
            "ess_tail": per(self.ess_tail),
            "targets": dict(TARGETS),
        }


@dataclass(frozen=True, eq=False)
class SampleResult:
    """``chain`` (steps, walkers, D) theta; ``log_prob`` (steps, walkers); ``convergence``; ``names``;
    ``seconds`` of sampling (this process, compile included); ``acceptance`` mean fraction; ``resumed_from``
    steps loaded from the state file (0 for a fresh run)."""

    names: tuple[str, ...]
    chain: np.ndarray
    log_prob: np.ndarray
    convergence: Convergence
    seconds: float
    acceptance: float
    resumed_from: int = 0
    chunks: list = field(default_factory=list)

    def kept(self) -> np.ndarray:
        """(walkers, draws, D) after burn-in."""
        return self.chain[self.convergence.discard :].swapaxes(0, 1)


def convergence(chain: np.ndarray, names=None) -> Convergence:
    """Convergence figures of ``chain`` (steps, walkers, D) against :data:`TARGETS`."""
    steps = chain.shape[0]
    tau = emcee.autocorr.integrated_time(chain, tol=0)
    tau_max = float(np.max(tau))
    discard = min(int(np.ceil(2.0 * tau_max)), steps // 2)
    kept = chain[discard:].swapaxes(0, 1)
    draws = {f"p{i}": kept[..., i] for i in range(kept.shape[-1])}
    data = az.convert_to_dataset(draws)
    rhat = np.array([float(az.rhat(data)[k]) for k in draws])
    ess_bulk = np.array([float(az.ess(data, method="bulk")[k]) for k in draws])
    ess_tail = np.array([float(az.ess(data, method="tail")[k]) for k in draws])
    names = list(names) if names is not None else list(draws)
    lengths = (steps - discard) / tau_max
    problems = []
    if lengths < TARGETS["min_tau_lengths"]:
        problems.append(f"chain is {lengths:.1f} autocorrelation times long (target {TARGETS['min_tau_lengths']:g})")
    for label, values, bad in (
        ("R-hat", rhat, ~(rhat <= TARGETS["max_rhat"])),
        ("bulk ESS", ess_bulk, ~(ess_bulk >= TARGETS["min_ess_bulk"])),
    ):
        if bad.any():
            worst = ", ".join(f"{names[i]} {values[i]:.3g}" for i in np.flatnonzero(bad)[:4])
            problems.append(f"{label} misses its target for {int(bad.sum())} parameter(s): {worst}")
    return Convergence(tau, discard, lengths, rhat, ess_bulk, ess_tail, not problems, tuple(problems))


def initial_walkers(posterior: Posterior, centre: np.ndarray, covariance: np.ndarray, n_walkers: int, seed: int):
    """``n_walkers`` points (n_walkers, D) from N(centre, covariance), each with a finite log posterior
    (redrawn up to 50 times, shrinking the spread). Raises if none can be found."""
    rng = np.random.default_rng([seed, 1])
    f = posterior.batched
    cov = np.array(covariance, dtype=float)
    walkers = rng.multivariate_normal(centre, cov, size=n_walkers, method="eigh")
    lp = f(walkers)
    for _ in range(50):
        bad = ~np.isfinite(lp)
        if not bad.any():
            return walkers, lp
        cov = cov * 0.5
        walkers[bad] = rng.multivariate_normal(centre, cov, size=int(bad.sum()), method="eigh")
        lp = f(walkers)
    raise RuntimeError(
        f"could not start the walkers: {int((~np.isfinite(lp)).sum())} of {n_walkers} have log posterior -inf "
        "around the least-squares point"
    )


def _save_state(path: Path, chain, log_prob, random_state, meta: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        np.savez(
            fh,
            chain=chain,
            log_prob=log_prob,
            rng=np.frombuffer(json.dumps(_rng_to_json(random_state)).encode(), dtype=np.uint8),
            meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
        )
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _rng_to_json(state) -> list:
    name, keys, pos, has_gauss, cached = state
    return [name, np.asarray(keys).tolist(), int(pos), int(has_gauss), float(cached)]


def _rng_from_json(data) -> tuple:
    name, keys, pos, has_gauss, cached = data
    return (name, np.asarray(keys, dtype=np.uint32), pos, has_gauss, cached)


def load_state(path: str | os.PathLike):
    """``(chain, log_prob, random_state, meta)`` from a state file written by :func:`sample`."""
    with np.load(path) as z:
        rng = _rng_from_json(json.loads(z["rng"].tobytes().decode()))
        meta = json.loads(z["meta"].tobytes().decode())
        return z["chain"], z["log_prob"], rng, meta


def walker_count(n_walkers: int | None, ndim: int) -> int:
    """``n_walkers``, or by default ``max(32, 2 ndim + 2)``, rounded up to even (emcee's red-blue halves).
    With 50 autocorrelation times required, 32 walkers already give an ESS near 1600; more walkers only cost
    more per step."""
    n = n_walkers or max(32, 2 * ndim + 2)
    return n + n % 2


def sample(
    posterior: Posterior,
    centre: np.ndarray,
    covariance: np.ndarray,
    *,
    n_walkers: int | None = None,
    seed: int = 0,
    chunk: int = 500,
    max_steps: int = 20_000,
    state_path: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = True,
    log=print,
) -> SampleResult:
    """Run emcee on ``posterior`` from N(``centre``, ``covariance``) in theta space until converged (see the
    module docstring) or ``max_steps``. ``n_walkers``: see :func:`walker_count`.
    ``log(message)`` reports each chunk."""
    start_time = time.perf_counter()
    ndim = posterior.ndim
    n_walkers = walker_count(n_walkers, ndim)
    state_path = Path(state_path) if state_path is not None else None
    meta = {"names": list(posterior.names), "n_walkers": n_walkers, "seed": seed}
    chain, lps = np.zeros((0, n_walkers, ndim)), np.zeros((0, n_walkers))
    sampler = emcee.EnsembleSampler(
        n_walkers, ndim, posterior.batched, vectorize=True, moves=[(m(), w) for m, w in MOVES]
    )
    if resume and state_path is not None and state_path.exists():
        chain, lps, rng_state, saved = load_state(state_path)
        if saved["names"] != meta["names"] or saved["n_walkers"] != n_walkers or saved["seed"] != seed:
            raise ValueError(
                f"{state_path}: saved state is of another run (names, walkers or seed differ); "
                "delete it or run without --resume"
            )
        sampler.random_state = rng_state
        state = emcee.State(chain[-1], log_prob=lps[-1], random_state=rng_state)
        log(f"resumed from {state_path} at step {chain.shape[0]}")
    else:
        walkers, lp0 = initial_walkers(posterior, centre, covariance, n_walkers, seed)
        sampler.random_state = np.random.RandomState(seed).get_state()
        state = emcee.State(walkers, log_prob=lp0, random_state=sampler.random_state)
    resumed_from = chain.shape[0]
    accepted = 0.0
    chunks = []
    result = None
    while chain.shape[0] < max_steps:
        done = chain.shape[0]
        n = min(chunk, max_steps - done)
        t0 = time.perf_counter()
        sampler.reset()
        state = sampler.run_mcmc(state, n, progress=progress, progress_kwargs={"desc": f"steps {done}-{done + n}"})
        chain = np.concatenate([chain, sampler.get_chain()])
        lps = np.concatenate([lps, sampler.get_log_prob()])
        accepted = float(np.mean(sampler.acceptance_fraction))
        if state_path is not None:
            _save_state(state_path, chain, lps, sampler.random_state, meta)
        result = convergence(chain, posterior.names)
        chunks.append({"steps": chain.shape[0], "seconds": time.perf_counter() - t0, "acceptance": accepted})
        log(
            f"step {chain.shape[0]}: acceptance {accepted:.2f}, tau_max {np.max(result.tau):.0f}, "
            f"{result.tau_lengths:.0f} tau long, max R-hat {np.max(result.rhat):.3f}, "
            f"min bulk ESS {np.min(result.ess_bulk):.0f}" + ("" if result.converged else " (not yet converged)")
        )
        if result.converged:
            break
    result = result if result is not None else convergence(chain, posterior.names)
    return SampleResult(
        posterior.names,
        chain,
        lps,
        result,
        time.perf_counter() - start_time,
        accepted,
        resumed_from,
        chunks,
    )


__all__ = [
    "MOVES",
    "TARGETS",
    "Convergence",
    "SampleResult",
    "convergence",
    "initial_walkers",
    "load_state",
    "sample",
    "walker_count",
]
