"""Constitutive elements of a Peano muscle, as pure JAX functions.

Sign conventions: forces are tensions [N] (positive pulls the load), displacements are contractions [m]
(positive shortens the muscle). Parallel elements act on the contraction ``X`` [m] of the contractile unit
(all tubes, muscle level) and return a force; series elements take the force and return a stretch [m].
Stateful elements use exact updates for inputs that vary linearly within a time step, so they are
unconditionally stable inside ``lax.scan``.
"""

from __future__ import annotations

import jax.numpy as jnp

from . import pouch


def bending_force(theta, k1_n, k2_n, exponent, width_m, length_m):
    """Bending resistance of the tube walls [N], energy based and stiffening.

    Bending energy per tube ``U = l (k1 theta^2/2 + k2 theta^(m+2)/(m+2))`` [J] with ``k1_n``, ``k2_n`` [N]
    effective stiffnesses and ``exponent`` m [-]; the force is ``dU/dx``. It is finite at ``theta -> 0``
    (``3 k1 l/w``) and lowers the force at every strain, the free strain most at low pressure.
    """
    stiffness = k1_n + k2_n * jnp.exp(exponent * jnp.log(theta))
    return (length_m / width_m) * stiffness / pouch._sin_minus_tcos_over_t3(theta)


def tensile_stretch(force_n, ka_n_per_m, kb_n_per_m2):
    """Stretch [m] of the series tensile element ``F = ka d + kb d^2`` (stiffening with load).

    Written as ``2F/(ka + sqrt(ka^2 + 4 kb |F|))``: exact, odd in F, and well conditioned as kb -> 0.
    """
    return 2.0 * force_n / (ka_n_per_m + jnp.sqrt(ka_n_per_m**2 + 4.0 * kb_n_per_m2 * jnp.abs(force_n)))


def tensile_force(stretch_m, ka_n_per_m, kb_n_per_m2):
    """Inverse of :func:`tensile_stretch`: ``ka d + kb d |d|`` [N]."""
    return ka_n_per_m * stretch_m + kb_n_per_m2 * stretch_m * jnp.abs(stretch_m)


def smooth_positive(x, width):
    """Smooth ``max(x, 0)`` with transition ``width`` (same units as x)."""
    return width * jnp.logaddexp(x / width, 0.0)


def extension_force(strain, k_n_per_m, rate, l0_m, width=1e-4):
    """Passive extension below zero strain [N], parallel to the whole muscle, stiffening.

    ``F = k l0 (exp(rate e) - 1)/rate`` with ``e`` the (smoothed) extension ``max(-strain, 0)`` [-]:
    stiffness ``k_n_per_m`` [N/m] at zero extension, growing exponentially with ``rate`` [-] as fibres
    and polymer chains straighten. Zero for contraction (a slack muscle carries no compression). Beyond
    ``rate e = 30`` (far outside any physical stretch) the curve continues along its tangent, so that
    solvers probing absurd stretches see a large finite force instead of an overflow.
    """
    e = smooth_positive(-strain, width)
    x = rate * e
    small = jnp.abs(x) < 1e-8
    safe_rate = jnp.where(small, 1.0, rate)
    x_capped = jnp.minimum(safe_rate * e, _EXTENSION_EXP_CAP)
    exponential = (jnp.expm1(x_capped) + jnp.exp(x_capped) * (safe_rate * e - x_capped)) / safe_rate
    grow = jnp.where(small, e * (1.0 + 0.5 * x), exponential)
    return k_n_per_m * l0_m * grow


_EXTENSION_EXP_CAP = 30.0


# --- viscoelastic elements -------------------------------------------------------------------------------


def maxwell_update(q_n, dx_m, dt_s, k_n_per_m, tau_s):
    """Maxwell branch (spring k, dashpot k tau) in parallel: force [N] after a step of ``dx_m``.

    Exact for a displacement that is linear within the step:
    ``q <- exp(-dt/tau) q + k tau (1 - exp(-dt/tau)) dx/dt``. Summed over branches this is a generalized
    Maxwell (Prony) element; with an equilibrium spring alongside it is a standard linear solid (Zener).
    """
    decay = jnp.exp(-dt_s / tau_s)
    return decay * q_n - k_n_per_m * tau_s * jnp.expm1(-dt_s / tau_s) * dx_m / dt_s


def kelvin_update(d_n, f_n, f_next, dt_s, k_n_per_m, tau_s):
    """Kelvin-Voigt unit (spring k, dashpot k tau) in series: stretch [m] after the force goes f_n -> f_next.

    Exact solution of ``k tau d' + k d = F(t)`` for F linear within the step. A tensile spring in series with
    one unit is a standard linear solid in Kelvin form; add a series dashpot (:func:`creep_update`) for Burgers.
    """
    decay = jnp.exp(-dt_s / tau_s)
    slope_tau = (f_next - f_n) / dt_s * tau_s
    return (f_next - slope_tau) / k_n_per_m + (d_n - (f_n - slope_tau) / k_n_per_m) * decay


def creep_update(d_n, f_n, f_next, dt_s, c_ns_per_m):
    """Series dashpot (Burgers creep) stretch [m]: exact for F linear within the step."""
    return d_n + 0.5 * dt_s * (f_n + f_next) / c_ns_per_m


# --- rate-independent friction ---------------------------------------------------------------------------


#: Width [m] over which the Dahl element's direction of motion turns smoothly from -1 to +1.
DAHL_SMOOTHING_M = 1e-7


def dahl_update(f_n, dx_m, stiffness_n_per_m, limit_n, smoothing_m=DAHL_SMOOTHING_M):
    """Dahl friction (Bouc-Wen with n = 1): force [N] after a displacement step ``dx_m``.

    ``dF/dx = k (1 - sgn(dx) F / F_c)``, solved exactly for a monotone step:
    ``F <- s F_c - (s F_c - F) exp(-k s dx / F_c)``. For a constant limit it is rate independent (the result
    does not depend on how a path is divided into steps), gives a loop of height ~2 F_c, and is the identity when
    ``dx = 0`` (no creep). Where the limit changes along the step (friction pressed by the pressure load), the
    caller passes the mean of the step's start and end limits, which keeps the result second order in the step
    (:func:`peano_bayes.physics.model.chain`): in the bundled PC blocking test (limit 9.6 N + 0.4 x the active
    force) the force at 20 Hz is then within 0.0006 N of a converged simulation, against 0.031 N with the
    step's end limit.
    The direction ``s = tanh(dx / smoothing_m)`` is smoothed over 0.1 um: with an exact sign, the slope in
    ``dx`` jumps at every reversal, and a muscle at rest (dx at round-off level, sign flickering) has a
    derivative that depends on round-off. Steps longer than ~2 um (20 widths) are exact to double precision;
    quasi-static rig samples move the tubes by ~10 um.
    """
    s = jnp.tanh(dx_m / smoothing_m)
    limit = jnp.maximum(limit_n, 1e-12)
    target = s * limit
    return target - (target - f_n) * jnp.exp(-stiffness_n_per_m * dx_m * s / limit)


# --- pressure ---------------------------------------------------------------------------------------------


def effective_pressure(pressure_pa, threshold_pa, floor_pa):
    """Pressure [Pa] that opens the tubes: smooth ``max(p - threshold, 0)``, never below ``floor_pa``.

    The small floor keeps the flat-tube limit regular: a tube at 0 kPa under tension sits at a vanishing
    half-angle instead of an exact stop (with a 100 Pa floor its contraction is below 1e-8 m).
    """
    width = jnp.maximum(0.05 * threshold_pa, 50.0)
    return floor_pa + smooth_positive(pressure_pa - threshold_pa - floor_pa, width)
