"""Many datasets at once: the main job (:func:`run_bundled`, ``peano-bayes run``) and :func:`fit_many`
(``fit-many``) run :func:`~.pipeline.infer` on each, fanned out over worker processes or a Dask cluster
(:mod:`~.fanout`); each worker also computes its material's part of the report (reference models, metrics,
figures: :func:`material_report`), and :func:`report_results` writes the cross-material index, ranking and
figures from the results."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .. import bundled
from ..atomic import write_text
from ..data import Dataset, load
from ..defaults import (
    DEFAULT_DRAWS,
    DEFAULT_MAX_STEPS,
    DEFAULT_SAMPLE_ALL,
    DEFAULT_TESTS,
)
from ..errors import PeanoBayesError, PeanoBayesInputError
from ..inference.reduce import prepare
from ..inference.summary import read_summary
from ..report.index import MATERIAL_FIGURES, index_markdown
from .pipeline import BUNDLED_MATERIALS, _check_label, _plan_posterior, infer, prior_of, select_tests


def reference_models(directory: Path, summary: dict, *, log=print) -> dict | None:
    """``directory/reference_models.json``: the paper's reference models fitted to the load cycles of the
    result's dataset (:func:`~peano_bayes.inference.reference_fit.reference_comparison`), made if missing;
    ``None`` when the dataset has no load cycles or is no longer where the summary says."""
    from ..inference.reference_fit import reference_comparison

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
    directory: Path, summary: dict, *, n_draws: int | None = None, log=print
) -> tuple[dict | None, dict | None]:
    """One finished material's part of the report, each piece computed only where it is missing: the reference
    models' fit (:func:`reference_models`), ``metrics.json``
    (:func:`~peano_bayes.analysis.metrics.evaluate_result`, kept if written by this version) and ``figures/``.
    Returns ``(reference models, metrics)``, ``None`` for what could not be had. The main job's workers run it as
    soon as their material is sampled, so the parent's report only reads it back."""
    from ..analysis.metrics import evaluate_result, metrics_current, read_metrics
    from ..report.figures import material_figures

    n_draws = REPORT_DRAWS if n_draws is None else n_draws
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


#: Posterior draws the main job's metrics, ranking and recommendation read (the metrics' default).
REPORT_DRAWS = DEFAULT_DRAWS


def report_results(out_dir: str | Path, materials=BUNDLED_MATERIALS, *, n_draws: int = REPORT_DRAWS, log=print) -> dict:
    """Metrics, figures, ranking and ``index.md`` for the finished materials of ``out_dir``.

    Per material with a ``summary.json``: ``metrics.json`` (:func:`~peano_bayes.analysis.metrics.evaluate_result`, kept
    if written by this version: :func:`~peano_bayes.analysis.metrics.metrics_current`) and ``figures/``; across them:
    ``ranking.json``/``ranking.md``, ``figures/`` and ``index.md``.
    Returns the ranking (:func:`~peano_bayes.analysis.ranking.rank_materials`)."""
    from ..analysis.ranking import failed_draw_counts, rank_materials, ranking_markdown
    from ..inference.results import load_result
    from ..report.figures import cross_material_figures

    out_dir = Path(out_dir)
    finished = [c for c in materials if (out_dir / c / "summary.json").exists()]
    summaries, metrics, results, references = [], {}, {}, {}
    for code in finished:
        directory = out_dir / code
        summaries.append(read_summary(directory))
        references[code], material_metrics = material_report(directory, summaries[-1], n_draws=n_draws, log=log)
        if material_metrics is not None:
            metrics[code] = material_metrics
        results[code] = load_result(directory)
    prior_only = {name for m in metrics.values() for name, s in m["summary"].items() if s["from_prior"]}
    pressures = {c: m.get("test_pressure_kpa") for c, m in metrics.items()}
    draws, failed = {c: m["draw_values"] for c, m in metrics.items()}, failed_draw_counts(metrics)
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
    :func:`~peano_bayes.app.fanout.run_units`, and the summaries in the order of ``items``. A label whose
    ``summary.json`` exists is not redone unless its chain can continue (:func:`_can_continue`). Writes
    ``out_dir/provenance.json``; raises after the others finished if any unit failed."""
    from .fanout import Unit, make_executor, provenance, raise_failures, run_units

    max_steps = kwargs.get("max_steps", DEFAULT_MAX_STEPS)
    summaries: dict[str, dict] = {}
    todo = []
    for label, source in items:
        done = out_dir / label / "summary.json"
        if done.exists():
            summary = read_summary(done)
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
    it resumes. The materials are work units of :func:`~peano_bayes.app.fanout.run_units`: ``jobs`` at once in local
    worker processes, or on the Dask cluster of ``scheduler`` (see :func:`~peano_bayes.app.fanout.make_executor`),
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
        sample_all = bool(kwargs.get("sample_all", DEFAULT_SAMPLE_ALL))
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


__all__ = ["REPORT_DRAWS", "RunLog", "fit_many", "material_report", "reference_models", "report_results", "run_bundled"]
