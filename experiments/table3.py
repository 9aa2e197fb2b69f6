"""Table 3 metrics measured from a rig :class:`~peano_bayes.data.Dataset` (simulated or loaded from files).

Shared by ``calibrate.py`` (noise-free virtual rig) and ``calibration_report.py`` (the bundled noisy datasets).
Every metric uses :mod:`peano_bayes.physics.metrics` (the paper's Table 3 definitions) on each run and is
averaged over specimens and repeats. Interpretation choices, stated once:

- stiffness: tangent of the stretching branch of the 0 kPa load cycles at -1.5 % strain [N/m], from a
  quadratic fitted over +-0.3 % strain around it (a plain finite difference of noisy data is meaningless);
  NaN when the cycle does not cover -1.5 % (the start tension already stretches the muscle past it);
- hysteresis loss, free strain and energy: the load cycles at the test pressure (Figure 9 uses the
  pressurized cycles of Figure 8(b)(d));
- step metrics: the formulas of :func:`peano_bayes.physics.metrics.step_metrics` (rms speed, rms power
  ``m (g + a) v``, rms mechanical over rms fluid power) on strain and flow smoothed with a zero-phase
  Savitzky-Golay filter (``STEP_SMOOTHING_S``, as any rig must before taking a speed and an acceleration from
  a 1 kHz position signal), over a window from the supply edge to the first maximum of the smoothed strain
  after it has risen halfway to its final value (the first overshoot peak; sensor noise makes earlier local
  maxima), or, for a response without overshoot (over 1 % of the rise), to 99 % of the rise. For an
  overshooting response on noise-free signals this equals ``step_metrics`` to within a percent.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from peano_bayes.physics import metrics as m
from peano_bayes.physics.model import GRAVITY_M_PER_S2

#: Savitzky-Golay window of the step-response smoothing [s] (order 3); 15 ms at 1 kHz is 15 samples.
STEP_SMOOTHING_S = 0.015

#: Metric name -> SI unit, in report order.
METRIC_UNITS = {
    "stiffness_at_minus_1.5pct_0kPa": "N/m",
    "hysteresis_loss": "fraction",
    "free_strain": "fraction",
    "energy_per_pressure": "J/MPa",
    "blocking_force_per_pressure": "N/MPa",
    "stroke": "fraction",
    "speed": "m/s",
    "power_per_pressure": "W/MPa",
    "efficiency": "fraction",
    "overshoot": "fraction",
}


#: Half-width of the strain window of the stiffness fit [-].
STIFFNESS_HALF_WINDOW = 0.003
STIFFNESS_STRAIN = -0.015


def _smooth(signal, time_s):
    """Zero-phase Savitzky-Golay smoothing (order 3) over ``STEP_SMOOTHING_S``."""
    dt = float(np.median(np.diff(time_s)))
    window = int(round(STEP_SMOOTHING_S / dt)) | 1
    if window < 5 or len(signal) <= window:
        return np.asarray(signal, float)
    return savgol_filter(np.asarray(signal, float), window, 3)


def stiffness(strain, force_n, flat_length_m, at_strain: float = STIFFNESS_STRAIN) -> float:
    """Tangent stiffness -dF/dy of the stretching branch at ``at_strain`` [N/m] from a quadratic fitted to the
    branch within ``STIFFNESS_HALF_WINDOW`` of it (one-sided where the branch turns there); NaN if the branch
    does not reach ``at_strain`` or starts less than ``STIFFNESS_HALF_WINDOW`` above it."""
    strain, force_n = np.asarray(strain, float), np.asarray(force_n, float)
    turn = int(np.argmin(strain))
    s, f = strain[: turn + 1], force_n[: turn + 1]
    if s.max() < at_strain + STIFFNESS_HALF_WINDOW or s.min() > at_strain + 1e-4:
        return float("nan")
    near = np.abs(s - at_strain) <= STIFFNESS_HALF_WINDOW
    coef = np.polyfit(s[near] - at_strain, f[near], 2)
    return float(-coef[1] / flat_length_m)


#: A step response overshoots if its peak exceeds its final value by this fraction of the rise; without
#: overshoot the window ends where the strain first reaches ``1 - OVERSHOOT_FRACTION`` of the rise.
OVERSHOOT_FRACTION = 0.01


def step_window(strain) -> tuple[int, int]:
    """``(half, stop)`` sample indices of a (smoothed) step response: ``half`` where the strain first reaches
    half its rise; ``stop`` the first maximum after it (the first overshoot peak, Table 3), or, for a response
    that does not overshoot, the first sample at 99 % of the rise (the peak is then undefined: the slow tail
    would otherwise set the rms speed, and noise would decide where it ends)."""
    strain = np.asarray(strain, float)
    n = max(len(strain) // 20, 3)
    initial, final = np.median(strain[:n]), np.median(strain[-n:])
    rise = final - initial
    half = int(np.argmax(strain - initial >= 0.5 * rise))
    if strain.max() - final < OVERSHOOT_FRACTION * rise:
        return half, int(np.argmax(strain - initial >= (1 - OVERSHOOT_FRACTION) * rise))
    step = np.diff(strain[half:])
    turns = np.nonzero((step[:-1] > 0) & (step[1:] <= 0))[0]
    stop = half + 1 + int(turns[0]) if len(turns) else len(strain) - 1
    return half, stop


def step_metrics(time_s, strain, supply_pa, flow_m3_per_s, load_n, flat_length_m, test_pressure_pa) -> dict:
    """Speed [m/s], power per pressure [W/MPa], efficiency [-] and overshoot (peak over final strain, as a
    fraction of the rise) of a step response, Table 3 definitions
    (the formulas of ``peano_bayes.physics.metrics.step_metrics``) on smoothed signals over the window from the
    supply edge (``metrics.step_window``) to the first overshoot peak (:func:`step_window`)."""
    time_s = np.asarray(time_s, float)
    strain = _smooth(strain, time_s)
    flow = _smooth(flow_m3_per_s, time_s)
    start, _ = m.step_window(time_s, strain, supply_pa)
    _, stop = step_window(strain)
    window = slice(start, max(stop, start + 2) + 1)
    v = np.gradient(strain * flat_length_m, time_s)
    a = np.gradient(v, time_s)
    power = load_n * (1.0 + a / GRAVITY_M_PER_S2) * v
    rms_power = float(np.sqrt(np.mean(power[window] ** 2)))
    fluid = np.asarray(supply_pa, float) * flow
    n = max(len(strain) // 20, 3)
    initial, final = np.median(strain[:n]), np.median(strain[-n:])
    return {
        "overshoot": float((strain.max() - final) / (final - initial)),
        "speed": float(np.sqrt(np.mean(v[window] ** 2))),
        "power_per_pressure": rms_power / (test_pressure_pa / m.PA_PER_MPA),
        "efficiency": rms_power / float(np.sqrt(np.mean(fluid[window] ** 2))),
    }


def run_metrics(dataset) -> dict[str, list[float]]:
    """Every Table 3 metric of every run of ``dataset``: metric name -> list of per-run values (SI units)."""
    l0 = dataset.geometry.flat_length_m
    p_test = dataset.conditions.test_pressure_pa
    out: dict[str, list[float]] = {name: [] for name in METRIC_UNITS}
    for run in dataset.runs:
        if run.test == "load_cycle":
            if np.median(run.pressure_pa) < 0.5 * p_test:
                out["stiffness_at_minus_1.5pct_0kPa"].append(stiffness(run.strain, run.force_n, l0))
            else:
                out["hysteresis_loss"].append(m.hysteresis_loss(run.strain, run.force_n))
                out["free_strain"].append(m.free_strain(run.strain, run.force_n))
                out["energy_per_pressure"].append(m.energy_per_pressure(run.strain, run.force_n, run.pressure_pa, l0))
        elif run.test == "blocking":
            out["blocking_force_per_pressure"].append(m.blocking_force_per_pressure(run.pressure_pa, run.force_n))
        elif run.test == "stroke":
            out["stroke"].append(m.stroke(run.strain))
        elif run.test == "step":
            load = float(np.nanmedian(run.load_n))
            for name, value in step_metrics(
                run.time_s, run.strain, run.supply_pa, run.flow_m3_per_s, load, l0, p_test
            ).items():
                out[name].append(value)
    return out


def dataset_metrics(dataset) -> dict[str, float]:
    """Table 3 metrics of ``dataset``, each the mean over specimens and repeats (SI units, per MPa where the
    paper normalizes); NaN for a metric no run measures or that a run cannot measure."""
    return {name: float(np.mean(v)) if v else float("nan") for name, v in run_metrics(dataset).items()}
