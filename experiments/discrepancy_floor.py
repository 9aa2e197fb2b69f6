"""Where the model-error floor sits: the misfit base + the true effect leaves, by test and pressure (issue 6).

The identifiability probe (``discrepancy_identifiability.py``) found that base + the hidden effect, fitted from
the truth on data with the load-cell noise shrunk 100 times, still leaves 0.26-0.32 of the rig's force noise in
the blocking test: the floor against which threshold pressure's own 0.32 must show. This script locates it.
It simulates the harness's rig data for ``--effect`` at SNR 2 (load-cell and strain noise / ``--shrink``; the
pressure sensors keep the rig's noise, so input denoising errors stay real), fits base + effect from the truth
with the discovery bins (4 samples in the quasi-static tests) and with one-sample bins, and reports the fitted
runs' residual RMS and mean per test and pressure quintile, in units of the rig's per-sample noise at 0.2 N.
A floor that one-sample bins remove is the bin quadrature (two points per bin, exact only for signals cubic in
time within a bin); one that stays comes from the inputs or the model. Since 4c9a133 the discovery bins of
blocking and stroke are predicted from every sample (``DISCOVERY_EVERY_SAMPLE``), so there only the load cycles
keep two points per bin; the committed ``discrepancy-6000/FLOOR-*`` files were made before, with two points,
and ``discrepancy-8000/FLOOR-*`` with the landed version (``--out experiments/discrepancy-8000``).

    python experiments/discrepancy_floor.py --effect threshold_pressure

``--shrink-pressure F`` divides the pressure sensors' noise too: a floor that falls with it comes from the
pressure inputs.

Writes ``OUT/floor-<effect>[-pressureF].csv`` and ``OUT/FLOOR-<effect>[-pressureF].md``; last line one JSON
object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from peano_bayes import enable_compilation_cache
from peano_bayes.atomic import write_text
from peano_bayes.discovery import discovery_data
from peano_bayes.discovery.data import DISCOVERY_BIN_SIZES
from peano_bayes.discovery.fitting import evaluate, fit_models
from peano_bayes.rig import RigNoise
from peano_bayes.validation.discovery_benchmark import (
    HIDEABLE,
    REFERENCE_FORCE_SD_N,
    Case,
    hidden_dataset,
    reference_sigma,
    true_model,
)

HERE = Path(__file__).resolve().parent
QUASI_STATIC = ("load_cycle", "blocking", "stroke")


def floor_rows(
    effect: str, strength: float, shrink: float, seed: int, bins: str, bin_sizes: dict, pressure_sd_pa: float
) -> list[dict]:
    case = Case((effect,), 2.0, force_sd_n=REFERENCE_FORCE_SD_N / shrink, pressure_sd_pa=pressure_sd_pa)
    split = discovery_data(hidden_dataset(case, seed, {effect: strength}), bin_sizes=bin_sizes)
    spec, start = true_model(effect, strength)
    (fit,) = fit_models([spec], [start], split.fit)
    if fit is None:
        raise SystemExit(f"the fit of base + {effect} failed")
    fit_eval, _ = evaluate(fit, split)
    cov = split.fit_covariates
    rows = []
    for test in QUASI_STATIC:
        here = (cov.test == test) & np.isfinite(fit_eval.error)
        error = fit_eval.error[here] / reference_sigma(test)
        pressure = cov.pressure_pa[here]
        edges = np.unique(np.quantile(pressure, np.linspace(0.0, 1.0, 6)))  # load cycles: two pressures
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            k = (pressure >= lo) & (pressure <= hi)
            rows.append(
                {
                    "effect": effect,
                    "bins": bins,
                    "test": test,
                    "pressure_kpa": f"{lo / 1e3:.0f}-{hi / 1e3:.0f}",
                    "n_bins": int(k.sum()),
                    "rms": float(np.sqrt(np.mean(error[k] ** 2))),
                    "mean": float(np.mean(error[k])),
                }
            )
        rows.append(
            {
                "effect": effect,
                "bins": bins,
                "test": test,
                "pressure_kpa": "all",
                "n_bins": int(here.sum()),
                "rms": float(np.sqrt(np.mean(error**2))),
                "mean": float(np.mean(error)),
            }
        )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effect", default="threshold_pressure", choices=HIDEABLE)
    parser.add_argument("--shrink", type=float, default=100.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--shrink-pressure", type=float, default=1.0, help="divide the pressure sensors' noise too (inputs test)"
    )
    parser.add_argument("--out", default=str(HERE / "discrepancy-6000"))
    args = parser.parse_args(argv)
    enable_compilation_cache()
    out = Path(args.out)
    strength = json.loads((out / "strengths.json").read_text())[f"{args.effect}@2"]
    single = {**DISCOVERY_BIN_SIZES, **{t: 1 for t in QUASI_STATIC}}
    pressure_sd_pa = RigNoise.pressure_sd_pa / args.shrink_pressure
    rows = []
    for bins, sizes in (("discovery", dict(DISCOVERY_BIN_SIZES)), ("one-sample", single)):
        rows += floor_rows(args.effect, strength, args.shrink, args.seed, bins, sizes, pressure_sd_pa)
    table = pd.DataFrame(rows)
    name = args.effect + (f"-pressure{args.shrink_pressure:g}" if args.shrink_pressure != 1.0 else "")
    write_text(out / f"floor-{name}.csv", table.to_csv(index=False, float_format="%.4g"))
    lines = [
        f"# Model-error floor of base + {args.effect} (SNR 2), by test and pressure",
        "",
        f"Made by `experiments/discrepancy_floor.py` (method in its docstring): load-cell and strain noise / "
        f"{args.shrink:g}, pressure noise {pressure_sd_pa:g} Pa (the rig's: {RigNoise.pressure_sd_pa:g}); fitted "
        "runs' residual RMS and mean in units of the rig's "
        "per-sample noise at 0.2 N, per pressure quintile.",
        "",
        "| bins | test | pressure [kPa] | n bins | rms | mean |",
        "|---|---|---|---|---|---|",
    ]
    for r in table.itertuples():
        lines.append(f"| {r.bins} | {r.test} | {r.pressure_kpa} | {r.n_bins} | {r.rms:.3f} | {r.mean:+.3f} |")
    write_text(out / f"FLOOR-{name}.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    overall = table[table.pressure_kpa == "all"]
    print(json.dumps({f"{r.bins}/{r.test}": round(r.rms, 3) for r in overall.itertuples()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
