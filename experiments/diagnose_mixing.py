"""Why a run mixes slowly: read a saved sampler state (``<result>/sampler_state.npz``) and measure, without a
single new log-posterior evaluation,

1. **the frozen proposal against the posterior it should match.** The sampling phase's independence proposal
   is fitted to the last half of the warm-up (:func:`~peano_bayes.inference.sample.proposal_at`). Per ensemble:
   the generalized eigenvalues of the kept chain's covariance against the proposal's scale matrix (1 everywhere
   for a perfect fit; above 1 where the posterior is wider than the proposal, which an independence move then
   under-proposes), the offset of the chain's mean in proposal standard deviations, and the integrated
   autocorrelation time along the direction where the posterior is widest relative to the proposal, beside the
   largest time over the parameters;
2. **how far from elliptical the posterior is, in the sampler's coordinates and in a reparameterization.** A
   multivariate t (the proposal's family) is fitted to half of the kept draws; on the other half the spread of
   ``ln pi(x) - ln q(x)`` is reported (0 for a posterior the t fits exactly; for log-normal weights of sd ``s``
   an independence Metropolis-Hastings move accepts about ``2 Phi(-s / sqrt 2)``). The reparameterization
   replaces the series tensile element's ``(tensile_ka, tensile_kb)`` by the log stretch at two forces
   (``--forces``), the quantities the load cycles measure, with the change of variables' Jacobian.

The last line printed is one JSON object.

    python experiments/diagnose_mixing.py RESULT_DIR [--material PR] [--forces 1 20]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import emcee
import numpy as np
from scipy import special

from peano_bayes.inference.priors import prior_for
from peano_bayes.inference.sample import IndependenceProposal, load_state, proposal_at

KA, KB = "tensile_ka_n_per_m", "tensile_kb_n_per_m2"


def proposal_fit(chain: np.ndarray, n_walkers: int, warmup: int) -> list[dict]:
    """Per ensemble: the frozen proposal against the kept chain (see the module docstring, item 1)."""
    rows = []
    for e in range(chain.shape[1] // n_walkers):
        own = chain[:, e * n_walkers : (e + 1) * n_walkers]
        proposal = proposal_at(own, warmup, warmup)
        kept = own[warmup:].reshape(-1, own.shape[-1])
        whiten = np.linalg.inv(np.linalg.cholesky(proposal.covariance))
        ratios, vectors = np.linalg.eigh(whiten @ np.cov(kept.T) @ whiten.T)
        direction = whiten.T @ vectors[:, -1]
        along = (own[warmup:] - proposal.mean) @ direction
        rows.append(
            {
                "variance_ratio_min": float(ratios[0]),
                "variance_ratio_max": float(ratios[-1]),
                "mean_offset_sd": float(np.linalg.norm(whiten @ (kept.mean(axis=0) - proposal.mean))),
                "tau_max": float(emcee.autocorr.integrated_time(own[warmup:], quiet=True).max()),
                "tau_widest_direction": float(emcee.autocorr.integrated_time(along[..., None], quiet=True)[0]),
            }
        )
    return rows


def ellipticity(draws: np.ndarray, log_prob: np.ndarray, log_jacobian) -> float:
    """sd of ``ln pi - ln q`` on the second half of ``draws`` for a t fitted to the first half."""
    half = len(draws) // 2
    q = IndependenceProposal.fit(draws[:half])
    return float(np.std((log_prob + log_jacobian - q.log_density(draws))[half:]))


def tensile_stretch_coordinates(draws: np.ndarray, names: list[str], material: str, forces) -> tuple:
    """``draws`` with the (ka, kb) columns replaced by ``ln d(F1), ln d(F2)`` [ln m], and ``ln |du/dz|``."""
    prior = prior_for(material)
    i, j = names.index(KA), names.index(KB)
    ka_prior, kb_prior = prior.marginals[KA], prior.marginals[KB]

    def to_z(u_ka, u_kb):
        ka, kb = ka_prior.from_unconstrained(u_ka)[0], kb_prior.from_unconstrained(u_kb)[0]
        # the stretch of F = ka d + kb d^2 at force F, in the form that stays accurate as kb -> 0
        return [np.log(2.0 * f / (ka + np.sqrt(ka**2 + 4.0 * kb * f))) for f in forces]

    h = 1e-6
    z1, z2 = to_z(draws[:, i], draws[:, j])
    a1, a2 = to_z(draws[:, i] + h, draws[:, j])
    b1, b2 = to_z(draws[:, i], draws[:, j] + h)
    det = ((a1 - z1) * (b2 - z2) - (b1 - z1) * (a2 - z2)) / h**2
    z = draws.copy()
    z[:, i], z[:, j] = z1, z2
    return z, -np.log(np.abs(det))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("result", type=Path, help="a result folder holding sampler_state.npz")
    parser.add_argument("--material", help="its prior (default: the folder's name)")
    parser.add_argument("--forces", type=float, nargs=2, default=(1.0, 20.0), help="forces [N] of the stretches")
    parser.add_argument("--draws", type=int, default=40_000, help="kept draws used for the ellipticity")
    args = parser.parse_args()
    chain, log_prob, _, meta = load_state(args.result / "sampler_state.npz")
    kind = meta.get("coordinates", {"kind": "theta"})["kind"]
    if kind != "theta":  # the analysis reads the chain as theta (the parameters in their prior's coordinates)
        raise SystemExit(f"{args.result}: sampler state in {kind} coordinates; rerun with --coordinates theta")
    names, n_walkers, warmup = list(meta["names"]), int(meta["n_walkers"]), int(meta["warmup"])
    material = args.material or args.result.name
    ensembles = proposal_fit(chain, n_walkers, warmup)
    for e, row in enumerate(ensembles):
        print(
            f"ensemble {e}: posterior / proposal variance {row['variance_ratio_min']:.2f}-"
            f"{row['variance_ratio_max']:.2f}, mean offset {row['mean_offset_sd']:.2f} sd; tau_max "
            f"{row['tau_max']:.1f}, tau along the widest direction {row['tau_widest_direction']:.1f} steps"
        )
    kept = chain[warmup:].reshape(-1, chain.shape[-1])
    lp = log_prob[warmup:].reshape(-1)
    pick = np.random.default_rng(0).choice(len(kept), min(args.draws, len(kept)), replace=False)
    kept, lp = kept[pick], lp[pick]
    spreads = {"sampler coordinates": ellipticity(kept, lp, 0.0)}
    if KA in names and KB in names:
        z, log_jacobian = tensile_stretch_coordinates(kept, names, material, args.forces)
        spreads[f"tensile stretch at {args.forces[0]:g} and {args.forces[1]:g} N"] = ellipticity(z, lp, log_jacobian)
    for label, s in spreads.items():
        accept = 2.0 * special.ndtr(-s / math.sqrt(2.0))
        print(f"{label}: sd(ln pi - ln q) {s:.3f} (an independence move accepts about {accept:.2f})")
    print(
        json.dumps(
            {
                "result": str(args.result),
                "steps": int(chain.shape[0]),
                "warmup": warmup,
                "ensembles": ensembles,
                "log_weight_sd": spreads,
            }
        )
    )


if __name__ == "__main__":
    main()
