"""Throughput of the fan-out seam: SBC replicates per hour with one and two workers, local processes against a
Dask LocalCluster, and the per-unit overhead of each executor.

    python experiments/bench_scale.py [--replicates 8] [--steps 300] [--walkers 8] [--noop 200]
                                      [--repeat-pools N]

Each configuration runs the same ``--replicates`` SBC replicates (``peano_bayes.validation.sbc.replicate_unit``,
root seed 20261126, ``--walkers`` walkers, warm-up and chunk of ``--steps`` / 3, at most ``--steps`` steps)
through ``peano_bayes.app.fanout.run_units`` with fresh workers, so each worker's tracing and cache loading is in
its time, as it is in a real study. The persistent compilation cache is warmed first by one replicate in a
worker process (not counted). Configurations, side by side in one run:

- ``processes-1``: one spawned local process with one XLA thread;
- ``processes-2-capped``: two spawned local processes, one XLA thread each (``fanout.cap_threads``);
- ``processes-2``: two spawned local processes with their thread pools as they are (``--jobs 2``, the default of
  ``run``, as it ran before the seam);
- ``dask-local-2``: a Dask LocalCluster of two one-thread workers (``--scheduler local:2``).

``--repeat-pools N`` then runs ``processes-2-capped`` and ``processes-2`` N more times each, alternating, to
tell the thread cap's effect from run-to-run noise (reported as the rates of every repeat). The per-unit
overhead is measured apart with ``--noop`` units that return at once: seconds per unit through
each executor, after its workers are up. Scaling efficiency = rate / (workers x the rate of ``processes-1``). The
machine should be otherwise idle. The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import multiprocessing
import time

from peano_bayes import enable_compilation_cache
from peano_bayes.app.fanout import Unit, cap_threads, make_executor, run_units
from peano_bayes.validation.sbc import replicate_unit

SEED = 20261126


def _noop(i: int) -> int:
    return i


def _units(n: int, steps: int, walkers: int) -> list[Unit]:
    settings = dict(seed=SEED, n_walkers=walkers, warmup=steps // 3, chunk=steps // 3, max_steps=steps)
    return [Unit(f"replicate {i}", replicate_unit, (i,), settings) for i in range(n)]


def _timed(executor, units) -> tuple[float, list]:
    start = time.perf_counter()
    outcomes = run_units(units, executor)
    failed = [o.error for o in outcomes if not o.ok]
    if failed:
        raise RuntimeError(f"units failed: {failed[:3]}")
    return time.perf_counter() - start, outcomes


def _overhead(executor, n: int) -> float:
    """Seconds per no-op unit once the workers are up (one warm-up round first)."""
    run_units([Unit(f"warm {i}", _noop, (i,)) for i in range(4)], executor)
    start = time.perf_counter()
    run_units([Unit(f"noop {i}", _noop, (i,)) for i in range(n)], executor)
    return (time.perf_counter() - start) / n


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--replicates", type=int, default=8)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--walkers", type=int, default=8)
    parser.add_argument("--noop", type=int, default=200)
    parser.add_argument("--repeat-pools", type=int, default=0, help="extra alternating runs of the two pools")
    args = parser.parse_args(argv)
    enable_compilation_cache()
    with make_executor(None, 2) as (executor, _):  # warm the persistent compilation cache in a worker
        run_units(_units(1, args.steps, args.walkers), executor)
    units = _units(args.replicates, args.steps, args.walkers)

    results, reference_rows = {}, None

    def record(name, seconds, outcomes, workers, overhead):
        nonlocal reference_rows
        rows = [{k: v for k, v in o.value.items() if k != "seconds"} for o in outcomes]
        reference_rows = rows if reference_rows is None else reference_rows  # those of processes-1
        results[name] = {
            "workers": workers,
            "seconds": round(seconds, 1),
            "replicates_per_hour": round(len(units) / seconds * 3600, 1),
            "overhead_s_per_unit": None if overhead is None else round(overhead, 5),
            "same_numbers_as_processes_1": rows == reference_rows,
        }
        print(f"{name}: {len(units)} replicates in {seconds:.0f} s ({results[name]['replicates_per_hour']:.0f}/h)",
              flush=True)  # fmt: skip

    spawn = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=1, mp_context=spawn, initializer=cap_threads) as executor:
        seconds, outcomes = _timed(executor, units)
        record("processes-1", seconds, outcomes, 1, _overhead(executor, args.noop))
    with cf.ProcessPoolExecutor(max_workers=2, mp_context=spawn, initializer=cap_threads) as executor:
        seconds, outcomes = _timed(executor, units)
        record("processes-2-capped", seconds, outcomes, 2, None)
    with make_executor(None, 2) as (executor, _):
        seconds, outcomes = _timed(executor, units)
        record("processes-2", seconds, outcomes, 2, _overhead(executor, args.noop))
    with make_executor("local:2") as (executor, _):
        seconds, outcomes = _timed(executor, units)
        record("dask-local-2", seconds, outcomes, 2, _overhead(executor, args.noop))

    repeats = {name: [results[name]["replicates_per_hour"]] for name in ("processes-2-capped", "processes-2")}
    for i in range(args.repeat_pools):
        for name, initializer in (("processes-2", None), ("processes-2-capped", cap_threads)):
            with cf.ProcessPoolExecutor(max_workers=2, mp_context=spawn, initializer=initializer) as executor:
                seconds, _ = _timed(executor, units)
            repeats[name].append(round(len(units) / seconds * 3600, 1))
            print(f"{name}, repeat {i + 1}: {repeats[name][-1]:.0f}/h", flush=True)
    one = results["processes-1"]["replicates_per_hour"]
    for r in results.values():
        r["scaling_efficiency"] = round(r["replicates_per_hour"] / (r["workers"] * one), 3)
    summary = {
        "replicates": len(units),
        "steps": args.steps,
        "walkers": args.walkers,
        "configurations": results,
        "pool_rates_per_hour": repeats,
        "capped_over_uncapped_mean_rate": round(
            sum(repeats["processes-2-capped"]) / len(repeats["processes-2-capped"])
            / (sum(repeats["processes-2"]) / len(repeats["processes-2"])),
            3,
        ),
        "dask_over_processes_rate": round(
            results["dask-local-2"]["replicates_per_hour"] / results["processes-2"]["replicates_per_hour"], 3
        ),
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
