"""Do the tensile-stretch sampler coordinates make a run mix faster? Two arms of the main job's fit, side by side.

For one bundled material and its default tests, ``infer`` runs twice from the same seed (least squares, mode,
warm-up, sampling): once moving theta itself and once moving the tensile element's log stretches at 1 and 20 N
in place of ``(tensile_ka, tensile_kb)`` (:class:`~peano_bayes.inference.coordinates.TensileStretch`), each for
at most ``--steps`` steps, in two local processes (one per core). Reported per arm, from its ``summary.json``
(every figure in theta, the reported parameters): steps, the largest integrated autocorrelation time and the
parameter that sets it, the ratio of chain length to it, max R-hat, min bulk ESS, acceptance, sampling seconds
and bulk ESS per second of sampling; and the ratios stretch / theta of tau_max and of ESS per second. Chains of
equal length, so the arms compare, though short chains under-estimate tau. The last line printed is one JSON
object.

    python experiments/coordinates_arms.py [--material PR] [--steps 1200] [--out /tmp/coordinates_arms]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from peano_bayes import bundled, enable_compilation_cache
from peano_bayes.app.fanout import Unit, make_executor, raise_failures, run_units
from peano_bayes.app.pipeline import infer

ARMS = ("theta", "tensile_stretch")


def arm(code: str, kind: str, out: str, steps: int, seed: int) -> dict:
    """One arm: ``infer`` of bundled ``code`` into ``out/<kind>`` with sampler coordinates ``kind``."""
    enable_compilation_cache()
    summary = infer(
        bundled.dataset_path(code),
        Path(out) / kind,
        seed=seed,
        max_steps=steps,
        chunk=steps,
        warmup=300,  # the protocol of the recorded table (the default then)
        progress=False,
        figures=False,
        coordinates=kind,
        label=code,
    )
    conv = summary["convergence"]
    tau = conv["tau_steps"]
    slowest = max(tau, key=tau.get)
    sampling_s = summary["timings_s"]["sampling_s"]
    return {
        "coordinates": summary["sampler_coordinates"],
        "steps": summary["steps"],
        "tau_max": tau[slowest],
        "slowest": slowest,
        "tau_lengths": conv["tau_lengths"],
        "max_rhat": max(conv["rhat"].values()),
        "min_ess_bulk": min(conv["ess_bulk"].values()),
        "acceptance": summary["acceptance"],
        "sampling_s": sampling_s,
        "min_ess_bulk_per_s": min(conv["ess_bulk"].values()) / sampling_s,
        "converged": conv["converged"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="PR")
    parser.add_argument("--steps", type=int, default=1200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="/tmp/coordinates_arms")
    args = parser.parse_args()
    units = [Unit(kind, arm, (args.material, kind, args.out, args.steps, args.seed)) for kind in ARMS]
    with make_executor(None, jobs=2) as (executor, _):
        outcomes = run_units(units, executor, log=print)
    raise_failures(outcomes, "arm")
    rows = {o.key: o.value for o in outcomes}
    for kind, r in rows.items():
        print(
            f"{args.material} {kind}: {r['steps']} steps, tau_max {r['tau_max']:.1f} ({r['slowest']}), "
            f"{r['tau_lengths']:.1f} tau long, max R-hat {r['max_rhat']:.3f}, min bulk ESS {r['min_ess_bulk']:.0f}, "
            f"acceptance {r['acceptance']:.2f}, sampling {r['sampling_s']:.0f} s",
            flush=True,
        )
    theta, stretch = rows["theta"], rows["tensile_stretch"]
    summary = {
        "benchmark": "coordinates_arms",
        "material": args.material,
        "steps": args.steps,
        "seed": args.seed,
        "arms": rows,
        "tau_max_ratio": stretch["tau_max"] / theta["tau_max"],
        "ess_per_s_ratio": stretch["min_ess_bulk_per_s"] / theta["min_ess_bulk_per_s"],
    }
    print(json.dumps(summary, default=float))


if __name__ == "__main__":
    main()
