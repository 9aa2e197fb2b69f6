"""peano_bayes: Bayesian material-property inference workbench for Peano fluidic muscles.

Importing the package enables float64 in JAX (the physics spans coefficients from 1e-9 to 1e15).
"""

import jax

jax.config.update("jax_enable_x64", True)

from .physics import (  # noqa: E402
    DEFAULT_CONFIG,
    PAPER_GEOMETRY,
    PAPER_PROPOSED_CONFIG,
    Blocking,
    Geometry,
    LoadCycle,
    ModelConfig,
    Step,
    Stroke,
    simulate_blocking,
    simulate_load_cycle,
    simulate_step,
    simulate_stroke,
    static_strain,
)

__version__ = "0.1.0"
__all__ = [
    "DEFAULT_CONFIG",
    "PAPER_GEOMETRY",
    "PAPER_PROPOSED_CONFIG",
    "Blocking",
    "Geometry",
    "LoadCycle",
    "ModelConfig",
    "Step",
    "Stroke",
    "simulate_blocking",
    "simulate_load_cycle",
    "simulate_step",
    "simulate_stroke",
    "static_strain",
]
