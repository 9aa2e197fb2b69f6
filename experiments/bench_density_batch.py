"""Cost per walker of one material's sampled log posterior against the batch size it is called with.

emcee's red-blue moves evaluate half an ensemble per call (about 21 walkers on the bundled muscles) and the
independence move a whole one; ``run`` advances four ensembles, so a step makes six to eight such calls. This
times the jitted, vmapped density that ``run`` samples (the posterior ``bench_inference.py`` rebuilds from a
fit folder) at batch sizes 21, 42, 84 and 168, each compiled apart (first call, reported) and then timed as
the best of five calls on parameter sets scattered by 0.005 in the sampler's coordinates around the fit's
linearisation point. Run it alone on the machine; the last line printed is one JSON object.

    python experiments/bench_density_batch.py --material FC --fit-dir RESULTS/FC
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from bench_inference import sampled_posterior

BATCHES = (21, 42, 84, 168)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--material", default="FC")
    parser.add_argument("--fit-dir", type=Path, required=True, help="a `peano-bayes run` folder of the material")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    posterior, point, _ = sampled_posterior(args.material, args.fit_dir)
    rng = np.random.default_rng(0)
    rows = {}
    for n in BATCHES:
        t0 = time.perf_counter()
        np.asarray(posterior.batched(point + 0.005 * rng.normal(size=(n, point.size))))
        first = time.perf_counter() - t0
        best = np.inf
        for _ in range(args.repeats):
            theta = point + 0.005 * rng.normal(size=(n, point.size))
            t0 = time.perf_counter()
            np.asarray(posterior.batched(theta))
            best = min(best, time.perf_counter() - t0)
        rows[n] = {"first_call_s": round(first, 1), "ms_per_call": 1e3 * best, "ms_per_walker": 1e3 * best / n}
        print(f"batch {n}: first call {first:.1f} s, {1e3 * best:.1f} ms, {1e3 * best / n:.2f} ms per walker")
    ratio = rows[BATCHES[0]]["ms_per_walker"] / rows[BATCHES[-1]]["ms_per_walker"]
    print(
        json.dumps(
            {
                "benchmark": "density_batch",
                "material": args.material,
                "batches": rows,
                f"per_walker_{BATCHES[0]}_over_{BATCHES[-1]}": ratio,
            }
        )
    )


if __name__ == "__main__":
    main()
