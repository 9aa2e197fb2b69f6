"""Inference benchmark on the full hierarchical posterior of one bundled material: minimum bulk ESS per second of
our sampler against (a) emcee with a plain-NumPy log posterior and (b) NumPyro NUTS (dense mass) on the same JAX
log density.

The density is the one ``peano-bayes fit TP`` samples (default ``--material TP``): the bundled file's load cycles,
blocking and stroke tests of two specimens, the configured model, population values with per-specimen contrasts
and their spread, the noise scales, the fitted inputs' error linearised at the exact-input mode (18 parameters
for TP).

- **ours**: :func:`peano_bayes.app.pipeline.infer` as the command line runs it (least squares, posterior mode, four
  ensembles to the convergence gates). Its sampling seconds include the warm-up; least squares, the mode and the
  compilation are timed apart. ESS is the tool's (arviz bulk ESS, every walker a chain, minimum over parameters),
  and, as a cross-check, walker-draws / tau_max.
- **(a) NumPy emcee**: no NumPy twin of the whole posterior exists; ``numpy_load_cycle.py`` is the twin of our
  load-cycle solver (checked equal first). The same sampler run on a NumPy port would evaluate at least the
  load cycles at every walker and step, so its time per step is bounded below by that many NumPy load-cycle
  evaluations (the blocking and stroke tests, the hierarchy and the input-error term would only add). Same
  algorithm on the same density gives the same ESS per step, so the ESS/s ratio is at least the ratio of time
  per step: a lower bound on our advantage.
- **(b) NUTS**: numpyro, dense mass matrix started at the Laplace inverse Hessian of the point ours started at
  (adapted further in warm-up), ``--nuts-chains`` chains (default 2, run one after another) of ``--nuts-warmup`` +
  ``--nuts-samples`` draws each, each chain started at its own draw from that approximation; its bulk ESS from
  arviz (minimum over parameters). A first short run compiles its step functions (timed apart, the persistent
  compilation cache then serves the measured run). A faster sampler of another distribution would prove
  nothing, so NUTS's draws are compared with ours (read back from ours' ``posterior.nc``): means and 94 %
  interval ends per parameter, in units of ours' sd and of the two runs' combined Monte Carlo error, which sets
  how small a difference the run can resolve (``reference_run.agreement``; ``nuts_against_ours`` in the JSON).

    python experiments/bench_inference.py [--material TP] [--nuts-chains 2] [--nuts-warmup 500]
        [--nuts-samples 1000] [--out DIR]

The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import arviz as az
import emcee
import jax
import jax.numpy as jnp
import numpy as np
import numpy_load_cycle
from reference_run import MAX_END_SD, agreement

from peano_bayes.app.pipeline import DEFAULT_MAX_STEPS, DEFAULT_TESTS, infer, prior_of, select_tests
from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.discovery.choice import configured_model
from peano_bayes.inference import build_posterior, prepare
from peano_bayes.inference.driver import linearisation_point
from peano_bayes.inference.laplace import capped_covariance, finite_difference_hessian
from peano_bayes.inference.posterior import DEFAULT_HELD
from peano_bayes.jax_config import enable_compilation_cache
from peano_bayes.physics import LoadCycle, simulate_load_cycle

SEED = 0


def sampled_posterior(material: str, fit_dir: Path):
    """The posterior ``infer`` sampled for ``material`` (the configured model, its inputs' error linearised and its
    residual correlation taken at the point ``infer`` recorded in ``input_error_point.json``)."""
    dataset = select_tests(load(dataset_path(material)), DEFAULT_TESTS)
    whole = prior_of(dataset, None)
    config = configured_model(whole.config).config
    posterior = build_posterior(prepare(dataset), whole.for_config(config), config=config, held=DEFAULT_HELD)
    # as a resumed fit reads it back (and refuses a record over other parameters)
    point, lag1, _ = linearisation_point(fit_dir / "input_error_point.json", fit_dir / "sampler_state.npz", posterior)
    return posterior.with_input_error_at(point).with_residual_lag1(lag1), point, config


def numpy_seconds_per_walker(posterior, point, config) -> tuple[float, float, int]:
    """Seconds of the NumPy twin for one walker's load cycles (best of three), its largest force difference [N]
    from our simulation of the same cycles, and the number of cycles."""
    groups = [g for g in posterior.observations.groups if g.test == "load_cycle"]
    params = {k: float(v) for k, v in posterior.params(point).items() if not isinstance(v, dict) and np.ndim(v) == 0}
    batch = {k: np.array([v]) for k, v in params.items() if k in config.parameter_names()}
    geometry = posterior.observations.geometry
    geo = (geometry.n_tubes, geometry.tube_width_m, geometry.tube_length_m)
    cycles = [(g.strain[row], g.pressure_pa[row], g.time_s[row]) for g in groups for row in range(g.strain.shape[0])]
    worst = 0.0
    for strain, pressure, time_s in cycles[:2]:
        ours = simulate_load_cycle(params, LoadCycle(time_s, strain, pressure), config=config, geometry=geometry)
        twin = numpy_load_cycle.simulate_load_cycle(batch, strain, pressure, geo)[0]
        difference = np.abs(np.asarray(ours.force_n) - twin)
        assert np.all(np.isfinite(difference)), "a load cycle the twin or ours cannot simulate"
        worst = max(worst, float(np.max(difference)))
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for strain, pressure, _t in cycles:
            numpy_load_cycle.simulate_load_cycle(batch, strain, pressure, geo)
        best = min(best, time.perf_counter() - t0)
    return best, worst, len(cycles)


def min_ess(draws: np.ndarray) -> float:
    """Minimum bulk ESS over parameters of draws (chains, draws, D)."""
    data = az.convert_to_dataset({f"p{i}": draws[..., i] for i in range(draws.shape[-1])})
    ess = az.ess(data, method="bulk")
    return float(min(float(ess[k]) for k in data.data_vars))


def laplace_inverse_mass(potential, centre: np.ndarray) -> np.ndarray:
    """(D, D) inverse Hessian of ``potential`` at ``centre`` (central differences of its JAX gradient), floored and
    capped as the mode search does (:func:`~peano_bayes.inference.laplace.capped_covariance`, sd at most 3):
    NUTS's initial inverse mass matrix, the same curvature ours starts its walkers from. Without it (unit mass)
    NUTS's warm-up ran at 20-27 s per iteration on TP (up to 1023 leapfrog steps of size 1e-4)."""
    centre = np.asarray(centre, dtype=float)
    hessian = finite_difference_hessian(jax.jit(jax.grad(potential)), centre)
    return capped_covariance(hessian, 9.0 * np.eye(centre.size), max_sd=3.0)


def run_nuts(posterior, centre, warmup: int, samples: int, chains: int) -> dict:
    """``chains`` NUTS chains run one after another on this process (``chain_method="sequential"``, so their
    seconds add up as one core's), each started at its own draw from the Laplace approximation around ``centre``
    so that split R-hat across chains can see a chain stuck where it started. Returns the seconds of all chains,
    bulk ESS and R-hat over all chains, and the draws (chains, samples, D)."""
    from numpyro.infer import MCMC, NUTS

    potential = jax.jit(lambda theta: -posterior.log_prob(theta))
    t0 = time.perf_counter()
    inverse_mass = laplace_inverse_mass(potential, centre)
    mass_s = time.perf_counter() - t0
    starts = np.random.default_rng(SEED).multivariate_normal(np.asarray(centre, dtype=float), inverse_mass, chains)

    def mcmc_run(n_warmup, n_samples, key, n_chains):
        kernel = NUTS(potential_fn=potential, dense_mass=True, inverse_mass_matrix=jnp.asarray(inverse_mass))
        # progress_bar=True: numpyro steps a jitted transition from Python, so the step functions compile once
        # whatever the run's length (the short run below compiles them, the persistent cache serves the long one)
        mcmc = MCMC(
            kernel,
            num_warmup=n_warmup,
            num_samples=n_samples,
            num_chains=n_chains,
            chain_method="sequential",
            progress_bar=True,
        )
        t0 = time.perf_counter()
        init = starts[0] if n_chains == 1 else starts[:n_chains]  # numpyro: (D,) for one chain, (chains, D) else
        mcmc.run(jax.random.PRNGKey(key), init_params=jnp.asarray(init), extra_fields=("num_steps",))
        return mcmc, time.perf_counter() - t0

    _, compile_s = mcmc_run(2, 2, SEED, 1)
    mcmc, seconds = mcmc_run(warmup, samples, SEED + 1, chains)
    draws = np.asarray(mcmc.get_samples(group_by_chain=True))
    data = az.convert_to_dataset({f"p{i}": draws[..., i] for i in range(draws.shape[-1])})
    rhat = az.rhat(data)
    return {
        "chains": chains,
        "chain_method": "sequential",
        "seconds": seconds,
        "short_run_with_compile_s": compile_s,
        "initial_mass_s": mass_s,
        "min_ess": min_ess(draws),
        "max_rhat": float(max(float(rhat[k]) for k in data.data_vars)) if chains > 1 else None,  # one: none
        "mean_leapfrog_steps": float(np.mean(np.asarray(mcmc.get_extra_fields()["num_steps"]))),
        "draws": draws,
    }


def ours_theta(posterior, fit_dir: Path) -> np.ndarray:
    """(walkers, draws, D) theta of ours' retained draws, read back from its ``posterior.nc`` (each walker a chain,
    as arviz stores them). A varying parameter's entry of theta is its specimens' geometric mean
    (``posterior.nc`` stores the population value under its name, a draw around that mean, see
    :meth:`Posterior.levels`)."""
    posterior_draws = az.from_netcdf(fit_dir / "posterior.nc").posterior
    shape = (posterior_draws.sizes["chain"], posterior_draws.sizes["draw"])
    values = {name: np.asarray(posterior_draws[name]).reshape(-1) for name in posterior.names}
    for name in posterior.varying:
        specimens = np.asarray(posterior_draws[f"specimen__{name}"]).reshape(-1, len(posterior.observations.specimens))
        values[name] = np.exp(np.log(specimens).mean(axis=-1))
    u = np.moveaxis(np.asarray(posterior.prior.to_unconstrained(values)), 0, -1)  # (d, n) stacked by name
    return np.column_stack([u, *(values[n] for n in posterior.contrast_names)]).reshape(*shape, -1)


def posterior_agreement(posterior, ours: np.ndarray, nuts: np.ndarray, n_ensembles: int) -> dict:
    """NUTS's posterior against ours by the rule and measure of ``reference_run.agreement``: per entry of theta,
    the mean's and the 94 % interval ends' differences in ours' sd and in the two runs' combined Monte Carlo
    error, the worst of each, and whether they are within 0.1 / 0.2 sd. ``ours`` is (walkers, draws, D), its
    walkers each a chain as the convergence rule's ESS counts them; ``nuts`` (chains, draws, D)."""
    return agreement(
        {name: nuts[..., i] for i, name in enumerate(posterior.names)},
        {name: ours[..., i] for i, name in enumerate(posterior.names)},
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--material", default="TP")
    parser.add_argument("--nuts-warmup", type=int, default=500)
    parser.add_argument("--nuts-samples", type=int, default=1000, help="NUTS draws kept per chain")
    parser.add_argument("--nuts-chains", type=int, default=2, help="NUTS chains, run one after another")
    parser.add_argument("--out", type=Path, default=None, help="where ours writes its fit (default: a temp dir)")
    parser.add_argument("--reuse-fit", action="store_true", help="read ours from --out instead of fitting again")
    parser.add_argument("--max-steps", type=int, default=DEFAULT_MAX_STEPS, help="ours' step limit (a smoke run)")
    args = parser.parse_args()
    enable_compilation_cache()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_inference_"))

    # Ours: the fit as the command line runs it.
    previous = out / args.material / "summary.json"
    reused = bool(args.reuse_fit and previous.exists())  # before infer writes a summary of its own there
    if reused:
        summary = json.loads(previous.read_text())
    else:
        summary = infer(
            dataset_path(args.material),
            out,
            seed=SEED,
            max_steps=args.max_steps,
            progress=False,
            figures=False,
            log=lambda m: None,
        )
    conv = summary["convergence"]
    timings = summary["timings_s"]
    steps, walkers = summary["steps"], summary["n_walkers"] * summary["n_ensembles"]
    ours_seconds = timings["sampling_s"]
    ours_ess = min(conv["ess_bulk"].values())
    tau_max = max(conv["tau_steps"].values())
    ours_ess_tau = (steps - conv["discard_steps"]) * walkers / tau_max
    ours_rate = ours_ess / ours_seconds
    ours_per_step = ours_seconds / steps

    posterior, point, config = sampled_posterior(args.material, out / summary["label"])
    # (a) NumPy emcee, a lower bound on its time per step.
    per_walker, twin_difference_n, cycles = numpy_seconds_per_walker(posterior, point, config)
    numpy_per_step = per_walker * walkers
    numpy_rate = (ours_ess / steps) / numpy_per_step
    # (b) NUTS on the same JAX density, from the point ours started its walkers around.
    nuts = run_nuts(posterior, point, args.nuts_warmup, args.nuts_samples, args.nuts_chains)
    nuts_rate = nuts["min_ess"] / nuts["seconds"]
    nuts_draws = nuts.pop("draws")
    np.save(out / f"nuts_draws_{args.material}.npy", nuts_draws)  # (chains, samples, D) theta, to compare again later
    same = posterior_agreement(
        posterior, ours_theta(posterior, out / summary["label"]), nuts_draws, summary["n_ensembles"]
    )

    print(f"machine: {platform.processor() or platform.machine()}, jax {jax.__version__}, emcee {emcee.__version__}")
    print(
        f"density: {args.material}, {posterior.ndim} parameters, {posterior.observations.n_bins} bins, "
        f"{cycles} load cycles; NumPy twin's load cycle agrees to {twin_difference_n:.2e} N"
    )
    print(f"{'sampler':<34} {'wall [s]':>10} {'min bulk ESS':>13} {'ESS/s':>10}")
    print(
        f"{'ours: emcee + jit/vmap':<34} {ours_seconds:10.1f} {ours_ess:13.0f} {ours_rate:10.2f}"
        f"   ({steps} steps x {walkers} walkers, converged={conv['converged']}, tau_max {tau_max:.1f}, "
        f"draws/tau {ours_ess_tau:.0f}; compile {timings['compile_s']:.1f} s apart)"
    )
    print(
        f"{'(a) emcee + NumPy (lower bound)':<34} {numpy_per_step * steps:10.1f} {ours_ess:13.0f} {numpy_rate:10.4f}"
        f"   (>= {numpy_per_step:.1f} s/step against our {ours_per_step * 1e3:.0f} ms)"
    )
    print(
        f"{'(b) NUTS dense (numpyro)':<34} {nuts['seconds']:10.1f} {nuts['min_ess']:13.0f} {nuts_rate:10.2f}"
        f"   ({nuts['chains']} chains one after another, {nuts['mean_leapfrog_steps']:.1f} leapfrog/draw, "
        f"max R-hat {nuts['max_rhat'] if nuts['max_rhat'] is None else round(nuts['max_rhat'], 3)})"
    )
    print(
        f"NUTS against ours: means within {same['max_mean_difference_sd']:.3f} sd ({same['worst_mean']}), "
        f"94 % interval ends within {same['max_interval_end_difference_sd']:.3f} sd ({same['worst_interval_end']})"
    )
    for name, row in same["rows"].items():
        if row["interval_end_sd"] > MAX_END_SD:
            print(
                f"  {name}: an interval end {row['interval_end_sd']:.3f} sd apart, "
                f"{row['interval_end_mcse']:.1f} times the two runs' combined Monte Carlo error"
            )
    print(
        json.dumps(
            {
                "benchmark": "inference",
                "date": time.strftime("%Y-%m-%d"),
                "reused_fit": reused,
                "nuts_chains": nuts["chains"],
                "nuts_warmup": args.nuts_warmup,
                "nuts_samples_per_chain": args.nuts_samples,
                "material": args.material,
                "ndim": posterior.ndim,
                "n_bins": posterior.observations.n_bins,
                "ours_ess_per_s": ours_rate,
                "ours_ess_per_s_by_tau": ours_ess_tau / ours_seconds,
                "numpy_emcee_ess_per_s_upper_bound": numpy_rate,
                "nuts_ess_per_s": nuts_rate,
                "ratio_vs_numpy_lower_bound": ours_rate / numpy_rate,
                "ratio_vs_nuts": ours_rate / nuts_rate,
                "ratio_vs_nuts_by_tau": (ours_ess_tau / ours_seconds) / nuts_rate,
                "ours_seconds": ours_seconds,
                "ours_steps": steps,
                "ours_walkers": walkers,
                "ours_tau_max": tau_max,
                "ours_converged": bool(conv["converged"]),
                "ours_timings_s": timings,
                "numpy_s_per_step_lower_bound": numpy_per_step,
                "numpy_load_cycles_per_walker": cycles,
                "numpy_max_force_difference_n": twin_difference_n,
                "ours_ms_per_step": ours_per_step * 1e3,
                "nuts": nuts,
                "nuts_against_ours": same,
            }
        )
    )


if __name__ == "__main__":
    main()
