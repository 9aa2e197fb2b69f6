"""Convergence of a run of independently started emcee ensembles: the rule :func:`sample` stops on.

A run is ``K`` ensembles of ``W`` walkers (chain shape (steps, K W, D), ensemble ``e`` holding walkers ``e W`` to
``(e + 1) W - 1``). After the warm-up and a further ``2 tau_max`` steps, the kept draws must satisfy every target
of :data:`TARGETS`:

- **nested R-hat <= 1.01** (:func:`nested_rhat`; Margossian et al. 2024, *Nested R-hat*): the superchains are
  the ensembles, each cut in time into its first and second half, and the subchains are the walkers. Comparing
  superchain means against the whole spread within each superchain sees an ensemble stuck apart from the others
  (a mode the others never reach) and a mean that moves between the first and the second half of the run (drift
  in time). Walkers of one ensemble move together (each proposal is built from the others' positions), so they
  are not independent chains; nested R-hat asks independence of the superchains only, which independently
  started ensembles have. Rank-normalized, and also on the folded draws ``|x - median|`` so that a difference in
  spread counts too, as in Vehtari et al. (2021); the larger of the two is reported.
- **bulk and tail ESS >= 1000** for every sampled quantity (arviz, each walker a chain).
- **the kept chain >= 20 tau_max** long, ``tau_max`` the largest integrated autocorrelation time [steps] over the
  parameters and ensembles (emcee's estimate, per ensemble), **and tau_max stable**: within 20 % of its value at
  the previous check, so that a ``tau`` still growing with the chain (a slow direction not yet seen) does not
  certify a run.

No fixed multiple of 50 tau is asked: that is emcee's advice for trusting the ``tau`` estimate itself, not a
precision target; with ESS >= 1000 the means' Monte Carlo error is already about 0.03 posterior sd.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import arviz as az
import emcee
import numpy as np
from scipy import special, stats

#: Convergence targets (see the module docstring).
TARGETS = {
    "max_rhat": 1.01,
    "min_ess_bulk": 1000.0,
    "min_ess_tail": 1000.0,
    "min_tau_lengths": 20.0,
    "max_tau_change": 0.2,
}
#: Fewest independently started ensembles whose comparison (nested R-hat) can certify convergence.
MIN_ENSEMBLES = 4
#: Fewest steps of a sampling chunk (see :func:`planned_chunk`): each chunk ends in a convergence check.
MIN_CHUNK = 50


def rank_normalized(x: np.ndarray) -> np.ndarray:
    """``x`` (..., D) with every column replaced by the normal scores of its ranks over all its elements
    (``Phi^-1((r - 3/8) / (S + 1/4))``, Blom's offsets as in Vehtari et al. 2021), ties averaged."""
    flat = x.reshape(-1, x.shape[-1])
    ranks = stats.rankdata(flat, axis=0, method="average")
    return special.ndtri((ranks - 0.375) / (flat.shape[0] + 0.25)).reshape(x.shape)


def _nested_ratio(x: np.ndarray) -> np.ndarray:
    """``sqrt(1 + B / W)`` of ``x`` (superchains, subchains, draws, D): ``B`` the variance of the superchain means,
    ``W`` the mean over superchains of the variance within each (of its subchain means, plus the mean within-
    subchain variance)."""
    k, m, n = x.shape[:3]
    chain_means = x.mean(axis=2)  # (k, m, D)
    super_means = chain_means.mean(axis=1)  # (k, D)
    between = super_means.var(axis=0, ddof=1)
    between_sub = chain_means.var(axis=1, ddof=1) if m > 1 else np.zeros_like(super_means)
    within_sub = x.var(axis=2, ddof=1).mean(axis=1) if n > 1 else np.zeros_like(super_means)
    within = (between_sub + within_sub).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.sqrt(1.0 + between / within)
    return np.where(within > 0, ratio, np.inf)


def nested_rhat(kept: np.ndarray, n_ensembles: int) -> np.ndarray:
    """(D,) nested R-hat of ``kept`` (steps, walkers, D) of ``n_ensembles`` ensembles: each ensemble's first and
    second half in time are the superchains (``2 n_ensembles`` of them), its walkers the subchains; the larger
    of the rank-normalized and the folded rank-normalized figure. ``inf`` for fewer than four steps or a
    parameter that does not move."""
    steps, walkers, ndim = kept.shape
    half = steps // 2
    if half < 2 or walkers % n_ensembles:
        return np.full(ndim, np.inf)
    per = walkers // n_ensembles
    halves = np.concatenate([kept[:half], kept[steps - half :]], axis=1)  # (half, 2 walkers, D)
    # (2 K superchains, W subchains, half draws, D): ensemble e's first half, then its second half
    x = np.moveaxis(halves.reshape(half, 2 * n_ensembles, per, ndim), 0, 2)
    bulk = _nested_ratio(rank_normalized(x))
    folded = _nested_ratio(rank_normalized(np.abs(x - np.median(x.reshape(-1, ndim), axis=0))))
    constant = np.ptp(kept.reshape(-1, ndim), axis=0) == 0
    return np.where(constant, np.inf, np.maximum(bulk, folded))


def walker_ess(kept: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bulk and tail ESS, each (D,), of ``kept`` (steps, walkers, D), every walker a chain (arviz; split and
    rank-normalized), each figure computed once for all parameters."""
    with warnings.catch_warnings():  # many walkers and a short kept chain are expected, not a shape mistake
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        data = az.convert_to_dataset({f"p{i}": kept[..., i].T for i in range(kept.shape[-1])})
    return tuple(
        np.array([float(figure[k]) for k in data.data_vars])
        for figure in (az.ess(data, method="bulk"), az.ess(data, method="tail"))
    )


@dataclass(frozen=True, eq=False)
class Convergence:
    """Figures of a run of ``n_ensembles`` ensembles at one check: ``tau`` (D,) integrated autocorrelation time
    [steps], the largest over the ensembles; ``discard`` burn-in [steps] from the chain's first step (warm-up
    plus ``2 tau_max``); ``tau_lengths`` kept length over ``tau_max``; ``tau_change`` relative change of
    ``tau_max`` since the previous check (``None`` at the first); ``rhat`` (D,) nested R-hat; ``ess_bulk`` and
    ``ess_tail`` (D,); ``converged`` whether every target of :data:`TARGETS` holds; ``problems`` what misses, in
    words."""

    tau: np.ndarray
    discard: int
    tau_lengths: float
    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    converged: bool
    problems: tuple[str, ...]
    n_ensembles: int = 1
    tau_change: float | None = None

    @property
    def tau_max(self) -> float:
        return float(np.max(self.tau))

    def as_dict(self, names) -> dict:
        per = lambda a: {n: float(v) for n, v in zip(names, a, strict=True)}  # noqa: E731
        return {
            "converged": self.converged,
            "problems": list(self.problems),
            "n_ensembles": self.n_ensembles,
            "discard_steps": self.discard,
            "tau_steps": per(self.tau),
            "tau_lengths": self.tau_lengths,
            "tau_change": self.tau_change,
            "rhat_kind": "nested (ensembles split in time as superchains, walkers as subchains)",
            "rhat": per(self.rhat),
            "ess_bulk": per(self.ess_bulk),
            "ess_tail": per(self.ess_tail),
            "targets": dict(TARGETS),
        }


def convergence(
    chain: np.ndarray, names=None, start: int = 0, n_ensembles: int = 1, previous_tau: float | None = None
) -> Convergence:
    """Convergence figures of ``chain`` (steps, walkers, D) of ``n_ensembles`` independently started ensembles
    after its first ``start`` steps (the warm-up) against :data:`TARGETS` (module docstring). ``previous_tau``:
    ``tau_max`` at the previous check (``None``: this is the first, and the run is not yet certified)."""
    sampled = chain[start:]
    steps, walkers, ndim = sampled.shape
    per = walkers // n_ensembles
    with np.errstate(invalid="ignore", divide="ignore"):  # a parameter no walker moved has no defined tau
        taus = np.array(
            [emcee.autocorr.integrated_time(sampled[:, e * per : (e + 1) * per], tol=0) for e in range(n_ensembles)]
        )
    stuck = ~np.all(np.isfinite(taus), axis=0)
    tau = np.where(stuck, np.inf, np.max(np.where(np.isfinite(taus), taus, np.inf), axis=0))
    tau_max = float(np.max(tau))
    discard = min(int(np.ceil(2.0 * tau_max)), steps // 2) if np.isfinite(tau_max) else steps // 2
    kept = sampled[discard:]
    discard += start
    rhat = nested_rhat(kept, n_ensembles)
    ess_bulk, ess_tail = walker_ess(kept)
    names = list(names) if names is not None else [f"p{i}" for i in range(ndim)]
    lengths = (chain.shape[0] - discard) / tau_max
    change = None
    if previous_tau is not None and np.isfinite(tau_max) and np.isfinite(previous_tau):
        change = abs(tau_max - previous_tau) / tau_max
    problems = []
    if n_ensembles < MIN_ENSEMBLES:
        problems.append(
            f"{n_ensembles} ensemble(s): R-hat needs at least {MIN_ENSEMBLES} independently started ensembles"
        )
    if stuck.any():
        which = ", ".join(names[i] for i in np.flatnonzero(stuck)[:4])
        problems.append(f"autocorrelation time undefined (a walker never moved) for {which}")
    if not lengths >= TARGETS["min_tau_lengths"]:
        problems.append(f"chain is {lengths:.1f} autocorrelation times long (target {TARGETS['min_tau_lengths']:g})")
    if change is None:
        problems.append("tau_max not yet compared between two checks")
    elif change > TARGETS["max_tau_change"]:
        target = 100 * TARGETS["max_tau_change"]
        problems.append(f"tau_max changed by {100 * change:.0f} % since the last check (target {target:g} %)")
    for label, values, bad in (
        ("R-hat", rhat, ~(rhat <= TARGETS["max_rhat"])),
        ("bulk ESS", ess_bulk, ~(ess_bulk >= TARGETS["min_ess_bulk"])),
        ("tail ESS", ess_tail, ~(ess_tail >= TARGETS["min_ess_tail"])),
    ):
        if bad.any():
            worst = ", ".join(f"{names[i]} {values[i]:.3g}" for i in np.flatnonzero(bad)[:4])
            problems.append(f"{label} misses its target for {int(bad.sum())} parameter(s): {worst}")
    return Convergence(
        tau, discard, lengths, rhat, ess_bulk, ess_tail, not problems, tuple(problems), n_ensembles, change
    )


def missing_steps(result: Convergence, steps: int, warmup: int) -> float:
    """Sampling steps still missing after a check at ``steps`` steps (``warmup`` of them warm-up), by what the
    current ``tau_max`` and ESS say, plus a tenth (``tau`` estimates grow as a chain lengthens); ``inf`` where
    ``tau`` is undefined. ESS grows in proportion to the kept length."""
    tau = result.tau_max
    if not np.isfinite(tau):
        return np.inf
    sampled, kept = steps - warmup, max(steps - result.discard, 1)
    by_tau = (TARGETS["min_tau_lengths"] + 2.0) * tau  # the kept length plus the 2 tau discarded
    ess = min(
        float(np.min(result.ess_bulk)) / TARGETS["min_ess_bulk"],
        float(np.min(result.ess_tail)) / TARGETS["min_ess_tail"],
    )
    by_ess = sampled + kept * (1.0 / ess - 1.0) if ess > 0 else np.inf
    return 1.1 * max(by_tau, by_ess) - sampled


def planned_chunk(result: Convergence, steps: int, warmup: int, chunk: int, min_chunk: int = MIN_CHUNK) -> int:
    """Steps for the next chunk of a run that is not yet converged (``result``, checked at ``steps`` steps,
    ``warmup`` of them warm-up): :func:`missing_steps`, between ``min_chunk`` and ``chunk``. A chain a few steps
    short of its target then ends a few steps past it, not up to ``chunk - 1`` past it. A pure function of the
    chain, so a resumed run plans the same chunks."""
    missing = missing_steps(result, steps, warmup)
    if not np.isfinite(missing):
        return chunk
    return min(chunk, max(min_chunk, int(np.ceil(round(missing, 6)))))  # round: 1.1 * 900 is 990.0000000000001


__all__ = [
    "MIN_CHUNK",
    "MIN_ENSEMBLES",
    "TARGETS",
    "Convergence",
    "convergence",
    "missing_steps",
    "nested_rhat",
    "planned_chunk",
    "rank_normalized",
    "walker_ess",
]
