"""Results of one dataset: an arviz ``InferenceData`` (``posterior.nc``) and ``summary.json``, written atomically.

Groups: ``posterior`` (kept draws, thinned to at most :data:`MAX_DRAWS_PER_WALKER` per walker; values in SI
units, walkers as chains: the **population** value under each parameter's name and, for the parameters that
differ between specimens, ``specimen__<name>`` (dim ``specimen``) and ``new_specimen__<name>``, see
:meth:`~peano_bayes.inference.posterior.Posterior.levels`), ``sample_stats`` (``lp``), ``prior`` (draws from the prior
file), and, on an evenly spaced subset of :data:`POINTWISE_DRAWS_PER_WALKER` draws per walker (their ``draw``
coordinate says which), ``log_likelihood`` (``y``: every measured bin) and ``posterior_predictive`` (``y``: the
prediction plus Gaussian noise of the bin's scale), with ``observed_data`` (``y`` and, per bin, its test,
specimen, run, time and raw-sample count). Every group's ``attrs`` hold the seed, package versions, the model
configuration, the prior files' text and the convergence verdict.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from importlib import metadata
from pathlib import Path

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from ..atomic import replacing
from ..errors import PeanoBayesInputError
from ..physics import PARAMETERS, ModelConfig
from .likelihood import group_log_likelihood
from .posterior import SPECIMEN_SD, STEP_ONLY_PARAMETERS, Posterior, fixed_batches
from .prior_files import load_prior
from .sample import SampleResult

MAX_DRAWS_PER_WALKER = 250
#: Prefixes of the hierarchy's specimen-level and new-specimen variables in the ``posterior`` group.
SPECIMEN_PREFIX = "specimen__"
NEW_SPECIMEN_PREFIX = "new_specimen__"
POINTWISE_DRAWS_PER_WALKER = 8
PRIOR_DRAWS = 1000
PACKAGES = ("peano_bayes", "jax", "optimistix", "emcee", "arviz", "numpy")


def package_versions() -> dict[str, str]:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name.replace("_", "-"))
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def physical_draws(posterior: Posterior, thetas: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    """name -> values [SI] for thetas (..., D): the hierarchy's levels (:meth:`Posterior.levels`: population
    values under the parameters' names, ``specimen__<name>`` (..., n_specimens), ``new_specimen__<name>``),
    contrasts as they are."""
    return posterior.levels(thetas, np.random.default_rng([seed, 4]))


def _predictions(posterior: Posterior, thetas: np.ndarray, rng: np.random.Generator):
    """Pointwise log-likelihood and predictive draws (n, n_bins) at thetas (n, D), measured bins only (the
    order of :meth:`Posterior.pointwise`); one simulation per draw serves both."""
    obs = posterior.observations
    kw = dict(config=posterior.config, geometry=obs.geometry, family=posterior.family)

    def one(theta, groups):
        params = posterior.params(theta)
        return [group_log_likelihood(params, group, **kw) for group in groups]

    # The run groups are an argument, not constants of the program (constants of that size make XLA's compile
    # slow, and tie the program to one dataset); the measured bins are picked out afterwards.
    f = jax.jit(jax.vmap(one, in_axes=(0, None)))
    measured = [np.isfinite(group.observed) for group in obs.groups]
    n = thetas.shape[0]
    outs = []
    for batch in fixed_batches(thetas, min(64, n)):  # one batch shape, one compile
        per_group = f(jnp.asarray(batch), obs.groups)
        outs.append(
            [np.concatenate([np.asarray(g[k])[:, ok] for g, ok in zip(per_group, measured, strict=True)], axis=1)
             for k in range(3)]
        )  # fmt: skip
    mean, scale, ll = (np.concatenate([o[k] for o in outs])[:n] for k in range(3))
    return ll, mean + scale * rng.standard_normal(mean.shape)


#: What ``observed_data`` holds of every bin beside its value ``y`` (:meth:`Posterior.observed`).
_BIN_FIELDS = ("test", "specimen", "run", "time_s", "count", "unit", "strain", "pressure_pa")


def to_inference_data(posterior: Posterior, result: SampleResult, *, seed: int, attrs: dict | None = None):
    """The :mod:`arviz` InferenceData of a sampling run (see the module docstring)."""
    kept = result.kept()  # (walkers, steps, D)
    thin = max(1, int(np.ceil(kept.shape[1] / MAX_DRAWS_PER_WALKER)))
    draws = np.arange(0, kept.shape[1], thin)
    kept = kept[:, draws]
    lp = result.log_prob[result.convergence.discard :].T[:, draws]
    walkers, n_draws, ndim = kept.shape
    every = max(1, n_draws // POINTWISE_DRAWS_PER_WALKER)
    subset = np.arange(n_draws - 1, -1, -every)[:POINTWISE_DRAWS_PER_WALKER][::-1]
    rng = np.random.default_rng([seed, 2])
    ll, yrep = _predictions(posterior, kept[:, subset].reshape(-1, ndim), rng)
    n_bins = ll.shape[-1]
    ll = ll.reshape(walkers, subset.size, n_bins)
    yrep = yrep.reshape(walkers, subset.size, n_bins)
    observed = posterior.observed()
    prior_theta = posterior.prior.sample(np.random.default_rng([seed, 3]), PRIOR_DRAWS)
    prior_draws = {k: np.asarray(v)[None] for k, v in posterior.prior.from_unconstrained(prior_theta).items()}
    post_draws = physical_draws(posterior, kept, seed)
    bin_coords = {"bin": np.arange(n_bins)}
    # Every walker is a chain; arviz warns when chains outnumber draws (its guess at a transposed array), which
    # here is the intended shape: a short run, or the few pointwise draws per walker.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"More chains \(\d+\) than draws", category=UserWarning)
        idata = az.from_dict(
            posterior=post_draws,
            sample_stats={"lp": lp},
            coords={"draw": draws + result.convergence.discard, "specimen": list(posterior.observations.specimens)},
            dims={k: ["specimen"] for k in post_draws if k.startswith(SPECIMEN_PREFIX)},
        )
        pointwise = az.from_dict(
            log_likelihood={"y": ll},
            posterior_predictive={"y": yrep},
            observed_data={"y": observed["value"], **{k: observed[k] for k in _BIN_FIELDS}},
            coords={**bin_coords, "draw": draws[subset] + result.convergence.discard},
            dims={k: ["bin"] for k in ("y", *_BIN_FIELDS)},
        )
    idata.extend(pointwise)
    idata.extend(az.from_dict(prior=prior_draws))
    provenance = _attrs(posterior, result, seed, attrs)
    for group in idata.groups():
        getattr(idata, group).attrs.update(provenance)
    return idata


def _attrs(posterior: Posterior, result: SampleResult, seed: int, extra: dict | None) -> dict:
    g = posterior.observations.geometry
    return {
        "seed": seed,
        "package_versions": json.dumps(package_versions()),
        "model_config": json.dumps(dataclasses.asdict(posterior.config)),
        "fixed_parameters": json.dumps(posterior.fixed),
        "prior_files": json.dumps([str(p) for p in posterior.prior.files]),
        "prior_text": posterior.prior.text,
        "likelihood_family": posterior.family,
        "bin_sizes": json.dumps(dict(posterior.observations.bin_sizes)),
        "geometry": json.dumps(
            {
                "n_tubes": int(g.n_tubes),
                "tube_width_m": float(g.tube_width_m),
                "tube_length_m": float(g.tube_length_m),
                "channel_width_frac": float(g.channel_width_frac),
            }
        ),
        "converged": int(result.convergence.converged),
        "n_ensembles": int(result.n_ensembles),
        "units": json.dumps(
            {**dict(posterior.prior.units), **{n: "-" for n in posterior.names[posterior.prior.ndim :]}}
        ),
        **(extra or {}),
    }


def write_netcdf(idata, path: Path) -> None:
    """Write ``idata`` to ``path`` as NetCDF, atomically (:func:`peano_bayes.atomic.replacing`)."""
    with replacing(path) as tmp:
        idata.to_netcdf(str(tmp))


def parameter_table(idata, names, hdi_prob: float = 0.94) -> dict:
    """name -> mean, sd and HDI bounds of the stored posterior (arviz); convergence figures are in
    :class:`~peano_bayes.inference.sample.Convergence`."""
    table = az.summary(idata, var_names=list(names), hdi_prob=hdi_prob, round_to="none")
    low, high = (c for c in table.columns if c.startswith("hdi_"))
    return {
        name: {
            "mean": float(row["mean"]),
            "sd": float(row["sd"]),
            "hdi_low": float(row[low]),
            "hdi_high": float(row[high]),
        }
        for name, row in table.iterrows()
    }


def posterior_contraction(idata, names) -> dict[str, float]:
    """name -> 1 - posterior variance / prior variance of each parameter in ``names``, in the log of the value
    for positive parameters (the sampler's scale) and the value itself otherwise; from the result's
    ``posterior`` (population values) and ``prior`` groups. Near 1: the data determine the parameter; near 0:
    its posterior is its prior."""
    out = {}
    for name in names:
        if name not in idata.posterior or "prior" not in idata.groups() or name not in idata.prior:
            continue
        post = np.asarray(idata.posterior[name].values, float).reshape(-1)
        prior = np.asarray(idata.prior[name].values, float).reshape(-1)
        if np.all(post > 0) and np.all(prior > 0):
            post, prior = np.log(post), np.log(prior)
        variance = float(np.var(prior))
        out[name] = float(1.0 - np.var(post) / variance) if variance > 0 else float("nan")
    return out


#: Prior sd (:meth:`~peano_bayes.inference.priors.Marginal.position`) beyond which a posterior median lying in a
#: tail of its prior is reported as a conflict between prior and data: a prior this far from where the data put
#: a parameter pulls its interval toward itself wherever the data leave a direction open (a ridge), so the
#: interval's coverage is the prior's, not the 94 % it claims. 3 sd is where a normal prior has 0.13 % of its
#: mass beyond.
PRIOR_CONFLICT_SD = 3.0


def prior_positions(idata, prior, names) -> dict[str, float]:
    """name -> where the posterior median of each parameter in ``names`` sits in its prior, in prior sd
    (:meth:`~peano_bayes.inference.priors.Marginal.position`: 0 at the prior median, negative below), from the
    result's ``posterior`` group (population values) and the :class:`~peano_bayes.inference.priors.Prior`
    ``prior``. Infinite where the median sits on a bound of the support."""
    out = {}
    for name in names:
        if name not in idata.posterior or name not in prior.marginals:
            continue
        median = float(np.median(np.asarray(idata.posterior[name].values, float)))
        out[name] = float(prior.marginals[name].position(median))
    return out


def prior_conflicts(prior, positions: dict[str, float], sd: float = PRIOR_CONFLICT_SD) -> list[str]:
    """The names in ``positions`` (:func:`prior_positions`) whose posterior median lies more than ``sd`` prior
    sd into a tail of its prior (:meth:`~peano_bayes.inference.priors.Marginal.in_tail`: a halfnormal's lower
    end is its mode, not a tail)."""
    return [name for name, z in positions.items() if prior.marginals[name].in_tail(z, sd)]


#: Posterior correlation (in the sampler's scale) beyond which two parameters are reported as a ridge.
RIDGE_CORRELATION = 0.9


def posterior_ridges(idata, names, threshold: float = RIDGE_CORRELATION) -> list[dict]:
    """The pairs of ``names`` whose population posteriors are correlated beyond ``threshold`` (in the log of
    the value for positive parameters, as :func:`posterior_contraction`): ridges the fitted tests cannot
    resolve along their length. For each pair ``a``, ``b``: ``correlation``; ``sd_a``, ``sd_b`` the posterior
    sd of each alone; and the combination the data do determine, the pair's direction of least posterior
    variance, written ``a * b^exponent`` (for log-scaled parameters, so ``sd_combination`` is a relative sd
    when small) with its sd. Sorted by |correlation|, strongest first."""
    columns, logged, kept = [], [], []
    for name in names:
        if name not in idata.posterior:
            continue
        values = np.asarray(idata.posterior[name].values, float).reshape(-1)
        positive = bool(np.all(values > 0))
        columns.append(np.log(values) if positive else values)
        logged.append(positive)
        kept.append(name)
    if len(kept) < 2:
        return []
    draws = np.vstack(columns)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.corrcoef(draws)
    out = []
    for i in range(len(kept)):
        for j in range(i + 1, len(kept)):
            r = float(corr[i, j])
            if not np.isfinite(r) or abs(r) < threshold:
                continue
            cov = np.cov(draws[[i, j]])
            values, vectors = np.linalg.eigh(cov)
            direction = vectors[:, 0]  # least variance
            out.append(
                {
                    "a": kept[i],
                    "b": kept[j],
                    "log_a": logged[i],
                    "log_b": logged[j],
                    "correlation": r,
                    "sd_a": float(np.sqrt(cov[0, 0])),
                    "sd_b": float(np.sqrt(cov[1, 1])),
                    "exponent": float(direction[1] / direction[0]),
                    "sd_combination": float(np.sqrt(values[0]) / abs(direction[0])),
                }
            )
    return sorted(out, key=lambda ridge: -abs(ridge["correlation"]))


# --- reading a result -----------------------------------------------------------------------------------------


def result_config(idata) -> ModelConfig:
    """The model configuration a result was sampled with (its ``model_config`` attribute)."""
    return ModelConfig(**json.loads(idata.posterior.attrs["model_config"]))


def draw_indices(total: int, n_draws: int) -> np.ndarray:
    """(n_draws,) indices, evenly spaced, of stored posterior draws (chains and draws stacked, ``total`` of
    them): the draws every reader of a result takes, so that quantities of one draw pair up."""
    return np.linspace(0, total - 1, n_draws).round().astype(int)


#: The levels of the hierarchy a reader of a result can ask for (see :func:`parameter_draws`).
LEVELS = ("new_specimen", "population")


def parameter_draws(
    idata, n_draws: int, seed: int = 0, *, level: str = "new_specimen"
) -> tuple[list[dict], tuple[str, ...]]:
    """``n_draws`` parameter sets [SI] from a result, evenly spaced over the stored posterior, and the names
    drawn from the prior instead (see :class:`~peano_bayes.analysis.metrics.PosteriorMetrics`).

    ``level``: ``"new_specimen"`` (default), a specimen not yet made, so the sets carry the between-specimen
    spread (what a designer building one more muscle gets), each inside its parameter's physical bounds
    (:func:`_inside_bounds`); ``"population"``, the material's population value.
    Results without a specimen hierarchy (one specimen) have one level.

    Every name the result's configuration reads: posterior draw if sampled; else the ``fixed_parameters``
    attribute or the nominal value (shape constants held in the fit); except step-only parameters
    (:data:`~peano_bayes.inference.posterior.STEP_ONLY_PARAMETERS`) of a fit without the step test, which are
    drawn from the prior the fit used (the result's ``prior`` attribute: a file or a material code) so the step
    metrics carry honest (prior) uncertainty."""
    if level not in LEVELS:
        raise PeanoBayesInputError(f"level must be one of {', '.join(LEVELS)}, got {level!r}")
    attrs = idata.posterior.attrs
    config = result_config(idata)
    material = attrs["material"]
    post = idata.posterior.stack(sample=("chain", "draw"))
    total = post.sizes["sample"]
    if not 1 <= n_draws <= total:
        raise PeanoBayesInputError(f"n_draws must be in [1, {total}] (the stored draws), got {n_draws}")
    pick = draw_indices(total, n_draws)
    fixed = {**config.nominal_parameters(), **json.loads(attrs.get("fixed_parameters", "{}"))}
    names = config.parameter_names()
    prior_only = tuple(n for n in names if n not in post and n in STEP_ONLY_PARAMETERS)
    prior_values = {}
    if prior_only:
        # The prior the fit used (a file of one's own, or the material's bundled prior for older results).
        prior = load_prior(attrs.get("prior", material)).for_config(config).select(prior_only)
        prior_values = prior.sample_params(np.random.default_rng([seed, 7]), n_draws)
    wanted = [*names, *(NEW_SPECIMEN_PREFIX + n for n in names), SPECIMEN_SD]
    drawn = {k: np.asarray(post[k].values)[pick] for k in wanted if k in post}  # (n_draws,) each, read once
    sets = []
    rng = np.random.default_rng([seed, 11])
    for i in range(n_draws):
        params = {}
        for n in names:
            if level == "new_specimen" and NEW_SPECIMEN_PREFIX + n in drawn:
                params[n] = _inside_bounds(n, float(drawn[NEW_SPECIMEN_PREFIX + n][i]), drawn, i, rng)
            elif n in drawn:
                params[n] = float(drawn[n][i])
            elif n in prior_values:
                params[n] = float(np.asarray(prior_values[n])[i])
            else:
                params[n] = float(fixed[n])
        sets.append(params)
    return sets, prior_only


def _inside_bounds(name: str, value: float, drawn: dict, i: int, rng: np.random.Generator) -> float:
    """A new specimen's ``value`` of ``name`` [SI], redrawn inside the parameter's physical bounds where the
    stored draw left them. The population value ``mu`` (``drawn[name][i]``, ``drawn``: name -> (n_draws,) values
    of the picked posterior draws) lies inside its prior's support,
    within the bounds, but ``mu exp(tau z)`` need not: a fit whose population sits near a bound (friction
    stiffness near 1e6 N/m on a muscle that never slips) then gives specimens the rig cannot simulate. Such a
    draw takes ``z`` from the standard normal truncated to the bounds, the hierarchy's own distribution
    restricted to the parameter's support, as the priors are."""
    low, high = PARAMETERS[name].bounds
    if low <= value <= high:
        return value
    mu = float(drawn[name][i])
    tau = float(drawn[SPECIMEN_SD][i]) if SPECIMEN_SD in drawn else 0.0
    if tau <= 0.0:
        return min(max(mu, low), high)
    z_low = math.log(low / mu) / tau if low > 0 else -math.inf
    z_high = math.log(high / mu) / tau if math.isfinite(high) else math.inf
    z = float(stats.truncnorm.rvs(z_low, z_high, random_state=rng))
    return min(max(mu * math.exp(tau * z), low), high)  # the clamp only guards the last rounding


def load_result(path: str | Path):
    """The arviz InferenceData of a result: ``path`` is a ``posterior.nc`` file or a directory holding one.
    Raises :class:`~peano_bayes.errors.PeanoBayesInputError` naming the file and what is wrong."""
    path = Path(path)
    nc = path / "posterior.nc" if path.is_dir() else path
    if not nc.is_file():
        raise PeanoBayesInputError(
            f"{nc}: no such file; expected a result directory of 'peano-bayes fit' or its posterior.nc"
        )
    try:
        idata = az.from_netcdf(str(nc))
    except (OSError, ValueError) as err:
        raise PeanoBayesInputError(f"{nc}: not a readable NetCDF result ({err})") from None
    if "posterior" not in idata.groups():
        raise PeanoBayesInputError(f"{nc}: has no posterior group; expected the posterior.nc of 'peano-bayes fit'")
    missing = [k for k in ("material", "model_config") if k not in idata.posterior.attrs]
    if missing:
        raise PeanoBayesInputError(
            f"{nc}: the posterior group lacks the attribute(s) {', '.join(missing)}; it was written by an older "
            "peano_bayes or another tool; rerun 'peano-bayes fit'"
        )
    return idata


__all__ = [
    "LEVELS",
    "NEW_SPECIMEN_PREFIX",
    "SPECIMEN_PREFIX",
    "load_result",
    "package_versions",
    "parameter_draws",
    "parameter_table",
    "physical_draws",
    "posterior_contraction",
    "posterior_ridges",
    "result_config",
    "to_inference_data",
    "write_netcdf",
]
