"""The tool's own Table 3 metrics on data from another physics, against what the rig would measure on it.

``experiments/independent_data.py`` fits rig data made by Veale's force-balance model and checks two static
quantities with the study script's own model-discrepancy term. This script asks the same of what a user reads:
``peano-bayes metrics`` (:func:`peano_bayes.analysis.metrics.evaluate_result`) on that fitted result, at each of
``FRACTIONS`` of FC's test pressure, with the discrepancy the tool adds where a fitted test misfits with
structure (``metrics.READ_OFF``). The truth of each metric is what the rig measures on Veale's population muscle
(Table 2 values, one specimen, no noise) under the same protocol at that pressure, by the same Table 3
definitions (:func:`peano_bayes.analysis.metrics.dataset_metrics`), so both sides use one measurement rule (the free
strain, for instance, extrapolates the relaxing load cycle from the start tension to zero force).

The data's load cycles were taken at FC's test pressure (200 kPa) only; at the lower pressures the load-cycle
metrics (free strain, energy) extrapolate the fitted model. The blocking and stroke tests ramp the pressure
through every pressure checked. A check is **in the measured domain** when its metric is read off a test that
measured at that pressure: blocking force per MPa and stroke at every pressure, free strain and energy per MPa
at the test pressure (10 of the 16).

First run exploratory, not pre-registered: on the seed-1 result that ``independent_data.py`` had already
passed on (13 of 16 inside; the 10 in the measured domain all inside).
Pre-registered (2026-11-29, before its run; the criterion was formed on seed 1's exploratory result): the
result of ``independent_data.py --seed 2`` (new data and sampler seed, otherwise its version 2), 100 draws,
metric seed 0, fractions 0.25 0.5 0.75 1.0; pass = every check in the measured domain inside the tool's 94 %
interval (``passed``). The six extrapolated checks are reported as they fall, with no criterion.

    python experiments/independent_data.py --seed 2 --out DIR
    python experiments/independent_metrics.py --result DIR/veale-seed2 [--draws N]

Writes ``metrics_at_<P>kPa.json`` (and ``metrics.json``) into the result directory, as ``peano-bayes metrics``
does; the last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from peano_bayes.analysis.metrics import NOISELESS, dataset_metrics, evaluate_result
from peano_bayes.materials import MATERIALS
from peano_bayes.physics.reference import VEALE_TABLE2, veale_free_strain
from peano_bayes.rig import simulate_veale_dataset

MATERIAL = "FC"
FRACTIONS = (0.25, 0.5, 0.75, 1.0)
#: The metrics a static force-balance model defines (no hysteresis, no dynamics), and the stroke; the free strain
#: both as the muscle's own (what ``metrics`` reports) and as the paper's reading of the load cycles.
QUANTITIES = (
    "blocking_force_per_pressure", "free_strain", "free_strain_paper_reading", "stroke", "energy_per_pressure"
)
#: Metrics read off a test that ramps the pressure (measured at every pressure checked); the others are read off
#: the load cycles, taken at the test pressure only.
MEASURED_AT_EVERY_PRESSURE = ("blocking_force_per_pressure", "stroke")


def rig_truth(pressure_pa: float) -> dict[str, float]:
    """Table 3 metrics [SI] the rig measures on Veale's population muscle (Table 2) at ``pressure_pa``, and its own
    free strain: Veale's static force balance at zero force (:func:`~peano_bayes.physics.reference.
    veale_free_strain`; the rig never reaches zero force, so it measures only the paper's extrapolated reading)."""
    spec = replace(MATERIALS[MATERIAL], test_pressure_pa=pressure_pa)
    truth = dataset_metrics(simulate_veale_dataset(spec, noise=NOISELESS, specimen_spread=0.0, repeats=1, specimens=1))
    return {**truth, "free_strain": float(veale_free_strain(pressure_pa, VEALE_TABLE2))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--result",
        type=Path,
        default=Path("results-independent/veale-seed1"),
        help="the result directory independent_data.py wrote (default results-independent/veale-seed1)",
    )
    parser.add_argument(
        "--draws", type=int, default=1000, help="posterior draws (default 1000, as peano-bayes metrics)"
    )
    args = parser.parse_args()
    if not (args.result / "summary.json").exists():
        raise SystemExit(f"{args.result}: no summary.json; run experiments/independent_data.py first")
    own_kpa = MATERIALS[MATERIAL].test_pressure_pa / 1e3
    rows = []
    for fraction in FRACTIONS:
        kpa = fraction * own_kpa
        common = None if fraction == 1.0 else kpa
        out = evaluate_result(args.result, n_draws=args.draws, progress=False, test_pressure_kpa=common)
        truth = rig_truth(1e3 * kpa)
        for name in QUANTITIES:
            s = out["summary"][name]
            rows.append(
                {
                    "metric": name,
                    "pressure_kpa": kpa,
                    "truth": truth[name],
                    "median": s["median"],
                    "hdi_low": s["hdi_low"],
                    "hdi_high": s["hdi_high"],
                    "inside": bool(s["hdi_low"] <= truth[name] <= s["hdi_high"]),
                    "parameter_hdi_low": s["parameter_hdi_low"],
                    "parameter_hdi_high": s["parameter_hdi_high"],
                    "inside_parameter_interval": bool(s["parameter_hdi_low"] <= truth[name] <= s["parameter_hdi_high"]),
                    "discrepancy_sd": s["discrepancy_sd"],
                    "discrepancy_test": s["discrepancy_test"],
                    "measured_domain": name in MEASURED_AT_EVERY_PRESSURE or fraction == 1.0,
                }
            )
    print(f"{'metric':<30}{'p [kPa]':>8}{'truth':>10}{'median':>10}{'94 %, parameters':>24}{'94 %, tool':>24}  inside")
    for r in rows:
        parameters = f"[{r['parameter_hdi_low']:.4g}, {r['parameter_hdi_high']:.4g}]"
        tool = f"[{r['hdi_low']:.4g}, {r['hdi_high']:.4g}]"
        print(
            f"{r['metric']:<30}{r['pressure_kpa']:>8.0f}{r['truth']:>10.4g}{r['median']:>10.4g}{parameters:>24}"
            f"{tool:>24}  {'yes' if r['inside'] else 'NO'}"
        )
    at_own = [r for r in rows if r["pressure_kpa"] == own_kpa]
    measured = [r for r in rows if r["measured_domain"]]
    report = {
        "result": str(args.result),
        "draws": args.draws,
        "total": len(rows),
        "inside": sum(r["inside"] for r in rows),
        "inside_parameter_interval": sum(r["inside_parameter_interval"] for r in rows),
        "measured_domain": {
            "total": len(measured),
            "inside": sum(r["inside"] for r in measured),
            "inside_parameter_interval": sum(r["inside_parameter_interval"] for r in measured),
        },
        "passed": all(r["inside"] for r in measured),
        # the answer-a-lab-can-act-on check: blocking force per MPa and the muscle's own free strain, every pressure
        "blocking_and_free_strain": {
            "total": sum(r["metric"] in ("blocking_force_per_pressure", "free_strain") for r in rows),
            "inside": sum(r["inside"] for r in rows if r["metric"] in ("blocking_force_per_pressure", "free_strain")),
        },
        "at_test_pressure": {
            "total": len(at_own),
            "inside": sum(r["inside"] for r in at_own),
            "inside_parameter_interval": sum(r["inside_parameter_interval"] for r in at_own),
        },
        "checks": rows,
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
