"""Why the SBC intervals under-cover: the likelihood's model error, replicate by replicate.

    python experiments/sbc_model_error.py --study STUDY   # a one-specimen study (experiments/sbc.py --out STUDY)

For every replicate of a finished SBC study (``experiments/sbc.py``; its ``replicates.jsonl``) this rebuilds
the replicate's truth and rig data exactly (same root seed, index and redraws; the truth is checked against the
recorded one) but with a noiseless load cell, so the observed bin means minus the likelihood's prediction at
the truth is the model error alone: what the likelihood's forward model (denoised inputs, two quadrature points
per bin) gets wrong about the rig (its own solver on the raw 100 Hz samples). Linearised at the truth, that
error shifts the posterior of the free physics parameters by ``delta = (J^T W J + P)^-1 J^T W r`` (``J`` the
prediction's Jacobian in the sampled coordinates, ``W`` the bins' inverse noise variances at the replicate's
true noise scale, ``P`` a Gaussian approximation of the prior's precision), which is ``z = delta / sd`` posterior
standard deviations; a central interval of level ``q`` then covers the truth with probability
``Phi(k - z) - Phi(-k - z)``, ``k = Phi^-1((1 + q) / 2)``. The mean of that over replicates is the coverage the
model error alone predicts, set beside the coverage the study measured, overall and by quartile of the true
noise scale (the error is a fixed force, so it matters most where the noise is small).

Writes ``STUDY/model_error.csv`` (one row per replicate) and ``STUDY/MODEL_ERROR.md``; last line one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
from scipy.stats import norm

from peano_bayes.atomic import write_text
from peano_bayes.inference.likelihood import bin_noise_sd, predict, prepare
from peano_bayes.rig import RigSimulationError
from peano_bayes.validation.sbc import NOISE_NAME, SBC_FREE, base_posterior, simulate

HERE = Path(__file__).resolve().parent
LEVELS = (0.5, 0.9)


def replay(base, row: dict) -> tuple[np.ndarray, int]:
    """The replicate's truth (D,) and rig seed, redrawn as :func:`run_replicate` drew them."""
    rng = np.random.default_rng([row["seed"], row["index"]])
    for _ in range(row["redraws"] + 1):
        truth = base.prior.sample(rng, 1)[0]
        data_seed = int(rng.integers(2**31))
    if not np.allclose(truth, row["truth"], rtol=0, atol=1e-12):
        raise RuntimeError(f"replicate {row['index']}: the replayed truth differs from the recorded one")
    return truth, data_seed


def model_error(base, truth: np.ndarray, data_seed: int, exact_inputs: bool, prior_sd: np.ndarray) -> dict:
    """Model error of one replicate at its truth: residual figures [N] and the linearised bias ``z`` of each
    free physics parameter in posterior sd (``prior_sd`` (D,): the prior's sd in the sampled coordinates)."""
    prior = base.prior
    params = {**base.fixed, **{k: float(v) for k, v in prior.from_unconstrained(truth).items()}}
    sigma = params[NOISE_NAME]
    data = simulate({**params, NOISE_NAME: 0.0}, seed=data_seed, exact_inputs=exact_inputs)
    posterior = base.with_observations(prepare(data))
    (group,) = posterior.observations.groups
    free = jnp.asarray([posterior.names.index(k) for k in SBC_FREE])

    def prediction(physics):
        p = posterior.params(jnp.asarray(truth).at[free].set(physics))
        model = {k: v for k, v in p.items() if k != NOISE_NAME}
        return predict(model, group, config=posterior.config, geometry=posterior.observations.geometry)[0]

    at_truth = jnp.asarray(truth)[free]
    residual = np.asarray(group.observed) - np.asarray(prediction(at_truth))
    sd = np.asarray(bin_noise_sd(sigma, group))
    measured = np.isfinite(residual)
    jac = np.asarray(jax.jacfwd(prediction)(at_truth)).reshape(-1, len(SBC_FREE))[measured.ravel()]
    weight = 1.0 / sd[measured] ** 2
    spread = prior_sd[np.asarray(free)]
    covariance = np.linalg.inv(jac.T @ (weight[:, None] * jac) + np.diag(1.0 / spread**2))
    delta = covariance @ (jac.T @ (weight * residual[measured]))
    return {
        "noise_sd_n": sigma,
        "error_rms_n": float(np.sqrt(np.mean(residual[measured] ** 2))),
        "error_max_n": float(np.max(np.abs(residual[measured]))),
        "error_rms_over_bin_sd": float(np.sqrt(np.mean((residual[measured] / sd[measured]) ** 2))),
        **{f"z_{k}": float(z) for k, z in zip(SBC_FREE, delta / np.sqrt(np.diag(covariance)), strict=True)},
    }


def predicted_coverage(z: np.ndarray, level: float) -> np.ndarray:
    k = norm.ppf(0.5 + level / 2)
    return norm.cdf(k - z) - norm.cdf(-k - z)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, required=True, help="a finished one-specimen SBC study folder")
    args = parser.parse_args(argv)
    path = args.study / "replicates.jsonl"
    if not path.exists():
        print(f"sbc_model_error.py: error: {path} not found (run experiments/sbc.py first)", file=sys.stderr)
        return 2
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    base = base_posterior()
    names = list(base.names)
    prior_sd = np.std(base.prior.sample(np.random.default_rng(0), 4000), axis=0)
    table = []
    for row in rows:
        truth, data_seed = replay(base, row)
        try:
            figures = model_error(base, truth, data_seed, row.get("exact_inputs", False), prior_sd)
        except RigSimulationError as err:
            print(f"replicate {row['index']}: {err}", file=sys.stderr)
            continue
        covered = {
            f"covered_{level:g}_{k}": bool(row["covered"][str(level)][names.index(k)])
            for level in LEVELS
            for k in SBC_FREE
        }
        table.append({"index": row["index"], **figures, **covered})
    frame = pd.DataFrame(table)
    write_text(args.study / "model_error.csv", frame.to_csv(index=False))

    quartile = pd.qcut(frame["noise_sd_n"], 4, labels=False)
    lines = [
        "# SBC: the likelihood's model error, replicate by replicate",
        "",
        f"`experiments/sbc_model_error.py` on `{args.study.name}` ({len(frame)} replicates). Model error = noiseless "
        "rig bin means minus the likelihood's prediction at the truth; z = the linearised posterior shift it "
        "causes, in posterior sd. Predicted coverage = mean of Phi(k - z) - Phi(-k - z) (model error alone); "
        "measured = the study's.",
        "",
        "| true noise sd [N] | replicates | model error rms [N] | rms / bin sd (median) | "
        + " | ".join(f"{level:.0%} measured / predicted, {k}" for level in LEVELS for k in SBC_FREE)
        + " |",
        "|---|---|---|---|" + "---|" * (len(LEVELS) * len(SBC_FREE)),
    ]
    summary = {}
    for label, sel in [("all", np.ones(len(frame), bool))] + [
        (f"{frame.noise_sd_n[quartile == q].min():.3f}-{frame.noise_sd_n[quartile == q].max():.3f}", quartile == q)
        for q in range(4)
    ]:
        part = frame[sel]
        cells = []
        for level in LEVELS:
            for k in SBC_FREE:
                measured = part[f"covered_{level:g}_{k}"].mean()
                predicted = predicted_coverage(part[f"z_{k}"].to_numpy(), level).mean()
                cells.append(f"{measured:.2f} / {predicted:.2f}")
                summary.setdefault(label, {})[f"{level:g}_{k}"] = [round(measured, 3), round(float(predicted), 3)]
        lines.append(
            f"| {label} | {len(part)} | {part.error_rms_n.median():.4f} | {part.error_rms_over_bin_sd.median():.3f} | "
            + " | ".join(cells)
            + " |"
        )
    big = frame[[f"z_{k}" for k in SBC_FREE]].abs().max(axis=1) > 1.0
    miss = ~frame[[f"covered_0.9_{k}" for k in SBC_FREE]].all(axis=1)
    lines += [
        "",
        f"Replicates whose model error shifts some parameter by more than 1 posterior sd: {int(big.sum())}; "
        f"of these, {int((big & miss).sum())} have a truth outside a 90 % interval, against "
        f"{int((~big & miss).sum())} of the other {int((~big).sum())}.",
    ]
    write_text(args.study / "MODEL_ERROR.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    summary["shifted_gt_1sd"] = {"replicates": int(big.sum()), "missed_90": int((big & miss).sum())}
    summary["others"] = {"replicates": int((~big).sum()), "missed_90": int((~big & miss).sum())}
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
