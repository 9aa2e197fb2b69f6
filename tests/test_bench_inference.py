"""The inference benchmark's comparison of NUTS's draws with ours (``experiments/bench_inference.py``)."""

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))
import bench_inference  # noqa: E402

POSTERIOR = SimpleNamespace(names=["a", "b", "c"])


def test_draws_of_one_normal_are_the_same_posterior_and_the_quantile_error_is_the_iid_one():
    rng = np.random.default_rng(0)
    ours, nuts = rng.normal(size=(20000, 3)), rng.normal(size=(4000, 3))
    same = bench_inference.posterior_agreement(POSTERIOR, ours, nuts)
    assert same["same_posterior"] and same["interval_ends_over_0_2_sd"] == []
    # an independent draw's 3 % (or 97 %) quantile has sd sqrt(p (1 - p) / n) / density at the quantile
    iid = np.sqrt(0.03 * 0.97 / 4000) / stats.norm.pdf(stats.norm.ppf(0.03))
    assert 0.7 * iid < same["worst_interval_end_nuts_mcse_sd"] < 1.4 * iid


def test_a_shifted_mean_and_a_wider_spread_are_found_on_their_own_parameters():
    rng = np.random.default_rng(1)
    ours = rng.normal(size=(20000, 3))
    nuts = rng.normal(size=(4000, 3)) * np.array([1.0, 1.0, 1.2]) + np.array([0.0, 0.15, 0.0])
    same = bench_inference.posterior_agreement(POSTERIOR, ours, nuts)
    assert not same["same_posterior"]
    assert same["worst_mean"] == "b" and 0.12 < same["max_mean_difference_sd"] < 0.18
    # a 1.2x wider posterior moves each 94 % end by 0.2 x 1.88 = 0.38 sd; the shift by 0.15 sd only
    assert same["interval_ends_over_0_2_sd"] == ["c"] and same["worst_interval_end"] == "c"
    assert 0.3 < same["max_interval_end_difference_sd"] < 0.46
