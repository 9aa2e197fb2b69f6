"""Ensemble MCMC (emcee) over a :class:`~peano_bayes.inference.posterior.Posterior`, in resumable chunks.

One jit+vmap log posterior is handed to emcee with ``vectorize=True`` (emcee's red-blue moves evaluate half
ensembles, so it compiles for one batch size). A run is :data:`~peano_bayes.defaults.DEFAULT_ENSEMBLES`
independent ensembles advanced step by step side by side, each **started from its own point**
(:func:`ensemble_centres`: distinct least-squares optima where the caller has them, otherwise draws of the
Laplace approximation widened :data:`CENTRE_SPREAD` times, so that an ensemble that lands in a mode the least
squares missed stays apart and R-hat sees it). Each run has two phases:

- **Warm-up** (discarded), as long as it needs: the first :data:`WARMUP_BOUNDS` round uses the
  differential-evolution mix :data:`MOVES`; at each later bound a multivariate-t independence proposal
  (:class:`IndependenceProposal`) is fitted to the second half of *all* ensembles' walker positions so far and
  joins the mix (:data:`ADAPTED_MOVES`). The warm-up ends at the first bound where the proposal's scale and
  centre are stable against the previous fit (:func:`proposal_change`, :data:`STABLE`), or at ``max_warmup``
  (then the result says the proposal never settled). A fixed ``warmup`` ends it there instead. Each fit
  depends only on the chain, so a resumed run rebuilds the proposals and the warm-up's end exactly
  (:func:`adapt`).
- **Sampling**: the last proposal is frozen (every move then leaves the posterior invariant: the independence
  move is a Metropolis-Hastings step with its Hastings factor) and the run proceeds in chunks, each as long as
  the current autocorrelation time and ESS say is still missing (:func:`~.diagnostics.planned_chunk`), until
  the rule of :mod:`~.diagnostics` certifies it (nested R-hat across the ensembles split in time, bulk and tail
  ESS, at least 20 ``tau_max`` kept with ``tau_max`` stable between two checks), or until ``max_steps``; a run
  stopped by the limit is returned with ``converged=False``.

The Markov kernel that advances one ensemble is behind a seam (:mod:`~peano_bayes.inference.kernels`: init, steps,
record, and one documented state tuple); emcee's ensemble sampler is the default behind it.

Why the independence move: the affine-invariant DE moves handle linear correlation but diffuse slowly in a
10-20 dimensional posterior; a global proposal shaped like the posterior decorrelates a walker in one accepted
step wherever the posterior is close to elliptical, and the DE moves keep exploring where it is not.

After every warm-up round and chunk the whole state (chain, log posterior, RNG state per ensemble, the checks so
far) is written atomically to ``state_path``; with ``resume=True`` a run continues from it with the same numbers
as a run that was never interrupted. Ctrl-C (SIGINT, in the main thread) stops the run after the step under way,
saves the state at that step and raises :class:`SamplingInterrupted`.

Progress: with ``progress`` and a terminal on stderr, a bar per chunk; otherwise (a log file, a worker) one
``log`` line per warm-up bound and per check (step, tau, R-hat, ESS, the time still expected).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import write_bytes
from ..defaults import DEFAULT_CHUNK, DEFAULT_ENSEMBLES, DEFAULT_MAX_STEPS, DEFAULT_MAX_WARMUP, DEFAULT_WARMUP
from ..errors import PeanoBayesError, PeanoBayesInputError
from .coordinates import Identity
from .diagnostics import MIN_CHUNK, MIN_ENSEMBLES, TARGETS, Convergence, convergence, missing_steps, planned_chunk
from .kernels import ADAPTED_MOVES, MOVES, EmceeEnsemble, EnsembleKernel, KernelState, moves_for
from .posterior import Posterior
from .status import SampleStatus
from .warmup import (
    STABLE,
    WARMUP_BOUNDS,
    Adaptation,
    IndependenceProposal,
    adapt,
    fit_proposal,
    proposal_change,
    warmup_bounds,
)

#: Version of the sampler's state file and rule; a state saved under another is refused on resume.
STATE_VERSION = 2
#: Each ensemble's centre is drawn from N(mode, (CENTRE_SPREAD sd)^2) of the Laplace approximation, and its
#: walkers from N(centre, (WALKER_SPREAD sd)^2) around it. A draw of the approximation itself lies about
#: sqrt(D) Mahalanobis units from the mode; centres twice as far apart put each ensemble in its own region, so
#: a mode within that reach that the least squares missed can hold one ensemble apart from the others, which
#: nested R-hat then refuses. Each walker's marginal spread, sqrt(2^2 + 1) = 2.2 sd, is near the former
#: common start's 2 sd, so the warm-up's way in is about as long.
CENTRE_SPREAD = 2.0
WALKER_SPREAD = 1.0
#: First sampling chunk [steps] before any autocorrelation time is known (capped by ``chunk``).
FIRST_CHUNK = 100
def _centre_draw(centre: np.ndarray, covariance: np.ndarray, scale: float, rng: np.random.Generator) -> np.ndarray:
    return rng.multivariate_normal(centre, scale**2 * covariance, method="eigh")


def ensemble_centres(
    posterior: Posterior,
    centre: np.ndarray,
    covariance: np.ndarray,
    n_ensembles: int,
    seed: int,
    optima=None,
    rows: int | None = None,
) -> np.ndarray:
    """(n_ensembles, D) start centres in theta: ``optima`` (k, D), distinct least-squares optima, first (at most
    ``n_ensembles`` of them), then draws of N(``centre``, (:data:`CENTRE_SPREAD` sd)^2) of ``covariance``, each
    with a finite log posterior (a draw where it is not is replaced by one at half the spread, up to 20 times;
    then ``centre`` itself). The draws are evaluated together in calls of ``rows`` points (the walkers' own
    batch size, default ``n_ensembles``), so no other batch shape is compiled."""
    given = [] if optima is None else [np.asarray(o, dtype=float) for o in optima][:n_ensembles]
    todo = list(range(len(given), n_ensembles))
    out = {e: p for e, p in enumerate(given)}
    rngs = {e: np.random.default_rng([seed, 2, e]) for e in todo}
    scales = dict.fromkeys(todo, CENTRE_SPREAD)
    rows = max(rows or n_ensembles, 1)
    for _ in range(20):
        if not todo:
            break
        trials = np.array([_centre_draw(centre, covariance, scales[e], rngs[e]) for e in todo])
        padded = np.vstack([trials, np.repeat(trials[-1:], max(rows - len(trials), 0), axis=0)])
        finite = np.isfinite(posterior.batched(padded)[: len(trials)])
        for e, trial, ok in zip(list(todo), trials, finite, strict=True):
            if ok:
                out[e] = trial
                todo.remove(e)
            else:
                scales[e] *= 0.5
    for e in todo:
        out[e] = np.asarray(centre, dtype=float)
    return np.array([out[e] for e in range(n_ensembles)])


def initial_walkers(
    posterior: Posterior, centre: np.ndarray, covariance: np.ndarray, n_walkers: int, seed: int, ensemble: int = 0
):
    """``n_walkers`` points (n_walkers, D) from N(centre, covariance), each with a finite log posterior
    (redrawn up to 50 times, shrinking the spread); ``ensemble`` selects an independent random stream. Raises
    if none can be found."""
    rng = np.random.default_rng([seed, 1, ensemble] if ensemble else [seed, 1])
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


def _save_state(path: Path, chain, log_prob, random_states, meta: dict) -> None:
    buffer = io.BytesIO()
    np.savez(
        buffer,
        chain=chain,
        log_prob=log_prob,
        rng=np.frombuffer(json.dumps([_rng_to_json(r) for r in random_states]).encode(), dtype=np.uint8),
        meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
    )
    write_bytes(path, buffer.getvalue())


def _rng_to_json(state) -> list:
    name, keys, pos, has_gauss, cached = state
    return [name, np.asarray(keys).tolist(), int(pos), int(has_gauss), float(cached)]


def _rng_from_json(data) -> tuple:
    name, keys, pos, has_gauss, cached = data
    return (name, np.asarray(keys, dtype=np.uint32), pos, has_gauss, cached)


#: How a resume mismatch names each key of a state file's metadata (a key not listed here is named as itself).
_STATE_KEYS = {
    "n_walkers": "--walkers (per ensemble)",
    "n_ensembles": "--ensembles",
    "seed": "--seed",
    "warmup": "--warmup",
    "coordinates": "--coordinates",
    "version": "sampler version (the state was saved by another version of peano-bayes: run without --resume)",
    "names": "sampled parameters",
}


def _differences(saved: dict, now: dict) -> list[str]:
    """The keys of ``now`` (this run's metadata) whose value in ``saved`` (a state file's) differs, each as
    ``option: saved X, now Y``; for the sampled parameters, the names only one side has."""

    def show(key, value):
        if value is None:
            return "unrecorded"
        if key == "coordinates" and isinstance(value, dict):
            forces = value.get("forces_n")
            return value.get("kind", "?") + (f" (forces {forces} N)" if forces else "")
        return str(value)

    out = []
    for key, is_ in now.items():
        was, label = saved.get(key), _STATE_KEYS.get(key, key)
        if was == is_:
            continue
        if key == "names" and was is not None:
            gone, new = [n for n in was if n not in is_], [n for n in is_ if n not in was]
            parts = [f"only saved: {', '.join(gone)}" if gone else "", f"only now: {', '.join(new)}" if new else ""]
            out.append(f"{label}: {'; '.join(p for p in parts if p) or 'the same names in another order'}")
        elif key == "names":
            out.append(f"{label}: unrecorded in the saved state")
        else:
            saved_text, now_text = show(key, was), show(key, is_)
            if saved_text == now_text:  # a difference the short form hides
                saved_text, now_text = str(was), str(is_)
            out.append(f"{label}: saved {saved_text}, now {now_text}")
    return out


def load_state(path: str | os.PathLike):
    """``(chain, log_prob, random_states, meta)`` from a state file written by :func:`sample`; one random
    state per ensemble."""
    with np.load(path) as z:
        saved = json.loads(z["rng"].tobytes().decode())
        if saved and isinstance(saved[0], str):  # a state file of one ensemble
            saved = [saved]
        meta = json.loads(z["meta"].tobytes().decode())
        return z["chain"], z["log_prob"], [_rng_from_json(r) for r in saved], meta


def walker_count(n_walkers: int | None, ndim: int) -> int:
    """Walkers per ensemble: ``n_walkers``, or by default ``max(32, 2 ndim + 2)``, rounded up to even (emcee's
    red-blue halves). At the rule's 20 autocorrelation times, four ensembles of 32 walkers give an ESS near
    2500; more walkers only cost more per step."""
    n = n_walkers or max(32, 2 * ndim + 2)
    if n < 2 * ndim:
        raise PeanoBayesInputError(
            f"{n} walkers per ensemble are fewer than twice the {ndim} sampled parameters; emcee's moves need at "
            f"least {2 * ndim} (omit --walkers for the default, max(32, 2 x parameters + 2))"
        )
    return n + n % 2


def _ensemble_seed(seed: int, ensemble: int) -> int:
    """The seed of ensemble ``ensemble``'s RandomState (``seed`` itself for the first)."""
    if ensemble == 0:
        return seed
    return int(np.random.SeedSequence([seed, ensemble]).generate_state(1)[0])


class SamplingInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a run after a whole step; its state up to that step is saved (the message says where)."""


@contextlib.contextmanager
def _stop_on_interrupt():
    """While active, SIGINT (Ctrl-C) sets the returned event instead of raising inside the density call (where
    emcee would print every walker's position and a traceback); the run stops after the step under way. Outside
    the main thread (a worker) signals cannot be caught, and the event is never set."""
    event = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield event
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: event.set())
    try:
        yield event
    finally:
        signal.signal(signal.SIGINT, previous)


def _bar(progress: bool, total: int, desc: str):
    """A tqdm bar on stderr when ``progress`` and stderr is a terminal, else ``None`` (a log reads one line per
    check instead of a stream of carriage returns)."""
    if not progress or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", leave=False)


def _eta(seconds: float) -> str:
    if not np.isfinite(seconds):
        return "unknown"
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"


@dataclass(frozen=True, eq=False)
class SampleResult:
    """``chain`` (steps, walkers, D) theta, the ensembles' walkers side by side (ensemble ``e`` holds walkers
    ``e W`` to ``(e + 1) W - 1``); ``log_prob`` (steps, walkers); ``convergence``; ``names``; ``seconds`` of
    sampling (this process, compile included); ``acceptance`` mean fraction; ``resumed_from`` steps loaded from
    the state file (0 for a fresh run); ``n_ensembles``; ``warmup`` steps of warm-up the run used;
    ``warmup_stable`` whether its proposal had settled (:func:`adapt`); ``warmup_changes`` the proposal's change
    at each bound; ``checks`` (steps, tau_max) of every convergence check."""

    names: tuple[str, ...]
    chain: np.ndarray
    log_prob: np.ndarray
    convergence: Convergence
    seconds: float
    acceptance: float
    resumed_from: int = 0
    chunks: list = field(default_factory=list)
    n_ensembles: int = 1
    warmup: int = 0
    warmup_stable: bool = True
    warmup_changes: list = field(default_factory=list)
    checks: list = field(default_factory=list)

    @property
    def status(self) -> SampleStatus:
        """How sampling ended (:class:`~peano_bayes.inference.status.SampleStatus`)."""
        return SampleStatus.CONVERGED if self.convergence.converged else SampleStatus.STEP_LIMIT

    def kept(self) -> np.ndarray:
        """(walkers, draws, D) after burn-in."""
        return self.chain[self.convergence.discard :].swapaxes(0, 1)


def sample(
    posterior: Posterior,
    centre: np.ndarray,
    covariance: np.ndarray,
    *,
    n_walkers: int | None = None,
    n_ensembles: int = DEFAULT_ENSEMBLES,
    seed: int = 0,
    chunk: int = DEFAULT_CHUNK,
    max_steps: int = DEFAULT_MAX_STEPS,
    warmup: int | None = DEFAULT_WARMUP,
    max_warmup: int = DEFAULT_MAX_WARMUP,
    min_steps: int = 0,
    optima=None,
    state_path: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = True,
    log=print,
    coordinates=None,
    kernel: Callable[..., EnsembleKernel] = EmceeEnsemble,
) -> SampleResult:
    """Run ``n_ensembles`` independent emcee ensembles of ``n_walkers`` walkers on ``posterior`` (see the module
    docstring), each started around its own centre (:func:`ensemble_centres` from ``centre`` (D,), ``covariance``
    (D, D) and ``optima`` (k, D), theta): the warm-up (adaptive for ``warmup=None``, at most ``max_warmup``
    steps; else exactly ``warmup``), then chunks of at most ``chunk`` steps until converged or ``max_steps`` in
    all; a converged run shorter than ``min_steps`` goes on, in chunks of at most ``chunk``, to ``min_steps``
    exactly (a reference run longer than the rule needs). ``n_walkers``: see :func:`walker_count`.
    ``log(message)`` reports each warm-up bound and check. ``coordinates`` (default theta itself,
    :class:`~peano_bayes.inference.coordinates.Identity`): what the ensembles move (see
    :mod:`~peano_bayes.inference.coordinates`); the state file holds those, while the result's chain, log
    posterior and convergence figures are in theta. ``kernel(density, ndim, n_walkers)`` makes the Markov kernel
    of one ensemble (:class:`~peano_bayes.inference.kernels.EnsembleKernel`; default emcee's,
    :class:`~peano_bayes.inference.kernels.EmceeEnsemble`). Raises :class:`SamplingInterrupted` on Ctrl-C, after
    saving the state."""
    start_time = time.perf_counter()
    if chunk < 1:
        raise PeanoBayesInputError(f"chunk must be >= 1 step, got {chunk}")
    if min_steps > max_steps:
        raise PeanoBayesInputError(f"min_steps ({min_steps}) exceeds max_steps ({max_steps}); raise max_steps")
    if warmup is not None and warmup < 0:
        raise PeanoBayesInputError(f"warmup must be >= 0 steps or None (adaptive), got {warmup}")
    coordinates = Identity() if coordinates is None else coordinates

    def density(z):
        theta, log_jacobian = coordinates.to_theta(z)
        lp = posterior.batched(theta) + log_jacobian
        return np.where(np.isfinite(lp), lp, -np.inf)

    def as_theta(z_chain):
        theta, log_jacobian = coordinates.to_theta(z_chain.reshape(-1, z_chain.shape[-1]))
        return theta.reshape(z_chain.shape), log_jacobian.reshape(z_chain.shape[:-1])

    ndim = posterior.ndim
    per = walker_count(n_walkers, ndim)
    n_ensembles = max(1, int(n_ensembles))
    total = per * n_ensembles
    state_path = Path(state_path) if state_path is not None else None
    meta = {
        "version": STATE_VERSION,
        "names": list(posterior.names),
        "n_walkers": per,
        "n_ensembles": n_ensembles,
        "seed": seed,
        "warmup": "adaptive" if warmup is None else int(warmup),
        "coordinates": coordinates.describe(),
    }
    if warmup is None:
        meta["max_warmup"] = int(max_warmup)
    chain, lps, checks = np.zeros((0, total, ndim)), np.zeros((0, total)), []
    if resume and state_path is not None and state_path.exists():
        chain, lps, rng_states, saved = load_state(state_path)
        saved.setdefault("n_ensembles", 1)
        saved.setdefault("coordinates", {"kind": "theta"})
        differ = _differences(saved, meta)
        if differ:
            raise PeanoBayesInputError(
                f"{state_path}: saved state is of another run: {'; '.join(differ)}; give the same options to "
                "resume it, else delete it or run without --resume"
            )
        checks = [list(c) for c in saved.get("checks", [])]
        states = [
            KernelState(chain[-1, e * per : (e + 1) * per], lps[-1, e * per : (e + 1) * per], r)
            for e, r in enumerate(rng_states)
        ]
        log(f"resumed from {state_path} at step {chain.shape[0]}")
    else:
        states = []
        centres = ensemble_centres(posterior, centre, covariance, n_ensembles, seed, optima, rows=per)
        for e in range(n_ensembles):
            walkers, lp0 = initial_walkers(posterior, centres[e], WALKER_SPREAD**2 * covariance, per, seed, e)
            walkers = coordinates.to_sampler(walkers)
            lp0 = lp0 + coordinates.to_theta(walkers)[1]
            random_state = np.random.RandomState(_ensemble_seed(seed, e)).get_state()
            states.append(KernelState(walkers, lp0, random_state))
    resumed_from = chain.shape[0]
    bounds = warmup_bounds(warmup, max_warmup)
    accepted, chunks, result, step_s = 0.0, [], None, None

    def check(steps: int, end: int) -> Convergence:
        """The rule at ``steps`` against the last check before it; recorded in ``checks`` (replacing any later)."""
        earlier = [c for c in checks if c[0] < steps]
        figures = convergence(as_theta(chain)[0], posterior.names, start=end, n_ensembles=n_ensembles,
                              previous_tau=earlier[-1][1] if earlier else None)  # fmt: skip
        checks[:] = [*earlier, [steps, figures.tau_max]]
        return figures

    with _stop_on_interrupt() as interrupted:
        while chain.shape[0] < max_steps:
            done = chain.shape[0]
            adaptation = adapt(chain, warmup, max_warmup)
            end = adaptation.end
            in_warmup = end is None or done < end
            if not in_warmup and result is None and done > end:  # resumed after a chunk: its last check again
                result = check(done, end)
                if result.converged and done >= min_steps:
                    break
            if in_warmup:
                n = next(b for b in bounds if b > done) - done
            elif result is None:
                n = min(chunk, FIRST_CHUNK)
            else:
                n = chunk if result.converged else planned_chunk(result, done, end, chunk)
                if done < min_steps:  # a run lengthened to min_steps ends there exactly
                    n = min(n, min_steps - done)
            n = min(n, max_steps - done)
            proposal = adaptation.proposal_at(done)
            kernels = [kernel(density, ndim, per) for _ in range(n_ensembles)]
            label = "warm-up" if in_warmup else "sampling"
            bar = _bar(progress, n, f"{label} {done}-{done + n}")
            t0 = time.perf_counter()
            steppers = [k.steps(states[e], n, proposal) for e, k in enumerate(kernels)]
            taken = 0
            try:
                while taken < n and not interrupted.is_set():
                    for e, stepper in enumerate(steppers):
                        states[e] = next(stepper)
                    taken += 1
                    if bar is not None:
                        bar.update(1)
            except ValueError as err:  # emcee refuses walkers that span fewer than ndim dimensions
                if "condition number" not in str(err):
                    raise
                raise PeanoBayesError(
                    f"the {per} walkers of an ensemble collapsed onto fewer than {ndim} dimensions at step "
                    f"{done}: the data do not determine all {ndim} sampled parameters "
                    f"({', '.join(posterior.names)}); fit more tests or runs, or narrow the prior"
                ) from None
            finally:
                if bar is not None:
                    bar.close()
            if taken:  # (a stop before the chunk's first step adds nothing)
                records = [k.record() for k in kernels]
                chain = np.concatenate([chain, np.concatenate([r[0] for r in records], axis=1)])
                lps = np.concatenate([lps, np.concatenate([r[1] for r in records], axis=1)])
                accepted = float(np.mean(np.concatenate([r[2] for r in records])))
            step_s = (time.perf_counter() - t0) / max(taken, 1)
            steps = chain.shape[0]
            # each state carries its ensemble's RNG state as of its last step (the start's, before any step)
            random_states = [state.random_state for state in states]
            if interrupted.is_set():
                where = ""
                if state_path is not None:
                    _save_state(state_path, chain, lps, random_states, {**meta, "checks": checks})
                    where = f"; state saved in {state_path}: run the same command with --resume to continue"
                raise SamplingInterrupted(f"stopped at step {steps}{where}")
            chunks.append({"steps": steps, "seconds": step_s * taken, "acceptance": accepted, "warmup": in_warmup})
            if in_warmup:
                after = adapt(chain, warmup, max_warmup)
                change = after.changes[-1] if after.changes and after.changes[-1]["step"] == steps else None
                log(
                    f"warm-up step {steps}: acceptance {accepted:.2f}"
                    + (
                        f", proposal sd changed {100 * change['scale']:.0f} %, centre moved {change['centre']:.2f} sd"
                        if change
                        else ""
                    )
                    + (
                        f"; warm-up ends here ({'stable' if after.stable else 'proposal NOT stable: limit reached'})"
                        if after.end == steps
                        else ""
                    )
                )
            else:
                result = check(steps, end)
                missing = 0.0 if result.converged else missing_steps(result, steps, end)
                change = "" if result.tau_change is None else f" (changed {100 * result.tau_change:.0f} %)"
                log(
                    f"sampling step {steps} (warm-up {end}): acceptance {accepted:.2f}, tau_max "
                    f"{result.tau_max:.1f}{change}, {result.tau_lengths:.0f} tau kept, max R-hat "
                    f"{np.max(result.rhat):.3f} ({n_ensembles} ensembles), min ESS bulk {np.min(result.ess_bulk):.0f}"
                    f" tail {np.min(result.ess_tail):.0f}"
                    + ("; converged" if result.converged else f"; ETA {_eta(max(missing, MIN_CHUNK) * step_s)}")
                )
            if state_path is not None:
                _save_state(state_path, chain, lps, random_states, {**meta, "checks": checks})
            if result is not None and not in_warmup and result.converged and steps >= min_steps:
                break
    adaptation = adapt(chain, warmup, max_warmup)
    end = adaptation.end
    theta_chain, log_jacobian = as_theta(chain)
    if result is None and end is not None and chain.shape[0] > end:  # resumed at or past the limit
        result = check(chain.shape[0], end)
    if result is None:  # the step limit came inside the warm-up: figures of its second half, never converged
        result = convergence(theta_chain, posterior.names, start=len(chain) // 2, n_ensembles=n_ensembles)
        limit = warmup if warmup is not None else f"adaptive, at most {max_warmup}"
        problems = (f"the step limit ({max_steps}) ended the run inside the warm-up ({limit} steps)",)
        result = dataclasses.replace(result, converged=False, problems=problems + result.problems)
    return SampleResult(
        posterior.names,
        theta_chain,
        lps - log_jacobian,
        result,
        time.perf_counter() - start_time,
        accepted,
        resumed_from,
        chunks,
        n_ensembles,
        end if end is not None else (warmup if warmup is not None else chain.shape[0]),
        adaptation.stable,
        adaptation.changes,
        checks,
    )


__all__ = [
    "ADAPTED_MOVES",
    "CENTRE_SPREAD",
    "MIN_ENSEMBLES",
    "MOVES",
    "STABLE",
    "TARGETS",
    "WARMUP_BOUNDS",
    "WALKER_SPREAD",
    "Adaptation",
    "Convergence",
    "IndependenceProposal",
    "SampleResult",
    "SamplingInterrupted",
    "adapt",
    "convergence",
    "ensemble_centres",
    "fit_proposal",
    "initial_walkers",
    "load_state",
    "moves_for",
    "proposal_change",
    "sample",
    "walker_count",
    "warmup_bounds",
]
