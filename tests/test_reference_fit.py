"""The paper's reference models fitted to load cycles, for the fit report."""

import dataclasses

import numpy as np

from peano_bayes.inference.reference_fit import (
    fit_sarosi_branch,
    fit_veale,
    quality,
    sarosi_predict,
    scaled_veale_geometry,
)
from peano_bayes.physics.reference import SAROSI_TABLE1, VEALE_TABLE2, veale_force


def test_sarosi_fit_recovers_table1_coefficients_from_their_own_curve(rng):
    pressure = rng.uniform(0.0, 5e5, 600)
    strain = rng.uniform(-0.02, 0.2, 600)
    truth = np.asarray(SAROSI_TABLE1.upper)
    force = sarosi_predict(truth, pressure, strain)
    fitted = fit_sarosi_branch(pressure, strain, force)
    np.testing.assert_allclose(sarosi_predict(fitted, pressure, strain), force, atol=1e-6)
    np.testing.assert_allclose(fitted, truth, rtol=1e-5, atol=1e-9)


def test_sarosi_fit_with_noise_leaves_residuals_at_the_noise(rng):
    pressure = rng.uniform(0.0, 3e5, 2000)
    strain = rng.uniform(0.0, 0.25, 2000)
    clean = sarosi_predict(np.asarray(SAROSI_TABLE1.lower), pressure, strain)
    noisy = clean + rng.normal(0.0, 0.5, clean.size)
    q = quality(noisy, sarosi_predict(fit_sarosi_branch(pressure, strain, noisy), pressure, strain))
    assert 0.45 < q["rmse"] < 0.52 and q["r2"] > 0.99 and q["bins"] == 2000


def test_quality_figures():
    q = quality(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 4.0]))
    assert q["max_error"] == 1.0 and np.isclose(q["rmse"], np.sqrt(1 / 3)) and np.isclose(q["r2"], 0.5)


def test_veale_geometry_is_table2_at_table2_tube():
    same = scaled_veale_geometry(0.015, 0.046)
    assert float(same.linkage_m) == float(VEALE_TABLE2.linkage_m)
    double = scaled_veale_geometry(0.030, 0.092)
    assert np.isclose(float(double.linkage_m), 2 * float(VEALE_TABLE2.linkage_m))
    assert np.isclose(float(double.area2_m2), 2 * float(VEALE_TABLE2.area2_m2))


def test_veale_fit_recovers_its_stiffnesses_from_its_own_curve(rng):
    """Noise-free bins of Veale's model at Table 2's tube with two stiffnesses moved off Table 2 (the fit's start):
    the fit finds the four stiffnesses and reproduces every force."""
    geometry = scaled_veale_geometry(0.015, 0.046)
    truth = dataclasses.replace(
        geometry,
        tensile_ka_n_per_m=1.5 * geometry.tensile_ka_n_per_m,
        bending_linear_n_per_m2=0.7 * geometry.bending_linear_n_per_m2,
    )
    pressure, strain = rng.uniform(5e4, 3e5, 300), rng.uniform(-0.01, 0.08, 300)
    force = np.asarray(veale_force(pressure, strain, truth))  # 20-234 N
    fitted = fit_veale(pressure, strain, force, 0.015, 0.046)
    np.testing.assert_allclose(np.asarray(veale_force(pressure, strain, fitted)), force, rtol=0, atol=1e-6)
    for name in ("tensile_ka_n_per_m", "tensile_kb_n_per_m2", "bending_quartic_n_per_m5", "bending_linear_n_per_m2"):
        np.testing.assert_allclose(float(getattr(fitted, name)), float(getattr(truth, name)), rtol=1e-6, err_msg=name)
