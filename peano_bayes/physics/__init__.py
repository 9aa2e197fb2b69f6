"""Physics of the Peano muscle: pure JAX, no probability, no files.

``pouch`` (ideal contractile unit) and ``elements`` (bending, tensile, extension, viscoelastic, friction) compose
into a muscle in ``model``; ``simulate`` runs the paper's four rig tests; ``metrics`` measures Table 3 metrics
from signals; ``reference`` holds the paper's two reference models (Sarosi, Veale).
"""

from .. import jax_config  # noqa: F401  (float64 before any JAX array is made; see peano_bayes.jax_config)
from . import elements, metrics, pouch, reference
from .geometry import PAPER_GEOMETRY, VALIDATION_GEOMETRY, Geometry, scale_parameters
from .model import (
    DEFAULT_CONFIG,
    ELASTIC_CONFIG,
    PAPER_PROPOSED_CONFIG,
    PARAMETERS,
    ModelConfig,
)
from .simulate import (
    Blocking,
    LoadCycle,
    Step,
    Stroke,
    simulate_blocking,
    simulate_load_cycle,
    simulate_step,
    simulate_stroke,
    static_force,
    static_strain,
)

__all__ = [
    "DEFAULT_CONFIG",
    "ELASTIC_CONFIG",
    "PAPER_PROPOSED_CONFIG",
    "PARAMETERS",
    "PAPER_GEOMETRY",
    "VALIDATION_GEOMETRY",
    "Blocking",
    "Geometry",
    "LoadCycle",
    "ModelConfig",
    "Step",
    "Stroke",
    "elements",
    "metrics",
    "pouch",
    "reference",
    "scale_parameters",
    "simulate_blocking",
    "simulate_load_cycle",
    "simulate_step",
    "simulate_stroke",
    "static_force",
    "static_strain",
]
