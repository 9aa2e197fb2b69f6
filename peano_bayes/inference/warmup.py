"""The sampler's independence proposal and the adaptive warm-up that fits it.

A multivariate-t proposal (:class:`IndependenceProposal`) is refitted to all ensembles' walkers at the bounds of
:data:`WARMUP_BOUNDS`; the warm-up ends where the refit agrees with the previous fit (:data:`STABLE`). Every fit
is a function of the chain alone, so a resumed run rebuilds the proposals and the warm-up's end (:func:`adapt`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import special

from ..defaults import DEFAULT_MAX_WARMUP

#: Degrees of freedom of the fitted multivariate-t proposal: heavier tails than the near-Gaussian posterior keep
#: some margin (on PR the move's acceptance against posterior draws was 0.41 with df 5 and 0.55 with df 20).
PROPOSAL_DF = 20.0
#: Smallest eigenvalue of a fitted proposal's scale matrix, relative to its largest.
EIGENVALUE_FLOOR = 1e-8
#: Step bounds at which the warm-up refits its proposal: rounds that grow by half, so that each fit rests on
#: more draws than the last and the noise in a stable proposal's refit shrinks as the warm-up lengthens.
WARMUP_BOUNDS = (100, 200, 300, 450, 700, 1050, 1600, 2400, 3600, 5400, 8100)
#: The warm-up ends where a refit proposal differs from the previous fit by at most these: ``scale`` the largest
#: relative change of its standard deviation along any direction, ``centre`` the shift of its mean in sd units
#: (Mahalanobis) of the new fit.
STABLE = {"scale": 0.2, "centre": 0.3}


@dataclass(frozen=True, eq=False)
class IndependenceProposal:
    """Multivariate-t independence proposal for emcee's :class:`emcee.moves.MHMove`: ``mean`` (D,),
    ``covariance`` (D, D) (of the t's scale matrix), ``df`` degrees of freedom (heavy tails keep the
    importance weights bounded where the posterior's tails are wider than the fitted ellipse)."""

    mean: np.ndarray
    covariance: np.ndarray
    df: float = PROPOSAL_DF

    @classmethod
    def fit(cls, draws: np.ndarray, df: float = PROPOSAL_DF) -> IndependenceProposal:
        """Fitted to ``draws`` (n, D): their mean and covariance, eigenvalues floored at
        :data:`EIGENVALUE_FLOOR` times the largest. Few or stuck walkers (a short warm-up, a walker that never
        moved) give a rank-deficient sample covariance; the floor keeps the scale matrix positive definite."""
        mean = draws.mean(axis=0)
        values, vectors = np.linalg.eigh(np.atleast_2d(np.cov(draws.T)))
        values = np.maximum(values, EIGENVALUE_FLOOR * max(values.max(), 1e-300))
        return cls(mean, (vectors * values) @ vectors.T, df)

    @cached_property
    def _cholesky(self) -> np.ndarray:
        return np.linalg.cholesky(self.covariance)

    def log_density(self, x: np.ndarray) -> np.ndarray:
        """(n,) log density of the proposal at ``x`` (n, D): the multivariate t with location ``mean``, scale
        matrix ``covariance`` and ``df`` degrees of freedom, through the Cholesky factor used to draw from it."""
        x = np.atleast_2d(x)
        d = self.mean.size
        solved = np.linalg.solve(self._cholesky, (x - self.mean).T)
        mahalanobis = np.sum(solved**2, axis=0)
        half_log_det = np.sum(np.log(np.diag(self._cholesky)))
        norm = (
            special.gammaln((self.df + d) / 2)
            - special.gammaln(self.df / 2)
            - 0.5 * d * np.log(self.df * np.pi)
            - half_log_det
        )
        return norm - 0.5 * (self.df + d) * np.log1p(mahalanobis / self.df)

    def draw(self, n: int, random: np.random.RandomState | np.random.Generator) -> np.ndarray:
        """(n, D) draws of the t: a normal through the Cholesky factor over the root of a chi-square / df,
        from ``random`` (a legacy ``RandomState``, as emcee passes, or a ``Generator``: the same calls)."""
        z = random.standard_normal((n, self.mean.size))
        w = random.chisquare(self.df, size=n) / self.df
        return self.mean + (z @ self._cholesky.T) / np.sqrt(w)[:, None]

    def __call__(self, coords: np.ndarray, random: np.random.RandomState):
        """emcee's proposal contract: new points (n, D) and log Hastings factors q(old) / q(new) (n,), drawn
        with emcee's own random state (so a resumed run repeats them)."""
        new = self.draw(coords.shape[0], random)
        return new, self.log_density(coords) - self.log_density(new)


def warmup_bounds(warmup: int | None, max_warmup: int = DEFAULT_MAX_WARMUP) -> list[int]:
    """Step bounds at which the proposal is refitted: :data:`WARMUP_BOUNDS` up to ``max_warmup`` (which is one),
    or, for a fixed ``warmup``, the bounds below it and ``warmup`` itself (none for 0)."""
    limit = max_warmup if warmup is None else warmup
    if limit <= 0:
        return []
    return [b for b in WARMUP_BOUNDS if b < limit] + [limit]


def fit_proposal(chain: np.ndarray, bound: int) -> IndependenceProposal:
    """The proposal fitted at ``bound``: to the second half of every walker's positions up to it (the first half
    is the way in from the dispersed starts), all ensembles pooled."""
    half = chain[bound // 2 : bound]
    return IndependenceProposal.fit(half.reshape(-1, chain.shape[-1]))


def proposal_change(old: IndependenceProposal, new: IndependenceProposal) -> dict[str, float]:
    """How far ``new`` moved from ``old``: ``scale``, the largest relative change of the standard deviation along
    any direction (from the eigenvalues of ``old``'s covariance whitened by ``new``'s), and ``centre``, the
    Mahalanobis distance between the means in ``new``'s metric."""
    chol = np.linalg.cholesky(new.covariance)
    whitened = np.linalg.solve(chol, np.linalg.solve(chol, old.covariance).T)
    ratios = np.sqrt(np.clip(np.linalg.eigvalsh(0.5 * (whitened + whitened.T)), 0.0, None))
    scale = float(np.max(np.abs(ratios - 1.0)))
    centre = float(np.linalg.norm(np.linalg.solve(chol, old.mean - new.mean)))
    return {"scale": scale, "centre": centre}


@dataclass(frozen=True, eq=False)
class Adaptation:
    """The warm-up as far as a chain shows it (:func:`adapt`): ``proposals`` bound -> proposal fitted there;
    ``changes`` one row per bound after the first (``step``, ``scale``, ``centre``); ``end`` the step the
    warm-up ended at, ``None`` while it goes on; ``stable`` whether it ended on a stable proposal (a fixed
    warm-up ends where it is told, stable or not)."""

    proposals: dict[int, IndependenceProposal]
    changes: list[dict]
    end: int | None
    stable: bool

    def proposal_at(self, step: int) -> IndependenceProposal | None:
        """The proposal in force at ``step``: the last fitted at a bound <= ``step``, frozen after the end."""
        limit = step if self.end is None else min(step, self.end)
        fitted = [b for b in self.proposals if b <= limit]
        return self.proposals[max(fitted)] if fitted else None


def adapt(chain: np.ndarray, warmup: int | None, max_warmup: int = DEFAULT_MAX_WARMUP) -> Adaptation:
    """Replay the warm-up on ``chain`` (steps, walkers, D) in the sampler's coordinates: fit the proposal at every
    bound the chain has reached and end the warm-up at the first bound (after the second) whose proposal is
    stable against the one before (:data:`STABLE`), or at the last bound (``warmup`` if fixed, else
    ``max_warmup``). A pure function of the chain, so a resumed run finds the same proposals and end."""
    bounds = warmup_bounds(warmup, max_warmup)
    proposals, changes, end, stable = {}, [], None, False
    previous = None
    for bound in bounds:
        if bound > chain.shape[0]:
            break
        proposals[bound] = proposal = fit_proposal(chain, bound)
        if previous is not None:
            change = proposal_change(previous, proposal)
            changes.append({"step": bound, **change})
            stable = change["scale"] <= STABLE["scale"] and change["centre"] <= STABLE["centre"]
            if warmup is None and stable:
                end = bound
                break
        previous = proposal
        if bound == bounds[-1]:
            end = bound
    if not bounds:
        end, stable = 0, True
    return Adaptation(proposals, changes, end, stable)


__all__ = [
    "EIGENVALUE_FLOOR",
    "PROPOSAL_DF",
    "STABLE",
    "WARMUP_BOUNDS",
    "Adaptation",
    "IndependenceProposal",
    "adapt",
    "fit_proposal",
    "proposal_change",
    "warmup_bounds",
]
