"""The bundled synthetic datasets (peano_bayes/bundled/data/*.csv) load, are complete and carry Table 4's conditions."""

from __future__ import annotations

import pytest

from peano_bayes import bundled
from peano_bayes.data import load
from peano_bayes.materials import MATERIALS

DATA = bundled.DATA_DIR
CSV_FILES = sorted(p for p in DATA.glob("*.csv") if not p.name.startswith("published_"))


def test_every_material_is_bundled():
    assert {p.stem for p in CSV_FILES} == set(MATERIALS)


@pytest.mark.parametrize("path", CSV_FILES, ids=lambda p: p.stem)
def test_bundled_dataset(path):
    dataset = load(path)
    assert dataset.material.code == path.stem
    assert len(dataset.specimens) == 2
    assert set(dataset.tests) == {"load_cycle", "blocking", "stroke", "step"}
    spec = MATERIALS[path.stem]
    assert dataset.conditions.test_pressure_pa == pytest.approx(spec.test_pressure_pa)
    assert dataset.conditions.step_load_n == pytest.approx(spec.step_load_n)
    assert dataset.conditions.start_tension_n == pytest.approx(spec.start_tension_n)
