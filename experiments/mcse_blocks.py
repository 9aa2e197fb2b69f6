"""Is the Monte Carlo standard error the convergence rule uses about right? A check on one long saved run.

The rule's MCSE (and its ESS) come from arviz with each ensemble's walkers laid end to end as one chain
(:func:`peano_bayes.inference.sample.pooled`). Here a run's kept draws (``posterior.nc``) are cut into
``--blocks`` consecutive blocks; per quantity, the block means scatter about their weighted mean by their own
MCSE if it is right, so chi^2 / (blocks - 1) = sum((m_b - m)^2 / mcse_b^2) / (blocks - 1) is about 1 (its median
for 3 degrees of freedom is 0.79). Each block should be many autocorrelation times long. Also printed: the MCSE of
each ensemble's walker-average chain over the pooled one, which would exceed 1 if walkers moving together made
the pooled MCSE too small.

    .venv/bin/python experiments/mcse_blocks.py RESULT/posterior.nc [--blocks 4] [--ensembles 4]

Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import arviz as az
import numpy as np

from peano_bayes.inference.sample import pooled


def scalar_draws(path: Path) -> dict[str, np.ndarray]:
    """(walkers, draws) of every scalar quantity of ``posterior.nc`` (a per-specimen value: one per element)."""
    posterior = az.from_netcdf(path).posterior
    out = {}
    for name, var in posterior.data_vars.items():
        values = np.asarray(var, dtype=float).reshape(var.shape[0], var.shape[1], -1)
        for i in range(values.shape[-1]):
            out[name if values.shape[-1] == 1 else f"{name}[{i}]"] = values[..., i]
    return out


def pooled_mcse(x: np.ndarray, n_ensembles: int) -> float:
    """MCSE of the mean of ``x`` (walkers, draws), each ensemble's walkers laid end to end as the rule does."""
    return float(az.mcse(pooled(np.moveaxis(x[..., None], 0, 1), n_ensembles)[..., 0], method="mean"))


def block_chi2(x: np.ndarray, n_blocks: int, n_ensembles: int) -> float:
    """chi^2 / dof of the block means of ``x`` (walkers, draws) against their pooled MCSE."""
    edges = np.linspace(0, x.shape[1], n_blocks + 1).astype(int)
    blocks = [x[:, a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]
    means = np.array([b.mean() for b in blocks])
    weights = 1.0 / np.array([pooled_mcse(b, n_ensembles) for b in blocks]) ** 2
    centre = np.sum(weights * means) / np.sum(weights)
    return float(np.sum(weights * (means - centre) ** 2) / (n_blocks - 1))


def walker_average_ratio(x: np.ndarray, n_ensembles: int) -> float:
    """MCSE of the mean from each ensemble's walker-average chain over the pooled MCSE."""
    per = x.shape[0] // n_ensembles
    averages = np.stack([x[e * per : (e + 1) * per].mean(axis=0) for e in range(n_ensembles)])
    return float(az.mcse(averages, method="mean")) / pooled_mcse(x, n_ensembles)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("posterior", type=Path, help="a result's posterior.nc")
    parser.add_argument("--blocks", type=int, default=4, help="consecutive blocks (default 4)")
    parser.add_argument("--ensembles", type=int, default=4, help="ensembles the file's walkers form (default 4)")
    args = parser.parse_args()
    if not args.posterior.is_file():
        parser.error(f"{args.posterior}: no such file; expected a result's posterior.nc")
    if args.blocks < 2:
        parser.error(f"--blocks must be at least 2, got {args.blocks}")
    draws = {k: v for k, v in scalar_draws(args.posterior).items() if np.std(v) > 0}
    chi2 = {k: block_chi2(v, args.blocks, args.ensembles) for k, v in draws.items()}
    ratio = {k: walker_average_ratio(v, args.ensembles) for k, v in draws.items()}
    c, r = np.array(list(chi2.values())), np.array(list(ratio.values()))
    print(
        f"{len(c)} quantities, {args.blocks} blocks: chi2/dof of the block means against their MCSE: mean "
        f"{c.mean():.2f}, median {np.median(c):.2f} (1 and 0.79 if the MCSE is right, for 4 blocks)"
    )
    print(f"walker-average MCSE / pooled MCSE: median {np.median(r):.2f}, range {r.min():.2f}-{r.max():.2f}")
    report = {
        "benchmark": "mcse_blocks",
        "posterior": str(args.posterior),
        "quantities": len(c),
        "blocks": args.blocks,
        "chi2_per_dof_mean": float(c.mean()),
        "chi2_per_dof_median": float(np.median(c)),
        "walker_average_ratio_median": float(np.median(r)),
        "walker_average_ratio_min": float(r.min()),
        "walker_average_ratio_max": float(r.max()),
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
