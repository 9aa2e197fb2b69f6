"""The subcommands of ``peano-bayes``; each is a thin wrapper over the documented Python API."""

from __future__ import annotations

from .cli import command


@command("run", "the main job (for now: a forward-model demo of the default four-tube muscle)")
def run(args):
    from .demo import blocking_and_free_strain

    rows = blocking_and_free_strain(args.pressures_kpa)
    print("Default four-tube Peano muscle (w = 15 mm, l = 49.5 mm), nominal parameters")
    print(f"{'pressure [kPa]':>15} {'blocking force [N]':>19} {'free strain [%]':>16}")
    for row in rows:
        print(f"{row['pressure_kpa']:15.0f} {row['blocking_force_n']:19.1f} {100 * row['free_strain']:16.2f}")
    return {"demo": rows}


run.arguments = lambda p: p.add_argument(
    "--pressures-kpa", type=float, nargs="+", default=[30, 100, 200, 300, 500], metavar="P",
    help="pressures to evaluate [kPa] (default: 30 100 200 300 500)",
)


@command("check", "validate a rig dataset (CSV + TOML sidecar) and summarize it")
def check(args):
    from .data import load

    dataset = load(args.data)
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


check.arguments = lambda p: p.add_argument("data", metavar="DATA.csv", help="the dataset CSV (or its stem)")
