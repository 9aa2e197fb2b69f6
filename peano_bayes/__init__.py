"""peano_bayes: Bayesian material-property inference workbench for Peano fluidic muscles.

Importing the package enables float64 in JAX (the physics spans coefficients from 1e-9 to 1e15).
"""

import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path:
    """Keep JAX's compiled programs on disk (default ``$PEANO_BAYES_CACHE`` or ``~/.cache/peano_bayes/jax``), so
    a second run of a command skips most of the compilation (minutes for the discovery model). The command
    line and the experiments call this; a library user opts in."""
    directory = Path(directory or os.environ.get("PEANO_BAYES_CACHE") or Path.home() / ".cache" / "peano_bayes" / "jax")
    directory.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    return directory


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
    "enable_compilation_cache",
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
