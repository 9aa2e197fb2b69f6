"""The subcommands of ``peano-bayes``, each a thin wrapper over one documented function of the Python API.

Every subcommand registers itself in :data:`COMMANDS` with :func:`command`; its ``arguments(parser)`` adds its
options and must not import JAX (so ``--help`` stays instant): heavy imports happen inside ``run(args)``.
``run`` returns a JSON-ready dict (printed under ``--json``); a dict whose ``converged`` is ``False`` makes the
command exit with status 3.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from . import bundled
from .defaults import (
    ALL_TESTS,
    CONTRAST_CHOICES,
    COORDINATE_KINDS,
    DEFAULT_CHUNK,
    DEFAULT_COORDINATES,
    DEFAULT_ENSEMBLES,
    DEFAULT_MAX_STEPS,
    DEFAULT_MAX_WARMUP,
    DEFAULT_STARTS,
    DEFAULT_TESTS,
    DEFAULT_WARMUP,
    MAX_PRESSURE_KPA,
)
from .errors import PeanoBayesInputError


@dataclass(frozen=True)
class Command:
    """One subcommand: its one-line ``help`` and ``run(args) -> dict | None``; ``run.arguments(parser)``, if
    set, adds its options."""

    help: str
    run: Callable

    def arguments(self, parser) -> None:
        getattr(self.run, "arguments", lambda parser: None)(parser)


#: name -> :class:`Command`, in the order ``--help`` lists them.
COMMANDS: dict[str, Command] = {}


def command(name: str, help: str):
    """Register ``run(args)`` as subcommand ``name``; set ``run.arguments = fn(parser)`` to add its options."""

    def decorate(run):
        COMMANDS[name] = Command(help, run)
        return run

    return decorate


def _writable_folder(path, option: str) -> Path:
    """``path`` as a folder a command may write into (existing, or creatable where its nearest existing parent is
    a writable folder); otherwise :class:`PeanoBayesInputError` naming ``option``, before any work is done."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise PeanoBayesInputError(f"{option} {path}: a file; expected a folder (existing or new)")
    parent = path
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not _can_create_in(parent):
        raise PeanoBayesInputError(f"{option} {path}: {parent} is not a folder this user can write into")
    return path


def _can_create_in(folder: Path) -> bool:
    """Whether a file can be created in ``folder``, by creating (and at once removing) one: ``os.access`` answers
    from permission bits, which say yes to root everywhere, also under ``/proc`` or on a read-only mount."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def _seed(text: str) -> int:
    """A ``--seed`` value: a whole number >= 0 (NumPy's generators refuse negative seeds)."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value


_DATA_HELP = (
    "the dataset: a CSV with its TOML sidecar (or its stem), or a bundled material code "
    f"({' '.join(bundled.MATERIALS)})"
)


@command("demo", "forward-model demo: blocking force and free strain of the default four-tube muscle")
def demo(args):
    from .demo import blocking_and_free_strain

    for value in args.pressures_kpa:
        _pressure_kpa(value, "--pressures-kpa")
    rows = blocking_and_free_strain(args.pressures_kpa)
    print("Default four-tube Peano muscle (w = 15 mm, l = 49.5 mm), nominal parameters")
    print(f"{'pressure [kPa]':>15} {'blocking force [N]':>19} {'free strain [%]':>16}")
    for row in rows:
        print(f"{row['pressure_kpa']:15.0f} {row['blocking_force_n']:19.1f} {100 * row['free_strain']:16.2f}")
    return {"demo": rows}


demo.arguments = lambda p: p.add_argument(
    "--pressures-kpa",
    type=float,
    nargs="+",
    default=[30, 100, 200, 300, 500],
    metavar="P",
    help="pressures to evaluate [kPa] (default: 30 100 200 300 500)",
)


@command("check", "validate a rig dataset (CSV + TOML sidecar) and summarize it")
def check(args):
    from .data import load

    dataset = load(bundled.resolve_dataset(args.data))
    g, c, m = dataset.geometry, dataset.conditions, dataset.material
    tests = {}
    for test in dataset.tests:
        runs = dataset.runs_of(test)
        tests[test] = {
            "runs": len(runs),
            "samples": sum(len(r) for r in runs),
            "specimens": list(dict.fromkeys(r.specimen for r in runs)),
            "time_s": [min(float(r.time_s[0]) for r in runs), max(float(r.time_s[-1]) for r in runs)],
            "longest_run_s": max(r.duration_s for r in runs),
        }
    print(f"{dataset.source_path}: {m.code} ({m.name}) - valid")
    print(
        f"  geometry: {g.n_tubes} tubes, {1e3 * g.tube_width_m:g} mm wide x "
        f"{1e3 * g.tube_length_m:g} mm long, channel {100 * g.channel_width_frac:g} %, "
        f"flat length l0 {1e3 * g.flat_length_m:g} mm"
    )
    print(
        f"  conditions: {c.fluid}, test pressure {c.test_pressure_pa / 1e3:g} kPa, "
        f"step load {c.step_load_n:g} N, start tension {c.start_tension_n:g} N"
    )
    print(f"  specimens: {', '.join(dataset.specimens)}")
    for test, t in tests.items():
        print(
            f"  {test:<10} {t['runs']:3d} run{'s' if t['runs'] != 1 else ' '} {t['samples']:8d} samples   "
            f"time {t['time_s'][0]:g} to {t['time_s'][1]:g} s"
        )
    return {
        "file": str(dataset.source_path),
        "valid": True,
        "material": {"code": m.code, "name": m.name},
        "geometry": {
            "n_tubes": g.n_tubes,
            "tube_width_m": float(g.tube_width_m),
            "tube_length_m": float(g.tube_length_m),
            "channel_width_frac": float(g.channel_width_frac),
            "flat_length_m": float(g.flat_length_m),
        },
        "conditions": {
            "fluid": c.fluid,
            "test_pressure_pa": c.test_pressure_pa,
            "step_load_n": c.step_load_n,
            "start_tension_n": c.start_tension_n,
        },
        "provenance": dict(dataset.provenance),
        "specimens": list(dataset.specimens),
        "tests": tests,
    }


check.arguments = lambda p: p.add_argument("data", metavar="DATA", help=_DATA_HELP)


@command("simulate", "the virtual rig: write a dataset (CSV + TOML sidecar) simulated from given parameters")
def simulate(args):
    from .data import dataset_paths, save
    from .rig import read_parameter_file, simulate_dataset

    params, config = read_parameter_file(args.params) if args.params else ({}, None)
    try:
        csv_path, toml_path = dataset_paths(args.out)
    except PeanoBayesInputError as err:
        raise PeanoBayesInputError(f"--out: {err}") from None
    _writable_folder(csv_path.parent, "--out")
    for path in (csv_path, toml_path):
        if path.is_dir():
            raise PeanoBayesInputError(f"--out: {path} is a directory; expected a file path like DIR/FC.csv")
        if path.exists() and not args.force:
            raise PeanoBayesInputError(f"--out: {path} exists; choose another path or pass --force to replace it")
    options = {} if config is None else {"config": config}
    dataset = simulate_dataset(
        args.material,
        params,
        quirks=args.quirk,
        seed=args.seed,
        drift=args.drift,
        specimens=args.specimens,
        repeats=args.repeats,
        progress=lambda line: print(f"simulated {line}", flush=True),
        **options,
    )
    try:
        save(dataset, csv_path)
    except OSError as err:
        raise PeanoBayesInputError(f"--out: cannot write {csv_path} ({err.strerror or err})") from None
    samples = sum(len(r) for r in dataset.runs)
    quirks = dataset.provenance["quirks"]
    print(
        f"wrote {csv_path} and {toml_path}: {dataset.material.code}, {len(dataset.runs)} runs, {samples} samples, "
        f"seed {args.seed}, quirks: {quirks}"
    )
    return {
        "csv": str(csv_path),
        "toml": str(toml_path),
        "material": dataset.material.code,
        "runs": len(dataset.runs),
        "samples": samples,
        "specimens": list(dataset.specimens),
        "seed": args.seed,
        "quirks": [] if quirks == "none" else quirks.split(", "),
        "drift": args.drift,
    }


def _simulate_arguments(p):
    p.add_argument("--material", required=True, metavar="CODE", help="Table 4 material code: TP P PR TPC PC PCS TFC FC")
    p.add_argument(
        "--params",
        metavar="PARAMS.toml",
        help="[parameters] name = value in SI units, optional [config] ModelConfig fields (default: nominal values)",
    )
    p.add_argument("--out", required=True, metavar="PATH.csv", help="dataset to write (PATH.csv + PATH.toml)")
    p.add_argument("--seed", type=_seed, default=0, help="seed of every random draw (default: 0)")
    p.add_argument(
        "--quirk",
        action="extend",
        nargs="+",
        default=[],
        metavar="NAME",
        help="switch on an effect by its name in the effect registry (repeatable; an unknown name lists them)",
    )
    p.add_argument("--drift", action="store_true", help="add a slow linear drift to the force sensor")
    p.add_argument("--specimens", type=int, default=2, help="specimens per material (default: 2, as in the paper)")
    p.add_argument("--repeats", type=int, default=3, help="repeats of each test (default: 3, as in the paper)")
    p.add_argument("--force", action="store_true", help="replace an existing dataset at --out")


simulate.arguments = _simulate_arguments


def _sampling_arguments(p, *, discover_by_default: bool = False):
    """The fit's options; ``discover_by_default`` (the main job): discovery runs unless ``--no-discover``."""
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
        "--walkers", type=int, default=None, help="emcee walkers per ensemble (default: max(32, 2 x parameters + 2))"
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
        "so --resume with a larger limit continues it",
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
        "(non-centred), 'centred' samples all as they are (default: auto; see docs/inference.md)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument(
        "--sample-all",
        action="store_true",
        help="also sample the shape constants held at nominal by default (slow mixing; see docs/inference.md)",
    )
    p.add_argument(
        "--discover",
        action=argparse.BooleanOptionalAction,
        default=discover_by_default,
        help="run discovery on the data first and sample the configured model plus the physics effects it names "
        "(report in <out>/<label>/discovery/; see docs/discovery.md); --no-discover samples the configured model "
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
    from .data import load
    from .pipeline import infer

    options = _check_sampling(args)
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
        metavar="FILE.toml",
        default=None,
        help="prior file (may 'extends' a bundled one; 'peano-bayes prior new' writes a start); "
        "default: the bundled prior of the sidecar's material code",
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
    materials = tuple(m.upper() for m in args.materials)
    unknown = [m for m in materials if m not in bundled.MATERIALS]
    if unknown:
        raise PeanoBayesInputError(f"unknown material(s) {', '.join(unknown)}; bundled: {' '.join(bundled.MATERIALS)}")
    repeated = sorted({m for m in materials if materials.count(m) > 1})
    if repeated:
        raise PeanoBayesInputError(f"--materials: {', '.join(repeated)} given more than once; expected each code once")
    from .pipeline import run_bundled

    summaries = run_bundled(args.out, materials=materials, **fanout, **options)
    return _many_report("run", args.out, summaries, "materials")


def _fanout_options(args) -> dict:
    """``jobs`` and ``scheduler`` of a fan-out command, checked (a bad scheduler exits 2 before anything runs)."""
    from .fanout import SCHEDULER_ENV, parse_scheduler

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
    p.add_argument("--materials", nargs="+", default=list(bundled.MATERIALS), metavar="CODE", help="subset to run")
    _fanout_arguments(p, "materials")
    _sampling_arguments(p, discover_by_default=True)


run.arguments = _run_arguments


@command("fit-many", "several datasets: 'fit' on each into --out DIR/<file stem>/, in parallel or on Dask")
def fit_many_command(args):
    options = _check_sampling(args)
    fanout = _fanout_options(args)
    paths = [bundled.resolve_dataset(d) for d in args.data]
    from .pipeline import fit_many

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
    _sampling_arguments(p)


fit_many_command.arguments = _fit_many_arguments


@command("prior", "priors: 'prior new --like CODE --out FILE.toml' writes a starting prior to edit")
def prior_command(args):
    from .atomic import replacing, write_into
    from .inference.priors import load_prior, starting_prior

    out = Path(args.out)
    if out.suffix != ".toml" or not out.stem or out.stem.startswith("."):
        raise PeanoBayesInputError(f"--out {out}: expected a file name ending in .toml, such as my_prior.toml")
    if out.is_dir():
        raise PeanoBayesInputError(f"--out {out}: a folder; expected the path of a prior file to write")
    if out.exists() and not args.force:
        raise PeanoBayesInputError(f"--out {out}: the file exists; choose another path or pass --force")
    if not out.parent.is_dir():
        raise PeanoBayesInputError(f"--out {out}: the folder {out.parent} does not exist")
    if args.material is not None and not args.material.strip():
        raise PeanoBayesInputError("--material: expected a material code, got an empty string")
    material = args.material or out.stem
    text = starting_prior(args.like, material=material, out=out)
    try:
        with replacing(out) as tmp:  # the file loads as it will in a fit before it replaces anything
            write_into(tmp, text.encode("utf-8"))
            prior = load_prior(tmp)
    except OSError as err:
        raise PeanoBayesInputError(f"--out {out}: cannot be written ({err.strerror or err})") from None
    print(
        f"wrote {out}: the prior of {args.like} ({len(prior.names)} parameters) for material {material}; edit it, "
        f"then: peano-bayes fit DATA.csv --prior {out} --out results"
    )
    return {"prior": str(out), "like": args.like, "material": material, "parameters": list(prior.names)}


def _prior_arguments(p):
    p.add_argument("action", choices=("new",), help="new: write a starting prior that extends a bundled one")
    p.add_argument(
        "--like",
        required=True,
        metavar="CODE|FILE.toml",
        help=f"start from a bundled material's prior ({' '.join(bundled.MATERIALS)}) or a prior file",
    )
    p.add_argument("--out", required=True, metavar="FILE.toml", help="the prior file to write")
    p.add_argument("--material", default=None, metavar="CODE", help="meta.material (default: the file's stem)")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")


prior_command.arguments = _prior_arguments


@command("metrics", "posterior of the paper's Table 3 metrics for one result, beside the published values")
def metrics_command(args):
    from .metrics import evaluate_result, metrics_markdown

    if args.draws < 2:
        raise PeanoBayesInputError(f"--draws must be >= 2, got {args.draws}")
    out = evaluate_result(
        args.result,
        n_draws=args.draws,
        seed=args.seed,
        progress=not args.no_progress,
        test_pressure_kpa=_pressure_kpa(args.pressure_kpa),
    )
    print(f"{out['material']}: {out['n_draws']} posterior draws ({out['n_failed']} failed to simulate)")
    if out["n_failed"]:
        print(f"peano-bayes metrics: WARNING: {_failed_draws(out['n_failed'], out['n_draws'])}", file=sys.stderr)
    print(metrics_markdown(out["material"], out["summary"], out["published"]))
    if out["prior_only"]:
        print(f"not informed by the fitted tests, drawn from the prior: {', '.join(out['prior_only'])}")
    own, at = out["own_test_pressure_kpa"], out["test_pressure_kpa"]
    if own is not None and at != own:
        print(
            f"simulated at {at:g} kPa; {out['material']} was tested at {own:g} kPa, so these metrics extrapolate its "
            "fitted model; the free strain, energy and hysteresis most, since the rig's load cycles run at 0 kPa "
            "and the test pressure only"
        )
    return {k: v for k, v in out.items() if k != "draws"}


def _failed_draws(n_failed: int, n_drawn: int) -> str:
    return (
        f"{n_failed} of {n_drawn} posterior draws could not be simulated; the metrics rest on the other "
        f"{n_drawn - n_failed}, the parameters the model simulates most easily, not a random subset"
    )


def _metrics_arguments(p):
    p.add_argument("result", metavar="RESULT", help="a result directory of 'peano-bayes fit' (or its posterior.nc)")
    p.add_argument("--draws", type=int, default=100, help="posterior draws simulated (default: 100)")
    p.add_argument(
        "--seed",
        type=_seed,
        default=0,
        help="seed of the draws (prior values of unfitted parameters, model discrepancy) (default: 0)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--pressure-kpa", type=float, default=None, metavar="KPA", help=_PRESSURE_HELP)


_PRESSURE_HELP = (
    "simulate the metrics at this pressure [kPa] instead of each material's own test pressure (written to "
    "metrics_at_<KPA>kPa.json)"
)


def _pressure_kpa(value: float | None, option: str = "--pressure-kpa") -> float | None:
    if value is not None and not (math.isfinite(value) and 0 < value <= MAX_PRESSURE_KPA):
        raise PeanoBayesInputError(
            f"{option} must be a pressure in kPa above 0 and at most {MAX_PRESSURE_KPA:g} (the model's range), "
            f"got {value:g}"
        )
    return value


metrics_command.arguments = _metrics_arguments


@command("rank", "design ranking with uncertainty across results (needs each result's metrics.json)")
def rank_command(args):

    from .atomic import write_text
    from .metrics import evaluate_result, metrics_current, metrics_file, previous_draws, read_metrics
    from .ranking import failed_draw_counts, rank_materials, ranking_markdown

    common = _pressure_kpa(args.pressure_kpa)
    out = _writable_folder(args.out if args.out else Path(args.results[0]).resolve().parent, "--out")
    for path in args.results:  # every input checked before any metrics are recomputed or anything written
        if not (Path(path).is_dir() or Path(path).is_file()):
            raise PeanoBayesInputError(
                f"{path}: no such result; expected a folder that 'peano-bayes fit' wrote (or its metrics file)"
            )
    given = [Path(p).resolve() for p in args.results]
    again = sorted({str(p) for p in given if given.count(p) > 1})
    if again:
        raise PeanoBayesInputError(f"result(s) given more than once: {', '.join(again)}")
    for path in args.results:  # metrics simulated once per result and kept; an older version's recomputed
        if not Path(path).is_dir() or metrics_current(path, common):
            continue
        stale = (Path(path) / "posterior.nc").exists() and metrics_file(path).exists()
        if common is not None or stale:  # a result without metrics.json at its own pressure is refused below
            n_previous = previous_draws(path, common)
            evaluate_result(path, n_draws=n_previous, test_pressure_kpa=common, progress=not args.quiet)
    metrics = [read_metrics(path, common) for path in args.results]  # validate every input before writing
    codes = [m["material"] for m in metrics]
    twice = sorted({c for c in codes if codes.count(c) > 1})
    if twice:
        raise PeanoBayesInputError(f"material(s) given more than once: {', '.join(twice)}")
    prior_only = {name for m in metrics for name, s in m.get("summary", {}).items() if s.get("from_prior")}
    pressures = {m["material"]: m.get("test_pressure_kpa") for m in metrics}
    own = {m["material"]: m.get("own_test_pressure_kpa", m.get("test_pressure_kpa")) for m in metrics}
    draws = {m["material"]: m["draws"] for m in metrics}
    if len(metrics) == 1:
        print("peano-bayes rank: WARNING: one result: it is best in every criterion by definition", file=sys.stderr)
    failed = failed_draw_counts({m["material"]: m for m in metrics})
    for code, (n_failed, n_drawn) in failed.items():
        if n_failed:
            print(f"peano-bayes rank: WARNING: {code}: {_failed_draws(n_failed, n_drawn)}", file=sys.stderr)
    report = rank_materials(
        draws, from_prior=prior_only, test_pressure_kpa=pressures, own_test_pressure_kpa=own, failed_draws=failed
    )
    out.mkdir(parents=True, exist_ok=True)
    text = ranking_markdown(report)
    write_text(out / "ranking.json", json.dumps(report, indent=1))
    write_text(out / "ranking.md", "# Ranking\n\n" + text + "\n")
    print(text)
    print(f"wrote {out / 'ranking.json'} and {out / 'ranking.md'}")
    return report


def _rank_arguments(p):
    p.add_argument("results", nargs="+", metavar="RESULT", help="result directories (each with metrics.json)")
    p.add_argument(
        "--out", default=None, metavar="DIR", help="where ranking.json/.md go (default: the results' parent)"
    )
    p.add_argument(
        "--pressure-kpa",
        type=float,
        default=None,
        metavar="KPA",
        help="compare every material at this pressure [kPa] (metrics simulated there once per result and kept "
        "as metrics_at_<KPA>kPa.json; default: each at its own test pressure)",
    )


rank_command.arguments = _rank_arguments


@command("recommend", "design recommendation: candidate materials and geometries scored against a requirement")
def recommend_command(args):

    from .atomic import write_text
    from .figures import recommendation_figure
    from .recommend import recommend, recommendation_markdown

    spec = Path(args.spec)
    out = _writable_folder(args.out if args.out else spec.parent, "--out")
    # validates the spec and every result before writing
    report = recommend(args.spec, args.results, mount_compliance_m_per_n=args.mount_compliance, seed=args.seed)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"{spec.stem}_recommendation"
    text = recommendation_markdown(report)
    write_text(stem.with_suffix(".json"), json.dumps(report, indent=1))
    write_text(stem.with_suffix(".md"), f"# Recommendation for {spec.name}\n\n{text}\n")
    recommendation_figure(report, stem)
    print(text)
    print(f"wrote {stem}.json, .md, .png and .pdf")
    return report


def _recommend_arguments(p):
    p.add_argument("--spec", required=True, metavar="SPEC.toml", help="the requirement and the candidate grid")
    p.add_argument(
        "--results", default=None, metavar="DIR", help="material results (default: the spec's [results] dir)"
    )
    p.add_argument("--out", default=None, metavar="DIR", help="where the outputs go (default: beside the spec)")
    p.add_argument(
        "--mount-compliance",
        type=float,
        default=0.0,
        metavar="M_PER_N",
        help="the design's mount compliance [m/N] in place of the rig's (default: 0, a stiff mount)",
    )
    p.add_argument("--seed", type=_seed, default=0, help="seed of the new-specimen draws (default: 0)")


recommend_command.arguments = _recommend_arguments


@command("discover", "find, name and add the effect the base model misses; report the gap before and after")
def discover_command(args):
    from .data import load
    from .discovery import DEFAULT_BASE, Gates, discover, discovery_data, write_report
    from .discovery.effects import check_effects

    named = None if args.base is None else [name.strip() for name in args.base.split(",") if name.strip()]
    if named == []:
        raise PeanoBayesInputError(f"--base: expected comma-separated effect names, got {args.base!r}")
    try:
        base = check_effects(named) if named is not None else DEFAULT_BASE
    except PeanoBayesInputError as err:
        raise PeanoBayesInputError(f"--base: {err}") from None
    if args.max_effects < 1:
        raise PeanoBayesInputError(f"--max-effects must be >= 1, got {args.max_effects}")
    _writable_folder(args.out, "--out")
    dataset = load(bundled.resolve_dataset(args.data))  # validate before anything is written
    split = discovery_data(dataset, specimen=args.specimen, tests=args.tests)

    def say(line):
        print(line, flush=True)

    say(
        f"{len(split.fit_runs)} fitted and {len(split.held_out_runs)} held-out runs of specimen {split.specimen} "
        "(the first fit compiles the model: a few minutes)"
    )
    gates = Gates(max_effects=args.max_effects)
    result = discover(split, base=base, gates=gates, seed=args.seed, progress=say)
    written = write_report(result, Path(args.out))
    report = result.report
    say(f"verdict: {report['verdict']}" + (f" ({', '.join(report['named'])})" if report["named"] else ""))
    if report["described"]:
        say(f"slow structure over the session, described by {', '.join(report['described'])}, names no effect")
    say(f"wrote {', '.join(str(p) for p in written)}")
    return report


def _discover_arguments(p):
    p.add_argument("data", metavar="DATA", help=_DATA_HELP)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory for report.json, report.md, figures/")
    p.add_argument(
        "--base",
        metavar="EFFECTS",
        default=None,
        help="comma-separated effects already in the base model (default: tensile_stiffness,bending_stiffness)",
    )
    p.add_argument("--specimen", default=None, help="specimen to analyse (default: the first in the file)")
    p.add_argument(
        "--tests",
        nargs="+",
        default=None,
        choices=("load_cycle", "blocking", "stroke", "step"),
        help="tests to use (default: all in the file; a 1 kHz step response is the costly one)",
    )
    p.add_argument("--max-effects", type=int, default=3, help="most effects to add (default: 3)")
    p.add_argument("--seed", type=_seed, default=0, help="seed of the base fit's extra starts and the block tests")


discover_command.arguments = _discover_arguments
