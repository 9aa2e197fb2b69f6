"""The inference benchmark's comparison of NUTS's draws with ours (``experiments/bench_inference.py``, by
``reference_run.agreement``'s rule and measure).

Independent draws, many of them, so that the quantiles' own noise (about 0.01 sd here) is far below every
tolerance; the third parameter has its own location and scale so that a missing division by ours' sd shows."""

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))
import bench_inference  # noqa: E402

POSTERIOR = SimpleNamespace(names=["a", "b", "c"])
LOC, SCALE = np.array([0.0, 0.0, 5.0]), np.array([1.0, 1.0, 3.0])
N_OURS, N_NUTS, ENSEMBLES = (8, 25_000), (2, 20_000), 4  # ours: (walkers, draws); NUTS: (chains, draws)
Z97 = stats.norm.ppf(0.97)


def _ours(rng):
    return LOC + SCALE * rng.normal(size=(*N_OURS, 3))


def _iid_quantile_se_sd(prob, n, stretch=1.0):
    """The standard error of an independent sample's ``prob`` quantile, in units of the unstretched sd: a normal
    whose half beyond the median is stretched by ``stretch`` has density phi(z) / stretch at its quantile there."""
    return np.sqrt(prob * (1 - prob) / n) / (stats.norm.pdf(stats.norm.ppf(prob)) / stretch)


def test_draws_of_one_distribution_are_the_same_posterior():
    rng = np.random.default_rng(0)
    nuts = LOC + SCALE * rng.normal(size=(*N_NUTS, 3))
    same = bench_inference.posterior_agreement(POSTERIOR, _ours(rng), nuts, ENSEMBLES)
    assert same["same_posterior"] and same["quantities"] == 3
    assert same["max_mean_difference_sd"] < 0.03 and same["max_interval_end_difference_sd"] < 0.06


def test_a_shifted_mean_and_a_stretched_upper_tail_are_found_on_their_own_parameters_with_their_errors():
    rng = np.random.default_rng(1)
    z = rng.normal(size=(*N_NUTS, 3))
    stretch = 2.5  # c's half above its median 2.5x wider, moved down to keep c's mean
    z[..., 2] = np.where(z[..., 2] > 0, stretch * z[..., 2], z[..., 2]) - (stretch - 1) * stats.norm.pdf(0)
    nuts = LOC + SCALE * z + np.array([0.0, 0.15, 0.0])  # b's mean 0.15 sd up
    same = bench_inference.posterior_agreement(POSTERIOR, _ours(rng), nuts, ENSEMBLES)
    assert not same["same_posterior"]
    assert same["worst_mean"] == "b" and abs(same["max_mean_difference_sd"] - 0.15) < 0.03
    # c's 97 % quantile moves by (stretch - 1) z97 less the shift, 2.2 sd; b's ends by 0.15 sd only
    assert same["worst_interval_end"] == "c" and same["rows"]["b"]["interval_end_sd"] < 0.2
    c = same["rows"]["c"]
    assert abs(c["interval_end_sd"] - (stretch - 1) * (Z97 - stats.norm.pdf(0))) < 0.1
    # in combined standard errors: that difference over both samplers' errors of the 97 % quantile, each near an
    # independent sample's (the 3 % end's error would give 2.3 times the figure; arviz's estimate of an error
    # scatters by about +-20 % at these sizes)
    combined = np.hypot(_iid_quantile_se_sd(0.97, np.prod(N_NUTS), stretch), _iid_quantile_se_sd(0.97, np.prod(N_OURS)))
    assert 0.67 < c["interval_end_mcse"] / (c["interval_end_sd"] / combined) < 1.5
