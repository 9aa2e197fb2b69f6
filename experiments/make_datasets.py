"""Generate the eight bundled synthetic datasets from ``data/true_parameters.toml`` (``calibrate.py``'s output).

For each material: ``peano_bayes.rig.simulate_dataset`` with the calibrated parameters, the configuration and
quirks recorded with them, a fixed seed per material (``SEEDS``), two specimens, three repeats, default noise
and 5 % specimen spread; written as ``data/<CODE>.csv`` + ``data/<CODE>.toml`` by ``peano_bayes.data.save``.
Run ``python experiments/make_datasets.py``.
"""

from __future__ import annotations

import argparse
import time
import tomllib
from pathlib import Path

from peano_bayes import bundled
from peano_bayes.data import save
from peano_bayes.physics import ModelConfig
from peano_bayes.rig import simulate_dataset

DATA = bundled.DATA_DIR
#: One fixed seed per material (Table 4 order), so regenerating gives the same bytes.
SEEDS = {"TP": 101, "P": 102, "PR": 103, "TPC": 104, "PC": 105, "PCS": 106, "TFC": 107, "FC": 108}


def read_truth(path: Path = DATA / "true_parameters.toml") -> dict[str, tuple[dict, ModelConfig, tuple]]:
    """code -> (parameters [SI], base ModelConfig, quirk names) from the calibration output."""
    document = tomllib.loads(path.read_text(encoding="utf-8"))
    out = {}
    for code, table in document.items():
        config = ModelConfig(**{k.removeprefix("config_"): v for k, v in table.items() if k.startswith("config_")})
        out[code] = (dict(table["parameters"]), config, tuple(table["quirks"]))
    return out


def main() -> None:
    """Simulate and save every material; print timings and file sizes."""
    argparse.ArgumentParser(description=__doc__).parse_args()  # --help, and no stray arguments
    for code, (params, config, quirks) in read_truth().items():
        tic = time.perf_counter()
        dataset = simulate_dataset(code, params, config=config, quirks=quirks, seed=SEEDS[code], repeats=3, specimens=2)
        csv_path = save(dataset, DATA / code)
        size_mb = csv_path.stat().st_size / 1e6
        print(f"{code}: {len(dataset.runs)} runs, {csv_path.name} {size_mb:.2f} MB, {time.perf_counter() - tic:.1f} s")


if __name__ == "__main__":
    main()
