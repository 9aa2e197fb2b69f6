"""The materials registry against the paper's Table 4 (published_metrics.csv condition rows)."""

import csv
from pathlib import Path

import pytest

from peano_bayes.bundled import DATA_DIR
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.materials import GEOMETRY, MATERIALS, MaterialSpec, material
from peano_bayes.physics import PAPER_GEOMETRY

#: The paper's numbers as the package ships them (read by the dataset calibration and the metrics tables).
METRICS_CSV = DATA_DIR / "published_metrics.csv"
#: The project's source copy of the same table, beside the checkout where it exists (not in an installed package).
SOURCE_CSV = Path(__file__).resolve().parents[2] / "shared" / "paper" / "published_metrics.csv"
#: metric in the CSV -> (MaterialSpec field, factor from the CSV unit to SI)
CONDITION_FIELDS = {
    "test_pressure": ("test_pressure_pa", {"kPa": 1e3}),
    "step_load": ("step_load_n", {"N": 1.0}),
    "start_tension": ("start_tension_n", {"N": 1.0}),
}


def _condition_rows():
    with METRICS_CSV.open(newline="", encoding="utf-8") as f:
        return [row for row in csv.DictReader(f) if row["kind"] == "condition"]


def test_the_shipped_paper_numbers_are_the_source_table():
    if not SOURCE_CSV.is_file():
        pytest.skip(f"{SOURCE_CSV} (the source copy) is not beside this checkout")
    assert METRICS_CSV.read_bytes() == SOURCE_CSV.read_bytes()


def test_codes_are_table_4_in_order():
    assert tuple(MATERIALS) == ("TP", "P", "PR", "TPC", "PC", "PCS", "TFC", "FC")
    assert {row["material"] for row in _condition_rows()} == set(MATERIALS)


def test_every_condition_matches_published_table_4():
    rows = _condition_rows()
    assert len(rows) == 3 * len(MATERIALS)  # every material has all three conditions
    for row in rows:
        field, units = CONDITION_FIELDS[row["metric"]]
        assert row["source"] == "Table 4"
        expected = float(row["value"]) * units[row["unit"]]
        assert getattr(MATERIALS[row["material"]], field) == pytest.approx(expected, rel=1e-12), row


def test_construction_fields():
    for spec in MATERIALS.values():
        assert isinstance(spec, MaterialSpec)
        assert spec.construction and spec.name and spec.label
        # plastic muscles have a film thickness, composites a textile, PR both
        assert (spec.film_thickness_m is not None) == (spec.code in ("TP", "P", "PR"))
        assert (spec.textile is not None) == (spec.code != "TP" and spec.code != "P")
    assert MATERIALS["TP"].film_thickness_m == pytest.approx(60e-6)
    assert MATERIALS["FC"].textile_areal_density_kg_per_m2 == pytest.approx(0.100)
    assert MATERIALS["PCS"].fiber_orientation == "45-45"
    assert GEOMETRY is PAPER_GEOMETRY and float(GEOMETRY.flat_length_m) == pytest.approx(0.06)


def test_conditions_and_material_for_the_sidecar():
    spec = MATERIALS["PCS"]
    assert spec.data_material().code == "PCS"
    c = spec.conditions()
    assert (c.fluid, c.test_pressure_pa, c.step_load_n, c.start_tension_n) == ("water", 200e3, 15.0, 40.0)


def test_lookup_is_case_insensitive_and_passes_specs_through():
    assert material("fc") is MATERIALS["FC"]
    assert material(MATERIALS["TP"]) is MATERIALS["TP"]


def test_unknown_code_suggests_a_near_one():
    with pytest.raises(PeanoBayesInputError, match=r"unknown material code 'TFX' \(did you mean 'TFC'\?\)"):
        material("TFX")
    with pytest.raises(PeanoBayesInputError, match="expected one of TP, P, PR, TPC, PC, PCS, TFC, FC"):
        material("nylon")
