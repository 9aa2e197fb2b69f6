"""The third physics (a Sarosi-type force surface with all four rig tests), its rig, the rig's added contributions
and the conditions drawn per seed (issue 80, item 5)."""

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from peano_bayes import materials
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.physics import VALIDATION_GEOMETRY
from peano_bayes.physics.reference import (
    SAROSI_TABLE1,
    SURFACE_TABLE1,
    sarosi_force,
    simulate_surface_step,
    surface_force,
    surface_free_strain,
    surface_strain_at_force,
)
from peano_bayes.rig import (
    CONDITIONS_STREAM,
    PRESSURE_RANGE_PA,
    RATE_RANGE_HZ,
    RigNoise,
    RigProtocol,
    draw_conditions,
    simulate_surface_dataset,
)

QUIET = RigNoise(0.0, 0.0, 0.0, 0.0, 0.0)
#: The discovery benchmark's shortened protocol (10 Hz quasi-static, 250 Hz step of 0.3 s).
SHORT = RigProtocol(10.0, 16.0, 8.0, step_rate_hz=250.0, step_duration_s=0.3, step_substeps=2)
PRESSURES = np.linspace(0.0, 500e3, 26)


def test_the_surface_is_sarosis_upper_branch_less_its_force_at_rest():
    p, eps = np.meshgrid(PRESSURES, np.linspace(-0.03, 0.12, 31))
    offset = float(sarosi_force(0.0, 0.0, SAROSI_TABLE1, "upper"))
    assert offset == pytest.approx(36.9905 + 0.25999, rel=1e-12)
    np.testing.assert_allclose(surface_force(p, eps), sarosi_force(p, eps) - offset, rtol=0, atol=1e-9)


def test_the_surface_carries_nothing_at_rest_nor_at_its_free_strain():
    assert float(surface_force(0.0, 0.0)) == 0.0
    assert float(surface_free_strain(0.0)) == pytest.approx(0.0, abs=1e-15)
    free = np.asarray(surface_free_strain(PRESSURES))
    np.testing.assert_allclose(surface_force(PRESSURES, free), 0.0, atol=1e-9)
    assert np.all(np.diff(free) > 0)
    # Table 1's upper branch less its force at rest, written out here, solved for zero force by brentq
    a1, a2, a3, a4, a5 = 8.6607e-5, 36.9905, -42.7436, -3.2994e-3, 4.656e-4

    def table_1(eps, p):
        return p * (a1 * math.exp(a3 * eps) + a4 * eps + a5) + a2 * (math.exp(a3 * eps) - 1)

    for p in (200e3, 500e3):  # 8.7 % and 11.9 %
        root = brentq(table_1, 0.0, 0.3, args=(p,), xtol=1e-14)
        assert float(surface_free_strain(p)) == pytest.approx(root, abs=1e-9)


def test_the_surface_falls_with_strain_and_grows_with_pressure_where_stated():
    # falls with strain at every pressure >= 0, far past the free strain
    eps = np.linspace(-0.05, 0.3, 351)
    force = np.asarray(surface_force(PRESSURES[:, None], eps[None, :]))
    assert np.all(np.diff(force, axis=1) < 0)
    # grows with pressure below a5/|a4| = 14.1 % strain (every state the rig reaches: free strain <= 11.9 %)
    eps = np.linspace(-0.05, 0.13, 181)
    force = np.asarray(surface_force(PRESSURES[:, None], eps[None, :]))
    assert np.all(np.diff(force, axis=0) > 0)
    assert SURFACE_TABLE1.area_m2 / abs(SURFACE_TABLE1.slope_area_m2) == pytest.approx(0.1411, abs=1e-4)


def test_the_strain_at_a_force_inverts_the_surface():
    force = np.array([0.0, 5.5, 40.0, 120.0])
    strain = np.asarray(surface_strain_at_force(PRESSURES[:, None], force[None, :]))
    np.testing.assert_allclose(surface_force(PRESSURES[:, None], strain), np.broadcast_to(force, strain.shape),
                               rtol=0, atol=1e-9)  # fmt: skip
    # at 0 kPa the relaxed muscle's stretch term alone: eps = ln(1 + F / a2) / a3
    expected = math.log1p(40.0 / 36.9905) / -42.7436
    assert float(surface_strain_at_force(0.0, 40.0)) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("pressure", [100e3, 200e3, 400e3])
def test_the_step_response_settles_at_the_static_equilibrium_under_its_load(pressure):
    t = np.arange(0.0, 4.0, 1 / 250)
    supply = np.where(t >= 0.05, pressure, 0.0)
    result = simulate_surface_step(t, supply, 40.0, damping_ratio=0.12, substeps=8)
    strain = np.asarray(result.strain)
    assert strain[0] == pytest.approx(float(surface_strain_at_force(0.0, 40.0)), abs=1e-12)  # starts at rest
    equilibrium = float(surface_strain_at_force(pressure, 40.0))
    assert strain[-1] == pytest.approx(equilibrium, abs=1e-7)
    assert abs(float(result.velocity[-1])) < 1e-7
    assert strain.max() > equilibrium + 1e-3  # lightly damped: it overshoots first


def test_the_step_is_resolved_by_its_substeps():
    """RK4 at the rig's 8 substeps per 4 ms sample against 64: the same response to 1e-7 strain."""
    t = np.arange(0.0, 0.3, 1 / 250)
    supply = np.where(t >= 0.05, 300e3, 0.0)
    fine = np.asarray(simulate_surface_step(t, supply, 40.0, damping_ratio=0.14, substeps=64).strain)
    coarse = np.asarray(simulate_surface_step(t, supply, 40.0, damping_ratio=0.14, substeps=8).strain)
    np.testing.assert_allclose(coarse, fine, rtol=0, atol=1e-7)


@pytest.fixture(scope="module")
def quiet():
    """One specimen at Table 1's values, noise-free, on the benchmark's shortened protocol, material PC."""
    return simulate_surface_dataset("PC", seed=3, noise=QUIET, specimens=1, repeats=2, protocol=SHORT,
                                    specimen_spread=0.0)  # fmt: skip


def test_the_surface_rig_runs_the_four_tests_of_the_protocol(quiet):
    spec = materials.material("PC")
    assert quiet.tests == ("load_cycle", "blocking", "stroke", "step")
    assert quiet.geometry == VALIDATION_GEOMETRY and quiet.conditions == spec.conditions()
    assert quiet.provenance["model"] == "sarosi_type_surface"
    assert json.loads(quiet.provenance["parameters"])["stretch_force_n"] == 36.9905
    runs = {r.key: r for r in quiet.runs}
    for number, pressure in ((0, 0.0), (2, spec.test_pressure_pa)):
        cycle = runs["A", "load_cycle", number]
        np.testing.assert_allclose(cycle.force_n, surface_force(pressure, cycle.strain), rtol=0, atol=1e-9)
        assert cycle.force_n[0] == pytest.approx(spec.start_tension_n, abs=1e-8)
        assert cycle.strain.min() <= -0.015
    blocking = runs["A", "blocking", 0]
    np.testing.assert_allclose(blocking.force_n, surface_force(blocking.pressure_pa, 0.0), rtol=0, atol=1e-9)
    stroke = runs["A", "stroke", 0]
    np.testing.assert_allclose(surface_force(stroke.pressure_pa, stroke.strain), 5.5, rtol=0, atol=1e-9)
    step = runs["A", "step", 0]
    np.testing.assert_array_equal(step.pressure_pa, step.supply_pa)  # an open inlet
    assert step.flow_m3_per_s is None and np.all(np.isnan(step.force_n))  # no flow model, no flow signal
    assert len(step) == 76 and step.load_n[0] == spec.step_load_n
    assert step.strain[0] == pytest.approx(float(surface_strain_at_force(0.0, 40.0)), abs=1e-12)


def test_specimens_differ_in_the_surfaces_stiffnesses_only():
    data = simulate_surface_dataset("PC", seed=5, noise=QUIET, specimens=2, repeats=1, protocol=SHORT,
                                    tests=("blocking",))  # fmt: skip
    per = json.loads(data.provenance["specimen_parameters"])
    base = json.loads(data.provenance["parameters"])
    for name, value in base.items():
        differs = [per[s][name] != value for s in "AB"]
        assert all(differs) if name in ("stretch_force_n", "slope_area_m2") else not any(differs), name


def test_a_contribution_is_added_before_the_noise_and_only_there(quiet):
    rng = np.random.default_rng(0)
    runs = {r.key: r for r in quiet.runs}
    added = {
        ("load_cycle", 3): {"force_n": rng.normal(size=len(runs["A", "load_cycle", 3]))},
        ("step", 1): {"strain": 1e-3 * rng.normal(size=76), "pressure_pa": 100.0 * rng.normal(size=76)},
    }
    kw = dict(seed=3, specimens=1, repeats=2, protocol=SHORT, specimen_spread=0.0)
    for noise in (QUIET, RigNoise()):
        plain = simulate_surface_dataset("PC", noise=noise, **kw)
        moved = simulate_surface_dataset("PC", noise=noise, added=added, **kw)
        for a, b in zip(plain.runs, moved.runs, strict=True):
            extra = added.get((a.test, a.run), {})
            for name in ("strain", "pressure_pa", "force_n", "supply_pa"):
                delta = np.nan_to_num(getattr(b, name) - getattr(a, name))
                np.testing.assert_allclose(delta, extra.get(name, 0.0), rtol=0, atol=1e-9, err_msg=f"{a.key} {name}")
        assert json.loads(moved.provenance["added"]) == {
            "load_cycle 3": ["force_n"],
            "step 1": ["pressure_pa", "strain"],
        }
        assert "added" not in plain.provenance


@pytest.mark.parametrize(
    ("added", "message"),
    [
        ({("stroke", 0): {"force_n": np.zeros(81)}}, "the stroke test does not measure force_n"),
        ({("blocking", 0): {"flow_m3_per_s": np.zeros(81)}}, "cannot add to 'flow_m3_per_s'"),
        ({("blocking", 3): {"force_n": np.zeros(81)}}, "the session has blocking runs 0-2, got run 3"),
        ({("blocking", 0): {"force_n": np.zeros(80)}}, r"expected shape \(81,\), got \(80,\)"),
        ({("shaking", 0): {"force_n": np.zeros(80)}}, "expected keys"),
    ],
)
def test_a_bad_contribution_is_refused(added, message):
    with pytest.raises(PeanoBayesInputError, match=message):
        simulate_surface_dataset("PC", noise=QUIET, specimens=1, protocol=SHORT, tests=("blocking", "stroke"),
                                 added=added)  # fmt: skip


def test_drawn_conditions_are_a_pure_function_of_the_seed_on_their_stream():
    first = [draw_conditions(s) for s in range(2000)]
    assert first == [draw_conditions(s) for s in range(2000)]
    u_rate, u_pressure = np.random.default_rng([20005, CONDITIONS_STREAM]).random(2)
    drawn = draw_conditions(20005)
    assert drawn.quasi_static_rate_hz == pytest.approx(10.0 ** (1.0 + int(5 * u_rate) / 4.0), rel=1e-12)
    assert drawn.test_pressure_pa == pytest.approx(100e3 + 300e3 * u_pressure, rel=1e-12)
    rates = np.array([c.quasi_static_rate_hz for c in first])
    pressures = np.array([c.test_pressure_pa for c in first])
    assert RATE_RANGE_HZ == (10.0, 100.0) and PRESSURE_RANGE_PA == (100e3, 400e3)
    # five log-spaced rates, 10 to 100 Hz, each drawn by about a fifth of the seeds (a few shapes to compile)
    np.testing.assert_allclose(sorted(set(rates)), [10.0, 17.7828, 31.6228, 56.2341, 100.0], rtol=1e-5)
    shares = np.array([np.mean(rates == r) for r in sorted(set(rates))])
    assert np.all(np.abs(shares - 0.2) < 0.035)  # 2000 seeds: sd of a share 0.009
    assert pressures.min() >= 100e3 and pressures.max() <= 400e3 and np.ptp(pressures) > 290e3
    with pytest.raises(PeanoBayesInputError, match="seed"):
        draw_conditions(-1)


def test_drawn_conditions_set_the_protocol_the_declared_pressure_and_the_provenance():
    drawn = draw_conditions(20005)
    spec = drawn.material("PC")
    protocol = drawn.protocol(SHORT)
    assert protocol == dataclasses.replace(SHORT, quasi_static_rate_hz=drawn.quasi_static_rate_hz)
    assert spec.test_pressure_pa == drawn.test_pressure_pa and spec.step_load_n == 40.0
    data = drawn.record(simulate_surface_dataset(spec, noise=QUIET, specimens=1, repeats=1, protocol=protocol,
                                                 tests=("load_cycle", "blocking")))  # fmt: skip
    recorded = json.loads(data.provenance["drawn_conditions"])
    assert recorded["seed"] == 20005 and recorded["stream"] == CONDITIONS_STREAM
    assert recorded["quasi_static_rate_hz"] == drawn.quasi_static_rate_hz
    assert recorded["test_pressure_pa"] == drawn.test_pressure_pa
    assert data.conditions.test_pressure_pa == drawn.test_pressure_pa
    blocking = next(r for r in data.runs if r.test == "blocking")
    np.testing.assert_allclose(np.diff(blocking.time_s), 1 / drawn.quasi_static_rate_hz, rtol=1e-9)
    assert blocking.pressure_pa[-1] == pytest.approx(drawn.test_pressure_pa, rel=1e-12)
