"""The inference pipeline of one dataset, and of the bundled eight: rig file -> fit -> sample -> results.

:func:`infer` is what ``peano-bayes fit`` runs; :func:`run_bundled` is ``peano-bayes run``. Output layout
of one fit: ``OUT/<label>/posterior.nc`` (arviz), ``summary.json``, ``fit.json`` (the least-squares start) and
``figures/``; a run adds ``metrics.json`` per material and ``OUT/index.md``, ``ranking.*`` and ``figures/``.
While sampling, ``sampler_state.npz`` holds every finished chunk (kept when the chain ends unconverged);
``resume=True`` continues from it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from . import bundled
from .atomic import write_text
from .data import Dataset, load
from .defaults import (
    ALL_TESTS,
    CONTRAST_CHOICES,
    DEFAULT_CHUNK,
    DEFAULT_COORDINATES,
    DEFAULT_ENSEMBLES,
    DEFAULT_MAX_STEPS,
    DEFAULT_STARTS,
    DEFAULT_TESTS,
    DEFAULT_WARMUP,
    HDI_PROB,
)
from .errors import PeanoBayesError, PeanoBayesInputError
from .formatting import format_number
from .inference.coordinates import choose_noncentred, sampler_coordinates
from .inference.fit import fit, fit_quality, predictions, residual_correlation, sensor_noise, structured_tests
from .inference.laplace import Laplace, NonCentred, posterior_mode, refine_mode
from .inference.likelihood import Observations, prepare
from .inference.posterior import CONTRAST_PREFIX, DEFAULT_HELD, SPECIMEN_SD, Posterior, build_posterior
from .inference.priors import Prior, load_prior
from .inference.results import (
    NEW_SPECIMEN_PREFIX,
    RIDGE_CORRELATION,
    parameter_table,
    posterior_contraction,
    posterior_ridges,
    to_inference_data,
    write_netcdf,
)
from .inference.sample import sample, walker_count
from .physics.model import ModelConfig

BUNDLED_MATERIALS = bundled.MATERIALS
#: Posterior contraction below which ``index.md`` says a parameter's posterior is close to its prior.
WEAKLY_INFORMED = 0.5


def select_tests(dataset: Dataset, tests) -> Dataset:
    """``dataset`` with the runs of ``tests`` (names of :data:`ALL_TESTS`) only; an unknown name, or no run
    left, is a :class:`~peano_bayes.errors.PeanoBayesInputError` naming the file and what it holds."""
    tests = tuple(tests)
    unknown = [t for t in tests if t not in ALL_TESTS]
    if unknown:
        raise PeanoBayesInputError(f"unknown test(s) {', '.join(unknown)}; expected some of {', '.join(ALL_TESTS)}")
    runs = tuple(r for r in dataset.runs if r.test in tests)
    if not runs:
        raise PeanoBayesInputError(
            f"{dataset.source_path}: no runs of {', '.join(tests)}; the file has {', '.join(dataset.tests)}"
        )
    return dataclasses.replace(dataset, runs=runs)


def prior_of(dataset: Dataset, prior: str | Path | None):
    """The whole prior of a fit (every parameter; :meth:`~peano_bayes.inference.priors.Prior.for_config`
    selects a model's): ``prior`` (file or code) if given, else the bundled prior of the material code."""
    if prior is not None:
        as_path = Path(prior)
        return load_prior(as_path.resolve() if as_path.is_file() else prior)
    code = dataset.material.code
    try:
        return load_prior(code)
    except PeanoBayesInputError as err:
        raise PeanoBayesInputError(
            f"{dataset.source_path}: {err}. Give this dataset a prior file with --prior FILE.toml (Python: "
            f"prior=...); 'peano-bayes prior new --like TPC --out {code}.toml' writes one to edit"
        ) from None


def _default_label(dataset: Dataset) -> str:
    return Path(dataset.source_path).stem if dataset.source_path else dataset.material.code


def _check_label(label: str) -> str:
    if not label or label in (".", "..") or any(c in label for c in '/\\:*?"<>|') or label != label.strip():
        raise PeanoBayesInputError(
            f"--label {label!r}: expected a folder name (letters, digits, '-', '_', '.'; no path separators)"
        )
    return label


def least_squares(posterior, prior, *, n_starts: int = DEFAULT_STARTS, seed: int = 0) -> dict:
    """Multi-start least squares over the model parameters ``posterior`` samples (``prior``: the full prior
    they come from), the rest held as in ``posterior``; a JSON-ready dict of the result."""
    config = posterior.config
    model_names = [n for n in posterior.prior.names if n in config.parameter_names()]
    result = fit(
        posterior.observations,
        prior.select(model_names),
        config=config,
        n_starts=n_starts,
        seed=seed,
        fixed=posterior.fixed,
    )
    return {
        "names": list(result.names),
        "params": result.params,
        "covariance": result.covariance.tolist(),
        "noise_estimate": result.noise_estimate,
        "cost": result.cost,
        "n_starts": result.n_starts,
        "n_failed": result.n_failed,
        "n_step_limit": result.n_step_limit,
        "converged": result.converged,
        "rounds": result.rounds,
        "optima": list(result.optima),
        "start_costs": result.start_costs.tolist(),
        "quality": result.quality,
        "seconds": result.seconds,
    }


def least_squares_outcome(fitted: dict) -> str:
    """One phrase on how the multi-start least squares of :func:`least_squares` ended (a ``fit.json`` written
    before the rounds were recorded says nothing about the best start)."""
    rounds = fitted.get("rounds", 1)
    in_rounds = f"{rounds} round{'s' if rounds != 1 else ''}"
    converged = fitted.get("converged")
    best = (
        ""
        if converged is None
        else f"best start converged in {in_rounds}; "
        if converged
        else f"best start NOT converged after {in_rounds}; "
    )
    return (
        f"{best}of {fitted['n_starts']} starts {fitted['n_failed']} failed and {fitted.get('n_step_limit', 0)}"
        " stopped unfinished"
    )


def walker_start(posterior, fitted: dict) -> tuple[np.ndarray, np.ndarray]:
    """Centre and covariance in theta for the walkers: the fit's point and Laplace covariance for the model
    parameters, the residual-based noise estimates, and the prior median of the pooling scale."""
    names = posterior.names
    centre = np.zeros(len(names))
    sd = np.full(len(names), 0.05)
    cov = np.diag(sd**2)
    fit_names = list(fitted["names"])
    fit_cov = np.asarray(fitted["covariance"])
    idx = [names.index(n) for n in fit_names]
    prior_u = posterior.prior.sample(np.random.default_rng(0), 2000)
    prior_sd = np.std(prior_u, axis=0)
    centre[: posterior.prior.ndim] = _theta_of(posterior, fitted, fitted["params"])
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


def _theta_of(posterior, fitted: dict, params: dict) -> np.ndarray:
    """The prior's part of theta at the least-squares ``params`` (name -> SI), with the fit's noise estimates and
    the prior medians for what the fit does not set."""
    point = {**posterior.prior.median(), **params, **fitted["noise_estimate"]}
    return np.asarray(posterior.prior.to_unconstrained(point))


def optimum_centres(posterior, fitted: dict, centre: np.ndarray) -> np.ndarray:
    """(k, D) theta of the other least-squares optima of ``fitted`` (``fit.json``'s ``optima``; none in a file
    written before they were recorded), each as ``centre`` with the prior's part at that optimum: where the
    sampler's ensembles start before it draws dispersed centres."""
    out = []
    for params in fitted.get("optima", []):
        theta = np.array(centre, dtype=float)
        theta[: posterior.prior.ndim] = _theta_of(posterior, fitted, {**fitted["params"], **params})
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
        f" ({laplace.status})" if laplace.status else ""
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


def _linearisation_point(path: Path, state_path: Path, posterior) -> tuple[np.ndarray, dict, tuple[bool, ...]]:
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


#: Where in a result folder ``fit --discover`` and ``run`` write the discovery report.
DISCOVERY_FOLDER = "discovery"


def _model_choice(dataset: Dataset, config, out: Path, *, discover: bool, resume: bool, log):
    """The model a fit samples when it is known before any fit: ``config`` without ``discover``; on ``resume``
    the model of the saved fit (the discovery report's if there is one, else ``config``). ``None`` when
    discovery is still to run (:func:`_discover`, from the least squares of ``config``)."""
    from .discovery.choice import choice_from_report, configured_model

    folder = out / DISCOVERY_FOLDER
    # A resumed fit keeps the model its saved least squares and sampler state belong to, whatever the flag says.
    read_back = resume and (folder / "report.json").exists()
    resumed_without = resume and not read_back and (out / "fit.json").exists()
    if read_back:
        choice = choice_from_report(config, json.loads((folder / "report.json").read_text()), folder)
        log(f"{dataset.material.code}: discovery report read from {folder}")
        _log_choice(dataset.material.code, choice, log)
        return choice
    if resumed_without and discover:
        log(
            f"{dataset.material.code}: resuming a fit sampled without discovery; discovery not run (delete "
            f"{out} to redo it with discovery)"
        )
    return None if discover and not resumed_without else configured_model(config)


def _log_choice(code: str, choice, log) -> None:
    added = ", ".join(choice.adopted) or "nothing"
    log(f"{code}: discovery verdict {choice.verdict}; named {', '.join(choice.named) or 'none'}; added {added}")
    if choice.not_in_model:
        log(f"{code}: named but not in the inference model: {', '.join(choice.not_in_model)}")


def _discover(dataset: Dataset, config, out: Path, *, seed: int, log, start: dict):
    """Discovery on ``dataset`` from ``config``'s effects, its base fit started at ``start`` (name -> value [SI],
    the least-squares optimum of ``config`` on the same data); its report goes into ``out/discovery``. Returns
    the :class:`~peano_bayes.discovery.choice.ModelChoice`: ``config`` plus the physics effects discovery named."""
    from .discovery.choice import choose_model, effects_in

    code = dataset.material.code
    log(f"{code}: discovery from the configured model ({' + '.join(effects_in(config))}), at its least squares ...")
    # the dataset holds the fitted tests only; discovery reads its first specimen's
    say = lambda m: log(f"{code}: discovery: {m}")  # noqa: E731
    choice = choose_model(dataset, config, out / DISCOVERY_FOLDER, seed=seed, log=say, start=start)
    _log_choice(code, choice, log)
    return choice


def _discovery_seconds(choice) -> float | None:
    """How long the discovery behind ``choice`` ran [s], from its report (also when a resumed fit read the report
    back); ``None`` for a model chosen without discovery or a report that does not say."""
    report_file = None if choice.report is None else Path(choice.report) / "report.json"
    if report_file is None or not report_file.is_file():
        return None
    seconds = json.loads(report_file.read_text()).get("seconds")
    return None if seconds is None else float(seconds)


def _with_known_mounts(dataset: Dataset, config: ModelConfig) -> ModelConfig:
    """``config`` with the mount in the model where some runs carry an added mount compliance (runs on a second,
    known mount are there to measure it); ``config`` itself otherwise."""
    if any(r.added_compliance > 0 for r in dataset.runs) and not config.mount:
        return dataclasses.replace(config, mount=True)
    return config


class PosteriorPlan(NamedTuple):
    """What :func:`infer` samples for a dataset: the model (``config``, with the mount where runs carry a known
    added compliance), its ``prior``, the binned ``observations``, the ``posterior`` and the walker count."""

    config: ModelConfig
    prior: Prior
    observations: Observations
    posterior: Posterior
    n_walkers: int


def _plan_posterior(
    dataset: Dataset, whole_prior: Prior, config: ModelConfig, *, sample_all: bool, n_walkers: int | None
) -> PosteriorPlan:
    """The posterior of ``dataset`` (its tests already selected) under ``config`` and ``whole_prior``; raises
    :class:`PeanoBayesInputError` for too few walkers (:func:`walker_count`)."""
    config = _with_known_mounts(dataset, config)
    prior = whole_prior.for_config(config)
    observations = prepare(dataset)
    posterior = build_posterior(observations, prior, config=config, held=() if sample_all else DEFAULT_HELD)
    return PosteriorPlan(config, prior, observations, posterior, walker_count(n_walkers, posterior.ndim))


def infer(
    data: str | Path | Dataset,
    out_dir: str | Path,
    *,
    seed: int = 0,
    resume: bool = False,
    tests=DEFAULT_TESTS,
    n_starts: int = DEFAULT_STARTS,
    n_walkers: int | None = None,
    n_ensembles: int = DEFAULT_ENSEMBLES,
    chunk: int = DEFAULT_CHUNK,
    max_steps: int = DEFAULT_MAX_STEPS,
    warmup: int = DEFAULT_WARMUP,
    min_steps: int = 0,
    progress: bool = True,
    sample_all: bool = False,
    prior: str | Path | None = None,
    label: str | None = None,
    figures: bool = True,
    discover: bool = False,
    coordinates: str = DEFAULT_COORDINATES,
    contrasts: str = "auto",
    log=print,
) -> dict:
    """Fit, sample and write the results of one dataset into ``out_dir/<label>/``; return the summary.

    ``data``: a rig file (CSV with its TOML sidecar) or a :class:`Dataset`. ``prior``: a prior file (which may
    ``extends`` a bundled one) or a material code; default: the bundled prior of the dataset's material code.
    ``label``: the result folder's name; default: the data file's stem (``TP`` for the bundled ``TP.csv``), so
    two datasets of one material do not overwrite each other. ``figures``: also draw the data over the
    posterior predictive (and the corner plot) into ``figures/``. ``tests``: which tests to fit
    (default :data:`DEFAULT_TESTS`). The least-squares point is polished to the posterior mode, first with the
    driving inputs taken as exact (:func:`~peano_bayes.inference.laplace.posterior_mode`), then on the full
    likelihood (:func:`~peano_bayes.inference.laplace.refine_mode`); sampling runs ``warmup`` steps of warm-up, then
    chunks of at most ``chunk`` steps until converged or ``max_steps``, and at least ``min_steps`` in all (see
    :func:`~peano_bayes.inference.sample.sample`). ``resume`` continues an interrupted run.
    ``sample_all`` also samples the shape constants held by default
    (:data:`~peano_bayes.inference.posterior.DEFAULT_HELD`). ``discover``: first run discovery on the data
    from the material's configured model, write its report into ``<label>/discovery/`` and sample the
    configured model plus the physics effects it named (:func:`~peano_bayes.discovery.choice.choose_model`; a
    resumed run reads the report instead of running discovery again). ``summary.json``'s ``model`` records the
    choice either way. ``coordinates``: what the sampler moves, ``"theta"`` or ``"tensile_stretch"``
    (:func:`~peano_bayes.inference.coordinates.sampler_coordinates`). ``contrasts``: ``"auto"`` samples each
    specimen contrast the data pin little non-centred (:func:`~peano_bayes.inference.coordinates.
    choose_noncentred`), ``"centred"`` none.
    """
    if contrasts not in CONTRAST_CHOICES:
        raise PeanoBayesInputError(f"contrasts={contrasts!r}: expected one of {', '.join(CONTRAST_CHOICES)}")
    timings = {}
    dataset = load(data) if not isinstance(data, Dataset) else data
    # The sensors' noise from every run of the file, before tests are left out: the quiet tests estimate it best.
    noise = sensor_noise(dataset.runs)
    dataset = select_tests(dataset, tests)
    code = dataset.material.code
    whole_prior = prior_of(dataset, prior)
    out = Path(out_dir) / _check_label(_default_label(dataset) if label is None else label)
    choice = _model_choice(dataset, whole_prior.config, out, discover=discover, resume=resume, log=log)
    # refuses too few walkers before anything is written
    plan = _plan_posterior(
        dataset, whole_prior, whole_prior.config if choice is None else choice.config, sample_all=sample_all,
        n_walkers=n_walkers,
    )  # fmt: skip
    fit_path, state_path = out / "fit.json", out / "sampler_state.npz"
    linearised_path = out / "input_error_point.json"
    fitted = None
    if resume and fit_path.exists():
        fitted = json.loads(fit_path.read_text())
        timings["least_squares_s"] = fitted["seconds"]
        log(f"{code}: least squares loaded from {fit_path}")
    else:
        for stale in (fit_path, state_path, linearised_path):
            stale.unlink(missing_ok=True)

    def fit_plan(plan: PosteriorPlan) -> dict:
        log(f"{code}: least squares from up to {n_starts} starts ...")
        fitted = least_squares(plan.posterior, plan.prior, n_starts=n_starts, seed=seed)
        timings["least_squares_s"] = timings.get("least_squares_s", 0.0) + fitted["seconds"]
        log(f"{code}: least squares done in {fitted['seconds']:.1f} s ({least_squares_outcome(fitted)})")
        return fitted

    if choice is None:  # discovery starts from the configured model's least squares: one fit serves both
        fitted = fit_plan(plan)
        choice = _discover(dataset, whole_prior.config, out, seed=seed, log=log, start=fitted["params"])
        if choice.adopted:  # a larger model: its own least squares
            plan = _plan_posterior(dataset, whole_prior, choice.config, sample_all=sample_all, n_walkers=n_walkers)
            fitted = None
    seconds = _discovery_seconds(choice)
    if seconds is not None:
        timings["discovery_s"] = seconds
    if plan.config != choice.config:
        log(f"{code}: some runs carry an added mount compliance, so the model includes the mount")
        choice = dataclasses.replace(choice, config=plan.config)
    config, prior, observations, posterior, n_walkers = plan
    out.mkdir(parents=True, exist_ok=True)
    log(
        f"{code}: {observations.n_bins} bins from {len(dataset.runs)} runs ({', '.join(dataset.tests)}); "
        f"{posterior.ndim} parameters sampled"
    )
    if fitted is None:
        fitted = fit_plan(plan)
    if not (resume and fit_path.exists()):
        write_text(fit_path, json.dumps(fitted, indent=1))

    centre, covariance = walker_start(posterior, fitted)
    # Every batch in calls of half an ensemble (what emcee's red-blue moves evaluate): one compilation, which
    # also serves the mode's refinement on the full likelihood.
    rows = max(1, n_walkers // 2)
    posterior = posterior.with_batch_rows(rows)
    start = None
    if resume and state_path.exists():  # a resumed run restores its walkers and needs no start
        # It reads back where its inputs' error was linearised and its AR(1) lags, so it samples the same posterior.
        point, lag1, noncentred = _linearisation_point(linearised_path, state_path, posterior)
        posterior = posterior.with_input_error_at(point).with_residual_lag1(lag1)
        _log_lags(posterior, lag1, lambda m: log(f"{code}: {m}"))
        timings["compile_s"] = _first_call_seconds(posterior, centre)
    else:
        start = posterior_at_mode(posterior, centre, covariance, log=lambda m: log(f"{code}: {m}"))
        posterior, centre, covariance = start.posterior, start.laplace.mode, start.laplace.covariance
        noncentred = choose_noncentred(posterior, centre, covariance) if contrasts == "auto" else ()
        record = {
            "names": list(posterior.names),
            "theta": start.exact.mode.tolist(),
            "residual_lag1": start.lag1,
            "noncentred": list(noncentred),
        }
        write_text(linearised_path, json.dumps(record))
        timings["compile_s"] = start.compile_s
        timings["mode_s"] = start.exact.seconds + start.laplace.seconds
    if any(noncentred):
        which = [n for n, f in zip(posterior.contrast_names, noncentred, strict=True) if f]
        log(f"{code}: {len(which)} of {len(noncentred)} specimen contrasts sampled non-centred ({', '.join(which)})")
    sampler = sampler_coordinates(posterior, coordinates, noncentred)
    optima = optimum_centres(posterior, fitted, centre)
    if len(optima):
        log(f"{code}: {len(optima)} other least-squares optim{'a' if len(optima) > 1 else 'um'}: ensembles start there")
    result = sample(
        posterior,
        centre,
        covariance,
        optima=optima,
        n_walkers=n_walkers,
        n_ensembles=n_ensembles,
        seed=seed,
        chunk=chunk,
        max_steps=max_steps,
        warmup=warmup,
        min_steps=min_steps,
        state_path=state_path,
        resume=resume,
        progress=progress,
        log=lambda m: log(f"{code}: {m}"),
        coordinates=sampler,
    )
    timings["sampling_s"] = result.seconds
    conv = result.convergence
    if not conv.converged:
        log(f"{code}: WARNING: NOT CONVERGED after {result.chain.shape[0]} steps: {'; '.join(conv.problems)}")
    idata = to_inference_data(
        posterior,
        result,
        seed=seed,
        attrs={
            "material": code,
            "dataset": str(dataset.source_path),
            "prior": str(prior.label),
            "conditions": json.dumps(dataclasses.asdict(dataset.conditions)),
        },
    )
    # Fit quality at the posterior mean in theta (unconstrained) space, specimen offsets included, and how far
    # its residuals are above the sensor noise (estimated from the raw signals, no model involved).
    theta_mean = result.kept().reshape(-1, posterior.ndim).mean(axis=0)
    params_mean = posterior.params(theta_mean)
    predicted = predictions(params_mean, posterior.observations, config)
    quality = fit_quality(params_mean, observations, config, predicted, noise=noise)
    # Whether each test's misfit is noise: the likelihood's intervals hold only if it is.
    correlation = residual_correlation(params_mean, posterior.observations, config, predicted)
    for test, c in correlation.items():
        c["likelihood_lag1"] = posterior.residual_lag1.get(test)
        if not c["consistent_with_noise"]:
            log(
                f"{code}: WARNING: the {test} residuals at the posterior mean are correlated from bin to bin "
                f"(lag-1 {c['lag1']:.2f}): the model misses structure in these data"
                + (
                    f"; the likelihood took them as AR(1) residuals (lag-1 {c['likelihood_lag1']:.2f})"
                    if c["likelihood_lag1"] is not None
                    else f", and the intervals it informs are too narrow (roughly {c['interval_factor']:.1f}x, as "
                    "for AR(1) residuals)"
                )
                + ("" if conv.converged else "; the run has not converged, so its mean may not be a fit yet")
                + "; 'peano-bayes metrics' adds its misfit beyond the sensor noise to the metrics read off it"
            )
    summary = {
        "material": code,
        "label": out.name,
        "dataset": str(dataset.source_path),
        "prior": str(prior.label),
        "tests": list(dataset.tests),
        # the report's folder relative to the result folder, so a result moved or published keeps its reference
        "model": dataclasses.replace(choice, report=None if choice.report is None else DISCOVERY_FOLDER).as_dict(),
        "seed": seed,
        "n_walkers": n_walkers,
        "warmup": result.warmup,
        "warmup_stable": result.warmup_stable,
        "warmup_changes": result.warmup_changes,
        "checks": [{"steps": int(a), "tau_max": float(b)} for a, b in result.checks],
        "n_ensembles": result.n_ensembles,
        "steps": int(result.chain.shape[0]),
        "resumed_from_step": result.resumed_from,
        "acceptance": result.acceptance,
        "sampler_coordinates": sampler.describe(),
        "convergence": conv.as_dict(posterior.names),
        "min_ess_per_s": float(np.min(conv.ess_bulk) / max(result.seconds, 1e-9)),
        "parameters": parameter_table(idata, posterior.names, HDI_PROB),
        "hierarchy": {
            "specimens": list(observations.specimens),
            "varying": list(posterior.varying),
            "spread": SPECIMEN_SD if posterior.varying else None,
            "levels": "parameters: population values; new_specimen: a specimen not yet made",
        },
        "new_specimen": {
            name: row
            for name, row in zip(
                posterior.varying,
                parameter_table(idata, [NEW_SPECIMEN_PREFIX + n for n in posterior.varying], HDI_PROB).values(),
                strict=True,
            )
        }
        if posterior.varying
        else {},
        "contraction": posterior_contraction(idata, posterior.prior.names),
        "ridges": posterior_ridges(idata, posterior.prior.names),
        "units": posterior.units,
        "fixed": posterior.fixed,
        "fit_quality_least_squares": fitted["quality"],
        "fit_quality_posterior_mean": quality,
        "residual_correlation": correlation,
        "least_squares": {
            k: fitted.get(k) for k in ("cost", "n_starts", "n_failed", "n_step_limit", "converged", "rounds", "params")
        },
        "posterior_mode": None
        if start is None
        else {
            "log_prob": start.laplace.log_prob,
            "steps": start.laplace.steps,
            "status": start.laplace.status or "successful",
            "exact_inputs": {
                "log_prob": start.exact.log_prob,
                "steps": start.exact.steps,
                "status": start.exact.status or "successful",
            },
        },
        "timings_s": timings,
    }
    write_netcdf(idata, out / "posterior.nc")
    write_text(out / "summary.json", json.dumps(summary, indent=1, default=float))
    if result.convergence.converged:
        state_path.unlink(missing_ok=True)
    else:  # kept: a resumed run with a larger step limit continues the same chain
        log(f"{code}: sampler state kept in {state_path}: --resume with a larger --max-steps continues it")
    log(f"{code}: wrote {out / 'posterior.nc'} and summary.json")
    if figures:
        from .figures import material_figures

        material_figures(out, dataset)
        log(f"{code}: figures in {out / 'figures'}")
    return summary


def ridge_lines(ridges: list[dict]) -> list[str]:
    """``index.md`` lines naming each ridge of :func:`~peano_bayes.inference.results.posterior_ridges`: the
    pair, its correlation, and the combination the data determine against each parameter alone."""
    if not ridges:
        return []
    lines = [
        "",
        f"**Ridges** (posterior correlation beyond {RIDGE_CORRELATION:g}): the tests determine a combination of "
        "each pair better than either alone; read their intervals together.",
        "",
    ]
    for r in ridges:
        spread = lambda sd, log: f"±{100 * sd:.2g} %" if log else f"±{sd:.2g}"  # noqa: E731
        if r["log_a"] and r["log_b"]:
            combination = f"{r['a']} × {r['b']}^{r['exponent']:.2f}"
        else:  # a signed parameter: the combination in the sampler's scale (logs of the positive ones)
            combination = f"{r['a']} {'+' if r['exponent'] >= 0 else '-'} {abs(r['exponent']):.2f} {r['b']}"
        lines.append(
            f"- {r['a']} and {r['b']}: correlation {r['correlation']:+.2f}; {combination} is determined to "
            f"{spread(r['sd_combination'], r['log_a'] and r['log_b'])} (1 sd), each alone to "
            f"{spread(r['sd_a'], r['log_a'])} and {spread(r['sd_b'], r['log_b'])}."
        )
    return lines


def model_table(summaries: list[dict]) -> list[str]:
    """Markdown lines: per material, the effects of the sampled model beside what discovery named (a fit
    without discovery says so), and what discovery left unexplained."""
    lines = [
        "## Models sampled",
        "",
        "| material | effects sampled | discovery verdict | discovery named | added by discovery | not in the "
        "inference model |",
        "|---|---|---|---|---|---|",
    ]
    notes = []
    for s in summaries:
        model = s.get("model")
        if model is None:  # a summary written before the model was recorded
            lines.append(f"| {s['material']} | (not recorded) | | | | |")
            continue
        found = model["discovery"]
        sampled = ", ".join(model["effects"])
        if found is None:
            lines.append(f"| {s['material']} | {sampled} | not run (the configured model) | | | |")
            continue
        lines.append(
            f"| {s['material']} | {sampled} | {found['verdict']} | {', '.join(found['named']) or 'none'} | "
            f"{', '.join(found['adopted']) or 'nothing'} | {', '.join(found['not_in_model'])} |"
        )
        if found["unexplained"]:
            report = Path(found["report"] or DISCOVERY_FOLDER)
            if not report.is_absolute():  # relative to the result folder, which index.md names by its label
                report = Path(s.get("label", s["material"])) / report
            notes.append(
                f"**{s['material']}**: discovery left structure it could not name; see its report "
                f"(`{report.as_posix()}/report.md`). The sampled model does not explain all of the data."
            )
    return [*lines, "", *(f"{n}\n" for n in notes)]


def shown_dataset_path(path: str) -> str:
    """A dataset path as a reader of ``index.md`` can use it: a bundled file by its place in the package
    (``peano_bayes/bundled/data/TP.csv``), not the absolute path of the machine that ran the job, also when
    the job ran from another copy of the package (a clone elsewhere, an installed wheel)."""
    parts = Path(path).parts
    for i in range(len(parts) - 3, -1, -1):
        if parts[i : i + 3] == ("peano_bayes", "bundled", "data"):
            return str(Path(*parts[i:]))
    return path


#: A material's figures that ``index.md`` links where they exist, in order: file stem -> what it shows.
MATERIAL_FIGURES = {
    "predictive": "data over the predictive band",
    "response": "force-strain loops per pressure, blocking force and stroke against pressure, with residuals",
    "step": "step response against the model",
    "corner": "corner plot",
    "trace": "trace plot per ensemble",
    "rank": "rank plot per ensemble",
}


def _finite(x) -> bool:
    return x is not None and math.isfinite(x)


def _with_unit(x, unit: str) -> str:
    """``x`` to three significant digits with its unit; empty where ``x`` is missing or not finite."""
    return f"{format_number(x)} {unit}" if _finite(x) else ""


def _sampler_run(summary: dict) -> str:
    """`` (W warm-up, tau_max T steps, first D discarded)`` for one material's index line: the sampler's warm-up,
    the largest integrated autocorrelation time (so a reader sees how hard the posterior was to sample) and the
    burn-in D counted from the chain's first step (the warm-up and a further ``2 tau_max``); parts a summary
    written before they were recorded lacks are left out."""
    conv = summary["convergence"]
    parts = []
    if summary.get("warmup") is not None:
        parts.append(f"{summary['warmup']} warm-up")
    taus = [t for t in conv.get("tau_steps", {}).values() if _finite(t)]
    if taus:
        parts.append(f"tau_max {max(taus):.1f} steps")
    if conv.get("discard_steps") is not None:
        parts.append(f"first {conv['discard_steps']} discarded")
    return f" ({', '.join(parts)})" if parts else ""


def index_markdown(
    summaries: list[dict],
    metrics: dict | None = None,
    ranking: dict | None = None,
    references: dict | None = None,
    figures: dict | None = None,
) -> str:
    """``results/index.md``: per material, a parameter table with 94 % intervals, fit quality, convergence,
    (given ``references``: code -> reference_models.json) the load-cycle fit against the paper's reference
    models, and (given ``metrics``: code -> metrics.json) the Table 3 metrics against the paper with links to
    the figures (``figures``: code -> names of :data:`MATERIAL_FIGURES` that exist; default: predictive and
    corner); then (given ``ranking``, :func:`~peano_bayes.ranking.rank_materials`) the cross-material
    ranking."""
    from .metrics import metrics_markdown
    from .ranking import ranking_markdown

    metrics = metrics or {}
    lines = ["# peano_bayes results", "", "Posterior means with 94 % highest-density intervals (SI units).", ""]
    lines += model_table(summaries)
    for s in summaries:
        conv = s["convergence"]
        verdict = "converged" if conv["converged"] else "**NOT CONVERGED**: " + "; ".join(conv["problems"])
        lines += [
            f"## {s['material']}",
            "",
            f"Data: `{shown_dataset_path(s['dataset'])}` ({', '.join(s['tests'])}); "
            f"{s.get('n_ensembles', 1)} ensembles of {s['n_walkers']} walkers x {s['steps']} steps"
            f"{_sampler_run(s)}; {verdict}. Max R-hat {max(conv['rhat'].values()):.3f}, "
            f"min bulk ESS {min(conv['ess_bulk'].values()):.0f}, "
            f"chain {conv['tau_lengths']:.0f} autocorrelation times long.",
            "",
            "Population values (the material), a new specimen's value (what one more muscle made of it would "
            "have: the population plus the between-specimen spread), and the posterior contraction "
            "(1 - posterior variance / prior variance, in the sampler's unconstrained space: near 0 means the data "
            "said little and the interval is the prior's).",
            "",
            "| parameter | unit | population mean | population 94 % | new specimen 94 % | contraction | R-hat | "
            "bulk ESS |",
            "|---|---|---|---|---|---|---|---|",
        ]

        def interval(row):
            low, high = (format_number(row[k], nonfinite=None) for k in ("hdi_low", "hdi_high"))
            return f"{low} to {high}"

        weak = []
        for name, row in s["parameters"].items():
            new = s.get("new_specimen", {}).get(name)
            contraction = s.get("contraction", {}).get(name)
            if contraction is not None and contraction < WEAKLY_INFORMED:
                weak.append(name)
            lines.append(
                f"| {name} | {s['units'].get(name, '')} | {format_number(row['mean'], nonfinite=None)} | "
                f"{interval(row)} | {interval(new) if new else ''} | "
                f"{'' if contraction is None else f'{contraction:.2f}'} | "
                f"{conv['rhat'][name]:.3f} | {conv['ess_bulk'][name]:.0f} |"
            )
        if weak:
            lines += [
                "",
                f"**Posterior close to its prior** (contraction below {WEAKLY_INFORMED:g}): {', '.join(weak)}. "
                "The fitted tests say little about these; their intervals are mostly the prior's.",
            ]
        lines += ridge_lines(s.get("ridges", []))
        correlation = s.get("residual_correlation", {})
        lines += [
            "",
            "| test | RMSE | max error | R² | RMSE beyond the sensor noise | residual lag-1 correlation |",
            "|---|---|---|---|---|---|",
        ]
        for test, q in s["fit_quality_posterior_mean"].items():
            c = correlation.get(test)
            lag = "" if c is None or c["lag1"] is None else f"{c['lag1']:.2f}"
            used = None if c is None else c.get("likelihood_lag1")
            if c is not None and not c["consistent_with_noise"]:
                lag += " (structured)" if used is None else f" (structured; sampled as AR(1), lag-1 {used:.2f})"
            elif used is not None:
                lag += f" (sampled as AR(1), lag-1 {used:.2f}: structured at the mode)"
            lines.append(
                f"| {test} | {format_number(q['rmse'], nonfinite=None)} {q['unit']} | "
                f"{format_number(q['max_error'], nonfinite=None)} {q['unit']} | {q['r2']:.4f} | "
                f"{_with_unit(q.get('excess_rmse'), q['unit'])} | {lag} |"
            )
        adopted = [t for t, c in correlation.items() if c.get("likelihood_lag1") is not None]
        structured = structured_tests(correlation)
        unadopted = [t for t in structured if t not in adopted]
        if structured:
            lines += [
                "",
                f"**Misfit with structure** in {', '.join(structured)}: the whitened residuals are correlated "
                "from bin to bin, so the model misses something these data show. "
                + (
                    f"The likelihood took the residuals of {', '.join(adopted)} as AR(1) from bin to bin, with "
                    "the correlation found at the posterior mode, so neighbouring bins do not count as independent "
                    "evidence; the values are those of the closest model in the family, not of a model that "
                    "explains the data. "
                    if adopted
                    else ""
                )
                + (
                    f"The intervals that {', '.join(unadopted)} inform are narrower than the data justify "
                    "(`residual_correlation` in `summary.json` gives a rough factor, as for AR(1) residuals). "
                    if unadopted
                    else ""
                )
                + (
                    "A quantity read off one of these tests can be off the model's prediction by roughly that "
                    "test's RMSE beyond the sensor noise: the parameter intervals above do not include it; the "
                    "Table 3 metrics below do where a metric is read off such a test (their *model misfit* "
                    "column; *Model discrepancy* in the project's docs/inference.md). "
                    if any(_finite(s["fit_quality_posterior_mean"].get(t, {}).get("excess_rmse")) for t in structured)
                    else ""
                )
                + "Try `--discover`.",
            ]
        reference = (references or {}).get(s["material"])
        ours = s["fit_quality_posterior_mean"].get("load_cycle")
        if reference and ours:
            lines += [
                "",
                "Load cycles against the paper's reference models fitted to the same bins "
                "(`inference/reference_fit.py`):",
                "",
                "| model | RMSE | max error | R² |",
                "|---|---|---|---|",
                f"| peano_bayes (posterior mean) | {format_number(ours['rmse'], nonfinite=None)} N | "
                f"{format_number(ours['max_error'], nonfinite=None)} N | {ours['r2']:.4f} |",
            ]
            for name, label in (("sarosi", "Sarosi static, 12 coefficients"), ("veale", "Veale force balance")):
                q = reference[name]["quality"]
                lines.append(
                    f"| {label} | {format_number(q['rmse'], nonfinite=None)} N | "
                    f"{format_number(q['max_error'], nonfinite=None)} N | {q['r2']:.4f} |"
                )
        t = s["timings_s"]
        lines += [
            "",
            "Timings: "
            + (f"discovery {t['discovery_s']:.1f} s, " if "discovery_s" in t else "")
            + f"least squares {t['least_squares_s']:.1f} s, posterior mode {t.get('mode_s', 0.0):.1f} s, "
            f"compile {t['compile_s']:.1f} s, sampling {t['sampling_s']:.1f} s.",
            "",
        ]
        m = metrics.get(s["material"])
        if m:
            code = s["material"]
            lines += [
                f"Table 3 metrics: posterior predictive median and 94 % HDI over {m['n_draws']} draws "
                f"({m['n_failed']} failed to simulate), beside the paper's values:",
                "",
                metrics_markdown(code, m["summary"], m["published"]),
                "",
                "Figures: "
                + ", ".join(
                    f"[{what}]({code}/figures/{name}.png)"
                    for name, what in MATERIAL_FIGURES.items()
                    if name in (figures or {}).get(code, ("predictive", "corner"))
                )
                + ".",
                "",
            ]
    if ranking and ranking.get("criteria"):
        unconverged = [s["material"] for s in summaries if not s["convergence"]["converged"]]
        lines += ["## Ranking across materials", ""]
        if unconverged:
            lines += [
                f"**Provisional for {', '.join(unconverged)}:** chains not converged (see above), so the "
                "probabilities involving them rest on an unconverged posterior.",
                "",
            ]
        lines += [
            "Figures: [parameters across materials](figures/forest.png), "
            "[metrics against the paper](figures/published.png), [P(best) per criterion](figures/ranking.png).",
            "",
            ranking_markdown(ranking),
            "",
        ]
    return "\n".join(lines)


def reference_models(directory: Path, summary: dict, *, log=print) -> dict | None:
    """``directory/reference_models.json``: the paper's reference models fitted to the load cycles of the
    result's dataset (:func:`~peano_bayes.inference.reference_fit.reference_comparison`), made if missing;
    ``None`` when the dataset has no load cycles or is no longer where the summary says."""
    from .inference.reference_fit import reference_comparison

    path = directory / "reference_models.json"
    if path.exists():
        return json.loads(path.read_text())
    source = Path(summary["dataset"])
    if "load_cycle" not in summary["tests"] or not source.exists():
        return None
    log(f"{summary['material']}: fitting the reference models to the load cycles ...")
    comparison = reference_comparison(prepare(select_tests(load(source), ["load_cycle"])))
    write_text(path, json.dumps(comparison, indent=1))
    return comparison


def material_report(
    directory: Path, summary: dict, *, n_draws: int = 100, log=print
) -> tuple[dict | None, dict | None]:
    """One finished material's part of the report, each piece computed only where it is missing: the reference
    models' fit (:func:`reference_models`), ``metrics.json`` (:func:`~peano_bayes.metrics.evaluate_result`, kept
    if written by this version) and ``figures/``. Returns ``(reference models, metrics)``, ``None`` for what
    could not be had. The main job's workers run it as soon as their material is sampled, so the parent's
    report only reads it back."""
    from .figures import material_figures
    from .metrics import evaluate_result, metrics_current, read_metrics

    code = summary["material"]
    references = reference_models(directory, summary, log=log)
    current = metrics_current(directory)
    if not current:
        log(f"{code}: Table 3 metrics from {n_draws} posterior draws ...")
        try:
            evaluate_result(directory, n_draws=n_draws, progress=False)
            current = True
        except PeanoBayesError as err:  # one material's metrics must not stop the others' report
            log(f"{code}: no Table 3 metrics: {err}")
    if not (directory / "figures" / "corner.png").exists():
        source = Path(summary["dataset"])
        material_figures(directory, load(source) if source.exists() else None)
        log(f"{code}: figures in {directory / 'figures'}")
    return references, read_metrics(directory) if current else None


#: Posterior draws the main job's metrics, ranking and recommendation read.
REPORT_DRAWS = 100


def report_results(out_dir: str | Path, materials=BUNDLED_MATERIALS, *, n_draws: int = REPORT_DRAWS, log=print) -> dict:
    """Metrics, figures, ranking and ``index.md`` for the finished materials of ``out_dir``.

    Per material with a ``summary.json``: ``metrics.json`` (:func:`~peano_bayes.metrics.evaluate_result`, kept
    if written by this version: :func:`~peano_bayes.metrics.metrics_current`) and ``figures/``; across them:
    ``ranking.json``/``ranking.md``, ``figures/`` and ``index.md``.
    Returns the ranking (:func:`~peano_bayes.ranking.rank_materials`)."""
    from .figures import cross_material_figures
    from .inference.results import load_result
    from .ranking import failed_draw_counts, rank_materials, ranking_markdown

    out_dir = Path(out_dir)
    finished = [c for c in materials if (out_dir / c / "summary.json").exists()]
    summaries, metrics, results, references = [], {}, {}, {}
    for code in finished:
        directory = out_dir / code
        summaries.append(json.loads((directory / "summary.json").read_text()))
        references[code], material_metrics = material_report(directory, summaries[-1], n_draws=n_draws, log=log)
        if material_metrics is not None:
            metrics[code] = material_metrics
        results[code] = load_result(directory)
    prior_only = {name for m in metrics.values() for name, s in m["summary"].items() if s["from_prior"]}
    pressures = {c: m.get("test_pressure_kpa") for c, m in metrics.items()}
    draws, failed = {c: m["draws"] for c, m in metrics.items()}, failed_draw_counts(metrics)
    ranking = (
        rank_materials(draws, from_prior=prior_only, test_pressure_kpa=pressures, failed_draws=failed)
        if metrics
        else None
    )
    if ranking:
        write_text(out_dir / "ranking.json", json.dumps(ranking, indent=1))
        write_text(out_dir / "ranking.md", "# Ranking\n\n" + ranking_markdown(ranking) + "\n")
        cross_material_figures(out_dir, results, metrics, ranking)
    figures = {c: [n for n in MATERIAL_FIGURES if (out_dir / c / "figures" / f"{n}.png").exists()] for c in finished}
    write_text(out_dir / "index.md", index_markdown(summaries, metrics, ranking, references, figures))
    log(f"wrote {out_dir / 'index.md'}")
    return ranking or {}


def _infer_unit(source: str, out_dir: str, label: str, kwargs: dict, report_draws: int | None = None) -> dict:
    """One dataset of a fan-out (:func:`run_bundled`, :func:`fit_many`): :func:`infer` into ``out_dir/label``,
    resumed from its sampler state if one is there (a unit re-run after its worker was lost continues from its
    last saved chunk); with ``report_draws``, then its part of the report from that many draws
    (:func:`material_report`), in the worker. Top level, so a worker process can import it."""
    resume = (Path(out_dir) / label / "sampler_state.npz").exists()
    summary = infer(source, out_dir, label=label, resume=resume, **kwargs)
    if report_draws is not None:
        material_report(Path(out_dir) / label, summary, n_draws=report_draws, log=kwargs.get("log", print))
    return summary


def _can_continue(summary: dict, directory: Path, max_steps: int) -> bool:
    """Whether a finished material's chain is worth resuming: unconverged, its sampler state kept, and
    ``max_steps`` beyond the steps it ran."""
    unconverged = not summary["convergence"]["converged"]
    return unconverged and summary.get("steps", 0) < max_steps and (directory / "sampler_state.npz").exists()


class RunLog:
    """A log function that prints each message (through ``echo``, default :func:`print`) and appends it, with
    the UTC time, to ``path`` (``results/run.log``). Picklable, so worker processes append to the same file
    (one short write per line, opened in append mode)."""

    def __init__(self, path: str | Path, echo=print):
        self.path = str(path)
        self.echo = echo

    def __call__(self, message: str) -> None:
        if self.echo is not None:
            self.echo(message)
        stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(f"{stamp} {message}\n")


def _infer_all(
    items: list[tuple[str, str]],
    out_dir: Path,
    *,
    jobs: int,
    scheduler: str | None,
    log,
    kwargs: dict,
    report_draws: int | None = None,
) -> list[dict]:
    """:func:`infer` on each ``(label, data file)`` of ``items`` into ``out_dir/label`` as work units of
    :func:`~peano_bayes.fanout.run_units`, and the summaries in the order of ``items``. A label whose
    ``summary.json`` exists is not redone unless its chain can continue (:func:`_can_continue`). Writes
    ``out_dir/provenance.json``; raises after the others finished if any unit failed."""
    from .fanout import Unit, make_executor, provenance, raise_failures, run_units

    max_steps = kwargs.get("max_steps", DEFAULT_MAX_STEPS)
    summaries: dict[str, dict] = {}
    todo = []
    for label, source in items:
        done = out_dir / label / "summary.json"
        if done.exists():
            summary = json.loads(done.read_text())
            if not _can_continue(summary, out_dir / label, max_steps):
                without = kwargs.get("discover") and (summary.get("model") or {}).get("discovery") is None
                note = " (it was sampled without discovery: delete it to redo it with discovery)" if without else ""
                log(f"{label}: {done} exists, skipped{note}")
                summaries[label] = summary
                continue
            log(f"{label}: not converged at {summary['steps']} steps; resuming with a larger step limit")
        todo.append((label, source))

    def finished(outcome):
        if outcome.ok:
            summaries[outcome.key] = outcome.value
            write_text(out_dir / "index.md", index_markdown([summaries[k] for k, _ in items if k in summaries]))

    # No worker for one unit or none (unless a Dask scheduler is named): it runs here, with progress bars.
    with make_executor(scheduler if todo else "", jobs if len(todo) > 1 else 1) as (executor, info):
        unit_kwargs = {**kwargs, "log": log}
        if executor is not None:
            unit_kwargs.update(progress=False, log=RunLog(out_dir / "run.log"))
            log(f"running {len(todo)} dataset(s) on {info.describe()}")
        units = [
            Unit(label, _infer_unit, (str(source), str(out_dir), label, unit_kwargs, report_draws))
            for label, source in todo
        ]
        outcomes = run_units(
            units,
            executor,
            on_result=finished,
            log=None if executor is None else log,
            log_dir=None if executor is None else out_dir / "logs",
        )
    record = provenance(info, outcomes, seed=kwargs.get("seed", 0), labels=[k for k, _ in items])
    earlier = out_dir / "provenance.json"  # units of earlier invocations stay on record
    if earlier.exists():
        record["units"] = {**json.loads(earlier.read_text()).get("units", {}), **record["units"]}
    write_text(earlier, json.dumps(record, indent=1))
    raise_failures(outcomes, "dataset")
    return [summaries[k] for k, _ in items if k in summaries]


def run_bundled(
    out_dir: str | Path = "results",
    *,
    materials=BUNDLED_MATERIALS,
    jobs: int = 1,
    scheduler: str | None = None,
    log=print,
    **kwargs,
) -> list[dict]:
    """The main job: :func:`infer` on every bundled dataset, then metrics, figures, ranking and
    ``out_dir/index.md`` (:func:`report_results`). Every log line also goes, timestamped, to
    ``out_dir/run.log`` (:class:`RunLog`), from worker processes too.

    A material whose ``summary.json`` exists is not redone (delete it to redo), unless its chain is unconverged,
    its sampler state was kept and ``max_steps`` now allows more steps: then, like a run that was interrupted,
    it resumes. The materials are work units of :func:`~peano_bayes.fanout.run_units`: ``jobs`` at once in local
    worker processes, or on the Dask cluster of ``scheduler`` (see :func:`~peano_bayes.fanout.make_executor`),
    with per-chunk log lines instead of progress bars when not run here; each unit's output is kept in
    ``out_dir/logs/<material>.log`` and the run's provenance (executor, package versions, seed, which worker ran
    what) in ``out_dir/provenance.json``. ``kwargs`` go to :func:`infer`.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = RunLog(out_dir / "run.log", log)
    items = [(code, str(bundled.dataset_path(code))) for code in materials]
    ordered = _infer_all(
        items, out_dir, jobs=jobs, scheduler=scheduler, log=log, kwargs=kwargs, report_draws=REPORT_DRAWS
    )
    report_results(out_dir, materials, n_draws=REPORT_DRAWS, log=log)
    return ordered


def _check_inputs(dataset: Dataset, kwargs: dict) -> None:
    """Raise :class:`PeanoBayesInputError` where :func:`infer` with ``kwargs`` would refuse ``dataset``'s
    tests, prior or walker count (with the configured model; a model that discovery enlarges is checked again
    by :func:`infer`)."""
    selected = select_tests(dataset, kwargs.get("tests", DEFAULT_TESTS))
    whole_prior = prior_of(selected, kwargs.get("prior"))
    if kwargs.get("n_walkers") is not None:
        sample_all = bool(kwargs.get("sample_all"))
        _plan_posterior(selected, whole_prior, whole_prior.config, sample_all=sample_all, n_walkers=kwargs["n_walkers"])


def fit_many(
    data_paths, out_dir: str | Path, *, jobs: int = 1, scheduler: str | None = None, log=print, **kwargs
) -> list[dict]:
    """:func:`infer` on each rig dataset of ``data_paths`` into ``out_dir/<file stem>/`` (stems must differ), as
    work units like :func:`run_bundled`'s (``jobs`` local processes or a Dask ``scheduler``; resumable; finished
    ones skipped; ``out_dir/run.log``, ``out_dir/logs/``, ``out_dir/provenance.json``), then
    ``out_dir/index.md`` over them. Every file is read and checked before any unit starts. ``kwargs`` go to
    :func:`infer`. Returns the summaries in the order given."""
    paths = [Path(p) for p in data_paths]
    if not paths:
        raise PeanoBayesInputError("fit-many needs at least one data file")
    labels = [_check_label(p.stem) for p in paths]
    repeated = sorted({k for k in labels if labels.count(k) > 1})
    if repeated:
        raise PeanoBayesInputError(
            f"data files must have distinct names (each names its result folder); repeated: {', '.join(repeated)}"
        )
    for path in paths:  # a bad file, prior, test choice or walker count is refused before anything is written
        _check_inputs(load(path), kwargs)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = RunLog(out_dir / "run.log", log)
    items = [(label, str(path)) for label, path in zip(labels, paths, strict=True)]
    summaries = _infer_all(items, out_dir, jobs=jobs, scheduler=scheduler, log=log, kwargs=kwargs)
    write_text(out_dir / "index.md", index_markdown(summaries))
    log(f"wrote {out_dir / 'index.md'}")
    return summaries


__all__ = [
    "ModeStart",
    "RunLog",
    "shown_dataset_path",
    "ALL_TESTS",
    "BUNDLED_MATERIALS",
    "DEFAULT_MAX_STEPS",
    "DEFAULT_TESTS",
    "fit_many",
    "index_markdown",
    "infer",
    "least_squares",
    "posterior_at_mode",
    "prior_of",
    "reference_models",
    "report_results",
    "run_bundled",
    "select_tests",
    "walker_start",
]
