"""peano_bayes: Bayesian material-property inference workbench for Peano fluidic muscles.

Importing ``peano_bayes`` alone is light (no JAX): the physics names below load on first use. Any part of the
package that computes with JAX switches JAX to 64-bit floats when imported (see :mod:`peano_bayes.jax_config`,
the one place the package changes JAX's global configuration, and why it must).
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"

#: Public name -> module it lives in (loaded on first access, so ``import peano_bayes`` does not import JAX).
#: Names importable from ``peano_bayes`` itself, loaded from their module on first use (JAX only then).
_PHYSICS_NAMES = (
    "DEFAULT_CONFIG PAPER_GEOMETRY PAPER_PROPOSED_CONFIG PARAMETERS Blocking Geometry LoadCycle ModelConfig Step "
    "Stroke simulate_blocking simulate_load_cycle simulate_step simulate_stroke static_force static_strain"
).split()
_LAZY = {**dict.fromkeys(_PHYSICS_NAMES, "peano_bayes.physics"), "enable_compilation_cache": "peano_bayes.jax_config"}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'peano_bayes' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
