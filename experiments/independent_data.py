"""Independent data: fit rig data made by another physics, and check what a designer reads off the posterior.

peano_bayes' own virtual rig shares the fitted model's assumptions, so recovering its parameters proves little
about data from elsewhere. Here the data come from Veale's force-balance model (``physics/reference.py``) with
the paper's Table 2 values: the rig's quasi-static protocol (load cycles, blocking, stroke) on two specimens
whose stiffnesses differ by the rig's log-normal spread, with the rig's sensor noise
(:func:`peano_bayes.rig.simulate_veale_dataset`). The default engine fits and samples it exactly as
``peano-bayes fit`` does (:func:`peano_bayes.app.pipeline.infer`). No parameter of one model maps onto the
other, so what is checked is what both predict: the **blocking force** and the **free strain** at each of
``--fractions`` of the test pressure. Veale's population muscle (Table 2 values, no specimen factor) gives the
truth. Our prediction is the 94 % interval for a **new specimen**: the posterior draws with the between-specimen
spread (``parameter_draws(level="new_specimen")``), each pushed through the relaxed muscle's static force at
zero strain and static strain at zero force. A check passes when the truth lies inside the interval.

**Model discrepancy.** Where the model cannot take the data's shape, the truth differs from the best model in the
family by a smooth curve that no parameter draw reproduces; the parameter intervals alone then miss it (version
1 below). Each quantity here is read off one fitted test (the blocking force off the blocking test, the free
strain off the stroke test, the same curves at zero strain and at about zero load), and that test's residuals at
the posterior mean measure how far the model misses such a curve beyond the sensor noise: ``excess_rmse`` in
``summary.json`` (:func:`peano_bayes.inference.fit.noise_excess`, the floor estimated from the raw signals
without a model). The interval "with discrepancy" adds to each draw an independent normal value of that sd
(the marginal predictive of an unknown discrepancy of that size); the parameter-only interval is reported too.

Pre-registered, version 1 (before its first run): seed 0, material conditions of FC (200 kPa, 40 N start
tension), the default engine and tests, 200 draws, fractions 0.25 0.5 0.75 1.0; pass = every check inside the
parameter-only interval. Failed (4 of 8 on the AR(1) likelihood).
Pre-registered, version 2 (2026-11-28, before its first run; the idea was formed on seed 0's result): seed 1
(data and sampler), otherwise as version 1; pass = every check inside the interval with discrepancy. Passed
(8 of 8; 4 of 8 inside the parameter-only intervals).
Pre-registered replication (2026-11-29, before its run): version 2's criterion on seed 2, the run that
``independent_metrics.py``'s pre-registered check reads.

    python experiments/independent_data.py [--out DIR] [--seed N] [--draws N]

Resumes an interrupted fit (``infer(resume=True)``). Writes ``OUT/independent_data-seed<N>.json``; the last line
printed is the same JSON object. ``passed`` is version 2's verdict (null for a result sampled before fits reported
``excess_rmse``), ``passed_parameter_interval`` version 1's.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np

from peano_bayes.app.pipeline import infer
from peano_bayes.atomic import write_text
from peano_bayes.data import load, save
from peano_bayes.defaults import HDI_PROB
from peano_bayes.inference.results import load_result, parameter_draws, result_config
from peano_bayes.materials import material
from peano_bayes.physics.reference import VEALE_TABLE2, veale_blocking_force, veale_free_strain
from peano_bayes.physics.simulate import static_force, static_strain
from peano_bayes.rig import simulate_veale_dataset

MATERIAL = "FC"
FRACTIONS = (0.25, 0.5, 0.75, 1.0)
#: Quantity -> the fitted test it is read off, whose model discrepancy it carries.
MEASURED_BY = {"blocking_force_n": "blocking", "free_strain": "stroke"}


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


def discrepancy_sd(summary: dict) -> dict[str, float] | None:
    """Quantity -> sd of the model discrepancy it carries: the RMSE beyond the sensor noise of the test it is
    read off (:data:`MEASURED_BY`), at the posterior mean; None for a result sampled before fits reported it
    (version 1's), which then gets the parameter-only intervals alone."""
    quality = summary["fit_quality_posterior_mean"]
    if any("excess_rmse" not in quality.get(t, {}) for t in MEASURED_BY.values()):
        return None
    sd = {q: quality[t]["excess_rmse"] for q, t in MEASURED_BY.items()}
    bad = {q: v for q, v in sd.items() if v is None or not np.isfinite(v)}
    if bad:
        raise SystemExit(f"the model discrepancy is not a number for {bad}: the sensor noise could not be estimated")
    return {q: float(v) for q, v in sd.items()}


def checks(
    idata, pressures_pa: np.ndarray, n_draws: int, seed: int, geometry, discrepancy: dict[str, float] | None
) -> list[dict]:
    """Per quantity and pressure: Veale's truth against the new-specimen 94 % interval, with the model
    discrepancy of ``discrepancy`` (quantity -> sd; None: parameter-only intervals alone, the others None) and
    without it (``parameter_*``)."""
    true = truth(pressures_pa)
    pred = predicted(idata, pressures_pa, n_draws, seed, geometry)
    rng = np.random.default_rng(seed)
    rows = []
    for quantity in MEASURED_BY:
        for j, p in enumerate(pressures_pa):
            draws = pred[quantity][:, j]
            draws = draws[np.isfinite(draws)]
            if draws.size < 2:
                raise RuntimeError(f"{quantity} at {p / 1e3:g} kPa: the physics failed for (almost) every draw")
            p_low, p_high = (float(v) for v in az.hdi(draws, hdi_prob=HDI_PROB))
            low = high = sd = None
            if discrepancy is not None:
                sd = discrepancy[quantity]
                with_discrepancy = draws + rng.normal(0.0, sd, draws.size)
                low, high = (float(v) for v in az.hdi(with_discrepancy, hdi_prob=HDI_PROB))
            value = float(true[quantity][j])
            rows.append(
                {
                    "quantity": quantity,
                    "pressure_kpa": float(p) / 1e3,
                    "truth": value,
                    "median": float(np.median(draws)),
                    "discrepancy_sd": sd,
                    "hdi_low": low,
                    "hdi_high": high,
                    "inside": None if low is None else bool(low <= value <= high),
                    "parameter_hdi_low": p_low,
                    "parameter_hdi_high": p_high,
                    "inside_parameter_interval": bool(p_low <= value <= p_high),
                    "n_draws": int(draws.size),
                }
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("results-independent"), help="output folder")
    parser.add_argument("--seed", type=int, default=1, help="seed of the data and the sampler (default 1)")
    parser.add_argument("--draws", type=int, default=200, help="posterior draws pushed through (default 200)")
    parser.add_argument(
        "--warmup", type=int, default=300, help="sampler warm-up steps (default 300: the pre-registered protocol's)"
    )
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
        summary = infer(
            data_file, args.out, seed=args.seed, resume=True, label=label, figures=False, warmup=args.warmup
        )
    idata = load_result(result_dir)
    pressures = np.asarray(FRACTIONS) * material(MATERIAL).test_pressure_pa
    discrepancy = discrepancy_sd(summary)
    if discrepancy is None:
        print("this result predates the fit's excess_rmse: parameter-only intervals (version 1's check) alone")
    rows = checks(idata, pressures, args.draws, args.seed, load(data_file).geometry, discrepancy)
    print(
        f"{'quantity':<18}{'p [kPa]':>8}{'truth':>10}{'median':>10}{'94 %, parameters':>24}"
        f"{'94 %, with discrepancy':>26}  inside"
    )
    for r in rows:
        parameters = f"[{r['parameter_hdi_low']:.4g}, {r['parameter_hdi_high']:.4g}]"
        interval = "-" if r["hdi_low"] is None else f"[{r['hdi_low']:.4g}, {r['hdi_high']:.4g}]"
        inside = r["inside"] if discrepancy is not None else r["inside_parameter_interval"]
        print(
            f"{r['quantity']:<18}{r['pressure_kpa']:>8.0f}{r['truth']:>10.4g}{r['median']:>10.4g}{parameters:>24}"
            f"{interval:>26}  {'yes' if inside else 'NO'}"
        )
    report = {
        "material_conditions": MATERIAL,
        "seed": args.seed,
        "converged": bool(summary["convergence"]["converged"]),
        "total": len(rows),
        "inside": None if discrepancy is None else sum(r["inside"] for r in rows),
        "passed": None if discrepancy is None else all(r["inside"] for r in rows),
        "inside_parameter_interval": sum(r["inside_parameter_interval"] for r in rows),
        "passed_parameter_interval": all(r["inside_parameter_interval"] for r in rows),
        "checks": rows,
    }
    write_text(args.out / f"independent_data-seed{args.seed}.json", json.dumps(report, indent=2) + "\n")
    print(json.dumps(report))


if __name__ == "__main__":
    main()
