"""Cost of integrating the fitted inputs' error out of the likelihood (``likelihood.INPUT_ERROR_TESTS``), side by
side in one process on a bundled material's load cycles, blocking and stroke tests: the package's way (``ours``: the
error's Jacobian computed once at the evaluation point and held, ``Posterior.with_input_error_at``, as ``fit`` does
at the exact-input mode), the Jacobian computed at every evaluation (``live``, one forward-mode derivative per error
column) and the inputs treated as exact (``reference``, ``prepare(..., input_errors=frozenset())``). For each:
compile time and evaluations per second of the batched log posterior (the sampler's), and compile time and calls
per second of its value and gradient (what a mode search on the full likelihood costs; the package's
``Posterior.value_and_grad`` treats the inputs as exact). The last line printed is one JSON object with the cost
ratios to the reference.

Evaluated at the material's generating values. Timings on a shared machine vary by 10-20 % between runs: run
it on an otherwise idle core (``taskset -c 1``).

    python experiments/bench_input_error.py [CODE] [--batch 144] [--repeats 5]
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

from peano_bayes.bundled import DATA_DIR, dataset_path
from peano_bayes.data import load
from peano_bayes.inference.posterior import build_posterior
from peano_bayes.inference.prior_files import prior_for
from peano_bayes.inference.reduce import prepare


def timed(fn, arg, repeats: int) -> tuple[float, float]:
    """(compile + first call seconds, best of ``repeats`` later calls in seconds)."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn(arg))  # JAX dispatches asynchronously: wait for the result
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(arg))
        best = min(best, time.perf_counter() - t0)
    return first, best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("code", nargs="?", default="TP")
    parser.add_argument("--batch", type=int, default=144, help="walkers per batched call (4 ensembles of 36)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    dataset = load(dataset_path(args.code))
    dataset = dataclasses.replace(dataset, runs=tuple(r for r in dataset.runs if r.test != "step"))
    prior = prior_for(args.code)
    with (DATA_DIR / "true_parameters.toml").open("rb") as f:
        truth = dict(tomllib.load(f)[args.code]["parameters"])
    noise = json.loads(dataset.provenance["noise"])
    truth.update(
        noise_load_cycle_force_n=noise["force_sd_n"],
        noise_blocking_force_n=noise["force_sd_n"],
        noise_stroke_strain=noise["strain_sd"],
    )
    out = {"material": args.code, "batch": args.batch}
    for label, errors in (("reference", frozenset()), ("live", None), ("ours", None)):
        observations = prepare(dataset) if errors is None else prepare(dataset, input_errors=errors)
        posterior = build_posterior(observations, prior)
        # At the generating values (population; noise at the rig's), specimens at their mean.
        values = {**posterior.prior.median(), **{k: v for k, v in truth.items() if k in posterior.prior.names}}
        theta = np.zeros(posterior.ndim)
        theta[: posterior.prior.ndim] = np.asarray(posterior.prior.to_unconstrained(values))
        if label == "ours":  # as fit does: the error's Jacobian computed once, then held
            posterior = posterior.with_input_error_at(theta)
        thetas = np.tile(theta, (args.batch, 1))
        compile_batched, best_batched = timed(posterior.batched, thetas, args.repeats)
        # The full likelihood's gradient (the package's own value_and_grad treats the inputs as exact).
        full = jax.jit(jax.value_and_grad(lambda t, post=posterior: -post.log_prob(t)))
        compile_grad, best_grad = timed(full, jnp.asarray(theta), args.repeats)
        out[label] = {
            "batched_compile_s": round(compile_batched, 2),
            "evaluations_per_s": round(args.batch / best_batched, 1),
            "grad_compile_s": round(compile_grad, 2),
            "grad_calls_per_s": round(1.0 / best_grad, 2),
        }
        print(label, out[label], flush=True)
    out["evaluation_cost_ratio"] = round(out["reference"]["evaluations_per_s"] / out["ours"]["evaluations_per_s"], 3)
    out["live_evaluation_cost_ratio"] = round(
        out["reference"]["evaluations_per_s"] / out["live"]["evaluations_per_s"], 3
    )
    out["grad_cost_ratio"] = round(out["reference"]["grad_calls_per_s"] / out["ours"]["grad_calls_per_s"], 3)
    out["extra_compile_s"] = round(
        out["ours"]["batched_compile_s"]
        + out["ours"]["grad_compile_s"]
        - out["reference"]["batched_compile_s"]
        - out["reference"]["grad_compile_s"],
        1,
    )
    print(json.dumps(out))


if __name__ == "__main__":
    main()
