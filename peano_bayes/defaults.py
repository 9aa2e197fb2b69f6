"""The settings of a fit that the command line shows in its help, kept free of JAX so ``--help`` is instant.

:func:`peano_bayes.pipeline.infer` and :func:`peano_bayes.inference.sample.sample` take their defaults from here.
"""

from __future__ import annotations

import os
from pathlib import Path

#: Every rig test a fit can use, in the data format's order.
ALL_TESTS = ("load_cycle", "blocking", "stroke", "step")
#: Tests fitted by default. The step response, sampled at 1 kHz and simulated through the inlet restriction,
#: costs about five times the three quasi-static tests together per evaluation (docs/validation.md, step-test
#: solve), so it is opt-in.
DEFAULT_TESTS = ("load_cycle", "blocking", "stroke")
#: Sampler steps after which a chain that has not met the convergence gates stops, marked unconverged.
DEFAULT_MAX_STEPS = 40_000
#: Least-squares starts (one vmapped Levenberg-Marquardt solve from each).
DEFAULT_STARTS = 16
#: Independently started emcee ensembles per fit; R-hat compares them (at least 4, see
#: :data:`peano_bayes.inference.sample.MIN_ENSEMBLES`).
DEFAULT_ENSEMBLES = 4
#: Sampler steps between saved states and convergence checks.
DEFAULT_CHUNK = 500
#: Warm-up steps (discarded) that fit the sampler's proposal. The sampling phase's independence proposal is
#: fitted to the warm-up's second half, 450 steps here against 150 with the former 300. From the same seed and
#: least-squares start, TP's tau_max fell 23.2 -> 9.4 steps (1619 -> 1464 steps in all) and FC's 40.4 -> 18.8
#: (2555 -> 1936). A run now lasts at least 1400 steps (warm-up plus the first chunk), so a material that
#: mixed fast with 300 (TFC's 851 steps) runs longer (docs/validation.md, *Warm-up length*).
DEFAULT_WARMUP = 900
#: What the sampler moves (:func:`peano_bayes.inference.coordinates.sampler_coordinates`): the series tensile
#: element as its log stretches at 1 and 20 N. From the same seed, 1200 steps and the former 300-step warm-up,
#: against theta itself (``experiments/coordinates_arms.py``): PR tau_max 40.4 -> 22.7 steps, min bulk ESS
#: 1082 -> 3820; FC 35.2 -> 30.0, 2490 -> 3823.
DEFAULT_COORDINATES = "tensile_stretch"
#: The sampler coordinates there are (``--coordinates``).
COORDINATE_KINDS = ("tensile_stretch", "theta")
#: Probability mass of the reported highest-density intervals (arviz's default).
HDI_PROB = 0.94
#: Highest pressure [kPa] the forward model is asked to predict at (requirements, ``--pressure-kpa``, the demo):
#: five times the paper's highest test pressure (200 kPa), far past the data any bundled prior rests on.
MAX_PRESSURE_KPA = 1000.0
#: Highest series compliance [m/N] of a mount (the data format's ``added_compliance_mm_per_n`` limit, 100 mm/N).
MAX_MOUNT_COMPLIANCE_M_PER_N = 0.1


def compilation_cache_dir() -> Path:
    """Where JAX's compiled programs are kept: ``$PEANO_BAYES_CACHE``, else ``~/.cache/peano_bayes/jax``."""
    return Path(os.environ.get("PEANO_BAYES_CACHE") or Path.home() / ".cache" / "peano_bayes" / "jax")
