"""The step test's per-substep root solve: the settings in the package against the earlier, more expensive
ones (bisection to 1e-9 in log half-angle, then five Newton steps), side by side in one process.

For each bundled material: its bundled step runs, simulated by the likelihood's own batched prediction at 16
points around its generating parameters (log-normal, 5 % spread, as a sampler evaluates them), and at 64 draws
from its prior (where least-squares starts and SBC go). Reported: milliseconds per batch of 16 of each setting
(best of ``--repeats``, compilation excluded), the ratio, the largest force imbalance each leaves (the solver
error the likelihood checks, N), how many of the prior draws each leaves above the likelihood's tolerance, and
the largest difference between the two settings' predicted strain where both converged (the rig's strain noise
is 5e-4). The last line printed is one JSON object.

    python experiments/bench_step_solve.py [--materials TP FC ...] [--repeats 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
import tomllib

import jax
import jax.numpy as jnp
import numpy as np

import peano_bayes.physics.simulate as simulate
from peano_bayes import bundled, enable_compilation_cache
from peano_bayes.bundled import DATA_DIR
from peano_bayes.data import load
from peano_bayes.inference import likelihood, prepare, prior_for

REFERENCE = {"bracket_atol": 1e-9, "newton_steps": 5}
OURS = {"bracket_atol": simulate._DYNAMIC_BRACKET_ATOL, "newton_steps": simulate.DYNAMIC_ITERATIONS}


def _timed(setting: dict, group, config, geometry, batch, repeats: int):
    simulate._DYNAMIC_BRACKET_ATOL, simulate.DYNAMIC_ITERATIONS = setting["bracket_atol"], setting["newton_steps"]
    strain, pressure = jnp.asarray(group.strain), jnp.asarray(group.pressure_pa)
    f = jax.jit(jax.vmap(lambda p: likelihood.predict_sets(p, group, strain, pressure, config, geometry)))
    predicted, error = (np.asarray(a) for a in f(batch))  # compiles (the setting is read when tracing)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f(batch))
        best = min(best, time.perf_counter() - t0)
    return predicted, error, best


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--materials", nargs="+", default=list(bundled.MATERIALS))
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    enable_compilation_cache()
    with (DATA_DIR / "true_parameters.toml").open("rb") as f:
        truths = tomllib.load(f)
    rows = {}
    try:
        for code in args.materials:
            dataset = load(bundled.dataset_path(code))
            dataset = dataclasses.replace(dataset, runs=tuple(r for r in dataset.runs if r.test == "step"))
            observations = prepare(dataset)
            group = observations.groups[0]
            config = prior_for(code).config  # the material's configured model
            truth = truths[code]["parameters"]
            names = config.parameter_names()
            params = {**config.nominal_parameters(), **{k: v for k, v in truth.items() if k in names}}
            rng = np.random.default_rng(1)
            batch = {k: jnp.asarray(float(v) * np.exp(0.05 * rng.standard_normal(16))) for k, v in params.items()}
            ref = _timed(REFERENCE, group, config, observations.geometry, batch, args.repeats)
            ours = _timed(OURS, group, config, observations.geometry, batch, args.repeats)
            prior = prior_for(code)
            drawn = prior.select([n for n in names if n in prior.names]).sample_params(np.random.default_rng(2), 64)
            prior_batch = {k: jnp.asarray(drawn.get(k, np.full(64, float(v)))) for k, v in params.items()}
            ref_prior = _timed(REFERENCE, group, config, observations.geometry, prior_batch, 1)
            ours_prior = _timed(OURS, group, config, observations.geometry, prior_batch, 1)
            tolerance = likelihood.SOLVER_TOLERANCE["step"]
            both = (ref_prior[1] <= tolerance) & (ours_prior[1] <= tolerance)
            rows[code] = {
                "reference_ms": 1e3 * ref[2],
                "ours_ms": 1e3 * ours[2],
                "speedup": ref[2] / ours[2],
                "reference_max_solver_error_n": float(np.max(ref[1])),
                "ours_max_solver_error_n": float(np.max(ours[1])),
                "max_strain_difference": float(np.max(np.abs(ours[0] - ref[0]))),
                "prior_draws": 64,
                "reference_prior_over_tolerance": int(np.sum(ref_prior[1] > tolerance)),
                "ours_prior_over_tolerance": int(np.sum(ours_prior[1] > tolerance)),
                "prior_max_strain_difference": float(np.max(np.abs(ours_prior[0] - ref_prior[0])[both])),
            }
            r = rows[code]
            print(
                f"{code}: {r['reference_ms']:.0f} ms -> {r['ours_ms']:.0f} ms per 16 points ({r['speedup']:.2f}x); "
                f"solver error {r['reference_max_solver_error_n']:.1e} -> {r['ours_max_solver_error_n']:.1e} N; "
                f"strain differs by at most {r['max_strain_difference']:.1e}; of 64 prior draws "
                f"{r['reference_prior_over_tolerance']} -> {r['ours_prior_over_tolerance']} over the solver "
                f"tolerance, strain differs by at most {r['prior_max_strain_difference']:.1e} where both converged",
                flush=True,
            )
    finally:
        simulate._DYNAMIC_BRACKET_ATOL, simulate.DYNAMIC_ITERATIONS = OURS["bracket_atol"], OURS["newton_steps"]
    speedups = [r["speedup"] for r in rows.values()]
    summary = {
        "benchmark": "step_solve",
        "reference": REFERENCE,
        "ours": OURS,
        "materials": rows,
        "min_speedup": min(speedups),
        "median_speedup": float(np.median(speedups)),
        "max_strain_difference": max(r["max_strain_difference"] for r in rows.values()),
        "prior_over_tolerance": {
            "reference": sum(r["reference_prior_over_tolerance"] for r in rows.values()),
            "ours": sum(r["ours_prior_over_tolerance"] for r in rows.values()),
            "of": 64 * len(rows),
        },
        "prior_max_strain_difference": max(r["prior_max_strain_difference"] for r in rows.values()),
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
