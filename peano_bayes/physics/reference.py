"""The two published reference models of a Peano muscle, as pure JAX functions.

Source: M. J. Veale, S. Q. Xie, I. A. Anderson (2016), *Modeling the Peano fluidic muscle and the effects of
its material properties on its static and dynamic behavior*, Smart Mater. Struct. 25, section 2:

- **Sarosi's empirical model** (eqs 1-10, coefficients in Table 1): upper (loading) and lower (unloading)
  static force curves, Lehr damping ratio from the area between them, and the dynamic step model
  ``m y'' = F_u(p, eps) - B(p, eps) y' - m g``.
- **Veale's force-balance model** (Table 2; equations as reconstructed for this package): a toggle linkage per tube,
  a parallel bending element and a series tensile element.
- **A Sarosi-type force surface** (Table 1's upper branch less its force at zero pressure and strain, so that the
  relaxed muscle carries none) and the hanging load it drives with Sarosi's damping: a third physics, neither the
  package's model nor Veale's, for the discovery benchmark's other-physics cases
  (:func:`peano_bayes.rig.simulate_surface_dataset`).

Units are SI throughout: pressure [Pa], strain [-] (contraction positive, a fraction, not %), force [N],
length [m], time [s]. Model parameters are pytrees of arrays (:class:`SarosiCoefficients`,
:class:`VealeParameters`) so the models can be fitted; every function is jit-, vmap- and grad-able. Implicit
quantities (free strain, equilibrium strain, Veale's linkage state) are solved with optimistix and
differentiated with its implicit adjoint. A solve that fails returns NaN instead of raising.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from .model import GRAVITY_M_PER_S2

__all__ = [
    "GRAVITY_M_PER_S2",
    "SAROSI_TABLE1",
    "VEALE_TABLE2",
    "SarosiCoefficients",
    "SURFACE_TABLE1",
    "SarosiStepResult",
    "SurfaceParameters",
    "SurfaceStepResult",
    "VealeParameters",
    "sarosi_damping",
    "sarosi_damping_ratio",
    "sarosi_equilibrium_strain",
    "sarosi_force",
    "sarosi_free_strain",
    "sarosi_stiffness",
    "simulate_sarosi_step",
    "simulate_surface_step",
    "surface_force",
    "surface_free_strain",
    "surface_strain_at_force",
    "veale_blocking_force",
    "veale_force",
    "veale_free_strain",
]

Curve = Literal["upper", "lower"]


def _as_float_array(x):
    return jnp.asarray(x, dtype=float)


def _map_scalar(fn, *arrays):
    """Apply the scalar function ``fn`` element-wise over broadcast ``arrays`` (via vmap)."""
    arrays = jnp.broadcast_arrays(*[_as_float_array(a) for a in arrays])
    shape = arrays[0].shape
    out = jax.vmap(fn)(*[a.reshape(-1) for a in arrays])
    return out.reshape(shape)


# Scalar root finds: a 1x1 Jacobian is diagonal, which lets lineax skip its general (slow to compile) solvers
# in the Newton step and in the implicit adjoint.
_SCALAR_TAGS = frozenset({lx.diagonal_tag})
_SCALAR_ADJOINT = optx.ImplicitAdjoint(linear_solver=lx.Diagonal())


def _solution_or_nan(sol):
    """The solver's value, or NaN where it did not converge (keeps jitted fits running)."""
    return jnp.where(sol.result == optx.RESULTS.successful, sol.value, jnp.nan)


# === Sarosi's empirical model =============================================================================


class SarosiCoefficients(eqx.Module):
    """Coefficients ``a_i1..a_i6`` of Sarosi's force law, shape (6,) each, for p [Pa] and strain [-].

    ``F_i(p, eps) = (a_i1 p + a_i2) exp(a_i3 eps) + a_i4 p eps + a_i5 p + a_i6`` [N], ``i`` = upper
    (loading, contracting) or lower (unloading) branch of the static hysteresis loop.
    """

    upper: jax.Array = eqx.field(converter=_as_float_array)
    lower: jax.Array = eqx.field(converter=_as_float_array)


#: Table 1 of the paper (four-tube muscle, fitted to 0-500 kPa quasi-static data).
SAROSI_TABLE1 = SarosiCoefficients(
    upper=[8.6607e-5, 36.9905, -42.7436, -3.2994e-3, 4.656e-4, 0.25999],
    lower=[16.524e-5, 20.6623, -51.9497, -2.9233e-3, 4.1291e-4, -2.109],
)


def _branch(coeffs: SarosiCoefficients, curve: str) -> jax.Array:
    if curve == "upper":
        return coeffs.upper
    if curve == "lower":
        return coeffs.lower
    raise ValueError(f"curve must be 'upper' or 'lower', got {curve!r}")


def _sarosi(a, p, eps):
    return (a[0] * p + a[1]) * jnp.exp(a[2] * eps) + a[3] * p * eps + a[4] * p + a[5]


def _sarosi_slope(a, p, eps):
    # True derivative dF/deps of the force law. Eq. (7) as printed has a_u4 p eps in place of a_u4 p,
    # which is not the derivative of eq. (4); we use the derivative.
    return a[2] * (a[0] * p + a[1]) * jnp.exp(a[2] * eps) + a[3] * p


def _expm1_over_x(x):
    """``(exp(x) - 1)/x``, exact and differentiable through ``x = 0``."""
    small = jnp.abs(x) < 1e-5
    safe = jnp.where(small, 1.0, x)
    return jnp.where(small, 1.0 + x / 2.0 + x * x / 6.0, jnp.expm1(safe) / safe)


def _sarosi_integral(a, p, eps0, eps1):
    """Closed form of ``int_{eps0}^{eps1} F(p, eps) d eps`` [N] (work per unit strain, J per unit l0)."""
    d = eps1 - eps0
    exp_part = (a[0] * p + a[1]) * jnp.exp(a[2] * eps0) * d * _expm1_over_x(a[2] * d)
    return exp_part + a[3] * p * 0.5 * (eps1 * eps1 - eps0 * eps0) + (a[4] * p + a[5]) * d


def _sarosi_root_scalar(a, p, target):
    """Strain [-] where ``F(p, eps) = target`` [N], Newton from eps = 0.

    With the Table 1 signs (a_3, a_4 < 0, a_1 p + a_2 > 0) F is convex and decreasing in eps, so Newton
    converges monotonically from any start; the residual is scaled to O(1) so the tolerances are relative.
    """
    scale = 1.0 + jnp.abs(a[0] * p) + jnp.abs(a[1]) + jnp.abs(a[4] * p) + jnp.abs(a[5]) + jnp.abs(target)

    def residual(eps, args):
        a_, p_, target_, scale_ = args
        return (_sarosi(a_, p_, eps) - target_) / scale_

    sol = optx.root_find(
        residual,
        optx.Newton(rtol=1e-12, atol=1e-13, linear_solver=lx.Diagonal()),
        jnp.zeros_like(p),
        args=(a, p, target, scale),
        max_steps=100,
        adjoint=_SCALAR_ADJOINT,
        throw=False,
        tags=_SCALAR_TAGS,
    )
    return _solution_or_nan(sol)


def sarosi_force(pressure_pa, strain, coeffs: SarosiCoefficients = SAROSI_TABLE1, curve: Curve = "upper"):
    """Contractile force ``F_i(p, eps)`` [N] of Sarosi's model, eqs (4)-(5).

    ``pressure_pa`` [Pa] and ``strain`` [-] broadcast; returns their broadcast shape. ``curve`` selects the
    upper (loading) or lower (unloading) branch.
    """
    a = _branch(coeffs, curve)
    return _sarosi(a, _as_float_array(pressure_pa), _as_float_array(strain))


def sarosi_stiffness(
    pressure_pa,
    strain,
    l0_m=0.06,
    coeffs: SarosiCoefficients = SAROSI_TABLE1,
    curve: Curve = "upper",
):
    """Muscle stiffness ``k = (dF_i/d eps)/l0`` [N/m], eq. (7) corrected to the true derivative.

    Eq. (7) as printed has ``a_u4 p eps``; the derivative of eq. (4) has ``a_u4 p``, which is used here.
    ``k`` is negative (force falls as the muscle contracts); the damping uses ``|k|``. Broadcasts like
    :func:`sarosi_force`; ``l0_m`` [m] is the flat muscle length (sum of tube widths).
    """
    a = _branch(coeffs, curve)
    return _sarosi_slope(a, _as_float_array(pressure_pa), _as_float_array(strain)) / l0_m


def sarosi_equilibrium_strain(
    pressure_pa,
    load_n,
    coeffs: SarosiCoefficients = SAROSI_TABLE1,
    curve: Curve = "upper",
):
    """Static strain [-] at which the muscle holds ``load_n`` [N]: root of ``F_i(p, eps) = load``.

    ``pressure_pa`` [Pa] and ``load_n`` broadcast; returns their broadcast shape (NaN if not converged).
    """
    a = _branch(coeffs, curve)
    return _map_scalar(lambda p, f: _sarosi_root_scalar(a, p, f), pressure_pa, load_n)


def sarosi_free_strain(pressure_pa, coeffs: SarosiCoefficients = SAROSI_TABLE1, curve: Curve = "lower"):
    """Free strain ``eps_max(p)`` [-]: root of ``F_i(p, eps) = 0``; the paper uses the lower curve.

    ``pressure_pa`` [Pa], any shape; returns the same shape.
    """
    return sarosi_equilibrium_strain(pressure_pa, 0.0, coeffs, curve)


def sarosi_damping_ratio(pressure_pa, coeffs: SarosiCoefficients = SAROSI_TABLE1, strain_min=0.0):
    """Lehr damping ratio ``zeta(p) = (U_u - U_l)/U_u`` [-], eqs (8)-(10).

    ``U_i`` is the area under branch i from ``strain_min`` (0 in the paper) to the free strain of the lower
    curve, integrated in closed form. ``pressure_pa`` [Pa], any shape; returns the same shape.
    """
    p = _as_float_array(pressure_pa)
    return _damping_ratio_given_free_strain(coeffs, p, sarosi_free_strain(p, coeffs, "lower"), strain_min)


def _damping_ratio_given_free_strain(coeffs: SarosiCoefficients, p, eps_max, strain_min=0.0):
    u_upper = _sarosi_integral(coeffs.upper, p, strain_min, eps_max)
    u_lower = _sarosi_integral(coeffs.lower, p, strain_min, eps_max)
    return (u_upper - u_lower) / u_upper


def sarosi_damping(pressure_pa, strain, mass_kg, l0_m=0.06, coeffs: SarosiCoefficients = SAROSI_TABLE1):
    """Damping coefficient ``B = 2 zeta(p) sqrt(|k(p, eps)| m)`` [N s/m], eq. (6).

    ``pressure_pa`` [Pa], ``strain`` [-] and ``mass_kg`` [kg] broadcast; ``l0_m`` [m] flat muscle length.
    """
    zeta = sarosi_damping_ratio(pressure_pa, coeffs)
    k = sarosi_stiffness(pressure_pa, strain, l0_m, coeffs, "upper")
    return 2.0 * zeta * jnp.sqrt(jnp.abs(k) * mass_kg)


class SarosiStepResult(NamedTuple):
    """Response of :func:`simulate_sarosi_step` on the input time grid, shape (n,) each."""

    strain: jax.Array  #: contraction strain eps [-]
    velocity: jax.Array  #: load velocity dy/dt = l0 d eps/dt [m/s], positive while contracting


def simulate_sarosi_step(
    time_s,
    pressure_pa,
    load_n,
    l0_m=0.06,
    coeffs: SarosiCoefficients = SAROSI_TABLE1,
    substeps: int = 4,
) -> SarosiStepResult:
    """Sarosi's dynamic model, eqs (1)-(3): ``m y'' = F_u(p, eps) - B(p, eps) y' - m g``, ``y = l0 eps``.

    ``time_s`` [s], shape (n,), strictly increasing (uniform or not); ``pressure_pa`` [Pa], shape (n,),
    sampled on it and taken as linear in time between samples. The hanging load ``load_n`` [N] gives the
    mass ``m = load/g`` (g = 9.81 m/s^2); ``l0_m`` [m] is the flat muscle length. The muscle starts at rest
    in static equilibrium at the first pressure, ``F_u(p_0, eps_0) = m g``.

    Integration: classical RK4 with ``substeps`` (static int) equal steps per sample interval, inside
    ``lax.scan``. ``zeta(p)`` needs a root solve; it is evaluated exactly at every RK4 stage pressure in one
    vectorised solve before the scan. The default (4 substeps) is accurate to ~1e-6 strain for sample
    intervals up to 1 ms on the Table 1 muscle (natural frequency ~13-25 Hz).
    """
    t = _as_float_array(time_s)
    p = _as_float_array(pressure_pa)
    load = _as_float_array(load_n)
    if t.ndim != 1 or p.shape != t.shape or t.shape[0] < 2:
        raise ValueError("time_s and pressure_pa must both have shape (n,), n >= 2")
    n_stage = 2 * substeps + 1
    a = coeffs.upper
    # Pressure at every RK4 stage: interval i, fractions 0, 1/(2S), ..., 1 of the interval.
    frac = jnp.linspace(0.0, 1.0, n_stage)
    p_stage = p[:-1, None] + frac[None, :] * (p[1:] - p[:-1])[:, None]
    # One batched root solve (one compiled solver): the lower-curve free strain at every stage pressure
    # (for zeta) and, last, the initial equilibrium F_u(p_0, eps_0) = m g.
    a_batch = jnp.concatenate([jnp.broadcast_to(coeffs.lower, (p_stage.size, 6)), coeffs.upper[None, :]], axis=0)
    p_batch = jnp.concatenate([p_stage.reshape(-1), p[:1]])
    target = jnp.concatenate([jnp.zeros(p_stage.size), jnp.broadcast_to(load, (1,))])
    roots = jax.vmap(_sarosi_root_scalar)(a_batch, p_batch, target)
    zeta_stage = _damping_ratio_given_free_strain(coeffs, p_stage, roots[:-1].reshape(p_stage.shape))
    f_stage = jnp.stack([p_stage, zeta_stage], axis=-1)  # (n-1, 2S+1, 2)
    dt_sub = (t[1:] - t[:-1]) / substeps

    gain = GRAVITY_M_PER_S2 / (load * l0_m)  # 1/(m l0) [1/(kg m)]

    def rhs(state, stage):
        eps, rate = state
        p_, zeta_ = stage[0], stage[1]
        spring = (_sarosi(a, p_, eps) - load) * gain
        damping = 2.0 * zeta_ * jnp.sqrt(jnp.abs(_sarosi_slope(a, p_, eps)) * gain) * rate
        return jnp.stack([rate, spring - damping])

    def interval(state, xs):
        stages, h = xs

        def substep(j, y):
            s0 = stages[2 * j]
            s1 = stages[2 * j + 1]
            s2 = stages[2 * j + 2]
            k1 = rhs(y, s0)
            k2 = rhs(y + 0.5 * h * k1, s1)
            k3 = rhs(y + 0.5 * h * k2, s1)
            k4 = rhs(y + h * k3, s2)
            return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

        new = jax.lax.fori_loop(0, substeps, substep, state)
        return new, new

    eps0 = roots[-1]
    y0 = jnp.stack([eps0, jnp.zeros_like(eps0)])
    _, ys = jax.lax.scan(interval, y0, (f_stage, dt_sub))
    ys = jnp.concatenate([y0[None, :], ys], axis=0)
    return SarosiStepResult(strain=ys[:, 0], velocity=l0_m * ys[:, 1])


# === Veale's force-balance model ==========================================================================


class VealeParameters(eqx.Module):
    """Geometry and material parameters of Veale's force-balance model (all scalars, SI).

    - ``width_m``: tube flat width w [m]
    - ``linkage_m``: linkage length l_a (Table 2's b) [m]; the ideal linkage contracts by at most 2 l_a
    - ``area1_m2``: area A1 on which the pressure spreads the tube walls [m^2]
    - ``area2_m2``: end-face ("piston") area A2 = h l pushing the tube ends apart [m^2]
    - ``tensile_ka_n_per_m``, ``tensile_kb_n_per_m2``: series tensile element ``F = ka d + kb d^2``,
      i.e. ``k1(F) = ka/2 + sqrt(ka^2/4 + kb F)`` (Table 2: 5e4 + sqrt(2.5e9 + 388.9e6 F))
    - ``bending_quartic_n_per_m5``, ``bending_linear_n_per_m2``: parallel bending element
      ``k2(u) = c4 u^4 + c1 |u|`` [N/m], force ``k2(u) u``
    """

    width_m: jax.Array = eqx.field(converter=_as_float_array)
    linkage_m: jax.Array = eqx.field(converter=_as_float_array)
    area1_m2: jax.Array = eqx.field(converter=_as_float_array)
    area2_m2: jax.Array = eqx.field(converter=_as_float_array)
    tensile_ka_n_per_m: jax.Array = eqx.field(converter=_as_float_array)
    tensile_kb_n_per_m2: jax.Array = eqx.field(converter=_as_float_array)
    bending_quartic_n_per_m5: jax.Array = eqx.field(converter=_as_float_array)
    bending_linear_n_per_m2: jax.Array = eqx.field(converter=_as_float_array)


#: Table 2 of the paper (w = 15 mm, l = 46 mm, h = 2 mm tubes; the muscle of Table 1, four tubes).
VEALE_TABLE2 = VealeParameters(
    width_m=0.015,
    linkage_m=0.002725,
    area1_m2=4.085e-4,
    area2_m2=0.92e-4,
    tensile_ka_n_per_m=1e5,
    tensile_kb_n_per_m2=3.889e8,
    bending_quartic_n_per_m5=1.625e15,
    bending_linear_n_per_m2=1.674e6,
)


def _tensile_force(params: VealeParameters, stretch):
    """Series element ``F = ka d + kb d |d|`` [N] (odd extension into compression)."""
    return params.tensile_ka_n_per_m * stretch + params.tensile_kb_n_per_m2 * stretch * jnp.abs(stretch)


def _bending_force(params: VealeParameters, u):
    """Parallel element ``k2(u) u`` [N]."""
    return (params.bending_quartic_n_per_m5 * u**4 + params.bending_linear_n_per_m2 * jnp.abs(u)) * u


def _veale_linkage_root(params: VealeParameters, p, other_force):
    """Normalised linkage coordinate ``z`` in [0, 1] (``u = 2 l_a z^2``) that balances the pressure.

    Force balance ``p A1 s = h (p A2 + G(u))`` with ``s = l_a (1 - z^2)``, ``h = l_a z sqrt(2 - z^2)`` and
    ``G(u) = other_force(u)`` (tensile plus bending force). Multiplied by ``h`` and written in ``z`` the
    balance has no singularity at the flat tube (z = 0), so p = 0 is handled. For p > 0 the residual is
    positive at z = 0, negative at z = 1 and has one root, which bisection brackets.
    """
    la = params.linkage_m

    def residual(z, args):
        p_, scale = args
        u = 2.0 * la * z * z
        g = p_ * params.area2_m2 + other_force(u)
        return (p_ * params.area1_m2 * (1.0 - z * z) - z * jnp.sqrt(2.0 - z * z) * g) / scale

    # Bound on every term of the residual, so that |residual| <= ~1 and atol is relative.
    u_max = 2.0 * la
    scale = (
        p * (params.area1_m2 + params.area2_m2)
        + jnp.abs(other_force(u_max))
        + jnp.abs(other_force(jnp.zeros_like(u_max)))
        + 1.0
    )
    sol = optx.root_find(
        residual,
        optx.Bisection(rtol=0.0, atol=1e-14, flip=True),
        jnp.asarray(0.5),
        args=(p, scale),
        options={"lower": 0.0, "upper": 1.0},
        max_steps=256,
        adjoint=_SCALAR_ADJOINT,
        throw=False,
        tags=_SCALAR_TAGS,
    )
    z = _solution_or_nan(sol)
    # Bisection stops ~1e-14 from the root; one Newton step takes the value to round-off (the residual
    # falls through a simple root). The step carries no gradient: derivatives come from the implicit
    # adjoint at the root, so the polished value and its gradient stay consistent.
    r, dr = jax.jvp(lambda zz: residual(zz, (p, scale)), (z,), (jnp.ones_like(z),))
    step = jnp.where(dr < 0.0, r / jnp.where(dr < 0.0, dr, -1.0), 0.0)
    return z - jax.lax.stop_gradient(jnp.clip(step, -1e-12, 1e-12))


def _veale_force_scalar(params: VealeParameters, p, eps):
    w, la = params.width_m, params.linkage_m

    def other_force(u):
        return _tensile_force(params, u - eps * w) + _bending_force(params, u)

    z = _veale_linkage_root(params, p, other_force)
    u = 2.0 * la * z * z
    return _tensile_force(params, u - eps * w)


def veale_force(pressure_pa, strain, params: VealeParameters = VEALE_TABLE2):
    """Muscle force [N] of Veale's force-balance model at pressure ``pressure_pa`` [Pa], strain [-].

    Per tube, with ``u`` the contraction of the ideal linkage (0 <= u <= 2 l_a), ``s = l_a - u/2`` and
    ``h = sqrt(l_a^2 - s^2)``:

    - linkage + bending: ``F = p A1 s/h - p A2 - k2(u) u``
    - series tensile element: ``u = eps w + delta`` with ``F = ka delta + kb delta^2``

    Interpretation (reproduces the research notes' Table 2 numbers): the tubes are in series, so every tube
    carries the muscle force F and the stretch delta is per tube under F; the muscle strain equals the tube
    strain ``(u - delta)/w`` (``l0 = n w``), so the number of tubes does not enter. At p = 0 and eps <= 0 the
    linkage is flat (u = 0) and ``F = ka (-eps w) + kb (eps w)^2``. Beyond the free strain the equations give
    a compressive (negative) force, returned as is; a slack muscle carries none, so clip if needed.

    Solved for ``u`` by bisection (optimistix) on the balance multiplied by ``h``; gradients by the implicit
    function theorem. Meant for p >= 0 and strains up to about the ideal limit 2 l_a/w (36 %); NaN where the
    balance has no root with 0 <= u <= 2 l_a (e.g. p < 0). The force is not differentiable in pressure
    at the corner p = 0, eps >= 0 (it grows like p^(2/3) there): its derivatives there are huge, not exact.
    ``pressure_pa`` and ``strain`` broadcast; returns their broadcast shape.
    """
    return _map_scalar(lambda p, e: _veale_force_scalar(params, p, e), pressure_pa, strain)


def veale_blocking_force(pressure_pa, params: VealeParameters = VEALE_TABLE2):
    """Blocking force [N]: :func:`veale_force` at zero strain. ``pressure_pa`` [Pa], any shape."""
    return veale_force(pressure_pa, 0.0, params)


def _veale_free_strain_scalar(params: VealeParameters, p):
    z = _veale_linkage_root(params, p, lambda u: _bending_force(params, u))
    return 2.0 * params.linkage_m * z * z / params.width_m


def veale_free_strain(pressure_pa, params: VealeParameters = VEALE_TABLE2):
    """Free strain [-] (force zero, so delta = 0 and eps = u/w) of Veale's model.

    Solves ``p A1 s = h (p A2 + k2(u) u)``. ``pressure_pa`` [Pa], any shape; returns the same shape. Zero at
    p = 0, where its pressure derivative is infinite.
    """
    return _map_scalar(lambda p: _veale_free_strain_scalar(params, p), pressure_pa)


# === A smooth force surface from Sarosi's Table 1 (another physics for the discovery benchmark) ============


class SurfaceParameters(eqx.Module):
    """Coefficients of the force surface :func:`surface_force` (scalars, SI; Sarosi's names in brackets).

    - ``exp_area_m2`` (a_u1) [m^2], ``stretch_force_n`` (a_u2) [N], ``exp_rate`` (a_u3) [-]: the exponential
      term ``(a1 p + a2) exp(a3 eps)``; ``a2 a3`` is the relaxed muscle's stiffness per unit strain at eps = 0
    - ``slope_area_m2`` (a_u4) [m^2] and ``area_m2`` (a_u5) [m^2]: the pressure term ``(a4 eps + a5) p``
    """

    exp_area_m2: jax.Array = eqx.field(converter=_as_float_array)
    stretch_force_n: jax.Array = eqx.field(converter=_as_float_array)
    exp_rate: jax.Array = eqx.field(converter=_as_float_array)
    slope_area_m2: jax.Array = eqx.field(converter=_as_float_array)
    area_m2: jax.Array = eqx.field(converter=_as_float_array)


#: Table 1's upper (loading) branch, the branch Sarosi's dynamic model drives the load with (a_u6 cancels).
SURFACE_TABLE1 = SurfaceParameters(
    exp_area_m2=8.6607e-5, stretch_force_n=36.9905, exp_rate=-42.7436, slope_area_m2=-3.2994e-3, area_m2=4.656e-4
)
#: Strain bracket [-] of :func:`surface_strain_at_force` and its halvings (0.6 in strain to below 1e-18).
_SURFACE_BRACKET = (-0.3, 0.3)
_SURFACE_BISECTIONS = 64


def _surface(params: SurfaceParameters, p, eps):
    decay = jnp.expm1(params.exp_rate * eps)  # exp(a3 eps) - 1, exact near eps = 0
    pressure_term = params.exp_area_m2 * (decay + 1.0) + params.slope_area_m2 * eps + params.area_m2
    return p * pressure_term + params.stretch_force_n * decay


def _surface_slope(params: SurfaceParameters, p, eps):
    """``dF/d eps`` [N per unit strain]: negative for p >= 0."""
    return (
        params.exp_rate * (params.exp_area_m2 * p + params.stretch_force_n) * jnp.exp(params.exp_rate * eps)
        + params.slope_area_m2 * p
    )


def surface_force(pressure_pa, strain, params: SurfaceParameters = SURFACE_TABLE1):
    """Muscle force [N] of the Sarosi-type surface at pressure ``pressure_pa`` [Pa] and strain [-]:

    ``F(p, eps) = F_u(p, eps) - F_u(0, 0) = p (a1 exp(a3 eps) + a4 eps + a5) + a2 (exp(a3 eps) - 1)``

    Sarosi's upper branch (eq. 4, Table 1) less its force at zero pressure and zero strain (a2 + a6 = 37.25 N,
    the 0 kPa error the paper reports for that fit), so that the relaxed, unstretched muscle carries no force:
    ``F(0, 0) = 0``. With Table 1's signs (a3, a4 < 0; a1, a2, a5 > 0) and ``p >= 0``:

    - ``F`` falls with strain everywhere (``dF/deps = a3 (a1 p + a2) exp(a3 eps) + a4 p < 0``), so each pressure
      has one free strain (:func:`surface_free_strain`), 0 at ``p = 0``;
    - ``F`` grows with pressure where ``a1 exp(a3 eps) + a4 eps + a5 > 0``, i.e. below a strain of about
      ``a5 / |a4|`` = 14.1 %; the free strain stays below it (8.7 % at 200 kPa, 11.8 % at 500 kPa);
    - at ``p = 0`` a stretched muscle (eps < 0) carries ``a2 (exp(a3 eps) - 1)`` (33 N at -1.5 %); for eps > 0
      the formula gives a compression, which a slack muscle cannot carry and no rig test reaches.

    Not peano_bayes' model (no linkage, no series or parallel elements): an empirical surface, smooth and
    explicit. ``pressure_pa`` and ``strain`` broadcast; returns their broadcast shape.
    """
    return _surface(params, _as_float_array(pressure_pa), _as_float_array(strain))


def surface_strain_at_force(pressure_pa, force_n, params: SurfaceParameters = SURFACE_TABLE1):
    """Strain [-] at which the surface carries ``force_n`` [N] at ``pressure_pa`` [Pa] (broadcast; returns their
    broadcast shape): the one root of the decreasing ``F(p, .) = force``.

    Bisection on eps in [-0.3, 0.3], which brackets every root with ``p >= 0`` and ``force_n`` from 0 to about
    1e7 N, then one Newton step from the bisected root with the root held fixed, which gives the implicit
    derivative ``-(dF/dtheta) / (dF/deps)`` to parameters and inputs and leaves the value at round-off.
    """
    p, target = jnp.broadcast_arrays(_as_float_array(pressure_pa), _as_float_array(force_n))

    def halve(_, bracket):
        low, high = bracket
        mid = 0.5 * (low + high)
        above = _surface(params, p, mid) > target
        return jnp.where(above, mid, low), jnp.where(above, high, mid)

    start = (jnp.full(p.shape, _SURFACE_BRACKET[0]), jnp.full(p.shape, _SURFACE_BRACKET[1]))
    low, high = jax.lax.fori_loop(0, _SURFACE_BISECTIONS, halve, start)
    root = jax.lax.stop_gradient(0.5 * (low + high))
    return root - (_surface(params, p, root) - target) / _surface_slope(params, p, root)


def surface_free_strain(pressure_pa, params: SurfaceParameters = SURFACE_TABLE1):
    """Free strain [-] of the surface (force zero) at ``pressure_pa`` [Pa], any shape; 0 at p = 0."""
    return surface_strain_at_force(pressure_pa, 0.0, params)


class SurfaceStepResult(NamedTuple):
    """Response of :func:`simulate_surface_step` on the input time grid, shape (n,) each."""

    strain: jax.Array  #: contraction strain eps [-]
    velocity: jax.Array  #: load velocity dy/dt = l0 d eps/dt [m/s], positive while contracting


def simulate_surface_step(
    time_s,
    pressure_pa,
    load_n,
    params: SurfaceParameters = SURFACE_TABLE1,
    damping_ratio=0.17,
    l0_m=0.06,
    substeps: int = 8,
) -> SurfaceStepResult:
    """The surface lifting a hanging load: ``m y'' = F(p, eps) - m g - B y'``, ``y = l0 eps``, ``m = load / g``,
    with Sarosi's damping ``B = 2 zeta sqrt(|k| m)``, ``k = (dF/deps) / l0`` (eq. 6 with the true derivative,
    evaluated at the current state) and a constant damping ratio ``zeta = damping_ratio`` [-].

    ``time_s`` [s], shape (n,), strictly increasing; ``pressure_pa`` [Pa], shape (n,), the muscle pressure
    sampled on it and taken as linear in time between samples; ``load_n`` [N] the hanging weight; ``l0_m`` [m]
    the flat length. The muscle starts at rest in static equilibrium at the first pressure,
    ``F(p_0, eps_0) = load``, and settles where ``F(p, eps) = load``. Classical RK4 with ``substeps`` (static
    int) equal steps per sample interval inside ``lax.scan``; at the rig's 250 Hz and 8 substeps (0.5 ms) the
    stiffest state the rig reaches (about 1e5 N/m on 4 kg, omega h = 0.08) is far inside RK4's stability.
    """
    t = _as_float_array(time_s)
    p = _as_float_array(pressure_pa)
    load = _as_float_array(load_n)
    if t.ndim != 1 or p.shape != t.shape or t.shape[0] < 2:
        raise ValueError("time_s and pressure_pa must both have shape (n,), n >= 2")
    gain = GRAVITY_M_PER_S2 / (load * l0_m)  # 1/(m l0) [1/(kg m)]
    zeta = _as_float_array(damping_ratio)

    def rhs(state, pressure):
        eps, rate = state
        spring = (_surface(params, pressure, eps) - load) * gain
        damping = 2.0 * zeta * jnp.sqrt(jnp.abs(_surface_slope(params, pressure, eps)) * gain) * rate
        return jnp.stack([rate, spring - damping])

    def interval(state, xs):
        p0, p1, dt = xs
        h = dt / substeps

        def substep(j, y):
            f0, f1 = j / substeps, (j + 1) / substeps
            pa, pm, pb = (p0 + f * (p1 - p0) for f in (f0, 0.5 * (f0 + f1), f1))
            k1 = rhs(y, pa)
            k2 = rhs(y + 0.5 * h * k1, pm)
            k3 = rhs(y + 0.5 * h * k2, pm)
            k4 = rhs(y + h * k3, pb)
            return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

        new = jax.lax.fori_loop(0, substeps, substep, state)
        return new, new

    eps0 = surface_strain_at_force(p[0], load, params)
    y0 = jnp.stack([eps0, jnp.zeros_like(eps0)])
    _, ys = jax.lax.scan(interval, y0, (p[:-1], p[1:], t[1:] - t[:-1]))
    ys = jnp.concatenate([y0[None, :], ys], axis=0)
    return SurfaceStepResult(strain=ys[:, 0], velocity=l0_m * ys[:, 1])
