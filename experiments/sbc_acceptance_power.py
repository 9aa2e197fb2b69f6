"""How often a perfectly calibrated sampler passes the SBC acceptance rule "every quantity's 90 % interval
covers 85-95 % of the truths", by the number of replicates and of ranked quantities.

A calibrated 90 % interval covers each replicate's truth with probability 0.9, so with ``n`` replicates a
quantity's coverage is Binomial(n, 0.9) / n. The rule fails a calibrated quantity whenever that falls outside
[0.85, 0.95] (both ends count as inside). Reported per ``n``:

- ``single``: the exact probability that one calibrated quantity passes;
- ``expected_false_misses_K``: K * (1 - single), the expected number of calibrated quantities the rule fails
  among K; a linear expectation, true whatever the dependence between quantities;
- ``independent_pass_K``: single ** K, the chance that all K pass if their coverages were independent.
  ``single`` bounds the joint chance from above whatever the dependence; for coverages that are jointly
  normal (nearly so for counts of 100 or more) with any correlations, single ** K bounds it from below, since the
  band is symmetric about 0.9 n (Sidak's inequality), so dependence can only raise it towards ``single``;
- ``detects_C``: the rule's power against one miscalibrated quantity, 1 - P(pass) for a 90 % interval that
  truly covers C (``--miscalibrated``, default 0.80 and 0.84);
- ``measured_dependence_pass``: the same chance by Monte Carlo for the quantities of an SBC study's folder, with
  their dependence taken from that study: the normal scores of its ranks give a correlation matrix, and each
  simulated study draws ``n`` replicates of a Gaussian with it (calibrated by construction: every margin is
  standard normal), a quantity covered where its score lies inside the central 90 %.

- ``pooled_rule_pass``: the same study's chance of passing the pooled rule of the SBC of what users run (90 %
  coverage pooled over every quantity within 87-93 %, and no rank histogram rejected at Holm-corrected 0.01).

The last line printed is one JSON object with every figure.

    python experiments/sbc_acceptance_power.py [--study experiments/sbc-hierarchical-2] [--seed 0] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import stats

from peano_bayes.atomic import write_text
from peano_bayes.validation.sbc import POOLED_BAND, RANK_ALPHA, RANK_DRAWS

HERE = Path(__file__).resolve().parent
BAND = (0.85, 0.95)
LEVEL = 0.9


def single_pass(n: int, coverage: float = LEVEL) -> float:
    """P(0.85 <= X / n <= 0.95) for X ~ Binomial(n, coverage): one quantity whose 90 % interval truly covers
    ``coverage`` passes the rule (default: a calibrated one)."""
    k = np.arange(n + 1)
    inside = (k >= BAND[0] * n - 1e-9) & (k <= BAND[1] * n + 1e-9)
    return float(stats.binom.pmf(k[inside], n, coverage).sum())


def rank_correlation(study: Path) -> tuple[list[str], np.ndarray]:
    """The quantities of an SBC folder's ``replicates.jsonl`` and the correlation of their ranks' normal scores."""
    rows = [json.loads(line) for line in (study / "replicates.jsonl").read_text().splitlines() if line.strip()]
    ranks = np.array([r["rank"] for r in rows], dtype=float)
    scores = stats.norm.ppf((ranks + 0.5) / (RANK_DRAWS + 1))  # ranks lie in 0..RANK_DRAWS
    return rows[0]["names"], np.corrcoef(scores, rowvar=False)


def dependent_pass(correlation: np.ndarray, n: int, studies: int, rng: np.random.Generator) -> float:
    """Monte Carlo chance that every quantity of a calibrated study with this dependence passes the rule."""
    half = stats.norm.ppf(0.5 + LEVEL / 2)
    chol = np.linalg.cholesky(correlation + 1e-12 * np.eye(len(correlation)))
    passed = 0
    for _ in range(studies):
        z = rng.standard_normal((n, len(correlation))) @ chol.T
        coverage = (np.abs(z) < half).mean(axis=0)
        passed += bool(np.all((coverage >= BAND[0] - 1e-12) & (coverage <= BAND[1] + 1e-12)))
    return passed / studies




def pooled_rule_pass(correlation: np.ndarray, n: int, studies: int, rng: np.random.Generator) -> float:
    """Monte Carlo chance that a calibrated study of ``n`` replicates with this dependence passes the pooled rule
    (:data:`POOLED_BAND`, :data:`RANK_ALPHA`): each replicate's quantities are a correlated standard normal
    vector; a quantity is covered where its score lies inside the central 90 %, and its rank is the score's
    normal probability in ten equal bins."""
    half = stats.norm.ppf(0.5 + LEVEL / 2)
    k = len(correlation)
    chol = np.linalg.cholesky(correlation + 1e-12 * np.eye(k))
    holm = RANK_ALPHA / (k - np.arange(k))  # the i-th smallest p-value's threshold
    passed = 0
    for _ in range(studies):
        z = rng.standard_normal((n, k)) @ chol.T
        pooled = (np.abs(z) < half).mean()
        bins = np.minimum((stats.norm.cdf(z) * 10).astype(int), 9)
        counts = np.stack([np.bincount(bins[:, j], minlength=10) for j in range(k)])
        p = np.sort(stats.chisquare(counts, axis=1).pvalue)
        rejected = np.any(np.cumprod(p <= holm))  # Holm: step down while the smallest are below their bounds
        passed += bool(POOLED_BAND[0] <= pooled <= POOLED_BAND[1] and not rejected)
    return passed / studies


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, default=HERE / "sbc-hierarchical-2")
    parser.add_argument("--replicates", type=int, nargs="+", default=[100, 200, 300, 400])
    parser.add_argument("--quantities", type=int, nargs="+", default=[11, 18, 30])
    parser.add_argument("--miscalibrated", type=float, nargs="+", default=[0.80, 0.84])
    parser.add_argument("--studies", type=int, default=20000, help="Monte Carlo studies per replicate count")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="also write the JSON object to this file (atomically)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    names, correlation = rank_correlation(args.study)
    off = correlation[~np.eye(len(names), dtype=bool)]
    out = {
        "band": list(BAND),
        "study": str(args.study.name),
        "study_quantities": len(names),
        "study_rank_correlation_abs_max": float(np.abs(off).max()),
        "rows": [],
    }
    for n in args.replicates:
        p = single_pass(n)
        row = {"replicates": n, "single": p}
        for k in args.quantities:
            row[f"expected_false_misses_{k}"] = k * (1 - p)
            row[f"independent_pass_{k}"] = p**k
        for c in args.miscalibrated:
            row[f"detects_{c:g}"] = 1 - single_pass(n, c)
        row["measured_dependence_pass"] = dependent_pass(correlation, n, args.studies, rng)
        row["pooled_rule_pass"] = pooled_rule_pass(correlation, n, args.studies, rng)
        out["rows"].append(row)
        per_k = "; ".join(
            f"K={k}: {k * (1 - p):.2f} false misses expected, all pass {p**k:.3f} if independent"
            for k in args.quantities
        )
        measured = row["measured_dependence_pass"]
        power = ", ".join(f"{c:g}: {row[f'detects_{c:g}']:.2f}" for c in args.miscalibrated)
        print(
            f"n={n}: one quantity passes {p:.3f}; {per_k}; "
            f"{args.study.name}'s {len(names)} with its dependence: {measured:.3f}, the pooled rule "
            f"{row['pooled_rule_pass']:.3f}; "
            f"detects one quantity whose 90 % interval covers {power}"
        )
    if args.out is not None:
        write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
