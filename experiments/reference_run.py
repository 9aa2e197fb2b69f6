"""Does the convergence rule certify the right posterior? A certified run against a 4x longer reference run.

Reads a certified result (a converged ``peano-bayes fit`` or ``run`` folder of a bundled material: its
``summary.json`` and ``posterior.nc``), fits the same dataset again with another seed, the same walkers, warm-up,
ensembles and tests, and exactly ``--factor`` times as many steps (``infer(min_steps=...)``: the rule may not
stop it early), then compares every sampled quantity of the two ``posterior.nc`` files (population values,
specimen values and contrasts, a new specimen, the spread, the noise scales): the certified run's mean and its
94 % interval ends (3 % and 97 % quantiles, equal-tailed, where ``summary.json`` reports HDIs), each in units of
the reference's sd. The main-job issue's rule for "the same posterior" is means within 0.1 sd and interval ends
within 0.2 sd. Each difference is also given in units of its Monte Carlo standard error (both runs' arviz MCSE,
every walker a chain, as the convergence rule's ESS counts them): at the rule's ESS of 1000 an
interval end's own error is about 0.09 sd, so a difference beyond 0.2 sd that is within 3 MCSE is noise, not a
wrong posterior.

The reference fits the dataset, prior and model the certified run recorded; a certified run whose discovery added
an effect to its model, or whose sampled parameters the reference does not share, is refused.

The reference run saves its state after every chunk: run the same command again to continue it.

    .venv/bin/python experiments/reference_run.py /work/scratch/certified_TP --out /work/scratch/reference_TP

With ``--against OTHER`` it runs nothing and compares the two existing results (OTHER's sd as the unit), for
two runs of the same posterior made some other way (another warm-up, say).

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
from peano_bayes.app.pipeline import infer
from peano_bayes.bundled import dataset_path

#: The rule for "the same posterior", in units of the reference's sd.
MAX_MEAN_SD, MAX_END_SD = 0.1, 0.2
#: The 94 % interval's ends.
QUANTILES = (0.03, 0.97)


def certified_warmup(summary: dict) -> int:
    """The warm-up steps of a converged run: ``summary.json``'s ``warmup``, or for a summary written before that
    key existed, its burn-in less the ``ceil(2 tau_max)`` steps the convergence rule discards after the warm-up."""
    if "warmup" in summary:
        return int(summary["warmup"])
    conv = summary["convergence"]
    return int(conv["discard_steps"]) - int(np.ceil(2.0 * max(conv["tau_steps"].values())))


def draws_by_quantity(path: Path) -> dict[str, np.ndarray]:
    """(walkers, draws) of every scalar quantity of ``posterior.nc``'s posterior group (every walker a chain, as
    the convergence rule's ESS counts them); a quantity with more dimensions than chain and draw (a
    per-specimen value) gives one entry per element, ``name[i]``."""
    posterior = az.from_netcdf(path).posterior
    out = {}
    for name, var in posterior.data_vars.items():
        values = np.asarray(var, dtype=float).reshape(var.shape[0], var.shape[1], -1)  # (walkers, draws, k)
        if values.shape[-1] == 1:
            out[name] = values[..., 0]
        else:
            out.update({f"{name}[{i}]": values[..., i] for i in range(values.shape[-1])})
    return out


def agreement(certified: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> dict:
    """Per quantity: |mean difference| and the larger |interval-end difference|, in the reference's sd and in
    their Monte Carlo standard errors (``*_mcse``: the difference over the root sum of both runs' MCSE); the
    largest of each with its quantity, and whether the largest in sd are within the rule. Both runs must hold
    the same quantities; a constant one (a held value) is skipped."""
    if set(certified) != set(reference):
        raise SystemExit(
            "the two posteriors hold different quantities: only certified "
            f"{sorted(set(certified) - set(reference))}, only reference {sorted(set(reference) - set(certified))}"
        )
    rows = {}
    for name in sorted(certified):
        ours, ref = certified[name], reference[name]
        sd = float(np.std(ref))
        if not np.isfinite(sd) or not np.all(np.isfinite(ours)):
            raise SystemExit(f"{name}: non-finite draws")
        if sd == 0.0:
            continue
        mean_se = np.hypot(az.mcse(ours, method="mean"), az.mcse(ref, method="mean"))
        mean = abs(float(np.mean(ours) - np.mean(ref)))
        ends, ends_z = [], []
        for q in QUANTILES:
            se = np.hypot(az.mcse(ours, method="quantile", prob=q), az.mcse(ref, method="quantile", prob=q))
            d = abs(float(np.quantile(ours, q) - np.quantile(ref, q)))
            ends.append(d / sd)
            ends_z.append(d / se)
        rows[name] = {
            "mean_sd": mean / sd,
            "mean_mcse": float(mean / mean_se),
            "interval_end_sd": max(ends),
            "interval_end_mcse": float(max(ends_z)),
        }
    if not rows:
        raise SystemExit("no quantity varies in the reference: nothing to compare")
    worst = {key: max(rows, key=lambda n: rows[n][key]) for key in next(iter(rows.values()))}
    return {
        "quantities": len(rows),
        "max_mean_difference_sd": rows[worst["mean_sd"]]["mean_sd"],
        "worst_mean": worst["mean_sd"],
        "max_interval_end_difference_sd": rows[worst["interval_end_sd"]]["interval_end_sd"],
        "worst_interval_end": worst["interval_end_sd"],
        "max_mean_difference_mcse": rows[worst["mean_mcse"]]["mean_mcse"],
        "max_interval_end_difference_mcse": rows[worst["interval_end_mcse"]]["interval_end_mcse"],
        "same_posterior": bool(
            rows[worst["mean_sd"]]["mean_sd"] <= MAX_MEAN_SD
            and rows[worst["interval_end_sd"]]["interval_end_sd"] <= MAX_END_SD
        ),
        "rows": rows,
    }


def certified_dataset(summary: dict) -> Path:
    """The dataset the certified run fitted: the recorded path, or, when that file is gone (a run from a
    temporary clone), the bundled file of the same name."""
    recorded = Path(summary["dataset"])
    if recorded.exists():
        return recorded
    bundled = dataset_path(summary["material"])
    if recorded.name != bundled.name or recorded.parent.parts[-2:] != ("bundled", "data"):
        raise SystemExit(f"{recorded}: the certified run's dataset is gone and is not a bundled file")
    return bundled


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("certified", type=Path, help="a converged result folder (summary.json, posterior.nc)")
    parser.add_argument("--out", type=Path, help="where the reference run writes (resumable)")
    parser.add_argument(
        "--against",
        type=Path,
        help="compare with this existing result folder instead of running a reference (its sd is the unit)",
    )
    parser.add_argument("--factor", type=int, default=4, help="reference length over the certified run's")
    parser.add_argument("--seed", type=int, default=1, help="the reference's seed (not the certified run's)")
    args = parser.parse_args()
    if not (args.certified / "summary.json").is_file() or not (args.certified / "posterior.nc").is_file():
        parser.error(f"{args.certified}: expected a result folder with summary.json and posterior.nc")
    summary = json.loads((args.certified / "summary.json").read_text())
    if not summary["convergence"]["converged"]:
        parser.error(f"{args.certified}: the run is not converged; the comparison needs a certified run")
    if args.against is not None:
        same = agreement(
            draws_by_quantity(args.certified / "posterior.nc"),
            draws_by_quantity(args.against / "posterior.nc"),
        )
        rows = same.pop("rows")
        print(
            json.dumps(
                {
                    "benchmark": "reference_run",
                    "certified": str(args.certified),
                    "against": str(args.against),
                    **same,
                    "per_quantity": rows,
                }
            )
        )
        return
    if args.out is None:
        parser.error("--out is required to run a reference (or give --against RESULT)")
    if args.seed == summary["seed"]:
        parser.error(f"--seed {args.seed} is the certified run's own seed; the reference needs another")
    if args.factor < 2:
        parser.error(f"--factor must be >= 2, got {args.factor}")
    if (summary["model"].get("discovery") or {}).get("adopted"):
        parser.error(
            f"{args.certified}: discovery added {summary['model']['discovery']['adopted']} to its model, which the "
            "reference would not repeat; compare a run without --discover"
        )
    material, steps = summary["material"], int(summary["steps"])
    length = args.factor * steps
    # The reference's settings, as its summary.json records them: the certified run's, with its own seed.
    sampling = dict(seed=args.seed, **{k: summary[k] for k in ("tests", "n_walkers", "n_ensembles")})
    settings = dict(sampling, sampler_coordinates=summary["sampler_coordinates"])
    warmup = certified_warmup(summary)
    enable_compilation_cache()

    label = f"{material}_reference"
    folder = args.out / label
    done = folder / "summary.json"
    previous = json.loads(done.read_text()) if done.exists() else None
    if previous is not None and (
        previous["steps"] != length
        or certified_warmup(previous) != warmup
        or any(previous[k] != v for k, v in settings.items())
    ):
        sys.exit(f"{done}: a reference of other settings or length; move it away or choose another --out")
    if previous is None:
        reference = infer(
            certified_dataset(summary),
            args.out,
            label=label,
            **sampling,
            warmup=warmup,
            coordinates=summary["sampler_coordinates"]["kind"],
            min_steps=length,
            max_steps=length,
            resume=(folder / "sampler_state.npz").exists(),
            progress=False,
            figures=False,
            log=lambda m: print(m, flush=True),
        )
    else:
        reference = previous
    # the model sampled (a certified run whose discovery added nothing sampled its configured model, as here)
    model = lambda s: {k: s["model"][k] for k in ("config", "effects")}  # noqa: E731
    for what, ours, theirs in (
        ("model", model(reference), model(summary)),
        ("prior", reference["prior"], summary["prior"]),
    ):
        if ours != theirs:
            sys.exit(f"the reference's {what} differs from the certified run's: {ours} against {theirs}")
    same = agreement(
        draws_by_quantity(args.certified / "posterior.nc"),
        draws_by_quantity(folder / "posterior.nc"),
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
        + ("" if conv["converged"] else " (the reference itself did not pass the convergence gates)")
    )
    print(
        f"in Monte Carlo standard errors: means within {same['max_mean_difference_mcse']:.1f}, interval ends "
        f"within {same['max_interval_end_difference_mcse']:.1f}"
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
