"""Subcommands on priors and results: ``prior``, ``metrics``, ``rank``, ``recommend``, ``discover``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ... import bundled
from ...defaults import DEFAULT_DRAWS
from ...errors import PeanoBayesInputError
from .registry import _DATA_HELP, _PRESSURE_HELP, _pressure_kpa, _seed, _writable_folder, command


@command("prior", "priors: 'prior new --like CODE --out FILE.toml' writes a starting prior to edit")
def prior_command(args):
    from ...atomic import replacing, write_into
    from ...inference.prior_files import load_prior, starting_prior

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
    p.add_argument(
        "action",
        choices=("new",),
        metavar="new",
        help="write a starting prior that extends a bundled material's prior or another prior file",
    )
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
    from ...analysis.metrics import evaluate_result, metrics_markdown

    if args.draws < 2:
        raise PeanoBayesInputError(f"--draws must be >= 2, got {args.draws}")
    out = evaluate_result(
        args.result,
        n_draws=args.draws,
        seed=args.seed,
        progress=not args.no_progress,
        test_pressure_kpa=_pressure_kpa(args.pressure_kpa),
    )
    print(f"{out['material']}: {out['draws']} posterior draws ({out['n_failed']} failed to simulate)")
    if out["n_failed"]:
        print(f"peano-bayes metrics: WARNING: {_failed_draws(out['n_failed'], out['draws'])}", file=sys.stderr)
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
    return {k: v for k, v in out.items() if k != "draw_values"}


def _failed_draws(n_failed: int, n_drawn: int) -> str:
    return (
        f"{n_failed} of {n_drawn} posterior draws could not be simulated; the metrics rest on the other "
        f"{n_drawn - n_failed}, the parameters the model simulates most easily, not a random subset"
    )


def _metrics_arguments(p):
    p.add_argument("result", metavar="RESULT", help="a result directory of 'peano-bayes fit' (or its posterior.nc)")
    p.add_argument(
        "--draws", type=int, default=DEFAULT_DRAWS, help=f"posterior draws simulated (default: {DEFAULT_DRAWS})"
    )
    p.add_argument(
        "--seed",
        type=_seed,
        default=0,
        help="seed of the draws (prior values of unfitted parameters, model discrepancy) (default: 0)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--pressure-kpa", type=float, default=None, metavar="KPA", help=_PRESSURE_HELP)


metrics_command.arguments = _metrics_arguments


@command("rank", "design ranking with uncertainty across results (needs each result's metrics.json)")
def rank_command(args):

    from ...analysis.metrics import evaluate_result, metrics_current, metrics_file, previous_draws, read_metrics
    from ...analysis.ranking import failed_draw_counts, rank_materials, ranking_markdown
    from ...atomic import write_text

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
    draws = {m["material"]: m["draw_values"] for m in metrics}
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

    from ...analysis.recommend import recommend, recommendation_markdown
    from ...atomic import write_text
    from ...report.figures import recommendation_figure

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
    from ...data import load
    from ...discovery import DEFAULT_BASE, Gates, discover, discovery_data, write_report
    from ...discovery.choice import base_least_squares
    from ...effects import check_effects, flexible_terms
    from ..pipeline import prior_of

    named = None if args.base is None else [n.strip() for item in args.base for n in item.split(",") if n.strip()]
    if named == []:
        raise PeanoBayesInputError(f"--base: expected effect names (space- or comma-separated), got {args.base!r}")
    try:
        base = check_effects(named) if named is not None else DEFAULT_BASE
    except PeanoBayesInputError as err:
        raise PeanoBayesInputError(f"--base: {err}") from None
    if args.max_effects < 1:
        raise PeanoBayesInputError(f"--max-effects must be >= 1, got {args.max_effects}")
    _writable_folder(args.out, "--out")
    dataset = load(bundled.resolve_dataset(args.data))  # validate before anything is written
    split = discovery_data(dataset, specimen=args.specimen, tests=args.tests)

    try:  # a prior the user named is checked before anything is said or run
        whole_prior, no_prior = prior_of(dataset, args.prior), None
    except PeanoBayesInputError as err:
        if args.prior is not None:
            raise
        whole_prior, no_prior = None, err

    def say(line):
        print(line, flush=True)

    say(
        f"{len(split.fit_runs)} fitted and {len(split.held_out_runs)} held-out runs of specimen {split.specimen} "
        "(the first fit compiles the model: a few minutes)"
    )
    start = None
    if whole_prior is None:
        say(f"no prior for material {dataset.material.code}, so the base fit uses discovery's own multi-start "
            f"search, not fit's least squares ({no_prior}); --prior FILE.toml gives it one")  # fmt: skip
    else:
        say(f"base model {'+'.join(base)}: the inference least squares (fit's starts and solver) ...")
        fitted = base_least_squares(
            dataset, base, whole_prior, specimen=split.specimen, tests=args.tests, seed=args.seed
        )
        say(f"least squares done in {fitted.seconds:.1f} s ({fitted.outcome()}); discovery's base fit starts there")
        start = fitted.params
    gates = Gates(max_effects=args.max_effects)
    result = discover(split, base=base, gates=gates, seed=args.seed, progress=say, start=start)
    written = write_report(result, Path(args.out))
    report = result.report
    say(f"verdict: {report['verdict']}" + (f" ({', '.join(report['named'])})" if report["named"] else ""))
    flexible = [d for d in report["described"] if d in flexible_terms()]
    unnamed = [d for d in report["described"] if d not in flexible and d not in report.get("withheld", [])]
    if flexible:
        say(f"slow structure over the session, described by {', '.join(flexible)}, names no effect")
    if unnamed:
        say(f"described without its own signature's evidence, not named: {', '.join(unnamed)}")
    if report.get("withheld"):
        say(f"not named while structure is left that the library does not remove: {', '.join(report['withheld'])}")
    say(f"wrote {', '.join(str(p) for p in written)}")
    return report


def _discover_arguments(p):
    p.add_argument("data", metavar="DATA", help=_DATA_HELP)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory for report.json, report.md, figures/")
    p.add_argument(
        "--base",
        nargs="+",
        action="extend",
        metavar="EFFECT",
        default=None,
        help="effects already in the base model, space-separated like the other list options (commas also work; "
        "default: tensile_stiffness bending_stiffness)",
    )
    p.add_argument(
        "--prior",
        metavar="FILE|CODE",
        default=None,
        help="prior whose starts the base model's least squares draws, as fit does (default: the bundled prior of "
        "the data's material code; without one, discovery's own multi-start search)",
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
    p.add_argument(
        "--seed", type=_seed, default=0, help="seed of the base fit's extra starts and the block tests (default: 0)"
    )


discover_command.arguments = _discover_arguments


__all__ = ["discover_command", "metrics_command", "prior_command", "rank_command", "recommend_command"]
