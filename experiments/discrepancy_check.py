"""Discovery on chosen (case, seed) pairs of the hidden-effect harness: a quick check of a workflow change on
runs whose old verdicts are known (tuning evidence, never the final benchmark's seeds).

    python experiments/discrepancy_check.py OUT.jsonl drift:3003 hysteresis:3000 none:3000

A pair is ``LABEL:SEED``; LABEL is ``drift``, ``none`` (force noise 0.2 N), ``none@SD`` (force noise SD [N]) or
hidden effect names joined by ``+`` (at SNR 2, strengths from ``discrepancy/strengths.json``). One JSON line per
run is appended to OUT.jsonl (verdict, accepted steps with their held-out delta elpd, the flexible terms
described, every screened candidate's evidence); one summary line per run is printed.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from peano_bayes import enable_compilation_cache
from peano_bayes.discovery import discover, discovery_data
from peano_bayes.validation.discovery_benchmark import Case, hidden_dataset, score

HERE = Path(__file__).resolve().parent


def case_of(label: str) -> Case:
    if label == "drift":
        return Case(drift=True)
    name, _, sd = label.partition("@")
    if name == "none":
        return Case(force_sd_n=float(sd or 0.2))
    return Case(tuple(label.split("+")), 2.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="JSON-lines file to append to")
    parser.add_argument("pairs", nargs="+", metavar="LABEL:SEED")
    args = parser.parse_args()
    enable_compilation_cache()
    strengths = json.loads((HERE / "discrepancy" / "strengths.json").read_text())
    with open(args.out, "a") as out:
        for pair in args.pairs:
            label, seed = pair.rsplit(":", 1)
            case, seed = case_of(label), int(seed)
            start = time.perf_counter()
            dataset = hidden_dataset(case, seed, {e: strengths[f"{e}@{case.snr:g}"] for e in case.effects})
            report = discover(discovery_data(dataset), seed=seed).report
            row = score(case, report)
            steps = [(s["effect"], round(s["evidence"]["delta_elpd"], 1)) for s in report["steps"]]
            row.update(seed=seed, steps=steps, described=report["described"], screened=report["screened"])
            print(
                f"{label} {seed}: {row['outcome']} (correct {row['correct']}), steps {steps}, "
                f"described {report['described']}, gap {row['gap_ratio']:.2f}, {time.perf_counter() - start:.0f} s",
                flush=True,
            )
            out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
