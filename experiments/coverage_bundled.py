"""Coverage of the bundled materials' generating values by the posteriors of a ``peano-bayes run`` (or ``fit``).

For every material with a result in ``RESULTS`` (``<CODE>/posterior.nc``), and every physics parameter it sampled
(not the noise scales, the specimen spread or the contrasts): is the **population** generating value (the
``[<CODE>.parameters]`` of the bundled ``true_parameters.toml``, before the rig's per-specimen factors; a
parameter not listed there was generated at its nominal value) inside the 94 % highest-density interval of the
population posterior? Also reported: the same for the specimens' own generating values (from the dataset's
provenance) against the per-specimen posteriors, and whether each result converged. Only converged results
count towards the headline figure.

The last line printed is one JSON object: ``inside``, ``total``, ``fraction`` (converged results only) and
per material the parameters and their verdicts.

    python experiments/coverage_bundled.py [RESULTS]   (default: results)
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

import arviz as az
import numpy as np

from peano_bayes.bundled import DATA_DIR, MATERIALS, dataset_path
from peano_bayes.data import load
from peano_bayes.defaults import HDI_PROB
from peano_bayes.inference.results import SPECIMEN_PREFIX, load_result, result_config

NOT_PHYSICS = ("noise_", "specimen_")


def material_coverage(code: str, directory: Path, truth: dict) -> dict:
    idata = load_result(directory)
    summary = json.loads((directory / "summary.json").read_text())
    nominal = result_config(idata).nominal_parameters()
    post = idata.posterior
    names = [n for n in summary["parameters"] if not n.startswith(NOT_PHYSICS)]
    provenance = load(dataset_path(code)).provenance
    own = json.loads(provenance["specimen_parameters"]) if "specimen_parameters" in provenance else {}
    rows = {}
    for name in names:
        value = float(truth.get(name, nominal.get(name, np.nan)))
        low, high = (float(v) for v in az.hdi(post[name].values.reshape(-1), hdi_prob=HDI_PROB))
        row = {"truth": value, "hdi_low": low, "hdi_high": high, "inside": bool(low <= value <= high)}
        if SPECIMEN_PREFIX + name in post and own:
            values = post[SPECIMEN_PREFIX + name]
            row["specimens"] = {}
            for specimen in values.coords["specimen"].values:
                draws = values.sel(specimen=specimen).values.reshape(-1)
                s_low, s_high = (float(v) for v in az.hdi(draws, hdi_prob=HDI_PROB))
                s_truth = float(own[str(specimen)][name])
                row["specimens"][str(specimen)] = {"truth": s_truth, "inside": bool(s_low <= s_truth <= s_high)}
        rows[name] = row
    return {"converged": bool(summary["convergence"]["converged"]), "parameters": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="?", default="results", help="the results directory (default: results)")
    args = parser.parse_args()
    root = Path(args.results)
    with (DATA_DIR / "true_parameters.toml").open("rb") as f:
        truths = tomllib.load(f)
    materials = {}
    for code in MATERIALS:
        if (root / code / "posterior.nc").is_file():
            materials[code] = material_coverage(code, root / code, truths[code]["parameters"])
    if not materials:
        sys.exit(f"{root}: no material results (<CODE>/posterior.nc); run 'peano-bayes run' first")
    inside = total = 0
    for code, m in materials.items():
        flag = "" if m["converged"] else "  (NOT CONVERGED: not counted)"
        print(f"{code}{flag}")
        for name, row in m["parameters"].items():
            verdict = "inside" if row["inside"] else "OUTSIDE"
            specimens = " ".join(
                f"{s}:{'in' if v['inside'] else 'OUT'}" for s, v in row.get("specimens", {}).items()
            )
            print(
                f"  {name:32s} truth {row['truth']:<12.4g} 94 % [{row['hdi_low']:.4g}, {row['hdi_high']:.4g}] "
                f"{verdict}  {specimens}"
            )
            if m["converged"]:
                inside += row["inside"]
                total += 1
    fraction = inside / total if total else float("nan")
    print(f"population generating values inside their 94 % interval: {inside} of {total} (converged results)")
    print(json.dumps({"inside": inside, "total": total, "fraction": fraction, "materials": materials}))


if __name__ == "__main__":
    main()
