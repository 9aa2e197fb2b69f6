"""Simulation-based calibration, small: the study's machinery and a coarse check of the coverage.

The full study (100+ replicates, coverage table committed) is ``experiments/sbc.py``; here a handful of
replicates share one compiled posterior and must cover their truths about as often as a calibrated inference
would."""

import numpy as np
import pytest

from peano_bayes.validation.sbc import (
    RANK_DRAWS,
    base_posterior,
    coverage_table,
    run_replicate,
    wilson_interval,
)


def test_wilson_interval_brackets_the_proportion():
    low, high = wilson_interval(9, 10)
    assert 0.55 < low < 0.9 < high < 1.0
    assert wilson_interval(0, 10)[0] == 0.0


def test_coverage_table_counts_and_rank_test():
    reps = [{"rank": [i % (RANK_DRAWS + 1)], "covered": {"0.5": [i % 2 == 0], "0.9": [True], "0.94": [True]}}
            for i in range(200)]
    row = coverage_table(reps, ["x"])[0]
    assert row["coverage_0.5"] == 0.5 and row["coverage_0.9"] == 1.0 and row["replicates"] == 200
    assert row["rank_chi2_p"] > 0.5  # ranks spread evenly
    lumped = [{**r, "rank": [0]} for r in reps]
    assert coverage_table(lumped, ["x"])[0]["rank_chi2_p"] < 1e-6


@pytest.mark.slow
def test_small_sbc_covers_its_truths():
    base = base_posterior()
    reps = [run_replicate(base, i, seed=7, max_steps=3000).as_dict() for i in range(4)]
    rows = coverage_table(reps, base.names)
    # 4 replicates x 4 parameters = 16 truths against their 90 % intervals; a calibrated inference misses
    # Binomial(16, 0.1) of them: 7 or more misses has probability 5e-4.
    covered = sum(r["covered"]["0.9"][j] for r in reps for j in range(len(base.names)))
    assert covered >= 10, rows
    assert all(0 <= k <= RANK_DRAWS for r in reps for k in r["rank"])
    # Truths differ between replicates (drawn from the prior), and every replicate reports its sampler.
    truths = np.array([r["truth"] for r in reps])
    assert np.all(np.std(truths, axis=0) > 0)
    assert all(r["steps"] > 0 and np.isfinite(r["tau_max"]) for r in reps)
