"""Re-run recorded rows of a discovery benchmark run with the code on the path, and compare them with the record.

A final run is made on the workflow code of one commit; the package then moves on. This shows whether the
discovery the package runs today (``peano-bayes discover``, and ``run``'s model choice) is still the version the
run measured: each chosen row's case and seed are re-run (``run_case``, the run's strengths) and compared field
by field with the recorded row: every verdict, named effect, screen outcome and other non-numeric field must be
equal; numbers are compared by relative difference. Re-running the run's own commit gives the size of the
differences that thread count and timing alone make (float summation order in the fits), the yardstick for the
rest.

Writes nothing; prints one line per row and, last, one JSON object (per key: whether every non-numeric field
is equal, the number of numeric fields that differ and the largest relative difference).

    python experiments/discrepancy_rerun.py --run experiments/discrepancy-14000 \\
        --keys "strain_stiffening|2|0.2|0|14001" "none-veale|0|0.2|0|14003"
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from discrepancy_benchmark import case_of_row, log_rows, run_logs

from peano_bayes import enable_compilation_cache
from peano_bayes.validation.discovery_benchmark import run_case

#: Fields that differ on every run by design.
IGNORED = frozenset({"seconds"})


def differences(recorded, rerun, path: str = "") -> tuple[list[str], list[tuple[str, float]]]:
    """Where ``rerun`` differs from ``recorded`` (JSON-like values): non-numeric paths (with a number that is
    NaN or infinite on one side only), and numeric paths with their relative difference |a - b| / max(|a|, |b|).
    NaN equals NaN; an int and a float of equal value agree. Numeric entries are (path, relative difference,
    recorded, rerun): a quantity at round-off of zero (an effect's gain where it has none) can differ by more
    than itself, so the worst entries are printed with their values."""
    exact, numeric = [], []
    if isinstance(recorded, dict) and isinstance(rerun, dict):
        for k in sorted(set(recorded) | set(rerun)):
            if k in IGNORED:
                continue
            if k not in recorded or k not in rerun:
                exact.append(f"{path}/{k} (missing)")
                continue
            e, n = differences(recorded[k], rerun[k], f"{path}/{k}")
            exact += e
            numeric += n
    elif isinstance(recorded, list) and isinstance(rerun, list):
        if len(recorded) != len(rerun):
            return [f"{path} (length {len(recorded)} vs {len(rerun)})"], []
        for i, (a, b) in enumerate(zip(recorded, rerun, strict=True)):
            e, n = differences(a, b, f"{path}[{i}]")
            exact += e
            numeric += n
    elif _number(recorded) and _number(rerun) and (isinstance(recorded, float) or isinstance(rerun, float)):
        a, b = float(recorded), float(rerun)
        if a == b or (math.isnan(a) and math.isnan(b)):
            pass
        elif math.isfinite(a) and math.isfinite(b):
            numeric.append((path, abs(a - b) / max(abs(a), abs(b)), a, b))
        else:  # NaN or infinite on one side only: a change of kind, not of round-off
            exact.append(f"{path} ({a!r} vs {b!r})")
    elif recorded != rerun:
        exact.append(path)
    return exact, numeric


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, help="a discovery benchmark run's folder")
    parser.add_argument("--keys", nargs="+", required=True, metavar="KEY", help="row keys (label|snr|noise|drift|seed)")
    args = parser.parse_args(argv)
    run = Path(args.run)
    if not (run / "strengths.json").is_file() or not run_logs(run):
        parser.error(f"{run} is not a benchmark run's folder: expected strengths.json and runs*.jsonl[.gz] in it")
    recorded = {r["key"]: r for log in run_logs(run) for r in log_rows(log)}
    missing = [k for k in args.keys if k not in recorded]
    if missing:
        parser.error(f"no row with key {missing[0]!r} in {run}")
    strengths = json.loads((run / "strengths.json").read_text())
    by_key = {}
    for key in args.keys:
        try:
            by_key[key] = case_of_row(recorded[key])
        except KeyError as err:
            parser.error(err.args[0])
    enable_compilation_cache()
    summary = {}
    for key in args.keys:
        case, seed = by_key[key], int(recorded[key]["seed"])
        # rows recorded before the base started at the inference least squares carry no base_start
        from_ls = recorded[key].get("base_start") == "inference_least_squares"
        chosen = {e: strengths[f"{e}@{case.snr:g}"] for e in case.effects}
        row = run_case(case, seed, chosen, least_squares_start=from_ls)
        row = json.loads(json.dumps(row, default=float))  # as the run wrote it
        exact, numeric = differences(recorded[key], row)
        worst = sorted(numeric, key=lambda t: -t[1])[:3]
        summary[key] = {
            "same_verdicts_and_names": not exact,
            "numeric_differences": len(numeric),
            "max_relative": worst[0][1] if worst else 0.0,
        }
        shown = "; ".join(f"{p} {a:.3g} vs {b:.3g}" for p, _, a, b in worst) or "-"
        print(
            f"{key}: outcome {row['outcome']} (recorded {recorded[key]['outcome']}); non-numeric differences: "
            f"{exact[:5] or 'none'}; {len(numeric)} numbers differ, the most (relative) {shown}; "
            f"{row['seconds']:.0f} s",
            flush=True,
        )
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
