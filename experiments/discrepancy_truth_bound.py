"""What the held-out gap target asks of the data: the true model fitted from the truth, scored as the benchmark scores.

The discovery benchmark scores a correct detection by ``after / before``: the held-out RMSE of the final
model's prediction against the **noise-free truth** over that of the refitted base, on the hidden effect's
scored test (``peano_bayes.validation.discovery_benchmark.truth_gap``; target <= 0.5). A correct detection's
final model is the base plus the true effect, fitted by the workflow from its own start. This script refits, on
the **same** noisy session of a run's row (same case, seed and strength), the base exactly as discovery does
(``fit_base``, same starts and seed: its ``before`` must match the row's) and the true model started at the
**generating values** (``true_model``: the hidden effect's strength and the rig's nominal material; the session's
specimen is a draw around them) and continued while it stops at the step limit and improves, as the base fit
is, and scores both with the benchmark's own ``truth_gap``. A true-model fit that still stops at the step limit
is reported and left out of the counts.

- ``true_ratio`` at or below 0.5 where the row's ``ratio`` is above it: the workflow's fit of the right model
  fell short of what the data allow (a fitting defect).
- ``true_ratio`` above 0.5 too: no workflow can meet the target on that session; what is left of the effect once
  the base has absorbed what it can (the row's effective SNR) is too small against the estimation noise.

Rows: the run's correct single-effect detections of ``--effects`` (default: every effect with one) that name
exactly the hidden effect (an ``ambiguous`` verdict counts as correct in the benchmark, but its final model may
hold the rival) and carry a truth-scored gap (runs scored before it have none), those above 0.5 first, at most
``--per-effect`` of each. Writes ``RUN/checks/truth_bound/truth_bound.csv`` and
``TRUTH_BOUND.md``; resumable (rows already in the CSV are kept); the last line is one JSON object (per effect:
rows checked, how many the true model brings to <= 0.5, how many the run's fits did).

    python experiments/discrepancy_truth_bound.py --run experiments/discrepancy-14000 --per-effect 8
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
from discrepancy_benchmark import case_of_row, log_rows, run_logs

from peano_bayes import enable_compilation_cache
from peano_bayes.atomic import write_text
from peano_bayes.discovery import discovery_data
from peano_bayes.discovery.fitting import evaluate, fit_models
from peano_bayes.discovery.model import DEFAULT_BASE
from peano_bayes.discovery.workflow import BASE_CONTINUATIONS, Discovery, Gates, fit_base
from peano_bayes.effects import hideable
from peano_bayes.validation.discovery_benchmark import hidden_dataset, run_key, true_model, truth_gap

HERE = Path(__file__).resolve().parent
TARGET = 0.5


def candidate_rows(run: Path, effects, per_effect: int) -> list[dict]:
    """The run's correct single-effect detections of ``effects`` that name exactly the hidden effect and have a
    finite truth-scored gap: per effect the misses of the target first (largest ratio first), then the rest, at
    most ``per_effect``."""
    rows = [r for log in run_logs(run) for r in log_rows(log)]
    rows = [
        r
        for r in rows
        if r["correct"]
        and len(r["effects"]) == 1
        and r["outcome"] == r["effects"][0]
        and r.get("truth_gap")
        and np.isfinite(r["gap_ratio"])
    ]
    chosen = []
    for effect in sorted({r["effects"][0] for r in rows} & set(effects or {r["effects"][0] for r in rows})):
        mine = sorted((r for r in rows if r["effects"][0] == effect), key=lambda r: -r["gap_ratio"])
        chosen += mine[:per_effect]
    return chosen


def check_row(row: dict, strengths: dict) -> dict:
    """The base as discovery fits it and the true model from the truth, on ``row``'s session, scored by
    :func:`truth_gap`; beside the row's own figures."""
    effect, seed, case = row["effects"][0], int(row["seed"]), case_of_row(row)
    assert run_key(case, seed) == row["key"]
    strength = {effect: strengths[f"{effect}@{case.snr:g}"]}
    split = discovery_data(hidden_dataset(case, seed, strength))
    base = fit_base(DEFAULT_BASE, split.fit, starts=Gates.base_starts, seed=seed)
    spec, x0 = true_model(effect, strength[effect])
    (truth_fit,) = fit_models([spec], [x0], split.fit)
    for _ in range(BASE_CONTINUATIONS):  # as fit_base goes on with a start stopped at the step limit
        if truth_fit is None or truth_fit.converged:
            break
        (more,) = fit_models([truth_fit.spec], [truth_fit.x], split.fit)
        if more is None or not more.cost < truth_fit.cost - 1e-6 * max(1.0, truth_fit.cost):
            break
        truth_fit = more
    if truth_fit is None:
        raise RuntimeError(f"the true model's fit failed on {row['key']}")
    (fit_before, held_before), (fit_after, held_after) = evaluate(base, split), evaluate(truth_fit, split)
    result = Discovery({}, split, fit_before, fit_after, held_before, held_after)
    mine = truth_gap(case, seed, result, strength)["truth_gap"][effect]
    theirs = row["truth_gap"][effect]
    return {
        "key": row["key"],
        "effect": effect,
        "seed": seed,
        "test": mine["test"],
        "effective_snr": theirs["effective_snr"],
        "run_before": theirs["before"],
        "run_after": theirs["after"],
        "run_ratio": theirs["ratio"],
        "before": mine["before"],
        "true_after": mine["after"],
        "true_ratio": mine["ratio"],
        "true_cost": truth_fit.cost,
        "true_converged": bool(truth_fit.converged),
    }


def table_md(table: pd.DataFrame, run: Path) -> str:
    lines = [
        "# The held-out gap the true model reaches on the run's own sessions",
        "",
        f"Made by `experiments/discrepancy_truth_bound.py` (method in its docstring) on rows of `{run.name}`: per "
        "correct detection, the base refitted as discovery does and the true model fitted from the generating "
        "values, both scored against the noise-free truth on the effect's scored test. `before` is the "
        "recomputed base's (it should equal the run's). Counts: rows at or below the 0.5 target; the true "
        "model's counts and median leave out fits that stopped at the step limit (`unconverged`).",
        "",
        "| effect | rows | run <= 0.5 | true model <= 0.5 | unconverged | run ratio (median) "
        "| true ratio (median) | effective SNR (median) | max rel. diff. of before |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for effect, g in table.groupby("effect"):
        drift = float(np.max(np.abs(g["before"] - g["run_before"]) / g["run_before"]))
        ok = g[g["true_converged"].astype(bool)]
        lines.append(
            f"| {effect} | {len(g)} | {int((g['run_ratio'] <= TARGET).sum())} | "
            f"{int((ok['true_ratio'] <= TARGET).sum())}/{len(ok)} | {len(g) - len(ok)} | "
            f"{g['run_ratio'].median():.2f} | {ok['true_ratio'].median():.2f} | {g['effective_snr'].median():.2f} "
            f"| {drift:.1e} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, help="a discovery benchmark run's folder (runs*.jsonl, strengths.json)")
    parser.add_argument(
        "--effects", nargs="+", default=None, choices=tuple(hideable()), metavar="EFFECT",
        help="default: every detected one",
    )
    parser.add_argument("--per-effect", type=int, default=8, help="rows per effect, misses of the target first")
    args = parser.parse_args(argv)
    run = Path(args.run)
    strengths_path = run / "strengths.json"
    if not strengths_path.is_file() or not run_logs(run):
        parser.error(f"{run} is not a benchmark run's folder: expected strengths.json and runs*.jsonl[.gz] in it")
    enable_compilation_cache()
    strengths = json.loads(strengths_path.read_text())
    out = run / "checks" / "truth_bound"
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "truth_bound.csv"
    done = pd.read_csv(csv) if csv.exists() else pd.DataFrame()
    records = done.to_dict("records")
    checked = set(done.get("key", []))
    todo = [r for r in candidate_rows(run, args.effects, args.per_effect) if r["key"] not in checked]
    print(f"{len(records)} rows done, {len(todo)} to check", flush=True)
    for i, row in enumerate(todo, 1):
        start = time.perf_counter()
        rec = check_row(row, strengths)
        records.append(rec)
        write_text(csv, pd.DataFrame(records).to_csv(index=False))  # full precision: the base check reads it back
        print(
            f"[{i}/{len(todo)}] {row['key']}: run ratio {rec['run_ratio']:.2f}, true model {rec['true_ratio']:.2f} "
            f"(before {rec['before']:.4g} vs the run's {rec['run_before']:.4g}), {time.perf_counter() - start:.0f} s",
            flush=True,
        )
    table = pd.DataFrame(records)
    if table.empty:
        print(json.dumps({}))
        return 0
    write_text(out / "TRUTH_BOUND.md", table_md(table, run))
    print(table_md(table, run))
    summary = {
        effect: {
            "rows": len(g),
            "run_at_most_half": int((g["run_ratio"] <= TARGET).sum()),
            "true_at_most_half": int((g["true_ratio"][g["true_converged"].astype(bool)] <= TARGET).sum()),
            "true_unconverged": int((~g["true_converged"].astype(bool)).sum()),
        }
        for effect, g in table.groupby("effect")
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
