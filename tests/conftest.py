"""Shared test set-up: float64 JAX (enabled by importing the package) and small helpers."""

import warnings

import numpy as np
import pytest
from hypothesis import settings

import peano_bayes  # noqa: F401  (enables jax_enable_x64)

# Fixed examples: the same cases on every machine and every run (no example database needed).
settings.register_profile("deterministic", derandomize=True, database=None)
settings.load_profile("deterministic")

warnings.filterwarnings("ignore", category=FutureWarning, module="arviz")


@pytest.fixture
def rng():
    return np.random.default_rng(20161105)
