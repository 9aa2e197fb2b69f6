"""Shared test set-up: float64 JAX (enabled by importing the package) and small helpers."""

import os
import warnings

import numpy as np
import pytest
from hypothesis import settings

from peano_bayes.app.fanout import cap_threads, xla_flags_with

# One compute thread per process, set before JAX starts its backend: the suite runs as two xdist workers on two
# cores, and the Dask workers, notebook kernels and command-line subprocesses that tests start inherit the same
# XLA flags, which JAX's persistent cache keys on, so they read the programs this process compiled.
#
# Compiling is most of the suite's time, and LLVM's optimization most of compiling; the sampling tests also run
# their programs thousands of times. XLA's backend optimization level 1 is the balance: level 0 compiles faster
# and runs slower, so it loses on the sampling tests what it gains on the large programs (figures:
# docs/validation.md, Known shortfalls). XLA's CPU fast-math is off, so the level changes results by round-off
# only (tests/test_rig.py saw 1 ulp); the main job, the studies and the benchmarks compile at the default level.
SUITE_XLA_FLAGS = "--xla_backend_optimization_level=1"
os.environ["XLA_FLAGS"] = xla_flags_with(SUITE_XLA_FLAGS)
cap_threads()

from peano_bayes.jax_config import enable_compilation_cache  # noqa: E402  (also float64 for every test)

# One persistent compilation cache for the session, both xdist workers and the command-line subprocesses
# (they read the same place): a program that several tests, workers or processes build identically compiles
# once. The package's own place ($PEANO_BAYES_CACHE, else ~/.cache/peano_bayes/jax); point
# PEANO_BAYES_CACHE at an empty directory to measure the suite cold.
enable_compilation_cache()

# Fixed examples: the same cases on every machine and every run (no example database needed).
settings.register_profile("deterministic", derandomize=True, database=None)
settings.load_profile("deterministic")

warnings.filterwarnings("ignore", category=FutureWarning, module="arviz")

# arviz 0.23 writes a daily stamp file through one fixed temporary name on its first import of the day: two
# xdist workers importing it at once race and one dies (FileNotFoundError). The controller loads this file
# before it starts the workers, so importing arviz here settles the stamp first.
import arviz  # noqa: E402, F401


@pytest.fixture
def rng():
    return np.random.default_rng(20161105)


@pytest.fixture(scope="session")
def recovered():
    """One fit + sample on virtual-rig TP load cycles with known truth (the slow part of the suite; shared by
    the recovery and the metrics tests): ``(posterior, result, draws, truth, fitted)``."""
    from peano_bayes.inference import build_posterior, prepare, prior_for, sample
    from peano_bayes.inference.driver import least_squares, walker_start
    from peano_bayes.inference.results import physical_draws
    from peano_bayes.physics import DEFAULT_CONFIG
    from peano_bayes.rig import RigNoise, simulate_dataset

    from .helpers import RECOVERY_FREE, recovery_truth

    truth = recovery_truth()
    data = simulate_dataset(
        "TP", truth, seed=31, specimens=1, repeats=1, specimen_spread=0.0, tests=("load_cycle",), noise=RigNoise()
    )
    prior = prior_for("TP")
    fixed = {k: v for k, v in truth.items() if k not in RECOVERY_FREE}
    posterior = build_posterior(prepare(data), prior, config=DEFAULT_CONFIG, fixed=fixed)
    assert set(posterior.names) == {*RECOVERY_FREE, "noise_load_cycle_force_n"}
    fitted = least_squares(posterior, prior, n_starts=8, seed=0)
    centre, covariance = walker_start(posterior, fitted)
    result = sample(
        posterior,
        centre,
        covariance,
        n_walkers=8,  # per ensemble: four ensembles of eight, 2 x the dimension each
        seed=2,
        # tau is about 4 steps here: a fixed 150-step warm-up (refits at 100 and 150) is enough, and the suite's
        # time is short of room; the adaptive warm-up is tested in test_sample.py
        warmup=150,
        chunk=250,
        max_steps=6000,
        progress=False,
        log=lambda m: None,
    )
    truth = {**truth, "noise_load_cycle_force_n": RigNoise().force_sd_n}
    return posterior, result, physical_draws(posterior, result.kept()), truth, fitted


@pytest.fixture(scope="session")
def result_dir(recovered, tmp_path_factory):
    """The :func:`recovered` fit written as a result directory (``posterior.nc`` of material TP)."""
    from peano_bayes.inference.results import to_inference_data

    posterior, result, _, _, _ = recovered
    idata = to_inference_data(posterior, result, seed=2, attrs={"material": "TP", "dataset": "virtual"})
    out = tmp_path_factory.mktemp("result")
    idata.to_netcdf(str(out / "posterior.nc"))
    return out

