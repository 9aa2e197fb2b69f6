"""Ideal Peano contractile unit: analytic values, limits and derivatives."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from peano_bayes.physics import pouch

# Reference values derived by hand from the pouch's closed forms (theta, eps, F/(p w l), V/(w^2 l)).
# Values as printed; each is checked to half a unit of its last printed digit.
TABLE = [
    (0.2, "0.0067", "4.90", "0.066"),
    (0.4, "0.0265", "2.30", "0.129"),
    (0.6, "0.0589", "1.38", "0.186"),
    (0.8, "0.1033", "0.871", "0.235"),
    (1.0, "0.1585", "0.540", "0.273"),
    (1.2, "0.2233", "0.302", "0.299"),
    (1.4, "0.2961", "0.121", "0.314"),
]


def _printed(text):
    return pytest.approx(float(text), abs=0.5 * 10.0 ** -len(text.split(".")[1]) + 1e-12)


@pytest.mark.parametrize("theta, eps, force, volume", TABLE)
def test_tabulated_values(theta, eps, force, volume):
    assert float(pouch.strain(theta)) == _printed(eps)
    assert float(pouch.force_per_pressure(theta, 1.0, 1.0)) == _printed(force)
    assert float(pouch.volume_factor(theta)) == _printed(volume)


def test_round_tube_limits():
    half_pi = jnp.pi / 2
    assert float(pouch.strain(half_pi)) == pytest.approx(1 - 2 / np.pi, rel=1e-14)
    assert float(pouch.IDEAL_FREE_STRAIN) == pytest.approx(0.3634, abs=1e-4)
    assert float(pouch.force_per_pressure(half_pi, 1.0, 1.0)) == pytest.approx(0.0, abs=1e-15)
    assert float(pouch.volume_factor(half_pi)) == pytest.approx(1 / np.pi, rel=1e-14)


CLOSED_FORMS = [
    (pouch.strain, lambda t: 1 - np.sin(t) / t),
    (pouch.sinc, lambda t: np.sin(t) / t),
    (pouch.volume_factor, lambda t: (t - np.sin(t) * np.cos(t)) / (2 * t**2)),
    (pouch._sin_minus_tcos_over_t3, lambda t: (np.sin(t) - t * np.cos(t)) / t**3),
]


@pytest.mark.parametrize("fn, closed", CLOSED_FORMS)
@pytest.mark.parametrize("theta", [0.5 * pouch._SMALL, pouch._SMALL * (1 - 1e-9), pouch._SMALL * (1 + 1e-9)])
def test_series_matches_closed_form_near_the_switch(fn, closed, theta):
    """The series branch agrees with the closed form where both are accurate (cancellation costs ~1e-11)."""
    assert float(fn(theta)) == pytest.approx(closed(theta), rel=1e-9)


@pytest.mark.parametrize("fn", [pouch.strain, pouch.sinc, pouch.volume_factor, pouch._sin_minus_tcos_over_t3])
def test_values_and_gradients_finite_down_to_zero(fn):
    thetas = jnp.array([0.0, 1e-12, 1e-6, 1e-3, 0.5, 1.5, jnp.pi / 2])
    values = jax.vmap(fn)(thetas)
    grads = jax.vmap(jax.grad(fn))(thetas)
    assert np.all(np.isfinite(values)) and np.all(np.isfinite(grads))


def test_small_angle_limits():
    assert float(pouch._sin_minus_tcos_over_t3(0.0)) == pytest.approx(1 / 3, rel=1e-15)
    assert float(jax.grad(pouch.strain)(1e-8)) == pytest.approx(1e-8 / 3, rel=1e-6)


@settings(max_examples=60, deadline=None)
@given(st.floats(min_value=1e-4, max_value=1.57))
def test_derivatives_match_autodiff(theta):
    assert float(pouch.dstrain_dtheta(theta)) == pytest.approx(float(jax.grad(pouch.strain)(theta)), rel=1e-9)
    assert float(pouch.dvolume_factor_dtheta(theta)) == pytest.approx(
        float(jax.grad(pouch.volume_factor)(theta)), rel=1e-9, abs=1e-14
    )


@settings(max_examples=60, deadline=None)
@given(st.floats(min_value=1e-3, max_value=1.5))
def test_virtual_work(theta):
    """F = p dV/dx: the force formula is the virtual-work derivative of the volume (per unit p, w, l)."""
    dv_dx = pouch.dvolume_factor_dtheta(theta) / pouch.dstrain_dtheta(theta)
    assert float(pouch.force_per_pressure(theta, 1.0, 1.0)) == pytest.approx(float(dv_dx), rel=1e-9)
