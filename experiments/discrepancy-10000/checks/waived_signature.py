"""Would a stricter own-signature gate have kept strain stiffening out of the pair? (read from the logged rows only)

Gate 3 (``own_signature``) is waived when the effect's signature was not visible before (``T_before <
min_signature``). In the 10000 run, 3 of 22 pair runs (hysteresis + flow restriction) added strain stiffening.
This lists every accepted step that passed with the gate waived although its own signature grew
(``T_after / T_before > 1``), with the hidden case and whether the run was scored right: the steps a rule
"a waived signature must not grow" would have refused. The accepted effect of a round is the passing candidate
that is never screened again (it is then in the model). No refit: later rounds would change, so this bounds
which runs the rule touches, not what they would end as.

    python experiments/discrepancy-10000/checks/waived_signature.py
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

from peano_bayes.discovery.workflow import Gates

RUN = Path(__file__).resolve().parents[1]

sys.path.insert(0, str(RUN.parent))
from discrepancy_benchmark import log_rows, run_logs  # noqa: E402


def refused_steps(rows: list[dict], min_signature: float = Gates.min_signature) -> list[tuple]:
    out = []
    for row in rows:
        accepted = set(row["named"]) | set(row["noise_model"])
        for i, screened in enumerate(row["screened"]):
            later = set().union(*map(set, row["screened"][i + 1 :]))
            for effect, ev in screened.items():
                if (
                    ev["passed"]
                    and effect in accepted
                    and effect not in later
                    and ev["signature_before"] < min_signature
                    and ev["signature_ratio"] > 1.0
                ):
                    out.append((row["label"], row["seed"], effect, round(ev["signature_ratio"], 2), row["correct"]))
    return out


def main() -> None:
    rows = [row for log in run_logs(RUN) for row in log_rows(log)]
    steps = refused_steps(rows)
    print("hidden case | seed | accepted effect | T_after/T_before | run scored right")
    for step in steps:
        print(" | ".join(map(str, step)))
    tally = Counter((label, effect, right) for label, _, effect, _, right in steps)
    print(
        json.dumps({"rows": len(rows), "refused_steps": len(steps), "by_case": {str(k): v for k, v in tally.items()}})
    )


if __name__ == "__main__":
    main()
