"""Does the convergence rule certify the right posterior? A certified run against a 4x longer reference run.

Reads a certified result (a converged ``peano-bayes fit`` or ``run`` folder of a bundled material: its
``summary.json`` and ``posterior.nc``), fits the same dataset again with another seed, the same walkers,
ensembles and tests, and exactly ``--factor`` times as many steps (``infer(min_steps=...)``: the rule may not
stop it early), then compares every sampled quantity of the two ``posterior.nc`` files (population values,
specimen values and contrasts, a new specimen, the spread, the noise scales): the certified run's mean and its
94 % interval ends (3 % and 97 % quantiles), each in units of the reference's sd. The main-job issue's rule for
"the same posterior" is means within 0.1 sd and interval ends within 0.2 sd.

The reference run saves its state after every chunk: run the same command again to continue it.

    .venv/bin/python experiments/reference_run.py /work/scratch/certified_TP --out /work/scratch/reference_TP

Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import arviz as az
import numpy as np

from peano_bayes import enable_compilation_cache
from peano_bayes.bundled import dataset_path
from peano_bayes.pipeline import infer

#: The rule for "the same posterior", in units of the reference's sd.
MAX_MEAN_SD, MAX_END_SD = 0.1, 0.2
#: The 94 % interval's ends.
QUANTILES = (0.03, 0.97)


def draws_by_quantity(path: Path) -> dict[str, np.ndarray]:
    """(n_draws,) draws of every scalar quantity of ``posterior.nc``'s posterior group; a quantity with more
    dimensions than chain and draw (a per-specimen value) gives one entry per element, ``name[i]``."""
    posterior = az.from_netcdf(path).posterior
    out = {}
    for name, var in posterior.data_vars.items():
        values = np.asarray(var).reshape(var.shape[0] * var.shape[1], -1)
        if values.shape[1] == 1:
            out[name] = values[:, 0]
        else:
            out.update({f"{name}[{i}]": values[:, i] for i in range(values.shape[1])})
    return out


def agreement(certified: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> dict:
    """Per quantity present in both: |mean difference| and the larger |interval-end difference|, in the
    reference's sd; the largest of each with its quantity, and whether both are within the rule."""
    rows = {}
    for name in sorted(set(certified) & set(reference)):
        ours, ref = certified[name], reference[name]
        sd = float(np.std(ref))
        if not np.isfinite(sd) or sd == 0.0:
            continue  # a constant (a held value): nothing to compare
        mean = abs(float(np.mean(ours) - np.mean(ref))) / sd
        ends = float(np.max(np.abs(np.quantile(ours, QUANTILES) - np.quantile(ref, QUANTILES)))) / sd
        rows[name] = {"mean_sd": mean, "interval_end_sd": ends}
    worst_mean = max(rows, key=lambda n: rows[n]["mean_sd"])
    worst_end = max(rows, key=lambda n: rows[n]["interval_end_sd"])
    return {
        "quantities": len(rows),
        "max_mean_difference_sd": rows[worst_mean]["mean_sd"],
        "worst_mean": worst_mean,
        "max_interval_end_difference_sd": rows[worst_end]["interval_end_sd"],
        "worst_interval_end": worst_end,
        "same_posterior": bool(
            rows[worst_mean]["mean_sd"] <= MAX_MEAN_SD and rows[worst_end]["interval_end_sd"] <= MAX_END_SD
        ),
        "rows": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("certified", type=Path, help="a converged result folder (summary.json, posterior.nc)")
    parser.add_argument("--out", type=Path, required=True, help="where the reference run writes (resumable)")
    parser.add_argument("--factor", type=int, default=4, help="reference length over the certified run's")
    parser.add_argument("--seed", type=int, default=1, help="the reference's seed (not the certified run's)")
    args = parser.parse_args()
    summary = json.loads((args.certified / "summary.json").read_text())
    if not summary["convergence"]["converged"]:
        sys.exit(f"{args.certified}: the run is not converged; the comparison needs a certified run")
    if args.seed == summary["seed"]:
        sys.exit(f"--seed {args.seed} is the certified run's own seed; the reference needs another")
    material, steps = summary["material"], int(summary["steps"])
    length = args.factor * steps
    enable_compilation_cache()

    label = f"{material}_reference"
    folder = args.out / label
    done = folder / "summary.json"
    previous = json.loads(done.read_text()) if done.exists() else None
    if previous is None or previous["steps"] < length:
        reference = infer(
            dataset_path(material),
            args.out,
            label=label,
            seed=args.seed,
            tests=summary["tests"],
            n_walkers=summary["n_walkers"],
            n_ensembles=summary["n_ensembles"],
            min_steps=length,
            max_steps=length,
            resume=(folder / "sampler_state.npz").exists(),
            progress=False,
            figures=False,
            log=lambda m: print(m, flush=True),
        )
    else:
        reference = previous
    same = agreement(
        draws_by_quantity(args.certified / "posterior.nc"), draws_by_quantity(folder / "posterior.nc")
    )
    conv = reference["convergence"]
    print(f"certified: {material}, {steps} steps, seed {summary['seed']}")
    print(
        f"reference: {reference['steps']} steps ({args.factor}x), seed {args.seed}, converged={conv['converged']}, "
        f"tau_max {max(conv['tau_steps'].values()):.1f}"
    )
    print(
        f"over {same['quantities']} quantities: means within {same['max_mean_difference_sd']:.3f} sd "
        f"({same['worst_mean']}), 94 % interval ends within {same['max_interval_end_difference_sd']:.3f} sd "
        f"({same['worst_interval_end']}); rule {MAX_MEAN_SD} / {MAX_END_SD} sd: "
        + ("the same posterior" if same["same_posterior"] else "NOT the same posterior")
    )
    rows = same.pop("rows")
    print(
        json.dumps(
            {
                "benchmark": "reference_run",
                "material": material,
                "certified_steps": steps,
                "certified_seed": summary["seed"],
                "reference_steps": reference["steps"],
                "reference_seed": args.seed,
                "reference_converged": conv["converged"],
                **same,
                "per_quantity": rows,
            }
        )
    )


if __name__ == "__main__":
    main()
