"""Ensemble MCMC (emcee) over a :class:`~peano_bayes.inference.posterior.Posterior`, in resumable chunks.

One jit+vmap log posterior is handed to emcee with ``vectorize=True`` (emcee's red-blue moves evaluate half
ensembles, so it compiles for two batch sizes). A run is :data:`~peano_bayes.defaults.DEFAULT_ENSEMBLES`
independent ensembles, each started from its own overdispersed draws around the Laplace approximation of the
posterior mode, and advanced chunk by chunk side by side. Each ensemble has two phases:

- **Warm-up** (``warmup`` steps in :data:`WARMUP_ROUNDS` rounds, discarded): the first round uses the
  differential-evolution mix :data:`MOVES`; after each round a multivariate-t independence proposal
  (:class:`IndependenceProposal`) is fitted to the second half of the walker positions so far and joins the
  mix (:data:`ADAPTED_MOVES`) for the next round. Each fitted proposal depends only on the chain, so a resumed
  run rebuilds it exactly.
- **Sampling**: the last proposal is frozen (the kernel no longer changes, so every move leaves the posterior
  invariant: the independence move is a Metropolis-Hastings step with its Hastings factor) and the run
  proceeds in chunks of at most ``chunk`` steps, each as long as the current autocorrelation time and ESS
  say is still missing (:func:`planned_chunk`), until

  - the kept chain (after the warm-up and a further ``2 tau_max``) is at least ``50 tau_max`` long (emcee's
    own reliability rule for its integrated autocorrelation time ``tau``),
  - R-hat <= 1.01 across the ensembles and bulk and tail ESS >= 1000 for every parameter (arviz, on the kept
    draws, each ensemble's walkers pooled into one chain: the walkers of one ensemble move together and are
    not the independent chains R-hat assumes),

  or until ``max_steps``; a run stopped by the limit is returned with ``converged=False``.

Why the independence move: the affine-invariant DE moves handle linear correlation but diffuse slowly in a
10-15 dimensional posterior (tau 57 steps on the bundled TP data even from the posterior mode); a global
proposal shaped like the posterior decorrelates a walker in one accepted step wherever the posterior is
close to elliptical, and the DE moves keep exploring where it is not (see :data:`ADAPTED_MOVES`).

After every warm-up round and chunk the whole state (chain, log posterior, RNG state per ensemble) is written
atomically to
``state_path``; with ``resume=True`` a run continues from it, and because the RNG state is restored it gives
the same numbers as a run that was never interrupted.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import arviz as az
import emcee
import numpy as np
from scipy import special

from ..atomic import write_bytes
from ..defaults import DEFAULT_CHUNK, DEFAULT_ENSEMBLES, DEFAULT_MAX_STEPS, DEFAULT_WARMUP
from ..errors import PeanoBayesError, PeanoBayesInputError
from .coordinates import Identity
from .posterior import Posterior

#: Convergence targets: chains of at least 50 integrated autocorrelation times, rank-normalized split R-hat
#: across the ensembles <= 1.01, bulk and tail ESS >= 1000 for every parameter.
TARGETS = {"min_tau_lengths": 50.0, "max_rhat": 1.01, "min_ess_bulk": 1000.0, "min_ess_tail": 1000.0}
#: Fewest independently started ensembles whose comparison (R-hat) can certify convergence.
MIN_ENSEMBLES = 4
#: Each ensemble starts from N(centre, (START_INFLATION sd)^2): overdispersed against the Laplace
#: approximation, so an ensemble that cannot leave its start shows in R-hat.
START_INFLATION = 2.0
#: Moves before any proposal is fitted (emcee's recommended differential-evolution mix).
MOVES = ((emcee.moves.DEMove, 0.8), (emcee.moves.DESnookerMove, 0.2))
#: Weights once the independence proposal is fitted: DE, snooker, independence. The independence move
#: decorrelates a walker in one accepted step where the posterior is near elliptical (on PR, with the proposal
#: of :func:`proposal_at`, tau_max 16.2 over 500 steps against 18.0 with weight 0.3); the DE moves carry back
#: walkers from the tails, where the ellipse under-covers and an independence-only kernel gets stuck.
ADAPTED_MOVES = (0.4, 0.1, 0.5)
#: Degrees of freedom of the fitted multivariate-t proposal. On PR the independence move's acceptance, against
#: posterior draws, was 0.41 with df 5 and 0.55 with df 20 for one proposal (100: 0.67 for one fitted to
#: 68,000 draws, so the posterior is close to Gaussian); df 20 keeps some margin for heavier tails.
PROPOSAL_DF = 20.0
#: Smallest eigenvalue of a fitted proposal's scale matrix, relative to its largest.
EIGENVALUE_FLOOR = 1e-8
#: Warm-up rounds; the proposal is refitted after each.
WARMUP_ROUNDS = 3
#: Fewest steps of a sampling chunk (see :func:`planned_chunk`): each chunk ends in a convergence check.
MIN_CHUNK = 50


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


def moves_for(proposal: IndependenceProposal | None) -> list:
    """emcee's weighted moves: :data:`MOVES` without a proposal, else :data:`ADAPTED_MOVES` with it."""
    if proposal is None:
        return [(m(), w) for m, w in MOVES]
    de, snooker, independence = ADAPTED_MOVES
    return [
        (emcee.moves.DEMove(), de),
        (emcee.moves.DESnookerMove(), snooker),
        (emcee.moves.MHMove(proposal), independence),
    ]


def warmup_rounds(warmup: int) -> list[int]:
    """Step boundaries ``[0, r, 2r, ..., warmup]`` of the warm-up rounds (no rounds when ``warmup`` is 0)."""
    if warmup <= 0:
        return [0]
    size = int(np.ceil(warmup / WARMUP_ROUNDS))
    return sorted({*range(0, warmup, size), warmup})


def proposal_at(chain: np.ndarray, step: int, warmup: int) -> IndependenceProposal | None:
    """The proposal in force at ``step`` of a run with ``warmup`` steps of warm-up: fitted to the second half
    of the chain up to the end of the last warm-up round finished by then (the first half is the way in from
    the overdispersed start), or ``None`` before the first round ends. The sampling phase's proposal thus sees
    the last half of the warm-up: on PR (with the former 300-step warm-up), 150 steps x 34 walkers gave an
    acceptance of 0.50 where the last round's second half (50 steps) gave 0.30."""
    bounds = warmup_rounds(warmup)
    finished = [b for b in bounds[1:] if b <= step]
    if not finished:
        return None
    end = finished[-1]
    half = chain[end // 2 : end]
    return IndependenceProposal.fit(half.reshape(-1, chain.shape[-1]))


@dataclass(frozen=True, eq=False)
class Convergence:
    """Figures of a run of ``n_ensembles`` ensembles: ``tau`` (D,) integrated autocorrelation time [steps], the
    largest over the ensembles; ``discard`` burn-in [steps]; ``tau_lengths`` kept length over ``tau_max``;
    ``rhat``/``ess_bulk``/``ess_tail`` (D,) on the kept draws, each ensemble's walkers pooled into one chain;
    ``converged`` whether every target of :data:`TARGETS` holds; ``problems`` what misses, in words."""

    tau: np.ndarray
    discard: int
    tau_lengths: float
    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    converged: bool
    problems: tuple[str, ...]
    n_ensembles: int = 1

    def as_dict(self, names) -> dict:
        per = lambda a: {n: float(v) for n, v in zip(names, a, strict=True)}  # noqa: E731
        return {
            "converged": self.converged,
            "problems": list(self.problems),
            "n_ensembles": self.n_ensembles,
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
    """``chain`` (steps, walkers, D) theta, the ensembles' walkers side by side (ensemble ``e`` holds walkers
    ``e W`` to ``(e + 1) W - 1``); ``log_prob`` (steps, walkers); ``convergence``; ``names``; ``seconds`` of
    sampling (this process, compile included); ``acceptance`` mean fraction; ``resumed_from`` steps loaded from
    the state file (0 for a fresh run); ``n_ensembles``; ``warmup`` steps of warm-up the run used."""

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

    def kept(self) -> np.ndarray:
        """(walkers, draws, D) after burn-in."""
        return self.chain[self.convergence.discard :].swapaxes(0, 1)


def pooled(chain: np.ndarray, n_ensembles: int) -> np.ndarray:
    """(n_ensembles, walkers_per_ensemble * steps, ...) from ``chain`` (steps, walkers, ...): each ensemble's
    walkers laid end to end as one chain (the unit R-hat compares: walkers of one ensemble are not independent
    chains, Foreman-Mackey on emcee issue 183)."""
    steps, walkers = chain.shape[:2]
    per = walkers // n_ensembles
    rest = chain.shape[2:]
    split = chain.reshape((steps, n_ensembles, per) + rest)
    return np.moveaxis(split, 0, 2).reshape((n_ensembles, per * steps) + rest)


def arviz_figures(data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank-normalized split R-hat, bulk ESS and tail ESS, each (D,) in ``data``'s variable order, of an arviz
    dataset of D variables (chains, draws): each figure computed once for all variables."""
    return tuple(
        np.array([float(figure[k]) for k in data.data_vars])
        for figure in (az.rhat(data), az.ess(data, method="bulk"), az.ess(data, method="tail"))
    )


def convergence(chain: np.ndarray, names=None, start: int = 0, n_ensembles: int = 1) -> Convergence:
    """Convergence figures of ``chain`` (steps, walkers, D) of ``n_ensembles`` independently started ensembles
    after its first ``start`` steps (the warm-up) against :data:`TARGETS`; ``discard`` counts from the chain's
    first step.

    The autocorrelation time is emcee's, per ensemble (the largest is kept); R-hat (rank-normalized split, arviz)
    compares the ensembles, each ensemble's walkers pooled into one chain; bulk and tail ESS are arviz's on the
    same pooled chains. With one ensemble R-hat cannot compare ensembles: it is computed with the walkers as
    chains and the run is never called converged."""
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
    chains = pooled(kept, n_ensembles) if n_ensembles > 1 else kept.swapaxes(0, 1)
    draws = {f"p{i}": chains[..., i] for i in range(ndim)}
    rhat, ess_bulk, ess_tail = arviz_figures(az.convert_to_dataset(draws))
    names = list(names) if names is not None else list(draws)
    lengths = (chain.shape[0] - discard) / tau_max
    problems = []
    if n_ensembles < MIN_ENSEMBLES:
        problems.append(
            f"{n_ensembles} ensemble(s): R-hat needs at least {MIN_ENSEMBLES} independently started ensembles"
        )
    if stuck.any():
        which = ", ".join(names[i] for i in np.flatnonzero(stuck)[:4])
        problems.append(f"autocorrelation time undefined (a walker never moved) for {which}")
    if lengths < TARGETS["min_tau_lengths"]:
        problems.append(f"chain is {lengths:.1f} autocorrelation times long (target {TARGETS['min_tau_lengths']:g})")
    for label, values, bad in (
        ("R-hat", rhat, ~(rhat <= TARGETS["max_rhat"])),
        ("bulk ESS", ess_bulk, ~(ess_bulk >= TARGETS["min_ess_bulk"])),
        ("tail ESS", ess_tail, ~(ess_tail >= TARGETS["min_ess_tail"])),
    ):
        if bad.any():
            worst = ", ".join(f"{names[i]} {values[i]:.3g}" for i in np.flatnonzero(bad)[:4])
            problems.append(f"{label} misses its target for {int(bad.sum())} parameter(s): {worst}")
    return Convergence(tau, discard, lengths, rhat, ess_bulk, ess_tail, not problems, tuple(problems), n_ensembles)


def planned_chunk(result: Convergence, steps: int, warmup: int, chunk: int, min_chunk: int = MIN_CHUNK) -> int:
    """Steps for the next chunk of a run of ``steps`` steps (``warmup`` of them warm-up) that is not yet
    converged (``result``): the steps its current autocorrelation time and ESS say are still missing, plus a
    tenth (``tau`` estimates grow as a chain lengthens), between ``min_chunk`` and ``chunk``. A chain a few
    steps short of its target then ends a few steps past it rather than up to ``chunk - 1`` past it (on PR,
    tau 21, a 500-step chunk would overshoot by a third of the run). A pure function of the chain, so a
    resumed run plans the same chunks."""
    tau = float(np.max(result.tau))
    if not np.isfinite(tau):
        return chunk
    sampled, kept = steps - warmup, max(steps - result.discard, 1)
    by_tau = (TARGETS["min_tau_lengths"] + 2.0) * tau  # the kept length plus the 2 tau discarded
    ess = min(
        float(np.min(result.ess_bulk)) / TARGETS["min_ess_bulk"],
        float(np.min(result.ess_tail)) / TARGETS["min_ess_tail"],
    )
    by_ess = sampled + kept * (1.0 / ess - 1.0) if ess > 0 else np.inf  # ESS grows with the kept length
    missing = 1.1 * max(by_tau, by_ess) - sampled
    if not np.isfinite(missing):
        return chunk
    return min(chunk, max(min_chunk, int(np.ceil(round(missing, 6)))))  # round: 1.1 * 900 is 990.0000000000001


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
    red-blue halves). With 50 autocorrelation times required, 32 walkers already give an ESS near 1600 per
    ensemble; more walkers only cost more per step."""
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
    warmup: int = DEFAULT_WARMUP,
    min_steps: int = 0,
    state_path: str | os.PathLike | None = None,
    resume: bool = False,
    progress: bool = True,
    log=print,
    coordinates=None,
) -> SampleResult:
    """Run ``n_ensembles`` independent emcee ensembles of ``n_walkers`` walkers on ``posterior``, each started
    from its own draws of N(``centre``, :data:`START_INFLATION`^2 ``covariance``) in theta space (overdispersed,
    so that R-hat can reveal an ensemble stuck in its start): ``warmup`` steps of warm-up, then chunks of at
    most ``chunk`` steps (:func:`planned_chunk`) until converged (:func:`convergence`) or ``max_steps`` in all
    (see the module docstring); a converged run shorter than ``min_steps`` goes on, in chunks of at most
    ``chunk``, to ``min_steps`` exactly (a reference run longer than the convergence rule needs).
    ``n_walkers``: see :func:`walker_count`. ``log(message)`` reports each round and chunk. ``coordinates``
    (default theta itself, :class:`~peano_bayes.inference.coordinates.Identity`): what the ensembles move (see
    :mod:`~peano_bayes.inference.coordinates`); the state file holds those, while the result's chain, log
    posterior and convergence figures are in theta."""
    start_time = time.perf_counter()
    if chunk < 1:
        raise PeanoBayesInputError(f"chunk must be >= 1 step, got {chunk}")
    if min_steps > max_steps:
        raise PeanoBayesInputError(f"min_steps ({min_steps}) exceeds max_steps ({max_steps}); raise max_steps")
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
    warmup = max(0, int(warmup))
    state_path = Path(state_path) if state_path is not None else None
    meta = {
        "names": list(posterior.names),
        "n_walkers": per,
        "n_ensembles": n_ensembles,
        "seed": seed,
        "warmup": warmup,
        "coordinates": coordinates.describe(),
    }
    chain, lps = np.zeros((0, total, ndim)), np.zeros((0, total))
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
        states = [
            emcee.State(chain[-1, e * per : (e + 1) * per], log_prob=lps[-1, e * per : (e + 1) * per], random_state=r)
            for e, r in enumerate(rng_states)
        ]
        log(f"resumed from {state_path} at step {chain.shape[0]}")
    else:
        states = []
        for e in range(n_ensembles):
            walkers, lp0 = initial_walkers(posterior, centre, START_INFLATION**2 * covariance, per, seed, e)
            walkers = coordinates.to_sampler(walkers)
            lp0 = lp0 + coordinates.to_theta(walkers)[1]
            random_state = np.random.RandomState(_ensemble_seed(seed, e)).get_state()
            states.append(emcee.State(walkers, log_prob=lp0, random_state=random_state))
    resumed_from = chain.shape[0]
    accepted = 0.0
    chunks = []
    result = None
    bounds = warmup_rounds(warmup)
    while chain.shape[0] < max_steps:
        done = chain.shape[0]
        in_warmup = done < warmup
        if result is None and done > warmup:  # resumed after a chunk: plan the next one as the run would have
            result = convergence(as_theta(chain)[0], posterior.names, start=warmup, n_ensembles=n_ensembles)
            if result.converged and done >= min_steps:
                break
        if in_warmup:
            n = next(b for b in bounds if b > done) - done
        else:
            n = chunk if result is None or result.converged else planned_chunk(result, done, warmup, chunk)
            if done < min_steps:  # a run lengthened to min_steps ends there exactly, converged on the way or not
                n = min(n, min_steps - done)
        n = min(n, max_steps - done)
        t0 = time.perf_counter()
        label = "warm-up" if in_warmup else "steps"
        parts, part_lps, acceptance, random_states = [], [], [], []
        for e in range(n_ensembles):
            own = chain[:, e * per : (e + 1) * per]
            sampler = emcee.EnsembleSampler(
                per, ndim, density, vectorize=True, moves=moves_for(proposal_at(own, done, warmup))
            )
            desc = f"{label} {done}-{done + n}" + (f", ensemble {e + 1}/{n_ensembles}" if n_ensembles > 1 else "")
            try:
                states[e] = sampler.run_mcmc(states[e], n, progress=progress, progress_kwargs={"desc": desc})
            except ValueError as err:  # emcee refuses walkers that span fewer than ndim dimensions
                if "condition number" not in str(err):
                    raise
                raise PeanoBayesError(
                    f"the {per} walkers of ensemble {e + 1} collapsed onto fewer than {ndim} dimensions at step "
                    f"{done}: the data do not determine all {ndim} sampled parameters "
                    f"({', '.join(posterior.names)}); fit more tests or runs, or narrow the prior"
                ) from None
            parts.append(sampler.get_chain())
            part_lps.append(sampler.get_log_prob())
            acceptance.append(sampler.acceptance_fraction)
            random_states.append(sampler.random_state)
        chain = np.concatenate([chain, np.concatenate(parts, axis=1)])
        lps = np.concatenate([lps, np.concatenate(part_lps, axis=1)])
        accepted = float(np.mean(np.concatenate(acceptance)))
        if state_path is not None:
            _save_state(state_path, chain, lps, random_states, meta)
        chunks.append(
            {"steps": chain.shape[0], "seconds": time.perf_counter() - t0, "acceptance": accepted, "warmup": in_warmup}
        )
        if in_warmup:
            log(f"warm-up step {chain.shape[0]} of {warmup}: acceptance {accepted:.2f}")
            continue
        result = convergence(as_theta(chain)[0], posterior.names, start=warmup, n_ensembles=n_ensembles)
        log(
            f"step {chain.shape[0]}: acceptance {accepted:.2f}, tau_max {np.max(result.tau):.1f}, "
            f"{result.tau_lengths:.0f} tau long, max R-hat {np.max(result.rhat):.3f} ({n_ensembles} ensembles), "
            f"min bulk ESS {np.min(result.ess_bulk):.0f}, min tail ESS {np.min(result.ess_tail):.0f}"
            + ("" if result.converged else " (not yet converged)")
        )
        if result.converged and chain.shape[0] >= min_steps:
            break
    theta_chain, log_jacobian = as_theta(chain)
    if result is None and chain.shape[0] > warmup:  # resumed at or past the limit: the saved chain as it is
        result = convergence(theta_chain, posterior.names, start=warmup, n_ensembles=n_ensembles)
    if result is None:  # the step limit came inside the warm-up: figures of its second half, never converged
        result = convergence(theta_chain, posterior.names, start=len(chain) // 2, n_ensembles=n_ensembles)
        problems = (f"the step limit ({max_steps}) ended the run inside the warm-up ({warmup} steps)",)
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
        warmup,
    )


__all__ = [
    "ADAPTED_MOVES",
    "DEFAULT_MAX_STEPS",
    "MIN_ENSEMBLES",
    "MOVES",
    "START_INFLATION",
    "WARMUP_ROUNDS",
    "IndependenceProposal",
    "TARGETS",
    "Convergence",
    "arviz_figures",
    "SampleResult",
    "convergence",
    "initial_walkers",
    "load_state",
    "moves_for",
    "pooled",
    "proposal_at",
    "sample",
    "walker_count",
    "warmup_rounds",
]
