"""Could any gate meet recall and false-positive targets together? A trade-off study on logged runs (issue 6).

Every run of a benchmark logs, per screening round, each candidate's evidence (``OUT/runs-*.jsonl``). This
reads round 0 (the base model alone, where a hidden single effect must first pass and where every false
positive of the no-effect runs starts) and asks two questions, from logged numbers only (no refitting):

1. **One statistic as the only gate** (an ROC): for each hidden effect at each SNR, the candidate of that
   effect scores ``S`` on the runs that hide it; on the no-effect runs (all noise levels) the best-scoring
   physics candidate scores ``S_null``. A gate ``S >= t`` has recall ``P(S >= t)`` and false-positive rate
   ``P(S_null >= t)``. Reported: the recall at the strictest ``t`` whose false-positive rate is <= 0.15, and
   the false-positive rate at the loosest ``t`` whose recall has a Wilson 95 % lower bound >= 0.7.
2. **The gates as run, one dropped at a time**: the share of runs whose hidden effect passes every remaining
   gate, and of no-effect runs where some physics candidate does.

Passing round 0 is necessary for naming an effect, not sufficient (a rival may pass with more evidence), so
these recalls are upper bounds on what the loop would report. Statistics: ``delta_elpd`` (held-out), ``elpd_z``
(its standard errors), ``minus_delta_bic``, ``heldout_gain`` (1 - held-out RMSE ratio), ``signature_removed``
(1 - own-signature ratio), ``strength_wald_ratio`` (Wald statistic over its threshold).

    python experiments/discrepancy_tradeoff.py experiments/discrepancy-6000

Writes ``OUT/tradeoff.csv``, ``OUT/tradeoff_gates.csv`` and ``OUT/TRADEOFF.md``; last line one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from peano_bayes.atomic import write_text
from peano_bayes.discovery.effects import PHYSICS_EFFECTS
from peano_bayes.validation.sbc import wilson_interval

sys.path.insert(0, str(Path(__file__).resolve().parent))
from discrepancy_benchmark import markdown  # noqa: E402

FALSE_POSITIVE_TARGET = 0.15
RECALL_TARGET = 0.7

STATISTICS = {
    "delta_elpd": lambda c: c["delta_elpd"],
    "elpd_z": lambda c: c["delta_elpd"] / c["elpd_se"] if c["elpd_se"] > 0 else np.inf * np.sign(c["delta_elpd"]),
    "minus_delta_bic": lambda c: -c["delta_bic"],
    "heldout_gain": lambda c: 1.0 - c["heldout_rmse_ratio"],
    "signature_removed": lambda c: 1.0 - c["signature_ratio"],
    "strength_wald_ratio": lambda c: c["strength_wald"] / c["strength_wald_threshold"],
}


def load_runs(out: Path) -> list[dict]:
    runs = []
    for log in sorted(out.glob("runs*.jsonl")):
        runs += [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    if not runs:
        raise SystemExit(f"no runs*.jsonl with rows in {out}")
    return runs


def _usable(c: dict | None) -> bool:
    return c is not None and c.get("solver_ok", False) and np.isfinite(c["delta_elpd"])


def _score(c: dict | None, statistic) -> float:
    return float(statistic(c)) if _usable(c) else -np.inf


def _null_runs(runs) -> list[dict]:
    return [r for r in runs if not r["effects"] and not r["drift"]]


def _single_runs(runs) -> dict[tuple[str, float], list[dict]]:
    groups: dict[tuple[str, float], list[dict]] = {}
    for r in runs:
        if len(r["effects"]) == 1 and not r["drift"]:
            groups.setdefault((r["effects"][0], float(r["snr"])), []).append(r)
    return groups


def smallest_count_with_wilson_low(n: int, target: float) -> int | None:
    """Fewest hits of ``n`` whose Wilson 95 % lower bound reaches ``target`` (None if even n of n does not)."""
    return next((k for k in range(n + 1) if wilson_interval(k, n)[0] >= target), None)


def roc_rows(runs) -> list[dict]:
    null = _null_runs(runs)
    rows = []
    for (effect, snr), hits in sorted(_single_runs(runs).items()):
        need = smallest_count_with_wilson_low(len(hits), RECALL_TARGET)
        for name, statistic in STATISTICS.items():
            s = np.array([_score(r["screened"][0].get(effect), statistic) for r in hits])
            s_null = np.array(
                [
                    max(
                        [_score(c, statistic) for e, c in r["screened"][0].items() if e in PHYSICS_EFFECTS] or [-np.inf]
                    )
                    for r in null
                ]
            )
            thresholds = np.unique(np.concatenate([s, s_null, [np.inf]]))
            recall = np.array([np.mean(s >= t) for t in thresholds])
            fp = np.array([np.mean(s_null >= t) for t in thresholds])
            ok = fp <= FALSE_POSITIVE_TARGET
            # the loosest threshold keeping `need` hits: the need-th largest hit score
            t_need = np.sort(s)[::-1][need - 1] if need else np.nan
            k_fp = int(np.sum(s_null >= t_need)) if need else 0
            rows.append(
                {
                    "effect": effect,
                    "snr": snr,
                    "statistic": name,
                    "n_hidden": len(hits),
                    "n_null": len(null),
                    "recall_at_fp_target": float(recall[ok].max()),
                    "hits_needed": need,
                    "fp_rate_at_recall_target": k_fp / len(null) if need else float("nan"),
                    "fp_wilson_high_at_recall_target": wilson_interval(k_fp, len(null))[1] if need else float("nan"),
                }
            )
    return rows


def gate_rows(runs) -> list[dict]:
    null = _null_runs(runs)
    gates = sorted({g for r in runs for c in r["screened"][0].values() for g in c["gates"]})

    def passes(c, dropped):
        return _usable(c) and all(v for g, v in c["gates"].items() if g != dropped)

    def fp(dropped):
        return float(
            np.mean(
                [any(passes(c, dropped) for e, c in r["screened"][0].items() if e in PHYSICS_EFFECTS) for r in null]
            )
        )

    rows = []
    for (effect, snr), hits in sorted(_single_runs(runs).items()):
        for dropped in [None, *gates]:
            rows.append(
                {
                    "effect": effect,
                    "snr": snr,
                    "dropped_gate": dropped or "(none: as run)",
                    "recall_upper": float(np.mean([passes(r["screened"][0].get(effect), dropped) for r in hits])),
                    "fp_rate": fp(dropped),
                }
            )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="a benchmark output directory with runs-*.jsonl")
    args = parser.parse_args(argv)
    out = Path(args.out)
    runs = load_runs(out)
    roc = pd.DataFrame(roc_rows(runs))
    gates = pd.DataFrame(gate_rows(runs))
    write_text(out / "tradeoff.csv", roc.to_csv(index=False, float_format="%.4g"))
    write_text(out / "tradeoff_gates.csv", gates.to_csv(index=False, float_format="%.4g"))
    best = roc.sort_values("recall_at_fp_target", ascending=False).drop_duplicates(["effect", "snr"])
    best = best.sort_values(["effect", "snr"])
    cheapest = roc.sort_values("fp_rate_at_recall_target").drop_duplicates(["effect", "snr"])
    cheapest = cheapest.sort_values(["effect", "snr"])
    as_run = gates[gates.dropped_gate == "(none: as run)"]
    text = [
        "# Recall against false positives: what one gate could do",
        "",
        f"Made by `experiments/discrepancy_tradeoff.py` from round 0 of the {len(runs)} logged runs in this "
        f"directory ({len(_null_runs(runs))} no-effect runs, all noise levels). See the script's docstring for "
        "the method; recalls are upper bounds on what the loop reports (a rival may win).",
        "",
        f"## Best single statistic per effect: recall with the false-positive rate held <= {FALSE_POSITIVE_TARGET}",
        "",
        markdown(best[["effect", "snr", "statistic", "n_hidden", "recall_at_fp_target"]], index=False),
        "",
        f"## Best single statistic per effect: false-positive rate at a recall whose Wilson lower bound is >= "
        f"{RECALL_TARGET}",
        "",
        markdown(
            cheapest[
                [
                    "effect",
                    "snr",
                    "statistic",
                    "hits_needed",
                    "n_hidden",
                    "fp_rate_at_recall_target",
                    "fp_wilson_high_at_recall_target",
                ]
            ],
            index=False,
        ),
        "",
        "## The gates as run, and with one dropped (round 0)",
        "",
        markdown(as_run[["effect", "snr", "recall_upper", "fp_rate"]], index=False),
        "",
        "Every gate dropped in turn: `tradeoff_gates.csv`; every statistic: `tradeoff.csv`.",
    ]
    write_text(out / "TRADEOFF.md", "\n".join(text) + "\n")
    print("\n".join(text))
    summary = {
        f"{r.effect}@{r.snr:g}": {
            "best_recall_at_fp_0.15": round(r.recall_at_fp_target, 3),
            "statistic": r.statistic,
        }
        for r in best.itertuples()
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
