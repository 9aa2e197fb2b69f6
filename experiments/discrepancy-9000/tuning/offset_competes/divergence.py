"""Which 9000-run rows the new acceptance rule changes, and the whole run's counts with it.

The old rule took the passing candidate with the largest held-out gain among physics effects and the session
baseline, a noise model only when neither passed; the new one lets the sensor's offset and gain compete on gain
too (heteroscedastic noise still only when nothing else passes). Both rules choose from the same screened
evidence, so a row whose every logged round picks the same winner under both rules runs identically; the rows
where some round picks differently (``pairs.txt``) were rerun with the new rule (``runs.jsonl``, via
``experiments/discrepancy_check.py``). This prints those pairs, then per case: correct under the old rule
(the 9000 run) and under the new (old rows, with the rerun rows replaced)."""

import glob
import json
from collections import Counter
from pathlib import Path

from peano_bayes.discovery.effects import NOISE_EFFECTS, WIDENING_NOISE

HERE = Path(__file__).resolve().parent


def pick(passing: dict, new: bool) -> str:
    preferred = [c for c in passing if c not in (WIDENING_NOISE if new else NOISE_EFFECTS)]
    return max(preferred or list(passing), key=passing.get)


def case(row) -> str:
    return row["label"] if row["label"] != "none" else f"none@{row['force_sd_n']:g}"


rows = [json.loads(line) for p in glob.glob(str(HERE.parents[1] / "runs-*.jsonl")) for line in open(p)]
diverged = []
for row in sorted(rows, key=lambda r: (case(r), r["seed"])):
    for screened in row["screened"]:
        passing = {k: v["delta_elpd"] for k, v in screened.items() if v["passed"]}
        if not passing:
            break
        if pick(passing, False) != pick(passing, True):
            diverged.append(f"{case(row)}:{row['seed']}")
            break
print("rows whose decisions change:", " ".join(diverged))
rerun = {f"{r['label']}:{r['seed']}": r for r in map(json.loads, open(HERE / "runs.jsonl"))}
assert set(rerun) == set(diverged), "runs.jsonl must hold exactly the changed rows"
old, new = Counter(), Counter()
for row in rows:
    key = f"{case(row)}:{row['seed']}"
    old[case(row)] += row["correct"]
    new[case(row)] += rerun[key]["correct"] if key in rerun else row["correct"]
    if key in rerun:
        print(f"  {key}: {row['outcome']} -> {rerun[key]['outcome']}")
for name in sorted(old):
    print(f"{name}: {old[name]}/22 -> {new[name]}/22")
