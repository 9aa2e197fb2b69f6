"""Piecewise-linear denoising of the driving inputs: exact on clean signals, recovers noisy ramps, holds and
steps far below the noise, robust noise estimate, NaN handling."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from peano_bayes.inference.denoise import MIN_SEGMENT, noise_sd, piecewise_linear_fit


def signal(t, knots, values):
    return np.interp(t, knots, values)


def test_noise_sd_ignores_ramps_and_steps(rng):
    t = np.linspace(0.0, 40.0, 801)
    clean = signal(t, [0, 20, 40], [0, 3e4, 0]) + np.where(t > 10, 5e3, 0.0)
    estimate = noise_sd(clean + rng.normal(0.0, 500.0, t.size))
    # 799 second differences: the MAD estimate is within ~10 % of the truth (standard error ~4 %).
    assert estimate == pytest.approx(500.0, rel=0.12)
    assert noise_sd(clean) < 1e-9 * 3e4 + 1e-6


def test_clean_piecewise_linear_signal_is_reproduced_to_round_off():
    t = np.linspace(0.0, 40.0, 801)
    clean = signal(t, [0, 20, 40], [0.0, -0.015, 0.0])
    np.testing.assert_allclose(piecewise_linear_fit(t, clean), clean, rtol=0.0, atol=1e-15)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_pieces=st.integers(1, 4),
    jump=st.booleans(),
)
def test_recovers_ramps_holds_and_steps_well_below_the_noise(seed, n_pieces, jump):
    """Random piecewise-linear commands (pieces >= 60 samples, a step optional) with noise sd 1: the fit's
    RMS error is below 0.35 sd (a single line over 60 samples has ~0.18)."""
    rng = np.random.default_rng(seed)
    n = 600
    t = np.arange(n) * 0.05
    cuts = np.sort(rng.choice(np.arange(60, n - 60, 60), size=n_pieces - 1, replace=False)) if n_pieces > 1 else []
    knots = np.concatenate([[0], t[np.asarray(cuts, dtype=int)], [t[-1]]])
    clean = signal(t, knots, rng.uniform(-50.0, 50.0, knots.size))
    if jump:
        clean = clean + np.where(t >= t[n // 2 + 7], rng.choice([-1, 1]) * rng.uniform(20.0, 60.0), 0.0)
    fitted = piecewise_linear_fit(t, clean + rng.standard_normal(n))
    assert np.sqrt(np.mean((fitted - clean) ** 2)) < 0.35


def test_nan_samples_are_skipped_and_filled(rng):
    t = np.linspace(0.0, 10.0, 201)
    clean = signal(t, [0, 5, 10], [0.0, 10.0, 10.0])
    noisy = clean + rng.normal(0.0, 0.1, t.size)
    noisy[[3, 50, 120]] = np.nan
    fitted = piecewise_linear_fit(t, noisy)
    assert np.all(np.isfinite(fitted))
    # RMS, not max: a segment may be as short as MIN_SEGMENT samples, whose end points have sd ~0.6 sigma.
    assert np.sqrt(np.mean((fitted - clean) ** 2)) < 0.05


def test_short_signals_are_left_alone():
    t = np.arange(2 * MIN_SEGMENT - 1, dtype=float)
    x = np.sin(t)
    np.testing.assert_array_equal(piecewise_linear_fit(t, x), x)
