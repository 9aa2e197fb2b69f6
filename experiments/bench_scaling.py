"""Scaling of the log posterior's cost: evaluations per second against the rig's sampling rate and the number
of runs, with the default segment binning (``prepare(dataset)``: a fixed number of bins per input segment) and,
side by side in the same process, the previous fixed-count binning (bins of four samples) as the reference.

Data: the TP virtual rig's load cycles, blocking and stroke tests (bundled true parameters, default noise) at
10, 100 and 1000 Hz with one specimen, then at 20 Hz with 1, 2 and 4 specimens (two load cycles, one blocking
and one stroke run each). Each rate is the best of ``--repeats`` timed batches of ``--batch`` walkers at the
truth (compilation timed apart, excluded). Expected: flat against the sampling rate with segment bins (linear
with fixed bins), linear in the number of runs. The last line printed is one JSON object.

    python experiments/bench_scaling.py [--batch 32] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import time
import tomllib

import numpy as np

from peano_bayes.bundled import DATA_DIR
from peano_bayes.inference.posterior import build_posterior
from peano_bayes.inference.prior_files import prior_for
from peano_bayes.inference.reduce import prepare
from peano_bayes.rig import RigProtocol, simulate_dataset

TESTS = ("load_cycle", "blocking", "stroke")


def rate(posterior, theta: np.ndarray, batch: int, repeats: int) -> tuple[float, float]:
    """(evaluations per second, compile seconds) of ``posterior.batched`` on ``batch`` copies of ``theta``."""
    thetas = np.tile(theta, (batch, 1))
    t0 = time.perf_counter()
    posterior.batched(thetas)
    compile_s = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        posterior.batched(thetas)
        best = min(best, time.perf_counter() - t0)
    return batch / best, compile_s


NOISE = {"noise_load_cycle_force_n": 0.2, "noise_blocking_force_n": 0.2, "noise_stroke_strain": 2e-4}


def case(truth: dict, rate_hz: float, specimens: int, batch: int, repeats: int) -> dict:
    data = simulate_dataset(
        "TP",
        truth,
        seed=11,
        specimens=specimens,
        repeats=1,
        tests=TESTS,
        protocol=RigProtocol(quasi_static_rate_hz=rate_hz),
    )
    out = {"rate_hz": rate_hz, "specimens": specimens, "runs": len(data.runs)}
    for label, observations in (("segment", prepare(data)), ("fixed4", prepare(data, {t: 4 for t in TESTS}))):
        posterior = build_posterior(observations, prior_for("TP"))
        known = {k: v for k, v in {**truth, **NOISE}.items() if k in posterior.prior.names}
        values = {**posterior.prior.median(), **known}
        theta = np.zeros(posterior.ndim)
        theta[: posterior.prior.ndim] = np.asarray(posterior.prior.to_unconstrained(values))
        evals, compile_s = rate(posterior, theta, batch, repeats)
        out[label] = {
            "evals_per_s": evals,
            "compile_s": compile_s,
            "bins": observations.n_bins,
            "simulated_points": int(sum(g.time_s.size for g in observations.groups)),
        }
    out["segment_over_fixed4"] = out["segment"]["evals_per_s"] / out["fixed4"]["evals_per_s"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with (DATA_DIR / "true_parameters.toml").open("rb") as f:
        truth = dict(tomllib.load(f)["TP"]["parameters"])
    rows = [case(truth, hz, 1, args.batch, args.repeats) for hz in (10.0, 100.0, 1000.0)]
    rows += [case(truth, 20.0, n, args.batch, args.repeats) for n in (1, 2, 4)]
    print("rate_hz specimens runs | segment: bins points evals/s | fixed 4: bins points evals/s | ratio")
    for r in rows:
        s, f = r["segment"], r["fixed4"]
        print(
            f"{r['rate_hz']:7g} {r['specimens']:9d} {r['runs']:4d} | {s['bins']:6d} {s['simulated_points']:6d} "
            f"{s['evals_per_s']:8.1f} | {f['bins']:6d} {f['simulated_points']:6d} {f['evals_per_s']:8.1f} | "
            f"{r['segment_over_fixed4']:.2f}"
        )
    print(json.dumps({"batch": args.batch, "rows": rows}))


if __name__ == "__main__":
    main()
