"""Where discovery's time goes on one bundled material, as ``run`` calls it (the configured model as the base,
its starts also around the prior's medians): the discovery runs twice in one process, so the second pays no
compilation, and every call of its three compiled programs (the vmapped Levenberg-Marquardt solve, the
Jacobian behind the Laplace covariance and the screening, the evaluation on fitted and held-out runs) is timed.
The difference between the two runs is compilation and tracing. Run it alone on the machine; the last line
printed is one JSON object.

    python experiments/profile_discovery.py [--material TP]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time

import jax

import peano_bayes.discovery.fitting as fitting
from peano_bayes.app.pipeline import DEFAULT_TESTS, prior_of, select_tests
from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.discovery.choice import choose_model

PROGRAMS = {"solve": "solve_batch", "jacobian": "jacobian_of", "evaluate": "pointwise"}


def timed_programs() -> dict:
    """Wrap discovery's compiled programs so each call's wall time (results ready) is added to the returned
    ``{program: [calls, seconds]}``; :func:`reset` zeroes it between runs."""
    record = {name: [0, 0.0] for name in PROGRAMS}

    def wrap(name, fn):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            out = jax.block_until_ready(fn(*args, **kwargs))
            record[name][0] += 1
            record[name][1] += time.perf_counter() - t0
            return out

        return timed

    for name, attribute in PROGRAMS.items():
        setattr(fitting, attribute, wrap(name, getattr(fitting, attribute)))
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="TP")
    args = parser.parse_args()
    dataset = select_tests(load(dataset_path(args.material)), DEFAULT_TESTS)
    prior = prior_of(dataset, None)
    record = timed_programs()
    runs = []
    for run in range(2):
        for entry in record.values():
            entry[:] = [0, 0.0]
        t0 = time.perf_counter()
        lines = []
        log = lambda m, lines=lines, t0=t0: lines.append((round(time.perf_counter() - t0, 1), m))  # noqa: E731
        with tempfile.TemporaryDirectory() as folder:
            choice = choose_model(dataset, prior.config, folder, seed=0, log=log, centre=prior.median())
        seconds = time.perf_counter() - t0
        runs.append(
            {
                "seconds": round(seconds, 1),
                "verdict": choice.verdict,
                "programs": {k: {"calls": c, "seconds": round(s, 1)} for k, (c, s) in record.items()},
                "progress": lines,
            }
        )
        print(f"run {run + 1}: {seconds:.1f} s, verdict {choice.verdict}; {runs[-1]['programs']}", flush=True)
    print(
        json.dumps(
            {
                "benchmark": "profile_discovery",
                "material": args.material,
                "first_run": runs[0],
                "second_run": runs[1],
                "compilation_s": round(runs[0]["seconds"] - runs[1]["seconds"], 1),
            }
        )
    )


if __name__ == "__main__":
    main()
