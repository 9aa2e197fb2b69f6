"""Compile time and run time of the least-squares fits, with the Jacobian materialized by forward mode (ours,
``inference.fit.dense_jacobian``) and with optimistix's default linearize-and-transpose (the reference), side by
side in one process on the same residual function, starts and solver settings.

Two fits are measured:
- ``inference``: the multi-start fit of a bundled material's load cycles, blocking and stroke tests
  (``inference.fit``'s residuals), ``--starts`` starts vmapped;
- ``discovery``: the superset model's batch of :data:`~peano_bayes.discovery.fitting.BATCH` fits on the
  quasi-static tests of a hidden-hysteresis dataset (seed 100), the discovery workflow's most frequent compile.

Each side is traced, lowered and compiled explicitly (an empty in-process cache; the persistent cache is
disabled here so that neither side reads the other's or an earlier run's programs), then run twice; the second
run is timed. The solutions of both sides are compared. The last line printed is one JSON object with the ratio
reference / ours of the compile times.

    python experiments/bench_fit_compile.py [--material TP] [--starts 4]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import jax

jax.config.update("jax_enable_compilation_cache", False)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

from peano_bayes.bundled import dataset_path  # noqa: E402
from peano_bayes.data import load  # noqa: E402
from peano_bayes.discovery import discovery_data  # noqa: E402
from peano_bayes.discovery.fitting import BATCH, MAX_STEPS, discovery_residuals  # noqa: E402
from peano_bayes.discovery.model import DEFAULT_BASE, model_spec, to_unconstrained  # noqa: E402
from peano_bayes.inference.fit import (  # noqa: E402
    DEFAULT_NOISE,
    dense_jacobian,
    prior_spread,
    residual_function,
)
from peano_bayes.inference.prior_files import prior_for  # noqa: E402
from peano_bayes.inference.reduce import prepare  # noqa: E402
from peano_bayes.validation.discovery_benchmark import TRUTH_PARAMS, Case, hidden_dataset  # noqa: E402

QUASI_STATIC = ("load_cycle", "blocking", "stroke")


def compile_and_run(fn, *args) -> dict:
    t0 = time.perf_counter()
    lowered = jax.jit(fn).trace(*args).lower()
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    t3 = time.perf_counter()
    out = jax.block_until_ready(compiled(*args))
    t4 = time.perf_counter()
    timing = {"trace_lower_s": round(t1 - t0, 1), "compile_s": round(t2 - t1, 1), "run_s": round(t4 - t3, 3)}
    timing["total_compile_s"] = round(t2 - t0, 1)
    return timing, out


def inference_fns(code: str, n_starts: int):
    dataset = load(dataset_path(code))
    dataset = dataclasses.replace(dataset, runs=tuple(r for r in dataset.runs if r.test != "step"))
    observations = prepare(dataset)
    prior = prior_for(code).for_config(likelihood=False)
    fixed = {k: jnp.asarray(v) for k, v in prior.config.nominal_parameters().items() if k not in prior.names}
    plain = residual_function(observations, prior, prior.config, DEFAULT_NOISE, prior_spread(prior, 0), fixed)
    starts = jnp.asarray(np.vstack([np.asarray(prior.median_unconstrained())[None], prior.sample(0, n_starts - 1)]))

    def solver(fn):
        def solve(u0s):
            def one(u0):
                solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6)
                value = optx.least_squares(fn, solver, u0, max_steps=80, throw=False).value
                return value, 0.5 * jnp.sum(fn(value, None) ** 2)

            return jax.vmap(one)(u0s)

        return solve

    return solver(plain), solver(dense_jacobian(plain)), (starts,)


def discovery_fns():
    data = discovery_data(hidden_dataset(Case(("hysteresis",), 4.0), seed=100), tests=QUASI_STATIC).fit
    spec = model_spec(DEFAULT_BASE, TRUTH_PARAMS)
    u0 = np.asarray(to_unconstrained(spec.pinned))
    rng = np.random.default_rng(0)
    starts = jnp.asarray(u0 + np.where(spec.mask, 0.1 * rng.standard_normal((BATCH, u0.size)), 0.0))
    masks, pinned = jnp.asarray(np.stack([spec.mask] * BATCH)), jnp.asarray(np.stack([spec.pinned] * BATCH))
    plain = lambda u, args: discovery_residuals(u, *args)[0]  # noqa: E731

    def solver(fn):
        def solve(starts, masks, pinned, data):
            def one(u0, mask, pin):
                args = (data, mask, pin, u0)
                solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6)
                value = optx.least_squares(fn, solver, u0, args, max_steps=MAX_STEPS, throw=False).value
                return value, 0.5 * jnp.sum(plain(value, args) ** 2)

            return jax.vmap(one)(starts, masks, pinned)

        return solve

    return solver(plain), solver(dense_jacobian(plain)), (starts, masks, pinned, data)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="TP")
    parser.add_argument("--starts", type=int, default=4)
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    out = {"benchmark": "fit_compile", "material": args.material, "starts": args.starts}
    for name, build in (("inference", lambda: inference_fns(args.material, args.starts)), ("discovery", discovery_fns)):
        reference_fn, ours_fn, fn_args = build()
        row = {}
        for label, fn in (("reference", reference_fn), ("ours", ours_fn)):
            row[label], (values, costs) = compile_and_run(fn, *fn_args)
            row[label]["costs"] = [round(float(c), 6) for c in np.asarray(costs)]
            print(name, label, row[label], flush=True)
        row["compile_ratio"] = round(row["reference"]["total_compile_s"] / row["ours"]["total_compile_s"], 2)
        row["run_ratio"] = round(row["reference"]["run_s"] / row["ours"]["run_s"], 2)
        ref, ours = np.asarray(row["reference"]["costs"]), np.asarray(row["ours"]["costs"])
        row["max_relative_cost_difference"] = float(np.max(np.abs(ref - ours) / np.maximum(np.abs(ref), 1e-12)))
        out[name] = row
    print(json.dumps(out))


if __name__ == "__main__":
    main()
