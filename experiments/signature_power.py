"""Which residual signatures can see which hidden effect: the first diagnosis of discovery, repeated on fresh
sessions, with each library effect's **matched** signature beside the library's fixed ones (no candidate refits).

Discovery reads an effect's residual structure off a fixed weight vector per signature
(:func:`peano_bayes.discovery.diagnose.signature_weights`). On the final run of the discovery benchmark the
relaxation signature had the same distribution with a Maxwell branch hidden as with nothing hidden
(`experiments/discrepancy_gate_failures.py`): it has no power on that protocol. This measures, for a next
workflow version's tuning round, how much a signature could see:

- **library signatures**: ``T`` and the block sign-flip ``p`` of each, exactly as discovery's first diagnosis
  computes them (:func:`~peano_bayes.discovery.diagnose.diagnose`, after :func:`~peano_bayes.discovery.workflow.
  fit_base`); on a seed of a recorded run they equal that row's first diagnosis (the script's consistency check);
- **matched signatures** ``matched:<effect>``: the standardized change of every fitted bin's prediction when the
  effect is switched on at the start discovery's screen uses (:func:`~peano_bayes.discovery.workflow.effect_start`,
  the library's start strength around the base fit), with the base fit's own Jacobian columns projected out (what
  the refitted base can absorb), so under white unit residuals ``T`` is a z-score; ``p`` by the same block sign
  flips. This is the score-test direction of the effect, across every fitted test.

A signature has power against an effect when its ``p`` is small in the case hiding the effect and not in the
others. The table prints, per signature and case, the median ``T`` and the share of rows with ``p < 0.05``, and
per matched signature the share of its squared weight on each test: where the effect acts once the base has
absorbed what it can.

    python experiments/signature_power.py --run experiments/discrepancy-14000 --out DIR \\
        --cases viscoelastic_relaxation none --seeds 6 --first-seed 20002

``--run`` supplies the calibrated strengths (``strengths.json``) of the benchmark version measured. Resumable:
rows already in ``DIR/signature_power.csv`` are kept. Writes ``DIR/SIGNATURE_POWER.md``; the last line printed
is one JSON object (per signature and case: rows, median T, share with p < 0.05).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from discrepancy_benchmark import cases

from peano_bayes import enable_compilation_cache
from peano_bayes.atomic import write_text
from peano_bayes.discovery import discovery_data
from peano_bayes.discovery.diagnose import diagnose, sign_flip_p, sign_flips, signature_statistic
from peano_bayes.discovery.fitting import evaluate, matched_directions
from peano_bayes.discovery.model import DEFAULT_BASE
from peano_bayes.discovery.workflow import Gates, effect_start, fit_base
from peano_bayes.discovery.workflow import matched_weights as matched_weights_of
from peano_bayes.effects import LIBRARY
from peano_bayes.validation.discovery_benchmark import hidden_dataset, run_key

#: Cases the tuning round of the relaxation signature needs: the effect, those it is confused with, the nulls.
DEFAULT_CASES = (
    "viscoelastic_relaxation",
    "series_viscoelastic",
    "hysteresis",
    "nonlinear_damping",
    "drift",
    "none",
    "none-veale",
)
LEVEL = 0.05
TESTS = ("load_cycle", "blocking", "stroke", "step")


def signature_test(w: np.ndarray, r: np.ndarray, blocks: np.ndarray, flips: np.ndarray) -> tuple[float, float]:
    """``T`` and its block sign-flip ``p``, as :func:`~peano_bayes.discovery.diagnose.diagnose` computes a
    signature's; NaN for an empty or non-finite weight."""
    if not (np.any(w) and np.all(np.isfinite(w))):
        return float("nan"), float("nan")
    return signature_statistic(r, w), sign_flip_p(w, r, blocks, flips)


def matched_weights(base, effects, split) -> dict[str, np.ndarray]:
    """Per effect, its standardized prediction change (n,) from the base fit to the screen's start, with the base
    fit's Jacobian columns (its free parameters, on the fitted bins) projected out
    (:func:`~peano_bayes.discovery.fitting.matched_directions`, on every fitted test)."""
    rows = matched_directions(base, [effect_start(base, effect) for effect in effects], split)
    return dict(zip(effects, rows, strict=True))


def row_statistics(case, seed: int, strengths: dict) -> list[dict]:
    """Every signature's ``T`` and ``p`` on one fresh session of ``case``."""
    dataset = hidden_dataset(case, seed, {e: strengths[f"{e}@{case.snr:g}"] for e in case.effects})
    split = discovery_data(dataset)
    base = fit_base(DEFAULT_BASE, split.fit, starts=Gates.base_starts, seed=seed)
    fit_eval, _ = evaluate(base, split)
    cov = split.fit_covariates
    library = matched_weights_of(base, split)  # the library's matched signatures, as discovery reads them
    diag = diagnose(fit_eval.r, cov, fit_eval.predicted, alpha=Gates.alpha, seed=seed, matched=library)
    key = run_key(case, seed)
    out = [
        {"key": key, "case": case.label, "seed": seed, "signature": name, "T": diag.statistic[name],
         "p": diag.p_value[name]}
        for name in diag.statistic
    ]  # fmt: skip
    blocks, flips = sign_flips(cov.block, seed)
    effects = [e for e in LIBRARY if LIBRARY[e].kind == "physics" and e not in base.spec.active]
    for effect, w in matched_weights(base, effects, split).items():
        t, p = signature_test(w, fit_eval.r, blocks, flips)
        row = {"key": key, "case": case.label, "seed": seed, "signature": f"matched:{effect}", "T": t, "p": p}
        total = float(np.sum(w**2))
        for test in TESTS:  # where the effect acts once the base has absorbed what it can
            row[f"share_{test}"] = float(np.sum(w[cov.test == test] ** 2) / total) if total > 0 else float("nan")
        out.append(row)
    return out


def summary(table: pd.DataFrame) -> dict:
    """signature -> case -> rows, median T, share of rows with p < :data:`LEVEL`."""
    out: dict = {}
    for (sig, case), g in table.groupby(["signature", "case"]):
        out.setdefault(sig, {})[case] = {
            "rows": len(g),
            "median_T": float(g["T"].median()),
            "p_below": float((g["p"] < LEVEL).mean()),
        }
    return out


def markdown(table: pd.DataFrame) -> str:
    cases_ = sorted(table["case"].unique())
    lines = [
        "# Which signatures see which hidden effect",
        "",
        "Made by `experiments/signature_power.py` (method in its docstring). Per signature and case: the median "
        f"of `T` over the rows, and the share of rows with block sign-flip `p < {LEVEL:g}` (unadjusted).",
        "",
        "| signature | " + " | ".join(cases_) + " |",
        "|---|" + "---|" * len(cases_),
    ]
    for sig, g in table.groupby("signature"):
        cells = []
        for case in cases_:
            c = g[g["case"] == case]
            cells.append(f"{c['T'].median():.1f} / {(c['p'] < LEVEL).mean():.2f}" if len(c) else "")
        lines.append(f"| {sig} | " + " | ".join(cells) + " |")
    matched = table[table["signature"].str.startswith("matched:")]
    if len(matched):
        lines += [
            "",
            "Where each matched signature lies: the mean share of its squared weight on each test (the effect's "
            "prediction change after the base fit's directions are projected out).",
            "",
            "| signature | " + " | ".join(TESTS) + " |",
            "|---|" + "---|" * len(TESTS),
        ]
        for sig, g in matched.groupby("signature"):
            lines.append(f"| {sig} | " + " | ".join(f"{g[f'share_{t}'].mean():.2f}" for t in TESTS) + " |")
    rows = table.groupby("case")["key"].nunique()
    lines += ["", "Rows per case: " + ", ".join(f"{c} {n}" for c, n in rows.items()) + "."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, type=Path, help="a benchmark run's folder (its strengths.json)")
    parser.add_argument("--out", required=True, type=Path, help="folder for signature_power.csv and the table")
    parser.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES), help="case labels of the benchmark")
    parser.add_argument("--seeds", type=int, default=6, help="sessions per case")
    parser.add_argument("--first-seed", type=int, default=20002, help="first seed (tuning seeds: not a final run's)")
    parser.add_argument("--snr", type=float, default=2.0)
    args = parser.parse_args(argv)
    strengths_path = args.run / "strengths.json"
    if not strengths_path.is_file():
        parser.error(f"--run {args.run}: expected a benchmark run's folder with strengths.json in it")
    if args.seeds < 1:
        parser.error(f"--seeds {args.seeds}: expected at least 1")
    strengths = json.loads(strengths_path.read_text())
    known = {c.label: c for c in cases([args.snr], [0.2])}
    unknown = [c for c in args.cases if c not in known]
    if unknown:
        parser.error(f"--cases: unknown {', '.join(unknown)}; expected some of {', '.join(sorted(known))}")
    missing = [
        f"{e}@{args.snr:g}" for c in args.cases for e in known[c].effects if f"{e}@{args.snr:g}" not in strengths
    ]
    if missing:
        parser.error(f"--run {args.run}: strengths.json has no {', '.join(missing)}")
    enable_compilation_cache()
    args.out.mkdir(parents=True, exist_ok=True)
    csv = args.out / "signature_power.csv"
    done = pd.read_csv(csv) if csv.exists() else pd.DataFrame(columns=["key"])
    records = done.to_dict("records")
    finished = set(done["key"])
    todo = [
        (known[c], s)
        for s in range(args.first_seed, args.first_seed + args.seeds)
        for c in args.cases
        if run_key(known[c], s) not in finished
    ]
    print(f"{len(finished)} sessions done, {len(todo)} to go", file=sys.stderr, flush=True)
    for i, (case, seed) in enumerate(todo, 1):
        start = time.perf_counter()
        records += row_statistics(case, seed, strengths)
        write_text(csv, pd.DataFrame(records).to_csv(index=False))
        print(
            f"[{i}/{len(todo)}] {run_key(case, seed)}: {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True
        )
    table = pd.DataFrame(records)
    write_text(args.out / "SIGNATURE_POWER.md", markdown(table))
    print(markdown(table), file=sys.stderr)
    print(json.dumps(summary(table)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
