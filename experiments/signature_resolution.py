"""How fine the blocks of the signature test must be for a hidden effect's own signature to reach significance
after Holm, and what finer blocks cost on the nulls: a tuning measurement for the rule that discovery names an
effect only on its own signature's evidence.

The block sign-flip test (:func:`peano_bayes.discovery.diagnose.sign_flip_p`) cannot give a p-value below about
``2^-B`` when a signature's weight lies in ``B`` blocks of consecutive bins; with Holm's correction over the 14
signatures, a signature confined to ten blocks cannot be significant at 0.01 however large its ``T``. This script
fits discovery's base model (as :func:`~peano_bayes.discovery.workflow.discover` does, its own multi-start) to
fresh sessions of the benchmark's cases and reads its first diagnosis with sign-flip blocks of ``k`` bins for each
``k`` of ``--block-bins``, once with fixed patterns for every signature but relaxation's (arm ``k``: what discovery
read after its relaxation signature changed) and once with every physics effect's signature read along its own
direction (:func:`~peano_bayes.discovery.workflow.matched_weights` for all of them, one-sided; arm ``own<k>``).
Per case and arm, the share of sessions whose hidden effect's registry signature is significant after Holm, and
the share whose any physics effect's signature is (on the nulls: what finer blocks would let through).

    python experiments/signature_resolution.py --out DIR --seeds 3 --first-seed 20005

Tuning seeds only. Resumable from ``DIR/rows.jsonl``; the last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from discrepancy_benchmark import cases

from peano_bayes import enable_compilation_cache
from peano_bayes.discovery import discovery_data
from peano_bayes.discovery.diagnose import diagnose
from peano_bayes.discovery.fitting import evaluate
from peano_bayes.discovery.model import DEFAULT_BASE
from peano_bayes.discovery.workflow import Gates, fit_base, matched_weights
from peano_bayes.effects import LIBRARY, hideable, physics_effects
from peano_bayes.stats import holm
from peano_bayes.validation.discovery_benchmark import hidden_dataset, run_key

DEFAULT_CASES = (*hideable(), "none", "none-veale")


def row(case, seed: int, strengths: dict, block_bins) -> dict:
    dataset = hidden_dataset(case, seed, {e: strengths[f"{e}@{case.snr:g}"] for e in case.effects})
    split = discovery_data(dataset)
    base = fit_base(DEFAULT_BASE, split.fit, starts=Gates.base_starts, seed=seed)
    fit_eval, _ = evaluate(base, split)
    matched = matched_weights(base, split, names={"relaxation"})  # the first change: relaxation alone
    out = {"key": run_key(case, seed), "case": case.label, "seed": seed, "by_block": {}}
    signatures = sorted({LIBRARY[e].signature for e in physics_effects() if e not in DEFAULT_BASE})
    every = matched_weights(base, split, names=signatures)  # every physics effect read along its own direction
    arms = [(str(k), k, matched) for k in block_bins] + [(f"own{k}", k, every) for k in block_bins]
    for label, k, weights in arms:
        cov = split.fit_covariates
        d = diagnose(fit_eval.r, cov, fit_eval.predicted, alpha=Gates.alpha, seed=seed, matched=weights, block_bins=k)
        out["by_block"][label] = {
            s: {"T": d.statistic[s], "p": d.p_value[s], "p_holm": d.p_holm[s]} for s in signatures
        }
    return out


def summary(rows: list[dict]) -> dict:
    """case -> arm -> sessions, share with the hidden effect's signature significant, share with any physics
    signature significant. Each arm also as ``<arm>/physics``: Holm over the physics signatures alone (the claims
    that name an effect), from the raw p-values (rows that recorded them)."""
    out: dict = {}
    for r in rows:
        effects = [e for e in LIBRARY if r["case"] == e]
        for k, sig in r["by_block"].items():
            families = [(k, {s: v["p_holm"] for s, v in sig.items()})]
            if all("p" in v for v in sig.values()):
                families.append((f"{k}/physics", holm({s: v["p"] for s, v in sig.items()})))
            for label, p_holm in families:
                cell = out.setdefault(r["case"], {}).setdefault(label, {"sessions": 0, "own": 0, "any": 0})
                cell["sessions"] += 1
                cell["own"] += int(bool(effects) and p_holm[LIBRARY[effects[0]].signature] < Gates.alpha)
                cell["any"] += int(any(p < Gates.alpha for p in p_holm.values()))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, default=Path("experiments/discrepancy-14000"), help="its strengths.json")
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES))
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=20005)
    parser.add_argument("--block-bins", type=int, nargs="+", default=[10, 5, 2, 1])
    args = parser.parse_args(argv)
    strengths = json.loads((args.run / "strengths.json").read_text())
    known = {c.label: c for c in cases([2.0], [0.2])}
    unknown = [c for c in args.cases if c not in known]
    if unknown:
        parser.error(f"--cases: unknown {', '.join(unknown)}")
    enable_compilation_cache()
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "rows.jsonl"
    rows = [json.loads(x) for x in path.read_text().splitlines()] if path.exists() else []
    done = {r["key"] for r in rows}
    todo = [(known[c], s) for s in range(args.first_seed, args.first_seed + args.seeds) for c in args.cases]
    todo = [(c, s) for c, s in todo if run_key(c, s) not in done]
    for i, (case, seed) in enumerate(todo, 1):
        start = time.perf_counter()
        r = row(case, seed, strengths, args.block_bins)
        with path.open("a") as f:
            f.write(json.dumps(r) + "\n")
        rows.append(r)
        print(f"[{i}/{len(todo)}] {r['key']}: {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    result = summary(rows)
    for case, by in sorted(result.items()):
        cells = ", ".join(f"k={k}: own {v['own']}/{v['sessions']} any {v['any']}/{v['sessions']}"
                          for k, v in by.items())
        print(f"{case}: {cells}", file=sys.stderr)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
