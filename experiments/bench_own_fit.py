"""A user's own fit: `peano-bayes fit` on a 10 Hz load-cycle file of another physics, on one core, as a user runs it.

The file is written here, from Veale's force-balance model (:func:`peano_bayes.rig.simulate_veale_dataset`, the
paper's four-tube muscle of Table 2): load cycles only, sampled at 10 Hz, at five pressures to 500 kPa (100, 200,
300, 400, 500), three repeats each, two specimens (stiffnesses 5 % apart), force noise 1.5 N. The prior is the one
a user starts from, `peano-bayes prior new --like TPC`. Then

    peano-bayes fit own.csv --prior prior.toml --tests load_cycle --no-discover --no-progress

runs pinned to one core (``taskset -c 0`` where it exists) with an empty compilation cache, and its wall time,
stages, warm-up, steps, tau (the largest, and the between-specimen spread's), R-hat, ESS and verdict are read
from ``summary.json``. Target (main-job issue): converged in at most 5 minutes of wall.

    .venv/bin/python experiments/bench_own_fit.py [--seed 0] [--keep DIR] [--coordinates KIND] [--contrasts KIND]
        [--max-steps N]

Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from peano_bayes.data.io import save
from peano_bayes.rig import RigNoise, RigProtocol, simulate_veale_dataset

PRESSURES_PA = (100e3, 200e3, 300e3, 400e3, 500e3)
FORCE_SD_N = 1.5
RATE_HZ = 10.0
TARGET_S = 300.0
SPREAD = "specimen_log_sd"


def write_file(folder: Path, seed: int) -> tuple[Path, float]:
    """The user's rig file (CSV and TOML sidecar) in ``folder``, and its largest |force| [N]."""
    dataset = simulate_veale_dataset(
        "TPC",
        seed=seed,
        noise=RigNoise(force_sd_n=FORCE_SD_N),
        repeats=3,
        specimens=2,
        tests=("load_cycle",),
        protocol=RigProtocol(quasi_static_rate_hz=RATE_HZ),
        cycle_pressures_pa=PRESSURES_PA,
    )
    return save(dataset, folder / "own.csv"), max(float(np.nanmax(np.abs(r.force_n))) for r in dataset.runs)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated file (default 0)")
    parser.add_argument("--keep", type=Path, help="copy the file and the result folder here")
    parser.add_argument("--coordinates", help="sampler coordinates to pass to fit (default: fit's own)")
    parser.add_argument("--contrasts", help="--contrasts to pass to fit (default: fit's own, auto)")
    parser.add_argument("--max-steps", type=int, help="--max-steps to pass to fit (an arm stopped at another's length)")
    args = parser.parse_args(argv)
    cli = [sys.executable, "-m", "peano_bayes"]
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    with tempfile.TemporaryDirectory(prefix="bench_own_fit_") as tmp:
        tmp = Path(tmp)
        data, max_force = write_file(tmp, args.seed)
        subprocess.run([*cli, "prior", "new", "--like", "TPC", "--out", str(tmp / "prior.toml")], check=True,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        env = {**os.environ, "PEANO_BAYES_CACHE": str(tmp / "cache")}
        cmd = [*pin, *cli, "fit", str(data), "--prior", str(tmp / "prior.toml"), "--tests", "load_cycle",
               "--no-discover", "--no-progress", "--label", "own", "--out", str(tmp / "results")]  # fmt: skip
        for option in ("coordinates", "contrasts", "max_steps"):
            if getattr(args, option) is not None:
                cmd += [f"--{option.replace('_', '-')}", str(getattr(args, option))]
        print(" ".join(cmd[len(pin) :]), file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        status = subprocess.run(cmd, env=env).returncode
        wall = time.perf_counter() - t0
        summary_path = tmp / "results" / "own" / "summary.json"
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else None
        if args.keep is not None:
            args.keep.mkdir(parents=True, exist_ok=True)
            shutil.copytree(tmp / "results", args.keep / "results", dirs_exist_ok=True)
            for name in ("own.csv", "own.toml", "prior.toml"):
                shutil.copy2(tmp / name, args.keep / name)
    row = {"benchmark": "bench_own_fit", "seed": args.seed, "exit_status": status, "wall_s": round(wall, 1),
           "cores": 1 if pin else os.cpu_count(), "max_force_n": round(max_force, 1),
           "target_s": TARGET_S}  # fmt: skip
    if summary is not None:
        conv = summary["convergence"]
        tau = conv["tau_steps"]
        row.update(
            converged=conv["converged"],
            stages_s={k: round(float(v), 1) for k, v in summary["timings_s"].items()},
            warmup=summary.get("warmup"),
            steps=summary["steps"],
            tau_max=round(max(tau.values()), 1),
            tau_spread=None if SPREAD not in tau else round(tau[SPREAD], 1),
            max_rhat=round(max(conv["rhat"].values()), 4),
            min_ess_bulk=round(min(conv["ess_bulk"].values())),
            min_ess_tail=round(min(conv["ess_tail"].values())),
            coordinates=summary.get("sampler_coordinates"),
            tau_by_parameter={k: round(v, 1) for k, v in sorted(tau.items(), key=lambda kv: -kv[1])[:6]},
            within_target=bool(conv["converged"] and wall <= TARGET_S),
        )
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
