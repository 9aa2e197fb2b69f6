"""The one place peano_bayes changes JAX's global configuration.

Importing any part of the package that computes with JAX (``physics``, ``inference``, ``discovery``, ``rig``,
``metrics``, ...) imports this module, which switches on 64-bit floats (``jax_enable_x64``). That is
required, not a preference: the model's coefficients span about 1e-9 (compliances, m/N) to 1e15 (bending
and tensile stiffness products), and the least-squares and sampling gradients lose their meaning in float32.
It affects every JAX computation in the process, which is why it is said here and in the package docstring.

:func:`enable_compilation_cache` (opt-in; the command line and the experiments call it) keeps compiled programs
on disk, so a second run of a command skips most of the compilation.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

from .defaults import compilation_cache_dir

jax.config.update("jax_enable_x64", True)


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path:
    """Keep JAX's compiled programs in ``directory`` (default ``$PEANO_BAYES_CACHE`` or
    ``~/.cache/peano_bayes/jax``) and return it. Sets JAX's ``jax_compilation_cache_dir`` and caches every
    program, however quickly it compiled: a fit builds hundreds of programs that compile in under a second
    each (JAX's default skips those); a fresh process (a worker, a second command) reads them instead."""
    directory = Path(directory) if directory is not None else compilation_cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return directory
