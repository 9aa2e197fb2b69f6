"""The Table 3 readouts (``analysis/readouts.py``) on signals whose metrics are known in closed form: straight or
quadratic loop branches (the trapezoid rule and linear interpolation are exact on them) and a step response of
known speed. The metrics of the posterior go through these same functions, so they must be checked apart from
the model."""

import numpy as np
import pytest

from peano_bayes.analysis.readouts import (
    blocking_force_per_pressure,
    energy_per_pressure,
    extrapolated_free_strain,
    hysteresis_loss,
    step_metrics,
    stiffness_n_per_m,
    stroke,
)
from peano_bayes.physics.model import GRAVITY_M_PER_S2

L0_M = 0.06


def _cycle(upper, lower, start, turn, n=401):
    """A load cycle from strain ``start`` stretched to ``turn`` (< start) along ``upper(s)``, then back along
    ``lower(s)``: the rig's order (positive strain is contraction, so stretching lowers the strain). The most
    stretched sample belongs to both branches, so the two must meet there."""
    assert upper(turn) == pytest.approx(lower(turn), abs=1e-12)
    down = np.linspace(start, turn, n)
    up = np.linspace(turn, start, n)[1:]
    strain = np.concatenate([down, up])
    return strain, np.concatenate([upper(down), lower(up)])


def test_hysteresis_loss_of_two_straight_branches():
    """Upper F = 20 - 100 s, lower 40 (s + 0.015) N below it, over s in [-0.015, 0.1]: the area under the upper
    is 20 x 0.115 - 50 (0.1^2 - 0.015^2) = 1.81125, the area between 40 x 0.115^2 / 2 = 0.2645, so the loss is
    0.2645 / 1.81125 = 0.14603..."""
    upper = lambda s: 20 - 100 * s  # noqa: E731
    strain, force = _cycle(upper, lambda s: upper(s) - 40 * (s + 0.015), 0.1, -0.015)
    assert hysteresis_loss(strain, force) == pytest.approx(0.2645 / 1.81125, rel=1e-12)
    strain, force = _cycle(upper, upper, 0.1, -0.015)
    assert hysteresis_loss(strain, force) == pytest.approx(0.0, abs=1e-12)  # the same curve both ways: no loss


def test_energy_and_extrapolated_free_strain_of_a_straight_relaxing_branch():
    """Relaxing branch F = 40 (1 - s / 0.2) ending at the start tension 10 N (s = 0.15): the paper's reading
    extrapolates it to F = 0 at s = 0.2 exactly, and the work from s = 0 is 40 x 0.2 / 2 = 4 N (strain), x 0.06 m
    over 0.03 MPa = 8 J/MPa."""
    relax = lambda s: 40 * (1 - s / 0.2)  # noqa: E731
    strain, force = _cycle(lambda s: relax(s) + 10 * (s + 0.03), relax, 0.15, -0.03)
    assert extrapolated_free_strain(strain, force) == pytest.approx(0.2, rel=1e-12)
    pressure = np.full_like(strain, 30e3)
    assert energy_per_pressure(strain, force, pressure, L0_M) == pytest.approx(8.0, rel=1e-12)
    # from the most stretched point instead: 40 (0.23 - (0.2^2 - 0.03^2) / 0.4) = 40 x 0.13225 ... over 0.03 MPa
    whole = 40 * (0.2 + 0.03 - (0.2**2 - 0.03**2) / 0.4) * L0_M / 0.03
    assert energy_per_pressure(strain, force, pressure, L0_M, from_strain=None) == pytest.approx(whole, rel=1e-12)


def test_stiffness_is_the_stretching_branchs_slope_at_minus_one_and_a_half_percent():
    """Stretching branch F = 20 - 100 s - 2000 s^2: dF/ds at s = -0.015 is -100 + 60 = -40 N, so the stiffness
    is 40 / 0.06 = 666.7 N/m (numpy's second-order gradient is exact on a quadratic at interior samples, and the
    slope between samples is read by linear interpolation, exact on the linear dF/ds)."""
    stretching = lambda s: 20 - 100 * s - 2000 * s**2  # noqa: E731
    strain, force = _cycle(stretching, lambda s: stretching(s) - 5 * (s + 0.05), 0.1, -0.05, n=231)
    assert stiffness_n_per_m(strain, force, L0_M) == pytest.approx(40 / L0_M, rel=1e-9)


def test_blocking_force_and_stroke_per_their_definitions():
    """Blocking force: the median force over the top 2 % of the pressure ramp per MPa (300 N/MPa here; a spike at
    the last sample must not move it). Stroke: the final minus the initial strain, each a median of the first and
    last 2 % (0.10 here, not the 0.12 of an overshoot to 0.13 on the way)."""
    pressure = np.linspace(0.0, 200e3, 1001)
    force = 3e-4 * pressure + 0.5 * np.sin(np.linspace(0, 40, 1001)) * (pressure < 150e3)  # 300 N/MPa at the top
    force[-1] += 20.0
    assert blocking_force_per_pressure(pressure, force) == pytest.approx(300.0, rel=1e-12)
    rise = np.interp(np.linspace(0, 1, 600), [0, 0.5, 1], [0.01, 0.13, 0.11])
    strain = np.concatenate([np.full(200, 0.01), rise, np.full(200, 0.11)])
    assert stroke(strain) == pytest.approx(0.10, rel=1e-12)


def test_step_metrics_of_a_known_rise():
    """A rise whose strain rate is 12 A / T u (1 - u)^2 (u = t / T, from the supply step at t = 0 to its end at
    t = T, strain 0 to A, then held): the load's RMS speed over the rise is L0 12 A / T sqrt(1/105) (the integral
    of u^2 (1 - u)^4 is 1/105); the power and efficiency are recomputed from the analytic speed and acceleration
    (the inertial term of m (g + a) v adds to the RMS power; its sign cannot show, since the speed is zero at both
    ends of the window and the cross term integrates v^2 dv); no overshoot."""
    amplitude, rise_s, load_n, p_pa, flow = 0.05, 0.05, 40.0, 200e3, 2e-5  # peak acceleration 1.5 g
    t = np.linspace(-0.2, 0.6, 80_001)
    u = np.clip(t, 0.0, rise_s) / rise_s
    strain = amplitude * 12 * (u**2 / 2 - 2 * u**3 / 3 + u**4 / 4)
    supply = np.where(t >= 0.0, p_pa, 0.0)
    out = step_metrics(t, strain, supply, np.full_like(t, flow), load_n, L0_M, p_pa)
    inside = (t >= 0.0) & (t <= rise_s)
    speed = L0_M * amplitude * 12 / rise_s * u * (1 - u) ** 2
    accel = L0_M * amplitude * 12 / rise_s**2 * (1 - u) * (1 - 3 * u)
    power = load_n * (1 + accel / GRAVITY_M_PER_S2) * speed
    rms_power = np.sqrt(np.mean(power[inside] ** 2))
    assert out["speed"] == pytest.approx(L0_M * amplitude * 12 / rise_s * np.sqrt(1 / 105), rel=1e-3)
    assert out["power_per_pressure"] == pytest.approx(rms_power / 0.2, rel=1e-3)
    assert out["efficiency"] == pytest.approx(rms_power / (p_pa * flow), rel=1e-3)
    assert out["overshoot"] == pytest.approx(0.0, abs=1e-12)
    assert np.isnan(step_metrics(t, strain, supply, None, load_n, L0_M, p_pa)["efficiency"])


def test_step_overshoot_is_the_peak_over_the_final_strain_as_a_fraction_of_the_rise():
    """A rise from 0.02 to 0.13, a fall to 0.12 and a long hold: overshoot (0.13 - 0.12) / (0.12 - 0.02) = 0.1."""
    t = np.linspace(0.0, 1.0, 10_001)
    strain = np.interp(t, [0.0, 0.1, 0.2, 0.3, 1.0], [0.02, 0.02, 0.13, 0.12, 0.12])
    supply = np.where(t >= 0.1, 100e3, 0.0)
    assert step_metrics(t, strain, supply, None, 10.0, L0_M, 100e3)["overshoot"] == pytest.approx(0.1, rel=1e-12)
