"""A fast look at calibration: the SBC problem's truths against the Laplace approximation at the posterior mode.

Each replicate of the hierarchical SBC problem (:mod:`peano_bayes.validation.sbc`, ``--specimens`` specimens,
TP load cycles) draws a truth, runs the virtual rig, and finds the posterior mode and its Laplace covariance as
``peano-bayes fit`` does before sampling (:func:`~peano_bayes.inference.laplace.posterior_mode`, then
:func:`~peano_bayes.inference.laplace.refine_mode`); no sampler runs. The truth's z-score per parameter,
``(truth - mode) / sd``, is then N(0, 1) for a calibrated Gaussian posterior. Seconds per replicate instead of
minutes, so likelihood variants can be compared on the same replicates before a full SBC is spent on one:

- ``exact-inputs-likelihood``: the load cycles' fitted driving inputs taken as exact (``input_errors`` empty);
- ``input-error``: the package's likelihood (the fitted inputs' error integrated out in the tests of
  :data:`~peano_bayes.inference.reduce.INPUT_ERROR_TESTS`);
- ``noiseless-inputs``: the rig's strain and pressure sensors noiseless, so the fitted inputs are exact (the
  ceiling either likelihood can reach).

The Laplace approximation is not the posterior (the spread ``specimen_log_sd`` is skewed, and a replicate whose
mode search stops early gives a large z), so a robust width, median |z| / 0.6745, is reported beside the
fraction with |z| < 1.645 (the Laplace 90 % interval's coverage). A diagnostic, not the SBC: the pre-registered
study samples. Rows are appended to ``OUT/<variant>.jsonl`` (a rerun skips replicates already there); the last
line printed is one JSON object.

    python experiments/sbc_laplace.py --variant input-error --replicates 60 --seed 555000 --out DIR
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from peano_bayes.inference.laplace import NonCentred, posterior_mode, refine_mode
from peano_bayes.inference.reduce import INPUT_ERROR_TESTS, prepare
from peano_bayes.validation import sbc

VARIANTS = {
    "exact-inputs-likelihood": (frozenset(), False),
    "input-error": (INPUT_ERROR_TESTS, False),
    "noiseless-inputs": (frozenset(), True),
}


def summary(rows: list[dict]) -> dict:
    """Per parameter: Laplace 90 % coverage, robust z width, mean z, replicates with |z| > 4."""
    names = rows[0]["names"]
    z = np.array([r["z"] for r in rows])
    return {
        name: {
            "coverage_90": float(np.mean(np.abs(z[:, j]) < 1.645)),
            "robust_z_sd": float(np.median(np.abs(z[:, j])) / 0.6745),
            "mean_z": float(np.mean(z[:, j])),
            "beyond_4": int(np.sum(np.abs(z[:, j]) > 4.0)),
        }
        for j, name in enumerate(names)
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variant", choices=sorted(VARIANTS), required=True)
    parser.add_argument("--replicates", type=int, default=60)
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--specimens", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    input_errors, noiseless = VARIANTS[args.variant]
    base = sbc.base_posterior(args.specimens, input_errors=input_errors)
    start, spread = sbc.mode_start(base)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"{args.variant}.jsonl"
    rows = [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []
    done = {r["index"] for r in rows if r["seed"] == args.seed}
    with path.open("a") as sink:
        for index in range(args.replicates):
            if index in done:
                continue
            t0 = time.perf_counter()
            truth, data, _, _ = sbc.replicate_data(base, index, seed=args.seed, exact_inputs=noiseless)
            observations = prepare(data, input_errors=input_errors)
            try:
                posterior = base.with_observations(observations)
            except ValueError:  # other segment shapes: its own compilation
                posterior = dataclasses.replace(base, observations=observations)
            posterior = posterior.with_batch_rows(8)
            exact = posterior_mode(posterior, start, np.diag(spread**2))
            posterior = posterior.with_input_error_at(exact.mode)  # as peano-bayes fit does (none to hold: no-op)
            laplace = refine_mode(posterior.batched, exact, coordinates=NonCentred.of(posterior))
            sd = np.sqrt(np.diag(laplace.covariance))
            row = {
                "seed": args.seed,
                "index": index,
                "variant": args.variant,
                "names": list(base.names),
                "z": ((truth.theta - laplace.mode) / sd).tolist(),
                "sd": sd.tolist(),
                "seconds": time.perf_counter() - t0,
            }
            sink.write(json.dumps(row) + "\n")
            sink.flush()
            rows.append(row)
            print(f"replicate {index}: {row['seconds']:.1f} s", flush=True)
    rows = [r for r in rows if r["seed"] == args.seed and r["index"] < args.replicates]
    print(
        json.dumps({"variant": args.variant, "seed": args.seed, "replicates": len(rows), "by_parameter": summary(rows)})
    )


if __name__ == "__main__":
    main()
