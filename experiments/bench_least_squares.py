"""Does the multi-start least squares converge? Per dataset: whether the best start met the solver's tolerance
and in how many rounds, how many starts failed or stopped at the step limit, the cost and the wall time.

The fits are the ones ``peano-bayes fit`` and ``run`` make (:func:`peano_bayes.inference.driver.least_squares` on the
default tests, the bundled prior of the material, 16 starts, seed 0). Datasets: the bundled files
(``--materials``; a bare ``--materials`` for none), and with ``--user-like`` a file such as a user's rig gives:
FC's generating values tested at 1200 kPa (forces to about 230 N; ``--user-like-kpa 2800``: about 300 N),
sampled at 10 Hz, two specimens, three repeats, the rig's noise. ``--user-like-material`` takes another bundled
material's generating values, ``--user-like-spread`` another between-specimen spread (0: identical specimens,
which shows how much of the least-squares misfit is the specimens' difference).

    python experiments/bench_least_squares.py [--materials TP PR ...] [--user-like [--user-like-kpa 2800]
        [--user-like-material PCS] [--user-like-spread 0]]

The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json

import numpy as np

from peano_bayes.app.pipeline import prior_of, select_tests
from peano_bayes.bundled import MATERIALS, dataset_path
from peano_bayes.data import Dataset, load
from peano_bayes.defaults import DEFAULT_STARTS, DEFAULT_TESTS
from peano_bayes.inference.driver import least_squares
from peano_bayes.inference.posterior import DEFAULT_HELD, build_posterior
from peano_bayes.inference.reduce import prepare
from peano_bayes.materials import material
from peano_bayes.physics import ModelConfig
from peano_bayes.rig import DEFAULT_PROTOCOL, simulate_dataset

USER_LIKE_PRESSURE_PA = 1200e3
USER_LIKE_RATE_HZ = 10.0
#: Log-normal sigma of each specimen's own stiffness factors: the rig's (``simulate_dataset``'s default).
USER_LIKE_SPREAD = 0.05


def user_like_dataset(
    pressure_pa: float = USER_LIKE_PRESSURE_PA, code: str = "FC", specimen_spread: float = USER_LIKE_SPREAD
) -> Dataset:
    """The generating values of bundled material ``code`` at ``pressure_pa`` [Pa] and 10 Hz, two specimens,
    each stiffness of each specimen drawn with its own log-normal factor of sigma ``specimen_spread`` (the rig's
    0.05 by default; see :func:`~peano_bayes.rig.simulate_dataset`): at a high pressure, a file of higher forces
    than the bundled ones."""
    provenance = load(dataset_path(code)).provenance  # the generating values and model of the bundled file
    params = json.loads(provenance["parameters"])
    config = ModelConfig(**json.loads(provenance["config"]))
    spec = dataclasses.replace(material(code), test_pressure_pa=pressure_pa)
    protocol = dataclasses.replace(DEFAULT_PROTOCOL, quasi_static_rate_hz=USER_LIKE_RATE_HZ)
    return simulate_dataset(
        spec, params, config=config, tests=DEFAULT_TESTS, protocol=protocol, seed=0, specimen_spread=specimen_spread
    )


def measure(dataset: Dataset) -> dict:
    dataset = select_tests(dataset, DEFAULT_TESTS)
    whole = prior_of(dataset, None)
    prior = whole.for_config(whole.config)
    observations = prepare(dataset)
    posterior = build_posterior(observations, prior, config=whole.config, held=DEFAULT_HELD)
    fitted = least_squares(posterior, prior, n_starts=DEFAULT_STARTS, seed=0)
    measured = [r.force_n[np.isfinite(r.force_n)] for r in dataset.runs if r.force_n is not None]
    force = max(float(np.abs(f).max()) for f in measured if f.size)  # stroke runs carry no force (NaN)
    return {
        "bins": int(observations.n_bins),
        "max_force_n": round(force, 1),
        "converged": fitted.converged,
        "rounds": fitted.rounds,
        "n_failed": fitted.n_failed,
        "n_step_limit": fitted.n_step_limit,
        "cost": round(fitted.cost, 3),
        # RMSE of the least-squares point per test [N or -], one parameter value shared by the specimens
        "rmse": {test: round(q["rmse"], 6) for test, q in fitted.quality.items()},
        "seconds": round(fitted.seconds, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--materials",
        nargs="*",
        default=list(MATERIALS),
        choices=MATERIALS,
        help="bundled files (default: all; none: `--materials`)",
    )
    parser.add_argument("--user-like", action="store_true", help="also the user-like 10 Hz file")
    parser.add_argument(
        "--user-like-kpa",
        type=float,
        default=USER_LIKE_PRESSURE_PA / 1e3,
        help="test pressure of that file [kPa] (default 1200: forces to about 230 N; 2800: about 300 N)",
    )
    parser.add_argument(
        "--user-like-material", default="FC", choices=MATERIALS, help="its generating values (default FC)"
    )
    parser.add_argument(
        "--user-like-spread",
        type=float,
        default=USER_LIKE_SPREAD,
        help=f"its between-specimen spread (default {USER_LIKE_SPREAD:g}, the rig's)",
    )
    args = parser.parse_args()
    rows = {}
    cases = [(code, lambda code=code: load(dataset_path(code))) for code in args.materials]
    if args.user_like:
        spread = "" if args.user_like_spread == USER_LIKE_SPREAD else f"-spread{args.user_like_spread:g}"
        label = f"{args.user_like_material}-{args.user_like_kpa:g}kPa-10Hz{spread}"
        make = functools.partial(
            user_like_dataset, args.user_like_kpa * 1e3, args.user_like_material, args.user_like_spread
        )
        cases.append((label, make))
    print(
        f"{'dataset':<24}{'bins':>6}{'max F [N]':>10}{'converged':>10}{'rounds':>7}{'failed':>7}{'limit':>6}"
        f"{'cost':>12}{'s':>7}",
        flush=True,
    )
    for label, make in cases:
        r = rows[label] = measure(make())
        print(
            f"{label:<24}{r['bins']:>6}{r['max_force_n']:>10.1f}{str(r['converged']):>10}{r['rounds']:>7}"
            f"{r['n_failed']:>7}{r['n_step_limit']:>6}{r['cost']:>12.3f}{r['seconds']:>7.1f}",
            flush=True,
        )
    summary = {
        "datasets": rows,
        "best_start_converged": sum(r["converged"] for r in rows.values()),
        "total": len(rows),
    }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
