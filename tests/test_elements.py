"""Constitutive elements: closed-form checks, limits, and autodiff against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from peano_bayes.physics import elements

from .helpers import central_difference


def test_bending_limits():
    w, l, k1 = 0.015, 0.0495, 2.0
    at_zero = float(elements.bending_force(1e-9, k1, 0.0, 6.0, w, l))
    at_round = float(elements.bending_force(np.pi / 2, k1, 0.0, 6.0, w, l))
    assert at_zero == pytest.approx(3 * k1 * l / w, rel=1e-9)  # finite at theta -> 0
    assert at_round == pytest.approx((np.pi / 2) ** 3 * k1 * l / w, rel=1e-9)  # 3.875 k1 l/w
    thetas = jnp.linspace(0.01, 1.5, 50)
    stiffening = elements.bending_force(thetas, 0.5, 10.0, 6.0, w, l)
    assert np.all(np.diff(np.asarray(stiffening)) > 0)  # rises with opening: lowers free strain


def test_bending_is_the_energy_derivative():
    """F_b = dU/dx with U = l (k1 th^2/2 + k2 th^(m+2)/(m+2)) and x = w (1 - sin th / th)."""
    w, l, k1, k2, m = 0.015, 0.0495, 0.7, 12.0, 5.5

    def energy(theta):
        return l * (k1 * theta**2 / 2 + k2 * theta ** (m + 2) / (m + 2))

    for theta in [0.05, 0.4, 1.0, 1.5]:
        dx = w * (np.sin(theta) - theta * np.cos(theta)) / theta**2
        expected = float(jax.grad(energy)(theta)) / dx
        assert float(elements.bending_force(theta, k1, k2, m, w, l)) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("ka, kb", [(2e4, 1e7), (1e3, 0.0), (1e5, 3.9e8)])
def test_tensile_inverse_and_oddness(ka, kb):
    forces = jnp.array([-50.0, -1.0, 0.0, 1e-6, 3.0, 300.0])
    stretch = elements.tensile_stretch(forces, ka, kb)
    np.testing.assert_allclose(elements.tensile_force(stretch, ka, kb), forces, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(elements.tensile_stretch(-forces, ka, kb), -stretch, rtol=1e-14)


def test_extension_only_in_extension():
    l0 = 0.06
    assert float(elements.extension_force(0.05, 1e3, 50.0, l0)) == pytest.approx(0.0, abs=1e-12)
    # Stiffness at -1.5 % strain: k exp(rate e) per unit displacement.
    eps = -0.015
    stiff = -float(jax.grad(elements.extension_force)(eps, 1e3, 50.0, l0)) / l0
    assert stiff == pytest.approx(1e3 * np.exp(50.0 * 0.015), rel=1e-3)
    assert float(elements.extension_force(eps, 1e3, 0.0, l0)) == pytest.approx(1e3 * l0 * 0.015, rel=1e-3)


def test_maxwell_relaxation_is_exact():
    """A ramp then hold: the update reproduces the analytic Maxwell response for any step size."""
    k, tau, rate, t_ramp = 2e3, 0.7, 1e-3, 1.0

    def simulate(dt):
        n = round(3.0 / dt)
        t = np.arange(n + 1) * dt
        x = np.minimum(t, t_ramp) * rate
        q = 0.0
        for i in range(n):
            q = elements.maxwell_update(q, x[i + 1] - x[i], dt, k, tau)
        return float(q)

    peak = k * tau * rate * (1 - np.exp(-t_ramp / tau))
    expected = peak * np.exp(-(3.0 - t_ramp) / tau)
    assert simulate(0.05) == pytest.approx(expected, rel=1e-10)
    assert simulate(0.5) == pytest.approx(expected, rel=1e-10)


def test_kelvin_creep_is_exact():
    """A force step then hold: creep d(t) = F/k (1 - exp(-t/tau)) whatever the step size."""
    k, tau, force = 1e4, 0.3, 20.0
    d, f = 0.0, 0.0
    d = elements.kelvin_update(d, 0.0, force, 1e-9, k, tau)  # the step itself
    f = force
    for _ in range(20):
        d = elements.kelvin_update(d, f, f, 0.05, k, tau)
    assert float(d) == pytest.approx(force / k * (1 - np.exp(-1.0 / tau)), rel=1e-6)
    assert float(elements.creep_update(0.0, 10.0, 10.0, 2.0, 1e3)) == pytest.approx(0.02)


def _dahl_cycle(n_steps, amplitude=1e-3, k=2e4, limit=2.0):
    x = np.concatenate(
        [
            np.linspace(0, amplitude, n_steps),
            np.linspace(amplitude, -amplitude, 2 * n_steps),
            np.linspace(-amplitude, amplitude, 2 * n_steps),
        ]
    )
    f, forces = 0.0, []
    for i in range(1, len(x)):
        f = float(elements.dahl_update(f, x[i] - x[i - 1], k, limit))
        forces.append(f)
    return x[1:], np.array(forces)


def test_dahl_is_rate_independent_and_bounded():
    """The loop does not depend on how finely (how fast) it is traversed, and stays within the limit."""
    x1, f1 = _dahl_cycle(200)
    x2, f2 = _dahl_cycle(2000)
    assert np.max(np.abs(f1)) <= 2.0 and np.max(np.abs(f2)) <= 2.0
    np.testing.assert_allclose(
        np.interp(0.0, x1[-400:], f1[-400:]), np.interp(0.0, x2[-4000:], f2[-4000:]), rtol=1e-3
    )
    assert float(elements.dahl_update(1.3, 0.0, 2e4, 2.0)) == pytest.approx(1.3, rel=1e-15)  # no creep


def test_effective_pressure():
    assert float(elements.effective_pressure(2e5, 0.0, 100.0)) == pytest.approx(2e5, rel=1e-9)
    assert float(elements.effective_pressure(0.0, 0.0, 100.0)) == pytest.approx(100.0, abs=10.0)
    assert float(elements.effective_pressure(4e3, 1e4, 100.0)) == pytest.approx(100.0, abs=1.0)
    assert float(elements.effective_pressure(3e4, 1e4, 100.0)) == pytest.approx(2e4, rel=1e-3)


# Every element, differentiated w.r.t. every argument it has, against central differences.
ELEMENT_CASES = [
    (
        elements.bending_force,
        dict(theta=0.6, k1_n=0.5, k2_n=10.0, exponent=6.0, width_m=0.015, length_m=0.0495),
    ),
    (elements.tensile_stretch, dict(force_n=40.0, ka_n_per_m=2e4, kb_n_per_m2=1e7)),
    (elements.extension_force, dict(strain=-0.012, k_n_per_m=1e3, rate=50.0, l0_m=0.06)),
    (elements.maxwell_update, dict(q_n=1.5, dx_m=2e-4, dt_s=0.05, k_n_per_m=2e3, tau_s=0.8)),
    (elements.kelvin_update, dict(d_n=1e-4, f_n=10.0, f_next=12.0, dt_s=0.05, k_n_per_m=2e4, tau_s=0.5)),
    (elements.creep_update, dict(d_n=1e-4, f_n=10.0, f_next=12.0, dt_s=0.05, c_ns_per_m=1e6)),
    (elements.dahl_update, dict(f_n=0.4, dx_m=3e-5, stiffness_n_per_m=2e4, limit_n=2.0)),
    (elements.effective_pressure, dict(pressure_pa=3e4, threshold_pa=5e3, floor_pa=100.0)),
]


@pytest.mark.parametrize("fn, args", ELEMENT_CASES, ids=lambda v: getattr(v, "__name__", ""))
def test_element_gradients_match_finite_differences(fn, args):
    args = {k: float(v) for k, v in args.items()}
    grads = jax.grad(lambda a: fn(**a))(args)
    for name in args:
        fd = central_difference(lambda a: fn(**a), args, name)
        assert float(grads[name]) == pytest.approx(fd, rel=1e-5, abs=1e-9 * max(1.0, abs(fd))), name
