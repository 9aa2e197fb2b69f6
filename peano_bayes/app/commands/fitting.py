"""Subcommands that fit and sample: ``fit`` (one dataset), ``run`` (the main job), ``fit-many``."""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import sys
from pathlib import Path

from ... import bundled
from ...defaults import (
    ALL_TESTS,
    CONTRAST_CHOICES,
    COORDINATE_KINDS,
    DEFAULT_CHUNK,
    DEFAULT_COORDINATES,
    DEFAULT_ENSEMBLES,
    DEFAULT_MAX_STEPS,
    DEFAULT_MAX_WARMUP,
    DEFAULT_SAMPLE_ALL,
    DEFAULT_STARTS,
    DEFAULT_TESTS,
    DEFAULT_WARMUP,
)
from ...errors import PeanoBayesInputError
from .registry import _DATA_HELP, _seed, _writable_folder, command


def _sampling_arguments(p, *, discover_by_default: bool = False, continued_by: str = "--resume"):
    """The fit's options; ``discover_by_default`` (the main job): discovery runs unless ``--no-discover``;
    ``continued_by``: how a run stopped at its step limit is continued (``fit``: ``--resume``; ``run`` and
    ``fit-many`` resume by themselves: the same command again)."""
    p.add_argument("--seed", type=_seed, default=0, help="seed of the starts and the sampler (default: 0)")
    p.add_argument(
        "--tests",
        nargs="+",
        default=list(DEFAULT_TESTS),
        choices=ALL_TESTS,
        metavar="TEST",
        help=f"tests to fit, some of {' '.join(ALL_TESTS)} (default: {' '.join(DEFAULT_TESTS)}; the step response "
        "costs several times more)",
    )
    p.add_argument(
        "--starts", type=int, default=DEFAULT_STARTS, help=f"least-squares starts (default: {DEFAULT_STARTS})"
    )
    p.add_argument(
        "--walkers",
        type=int,
        default=None,
        help="emcee walkers per ensemble, at least 2 x the sampled parameters (default: max(32, 2 x parameters + 2))",
    )
    p.add_argument(
        "--ensembles",
        type=int,
        default=DEFAULT_ENSEMBLES,
        help=f"independently started ensembles that R-hat compares (default: {DEFAULT_ENSEMBLES}; fewer than 4 "
        "never certify convergence)",
    )
    p.add_argument(
        "--chunk",
        type=int,
        default=DEFAULT_CHUNK,
        help=f"steps between saved states and checks (default: {DEFAULT_CHUNK})",
    )
    p.add_argument(
        "--max-steps",
        type=int,
        default=DEFAULT_MAX_STEPS,
        help=f"step limit (default: {DEFAULT_MAX_STEPS}); beyond it the run is unconverged and its state is kept, "
        f"so {continued_by} with a larger limit continues it",
    )
    p.add_argument(
        "--warmup",
        type=int,
        default=DEFAULT_WARMUP,
        help=f"warm-up steps, discarded, that fit the proposal (default: as long as the proposal needs to settle, "
        f"at most {DEFAULT_MAX_WARMUP}; see docs/inference.md)",
    )
    p.add_argument(
        "--coordinates",
        choices=COORDINATE_KINDS,
        default=DEFAULT_COORDINATES,
        help=f"what the sampler moves: the tensile element as its log stretches at two forces, or theta itself "
        f"(default: {DEFAULT_COORDINATES}; see docs/inference.md)",
    )
    p.add_argument(
        "--contrasts",
        choices=CONTRAST_CHOICES,
        default=CONTRAST_CHOICES[0],
        help="specimen contrasts: 'auto' samples those the data pin little as multiples of the spread "
        "(non-centred), 'centred' samples all as they are, 'noncentred' all as multiples of the spread "
        "(default: auto; see docs/inference.md)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument(
        "--sample-all",
        action=argparse.BooleanOptionalAction,
        default=DEFAULT_SAMPLE_ALL,
        help="sample the three shape constants (length fraction, bending exponent, extension rate) with the rest, "
        "as needed unless a muscle's constants are known to be nominal; --no-sample-all holds them at nominal "
        "(exact only for such a muscle), in about half to two thirds of the time "
        f"(default: {'--sample-all' if DEFAULT_SAMPLE_ALL else '--no-sample-all'}; see docs/inference.md)",
    )
    p.add_argument(
        "--discover",
        action=argparse.BooleanOptionalAction,
        default=discover_by_default,
        help="run discovery on the data first and sample the configured model plus the physics effects it names "
        "(report in the result folder's discovery/; see docs/discovery.md); --no-discover samples the configured model "
        f"(default: {'--discover' if discover_by_default else '--no-discover'})",
    )


def _check_sampling(args):
    for name in ("starts", "chunk", "max_steps"):
        if getattr(args, name) < 1:
            raise PeanoBayesInputError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if args.warmup is not None and args.warmup < 0:
        raise PeanoBayesInputError(f"--warmup must be >= 0, got {args.warmup}")
    if args.walkers is not None and args.walkers < 4:
        raise PeanoBayesInputError(f"--walkers must be >= 4, got {args.walkers}")
    if args.ensembles < 1:
        raise PeanoBayesInputError(f"--ensembles must be >= 1, got {args.ensembles}")
    return dict(
        seed=args.seed,
        tests=tuple(args.tests),
        n_starts=args.starts,
        n_walkers=args.walkers,
        n_ensembles=args.ensembles,
        chunk=args.chunk,
        max_steps=args.max_steps,
        warmup=args.warmup,
        progress=not args.no_progress,
        sample_all=args.sample_all,
        discover=args.discover,
        coordinates=args.coordinates,
        contrasts=args.contrasts,
    )


def _report(summary: dict) -> dict:
    conv = summary["convergence"]
    return {
        "material": summary["material"],
        "label": summary.get("label", summary["material"]),
        "converged": conv["converged"],
        "problems": conv["problems"],
        "steps": summary["steps"],
        "max_rhat": max(conv["rhat"].values()),
        "min_ess_bulk": min(conv["ess_bulk"].values()),
        "timings_s": summary["timings_s"],
        "model": summary.get("model"),
    }


@command("fit", "one dataset: multi-start least squares, then MCMC (emcee), into --out DIR/LABEL/ (resumable)")
def fit_command(args):
    from ...data import load
    from ..pipeline import infer

    options = _check_sampling(args)
    _writable_folder(args.out, "--out")
    dataset = load(bundled.resolve_dataset(args.data))  # validate before anything is written
    stem = Path(dataset.source_path).stem if dataset.source_path else dataset.material.code
    target = Path(args.out) / (args.label if args.label is not None else stem)
    if (target / "summary.json").exists() and not (args.resume or args.force):
        raise PeanoBayesInputError(
            f"{target}: holds a finished result; pass --force to fit again and replace it, or --label NAME (or "
            "another --out) for a new folder"
        )
    if args.resume and not any((target / name).exists() for name in ("sampler_state.npz", "fit.json")):
        print(f"peano-bayes fit: nothing saved in {target} to resume: starting a new fit", file=sys.stderr)
    summary = infer(
        dataset,
        args.out,
        resume=args.resume,
        prior=args.prior,
        label=args.label,
        figures=not args.no_figures,
        **options,
    )
    report = _report(summary)
    out = Path(args.out) / report["label"]
    if report["converged"]:
        print(f"wrote {out}: converged after {report['steps']} steps")
    else:
        print(
            f"peano-bayes fit: WARNING: {report['label']} did NOT converge: {'; '.join(report['problems'])}; "
            f"results in {out} are marked unconverged (--resume with a larger --max-steps continues)",
            file=sys.stderr,
        )
    return report


def _fit_arguments(p):
    p.add_argument("data", metavar="DATA", help=_DATA_HELP)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (results go to DIR/LABEL/)")
    p.add_argument(
        "--prior",
        metavar="FILE.toml|CODE",
        default=None,
        help="prior file (may 'extends' a bundled one; 'peano-bayes prior new' writes a start) or a bundled "
        "material code; default: the bundled prior of the sidecar's material code",
    )
    p.add_argument(
        "--label", metavar="NAME", default=None, help="name of the result folder (default: the data file's stem)"
    )
    again = p.add_mutually_exclusive_group()  # continue the saved run, or start over: not both
    again.add_argument("--resume", action="store_true", help="continue an interrupted run from its saved state")
    again.add_argument("--force", action="store_true", help="fit again over a finished result in the same folder")
    p.add_argument("--no-figures", action="store_true", help="skip the figures (predictive band, corner plot)")
    _sampling_arguments(p)


fit_command.arguments = _fit_arguments


@command("run", "the main job: every bundled material, fit + sample into results/ with results/index.md")
def run(args):
    options = _check_sampling(args)
    fanout = _fanout_options(args)
    _writable_folder(args.out, "--out")
    materials = tuple(m.upper() for m in args.materials)
    unknown = [m for m in materials if m not in bundled.MATERIALS]
    if unknown:
        raise PeanoBayesInputError(f"unknown material(s) {', '.join(unknown)}; bundled: {' '.join(bundled.MATERIALS)}")
    repeated = sorted({m for m in materials if materials.count(m) > 1})
    if repeated:
        raise PeanoBayesInputError(f"--materials: {', '.join(repeated)} given more than once; expected each code once")
    from ..batch import run_bundled

    with _no_leftover_folder(args.out):
        summaries = run_bundled(args.out, materials=materials, **fanout, **options)
    return _many_report("run", args.out, summaries, "materials")


@contextlib.contextmanager
def _no_leftover_folder(out):
    """Remove ``out`` if this command created it and stops with nothing in it but its ``run.log`` (a Dask
    scheduler that cannot be reached, an input refused by a worker): a failed command leaves nothing
    half-written. A folder that existed before, or holds any result, is kept."""
    out = Path(out)
    existed = out.exists()
    try:
        yield
    except BaseException:
        if not existed and out.is_dir() and {p.name for p in out.iterdir()} <= {"run.log"}:
            shutil.rmtree(out, ignore_errors=True)
        raise


def _fanout_options(args) -> dict:
    """``jobs`` and ``scheduler`` of a fan-out command, checked (a bad scheduler exits 2 before anything runs)."""
    from ..fanout import SCHEDULER_ENV, parse_scheduler

    if args.jobs < 1:
        raise PeanoBayesInputError(f"--jobs must be >= 1, got {args.jobs}")
    parse_scheduler(args.scheduler if args.scheduler is not None else os.environ.get(SCHEDULER_ENV))
    return {"jobs": args.jobs, "scheduler": args.scheduler}


def _many_report(name: str, out, summaries: list[dict], what: str) -> dict:
    reports = [_report(s) for s in summaries]
    bad = [r["label"] for r in reports if not r["converged"]]
    print(f"wrote {out}/index.md: {len(reports) - len(bad)} of {len(reports)} {what} converged")
    if bad:
        print(f"peano-bayes {name}: WARNING: NOT CONVERGED: {', '.join(bad)} (see {out}/index.md)", file=sys.stderr)
    return {what: reports, "converged": not bad}


def _fanout_arguments(p, what: str) -> None:
    p.add_argument(
        "--jobs", type=int, default=2, help=f"{what} run at once, one local worker process each (default: 2)"
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="SPEC",
        help="run on Dask instead of local processes: 'local:N' starts a LocalCluster of N workers, "
        "'tcp://HOST:8786' uses a running cluster (default: $PEANO_BAYES_SCHEDULER, else local processes; "
        "needs dask.distributed; see docs/scaling.md)",
    )


def _run_arguments(p):
    p.add_argument("--out", default="results", metavar="DIR", help="output directory (default: results)")
    p.add_argument(
        "--materials",
        nargs="+",
        default=list(bundled.MATERIALS),
        metavar="CODE",
        help=f"the materials to run (default: all eight, {' '.join(bundled.MATERIALS)})",
    )
    _fanout_arguments(p, "materials")
    _sampling_arguments(p, discover_by_default=True, continued_by="the same command again")


run.arguments = _run_arguments


@command("fit-many", "several datasets: 'fit' on each into --out DIR/<file stem>/, in parallel or on Dask")
def fit_many_command(args):
    options = _check_sampling(args)
    fanout = _fanout_options(args)
    _writable_folder(args.out, "--out")
    paths = [bundled.resolve_dataset(d) for d in args.data]
    from ..batch import fit_many

    with _no_leftover_folder(args.out):
        summaries = fit_many(paths, args.out, prior=args.prior, **fanout, **options)
    return _many_report("fit-many", args.out, summaries, "datasets")


def _fit_many_arguments(p):
    p.add_argument(
        "data",
        nargs="+",
        metavar="DATA",
        help="rig datasets, each a CSV with its TOML sidecar (or its stem) or a bundled material code; their names "
        "must differ",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (results go to DIR/<file stem>/)")
    p.add_argument(
        "--prior", metavar="FILE.toml", default=None, help="one prior file for all (default: each sidecar's material)"
    )
    _fanout_arguments(p, "datasets")
    _sampling_arguments(p, continued_by="the same command again")


fit_many_command.arguments = _fit_many_arguments


__all__ = ["fit_command", "fit_many_command", "run"]
