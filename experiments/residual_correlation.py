"""Does the fit-quality check tell noise from a misfit with structure? FC's default fit, two datasets.

For the bundled FC file (made by the model that is fitted) and for data from Veale's force-balance model under
FC's conditions (``rig.simulate_veale_dataset``, seed 0, as ``independent_data.py`` makes them), ``infer`` runs
up to the posterior mode on the full likelihood (least squares, mode, the input error linearised; the sampler is
not run) and the whitened residuals there are read per run (``likelihood.whitened_residuals``): their lag-1
correlation and rms per run (median and range over runs), and the package's pooled check
(``fit.residual_correlation``). The last line printed is one JSON object.

    python experiments/residual_correlation.py [--out /tmp/residual_correlation]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import peano_bayes.app.pipeline as pipeline
from peano_bayes import bundled, enable_compilation_cache
from peano_bayes.data import load
from peano_bayes.inference.fit import lag1_sums, residual_correlation
from peano_bayes.inference.likelihood import whitened_residuals
from peano_bayes.rig import simulate_veale_dataset


class _AtTheMode(Exception):
    """Carries the posterior and its mode out of ``infer`` where sampling would start."""


def _stop(posterior, centre, covariance, **kwargs):
    raise _AtTheMode(posterior, centre)


def at_mode(dataset, out: Path):
    """(posterior, mode theta) of ``infer``'s default fit of ``dataset``, the sampler not run."""
    sample, pipeline.sample = pipeline.sample, _stop
    try:
        pipeline.infer(dataset, out, seed=0, progress=False, figures=False)
    except _AtTheMode as stopped:
        return stopped.args
    finally:
        pipeline.sample = sample
    raise RuntimeError("infer finished without reaching the sampler")


def per_run(posterior, params) -> dict:
    """Per test: lag-1 correlation and rms of each run's whitened residuals, median and range over runs."""
    rows: dict[str, list] = {}
    for group in posterior.observations.groups:
        z = whitened_residuals(params, group, config=posterior.config, geometry=posterior.observations.geometry)
        for (cross, later, earlier, _), row in zip(lag1_sums(z), z, strict=True):
            rows.setdefault(group.test, []).append(
                (float(cross / np.sqrt(later * earlier)), float(np.sqrt(np.nanmean(row**2))))
            )
    out = {}
    for test, values in rows.items():
        lag, rms = np.asarray(values).T
        out[test] = {
            "runs": len(values),
            "lag1_median": float(np.median(lag)),
            "lag1_range": [float(lag.min()), float(lag.max())],
            "rms_median": float(np.median(rms)),
            "rms_range": [float(rms.min()), float(rms.max())],
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("/tmp/residual_correlation"))
    args = parser.parse_args()
    enable_compilation_cache()
    datasets = {"own_rig": load(bundled.dataset_path("FC")), "veale": simulate_veale_dataset("FC", seed=0)}
    report = {}
    for label, dataset in datasets.items():
        posterior, mode = at_mode(dataset, args.out / label)
        params = posterior.params(mode)
        report[label] = {
            "per_run": per_run(posterior, params),
            "pooled": residual_correlation(params, posterior.observations, posterior.config),
        }
        for test, row in report[label]["per_run"].items():
            pooled = report[label]["pooled"][test]
            print(
                f"{label} {test}: lag-1 median {row['lag1_median']:.2f} "
                f"({row['lag1_range'][0]:.2f} to {row['lag1_range'][1]:.2f}) over {row['runs']} runs, "
                f"rms median {row['rms_median']:.2f}; pooled {pooled['lag1']:.3f} over {pooled['pairs']} pairs, "
                f"{'consistent with noise' if pooled['consistent_with_noise'] else 'structured'}",
                flush=True,
            )
    print(json.dumps({"study": "residual_correlation", **report}))


if __name__ == "__main__":
    main()
