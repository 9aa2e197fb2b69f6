"""Inference benchmark: minimum bulk ESS per second of our sampler against (a) the same emcee run with a
per-walker plain-NumPy log posterior and (b) NumPyro NUTS (dense mass) on the same JAX log density.

The density: virtual-rig load cycles of TP (one specimen, one repeat: 0 kPa and the test pressure), the
likelihood of ``peano_bayes.inference`` (denoised inputs, bins of 4 with two-point quadrature), free
parameters ``tensile_ka_n_per_m``, ``bending_k1_n``, ``friction_pressure_fraction`` and the noise scale, the
rest at the truth. All three samplers start from the same posterior mode (least squares polished by BFGS,
``peano_bayes.inference.laplace``).

- **ours**: emcee, ``vectorize=True`` with the jit+vmap log posterior, warm-up rounds that fit an independence
  proposal, then DE + snooker + independence moves to the convergence gates (``peano_bayes.inference.sample``);
  its wall time includes the warm-up.
- **(a) NumPy emcee**: the same sampler, final move mix and seed with a per-walker log posterior whose physics is
  ``numpy_load_cycle.py`` (the NumPy twin of our solver, checked equal first). Same algorithm on the same
  density gives the same chain statistics, so its ESS per step is taken from ours and only its time per step
  is measured (over ``--numpy-steps`` steps; a full run would take hours). ESS/s ratio = time-per-step ratio.
- **(b) NUTS**: numpyro, dense mass matrix, ``--nuts-warmup`` + ``--nuts-samples`` draws from the same JAX
  log density; its bulk ESS from arviz; time with and without compilation.

    python experiments/bench_inference.py [--numpy-steps 20] [--nuts-warmup 500] [--nuts-samples 1000]

The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import arviz as az
import emcee
import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy_load_cycle  # noqa: E402

from peano_bayes.inference import build_posterior, prepare, prior_for, sample  # noqa: E402
from peano_bayes.inference.laplace import posterior_mode  # noqa: E402
from peano_bayes.inference.likelihood import OBSERVED  # noqa: E402
from peano_bayes.inference.sample import moves_for, proposal_at  # noqa: E402
from peano_bayes.physics import DEFAULT_CONFIG  # noqa: E402
from peano_bayes.pipeline import least_squares, walker_start  # noqa: E402
from peano_bayes.rig import RigNoise, simulate_dataset  # noqa: E402

FREE = ("tensile_ka_n_per_m", "bending_k1_n", "friction_pressure_fraction")
TRUTH = dict(DEFAULT_CONFIG.nominal_parameters(), tensile_ka_n_per_m=8e3, bending_k1_n=1.0)
WALKERS = 16
SEED = 2


def build():
    data = simulate_dataset(
        "TP", TRUTH, seed=31, specimens=1, repeats=1, specimen_spread=0.0, tests=("load_cycle",), noise=RigNoise()
    )
    prior = prior_for("TP")
    fixed = {k: v for k, v in TRUTH.items() if k not in FREE}
    return build_posterior(prepare(data), prior, config=DEFAULT_CONFIG, fixed=fixed), prior


def numpy_log_posterior(posterior):
    """Per-walker log posterior with the physics in NumPy (the prior term, a few ns of arithmetic, is the
    same jitted JAX function on both sides)."""
    group = posterior.observations.groups[0]
    observed, counts = group.observed, group.counts
    log_prior = jax.jit(posterior.log_prior)
    noise_name = OBSERVED[group.test][1]
    geometry = posterior.observations.geometry
    geo = (geometry.n_tubes, geometry.tube_width_m, geometry.tube_length_m)
    u, m = group.bin_time_s.shape

    def logp(theta):
        lp = float(log_prior(theta))
        if not np.isfinite(lp):
            return -np.inf
        params = {k: float(v) for k, v in posterior.params(theta).items() if np.ndim(v) == 0}
        batch = {k: np.array([v]) for k, v in params.items() if k in DEFAULT_CONFIG.parameter_names()}
        total = 0.0
        for row in range(u):
            force = numpy_load_cycle.simulate_load_cycle(batch, group.strain[row], group.pressure_pa[row], geo)[0]
            predicted = force.reshape(m, group.points_per_bin).mean(axis=1)
            for r in np.flatnonzero(group.shared == row):
                scale = params[noise_name] / np.sqrt(np.maximum(counts[r], 1.0))
                resid = (observed[r] - predicted) / scale
                ok = np.isfinite(resid)
                total += float(np.sum(-0.5 * resid[ok] ** 2 - np.log(scale[ok]) - 0.5 * np.log(2 * np.pi)))
        return lp + total if np.isfinite(total) else -np.inf

    return logp


def min_ess(draws: np.ndarray) -> float:
    """Minimum bulk ESS over parameters of draws (chains, draws, D)."""
    data = az.convert_to_dataset({f"p{i}": draws[..., i] for i in range(draws.shape[-1])})
    return float(min(float(az.ess(data, method="bulk")[k]) for k in data.data_vars))


def run_nuts(posterior, centre, warmup: int, samples: int):
    from numpyro.infer import MCMC, NUTS

    potential = jax.jit(lambda theta: -posterior.log_prob(theta))
    kernel = NUTS(potential_fn=potential, dense_mass=True)
    mcmc = MCMC(kernel, num_warmup=warmup, num_samples=samples, num_chains=1, progress_bar=False)
    t0 = time.perf_counter()
    mcmc.run(jax.random.PRNGKey(SEED), init_params=jnp.asarray(centre), extra_fields=("num_steps",))
    total = time.perf_counter() - t0
    draws = np.asarray(mcmc.get_samples())[None]
    # Second run on the compiled kernel: the time without compilation.
    t0 = time.perf_counter()
    mcmc.run(jax.random.PRNGKey(SEED + 1), init_params=jnp.asarray(centre), extra_fields=("num_steps",))
    warm = time.perf_counter() - t0
    draws2 = np.asarray(mcmc.get_samples())[None]
    steps = float(np.mean(np.asarray(mcmc.get_extra_fields()["num_steps"])))
    return {
        "seconds_with_compile": total,
        "seconds": warm,
        "min_ess": min(min_ess(draws), min_ess(draws2)),
        "mean_leapfrog_steps": steps,
        "means": draws2[0].mean(axis=0).tolist(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--numpy-steps", type=int, default=20)
    parser.add_argument("--nuts-warmup", type=int, default=500)
    parser.add_argument("--nuts-samples", type=int, default=1000)
    args = parser.parse_args()

    posterior, prior = build()
    fitted = least_squares(posterior, prior, n_starts=8, seed=0)
    centre, covariance = walker_start(posterior, fitted)
    laplace = posterior_mode(posterior, centre, covariance)
    centre, covariance = laplace.mode, laplace.covariance
    warmup = 300

    # Ours: compile once (both batch sizes), then the full run to the gates.
    t0 = time.perf_counter()
    posterior.batched(np.tile(centre, (WALKERS, 1)))
    posterior.batched(np.tile(centre, (WALKERS // 2, 1)))
    compile_s = time.perf_counter() - t0
    ours = sample(posterior, centre, covariance, n_walkers=WALKERS, seed=SEED, chunk=500, max_steps=20_000,
                  warmup=warmup, progress=False, log=lambda m: None)
    steps = ours.chain.shape[0]
    ours_ess = float(np.min(ours.convergence.ess_bulk))
    ours_rate = ours_ess / ours.seconds

    # (a) NumPy emcee: check the density, then time steps of the same sampler.
    logp_np = numpy_log_posterior(posterior)
    probe = ours.chain[-1]
    ours_lp = posterior.batched(probe)
    np_lp = np.array([logp_np(t) for t in probe])
    agreement = float(np.max(np.abs(np_lp - ours_lp)))
    moves = moves_for(proposal_at(ours.chain, steps, warmup))  # the mix our run sampled with after its warm-up
    sampler = emcee.EnsembleSampler(WALKERS, posterior.ndim, logp_np, moves=moves)
    sampler.random_state = np.random.RandomState(SEED).get_state()  # as peano_bayes.inference.sample does
    t0 = time.perf_counter()
    sampler.run_mcmc(probe, args.numpy_steps, progress=False)
    numpy_per_step = (time.perf_counter() - t0) / args.numpy_steps
    ours_per_step = ours.seconds / steps
    numpy_rate = (ours_ess / steps) / numpy_per_step

    # (b) NUTS on the same JAX density.
    nuts = run_nuts(posterior, centre, args.nuts_warmup, args.nuts_samples)
    nuts_rate = nuts["min_ess"] / nuts["seconds"]

    print(f"machine: {platform.processor() or platform.machine()}, jax {jax.__version__}, emcee {emcee.__version__}")
    n_bins = posterior.observations.n_bins
    print(f"density: {posterior.ndim} parameters, {n_bins} bins; NumPy agrees to {agreement:.2e}")
    print(f"{'sampler':<34} {'wall [s]':>10} {'min bulk ESS':>13} {'ESS/s':>10}")
    print(f"{'ours: emcee + jit/vmap':<34} {ours.seconds:10.1f} {ours_ess:13.0f} {ours_rate:10.2f}"
          f"   ({steps} steps, converged={ours.convergence.converged}, compile {compile_s:.1f} s apart)")
    print(f"{'(a) emcee + NumPy per walker':<34} {numpy_per_step * steps:10.1f} {ours_ess:13.0f} {numpy_rate:10.2f}"
          f"   ({numpy_per_step * 1e3:.0f} ms/step against our {ours_per_step * 1e3:.1f})")
    print(f"{'(b) NUTS dense (numpyro)':<34} {nuts['seconds']:10.1f} {nuts['min_ess']:13.0f} {nuts_rate:10.2f}"
          f"   ({nuts['mean_leapfrog_steps']:.1f} leapfrog/draw, {nuts['seconds_with_compile']:.1f} s with compile)")
    print(json.dumps({
        "ours_ess_per_s": ours_rate,
        "numpy_emcee_ess_per_s": numpy_rate,
        "nuts_ess_per_s": nuts_rate,
        "ratio_vs_numpy": ours_rate / numpy_rate,
        "ratio_vs_nuts": ours_rate / nuts_rate,
        "ours_seconds": ours.seconds,
        "ours_steps": steps,
        "ours_converged": bool(ours.convergence.converged),
        "compile_s": compile_s,
        "numpy_ms_per_step": numpy_per_step * 1e3,
        "ours_ms_per_step": ours_per_step * 1e3,
        "numpy_logp_max_abs_diff": agreement,
        "nuts": nuts,
    }))


if __name__ == "__main__":
    main()
