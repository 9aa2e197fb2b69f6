"""The main job's cost: `peano-bayes run` from a fresh clone with an empty compilation cache, ours beside a
reference commit, one after the other on this machine.

    python experiments/bench_main_job.py [--reference REF | --reference-json FILE] [--materials TP FC ...]
                                         [--jobs 2] [--max-steps N] [--keep DIR]

For each of HEAD and ``--reference`` (if given) the repository is cloned into a temporary folder and checked
out there, and ``python -m peano_bayes run`` runs in the clone with this interpreter's packages (the versions
``constraints.txt`` pins; building a virtual environment per clone would time pip, not the job), a fresh
``PEANO_BAYES_CACHE`` (so every program compiles from nothing) and the given options. The wall time is the
whole command's. Per material, from its ``summary.json``: the stage times (least squares, mode, compile,
sampling), warm-up length, steps, tau_max, max R-hat, min bulk and tail ESS and whether it converged; a material
without a
summary (the run failed) is reported as missing. The last line is one JSON object with both runs and, when
both ran, the ratio of their wall times (reference / ours). ``--keep DIR`` keeps the result folders.

The working folder is removed only when the job has finished; a run stopped part way (Ctrl-C, its session
ended) continues with ``--resume /tmp/bench_main_job_XXXX`` (the path it printed; the same materials and
options): ``peano-bayes run`` picks up in the same clone, cache and results, and the wall time is the sum of the
parts the results' ``run.log`` records (``parts`` in the JSON).

Both runs take the machine for most of an hour; to keep them apart but on the same day, measure the reference
first with ``--ref REF --save-json REF.json`` and later pass ``--reference-json REF.json`` to the run of HEAD.
"""

from __future__ import annotations

import argparse
import calendar
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MATERIALS = ("TP", "P", "PR", "TPC", "PC", "PCS", "TFC", "FC")


def material_figures(summary: dict) -> dict:
    """Stage times [s], steps and convergence figures of one material's ``summary.json``."""
    conv = summary.get("convergence", {})
    per = lambda key: list((conv.get(key) or {}).values())  # noqa: E731
    return {
        "stages_s": {k: round(float(v), 1) for k, v in summary.get("timings_s", {}).items()},
        "warmup": summary.get("warmup"),
        "warmup_stable": summary.get("warmup_stable"),
        "steps": summary.get("steps"),
        "tau_max": max(per("tau_steps"), default=None),
        "max_rhat": max(per("rhat"), default=None),
        "min_ess_bulk": min(per("ess_bulk"), default=None),
        "min_ess_tail": min(per("ess_tail"), default=None),
        "converged": bool(conv.get("converged", False)),
    }


def wall_parts(run_log: Path, before: float | None = None) -> list[dict]:
    """The invocations recorded in a main job's ``run.log``: each part begins at its ``running N dataset(s)``
    line and ends at its last line before the next part began (or the file's last line), timestamps to the
    second. A part that was stopped ends at its last logged line, so its wall is short by up to one log interval
    (a sampling check, a few minutes at most). ``before`` (epoch seconds): only lines logged before it count, so
    a later invocation that logs no ``running`` line (one material left) cannot stretch the earlier parts."""
    stamps: list[tuple[float, str]] = []
    for line in run_log.read_text().splitlines():
        stamp, _, text = line.partition(" ")
        try:
            at = calendar.timegm(time.strptime(stamp, "%Y-%m-%dT%H:%M:%SZ"))
            if before is None or at < before:
                stamps.append((at, text))
        except ValueError:
            continue  # a continuation line of a multi-line message
    starts = [i for i, (_, text) in enumerate(stamps) if text.startswith("running ") and "dataset(s)" in text]
    # an invocation's own lines before its "running" line (materials skipped or resumed) start the next part
    opening = ("exists, skipped", "resuming with a larger step limit")
    parts = []
    for n, i in enumerate(starts):
        last = (starts[n + 1] if n + 1 < len(starts) else len(stamps)) - 1
        while n + 1 < len(starts) and last > i and any(k in stamps[last][1] for k in opening):
            last -= 1
        parts.append({"start_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(stamps[i][0])),
                      "wall_s": stamps[last][0] - stamps[i][0]})  # fmt: skip
    return parts


def run_at(ref: str, materials, options: list[str], keep: Path | None, resume: Path | None = None) -> dict:
    """Clone ``ref`` into a temporary folder, run the main job there, and collect its figures. With ``resume``
    (the folder of an earlier, stopped run of this script: its ``clone``, ``cache`` and ``results``) the job
    continues there instead, and the wall time is the sum of the parts its ``run.log`` records."""
    if resume is None:
        tmp = tempfile.mkdtemp(prefix="bench_main_job_")
        clone = Path(tmp) / "clone"
        subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(REPO), str(clone)], check=True)
        subprocess.run(["git", "-C", str(clone), "checkout", "--quiet", ref], check=True)
    else:
        tmp, clone = str(resume), resume / "clone"
        if not (clone / ".git").exists() or not (resume / "results" / "run.log").exists():
            print(f"--resume {resume}: expected an earlier run's clone/ and results/run.log there", file=sys.stderr)
            raise SystemExit(2)
    # the folder goes only when the job has finished: a stopped run (Ctrl-C, a lost session) can be resumed
    print(f"working in {tmp} (--resume {tmp} continues it if stopped)", file=sys.stderr, flush=True)
    commit = subprocess.run(
        ["git", "-C", str(clone), "rev-parse", "--short", "HEAD"], check=True, capture_output=True, text=True
    ).stdout.strip()
    out = Path(tmp) / "results"
    env = {**os.environ, "PYTHONPATH": str(clone), "PEANO_BAYES_CACHE": str(Path(tmp) / "cache")}
    cmd = [sys.executable, "-m", "peano_bayes", "run", "--out", str(out), "--materials", *materials, *options]
    print(f"{ref} ({commit}): {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
    started, t0 = time.time(), time.perf_counter()
    status = subprocess.run(cmd, cwd=clone, env=env).returncode
    this_part = wall = time.perf_counter() - t0
    parts = wall_parts(out / "run.log", before=started) if resume is not None else None
    if parts:
        wall = sum(p["wall_s"] for p in parts) + this_part
    per = {}
    for code in materials:
        path = out / code / "summary.json"
        per[code] = material_figures(json.loads(path.read_text())) if path.exists() else {"missing": True}
    if keep is not None:
        shutil.copytree(out, keep / commit, dirs_exist_ok=True)
    finished = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    record = {"ref": ref, "commit": commit, "exit_status": status, "wall_s": round(wall, 1),
              "finished_utc": finished, "materials": per}  # fmt: skip
    if parts:
        this = {"start_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(started)), "wall_s": round(this_part, 1)}
        record["parts"] = [*parts, this]
    if status in (0, 3):  # finished (3: written, some material unconverged); otherwise kept for --resume
        shutil.rmtree(tmp)
    return record


def table(run: dict) -> str:
    lines = [f"{run['ref']} ({run['commit']}): {run['wall_s']:.0f} s, exit {run['exit_status']}"]
    for code, m in run["materials"].items():
        if m.get("missing"):
            lines.append(f"  {code:4s} no summary")
            continue
        stages = ", ".join(f"{k.removesuffix('_s')} {v:.0f}" for k, v in m["stages_s"].items())
        lines.append(
            f"  {code:4s} {m.get('warmup')} warm-up, {m['steps']} steps, tau_max {m['tau_max']:.1f}, "
            f"R-hat {m['max_rhat']:.3f}, "
            f"ESS {m['min_ess_bulk']:.0f}/{m['min_ess_tail']:.0f}, converged {m['converged']}; {stages} s"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", help="git ref of the code to compare with (omit: ours only)")
    parser.add_argument("--materials", nargs="+", default=list(MATERIALS))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--max-steps", type=int, help="step limit per material (default: the run command's)")
    parser.add_argument("--keep", type=Path, help="copy each run's results folder into KEEP/<commit>/")
    parser.add_argument(
        "--reference-json",
        type=Path,
        help="a reference run measured earlier the same day by this script's run_at (its JSON), instead of running "
        "--reference now: lets the two runs be made apart while other work waits; its finish time is reported",
    )
    parser.add_argument("--save-json", type=Path, help="also write the run of --ref (default HEAD) to this file")
    parser.add_argument("--ref", default="HEAD", help="the code measured as 'ours' (default HEAD)")
    parser.add_argument(
        "--resume",
        type=Path,
        help="continue a stopped run of this script in its folder (/tmp/bench_main_job_*: clone, cache, results); "
        "the wall time is then the sum of its parts",
    )
    args = parser.parse_args(argv)
    if args.reference and args.reference_json:
        parser.error("give --reference or --reference-json, not both")
    options = ["--jobs", str(args.jobs), "--no-progress"]
    if args.max_steps:
        options += ["--max-steps", str(args.max_steps)]
    runs = {"ours": run_at(args.ref, args.materials, options, args.keep, resume=args.resume)}
    if args.save_json:
        args.save_json.write_text(json.dumps(runs["ours"]))
    print(table(runs["ours"]), flush=True)
    if args.reference_json:
        runs["reference"] = json.loads(args.reference_json.read_text())
        print(table(runs["reference"]), flush=True)
    elif args.reference:
        runs["reference"] = run_at(args.reference, args.materials, options, args.keep)
        print(table(runs["reference"]), flush=True)
    if "reference" in runs:
        runs["wall_ratio_reference_over_ours"] = round(runs["reference"]["wall_s"] / runs["ours"]["wall_s"], 2)
    print(json.dumps({"materials": args.materials, "jobs": args.jobs, "cores": os.cpu_count(), **runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
