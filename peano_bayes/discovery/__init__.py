"""Discrepancy workflow: find where the model and the data disagree, name the missing effect, add it, and show
the gap shrink (effect names: :data:`~peano_bayes.effects.LIBRARY`).

Data flow: a rig :class:`~peano_bayes.data.Dataset` -> :func:`discovery_data` (one specimen, binned, whole
runs split into fit and held-out, covariates) -> :func:`discover` (base fit, diagnosis, screening of the
:data:`LIBRARY`, gates) -> :func:`write_report`. :mod:`peano_bayes.validation.discovery_benchmark` validates it
on data with hidden effects.
"""

from .. import jax_config  # noqa: F401  (float64 before any JAX array is made; see peano_bayes.jax_config)
from ..effects import CONFUSABLE, LIBRARY, Effect, noise_effects, physics_effects
from .data import SplitData, discovery_data
from .model import DEFAULT_BASE, SUPERSET_CONFIG
from .report import report_markdown, write_report
from .workflow import Discovery, Gates, discover

__all__ = [
    "CONFUSABLE",
    "DEFAULT_BASE",
    "Discovery",
    "Effect",
    "Gates",
    "LIBRARY",
    "noise_effects",
    "physics_effects",
    "SUPERSET_CONFIG",
    "SplitData",
    "discover",
    "discovery_data",
    "report_markdown",
    "write_report",
]
