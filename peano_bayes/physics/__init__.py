"""Physics of the Peano muscle: pure JAX, no probability, no files.

``pouch`` (ideal contractile unit) and ``elements`` (bending, tensile, extension, viscoelastic, friction) compose
into a muscle in ``model``; ``simulate`` runs the paper's four rig tests; ``reference`` holds the paper's two
reference models (Sarosi, Veale). Reading the paper's Table 3 metrics off signals is analysis, not physics
(:mod:`peano_bayes.analysis.readouts`).
"""

from .. import jax_config  # noqa: F401  (float64 before any JAX array is made; see peano_bayes.jax_config)
from . import elements, pouch, reference, simulate
from .geometry import PAPER_GEOMETRY, VALIDATION_GEOMETRY, Geometry, scale_parameters
from .model import (
    DEFAULT_CONFIG,
    ELASTIC_CONFIG,
    PAPER_PROPOSED_CONFIG,
    PARAMETERS,
    ModelConfig,
)
from .simulate import *  # noqa: F403  (the four rig tests' inputs, results and simulations: simulate.__all__)

__all__ = [
    "DEFAULT_CONFIG",
    "ELASTIC_CONFIG",
    "PAPER_PROPOSED_CONFIG",
    "PARAMETERS",
    "PAPER_GEOMETRY",
    "VALIDATION_GEOMETRY",
    "Geometry",
    "ModelConfig",
    "elements",
    "pouch",
    "reference",
    "scale_parameters",
    *simulate.__all__,
]
