"""The settings of a fit that the command line shows in its help, kept free of JAX so ``--help`` is instant.

:func:`peano_bayes.app.pipeline.infer` and :func:`peano_bayes.inference.sample.sample` take their defaults from here.
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
#: Posterior draws that metrics, ranking and recommendation read by default, spread evenly over every ensemble's
#: walkers: a probability near 0.9 read off them carries a Monte Carlo standard error of about 0.01 (0.03 at 100
#: draws, enough to move a verdict across its threshold).
DEFAULT_DRAWS = 1000
#: Least-squares starts (one vmapped Levenberg-Marquardt solve from each).
DEFAULT_STARTS = 16
#: Whether a fit samples the three shape constants of
#: :data:`peano_bayes.inference.posterior.DEFAULT_HELD` (``--sample-all``, the default) or holds them at nominal
#: (``--no-sample-all``). Held, a fit is cheaper but exact only for a muscle whose constants are nominal (the
#: bundled data were made so): on virtual muscles whose constants were drawn from their priors, holding them put
#: 9 of 93 population values inside their 94 % intervals and sampling them 107 of 114, for about 1.2 times the
#: steps (docs/validation.md, recovery with the constants sampled).
DEFAULT_SAMPLE_ALL = True
#: Independently started emcee ensembles per fit; R-hat compares them (at least 4, see
#: :data:`peano_bayes.inference.sample.MIN_ENSEMBLES`).
DEFAULT_ENSEMBLES = 4
#: Most sampler steps between saved states and convergence checks (each chunk is planned from the last check).
DEFAULT_CHUNK = 500
#: Warm-up steps (discarded) that fit the sampler's proposal: ``None`` lets the warm-up run until its proposal
#: is stable (:func:`peano_bayes.inference.sample.adapt`), at most :data:`DEFAULT_MAX_WARMUP` steps; a number
#: fixes it.
DEFAULT_WARMUP = None
#: Longest adaptive warm-up [steps]; a run that reaches it samples with the last proposal and says so.
DEFAULT_MAX_WARMUP = 3600
#: How a fit samples the specimen contrasts (``--contrasts``): ``auto`` samples those the data pin little as
#: multiples of the between-specimen spread (:func:`peano_bayes.inference.coordinates.choose_noncentred`),
#: ``centred`` none, ``noncentred`` all of them (:func:`peano_bayes.inference.coordinates.contrast_flags`).
CONTRAST_CHOICES = ("auto", "centred", "noncentred")
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
