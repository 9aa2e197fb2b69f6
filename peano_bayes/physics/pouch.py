"""Ideal Peano contractile unit (Niiyama et al. 2015, virtual work).

Each tube wall is a circular arc of flat width ``w`` and half-angle ``theta`` in (0, pi/2].
All functions are pure JAX, element-wise, and exact (with Taylor series) near ``theta -> 0``,
where the closed forms are 0/0.

Per tube, with flat width ``w`` [m] and effective length ``l_e`` [m]:

- contraction   ``x = w (1 - sin(theta)/theta)``                [m]
- volume        ``V = w^2 l_e (theta - sin cos)/(2 theta^2)``   [m^3]
- force         ``F = p w l_e cos(theta)/theta``                 [N]   (virtual work, F = p dV/dx)
"""

from __future__ import annotations

import jax.numpy as jnp

#: Below this half-angle [rad] the series expansions are used (their error is < 1e-16 there).
_SMALL = 1e-2

IDEAL_FREE_STRAIN = 1.0 - 2.0 / jnp.pi  # strain at theta = pi/2 (F = 0), 0.3634


def _where_small(theta, series, exact):
    """Select ``series(theta**2)`` below ``_SMALL`` and ``exact(theta)`` above, NaN-safe for gradients.

    The series take ``t2 = theta**2`` and are written in Horner form: inside ``jit`` the half-angle is often
    ``exp(log theta)``, and XLA rewrites every power ``theta**k`` of it as a separate ``exp(k log theta)``.
    """
    small = theta < _SMALL
    safe = jnp.where(small, _SMALL, theta)  # keeps the unused branch finite under autodiff
    return jnp.where(small, series(theta * theta), exact(safe))


def sinc(theta):
    """sin(theta)/theta [-]."""
    return _where_small(
        theta, lambda t2: 1.0 - t2 * (1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 / 5040.0)), lambda t: jnp.sin(t) / t
    )


def strain(theta):
    """Contraction strain of one ideal tube, 1 - sin(theta)/theta [-]."""
    return _where_small(
        theta,
        lambda t2: t2 * (1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 * (1.0 / 5040.0 - t2 / 362880.0))),
        lambda t: 1.0 - jnp.sin(t) / t,
    )


def dstrain_dtheta(theta):
    """d(strain)/d(theta) = (sin - theta cos)/theta^2 [1/rad]."""
    return theta * _sin_minus_tcos_over_t3(theta)


def _sin_minus_tcos_over_t3(theta):
    """(sin(theta) - theta cos(theta))/theta^3, -> 1/3 at theta = 0."""
    return _where_small(
        theta,
        lambda t2: 1.0 / 3.0 - t2 * (1.0 / 30.0 - t2 * (1.0 / 840.0 - t2 / 45360.0)),
        lambda t: (jnp.sin(t) - t * jnp.cos(t)) / (t * t * t),
    )


def force_per_pressure(theta, width_m, length_m):
    """Tube force per unit pressure, w l cos(theta)/theta [N/Pa]; diverges as theta -> 0."""
    cos_over = _where_small(
        theta,
        lambda t2: (1.0 - t2 * (0.5 - t2 * (1.0 / 24.0 - t2 / 720.0))) / theta,
        lambda t: jnp.cos(t) / t,  # shares cos(t) with the other closed forms
    )
    return width_m * length_m * cos_over


def volume_factor(theta):
    """V/(w^2 l) = (theta - sin cos)/(2 theta^2) [-]; 0 at theta = 0, 1/pi at pi/2."""
    return _where_small(
        theta,
        lambda t2: theta * (1.0 / 3.0 - t2 * (1.0 / 15.0 - t2 * 2.0 / 315.0)),
        lambda t: (t - jnp.sin(t) * jnp.cos(t)) / (2.0 * t * t),
    )


def dvolume_factor_dtheta(theta):
    """d(V/(w^2 l))/d(theta) = cos(theta)(sin - theta cos)/theta^3 [1/rad]."""
    return jnp.cos(theta) * _sin_minus_tcos_over_t3(theta)
