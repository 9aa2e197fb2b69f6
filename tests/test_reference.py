"""Reproductions and differentiability of the paper's two reference models (physics/reference.py).

Targets come from Veale, Xie, Anderson (2016) (Tables 1-2, section 2) and from consequences of the two models
derived in the project's design notes before this code was written (Veale's force balance and its roots;
Sarosi's static curves, their linearisation and the step response), not from running it. Tabulated values
are checked to their printed precision: within 0.6 units of the last printed digit (half a unit for rounding
plus a little slack, because a few tabulated entries sit right on a rounding boundary).

Compilation dominates the runtime, so each model is evaluated once per module on every pressure/strain
the tests need (module fixtures), and each gradient check compiles one ``value_and_grad``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import peano_bayes  # noqa: F401  (enables float64)
from peano_bayes.physics import reference as ref

KPA = 1e3
G = 9.81
REL_GRAD_TOL = 1e-5
LOAD_N = 42.0

SAROSI_P_KPA = [50, 80, 100, 200, 300, 400, 500]
VEALE_P_KPA = [30, 80, 100, 200, 300, 400, 500]
GRID_P = np.linspace(0.0, 600 * KPA, 13)
GRID_EPS = np.linspace(-0.05, 0.14, 20)
CURVE_EPS = [0.0, 0.02, 0.05, 0.08, 0.10, 0.12]
EXTENSION_EPS = [-0.05, -0.015, -0.001]

simulate = jax.jit(ref.simulate_sarosi_step, static_argnames="substeps")


def assert_printed(measured, printed, unit):
    """``measured`` agrees with the ``printed`` values whose last digit is worth ``unit``."""
    np.testing.assert_allclose(np.asarray(measured), np.asarray(printed), rtol=0, atol=0.6 * unit)


def evaluate_groups(fn, groups):
    """Evaluate ``fn`` (jitted, one compile) on all named groups of inputs at once.

    ``groups`` maps a name to a tuple of equal-length 1-D arrays (the arguments of ``fn``); ``fn`` returns a
    dict of 1-D arrays. Returns ``{output key: {group name: array}}``.
    """
    names = list(groups)
    n_args = len(groups[names[0]])
    sizes = np.cumsum([len(groups[k][0]) for k in names])[:-1]
    args = [jnp.asarray(np.concatenate([groups[k][i] for k in names])) for i in range(n_args)]
    out = jax.jit(fn)(*args)
    return {key: dict(zip(names, np.split(np.asarray(val), sizes), strict=True)) for key, val in out.items()}


# === fixtures: one evaluation of each model ===============================================================


@pytest.fixture(scope="module")
def sarosi():
    """Static Sarosi quantities at the table pressures, p = 0, a huge pressure and the grid."""
    p = {
        "table": np.asarray(SAROSI_P_KPA, dtype=float) * KPA,
        "zero": np.zeros(1),
        "huge": np.full(1, 1e12),
        "grid": GRID_P,
    }

    def statics(pressure):
        eq = ref.sarosi_equilibrium_strain(pressure, LOAD_N)
        return {
            "upper0": ref.sarosi_force(pressure, 0.0, curve="upper"),
            "lower0": ref.sarosi_force(pressure, 0.0, curve="lower"),
            "free_lower": ref.sarosi_free_strain(pressure),
            "free_upper": ref.sarosi_free_strain(pressure, curve="upper"),
            "zeta": ref.sarosi_damping_ratio(pressure),
            "equilibrium": eq,
            "stiffness_eq": ref.sarosi_stiffness(pressure, eq),
            "damping_eq": ref.sarosi_damping(pressure, eq, LOAD_N / G),
        }

    return evaluate_groups(statics, {k: (v,) for k, v in p.items()})


@pytest.fixture(scope="module")
def veale():
    """Veale's model: blocking force and free strain at the pressures, force at (p, eps) pairs."""
    pg, eg = np.meshgrid(GRID_P, GRID_EPS, indexing="ij")
    pairs = {
        "curve500": (np.full(len(CURVE_EPS), 500 * KPA), np.asarray(CURVE_EPS)),
        "extension0": (np.zeros(len(EXTENSION_EPS)), np.asarray(EXTENSION_EPS)),
        "table": (np.asarray(VEALE_P_KPA, dtype=float) * KPA, np.zeros(len(VEALE_P_KPA))),
        "grid": (pg.ravel(), eg.ravel()),
    }

    def model(pressure, strain):
        free = ref.veale_free_strain(pressure)
        return {
            "force": ref.veale_force(pressure, strain),
            "blocking": ref.veale_blocking_force(pressure),
            "free": free,
            "force_at_free": ref.veale_force(pressure, free),
        }

    return evaluate_groups(model, pairs)


@pytest.fixture(scope="module")
def step_response():
    """Ideal step 80 -> 500 kPa (0.1 ms rise), 42 N load, l0 = 0.06 m, 1.5 s on a 0.1 ms grid."""
    t = jnp.arange(15001, dtype=float) * 1e-4
    p = jnp.where(t > 0, 500 * KPA, 80 * KPA)
    return t, simulate(t, p, LOAD_N, 0.06)


# === Sarosi: statics ======================================================================================


def test_sarosi_required_reproductions(sarosi):
    i500 = SAROSI_P_KPA.index(500)
    assert abs(sarosi["upper0"]["table"][i500] - 313.4) <= 0.1
    assert abs(sarosi["lower0"]["table"][i500] - 307.6) <= 0.1
    assert abs(100 * sarosi["free_lower"]["table"][i500] - 14.0) <= 0.05
    assert abs(sarosi["zeta"]["table"][i500] - 0.11) <= 0.005


def test_sarosi_table_of_research_notes(sarosi):
    assert_printed(sarosi["upper0"]["table"], [64.9, 81.4, 92.5, 147.7, 202.9, 258.1, 313.4], 0.1)
    assert_printed(sarosi["lower0"]["table"], [47.5, 64.8, 76.4, 134.2, 192.0, 249.8, 307.6], 0.1)
    assert_printed(100 * sarosi["free_lower"]["table"], [12.7, 13.2, 13.4, 13.8, 13.9, 14.0, 14.0], 0.1)
    assert_printed(100 * sarosi["free_upper"]["table"], [14.3, 14.3, 14.2, 14.2, 14.2, 14.1, 14.1], 0.1)
    assert_printed(sarosi["zeta"]["table"], [0.34, 0.27, 0.24, 0.17, 0.14, 0.12, 0.11], 0.01)


def test_sarosi_structural_facts_of_research_notes(sarosi):
    # Sarosi's curves: 18.6-37 N at p = 0, eps = 0; a 4.4 % free strain at p = 0, where the upper
    # curve (F -> a_u6 > 0) has no root at all (NaN); free strain -> 14.1 % on both curves as p -> inf.
    assert_printed(sarosi["lower0"]["zero"], 18.6, 0.1)
    assert_printed(sarosi["upper0"]["zero"], 37, 1)
    assert_printed(100 * sarosi["free_lower"]["zero"], 4.4, 0.1)
    assert np.isnan(sarosi["free_upper"]["zero"]).all()
    assert_printed(100 * sarosi["free_lower"]["huge"], 14.1, 0.1)
    assert_printed(100 * sarosi["free_upper"]["huge"], 14.1, 0.1)
    # Stiffness at eps = -1.5 %, l0 = 0.06 m: 5.0e4, 6.4e4, 1.36e5 N/m at 0, 80, 500 kPa.
    k = ref.sarosi_stiffness(jnp.array([0.0, 80 * KPA, 500 * KPA]), -0.015, 0.06)
    assert_printed(-k / 1e4, [5.0, 6.4, 13.6], 0.1)


def test_sarosi_stiffness_is_the_true_derivative():
    # Eq. (7) as printed (a_u4 p eps) is not the derivative of eq. (4); the code uses the derivative.
    for p, eps in [(0.0, 0.0), (80 * KPA, 0.03), (500 * KPA, 0.116)]:
        slope = float(jax.grad(lambda e, p=p: ref.sarosi_force(p, e))(eps))
        assert abs(float(ref.sarosi_stiffness(p, eps, 0.06)) - slope / 0.06) < 1e-12 * abs(slope)


def test_sarosi_linearisation_of_research_notes(sarosi):
    # Sarosi's step model linearised (42 N, l0 = 0.06 m): at 500 kPa k ~ 2.8e4 N/m, f_n ~ 12.9 Hz, zeta = 0.113,
    # B ~ 78 N s/m; at 80 kPa k ~ 1.3e4 N/m, f_n ~ 8.8 Hz, zeta = 0.27.
    i80, i500 = SAROSI_P_KPA.index(80), SAROSI_P_KPA.index(500)
    k = -sarosi["stiffness_eq"]["table"]
    f_n = np.sqrt(k / (LOAD_N / G)) / (2 * np.pi)
    assert_printed(k[[i500, i80]] / 1e4, [2.8, 1.3], 0.1)
    assert_printed(f_n[[i500, i80]], [12.9, 8.8], 0.1)
    assert_printed(sarosi["zeta"]["table"][i500], 0.113, 0.001)
    assert_printed(sarosi["zeta"]["table"][i80], 0.27, 0.01)
    assert_printed(sarosi["damping_eq"]["table"][i500], 78, 1)


def test_sarosi_bad_curve_raises():
    with pytest.raises(ValueError):
        ref.sarosi_force(1e5, 0.0, curve="middle")


# === Sarosi: dynamics =====================================================================================


def test_step_initial_equilibrium(step_response, sarosi):
    t, res = step_response
    assert_printed(100 * res.strain[0], 2.97, 0.01)
    assert abs(float(res.strain[0]) - sarosi["equilibrium"]["table"][SAROSI_P_KPA.index(80)]) < 1e-12
    assert float(res.velocity[0]) == 0.0


def test_step_steady_state_matches_static_root(step_response, sarosi):
    t, res = step_response
    static = sarosi["equilibrium"]["table"][SAROSI_P_KPA.index(500)]  # root of F_u(500 kPa, eps) = m g
    assert abs(float(res.strain[-1]) - static) < 1e-5
    assert abs(float(res.velocity[-1])) < 1e-5
    assert_printed(100 * static, 11.6, 0.1)


def test_step_overshoots_like_research_notes(step_response):
    t, res = step_response
    i = int(jnp.argmax(res.strain))
    peak, t_peak = float(res.strain[i]), float(t[i])
    assert peak > float(res.strain[-1]) + 0.03
    # Sarosi's step model: peak 17.9 % at 38 ms.
    assert_printed(100 * peak, 17.9, 0.1)
    assert abs(1e3 * t_peak - 38) <= 1.0


def test_step_on_coarse_nonuniform_grid(step_response):
    # Irregular gaps of 0.1-1.2 ms picked from the 0.1 ms grid (same 0.1 ms rise, default 4 substeps) must
    # reproduce the fine solution at the shared samples. Padded to the fixture's length: no recompile.
    t, fine = step_response
    gaps = np.random.default_rng(0).integers(1, 13, size=3000)
    keep = np.concatenate([[0, 1], 1 + np.cumsum(gaps)])
    keep = keep[keep < 15001]
    pad = float(t[-1]) + 1e-4 * np.arange(1, 15001 - len(keep) + 1)
    t_nu = jnp.concatenate([t[keep], jnp.asarray(pad)])
    coarse = simulate(t_nu, jnp.where(t_nu > 0, 500 * KPA, 80 * KPA), LOAD_N, 0.06)
    n = len(keep)
    assert float(jnp.max(jnp.abs(coarse.strain[:n] - fine.strain[keep]))) < 1e-6
    assert float(jnp.max(jnp.abs(coarse.velocity[:n] - fine.velocity[keep]))) < 1e-6
    with pytest.raises(ValueError):
        ref.simulate_sarosi_step(t_nu, t_nu[:-1], LOAD_N)


# === Veale ================================================================================================


def test_veale_required_reproductions(veale):
    i200, i500 = VEALE_P_KPA.index(200), VEALE_P_KPA.index(500)
    blocking, free = veale["blocking"]["table"], 100 * veale["free"]["table"]
    assert abs(blocking[i500] / 298.7 - 1) <= 0.01
    assert abs(free[i500] - 15.0) <= 0.1
    assert_printed(blocking[i200], 155, 1)
    assert_printed(free[i200], 12.9, 0.1)


def test_veale_table_of_research_notes(veale):
    assert_printed(veale["blocking"]["table"], [39.5, 80.1, 94.1, 155.2, 207.6, 254.9, 298.6], 0.1)
    np.testing.assert_allclose(veale["force"]["table"], veale["blocking"]["table"], rtol=1e-14)
    # The tabulated 30 and 100 kPa free strains (9.2, 11.5) sit 0.05 points above the exact roots (9.149, 11.448).
    assert_printed(100 * veale["free"]["table"], [9.2, 11.0, 11.5, 12.9, 13.8, 14.5, 15.0], 0.1)
    assert_printed(veale["force"]["curve500"], [299, 245, 182, 127, 89, 50], 1)
    # The free strain is the zero of the force.
    np.testing.assert_allclose(veale["force_at_free"]["table"], 0.0, atol=1e-9)


def test_veale_flat_linkage_at_zero_pressure(veale):
    # p = 0, eps <= 0: pure tensile spring F = ka d + kb d^2 with d = -eps w; the reference value is 42 N at -1.5 %.
    d = -np.asarray(EXTENSION_EPS) * 0.015
    np.testing.assert_allclose(veale["force"]["extension0"], 1e5 * d + 3.889e8 * d**2, rtol=1e-12)
    assert_printed(veale["force"]["extension0"][1], 42, 1)
    np.testing.assert_allclose(veale["free"]["extension0"], 0.0, atol=1e-12)  # no free strain at p = 0


# === Gradients against central finite differences =========================================================


def central_difference(fn, x, h):
    """Fourth-order central difference of the scalar function ``fn`` at ``x`` with step ``h``."""
    return (8.0 * (fn(x + h) - fn(x - h)) - (fn(x + 2.0 * h) - fn(x - 2.0 * h))) / (12.0 * h)


def assert_grad_close(ad, fd, tol=REL_GRAD_TOL):
    ad, fd = float(ad), float(fd)
    assert abs(ad - fd) <= tol * abs(fd), (ad, fd, abs(ad - fd) / abs(fd))


def check_gradients(fn, *points, rel_step=1e-3):
    """Compare ``jax.grad`` of the scalar ``fn(*args)`` with central differences, every array element.

    ``points`` are argument tuples (pytrees of arrays). One jitted ``value_and_grad`` serves all of them
    and is returned. The difference stencil is fourth order, so a relative step of 1e-3 keeps the
    truncation error ~1e-12 while round-off and root-solver noise (~1e-13 relative) stay ~1e-10.
    """
    value_and_grad = jax.jit(jax.value_and_grad(fn, argnums=tuple(range(len(points[0])))))
    for args in points:
        args = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=float), args)  # no weak types
        _, grads = value_and_grad(*args)
        leaves, treedef = jax.tree_util.tree_flatten(args)
        grad_leaves = jax.tree_util.tree_leaves(grads)
        for k, (leaf, grad) in enumerate(zip(leaves, grad_leaves, strict=True)):
            leaf, grad = np.asarray(leaf, dtype=float), np.asarray(grad)
            for idx in np.ndindex(leaf.shape):

                def value(x, k=k, leaf=leaf, idx=idx, leaves=leaves, treedef=treedef):
                    new = leaf.copy()
                    new[idx] = x
                    perturbed = [*leaves[:k], jnp.asarray(new), *leaves[k + 1 :]]
                    return float(value_and_grad(*jax.tree_util.tree_unflatten(treedef, perturbed))[0])

                x0 = float(leaf[idx])
                assert_grad_close(grad[idx], central_difference(value, x0, rel_step * abs(x0)))
    return value_and_grad


def test_sarosi_force_gradients():
    # w.r.t. all 12 coefficients, pressure and strain, on both curves (the other curve's are exactly zero)
    for curve in ("upper", "lower"):
        check_gradients(
            lambda c, p, e, curve=curve: ref.sarosi_force(p, e, c, curve), (ref.SAROSI_TABLE1, 300 * KPA, 0.05)
        )


def test_sarosi_damping_ratio_gradients():
    check_gradients(lambda c, p: ref.sarosi_damping_ratio(p, c), (ref.SAROSI_TABLE1, 200 * KPA))


def test_simulate_sarosi_step_gradients():
    # w.r.t. the 12 coefficients and the load
    t = jnp.arange(121) * 1e-3
    p = jnp.where(t > 0, 500 * KPA, 80 * KPA)

    def response(coeffs, load):  # strain while rising, near the peak, and settling
        strain = ref.simulate_sarosi_step(t, p, load, 0.06, coeffs).strain
        return strain[20] + strain[40] + strain[120]

    check_gradients(response, (ref.SAROSI_TABLE1, LOAD_N))


def test_veale_force_gradients():
    # w.r.t. the 8 parameters, pressure and strain, contracting and extended
    points = [(ref.VEALE_TABLE2, 300 * KPA, 0.05), (ref.VEALE_TABLE2, 80 * KPA, -0.02)]
    value_and_grad = check_gradients(lambda q, p, e: ref.veale_force(p, e, q), *points)
    # p = 0, eps < 0 (flat linkage, root u = 0): F = ka d + kb d^2, d = -eps w; only ka, kb, w and eps act.
    d = 0.015 * 0.015
    _, (gq, gp, ge) = value_and_grad(ref.VEALE_TABLE2, jnp.asarray(0.0), jnp.asarray(-0.015))
    np.testing.assert_allclose(float(gq.tensile_ka_n_per_m), d, rtol=1e-10)
    np.testing.assert_allclose(float(gq.tensile_kb_n_per_m2), d * d, rtol=1e-10)
    np.testing.assert_allclose(float(gq.width_m), (1e5 + 2 * 3.889e8 * d) * 0.015, rtol=1e-10)
    for field in ("area1_m2", "area2_m2", "bending_quartic_n_per_m5", "bending_linear_n_per_m2"):
        assert abs(float(getattr(gq, field))) < 1e-12
    # muscle-level stiffness at 0 kPa, -1.5 % (l0 = 4 w = 0.06 m): 6.9e4 N/m worked out by hand
    assert_printed(-float(ge) / 0.06 / 1e4, 6.9, 0.1)
    # the linkage opens like u ~ p^2 from flat, so the force is stationary in pressure at p = 0
    assert abs(float(gp)) < 1e-12


def test_veale_blocking_force_and_free_strain_gradients():
    check_gradients(lambda q, p: ref.veale_blocking_force(p, q), (ref.VEALE_TABLE2, 500 * KPA))
    check_gradients(lambda q, p: ref.veale_free_strain(p, q), (ref.VEALE_TABLE2, 200 * KPA))


# === jit, vmap, NaN-free grid =============================================================================


def test_vmap_matches_broadcasting(sarosi, veale, step_response):
    pv = jnp.asarray(VEALE_P_KPA, dtype=float) * KPA
    ps = jnp.asarray(SAROSI_P_KPA, dtype=float) * KPA
    widths = jnp.array([0.015, 0.01725])
    t = jnp.arange(15001, dtype=float) * 1e-4
    pt = jnp.where(t > 0, 500 * KPA, 80 * KPA)
    loads = jnp.array([20.0, LOAD_N])

    @jax.jit
    def batched():
        return {
            "blocking": jax.vmap(ref.veale_blocking_force)(pv),
            "zeta": jax.vmap(ref.sarosi_damping_ratio)(ps),
            # over parameter sets, as a fit would
            "free_w": jax.vmap(
                lambda w: ref.veale_free_strain(500 * KPA, eqx.tree_at(lambda q: q.width_m, ref.VEALE_TABLE2, w))
            )(widths),
            # the dynamic model over loads (several step experiments)
            "strain_loads": jax.vmap(lambda f: ref.simulate_sarosi_step(t, pt, f).strain)(loads),
        }

    out = batched()
    np.testing.assert_allclose(out["blocking"], veale["blocking"]["table"], rtol=1e-12)
    np.testing.assert_allclose(out["zeta"], sarosi["zeta"]["table"], rtol=1e-12)
    np.testing.assert_allclose(out["free_w"][0], veale["free"]["table"][-1], rtol=1e-12)
    # a wider tube (same linkage and areas) reaches a smaller free strain u/w
    np.testing.assert_allclose(out["free_w"][1], out["free_w"][0] * 0.015 / 0.01725, rtol=1e-12)
    np.testing.assert_allclose(out["strain_loads"][1], step_response[1].strain, rtol=1e-12)
    assert float(out["strain_loads"][0, -1]) > float(out["strain_loads"][1, -1])  # lighter load contracts more


def test_no_nan_on_grid(sarosi, veale):
    p, eps = GRID_P[:, None], GRID_EPS[None, :]
    for curve in ("upper", "lower"):
        assert np.all(np.isfinite(np.asarray(ref.sarosi_force(p, eps, curve=curve))))
    assert np.all(np.isfinite(np.asarray(ref.sarosi_stiffness(p, eps))))
    for key in ("zeta", "free_lower", "equilibrium", "damping_eq"):
        assert np.all(np.isfinite(sarosi[key]["grid"])), key
    for key in ("force", "blocking", "free", "force_at_free"):
        assert np.all(np.isfinite(veale[key]["grid"])), key
