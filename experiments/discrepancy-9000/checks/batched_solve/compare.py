"""Compare this folder's discrepancy_check.py rows with the same (case, seed) rows of the 9000 run: verdict,
every screened candidate's gates, the gap ratio, and the largest relative change of the evidence figures."""

import glob
import json
import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
PAIRS = ["drift:9001", "drift:9009", "hysteresis:9000", "none@0.1:9003", "cyclic_softening:9020",
         "viscoelastic_relaxation:9005", "hysteresis+flow_restriction:9002", "threshold_pressure:9000"]  # fmt: skip
FIGURES = ("delta_elpd", "delta_bic", "heldout_rmse_ratio", "signature_ratio", "strength_wald")

old = {}
for path in glob.glob(str(HERE.parents[1] / "runs-*.jsonl")):
    for line in open(path):
        r = json.loads(line)
        old[(r["label"] if r["label"] != "none" else f"none@{r['force_sd_n']:g}", r["seed"])] = r
new = [json.loads(line) for line in open(HERE / "runs.jsonl")]
for pair, n in zip(PAIRS, new, strict=True):
    label, seed = pair.rsplit(":", 1)
    o = old[(label, int(seed))]
    assert n["seed"] == int(seed)
    worst, count, gates_same = 0.0, 0, len(o["screened"]) == len(n["screened"])
    for so, sn in zip(o["screened"], n["screened"], strict=False):
        gates_same &= so.keys() == sn.keys()
        for k in so.keys() & sn.keys():
            gates_same &= so[k]["gates"] == sn[k]["gates"]
            for f in FIGURES:
                a, b = so[k][f], sn[k][f]
                if a is not None and b is not None and math.isfinite(a) and math.isfinite(b):
                    worst, count = max(worst, abs(a - b) / max(1.0, abs(a))), count + 1
    print(
        f"{pair}: {n['outcome']} (9000 run: {o['outcome']}), gates identical {gates_same}, "
        f"gap ratio change {abs(n['gap_ratio'] - o['gap_ratio']):.1e}, largest relative change {worst:.1e} "
        f"of {count} evidence figures"
    )
