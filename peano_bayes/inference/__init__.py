"""Inference: priors as data (``priors/*.toml``), the likelihood of rig data, the posterior, multi-start least
squares, resumable emcee sampling and arviz results."""

from .. import jax_config  # noqa: F401  (float64 before any JAX array is made; see peano_bayes.jax_config)
from .fit import DEFAULT_NOISE, FitResult, fit, fit_quality
from .likelihood import SOLVER_TOLERANCE, log_likelihood, pointwise_log_likelihood, predict
from .posterior import Posterior, build_posterior
from .prior_files import DEFAULT_PRIORS_DIR, load_prior, parse_entry, prior_files, prior_for
from .priors import ALL_PARAMETERS, LIKELIHOOD_PARAMETERS, Marginal, Prior
from .reduce import DEFAULT_BIN_SIZES, NOISE_PARAMETERS, Observations, RunGroup, prepare
from .sample import Convergence, SampleResult, convergence, sample

__all__ = [
    "ALL_PARAMETERS",
    "Convergence",
    "Posterior",
    "SampleResult",
    "build_posterior",
    "convergence",
    "sample",
    "DEFAULT_NOISE",
    "FitResult",
    "fit",
    "fit_quality",
    "DEFAULT_BIN_SIZES",
    "DEFAULT_PRIORS_DIR",
    "LIKELIHOOD_PARAMETERS",
    "Marginal",
    "NOISE_PARAMETERS",
    "Observations",
    "Prior",
    "RunGroup",
    "SOLVER_TOLERANCE",
    "load_prior",
    "log_likelihood",
    "parse_entry",
    "pointwise_log_likelihood",
    "predict",
    "prepare",
    "prior_files",
    "prior_for",
]
