"""Re-run one no-effect benchmark case on seed 6016 with whatever workflow is on PYTHONPATH; print its verdict and
flow restriction's first-round screening figures (diagnosis of the 6000 run's spurious flow restriction).

    PYTHONPATH=<checkout> python experiments/discrepancy-6000/seed6016/rerun_none.py 0.2   # force noise [N]
"""

import json
import sys
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(EXPERIMENTS))

from discrepancy_benchmark import _one  # noqa: E402

from peano_bayes.discovery.harness import Case  # noqa: E402

strengths = json.loads((EXPERIMENTS / "discrepancy-6000" / "strengths.json").read_text())
row = _one(Case((), 0.0, force_sd_n=float(sys.argv[1])), 6016, strengths)
keep = ("delta_elpd", "elpd_se", "delta_bic", "passed", "gates")
flow = {k: v for k, v in row["screened"][0]["flow_restriction"].items() if k in keep}
print(row["outcome"], json.dumps({"flow_restriction": flow}))
