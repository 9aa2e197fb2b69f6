"""The driver's stages from a posterior to the sampler's start: multi-start least squares (a
:class:`~peano_bayes.inference.fit.FitResult`, saved as ``fit.json``), the walkers' centre and covariance, the
posterior mode and the posterior the sampler explores.
:func:`peano_bayes.app.pipeline.infer` (``fit``, ``run``) and the validation studies run them in this order."""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..defaults import (
    DEFAULT_STARTS,
)
from ..errors import PeanoBayesInputError
from .fit import FitResult, fit
from .laplace import Laplace, NonCentred, posterior_mode, refine_mode
from .posterior import CONTRAST_PREFIX, SPECIMEN_SD, Posterior


def least_squares(posterior, prior, *, n_starts: int = DEFAULT_STARTS, seed: int = 0) -> FitResult:
    """Multi-start least squares over the model parameters ``posterior`` samples (``prior``: the full prior
    they come from), the rest held as in ``posterior``. ``fit.json`` holds its :meth:`FitResult.to_json`."""
    config = posterior.config
    model_names = [n for n in posterior.prior.names if n in config.parameter_names()]
    return fit(
        posterior.observations,
        prior.select(model_names),
        config=config,
        n_starts=n_starts,
        seed=seed,
        fixed=posterior.fixed,
    )


def with_known_mounts(dataset, config):
    """``config`` (a :class:`~peano_bayes.physics.ModelConfig`) with the mount in the model where some runs of
    ``dataset`` carry an added mount compliance (runs on a second, known mount are there to measure it);
    ``config`` itself otherwise."""
    if any(r.added_compliance > 0 for r in dataset.runs) and not config.mount:
        return dataclasses.replace(config, mount=True)
    return config


def walker_start(posterior, fitted: FitResult) -> tuple[np.ndarray, np.ndarray]:
    """Centre and covariance in theta for the walkers: the fit's point and Laplace covariance for the model
    parameters, the residual-based noise estimates, and the prior median of the pooling scale."""
    names = posterior.names
    centre = np.zeros(len(names))
    sd = np.full(len(names), 0.05)
    cov = np.diag(sd**2)
    fit_names = list(fitted.names)
    fit_cov = np.asarray(fitted.covariance)
    idx = [names.index(n) for n in fit_names]
    prior_u = posterior.prior.sample(np.random.default_rng(0), 2000)
    prior_sd = np.std(prior_u, axis=0)
    centre[: posterior.prior.ndim] = _theta_of(posterior, fitted, fitted.params)
    # The Laplace covariance, capped at the prior's spread in each direction.
    fsd = np.sqrt(np.clip(np.diag(fit_cov), 1e-12, None))
    cap = np.minimum(fsd, prior_sd[idx]) / fsd
    cov[np.ix_(idx, idx)] = fit_cov * np.outer(cap, cap)
    for i, n in enumerate(names):
        if n == SPECIMEN_SD:
            cov[i, i] = 0.3**2
        elif n.startswith(CONTRAST_PREFIX):
            cov[i, i] = 0.02**2
    return centre, cov


def _theta_of(posterior, fitted: FitResult, params: dict) -> np.ndarray:
    """The prior's part of theta at the least-squares ``params`` (name -> SI), with the fit's noise estimates and
    the prior medians for what the fit does not set."""
    point = {**posterior.prior.median(), **params, **fitted.noise_estimate}
    return np.asarray(posterior.prior.to_unconstrained(point))


def optimum_centres(posterior, fitted: FitResult, centre: np.ndarray) -> np.ndarray:
    """(k, D) theta of the other least-squares optima of ``fitted`` (:attr:`FitResult.optima`), each as
    ``centre`` with the prior's part at that optimum: where the sampler's ensembles start before it draws
    dispersed centres."""
    out = []
    for params in fitted.optima:
        theta = np.array(centre, dtype=float)
        theta[: posterior.prior.ndim] = _theta_of(posterior, fitted, {**fitted.params, **params})
        out.append(theta)
    return np.array(out).reshape(-1, len(centre))


@dataclasses.dataclass(frozen=True)
class ModeStart:
    """Where sampling starts (:func:`posterior_at_mode`).

    ``posterior``: the posterior the sampler explores: the driving inputs' error linearised at ``exact.mode``, and
    AR(1) residuals for the tests whose residuals there are correlated from bin to bin. ``exact``: the mode of the
    posterior given to :func:`posterior_at_mode`, with the driving inputs taken as exact (``mode`` (D,) theta).
    ``laplace``: the mode and covariance ((D,), (D, D) theta) of ``posterior``, on the full likelihood.
    ``lag1``: test -> lag-1 residual correlation measured at ``exact.mode`` (``posterior.residual_lag1`` holds
    what the likelihood uses, which may be bounded). ``compile_s``: wall seconds of the first batched
    evaluation, compilation included."""

    posterior: Posterior
    exact: Laplace
    laplace: Laplace
    lag1: dict[str, float]
    compile_s: float


def posterior_at_mode(
    posterior: Posterior, centre: np.ndarray, covariance: np.ndarray, *, log: Callable[[str], None] = lambda m: None
) -> ModeStart:
    """From the least-squares start (``centre`` (D,), ``covariance`` (D, D), theta: :func:`walker_start`) to the
    posterior the sampler explores and its Laplace approximation.

    BFGS first finds the mode with the driving inputs taken as exact (:func:`~peano_bayes.inference.laplace.
    posterior_mode`); the fitted inputs' error is linearised there once, and a test whose residuals there are
    correlated from bin to bin is given AR(1) residuals of that correlation; the mode is then refined on that full
    likelihood (:func:`~peano_bayes.inference.laplace.refine_mode`, in non-centred coordinates where there are
    specimen contrasts). ``posterior`` must already evaluate batches in the sampler's calls
    (``with_batch_rows``), so one compilation serves the refinement and the sampler. ``log`` receives one line per
    stage."""
    if posterior.batch_rows is None:
        raise ValueError("posterior_at_mode: give the posterior its batch size first (Posterior.with_batch_rows)")
    log("posterior mode (BFGS) from the least-squares point ...")
    exact = posterior_mode(posterior, centre, covariance)
    log(_mode_line("mode with exact inputs found in", exact))
    posterior = posterior.with_input_error_at(exact.mode)
    lag1 = posterior.residual_lag1_at(exact.mode)
    posterior = posterior.with_residual_lag1(lag1)
    _log_lags(posterior, lag1, log)
    compile_s = _first_call_seconds(posterior, centre)
    laplace = refine_mode(posterior.batched, exact, coordinates=NonCentred.of(posterior))
    log(_mode_line("mode on the full likelihood in", laplace))
    return ModeStart(posterior, exact, laplace, lag1, compile_s)


def _mode_line(what: str, laplace: Laplace) -> str:
    return f"{what} {laplace.steps} steps, {laplace.seconds:.1f} s, log posterior {laplace.log_prob:.1f}" + (
        "" if laplace.succeeded else f" ({laplace.describe()})"
    )


def _first_call_seconds(posterior: Posterior, theta: np.ndarray) -> float:
    """Wall seconds of one batched evaluation at ``theta`` (D,) repeated ``batch_rows`` times: on a fresh
    posterior, its compilation (or load from the persistent cache)."""
    t0 = time.perf_counter()
    posterior.batched(np.tile(theta, (posterior.batch_rows, 1)))
    return time.perf_counter() - t0


def _log_lags(posterior, lag1: dict, log) -> None:
    for test, rho in lag1.items():
        log(
            f"the {test} residuals at the mode are correlated from bin to bin (lag-1 {rho:.2f}): the model "
            f"misses structure in these data; they are sampled as AR(1) residuals with lag-1 "
            f"{posterior.residual_lag1[test]:.2f}, so neighbouring bins no longer count as independent evidence"
        )


def linearisation_point(path: Path, state_path: Path, posterior) -> tuple[np.ndarray, dict, tuple[bool, ...]]:
    """The point a resumed run linearised its inputs' error at, the AR(1) residual correlations it took there
    and which specimen contrasts it sampled non-centred (``input_error_point.json``; none in a file written
    before they existed); a sampler state without it, or with other parameters, was written by another
    likelihood and cannot be continued."""
    if not path.exists():
        raise PeanoBayesInputError(
            f"{state_path}: no {path.name} beside it: the state was written by an earlier version of peano-bayes, "
            "whose likelihood differs; run again without --resume"
        )
    stored = json.loads(path.read_text())
    if stored.get("names") != list(posterior.names):
        raise PeanoBayesInputError(
            f"{path}: linearised over the parameters {', '.join(stored.get('names') or [])}; this fit samples "
            f"{', '.join(posterior.names)}. Run again without --resume"
        )
    noncentred = tuple(bool(f) for f in stored.get("noncentred", ()))
    return np.asarray(stored["theta"], dtype=float), dict(stored.get("residual_lag1", {})), noncentred


__all__ = [
    "ModeStart",
    "least_squares",
    "linearisation_point",
    "optimum_centres",
    "posterior_at_mode",
    "walker_start",
    "with_known_mounts",
]
