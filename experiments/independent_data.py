"""Independent data: fit rig data made by another physics, and check what a designer reads off the posterior.

peano_bayes' own virtual rig shares the fitted model's assumptions, so recovering its parameters proves little
about data from elsewhere. Here the data come from Veale's force-balance model (``physics/reference.py``) with
the paper's Table 2 values: the rig's quasi-static protocol (load cycles, blocking, stroke) on two specimens
whose stiffnesses differ by the rig's log-normal spread, with the rig's sensor noise
(:func:`peano_bayes.rig.simulate_veale_dataset`). The default engine fits and samples it exactly as
``peano-bayes fit`` does (:func:`peano_bayes.pipeline.infer`). No parameter of one model maps onto the
other, so what is checked is what both predict: the **blocking force** and the **free strain** at each of
``--fractions`` of the test pressure. Veale's population muscle (Table 2 values, no specimen factor) gives the
truth. Our prediction is the 94 % interval for a **new specimen**: the posterior draws with the between-specimen
spread (``parameter_draws(level="new_specimen")``), each pushed through the relaxed muscle's static force at
zero strain and static strain at zero force. A check passes when the truth lies inside the interval.

Pre-registered (before the first run): seed 0, material conditions of FC (200 kPa, 40 N start tension), the
default engine and tests, 200 draws, fractions 0.25 0.5 0.75 1.0; pass = every check inside.

    python experiments/independent_data.py [--out DIR] [--seed N] [--draws N]

Resumes an interrupted fit (``infer(resume=True)``). The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np

from peano_bayes.atomic import write_text
from peano_bayes.data import load, save
from peano_bayes.defaults import HDI_PROB
from peano_bayes.inference.results import load_result, parameter_draws, result_config
from peano_bayes.materials import material
from peano_bayes.physics.reference import VEALE_TABLE2, veale_blocking_force, veale_free_strain
from peano_bayes.physics.simulate import static_force, static_strain
from peano_bayes.pipeline import infer
from peano_bayes.rig import simulate_veale_dataset

MATERIAL = "FC"
FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def truth(pressures_pa: np.ndarray) -> dict[str, np.ndarray]:
    """Veale's population muscle at each pressure: blocking force [N] and free strain [-]."""
    return {
        "blocking_force_n": np.asarray(veale_blocking_force(jnp.asarray(pressures_pa), VEALE_TABLE2), float),
        "free_strain": np.asarray(veale_free_strain(jnp.asarray(pressures_pa), VEALE_TABLE2), float),
    }


def predicted(idata, pressures_pa: np.ndarray, n_draws: int, seed: int, geometry) -> dict[str, np.ndarray]:
    """(draws, pressures) new-specimen predictions of the blocking force [N] and free strain [-] of a muscle
    of ``geometry`` (the dataset's)."""
    config = result_config(idata)
    sets, _ = parameter_draws(idata, n_draws, seed, level="new_specimen")
    stacked = {k: jnp.asarray([s[k] for s in sets]) for k in sets[0]}

    def one(params, p):
        return (
            static_force(params, p, 0.0, config=config, geometry=geometry),
            static_strain(params, p, 0.0, config=config, geometry=geometry),
        )

    per_pressure = jax.jit(jax.vmap(jax.vmap(one, in_axes=(None, 0)), in_axes=(0, None)))
    force, strain = per_pressure(stacked, jnp.asarray(pressures_pa))
    return {"blocking_force_n": np.asarray(force), "free_strain": np.asarray(strain)}


def checks(idata, pressures_pa: np.ndarray, n_draws: int, seed: int, geometry) -> list[dict]:
    """Per quantity and pressure: Veale's truth against the new-specimen 94 % interval."""
    true = truth(pressures_pa)
    pred = predicted(idata, pressures_pa, n_draws, seed, geometry)
    rows = []
    for quantity in ("blocking_force_n", "free_strain"):
        for j, p in enumerate(pressures_pa):
            draws = pred[quantity][:, j]
            draws = draws[np.isfinite(draws)]
            if draws.size < 2:
                raise RuntimeError(f"{quantity} at {p / 1e3:g} kPa: the physics failed for (almost) every draw")
            low, high = (float(v) for v in az.hdi(draws, hdi_prob=HDI_PROB))
            value = float(true[quantity][j])
            rows.append(
                {
                    "quantity": quantity,
                    "pressure_kpa": float(p) / 1e3,
                    "truth": value,
                    "median": float(np.median(draws)),
                    "hdi_low": low,
                    "hdi_high": high,
                    "inside": bool(low <= value <= high),
                    "n_draws": int(draws.size),
                }
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("results-independent"), help="output folder")
    parser.add_argument("--seed", type=int, default=0, help="seed of the data and the sampler (default 0)")
    parser.add_argument("--draws", type=int, default=200, help="posterior draws pushed through (default 200)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    label = f"veale-seed{args.seed}"
    data_file = args.out / f"{label}.csv"
    if not data_file.exists():
        save(simulate_veale_dataset(MATERIAL, seed=args.seed), data_file)
    result_dir = args.out / label
    finished = (result_dir / "summary.json").exists() and not (result_dir / "sampler_state.npz").exists()
    if finished:  # a finished result is read, not sampled again
        summary = json.loads((result_dir / "summary.json").read_text())
    else:
        summary = infer(data_file, args.out, seed=args.seed, resume=True, label=label, figures=False)
    idata = load_result(result_dir)
    pressures = np.asarray(FRACTIONS) * material(MATERIAL).test_pressure_pa
    rows = checks(idata, pressures, args.draws, args.seed, load(data_file).geometry)
    print(f"{'quantity':<18}{'p [kPa]':>8}{'truth':>10}{'median':>10}{'94 % interval':>24}  inside")
    for r in rows:
        interval = f"[{r['hdi_low']:.4g}, {r['hdi_high']:.4g}]"
        print(
            f"{r['quantity']:<18}{r['pressure_kpa']:>8.0f}{r['truth']:>10.4g}{r['median']:>10.4g}{interval:>24}"
            f"  {'yes' if r['inside'] else 'NO'}"
        )
    report = {
        "material_conditions": MATERIAL,
        "seed": args.seed,
        "converged": bool(summary["convergence"]["converged"]),
        "inside": sum(r["inside"] for r in rows),
        "total": len(rows),
        "passed": all(r["inside"] for r in rows),
        "checks": rows,
    }
    write_text(args.out / "independent_data.json", json.dumps(report, indent=2) + "\n")
    print(json.dumps(report))


if __name__ == "__main__":
    main()
