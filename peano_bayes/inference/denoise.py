"""Denoising of the rig's driving signals by a piecewise-linear least-squares fit.

The likelihood simulates each run from its *measured* inputs (imposed strain, pressure, supply pressure). Fed
raw, their sensor noise drives the model and comes out amplified by its sensitivity: on the bundled datasets the
stroke and step residuals are 14 and 21 times the strain noise at the true parameters (errors in variables).
Rig inputs are commanded signals, ramps, holds and steps, so each run's input is replaced by its best
piecewise-linear fit: segments chosen by optimal partitioning (Jackson et al. 2005, Signal Processing Letters
12(2)) with a BIC penalty per segment of ``3 ln n`` for a line (slope, intercept, breakpoint) or ``2 ln n`` for
a hold (constant) against ``RSS / sigma^2``,
where ``sigma`` is estimated from the median absolute second difference (unaffected by ramps and steps).
Segments are fitted independently, so a step is two segments and a kink costs at most a small offset.
"""

from __future__ import annotations

import numpy as np

#: Consistency factor of the median absolute deviation for a normal distribution.
_MAD_TO_SD = 1.482602218505602
#: Shortest segment [samples]: shorter ones mostly fit noise (a commanded hold or ramp lasts longer).
MIN_SEGMENT = 10


def noise_sd(x: np.ndarray) -> float:
    """Robust estimate of white-noise sd in ``x`` (n,) from its second differences (sd sqrt(6) sigma)."""
    d2 = np.diff(np.asarray(x, dtype=float), 2)
    d2 = d2[np.isfinite(d2)]
    if d2.size == 0:
        return 0.0
    return float(_MAD_TO_SD * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


class _SegmentCost:
    """Residual sum of squares of the line fitted to samples ``i..j-1``, from prefix sums (O(n) memory)."""

    def __init__(self, t: np.ndarray, x: np.ndarray):
        # Centred and scaled for numerical stability of the prefix-sum formulae.
        t = (t - t.mean()) / max(np.ptp(t), 1e-300)
        self.x_scale = max(float(np.std(x)), 1e-300)
        x = (x - x.mean()) / self.x_scale
        prefix = lambda a: np.concatenate([[0.0], np.cumsum(a)])  # noqa: E731
        self.sums = [prefix(a) for a in (np.ones_like(t), t, x, t * t, t * x, x * x)]

    def ending_at(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(j,) RSS of the line and of the constant fitted to ``i..j-1``, for every start i < j (inf where
        shorter than :data:`MIN_SEGMENT`)."""
        m, mt, mx, mtt, mtx, mxx = (s[j] - s[:j] for s in self.sums)
        with np.errstate(invalid="ignore", divide="ignore"):
            ctt = mtt - mt * mt / m
            ctx = mtx - mt * mx / m
            cxx = mxx - mx * mx / m
            rss = np.where(ctt > 1e-300, cxx - ctx * ctx / ctt, cxx)
        short = m < MIN_SEGMENT
        line, constant = (np.where(short, np.inf, np.maximum(r, 0.0) * self.x_scale**2) for r in (rss, cxx))
        return line, constant


def piecewise_linear_segments(time_s: np.ndarray, values: np.ndarray, sd: float | None = None):
    """The best piecewise-linear least-squares fit of ``values`` (n,) over ``time_s`` (n,) and its segments.

    Returns ``(fitted (n,), segments)``: ``segments`` is a list of ``(start, stop, sloped)`` over the finite
    samples (indices into ``time_s[isfinite(values)]``), in order; ``sloped`` False for a hold (a constant).
    ``sd``: the noise sd (default: :func:`noise_sd`). NaN samples are left out of the fit and filled by linear
    interpolation of the fit. Signals without noise (sd 0) or too short are returned unchanged, with no
    segments.
    """
    time_s, values = np.asarray(time_s, dtype=float), np.asarray(values, dtype=float)
    ok = np.isfinite(values)
    t, x = time_s[ok], values[ok]
    n = t.size
    sd = noise_sd(x) if sd is None else float(sd)
    if n < 2 * MIN_SEGMENT or not sd > 0.0:
        return values.copy(), []
    cost = _SegmentCost(t, x)
    log_n = np.log(n)
    best = np.full(n + 1, np.inf)
    best[0] = 0.0
    start = np.zeros(n + 1, dtype=int)
    sloped = np.zeros(n + 1, dtype=bool)
    for j in range(MIN_SEGMENT, n + 1):
        line, constant = cost.ending_at(j)
        line = line / sd**2 + 3.0 * log_n
        constant = constant / sd**2 + 2.0 * log_n
        total = best[:j] + np.minimum(line, constant)
        i = int(np.argmin(total))
        best[j], start[j], sloped[j] = total[i], i, line[i] < constant[i]
    fitted = np.empty(n)
    segments = []
    j = n
    while j > 0:
        i = start[j]
        tt, xx = t[i:j], x[i:j]
        slope_fitted = bool(sloped[j] and np.ptp(tt) > 0)
        if slope_fitted:
            slope, intercept = np.polyfit(tt - tt.mean(), xx, 1)
            fitted[i:j] = intercept + slope * (tt - tt.mean())
        else:
            fitted[i:j] = xx.mean()
        segments.append((int(i), int(j), slope_fitted))
        j = i
    return np.interp(time_s, t, fitted), segments[::-1]


def piecewise_linear_fit(time_s: np.ndarray, values: np.ndarray, sd: float | None = None) -> np.ndarray:
    """Best piecewise-linear least-squares fit of ``values`` (n,) over ``time_s`` (n,), same shape (see
    :func:`piecewise_linear_segments`)."""
    return piecewise_linear_segments(time_s, values, sd)[0]


def fit_error_basis(time_s: np.ndarray, values: np.ndarray, segments, sd: float) -> np.ndarray:
    """(n, q) matrix ``B`` whose columns span the error of the piecewise-linear fit: with white noise of sd
    ``sd`` in ``values``, the fitted signal minus the noise-free one (given the segmentation) is ``B a``,
    ``a ~ N(0, I_q)``. Per segment, ``sd`` times an orthonormal basis of what the segment's fit can do over its
    samples (the constant, and the centred time of a sloped segment), so ``q`` = 2 per ramp + 1 per hold. Rows
    of NaN samples are interpolated, like the fit."""
    time_s, values = np.asarray(time_s, dtype=float), np.asarray(values, dtype=float)
    ok = np.isfinite(values)
    t = time_s[ok]
    columns = []
    for i, j, sloped in segments:
        column = np.zeros(t.size)
        column[i:j] = 1.0 / np.sqrt(j - i)
        columns.append(column)
        if sloped:
            centred = t[i:j] - t[i:j].mean()
            column = np.zeros(t.size)
            column[i:j] = centred / np.sqrt(np.sum(centred**2))
            columns.append(column)
    if not columns:
        return np.zeros((time_s.size, 0))
    basis = sd * np.stack(columns, axis=1)
    return np.stack([np.interp(time_s, t, c) for c in basis.T], axis=1)


__all__ = ["MIN_SEGMENT", "fit_error_basis", "noise_sd", "piecewise_linear_fit", "piecewise_linear_segments"]
