"""Simulation-based calibration, small: the study's machinery.

The study itself (100+ replicates run to the convergence gates, coverage table committed) is
``experiments/sbc.py``; here two short replicates share one compiled posterior and report ranks and coverage."""

import json

import numpy as np
import pytest

from peano_bayes.validation.sbc import (
    LEVELS,
    RANK_DRAWS,
    base_posterior,
    coverage_table,
    derived_levels,
    draw_truth,
    rank_and_coverage,
    rank_names,
    replicate_data,
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


@pytest.mark.xdist_group("short_tp_fits")  # its SBC posterior is the fan-out test's unit (tests/test_fanout.py)
def test_sbc_replicates_share_one_compiled_posterior_and_report_ranks_and_coverage():
    """The study's machinery on two short replicates: each draws its own truth from the prior, swaps its data into
    the base posterior's compiled functions (``with_observations``: the base, never sampled itself, ends up holding
    the compiled log posterior), and reports a rank among RANK_DRAWS draws and a coverage flag for every level and
    parameter, with nested central intervals (a truth inside the 50 % interval is inside the 90 % one, and so on).

    The coverage *study* (100 replicates to the convergence gates or an 8000-step limit, 90 % coverage against
    its 85-95 % target) is ``experiments/sbc.py``, committed in ``experiments/sbc-hierarchical-2/SBC.md``: a
    replicate costs about 2 minutes (median; up to two hours at the step limit), so four of them (the former
    ``test_small_sbc_covers_its_truths``, 445 s of the suite) coarsely repeated a check that the study makes
    with 25 times the replicates."""
    base = base_posterior()
    assert not base._compiled
    reps = [run_replicate(base, i, seed=7, warmup=40, chunk=40, max_steps=80).as_dict() for i in range(2)]
    assert {"batched", "value_and_grad"} <= set(base._compiled)  # compiled once, through the replicates
    d = len(base.names)
    truths = np.array([r["truth"] for r in reps])
    assert truths.shape == (2, d) and np.all(truths[0] != truths[1])  # own truth per replicate
    for r in reps:
        assert len(r["rank"]) == d and all(0 <= k <= RANK_DRAWS for k in r["rank"])
        assert set(r["covered"]) == {str(level) for level in LEVELS}
        nested = np.array([r["covered"][str(level)] for level in sorted(LEVELS)])
        assert nested.shape == (len(LEVELS), d) and np.all(nested[:-1] <= nested[1:]), r["covered"]
        assert 0 < r["steps"] <= 80 and np.isfinite(r["tau_max"]) and r["redraws"] >= 0
        assert r["ar1"] == {}  # the model that made the data leaves residuals without structure
    rows = coverage_table(reps, base.names)
    assert [row["parameter"] for row in rows] == list(base.names)
    for j, row in enumerate(rows):
        assert row["replicates"] == 2
        for level in LEVELS:
            assert row[f"coverage_{level:g}"] == sum(r["covered"][str(level)][j] for r in reps) / 2


def test_ranks_and_coverage_of_a_known_posterior_are_uniform_and_nominal():
    """The statistics on a posterior known exactly: truth and 4000 draws from the same normal, 400 replicates.
    Hand-checked first: a truth above every draw ranks RANK_DRAWS and lies outside every interval; one at the
    middle ranks 49 of 99 and lies inside all. Then calibration: the rank histogram is uniform (chi-square
    p > 0.001 on 10 bins) and each interval's coverage is within 3.5 binomial sd of its level; a posterior twice
    too narrow fails both."""
    draws = np.arange(1000.0)[:, None]
    rank, covered = rank_and_coverage(draws, np.array([5000.0]))
    assert rank.tolist() == [RANK_DRAWS] and all(covered[str(level)] == [False] for level in LEVELS)
    rank, covered = rank_and_coverage(draws, np.array([495.0]))  # the 99 draws kept are 0, 10, 20, 31, ..., 999:
    assert rank.tolist() == [49] and all(covered[str(level)] == [True] for level in LEVELS)  # 49 up to 489
    rng = np.random.default_rng(20261206)
    n = 400

    def study(scale):
        reps = []
        for _ in range(n):
            truth = rng.normal(size=2)
            draws = truth + rng.normal(size=2) + scale * rng.normal(size=(4000, 2))  # posterior N(mean, 1)
            rank, covered = rank_and_coverage(draws, truth)
            reps.append({"rank": rank.tolist(), "covered": covered})
        return coverage_table(reps, ["a", "b"])

    for row in study(1.0):
        assert row["rank_chi2_p"] > 1e-3, row
        for level in LEVELS:
            assert abs(row[f"coverage_{level:g}"] - level) < 3.5 * np.sqrt(level * (1 - level) / n), (row, level)
    for row in study(0.5):  # overconfident
        assert row["rank_chi2_p"] < 1e-3 and row["coverage_0.9"] < 0.9 - 3.5 * np.sqrt(0.09 / n), row


def test_hierarchical_sbc_draws_its_truths_by_the_generative_hierarchy():
    """The hierarchical study (``--specimens 2``) draws a population value ``mu`` from the prior, specimens
    ``mu exp(tau z)`` and a new specimen ``mu exp(tau z_new)``; theta holds the specimens' geometric mean ``m``
    (the posterior's coordinate) and their Helmert contrasts, which are then ``tau N(0, 1)``, and ``m`` lies
    ``tau z_bar`` (sd ``tau / sqrt(2)``) from ``mu``."""
    base = base_posterior(2)
    assert set(base.varying) == {"tensile_ka_n_per_m", "bending_k1_n"}  # the free parameters that differ
    names = rank_names(base)
    d = base.ndim
    assert names[:d] == base.names and base.n_contrasts == 2
    assert names[d:] == tuple(f"{level}__{p}" for p in base.varying for level in ("population", "new_specimen"))
    rng = np.random.default_rng(3)
    contrast_z, mean_z, new_z, outside = [], [], [], 0
    for i in range(1500):
        truth = draw_truth(base, rng)
        if truth is None:  # the specimens' mean left the prior's support: a population value near its bound
            outside += 1
            continue
        theta = truth.theta
        np.testing.assert_array_equal(truth.ranked[:d], theta)
        spread = float(base.prior.from_unconstrained(theta[: base.prior.ndim])["specimen_log_sd"])
        contrasts = theta[base.prior.ndim :]
        contrast_z.append(contrasts / spread)
        params = base.params(theta) if i < 50 else None
        for j, p in enumerate(base.varying):
            population, new = truth.ranked[d + 2 * j], truth.ranked[d + 2 * j + 1]
            a, b = truth.specimen_values[0][p], truth.specimen_values[1][p]
            log_m = 0.5 * np.log(a * b)
            mean_z.append((log_m - population) / spread)
            new_z.append((new - population) / spread)
            if params is not None:
                np.testing.assert_allclose(log_m, np.log(float(params[p])), rtol=1e-12)  # theta holds m
                np.testing.assert_allclose(np.log(b / a), np.sqrt(2.0) * contrasts[j], rtol=1e-9)
    assert outside < 75  # 2.2 % of 3000 draws: tensile_ka's loguniform prior has bounds at 300 and 5e4 N/m
    contrast_z = np.array(contrast_z)
    # about 1500 draws: se of a mean 0.026, of an sd about 0.018 (relative); tolerances near 3.5 se
    np.testing.assert_allclose(contrast_z.mean(axis=0), 0.0, atol=0.09)
    np.testing.assert_allclose(contrast_z.std(axis=0), 1.0, rtol=0.065)
    np.testing.assert_allclose([np.mean(mean_z), np.mean(new_z)], 0.0, atol=0.07)  # 3000 values each
    np.testing.assert_allclose(np.std(mean_z), 1.0 / np.sqrt(2.0), rtol=0.05)
    np.testing.assert_allclose(np.std(new_z), 1.0, rtol=0.05)


def test_hierarchical_sbc_ranks_the_posteriors_levels_and_simulates_each_specimen_with_its_own_values():
    """The posterior side: :func:`derived_levels` passes theta through and adds ``Posterior.levels``'
    population (sd ``tau / sqrt(2)`` around ``m``) and new specimen (sd ``tau`` around the population), as
    ln SI; and a replicate's data are simulated with the truth's own specimen values."""
    base = base_posterior(2)
    truth, data, redraws, _ = replicate_data(base, 0, seed=5)
    theta, d = truth.theta, base.ndim
    recorded = json.loads(data.provenance["specimen_parameters"])
    for s, label in enumerate(("A", "B")):
        for p, value in truth.specimen_values[s].items():
            assert recorded[label][p] == value
    assert recorded["A"]["tensile_ka_n_per_m"] != recorded["B"]["tensile_ka_n_per_m"] and redraws >= 0
    spread = float(base.prior.from_unconstrained(theta[: base.prior.ndim])["specimen_log_sd"])
    thetas = np.repeat(theta[None], 4000, axis=0)
    levels = derived_levels(base, thetas, np.random.default_rng(4))
    assert levels.shape == (4000, len(rank_names(base)))
    np.testing.assert_array_equal(levels[:, :d], thetas)
    for j, p in enumerate(base.varying):
        log_m = np.log(float(base.params(theta)[p]))
        population, new = levels[:, d + 2 * j], levels[:, d + 2 * j + 1]
        np.testing.assert_allclose(np.mean(population - log_m), 0.0, atol=0.06 * spread)  # se 0.011 tau
        np.testing.assert_allclose(np.std(population - log_m), spread / np.sqrt(2.0), rtol=0.05)
        np.testing.assert_allclose(np.std(new - population), spread, rtol=0.05)


def test_the_acceptance_rules_chance_for_a_calibrated_sampler():
    """experiments/sbc_acceptance_power.py: one calibrated quantity passes 85-95 % at 100 replicates with the
    binomial probability, and its Monte Carlo gives single ** K for independent quantities and single for
    quantities that move as one."""
    import sys
    from pathlib import Path

    from scipy import stats

    sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))
    import sbc_acceptance_power as power

    exact = stats.binom.cdf(95, 100, 0.9) - stats.binom.cdf(84, 100, 0.9)
    assert abs(power.single_pass(100) - exact) < 1e-12
    rng = np.random.default_rng(7)
    studies = 4000
    independent = power.dependent_pass(np.eye(3), 100, studies, rng)
    se = np.sqrt(exact**3 * (1 - exact**3) / studies)
    assert abs(independent - exact**3) < 4 * se
    as_one = power.dependent_pass(np.full((3, 3), 0.999999) + 1e-6 * np.eye(3), 100, studies, rng)
    assert abs(as_one - exact) < 4 * np.sqrt(exact * (1 - exact) / studies)


def test_the_pooled_rule_on_known_studies():
    from peano_bayes.validation.sbc import pooled_rule

    rng = np.random.default_rng(3)
    n = 100

    def study(covered_share, ranks_of):
        reps = []
        for i in range(n):
            covered = [bool(i < covered_share[j] * n) for j in range(2)]
            reps.append(
                {
                    "covered": {str(level): covered for level in (0.5, 0.9, 0.94)},
                    "rank": [ranks_of[j](i) for j in range(2)],
                    "converged": i % 10 != 0,
                }
            )
        return reps

    uniform = lambda i: int(rng.integers(0, RANK_DRAWS + 1))  # noqa: E731
    piled = lambda i: 0  # noqa: E731  every truth below every draw: the histogram's first bin holds all
    calibrated = study([0.90, 0.90], [uniform, uniform])
    rule = pooled_rule(coverage_table(calibrated, ["a", "b"]), calibrated)
    assert rule["pooled_coverage"] == 0.90 and rule["unconverged"] == 10  # counted, not dropped
    assert rule["passed"] and rule["rank_rejected"] == []
    # pooled 0.86 (0.92 and 0.80): outside 87-93 % although one quantity alone is inside
    low = study([0.92, 0.80], [uniform, uniform])
    assert pooled_rule(coverage_table(low, ["a", "b"]), low)["pooled_coverage"] == 0.86
    assert not pooled_rule(coverage_table(low, ["a", "b"]), low)["passed"]
    # one quantity's ranks all in one bin: chi-square p ~ 0, Holm p = 2 p, rejected whatever the coverage
    skewed = study([0.90, 0.90], [uniform, piled])
    rule = pooled_rule(coverage_table(skewed, ["a", "b"]), skewed)
    assert rule["rank_rejected"] == ["b"] and not rule["passed"]
    raw = coverage_table(skewed, ["a", "b"])
    assert rule["rank_p_holm"]["b"] == pytest.approx(min(1.0, 2 * raw[1]["rank_chi2_p"]), rel=1e-12)
