"""How much of each hidden effect the base model can absorb (why some effects are missed at SNR 2).

The benchmark's SNR (peano_bayes.validation.discovery_benchmark) is ``max over tests of RMS(y_with - y_without) /
sigma`` at *equal* base parameters. Discovery, though, sees only what is left after the base model (tensile +
bending stiffness, free) is refitted: the part of the effect's signal the base cannot mimic. This script measures
that part. For each hideable effect at the strength the final benchmark used for SNR 2 (``--strengths``, default the
current final run's ``experiments/discrepancy-14000/strengths.json``), it simulates the harness's rig data with the
load-cell noise shrunk ``--shrink`` times (so the fit sees the same relative weights of force and strain tests but
noise does not blur the misfit), fits the base model from four starts and the base plus the hidden effect from the
truth, and reports per test the RMS of the binned misfit on the fitted and held-out runs, in units of the rig's
per-sample noise at 0.2 N (the SNR's sigma):

- ``snr_nominal``: the benchmark's SNR of that test (signal at equal base parameters);
- ``snr_left_base``: what the refitted base leaves (the signal discovery can see);
- ``snr_left_effect``: what base + the hidden effect leaves: the floor of model error the library cannot
  remove (input denoising, binning), much the same whatever the effect;
- ``snr_visible = sqrt(max(snr_left_base^2 - snr_left_effect^2, 0))``: the effect's own part of the misfit.

``--coupon F1 F2 ...`` asks whether a tensile stiffness known from a coupon test would expose an effect the
base absorbs (series compliance): it adds, per factor F, ``snr_left_coupon_F``, what the base leaves with its
tensile parameters pinned at F times the truth (F = 1 a perfect coupon test, 0.9 / 1.1 one 10 % off) and the
bending parameters refitted from the free base fit.

Writes ``OUT/identifiability.csv`` and ``OUT/IDENTIFIABILITY.md`` (default OUT: ``checks/identifiability`` in
the current final run's folder; ``-snr<SNR>`` added to both names for another SNR or a subset of effects); last
line one JSON object. Tables made with an earlier workflow are in the git history, e.g.
``1555d13:experiments/discrepancy-6000/IDENTIFIABILITY-snr2.md``.

    python experiments/discrepancy_identifiability.py
    python experiments/discrepancy_identifiability.py --snr 8 --effects series_compliance threshold_pressure
    python experiments/discrepancy_identifiability.py --effects series_compliance --coupon 1 0.99 0.97 0.9
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from peano_bayes import enable_compilation_cache
from peano_bayes.atomic import write_text
from peano_bayes.discovery import discovery_data
from peano_bayes.discovery.fitting import evaluate, fit_models
from peano_bayes.discovery.model import DEFAULT_BASE, NAMES, ModelSpec
from peano_bayes.discovery.workflow import fit_base
from peano_bayes.validation.discovery_benchmark import (
    HIDEABLE,
    REFERENCE_FORCE_SD_N,
    Case,
    hidden_dataset,
    reference_sigma,
    snr_by_test,
    strength_for_snr,
    true_model,
)

HERE = Path(__file__).resolve().parent
TENSILE = ("tensile_ka_n_per_m", "tensile_kb_n_per_m2")


def _left(fit, split) -> dict:
    """Per test: RMS of the binned misfit over fitted and held-out runs, in units of the rig's sigma."""
    fit_eval, held_eval = evaluate(fit, split)
    tests = np.concatenate([split.fit_covariates.test, split.held_out_covariates.test])
    error = np.concatenate([fit_eval.error, held_eval.error])
    out = {}
    for test in np.unique(tests):
        e = error[(tests == test) & np.isfinite(error)]
        out[str(test)] = float(np.sqrt(np.mean(e**2))) / reference_sigma(str(test))
    return out


def _coupon_fit(free_base, truth, factor: float, split):
    """The base refitted with its tensile parameters pinned at ``factor`` x their values in ``truth`` (d,) (a
    coupon test)."""
    mask, pinned = free_base.spec.mask.copy(), free_base.spec.pinned.copy()
    for name in TENSILE:
        i = NAMES.index(name)
        mask[i], pinned[i] = False, truth[i] * factor
    spec = ModelSpec(free_base.spec.active, mask, pinned)
    (fit,) = fit_models([spec], [np.where(mask, free_base.x, pinned)], split.fit)
    return fit


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--strengths", default=str(HERE / "discrepancy-14000" / "strengths.json"))
    parser.add_argument("--snr", type=float, default=2.0)
    parser.add_argument("--shrink", type=float, default=100.0, help="noise divisor of the simulated data")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--effects", nargs="+", default=list(HIDEABLE), choices=HIDEABLE, metavar="EFFECT")
    parser.add_argument(
        "--coupon",
        type=float,
        nargs="*",
        default=[],
        metavar="FACTOR",
        help="also fit the base with its tensile stiffness pinned at FACTOR x the truth",
    )
    parser.add_argument("--out", default=str(HERE / "discrepancy-14000" / "checks" / "identifiability"))
    args = parser.parse_args(argv)
    enable_compilation_cache()
    strengths = json.loads(Path(args.strengths).read_text())
    rows = []
    for effect in args.effects:
        start = time.perf_counter()
        # The benchmark's calibrated strength where it has one, else the same calibration run here.
        strength = strengths.get(f"{effect}@{args.snr:g}") or strength_for_snr(effect, args.snr)
        case = Case((effect,), args.snr, force_sd_n=REFERENCE_FORCE_SD_N / args.shrink)
        split = discovery_data(hidden_dataset(case, args.seed, {effect: strength}))
        best_base = fit_base(DEFAULT_BASE, split.fit, starts=4, seed=args.seed)
        true_spec, x0 = true_model(effect, strength)
        (effect_fit,) = fit_models([true_spec], [x0], split.fit)
        left_effect = _left(effect_fit, split) if effect_fit is not None else {}
        left_base = _left(best_base, split)
        left_coupon = {}
        for factor in args.coupon:
            fit = _coupon_fit(best_base, x0, factor, split)
            left_coupon[factor] = _left(fit, split) if fit is not None else {}
        nominal = snr_by_test(effect, strength)
        for test in left_base:
            rows.append(
                {
                    "effect": effect,
                    "test": test,
                    "snr_nominal": nominal[test],
                    "snr_left_base": left_base[test],
                    "snr_left_effect": left_effect.get(test, float("nan")),
                    **{f"snr_left_coupon_{f:g}": c.get(test, float("nan")) for f, c in left_coupon.items()},
                }
            )
        print(
            f"{effect}: nominal max {max(nominal.values()):.2f}, left by the refitted base max "
            f"{max(left_base.values()):.2f} ({time.perf_counter() - start:.0f} s)",
            flush=True,
        )
    table = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table["snr_visible"] = np.sqrt(np.maximum(table.snr_left_base**2 - table.snr_left_effect**2, 0.0))
    suffix = "" if args.snr == 2.0 and args.effects == list(HIDEABLE) else f"-snr{args.snr:g}"
    suffix += "-coupon" if args.coupon else ""
    columns = ["snr_nominal", "snr_left_base", "snr_left_effect", "snr_visible"]
    columns += [c for c in table.columns if c.startswith("snr_left_coupon_")]
    write_text(out / f"identifiability{suffix}.csv", table.to_csv(index=False, float_format="%.4g"))
    summary = table.groupby("effect")[columns].max()
    source = Path(args.strengths).resolve().relative_to(HERE.parent)
    lines = [
        "# How much of each hidden effect the base model absorbs",
        "",
        f"Strengths of SNR {args.snr:g} from `{source}` where it has them, "
        "else calibrated by `strength_for_snr` (the benchmark's bisection); data simulated with "
        f"the load-cell noise divided by {args.shrink:g}; SNR columns in units of the rig's per-sample noise at "
        f"{REFERENCE_FORCE_SD_N} N (max over tests). `snr_left_base`: RMS misfit of the refitted base model "
        "(tensile + bending stiffness), fitted and held-out runs; `snr_left_effect`: of base + the hidden effect "
        "(started at the truth): the model-error floor; `snr_visible`: sqrt(left_base^2 - left_effect^2) per "
        "test, the part of the misfit that is the effect's own. Made by "
        "`experiments/discrepancy_identifiability.py`."
        + (
            " `snr_left_coupon_F`: what the base leaves with its tensile parameters pinned at F times the truth "
            "(a coupon test F - 1 off), bending refitted."
            if args.coupon
            else ""
        ),
        "",
        "| effect | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for effect, r in summary.iterrows():
        lines.append(f"| {effect} | " + " | ".join(f"{r[c]:.2f}" for c in columns) + " |")
    write_text(out / f"IDENTIFIABILITY{suffix}.md", "\n".join(lines) + "\n")
    print(json.dumps({e: round(float(v), 4) for e, v in summary["snr_visible"].items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
