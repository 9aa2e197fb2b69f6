"""The inference pipeline of one dataset: rig file -> model choice -> least squares -> mode -> sample -> results.

:func:`infer` is what ``peano-bayes fit`` runs; many datasets (``run``, ``fit-many``) are :mod:`~.batch`'s.
Output layout of one fit: ``OUT/<label>/posterior.nc`` (arviz), ``summary.json``, ``fit.json`` (the
least-squares start) and ``figures/``; a run adds ``metrics.json`` per material and ``OUT/index.md``,
``ranking.*`` and ``figures/``.
While sampling, ``sampler_state.npz`` holds every finished chunk (kept when the chain ends unconverged);
``resume=True`` continues from it.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import bundled
from ..atomic import write_text
from ..data import Dataset, load
from ..defaults import (
    ALL_TESTS,
    CONTRAST_CHOICES,
    DEFAULT_CHUNK,
    DEFAULT_COORDINATES,
    DEFAULT_ENSEMBLES,
    DEFAULT_MAX_STEPS,
    DEFAULT_SAMPLE_ALL,
    DEFAULT_STARTS,
    DEFAULT_TESTS,
    DEFAULT_WARMUP,
    HDI_PROB,
)
from ..errors import PeanoBayesInputError
from ..inference.coordinates import contrast_flags, sampler_coordinates
from ..inference.driver import (
    _first_call_seconds,
    _log_lags,
    least_squares,
    linearisation_point,
    optimum_centres,
    posterior_at_mode,
    walker_start,
    with_known_mounts,
)
from ..inference.fit import FitResult, fit_quality, predictions, residual_correlation, sensor_noise
from ..inference.posterior import DEFAULT_HELD, SPECIMEN_SD, Posterior, build_posterior
from ..inference.prior_files import load_prior
from ..inference.priors import Prior
from ..inference.reduce import Observations, prepare
from ..inference.results import (
    NEW_SPECIMEN_PREFIX,
    PRIOR_CONFLICT_SD,
    parameter_table,
    posterior_contraction,
    posterior_ridges,
    prior_conflicts,
    prior_positions,
    to_inference_data,
    write_netcdf,
)
from ..inference.sample import sample, walker_count
from ..inference.summary import Summary, write_summary
from ..physics.model import ModelConfig
from ..report.index import DISCOVERY_FOLDER

BUNDLED_MATERIALS = bundled.MATERIALS


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


def _model_choice(dataset: Dataset, config, out: Path, *, discover: bool, resume: bool, log):
    """The model a fit samples when it is known before any fit: ``config`` without ``discover``; on ``resume``
    the model of the saved fit (the discovery report's if there is one, else ``config``). ``None`` when
    discovery is still to run (:func:`_discover`, from the least squares of ``config``)."""
    from ..discovery.choice import choice_from_report, configured_model

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
    from ..discovery.choice import choose_model
    from ..effects import effects_in

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
    config = with_known_mounts(dataset, config)
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
    sample_all: bool = DEFAULT_SAMPLE_ALL,
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
    ``sample_all``: sample the three shape constants of :data:`~peano_bayes.inference.posterior.DEFAULT_HELD`
    too, or (``False``) hold them at nominal (default
    :data:`~peano_bayes.defaults.DEFAULT_SAMPLE_ALL`). ``discover``: first run discovery on the data
    from the material's configured model, write its report into ``<label>/discovery/`` and sample the
    configured model plus the physics effects it named (:func:`~peano_bayes.discovery.choice.choose_model`; a
    resumed run reads the report instead of running discovery again). ``summary.json``'s ``model`` records the
    choice either way. ``coordinates``: what the sampler moves, ``"theta"`` or ``"tensile_stretch"``
    (:func:`~peano_bayes.inference.coordinates.sampler_coordinates`). ``contrasts``: ``"auto"`` samples each
    specimen contrast the data pin little non-centred (:func:`~peano_bayes.inference.coordinates.
    choose_noncentred`), ``"centred"`` none, ``"noncentred"`` all.
    """
    if contrasts not in CONTRAST_CHOICES:
        raise PeanoBayesInputError(f"contrasts={contrasts!r}: expected one of {', '.join(CONTRAST_CHOICES)}")
    timings = {}
    dataset = load(data) if not isinstance(data, Dataset) else data
    # The sensors' noise from every run of the file, before tests are left out: the quiet tests estimate it best.
    noise = sensor_noise(dataset.runs)
    absent = [t for t in dict.fromkeys(tests) if t not in dataset.tests]
    dataset = select_tests(dataset, tests)
    code = dataset.material.code
    if absent:  # said, not silent: the fit uses fewer tests than asked for
        log(f"{code}: the file has no {', '.join(absent)} runs; fitting {', '.join(dataset.tests)} only")
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
        fitted = FitResult.from_json(json.loads(fit_path.read_text()), where=str(fit_path))
        timings["least_squares_s"] = fitted.seconds
        log(f"{code}: least squares loaded from {fit_path}")
    else:
        for stale in (fit_path, state_path, linearised_path):
            stale.unlink(missing_ok=True)

    def fit_plan(plan: PosteriorPlan) -> FitResult:
        log(f"{code}: least squares from up to {n_starts} starts ...")
        fitted = least_squares(plan.posterior, plan.prior, n_starts=n_starts, seed=seed)
        timings["least_squares_s"] = timings.get("least_squares_s", 0.0) + fitted.seconds
        log(f"{code}: least squares done in {fitted.seconds:.1f} s ({fitted.outcome()})")
        return fitted

    if choice is None:  # discovery starts from the configured model's least squares: one fit serves both
        fitted = fit_plan(plan)
        choice = _discover(dataset, whole_prior.config, out, seed=seed, log=log, start=fitted.params)
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
    held = [f"{name} = {posterior.fixed[name]:g}" for name in DEFAULT_HELD if name in posterior.fixed]
    held_note = (
        f"; shape constants held at nominal, not sampled: {', '.join(held)} (--sample-all samples them)" if held else ""
    )
    out.mkdir(parents=True, exist_ok=True)
    log(
        f"{code}: {observations.n_bins} bins from {len(dataset.runs)} runs ({', '.join(dataset.tests)}); "
        f"{posterior.ndim} parameters sampled{held_note}"
    )
    if fitted is None:
        fitted = fit_plan(plan)
    if not (resume and fit_path.exists()):
        write_text(fit_path, json.dumps(fitted.to_json(), indent=1))

    centre, covariance = walker_start(posterior, fitted)
    # Every batch in calls of half an ensemble (what emcee's red-blue moves evaluate): one compilation, which
    # also serves the mode's refinement on the full likelihood.
    rows = max(1, n_walkers // 2)
    posterior = posterior.with_batch_rows(rows)
    start = None
    if resume and state_path.exists():  # a resumed run restores its walkers and needs no start
        # It reads back where its inputs' error was linearised and its AR(1) lags, so it samples the same posterior.
        point, lag1, noncentred = linearisation_point(linearised_path, state_path, posterior)
        posterior = posterior.with_input_error_at(point).with_residual_lag1(lag1)
        _log_lags(posterior, lag1, lambda m: log(f"{code}: {m}"))
        timings["compile_s"] = _first_call_seconds(posterior, centre)
    else:
        start = posterior_at_mode(posterior, centre, covariance, log=lambda m: log(f"{code}: {m}"))
        posterior, centre, covariance = start.posterior, start.laplace.mode, start.laplace.covariance
        noncentred = contrast_flags(contrasts, posterior, centre, covariance)
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
    positions = prior_positions(idata, posterior.prior, posterior.prior.names)
    conflicts = prior_conflicts(posterior.prior, positions)
    if conflicts:
        log(
            f"{code}: WARNING: the posterior median lies more than {PRIOR_CONFLICT_SD:g} prior sd into a tail of "
            "its prior, or against a bound of its support, for "
            + ", ".join(f"{n} ({positions[n]:+.1f})" for n in conflicts)
            + ": prior and data disagree there, and along any direction the data leave open the interval "
            "follows the prior; check the prior file's entry"
        )
    summary = Summary(**{
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
        "prior_z": positions,
        "prior_conflicts": conflicts,
        "ridges": posterior_ridges(idata, posterior.prior.names),
        "units": posterior.units,
        "fixed": posterior.fixed,
        "fit_quality_least_squares": fitted.quality,
        "fit_quality_posterior_mean": quality,
        "residual_correlation": correlation,
        "least_squares": {
            k: getattr(fitted, k)
            for k in ("cost", "n_starts", "n_failed", "n_step_limit", "converged", "rounds", "params")
        },
        "posterior_mode": None
        if start is None
        else {
            "log_prob": start.laplace.log_prob,
            "steps": start.laplace.steps,
            "status": start.laplace.status.value,
            "detail": start.laplace.detail,
            "exact_inputs": {
                "log_prob": start.exact.log_prob,
                "steps": start.exact.steps,
                "status": start.exact.status.value,
                "detail": start.exact.detail,
            },
        },
        "timings_s": timings,
    })  # fmt: skip
    write_netcdf(idata, out / "posterior.nc")
    write_summary(out / "summary.json", summary)
    if result.convergence.converged:
        state_path.unlink(missing_ok=True)
    else:  # kept: a resumed run with a larger step limit continues the same chain
        log(f"{code}: sampler state kept in {state_path}: --resume with a larger --max-steps continues it")
    log(f"{code}: wrote {out / 'posterior.nc'} and summary.json")
    if figures:
        from ..report.figures import material_figures

        material_figures(out, dataset)
        log(f"{code}: figures in {out / 'figures'}")
    return summary


__all__ = ["BUNDLED_MATERIALS", "PosteriorPlan", "infer", "prior_of", "select_tests"]
