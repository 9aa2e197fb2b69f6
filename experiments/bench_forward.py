"""Forward-model benchmark: evaluations per second of each rig-test simulation, single and vmapped over 64
parameter sets, against a plain-NumPy load cycle (``numpy_load_cycle.py``) batched over the same 64 sets.

Both sides run in this process, on the same protocol and parameter sets, and the NumPy forces are checked
against ours before timing. Compilation is timed apart and excluded from the rates. Each rate is the best of
``--repeats`` timed runs (these machines are noisy). The last line printed is one JSON object.

    python experiments/bench_forward.py [--batch 64] [--repeats 5] [--samples 801]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np
import numpy_load_cycle

from peano_bayes.physics import (
    DEFAULT_CONFIG,
    Blocking,
    LoadCycle,
    Step,
    Stroke,
    simulate_blocking,
    simulate_load_cycle,
    simulate_step,
    simulate_stroke,
)


def protocols(samples: int):
    """The paper's four tests at 200 kPa: a 0.08 -> -0.012 -> 0.08 strain cycle over 40 s (``samples``
    samples), 0 -> 200 kPa ramps over 10 s (201 samples), and a 0.6 s step with a 40 N load at 1 kHz."""
    t = np.linspace(0.0, 40.0, samples)
    strain = np.interp(t, [0.0, 20.0, 40.0], [0.08, -0.012, 0.08])
    ramp = np.linspace(0.0, 1.0, 201)
    ts = np.linspace(0.0, 0.6, 601)
    return {
        "load_cycle": LoadCycle(jnp.asarray(t), jnp.asarray(strain), jnp.full(samples, 2e5)),
        "blocking": Blocking(jnp.asarray(10.0 * ramp), jnp.asarray(2e5 * ramp)),
        "stroke": Stroke(jnp.asarray(10.0 * ramp), jnp.asarray(2e5 * ramp)),
        "step": Step(jnp.asarray(ts), jnp.asarray(np.where(ts > 0.05, 2e5, 0.0)), 40.0, 2),
    }


SIMULATORS = {
    "load_cycle": lambda p, pr: simulate_load_cycle(p, pr, config=DEFAULT_CONFIG).force_n,
    "blocking": lambda p, pr: simulate_blocking(p, pr, config=DEFAULT_CONFIG).force_n,
    "stroke": lambda p, pr: simulate_stroke(p, pr, config=DEFAULT_CONFIG).strain,
    "step": lambda p, pr: simulate_step(p, pr, config=DEFAULT_CONFIG).strain,
}


def parameter_sets(batch: int, seed: int = 0):
    """``batch`` parameter sets scattered around the nominal values (log-normal, 20 %)."""
    rng = np.random.default_rng(seed)
    nominal = DEFAULT_CONFIG.nominal_parameters()
    return {k: v * np.exp(0.2 * rng.normal(size=batch)) for k, v in nominal.items()}


def best_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--samples", type=int, default=801, help="load-cycle samples")
    args = parser.parse_args(argv)

    sets = parameter_sets(args.batch)
    batched = {k: jnp.asarray(v) for k, v in sets.items()}
    single = {k: jnp.asarray(v[0]) for k, v in sets.items()}
    tests = protocols(args.samples)
    results = {}
    for name, simulate in SIMULATORS.items():
        protocol = tests[name]
        one = jax.jit(lambda p, simulate=simulate, protocol=protocol: simulate(p, protocol))
        many = jax.jit(jax.vmap(lambda p, simulate=simulate, protocol=protocol: simulate(p, protocol)))
        start = time.perf_counter()
        jax.block_until_ready(one(single))
        jax.block_until_ready(many(batched))
        compile_s = time.perf_counter() - start
        t_one = best_time(lambda one=one: jax.block_until_ready(one(single)), args.repeats)
        t_many = best_time(lambda many=many: jax.block_until_ready(many(batched)), args.repeats)
        results[name] = {
            "single_evals_per_s": 1.0 / t_one,
            "vmap_evals_per_s": args.batch / t_many,
            "compile_s": compile_s,
        }
        print(
            f"{name:11s} single {1.0 / t_one:9.1f}/s   vmap-{args.batch} {args.batch / t_many:9.1f}/s"
            f"   (compile {compile_s:.1f} s)",
            flush=True,
        )

    cycle = tests["load_cycle"]
    strain, pressure = np.asarray(cycle.strain), np.asarray(cycle.pressure_pa)
    ours = np.asarray(jax.jit(jax.vmap(lambda p: SIMULATORS["load_cycle"](p, cycle)))(batched))
    theirs = numpy_load_cycle.simulate_load_cycle(sets, strain, pressure)
    agreement = float(np.max(np.abs(ours - theirs)))
    if agreement > 1e-6:
        raise SystemExit(f"NumPy reference disagrees with peano_bayes by {agreement:.3g} N; not benchmarking")
    t_numpy = best_time(lambda: numpy_load_cycle.simulate_load_cycle(sets, strain, pressure), args.repeats)
    loop_sets = min(8, args.batch)  # a per-set loop is slow; time 8 sets and report the rate
    t_loop = best_time(
        lambda: [
            numpy_load_cycle.simulate_load_cycle({k: v[i : i + 1] for k, v in sets.items()}, strain, pressure)
            for i in range(loop_sets)
        ],
        max(1, args.repeats // 2),
    )
    numpy_rate = args.batch / t_numpy
    loop_rate = loop_sets / t_loop
    ratio = results["load_cycle"]["vmap_evals_per_s"] / numpy_rate
    print(f"numpy load cycle: batched-{args.batch} {numpy_rate:.1f}/s, per-set loop {loop_rate:.1f}/s")
    print(f"max |force difference| peano_bayes vs NumPy: {agreement:.2e} N")
    print(f"vmapped load cycle / NumPy batched = {ratio:.1f}x (target >= 20x)")
    summary = {
        "benchmark": "forward",
        "batch": args.batch,
        "load_cycle_samples": args.samples,
        "ours": results,
        "numpy_load_cycle_batched_evals_per_s": numpy_rate,
        "numpy_load_cycle_loop_evals_per_s": loop_rate,
        "max_force_difference_n": agreement,
        "ratio_vmap_vs_numpy_batched": ratio,
        "ratio_vmap_vs_numpy_loop": results["load_cycle"]["vmap_evals_per_s"] / loop_rate,
        "target_ratio": 20.0,
        "meets_target": bool(ratio >= 20.0),
        "machine": {
            "cpus": os.cpu_count(),
            "jax_devices": jax.local_device_count(),
            "platform": platform.platform(),
            "jax": jax.__version__,
        },
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
