"""Scalar-solve benchmark: the quasi-static simulations of a bundled material's fit, by each route to the root.

Every simulated input row of the material's default tests (load cycles, blocking and stroke, as the likelihood
prepares them: the model's time grid, not the rig's samples) is simulated for ``--walkers`` parameter sets
around the generating values of specimen A (log-normal, ``--spread``), vmapped as the sampler's ensemble is.
Three routes to each time step's root (``peano_bayes.physics.simulate.QUASI_STATIC_ROUTE``):

- ``previous``: a bracket of +-0.01 around the previous sample's root, bisected to 1e-3 (whole range where
  it misses), then Newton;
- ``bracket_first``: a bracket of +-4.5e-4 around the root extrapolated from the previous two samples,
  searched outward and bisected only where it misses, then safeguarded Newton;
- ``newton_first`` (the package's route): three plain Newton steps from the extrapolated root, accepted where
  they converge; the ``bracket_first`` route at the samples where some member's did not.

All compile apart (timed, excluded from the rates) and simulate the same rows and parameter sets; they solve
the same equations, so their signals must agree (the script stops, reporting no speed, where any route differs
from ``bracket_first`` by more than 1e-6 N or 1e-6 in strain). The time per walker is the best of
``--repeats`` runs (these machines are noisy); only the forward simulation is timed, not its gradient. The
last line printed is one JSON object; its ratios are speed-ups over ``bracket_first``.

    python experiments/bench_solve.py [--material TP] [--walkers 152] [--spread 0.02] [--repeats 5]
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

from peano_bayes.app.pipeline import DEFAULT_TESTS, prior_of, select_tests
from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.discovery.choice import configured_model
from peano_bayes.inference import prepare
from peano_bayes.inference.likelihood import simulate_test
from peano_bayes.jax_config import enable_compilation_cache
from peano_bayes.physics import simulate

QUASI_STATIC = ("load_cycle", "blocking", "stroke")


def workload(material: str):
    """The quasi-static run groups of ``material``'s prepared default tests, its sampled model configuration,
    its geometry, and specimen A's generating parameters (name -> value)."""
    dataset = select_tests(load(dataset_path(material)), DEFAULT_TESTS)
    config = configured_model(prior_of(dataset, None).config).config
    observations = prepare(dataset)
    groups = [g for g in observations.groups if g.test in QUASI_STATIC]
    truth = json.loads(dataset.provenance["specimen_parameters"])["A"]
    params = {k: float(v) for k, v in {**config.nominal_parameters(), **truth}.items()}
    return groups, config, observations.geometry, params


def parameter_sets(params: dict, walkers: int, spread: float, seed: int = 0) -> dict:
    """``walkers`` parameter sets, each value scattered log-normally by ``spread`` around ``params``."""
    rng = np.random.default_rng(seed)
    return {k: jnp.asarray(v * np.exp(spread * rng.normal(size=walkers))) for k, v in params.items()}


def simulator(groups, config, geometry):
    """``f(sets) -> list of (walkers, rows, L)`` signals of every group, jitted (traced on first call)."""

    def one_set(params):
        out = []
        for g in groups:

            def row(time_s, strain, pressure_pa, load_n, test=g.test):
                return simulate_test(test, params, time_s, strain, pressure_pa, None, load_n, config, geometry)[0]

            inputs = (g.time_s, g.strain, g.pressure_pa, g.load_n)
            out.append(jax.vmap(row)(*(jnp.asarray(a, dtype=jnp.float64) for a in inputs)))
        return out

    return jax.jit(jax.vmap(one_set))


ROUTES = ("previous", "bracket_first", "newton_first")
REFERENCE = "bracket_first"


def timed_route(route: str, groups, config, geometry, sets, repeats: int):
    """(signals, compile seconds, best seconds per call) of one route."""
    before, simulate.QUASI_STATIC_ROUTE = simulate.QUASI_STATIC_ROUTE, route
    try:
        fn = simulator(groups, config, geometry)
        start = time.perf_counter()
        signals = jax.block_until_ready(fn(sets))
        compile_s = time.perf_counter() - start
    finally:
        simulate.QUASI_STATIC_ROUTE = before
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(sets))
        best = min(best, time.perf_counter() - start)
    return [np.asarray(s) for s in signals], compile_s, best


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default="TP")
    parser.add_argument("--walkers", type=int, default=152)
    parser.add_argument("--spread", type=float, default=0.02, help="log-normal scatter of the parameter sets")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    enable_compilation_cache()

    groups, config, geometry, params = workload(args.material)
    sets = parameter_sets(params, args.walkers, args.spread)
    steps = int(sum(g.time_s.shape[1] - 1 for g in groups))
    rows = int(sum(g.time_s.shape[0] for g in groups))
    print(f"{args.material}: {rows} simulated rows in {len(groups)} groups, {steps} scan steps per walker", flush=True)
    routes = {}
    for name in ROUTES:
        signals, compile_s, best = timed_route(name, groups, config, geometry, sets, args.repeats)
        routes[name] = {"signals": signals, "compile_s": compile_s, "ms_per_walker": best / args.walkers * 1e3}
        rate = routes[name]["ms_per_walker"]
        print(f"{name:13s} {rate:6.2f} ms per walker   (compile {compile_s:.1f} s)", flush=True)
    difference = {}
    for name in ROUTES:
        if name == REFERENCE:
            continue
        difference[name] = {}
        for g, a, b in zip(groups, routes[name]["signals"], routes[REFERENCE]["signals"], strict=True):
            # force [N] for load cycles and blocking, strain [-] for the stroke
            difference[name][g.test] = max(difference[name].get(g.test, 0.0), float(np.max(np.abs(a - b))))
    print(f"largest signal difference from {REFERENCE}: {difference}")
    if max(v for d in difference.values() for v in d.values()) > 1e-6:
        raise SystemExit(f"a route disagrees with {REFERENCE} by more than 1e-6; not reporting their speed")
    speedup = {name: routes[REFERENCE]["ms_per_walker"] / routes[name]["ms_per_walker"] for name in ROUTES}
    print("speed-up over " + REFERENCE + ": " + ", ".join(f"{k} {v:.2f}x" for k, v in speedup.items()))
    summary = {
        "benchmark": "solve",
        "material": args.material,
        "walkers": args.walkers,
        "spread": args.spread,
        "rows": rows,
        "scan_steps_per_walker": steps,
        "ms_per_walker": {k: v["ms_per_walker"] for k, v in routes.items()},
        "compile_s": {k: v["compile_s"] for k, v in routes.items()},
        "max_signal_difference_from_reference": difference,
        "reference": REFERENCE,
        "speedup_over_reference": speedup,
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
