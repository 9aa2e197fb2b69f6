"""Plain-NumPy load-cycle simulation of the default muscle, the reference for ``bench_forward.py``.

The same physics as ``peano_bayes.physics`` with ``DEFAULT_CONFIG`` (ideal tubes, bending, series tensile
spring, passive extension, Dahl friction across the contractile unit) and the same algorithm per sample
(bisection to 1e-3 in log(theta) over a bracket of +-0.01 around the previous sample's root where it holds the
root, the whole range otherwise; then Newton), written the way a careful NumPy user would: every
operation is vectorized over a batch of parameter sets, and the time loop (which carries friction history and
cannot be vectorized) is a Python loop. Newton slopes come from central differences, as NumPy has no autodiff.
"""

from __future__ import annotations

import numpy as np

THETA_MIN, THETA_MAX = 1e-7, 0.5 * np.pi - 1e-6
LOG_LO, LOG_HI = np.log(THETA_MIN), np.log(THETA_MAX)
PRESSURE_FLOOR_PA = 100.0
SMALL = 1e-2
DAHL_SMOOTHING_M = 1e-7


def _sin_minus_tcos_over_t3(t):
    safe = np.where(t < SMALL, SMALL, t)
    series = 1.0 / 3.0 - t**2 / 30.0 + t**4 / 840.0 - t**6 / 45360.0
    return np.where(t < SMALL, series, (np.sin(safe) - safe * np.cos(safe)) / safe**3)


def _tube_strain(t):
    safe = np.where(t < SMALL, SMALL, t)
    series = t**2 / 6.0 - t**4 / 120.0 + t**6 / 5040.0 - t**8 / 362880.0
    return np.where(t < SMALL, series, 1.0 - np.sin(safe) / safe)


def _smooth_positive(x, width):
    return width * np.logaddexp(x / width, 0.0)


def _extension_force(strain, k, rate, l0, width=1e-4):
    e = _smooth_positive(-strain, width)
    x = rate * e
    small = np.abs(x) < 1e-8
    safe_rate = np.where(small, 1.0, rate)
    capped = np.minimum(safe_rate * e, 30.0)
    exponential = (np.expm1(capped) + np.exp(capped) * (safe_rate * e - capped)) / safe_rate
    return k * l0 * np.where(small, e * (1.0 + 0.5 * x), exponential)


def _chain(theta, pressure_pa, x_prev, friction_prev, limit_prev, p, geometry, relaxed):
    """Chain force [N], shortening [m], friction [N] and friction limit [N] at half-angle theta (arrays over the
    batch). The Dahl step uses the mean of the previous sample's limit and this one's (the limit grows with the
    pressure load along the step)."""
    n, w, length = geometry
    p_eff = PRESSURE_FLOOR_PA + _smooth_positive(pressure_pa - PRESSURE_FLOOR_PA, 50.0)
    x = n * w * _tube_strain(theta)
    l_e = p["length_fraction"] * length
    active = p_eff * w * l_e * np.cos(theta) / theta
    stiffness = p["bending_k1_n"] + p["bending_k2_n"] * np.exp(p["bending_exponent"] * np.log(theta))
    force = active - (length / w) * stiffness / _sin_minus_tcos_over_t3(theta)
    limit_end = p["friction_force_n"] + p["friction_pressure_fraction"] * active
    if relaxed:
        friction = np.zeros_like(force)
    else:
        dx = x - x_prev
        limit = np.maximum(0.5 * (limit_prev + limit_end), 1e-12)
        s = np.tanh(dx / DAHL_SMOOTHING_M)
        target = s * limit
        friction = target - (target - friction_prev) * np.exp(-p["friction_stiffness_n_per_m"] * dx * s / limit)
    force = force - friction
    ka, kb = p["tensile_ka_n_per_m"], p["tensile_kb_n_per_m2"]
    stretch = 2.0 * force / (ka + np.sqrt(ka**2 + 4.0 * kb * np.abs(force)))
    return force, x - stretch, friction, limit_end


def _solve(residual, shape, newton_steps, z_prev=None):
    """Vectorized bisection on log(theta) to 1e-3 (residual rising with theta), then Newton steps.

    With ``z_prev``, the bracket is ``z_prev +- 0.01`` wherever it holds the root (as in peano_bayes).
    """
    lo = np.full(shape, LOG_LO)
    hi = np.full(shape, LOG_HI)
    if z_prev is not None:
        near_lo, near_hi = np.clip(z_prev - 0.01, LOG_LO, LOG_HI), np.clip(z_prev + 0.01, LOG_LO, LOG_HI)
        holds = (residual(near_lo) <= 0.0) & (residual(near_hi) >= 0.0)
        lo, hi = np.where(holds, near_lo, lo), np.where(holds, near_hi, hi)
    while np.max(hi - lo) > 1e-3:
        mid = 0.5 * (lo + hi)
        above = residual(mid) > 0.0
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    z = 0.5 * (lo + hi)
    for _ in range(newton_steps):
        h = 1e-7
        slope = (residual(z + h) - residual(z - h)) / (2.0 * h)
        z = np.clip(z - residual(z) / slope, LOG_LO, LOG_HI)
    return z


def simulate_load_cycle(params, strain, pressure_pa, geometry=(4, 0.015, 0.0495)):
    """Force [N], shape (batch, n), along an imposed ``strain`` (n,) at ``pressure_pa`` (n,).

    ``params``: dict of arrays of shape (batch,) with the default model's parameter names.
    """
    params = {k: np.asarray(v, dtype=float) for k, v in params.items()}
    batch = next(iter(params.values())).shape
    n_tubes, w, length = geometry
    l0 = n_tubes * w
    out = np.empty(batch + (len(strain),))
    x_prev = np.zeros(batch)
    friction = np.zeros(batch)
    limit = np.zeros(batch)
    z = None
    for i, (eps, pr) in enumerate(zip(strain, pressure_pa, strict=True)):
        relaxed = i == 0

        def fn(z, eps=eps, pr=pr, relaxed=relaxed, x_prev=x_prev, friction=friction, limit=limit):
            return _chain(np.exp(z), pr, x_prev, friction, limit, params, geometry, relaxed)[1] - eps * l0

        z = _solve(fn, batch, 4 if relaxed else 3, z_prev=z)
        force, _, friction, limit = _chain(np.exp(z), pr, x_prev, friction, limit, params, geometry, relaxed)
        x_prev = n_tubes * w * _tube_strain(np.exp(z))
        out[..., i] = force + _extension_force(eps, params["extension_k_n_per_m"], params["extension_rate"], l0)
    return out
