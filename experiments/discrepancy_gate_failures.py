"""Which gate stops a hidden effect, read off a recorded discovery benchmark run (no new fits).

Every screened candidate of every row in ``RUN/runs*.jsonl[.gz]`` carries its evidence and its gate results
(:func:`peano_bayes.discovery.workflow._score`). This counts the candidate evaluations that failed exactly one
gate, by gate and by whether the candidate was the effect hidden in that row's data (a *true* candidate) or not
(a *false* one), and lists, for ``--effect``, every row where that effect was hidden and not named alone: round
by round, the candidate's held-out elpd gain (with its se), delta BIC, its own signature's statistic before the
refit (and that signature's p-value in the diagnosis before it, unadjusted and after Holm), the ratio the refit
left, and the gates it failed.

It also counts what the own-signature gate's visibility rule does. The gate checks ``T_after / T_before`` only
where the signature was visible, ``T_before >= min_signature``; for each level in ``--levels`` it counts how many
of the candidates that failed only that gate had a signature whose own p-value (block sign flips, unadjusted)
was at least the level, i.e. would have passed had "visible" meant "significant at that level". A post-hoc
reading of a final run: it shows where a gate binds, and changes nothing in the recorded result.

And whether ``--effect``'s own signature could see it at all: per case, the distribution of that signature's
statistic in the first diagnosis (the base refitted, before any candidate), so the case that hides the effect can
be set beside the cases that do not; and, over the rows that hide the effect alone, the detections against
whether that first statistic was visible (``T >= min_signature``). A signature without power has the same
distribution with the effect hidden as without, and then a detection says only that the noise kept ``T`` below
the visibility threshold, where the gate is not checked.

    python experiments/discrepancy_gate_failures.py experiments/discrepancy-14000 --effect viscoelastic_relaxation

Writes ``RUN/checks/gate_failures/GATE_FAILURES.md``; last line one JSON object.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections import Counter
from pathlib import Path

from discrepancy_benchmark import log_rows, run_logs

from peano_bayes.atomic import write_text
from peano_bayes.discovery.workflow import Gates
from peano_bayes.effects import LIBRARY


def single_gate_failures(rows) -> Counter:
    """``(gate, true_candidate) -> count`` over every candidate evaluation that failed exactly one gate."""
    counts = Counter()
    for row in rows:
        for round_ in row["screened"]:
            for name, ev in round_.items():
                failed = [g for g, ok in ev["gates"].items() if not ok]
                if len(failed) == 1:
                    counts[(failed[0], name in row["effects"])] += 1
    return counts


def visibility_release(rows, levels) -> dict:
    """Per level: of the candidates that failed only the own-signature gate, how many (true, false) had a
    signature p-value (unadjusted, in the diagnosis before their round) of at least the level."""
    out = {}
    for level in levels:
        c = Counter()
        for row in rows:
            for i, round_ in enumerate(row["screened"]):
                p = row["diagnoses"][i]["signatures"]
                for name, ev in round_.items():
                    if [g for g, ok in ev["gates"].items() if not ok] == ["own_signature"]:
                        truth = name in row["effects"]
                        c[(truth, "released" if p[ev["signature"]]["p"] >= level else "kept")] += 1
        out[level] = {
            "true_released": c[(True, "released")],
            "true_total": c[(True, "released")] + c[(True, "kept")],
            "false_released": c[(False, "released")],
            "false_total": c[(False, "released")] + c[(False, "kept")],
        }
    return out


def misses(rows, effect: str) -> list[dict]:
    """Rows where ``effect`` alone was hidden (at any SNR) and the verdict did not name it alone, with the
    effect's evidence in every round it was refitted."""
    out = []
    for row in rows:
        if row["effects"] != [effect] or row["named"] == [effect]:
            continue
        rounds = []
        for i, round_ in enumerate(row["screened"]):
            ev = round_.get(effect)
            if ev is None:
                continue
            sig = row["diagnoses"][i]["signatures"][ev["signature"]]
            rounds.append(
                {
                    "round": i,
                    "delta_elpd": ev["delta_elpd"],
                    "elpd_se": ev["elpd_se"],
                    "delta_bic": ev["delta_bic"],
                    "signature_before": ev["signature_before"],
                    "signature_p": sig["p"],
                    "signature_p_holm": sig["p_holm"],
                    "signature_ratio": ev["signature_ratio"],
                    "failed": [g for g, ok in ev["gates"].items() if not ok],
                }
            )
        out.append({"key": row["key"], "named": row["named"], "verdict": row["verdict"], "rounds": rounds})
    return out


def case_of(row) -> str:
    """A row's case: its key without the seed (label, SNR, force noise sd, drift)."""
    return row["key"].rsplit("|", 1)[0]


def signature_power(rows, signature: str, min_signature: float) -> dict:
    """Per case: ``n``, the median and root mean square of ``signature``'s statistic in the first diagnosis, how
    many rows had it visible (``T >= min_signature``) and how many significant at 0.05 (unadjusted)."""
    by_case: dict[str, list] = {}
    for row in rows:
        if row["diagnoses"]:
            by_case.setdefault(case_of(row), []).append(row["diagnoses"][0]["signatures"][signature])
    out = {}
    for case, sigs in sorted(by_case.items()):
        t = [s["T"] for s in sigs]
        out[case] = {
            "n": len(t),
            "median_T": statistics.median(t),
            "rms_T": statistics.fmean(x * x for x in t) ** 0.5,
            "visible": sum(x >= min_signature for x in t),
            "p_below_0.05": sum(s["p"] < 0.05 for s in sigs),
        }
    return out


def detection_by_visibility(rows, effect: str, signature: str, min_signature: float) -> Counter:
    """Over the rows hiding ``effect`` alone: ``(visible in the first diagnosis, correct) -> count``."""
    counts = Counter()
    for row in rows:
        if row["effects"] == [effect] and row["diagnoses"]:
            visible = row["diagnoses"][0]["signatures"][signature]["T"] >= min_signature
            counts[(bool(visible), bool(row["correct"]))] += 1
    return counts


def markdown(counts: Counter, release: dict, missed: list[dict], effect: str, run: Path, power=None) -> str:
    lines = [
        f"# Which gate stops a hidden effect: {run.name}",
        "",
        "Generated by `experiments/discrepancy_gate_failures.py` from the run's recorded rows (no new fits).",
        "",
        "## Candidate evaluations that failed exactly one gate",
        "",
        "| gate | true candidate | false candidate |",
        "|---|---|---|",
    ]
    for gate in sorted({g for g, _ in counts}):
        lines.append(f"| {gate} | {counts[(gate, True)]} | {counts[(gate, False)]} |")
    lines += [
        "",
        "## The own-signature gate's visibility rule",
        "",
        "Of the candidates that failed only `own_signature` (visible by `T_before >= min_signature`, not reduced "
        "enough), those whose signature's own p-value was at least the level (would pass were visibility "
        "significance at that level):",
        "",
        "| level | true released | false released |",
        "|---|---|---|",
    ]
    for level, r in release.items():
        lines.append(
            f"| {level:g} | {r['true_released']} of {r['true_total']} | {r['false_released']} of {r['false_total']} |"
        )
    if power is not None:
        signature, min_signature, by_case, detection = power
        lines += [
            "",
            f"## Could `{signature}` see `{effect}`?",
            "",
            f"The statistic of `{signature}` in each row's first diagnosis (base refitted, no candidate yet), by case; "
            f"visible: `T >= {min_signature:g}`, where the own-signature gate is checked.",
            "",
            "| case | rows | median T | RMS T | visible | p < 0.05 |",
            "|---|---|---|---|---|---|",
        ]
        for case, c in by_case.items():
            cell = case.replace("|", "\\|")
            lines.append(
                f"| {cell} | {c['n']} | {c['median_T']:.2f} | {c['rms_T']:.2f} | {c['visible']} | {c['p_below_0.05']} |"
            )
        lines += [
            "",
            f"Rows hiding `{effect}` alone, by whether `{signature}` was visible in the first diagnosis:",
            "",
            "| first diagnosis | correct | missed |",
            "|---|---|---|",
            f"| visible | {detection[(True, True)]} | {detection[(True, False)]} |",
            f"| not visible | {detection[(False, True)]} | {detection[(False, False)]} |",
        ]
    lines += [
        "",
        f"## `{effect}` hidden and not named alone: {len(missed)} rows",
        "",
        "| row | named | round | delta elpd (se) | delta BIC | T before | p (Holm) | T ratio | failed |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for m in missed:
        key = m["key"].replace("|", "\\|")  # a row key's separators would split the table's cells
        named = ", ".join(m["named"]) or m["verdict"]
        if not m["rounds"]:
            lines.append(f"| {key} | {named} | never refitted | | | | | | |")
        for r in m["rounds"]:
            lines.append(
                f"| {key} | {named} | {r['round']} | {r['delta_elpd']:.1f} ({r['elpd_se']:.1f}) | "
                f"{r['delta_bic']:.0f} | {r['signature_before']:.2f} | {r['signature_p']:.3f} "
                f"({r['signature_p_holm']:.2f}) | {r['signature_ratio']:.2f} | {', '.join(r['failed']) or '-'} |"
            )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="a discovery benchmark run's folder (runs*.jsonl[.gz] in it)")
    parser.add_argument("--effect", default="viscoelastic_relaxation", help="the effect whose misses to list")
    parser.add_argument("--levels", nargs="+", type=float, default=[0.01, 0.05, 0.1, 0.2])
    args = parser.parse_args(argv)
    if not run_logs(args.run):
        parser.error(f"{args.run} is not a benchmark run's folder: expected runs*.jsonl[.gz] in it")
    rows = [r for log in run_logs(args.run) for r in log_rows(log)]
    if not any(args.effect in r["effects"] for r in rows):
        parser.error(f"no row of {args.run} hides {args.effect!r}")
    counts = single_gate_failures(rows)
    release = visibility_release(rows, args.levels)
    missed = misses(rows, args.effect)
    signature, min_signature = LIBRARY[args.effect].signature, Gates().min_signature
    by_case = signature_power(rows, signature, min_signature)
    detection = detection_by_visibility(rows, args.effect, signature, min_signature)
    out = args.run / "checks" / "gate_failures"
    out.mkdir(parents=True, exist_ok=True)
    power = (signature, min_signature, by_case, detection)
    write_text(out / "GATE_FAILURES.md", markdown(counts, release, missed, args.effect, args.run, power))
    only_own = [m for m in missed if m["rounds"] and all(r["failed"] == ["own_signature"] for r in m["rounds"])]
    print(f"wrote {out / 'GATE_FAILURES.md'}", file=sys.stderr)
    print(
        json.dumps(
            {
                "rows": len(rows),
                "single_gate_failures": {f"{g}|{'true' if t else 'false'}": n for (g, t), n in sorted(counts.items())},
                "visibility_release": {f"{k:g}": v for k, v in release.items()},
                "effect": args.effect,
                "misses": len(missed),
                "misses_failing_only_own_signature_in_every_round": len(only_own),
                "signature": signature,
                "signature_power": by_case,
                "detection_by_visibility": {
                    f"{'visible' if v else 'not_visible'}|{'correct' if c else 'missed'}": n
                    for (v, c), n in sorted(detection.items())
                },
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
