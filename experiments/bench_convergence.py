"""Cost of the convergence check that ``sample`` runs after every chunk, against the former per-parameter loop.

The check (:func:`peano_bayes.inference.sample.convergence`) computes emcee's autocorrelation time per ensemble,
then arviz's rank-normalized R-hat and bulk and tail ESS on each ensemble's pooled walkers. Until 2026-11-29 it
called ``az.rhat(data)`` (and each ESS) once per parameter and kept one entry, so each figure was computed for
every parameter D times over (20x the work for 20 parameters), between chunks while the sampler waits. Now each
figure is computed once for all parameters.

On synthetic chains of the sizes the sampler meets (AR(1) walkers, lag-1 0.99, so tau is about 200 steps), the
script times the arviz figures both ways on the same pooled draws and checks that they are equal, and times the
whole check as it is now. Sizes: the main job's longest chain (PCS: 2343 steps, 4 x 42 walkers, 20 parameters;
300 warm-up steps dropped where the main job dropped 900, so about 1640 kept steps where its last check had about
1390) and a long run (7300 steps, 4 x 38 walkers, 20 parameters; the independent-data fit, with 4 x 42 walkers,
was at that length when its checks were timed by hand).

    python experiments/bench_convergence.py

Last line: one JSON object with, per size, ``once_s``, ``per_parameter_s``, their ratio, ``check_s`` (the whole
check now) and ``equal`` (the figures agree exactly).
"""

from __future__ import annotations

import json
import time

import arviz as az
import numpy as np

from peano_bayes.inference.sample import arviz_figures, convergence, pooled

SIZES = {  # name -> (steps, walkers, parameters, warm-up steps, ensembles)
    "main_job_longest": (2343, 168, 20, 300, 4),
    "long_run": (7300, 152, 20, 300, 4),
}


def chain_of(steps: int, walkers: int, ndim: int, lag1: float = 0.99, seed: int = 0) -> np.ndarray:
    """(steps, walkers, ndim) AR(1) walkers of unit marginal variance."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((steps, walkers, ndim))
    chain = np.empty_like(noise)
    chain[0] = noise[0]
    scale = np.sqrt(1.0 - lag1**2)
    for t in range(1, steps):
        chain[t] = lag1 * chain[t - 1] + scale * noise[t]
    return chain


def figures_per_parameter(data, names) -> tuple[np.ndarray, ...]:
    """The former check's arviz part: each figure computed for all parameters, once per parameter."""
    return (
        np.array([float(az.rhat(data)[k]) for k in names]),
        np.array([float(az.ess(data, method="bulk")[k]) for k in names]),
        np.array([float(az.ess(data, method="tail")[k]) for k in names]),
    )


def timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0


def main() -> None:
    report = {}
    for name, (steps, walkers, ndim, warmup, n_ensembles) in SIZES.items():
        chain = chain_of(steps, walkers, ndim)
        result, check_s = timed(convergence, chain, None, warmup, n_ensembles)
        kept = pooled(chain[result.discard :], n_ensembles)
        names = [f"p{i}" for i in range(ndim)]
        data = az.convert_to_dataset({k: kept[..., i] for i, k in enumerate(names)})
        once, once_s = timed(arviz_figures, data)  # as the check does now
        former, former_s = timed(figures_per_parameter, data, names)
        equal = all(np.array_equal(a, b) for a, b in zip(once, former, strict=True))
        equal = equal and all(
            np.array_equal(a, b) for a, b in zip(once, (result.rhat, result.ess_bulk, result.ess_tail), strict=True)
        )
        report[name] = {
            "steps": steps,
            "walkers": walkers,
            "parameters": ndim,
            "check_s": round(check_s, 2),
            "once_s": round(once_s, 2),
            "per_parameter_s": round(former_s, 2),
            "ratio": round(former_s / once_s, 1),
            "equal": bool(equal),
        }
        print(
            f"{name}: {steps} steps x {walkers} walkers x {ndim}: figures once {once_s:.1f} s, per parameter "
            f"{former_s:.1f} s ({former_s / once_s:.1f}x), whole check now {check_s:.1f} s, equal {equal}"
        )
    print(json.dumps(report))


if __name__ == "__main__":
    main()
