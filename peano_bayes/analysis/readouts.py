"""The paper's Table 3 metrics, computed from signals (simulated or measured) with the paper's definitions.

Inputs are 1-D arrays in SI units; outputs are floats in SI units, normalized by pressure where the paper
normalizes (per MPa). Nothing here reads model internals, so the same code measures rig data and simulations.
"""

from __future__ import annotations

import numpy as np

from ..physics.model import GRAVITY_M_PER_S2

PA_PER_MPA = 1e6


def loop_branches(strain, force_n):
    """Split a load cycle at its most stretched sample: (stretching branch, relaxing branch)."""
    strain, force_n = np.asarray(strain, float), np.asarray(force_n, float)
    turn = int(np.argmin(strain))
    return (strain[: turn + 1], force_n[: turn + 1]), (strain[turn:], force_n[turn:])


def _area(strain, force_n):
    """Area under F(strain) over the strain range, orientation-free [N]."""
    order = np.argsort(strain)
    return float(np.trapezoid(force_n[order], strain[order]))


def hysteresis_loss(strain, force_n) -> float:
    """Area between the upper (stretching) and lower (relaxing) curves over the area under the upper [-].

    Areas are taken over the strain range both branches cover.
    """
    (s_up, f_up), (s_down, f_down) = loop_branches(strain, force_n)
    lo = max(s_up.min(), s_down.min())
    hi = min(s_up.max(), s_down.max())
    grid = np.linspace(lo, hi, 256)
    upper = np.interp(grid, *_sorted(s_up, f_up))
    lower = np.interp(grid, *_sorted(s_down, f_down))
    u_up = float(np.trapezoid(upper, grid))
    u_down = float(np.trapezoid(lower, grid))
    return (u_up - u_down) / u_up if u_up > 0 else float("nan")


def _sorted(s, f):
    order = np.argsort(s)
    return s[order], f[order]


def extrapolated_free_strain(strain, force_n, fit_fraction: float = 0.2) -> float:
    """The paper's reading of the free strain [-]: where the relaxing curve of a measured load cycle reaches zero
    force.

    The rig stops at the start tension, so the last ``fit_fraction`` of the relaxing branch's strain range is
    extrapolated linearly to F = 0 (the value is taken directly if the branch reaches zero force). The branch
    still bends there, so on the bundled muscles this reads 0.02-0.08 below the muscle's own free strain
    (:func:`peano_bayes.physics.free_strain`, what the metrics report as ``free_strain``).
    """
    _, (s_down, f_down) = loop_branches(strain, force_n)
    if np.any(f_down <= 0):
        s, f = _sorted(s_down, f_down)
        return float(np.interp(0.0, f[::-1], s[::-1]))
    span = s_down.max() - s_down.min()
    tail = s_down >= s_down.max() - fit_fraction * span
    slope, intercept = np.polyfit(s_down[tail], f_down[tail], 1)
    return float(-intercept / slope) if slope < 0 else float(s_down.max())


def energy_per_pressure(strain, force_n, pressure_pa, flat_length_m, from_strain: float | None = 0.0) -> float:
    """Work output contracting quasi-statically from ``from_strain`` to the free strain, per MPa [J/MPa].

    Integrates the relaxing curve from ``from_strain`` (default 0, the unstretched length; ``None``: the
    cycle's most stretched point) to its end, then the linear extrapolation to the free strain.
    """
    _, (s_down, f_down) = loop_branches(strain, force_n)
    s, f = _sorted(s_down, f_down)
    eps_free = extrapolated_free_strain(strain, force_n)
    start = s.min() if from_strain is None else from_strain
    inside = s >= start
    grid = np.concatenate([[start], s[inside]]) if s.min() < start else s[inside]
    force = np.interp(grid, s, f)
    work = np.trapezoid(force, grid)
    if eps_free > grid[-1]:
        work += 0.5 * force[-1] * (eps_free - grid[-1])
    return float(work * flat_length_m / (np.median(pressure_pa) / PA_PER_MPA))


def stiffness_n_per_m(strain, force_n, flat_length_m, at_strain: float = -0.015) -> float:
    """Tangent stiffness dF/dy of the stretching branch at ``at_strain`` [N/m] (paper: -1.5 % at 0 kPa)."""
    (s_up, f_up), _ = loop_branches(strain, force_n)
    s, f = _sorted(s_up, f_up)
    slope = np.gradient(f, s)
    return float(-np.interp(at_strain, s, slope) / flat_length_m)


def blocking_force_per_pressure(pressure_pa, force_n) -> float:
    """Force at the unstretched length at the highest pressure, per MPa [N/MPa] (median of the top 2 %)."""
    pressure_pa, force_n = np.asarray(pressure_pa, float), np.asarray(force_n, float)
    top = pressure_pa >= pressure_pa.max() - 0.02 * (pressure_pa.max() - pressure_pa.min())
    return float(np.median(force_n[top]) / (np.median(pressure_pa[top]) / PA_PER_MPA))


def stroke(strain) -> float:
    """Distance the muscle lifts its load over the force-producing length [-]: final minus initial strain."""
    strain = np.asarray(strain, float)
    n = max(len(strain) // 50, 1)
    return float(np.median(strain[-n:]) - np.median(strain[:n]))


#: With ``overshoot_fraction``, a step response overshoots if its peak exceeds its final value by this fraction of
#: the rise (the value the measured Table 3 metrics use).
OVERSHOOT_FRACTION = 0.01


def _step_ends(strain):
    """Initial and final strain of a step response: medians of its first and last 5 % (at least 3 samples)."""
    n = max(len(strain) // 20, 3)
    return np.median(strain[:n]), np.median(strain[-n:])


def step_window(time_s, strain, supply_pa, *, overshoot_fraction: float | None = None):
    """Indices ``(start, stop)`` from the step edge to the first maximum of the strain (first overshoot peak).

    The edge is the first sample where the supply passes halfway between its initial and final values.

    ``overshoot_fraction`` None (noise-free signals): the peak is the first local maximum after the edge, or the
    global maximum if the response never turns. A fraction ``f`` (noisy, smoothed signals): the peak is the first
    local maximum after the strain has risen halfway (sensor noise makes earlier local maxima), or the last
    sample; a response whose peak exceeds its final value by less than ``f`` of the rise does not overshoot, and
    the window ends at the first sample at ``1 - f`` of the rise (the slow tail would otherwise set the rms speed,
    and noise would decide where it ends). ``stop`` is at least ``start + 2``.
    """
    supply_pa, strain = np.asarray(supply_pa, float), np.asarray(strain, float)
    half = 0.5 * (supply_pa[0] + supply_pa[-1])
    start = int(np.argmax(supply_pa >= half)) if supply_pa[-1] > supply_pa[0] else 0
    if overshoot_fraction is None:
        search, fallback = start, start + int(np.argmax(strain[start:]))
    else:
        initial, final = _step_ends(strain)
        rise = final - initial
        search, fallback = int(np.argmax(strain - initial >= 0.5 * rise)), len(strain) - 1
        if strain.max() - final < overshoot_fraction * rise:
            settled = int(np.argmax(strain - initial >= (1 - overshoot_fraction) * rise))
            return start, max(settled, start + 2)
    rise = np.diff(strain[search:])
    turns = np.nonzero((rise[:-1] > 0) & (rise[1:] <= 0))[0]
    stop = search + 1 + int(turns[0]) if len(turns) else fallback
    return start, max(stop, start + 2)


def step_metrics(
    time_s,
    strain,
    supply_pa,
    flow_m3_per_s,
    load_n,
    flat_length_m,
    test_pressure_pa,
    *,
    overshoot_fraction: float | None = None,
):
    """Speed [m/s], power per pressure [W/MPa], efficiency [-] and overshoot [-] of a step response (Table 3).

    Speed: rms load speed over :func:`step_window` (``overshoot_fraction`` chooses its end), from the step edge to
    the first overshoot peak. Power: rms mechanical power on the inertial load, ``m (g + a) v``, over the same
    window. Efficiency: rms mechanical over rms fluid power ``p_supply Q`` in the window (NaN when flow was not
    measured). Overshoot: peak over final strain, as a fraction of the rise (initial and final strain are the
    medians of the first and last 5 % of the record). Noisy signals must be smoothed first: speed and
    acceleration are finite differences.
    """
    time_s, strain = np.asarray(time_s, float), np.asarray(strain, float)
    start, stop = step_window(time_s, strain, supply_pa, overshoot_fraction=overshoot_fraction)
    v = np.gradient(strain * flat_length_m, time_s)
    a = np.gradient(v, time_s)
    window = slice(start, stop + 1)
    speed = float(np.sqrt(np.mean(v[window] ** 2)))
    power = load_n * (1.0 + a / GRAVITY_M_PER_S2) * v
    rms_power = float(np.sqrt(np.mean(power[window] ** 2)))
    if flow_m3_per_s is None or np.all(np.isnan(flow_m3_per_s)):
        efficiency = float("nan")
    else:
        fluid = np.asarray(supply_pa, float) * np.asarray(flow_m3_per_s, float)
        efficiency = rms_power / float(np.sqrt(np.mean(fluid[window] ** 2)))
    initial, final = _step_ends(strain)
    return {
        "overshoot": float((strain.max() - final) / (final - initial)),
        "speed": speed,
        "power_per_pressure": rms_power / (test_pressure_pa / PA_PER_MPA),
        "efficiency": efficiency,
    }
