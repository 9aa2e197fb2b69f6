"""The sampler seam: the Markov kernel the driver (:func:`~peano_bayes.inference.sample.sample`) advances, one
ensemble of walkers at a time, with emcee behind it.

The driver owns everything around the kernel: the ensembles' starts, the warm-up's proposal fits, the chunking,
the convergence rule, the state file and Ctrl-C. It asks a kernel for three things (:class:`EnsembleKernel`):

- ``init(position, log_prob, random_state) -> KernelState``: a state from walker positions (W, D) in the
  sampler's coordinates, their log density (W,) and an RNG state;
- ``steps(state, n, proposal)``: an iterator that takes ``n`` steps from ``state`` and yields the
  :class:`KernelState` after each (so the driver can advance several ensembles side by side and stop between
  steps); ``proposal`` is the warm-up's current :class:`~peano_bayes.inference.warmup.IndependenceProposal`, or
  ``None`` before the first is fitted;
- ``record()``: ``(chain (n, W, D), log_prob (n, W), acceptance (W,))`` of the steps the last iterator took.

:class:`KernelState` is the one documented state tuple: ``position`` (W, D), ``log_prob`` (W,) and
``random_state`` (NumPy's legacy ``RandomState.get_state()`` tuple, what emcee draws from). The driver saves
those three per ensemble (see :mod:`~peano_bayes.inference.sample`), so any kernel with the same state resumes.

:class:`EmceeEnsemble` is emcee's ``EnsembleSampler`` with ``vectorize=True`` (one batched density call per
half-ensemble) and the move mix :func:`moves_for`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple, Protocol

import emcee
import numpy as np

from .warmup import IndependenceProposal

#: Moves before any proposal is fitted (emcee's recommended differential-evolution mix).
MOVES = ((emcee.moves.DEMove, 0.8), (emcee.moves.DESnookerMove, 0.2))
#: Weights once the independence proposal is fitted: DE, snooker, independence. The independence move
#: decorrelates a walker in one accepted step where the posterior is near elliptical; the DE moves carry back
#: walkers from the tails, where the ellipse under-covers and an independence-only kernel gets stuck.
ADAPTED_MOVES = (0.4, 0.1, 0.5)


def moves_for(proposal: IndependenceProposal | None) -> list:
    """emcee's move mix: :data:`MOVES` before a proposal is fitted, then :data:`ADAPTED_MOVES` with the
    independence move (a Metropolis-Hastings step drawing from ``proposal``)."""
    if proposal is None:
        return [(move(), weight) for move, weight in MOVES]
    de, snooker, independence = ADAPTED_MOVES
    return [
        (emcee.moves.DEMove(), de),
        (emcee.moves.DESnookerMove(), snooker),
        (emcee.moves.MHMove(proposal), independence),
    ]


class KernelState(NamedTuple):
    """One ensemble's state: ``position`` (W, D) in the sampler's coordinates, ``log_prob`` (W,) there, and
    ``random_state`` (NumPy legacy RNG state tuple)."""

    position: np.ndarray
    log_prob: np.ndarray
    random_state: tuple


class EnsembleKernel(Protocol):
    """What :func:`~peano_bayes.inference.sample.sample` needs of a kernel (see the module docstring)."""

    def init(self, position: np.ndarray, log_prob: np.ndarray, random_state) -> KernelState: ...

    def steps(self, state: KernelState, n: int, proposal: IndependenceProposal | None) -> Iterator[KernelState]: ...

    def record(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


class EmceeEnsemble:
    """:class:`EnsembleKernel` over emcee: ``density`` (W, D) -> (W,) log density in the sampler's coordinates
    (``-inf`` outside the support), ``n_walkers`` walkers in ``ndim`` dimensions."""

    def __init__(self, density: Callable[[np.ndarray], np.ndarray], ndim: int, n_walkers: int):
        self.density, self.ndim, self.n_walkers = density, ndim, n_walkers
        self._sampler: emcee.EnsembleSampler | None = None

    def init(self, position, log_prob, random_state) -> KernelState:
        return KernelState(np.asarray(position), np.asarray(log_prob), random_state)

    def steps(self, state: KernelState, n: int, proposal: IndependenceProposal | None) -> Iterator[KernelState]:
        moves = moves_for(proposal)
        self._sampler = emcee.EnsembleSampler(self.n_walkers, self.ndim, self.density, vectorize=True, moves=moves)
        start = emcee.State(state.position, log_prob=state.log_prob, random_state=state.random_state)
        for s in self._sampler.sample(start, iterations=n):
            yield KernelState(s.coords, s.log_prob, s.random_state)

    def record(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._sampler is None:
            raise RuntimeError("record() before any steps()")
        s = self._sampler
        return s.get_chain(), s.get_log_prob(), s.acceptance_fraction


__all__ = ["ADAPTED_MOVES", "MOVES", "EmceeEnsemble", "EnsembleKernel", "KernelState", "moves_for"]
