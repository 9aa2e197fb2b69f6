"""How well the likelihood fits a bundled dataset at its generating values, test by test, beside a result's
posterior mean: where the truth fits worse than the noise, the likelihood (its reduced inputs, bins and
simulation) is not the process that made the data, and the posterior moves away from the truth to absorb it.

Truth: every specimen's own generating values (the dataset's provenance) and the rig's noise scales. Posterior
mean: each specimen's posterior mean (``specimen__<name>``) or the population mean of a shared parameter.
Prints per test the log-likelihood, the rms of (observed - predicted) / bin sd and the rms of the residuals
whitened by the likelihood's own covariance (which differ where the fitted inputs' error is integrated out,
``likelihood.INPUT_ERROR_TESTS``: the second is the fit in noise units), then, for the worst test at the truth,
the mean of the raw z per tenth of each run. The last line is one JSON object.

    python experiments/fit_at_truth.py CODE RESULT_DIR      (e.g. TP results/TP)
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import arviz as az
import jax.numpy as jnp
import numpy as np

from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.inference.likelihood import group_log_likelihood, whitened_residuals
from peano_bayes.inference.posterior import build_posterior
from peano_bayes.inference.prior_files import prior_for
from peano_bayes.inference.reduce import prepare
from peano_bayes.inference.results import SPECIMEN_PREFIX


def per_test(params, observations, config) -> dict:
    """Per test, over every run group of it (runs of other lengths are other groups): the log-likelihood, the
    rms of the raw and of the whitened z, and ``runs``: (key, z row) per run."""
    parts: dict[str, dict] = {}
    for g in observations.groups:
        pred, scale, ll = group_log_likelihood(params, g, config=config, geometry=observations.geometry)
        z = (g.observed - np.asarray(pred)) / np.asarray(scale)
        white = np.asarray(whitened_residuals(params, g, config=config, geometry=observations.geometry))
        entry = parts.setdefault(g.test, {"ll": 0.0, "z": [], "white": [], "runs": []})
        entry["ll"] += float(np.nansum(ll))
        entry["z"].append(z[np.isfinite(z)])
        entry["white"].append(white[np.isfinite(white)])
        entry["runs"] += list(zip(g.keys, z, strict=True))
    return {
        test: {
            "log_likelihood": e["ll"],
            "z_rms": float(np.sqrt(np.mean(np.concatenate(e["z"]) ** 2))),
            "z_whitened_rms": float(np.sqrt(np.mean(np.concatenate(e["white"]) ** 2))),
            "runs": e["runs"],
        }
        for test, e in parts.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("code")
    parser.add_argument("result")
    args = parser.parse_args()
    dataset = load(dataset_path(args.code))
    dataset = dataclasses.replace(dataset, runs=tuple(r for r in dataset.runs if r.test != "step"))
    observations = prepare(dataset)
    posterior = build_posterior(observations, prior_for(args.code))
    own = json.loads(dataset.provenance["specimen_parameters"])
    noise = json.loads(dataset.provenance["noise"])
    scales = {
        "noise_load_cycle_force_n": noise["force_sd_n"],
        "noise_blocking_force_n": noise["force_sd_n"],
        "noise_stroke_strain": noise["strain_sd"],
        "noise_step_strain": noise["strain_sd"],
    }
    specimens = list(observations.specimens)
    truth = {k: jnp.asarray([own[s][k] for s in specimens]) for k in own[specimens[0]]}
    idata = az.from_netcdf(f"{args.result}/posterior.nc")
    mean = dict(truth)
    for k in truth:
        if SPECIMEN_PREFIX + k in idata.posterior:
            mean[k] = jnp.asarray(idata.posterior[SPECIMEN_PREFIX + k].mean(("chain", "draw")).values)
        elif k in idata.posterior:
            mean[k] = jnp.asarray(float(idata.posterior[k].mean()))
    for params in (truth, mean):
        params.update({k: jnp.asarray(v) for k, v in scales.items()})
    report = {}
    for label, params in (("truth", truth), ("posterior_mean", mean)):
        report[label] = per_test(params, observations, posterior.config)
        cells = ", ".join(
            f"{t} ll {r['log_likelihood']:.1f} z_rms {r['z_rms']:.3f} whitened {r['z_whitened_rms']:.3f}"
            for t, r in report[label].items()
        )
        print(f"{label}: {cells}")
    worst = max(report["truth"], key=lambda t: report["truth"][t]["z_rms"])
    np.set_printoptions(precision=2, suppress=True, linewidth=160)
    print(f"{worst} at the truth, mean z per tenth of each run:")
    for key, row in sorted(report["truth"][worst]["runs"], key=lambda kr: kr[0]):
        row = row[np.isfinite(row)]
        print(f"  {key}: {np.array([np.mean(part) for part in np.array_split(row, 10)])}")
    summary = {k: {t: {m: v for m, v in r.items() if m != "runs"} for t, r in v.items()} for k, v in report.items()}
    print(json.dumps({"material": args.code, "worst_test_at_truth": worst, **summary}))


if __name__ == "__main__":
    main()
