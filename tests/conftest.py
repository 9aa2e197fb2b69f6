"""Shared test set-up: float64 JAX (enabled by importing the package) and small helpers."""

import warnings

import numpy as np
import pytest

import peano_bayes  # noqa: F401  (enables jax_enable_x64)

warnings.filterwarnings("ignore", category=FutureWarning, module="arviz")


@pytest.fixture
def rng():
    return np.random.default_rng(20161105)
