"""Subcommands on data: ``demo`` (the forward model), ``check`` (validate a rig file), ``simulate`` (the
virtual rig)."""

from __future__ import annotations

import sys
from pathlib import Path

from ... import bundled
from ...defaults import MAX_PRESSURE_KPA
from ...errors import PeanoBayesInputError
from .registry import _DATA_HELP, _pressure_kpa, _seed, _writable_folder, command


@command("demo", "forward-model demo: blocking force and free strain of the default four-tube muscle")
def demo(args):
    from ..demo import blocking_and_free_strain

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
    help=f"pressures to evaluate [kPa], each above 0 and at most {MAX_PRESSURE_KPA:g} (default: 30 100 200 300 500)",
)


@command("check", "validate a rig dataset (CSV + TOML sidecar) and summarize it")
def check(args):
    from ...data import load

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
    warnings = []
    highest_kpa = max(float(r.pressure_pa.max()) for r in dataset.runs) / 1e3
    if highest_kpa > MAX_PRESSURE_KPA:  # valid data, but past what the answers are offered for
        warnings.append(
            f"pressures reach {highest_kpa:g} kPa, above the {MAX_PRESSURE_KPA:g} kPa to which metrics "
            "(--pressure-kpa), recommend and demo predict; a fit there extrapolates the bundled priors, which rest "
            "on tests to 200 kPa"
        )
    for warning in warnings:
        print(f"peano-bayes check: WARNING: {warning}", file=sys.stderr)
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
        "warnings": warnings,
    }


check.arguments = lambda p: p.add_argument("data", metavar="DATA", help=_DATA_HELP)


#: Suffixes of other file types, refused at the end of ``simulate --out`` (any other dotted word is part of a stem).
_OTHER_FILE_TYPES = (".txt", ".dat", ".json", ".tsv", ".xls", ".xlsx", ".nc", ".npz", ".npy", ".h5", ".hdf5",
                     ".parquet", ".md", ".log", ".zip", ".tar", ".gz", ".bz2", ".xz", ".pkl", ".bak")  # fmt: skip


@command("simulate", "the virtual rig: write a dataset (CSV + TOML sidecar) simulated from given parameters")
def simulate(args):
    from ...data import dataset_paths, save
    from ...rig import read_parameter_file, simulate_dataset

    params, config = read_parameter_file(args.params) if args.params else ({}, None)
    out = Path(args.out)
    if out.suffix.lower() in _OTHER_FILE_TYPES:  # x.txt would become x.txt.csv; a stem like FC.v2 is a stem
        stem = out
        while stem.suffix.lower() in (*_OTHER_FILE_TYPES, ".csv"):
            stem = stem.with_suffix("")
        raise PeanoBayesInputError(
            f"--out: {args.out} ends in {out.suffix!r}, another file type; a dataset is written as PATH.csv with "
            f"its PATH.toml sidecar: give {stem}.csv (or {args.out}.csv to keep the suffix in the name)"
        )
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
    p.add_argument(
        "--specimens", type=int, default=2, help="specimens per material, 1 to 26 (default: 2, as in the paper)"
    )
    p.add_argument(
        "--repeats", type=int, default=3, help="repeats of each test, 1 to 100 (default: 3, as in the paper)"
    )
    p.add_argument("--force", action="store_true", help="replace an existing dataset at --out")


simulate.arguments = _simulate_arguments


__all__ = ["check", "demo", "simulate"]
