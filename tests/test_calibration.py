"""Simulation-based calibration, small: the study's machinery.

The study itself (100+ replicates run to the convergence gates, coverage table committed) is
``experiments/sbc.py``; here two short replicates share one compiled posterior and report ranks and coverage."""

import numpy as np

from peano_bayes.validation.sbc import (
    LEVELS,
    RANK_DRAWS,
    base_posterior,
    coverage_table,
    derived_levels,
    draw_truth,
    rank_names,
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


def test_sbc_replicates_share_one_compiled_posterior_and_report_ranks_and_coverage():
    """The study's machinery on two short replicates: each draws its own truth from the prior, swaps its data into
    the base posterior's compiled functions (``with_observations``: the base, never sampled itself, ends up holding
    the compiled log posterior), and reports a rank among RANK_DRAWS draws and a coverage flag for every level and
    parameter, with nested central intervals (a truth inside the 50 % interval is inside the 90 % one, and so on).

    The coverage *study* (100 replicates to the convergence gates, 90 % coverage against its 85-95 % target) is
    ``experiments/sbc.py``, committed in ``experiments/sbc/SBC.md``: chains run to convergence cost about a minute
    per replicate, so four of them (the former ``test_small_sbc_covers_its_truths``, 445 s of the suite) coarsely
    repeated a check that the study makes with 25 times the replicates."""
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
    rows = coverage_table(reps, base.names)
    assert [row["parameter"] for row in rows] == list(base.names)
    for j, row in enumerate(rows):
        assert row["replicates"] == 2
        for level in LEVELS:
            assert row[f"coverage_{level:g}"] == sum(r["covered"][str(level)][j] for r in reps) / 2


def test_hierarchical_sbc_draws_its_truths_by_the_posteriors_own_prior_and_ranks_the_derived_levels():
    """The hierarchical study (``--specimens 2``): a truth's contrasts are N(0, spread^2), each specimen's
    values are the sampled value (their geometric mean) moved by its Helmert offset, and the population and
    new-specimen levels it ranks follow :meth:`Posterior.levels` (population = m exp(-spread z_bar), z_bar ~
    N(0, 1/2); new specimen = population exp(spread z))."""
    base = base_posterior(2)
    assert set(base.varying) == {"tensile_ka_n_per_m", "bending_k1_n"}  # the free parameters that differ
    names = rank_names(base)
    assert names[: base.ndim] == base.names and base.n_contrasts == 2
    assert names[base.ndim :] == tuple(
        f"{level}__{p}" for p in base.varying for level in ("population", "new_specimen")
    )
    rng = np.random.default_rng(3)
    z = []
    for i in range(1500):
        theta, values = draw_truth(base, rng)
        spread = float(base.prior.from_unconstrained(theta[: base.prior.ndim])["specimen_log_sd"])
        contrasts = theta[base.prior.ndim :]
        z.append(contrasts / spread)
        if i >= 50:
            continue
        params = base.params(theta)
        for j, p in enumerate(base.varying):
            a, b = values[0][p], values[1][p]
            np.testing.assert_allclose(np.sqrt(a * b), float(params[p]), rtol=1e-12)  # geometric mean
            np.testing.assert_allclose(np.log(b / a), np.sqrt(2.0) * contrasts[j], rtol=1e-10)
    z = np.array(z)
    np.testing.assert_allclose(z.mean(axis=0), 0.0, atol=0.08)  # 3.5 standard errors of 1500 normals
    np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.06)
    thetas = np.repeat(theta[None], 4000, axis=0)
    levels = derived_levels(base, thetas, np.random.default_rng(4))
    assert levels.shape == (4000, len(names))
    np.testing.assert_array_equal(levels[:, : base.ndim], thetas)
    for j, p in enumerate(base.varying):
        log_m = np.log(float(base.params(theta)[p]))
        population, new = levels[:, base.ndim + 2 * j], levels[:, base.ndim + 2 * j + 1]
        np.testing.assert_allclose(np.std(population - log_m), spread / np.sqrt(2.0), rtol=0.05)
        np.testing.assert_allclose(np.std(new - population), spread, rtol=0.05)
