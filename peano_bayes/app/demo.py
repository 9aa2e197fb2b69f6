"""Forward-model demo: blocking force and free strain of a default four-tube muscle at several pressures."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..physics import DEFAULT_CONFIG, PAPER_GEOMETRY, Blocking, ModelConfig, simulate_blocking, static_strain


def blocking_and_free_strain(
    pressures_kpa, *, config: ModelConfig = DEFAULT_CONFIG, params=None, geometry=PAPER_GEOMETRY
):
    """Blocking force [N] and free strain [-] at each pressure [kPa], nominal parameters unless given.

    Blocking: the muscle held at zero strain along a 0 -> p ramp; free strain: equilibrium strain at zero force.
    Returns a list of dicts with ``pressure_kpa``, ``blocking_force_n``, ``free_strain``.
    """
    params = {k: jnp.asarray(v) for k, v in (params or config.nominal_parameters()).items()}
    ramp = jnp.linspace(0.0, 1.0, 101)

    @jax.jit
    def one(p_pa):
        force = simulate_blocking(
            params, Blocking(10.0 * ramp, p_pa * ramp), config=config, geometry=geometry
        )
        return force.force_n[-1], static_strain(params, p_pa, 0.0, config=config, geometry=geometry)

    rows = []
    for p_kpa in pressures_kpa:
        force, eps = one(jnp.asarray(1e3 * float(p_kpa)))
        rows.append(
            {"pressure_kpa": float(p_kpa), "blocking_force_n": float(force), "free_strain": float(eps)}
        )
    return rows
