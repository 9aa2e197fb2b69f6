"""Re-score a benchmark's logged candidates under the current identification gate.

Every screened candidate of every run in ``OUT/runs-*.jsonl[.gz]`` carries its evidence and gate results. This
recomputes gate 6 (:func:`peano_bayes.discovery.workflow.identified`) from the logged correlation and held-out
elpd, keeps the other gates as logged, and counts the candidates whose pass/fail would change. If none changes,
the run's every decision, and so its verdicts and tables, are the same under the current gates; on a run logged
before a change of gate 6 it shows what the change would have rejected or let through.

    python experiments/discrepancy_rescore.py experiments/discrepancy-14000

Last line: one JSON object, per directory the number of runs, candidates, and flips (with their keys).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from discrepancy_benchmark import log_rows, run_logs

from peano_bayes.discovery.workflow import Gates, identified


def rescore(out: Path, gates: Gates | None = None) -> dict:
    gates = gates or Gates()
    runs = candidates = 0
    flips = []
    for row in (row for log in run_logs(out) for row in log_rows(log)):
        runs += 1
        for step, screened in enumerate(row.get("screened", [])):
            for name, ev in screened.items():
                candidates += 1
                others = all(v for k, v in ev["gates"].items() if k != "identified")
                now = others and identified(ev["max_correlation_with_base"], ev["delta_elpd"], ev["elpd_se"], gates)
                if now != ev["passed"]:
                    flips.append(f"{row['key']} step {step} {name}: {'passes' if now else 'fails'} now")
    return {"runs": runs, "candidates": candidates, "flips": len(flips), "flipped": flips}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dirs", nargs="+", type=Path)
    args = parser.parse_args(argv)
    result = {}
    for out in args.dirs:
        r = result[str(out)] = rescore(out)
        print(f"{out}: {r['runs']} runs, {r['candidates']} candidates, {r['flips']} change", flush=True)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
