"""The rig data format: every malformed fixture gives its exact error (library and command line); the valid
fixture loads in SI units, read-only, and survives save/load."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from peano_bayes.app.cli import main
from peano_bayes.data import Conditions, DataFormatError, Dataset, Material, Run, dataset_paths, load, save
from peano_bayes.data.format import COLUMNS, KEYS, TESTS, markdown_tables
from peano_bayes.physics.geometry import Geometry

HERE = Path(__file__).parent
MALFORMED = HERE / "malformed"
VALID = MALFORMED / "valid.csv"
DOCS = HERE.parent / "docs" / "data-format.md"
# ``python -m peano_bayes.app.cli`` runs cli.py as __main__, a second copy of the module whose command registry
# the subcommands never fill; the console script (and this) import it once, as ``peano_bayes.app.cli``.
CLI = [sys.executable, "-c", "import sys; from peano_bayes.app.cli import main; sys.exit(main())"]


class Case(NamedTuple):
    stem: str
    file: str  # name of the file the error names
    row: int | None
    column: str | None
    value: object
    expected: str  # a substring of err.expected
    message: str  # a substring of str(err)


CASES = [
    # -- files
    Case("does_not_exist", "does_not_exist.csv", None, None, None, "existing dataset CSV", "file not found"),
    Case("missing_sidecar", "missing_sidecar.toml", None, None, None, "missing_sidecar.toml next to",
         "missing sidecar"),
    Case("not_utf8_csv", "not_utf8_csv.csv", 8, "specimen", b"\xe9", "UTF-8", "not UTF-8 text"),
    Case("not_utf8_toml", "not_utf8_toml.toml", 3, None, b"\xe9", "UTF-8", "not UTF-8 text"),
    # -- CSV header
    Case("empty_file", "empty_file.csv", 1, None, None, "header line naming the columns", "empty file"),
    Case("empty_header", "empty_header.csv", 1, None, "", "header line naming the columns",
         "empty header line"),
    Case("empty_column_name", "empty_column_name.csv", 1, None, "", "a name for every column",
         "header field 11 has no column name"),
    Case("duplicate_column", "duplicate_column.csv", 1, "strain", None, "each name once", "duplicate column"),
    Case("unknown_column", "unknown_column.csv", 1, "forse_n", "forse_n", "one of the columns specimen",
         "unknown column (did you mean 'force_n'?)"),
    Case("semicolon_separated", "semicolon_separated.csv", 1, None,
         "specimen;test;run;time_s;pressure_kpa;strain;force_n;supply_kpa;flow_ml_s;load_n",
         "comma-separated columns", "the header is one field: the columns look separated by ';'"),
    Case("missing_column", "missing_column.csv", 1, "strain", None, "a header with specimen",
         "missing required column"),
    Case("header_only", "header_only.csv", None, None, None, "at least one run", "no data rows"),
    # -- CSV rows
    Case("wrong_field_count", "wrong_field_count.csv", 7, None, 11,
         "10 fields, as in the header; if the numbers use a decimal comma", "wrong number of fields"),
    Case("short_row", "short_row.csv", 10, None, 4, "10 fields", "wrong number of fields"),
    Case("unknown_test", "unknown_test.csv", 4, "test", "load_cylce", "one of load_cycle, blocking",
         "unknown test type (did you mean 'load_cycle'?)"),
    Case("empty_test", "empty_test.csv", 4, "test", "", "one of load_cycle", "empty cell"),
    Case("non_numeric", "non_numeric.csv", 5, "strain", "abc", "decimal number in [-0.5, 0.5]",
         "not a number"),
    Case("optional_non_numeric", "optional_non_numeric.csv", 10, "flow_ml_s", "n/a", "mL/s", "not a number"),
    Case("empty_needed_cell", "empty_needed_cell.csv", 3, "force_n", "", "decimal number in [-100, 5000] N",
         "every load_cycle row needs force_n"),
    Case("empty_specimen", "empty_specimen.csv", 9, "specimen", "", "non-empty text",
         "every step row needs specimen"),
    Case("nan_cell", "nan_cell.csv", 6, "pressure_kpa", "NaN", "[-10, 2000] kPa", "NaN or infinity"),
    Case("inf_cell", "inf_cell.csv", 7, "force_n", "-inf", "[-100, 5000] N", "NaN or infinity"),
    Case("overflow_cell", "overflow_cell.csv", 11, "supply_kpa", "1e999", "[-10, 2000] kPa", "not finite"),
    Case("strain_range", "strain_range.csv", 4, "strain", "0.8", "in [-0.5, 0.5]",
         "outside the physical range"),
    Case("pressure_below_range", "pressure_below_range.csv", 8, "pressure_kpa", "-25", "in [-10, 2000] kPa",
         "outside the physical range"),
    Case("pressure_above_range", "pressure_above_range.csv", 12, "pressure_kpa", "3000", "in [-10, 2000] kPa",
         "outside the physical range"),
    Case("negative_time", "negative_time.csv", 2, "time_s", "-0.5", "in [0, 1e6] s", "outside the physical"),
    Case("negative_run", "negative_run.csv", 3, "run", "-1", "whole number >= 0", "not a valid run index"),
    Case("non_integer_run", "non_integer_run.csv", 3, "run", "1.5", "whole number >= 0",
         "not a valid run index"),
    Case("time_not_increasing", "time_not_increasing.csv", 5, "time_s", "0.75", "> 1.0",
         "time_s not strictly increasing within run (specimen 'A', test 'load_cycle', run 0), after row 4"),
    Case("duplicate_row", "duplicate_row.csv", 6, "time_s", "1.5", "one row per sample",
         "duplicate sample: same specimen, test, run and time_s as row 5"),
    Case("too_few_samples", "too_few_samples.csv", 8, "run", 3, "at least 5 samples",
         "run (specimen 'B', test 'step', run 1) has too few samples"),
    Case("added_compliance_varies", "added_compliance_varies.csv", 5, "added_compliance_mm_per_n", "0.03",
         "0.02 mm/N as in row 2: one value per run",
         "added_compliance_mm_per_n differs between the rows of run (specimen 'A', test 'load_cycle', run 0)"),
    Case("two_errors_first_row_wins", "two_errors_first_row_wins.csv", 3, "strain", "0.9", "[-0.5, 0.5]",
         "outside the physical range"),
    Case("two_errors_same_row", "two_errors_same_row.csv", 4, "pressure_kpa", "y", "kPa", "not a number"),
    Case("blank_line_shifts_rows", "blank_line_shifts_rows.csv", 6, "force_n", "1e4", "[-100, 5000] N",
         "outside the physical range"),
    # -- sidecar
    Case("invalid_toml", "invalid_toml.toml", 6, None, "n_tubes = 4 tubes", "valid TOML", "not valid TOML"),
    Case("missing_section", "missing_section.toml", None, "geometry", None, "keys n_tubes, tube_width_mm",
         "missing section [geometry]"),
    Case("missing_key", "missing_key.toml", 5, "geometry.tube_length_mm", None, "a number > 0 (mm)",
         "missing key tube_length_mm in [geometry]"),
    Case("missing_provenance_source", "missing_provenance_source.toml", 17, "provenance.source", None,
         "non-empty string", "missing key source in [provenance]"),
    Case("unknown_key", "unknown_key.toml", 7, "geometry.tube_widht_mm", "tube_widht_mm", "one of n_tubes",
         "unknown key in [geometry] (did you mean 'tube_width_mm'?)"),
    Case("unknown_section", "unknown_section.toml", 11, "condition", "condition", "[conditions]",
         "unknown section (did you mean [conditions]?)"),
    Case("section_not_table", "section_not_table.toml", 1, "material", "FC", "a [material] table",
         "material must be a [material] table"),
    Case("wrong_type", "wrong_type.toml", 6, "geometry.n_tubes", "4", "an integer >= 1", "wrong type"),
    Case("wrong_type_float_for_int", "wrong_type_float_for_int.toml", 6, "geometry.n_tubes", 4.0,
         "an integer", "wrong type"),
    Case("wrong_type_provenance", "wrong_type_provenance.toml", 19, "provenance.year", 2016, "a string",
         "wrong type"),
    Case("empty_material_code", "empty_material_code.toml", 2, "material.code", "", "non-empty string",
         "empty string"),
    Case("n_tubes_zero", "n_tubes_zero.toml", 6, "geometry.n_tubes", 0, "an integer >= 1",
         "outside the valid range"),
    Case("tube_width_not_positive", "tube_width_not_positive.toml", 7, "geometry.tube_width_mm", -15.0,
         "a number > 0 (mm)", "outside the valid range"),
    Case("tube_length_zero", "tube_length_zero.toml", 8, "geometry.tube_length_mm", 0.0, "> 0 (mm)",
         "outside the valid range"),
    Case("channel_frac_one", "channel_frac_one.toml", 9, "geometry.channel_width_frac", 1.0, "in [0, 1)",
         "outside the valid range"),
    Case("test_pressure_not_positive", "test_pressure_not_positive.toml", 13, "conditions.test_pressure_kpa",
         0.0, "in (0, 2000] (kPa)", "outside the valid range"),
    Case("test_pressure_nan", "test_pressure_nan.toml", 13, "conditions.test_pressure_kpa", math.nan,
         "(0, 2000] (kPa)", "not a finite number"),
]
IDS = [c.stem for c in CASES]


def test_every_fixture_has_a_case():
    stems = {p.stem for p in MALFORMED.glob("*.csv")} | {p.stem for p in MALFORMED.glob("*.toml")}
    assert stems - {"valid"} == {c.stem for c in CASES} - {"does_not_exist"}
    assert len(CASES) >= 28


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_load_reports_the_exact_problem(case: Case):
    with pytest.raises(DataFormatError) as info:
        load(MALFORMED / f"{case.stem}.csv")
    err = info.value
    assert isinstance(err, ValueError)
    assert Path(err.file).name == case.file
    assert (err.row, err.column) == (case.row, case.column)
    if isinstance(case.value, float) and math.isnan(case.value):
        assert math.isnan(err.value)
    else:
        assert err.value == case.value and type(err.value) is type(case.value)
    assert case.expected in err.expected
    assert case.message in str(err)
    assert str(err).startswith(err.file)
    if case.row is not None:
        assert f"row {case.row}" in str(err)
    if case.column is not None:
        assert f"column '{case.column}'" in str(err)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_check_command_exits_2_with_one_line(case: Case, capsys):
    assert main(["check", str(MALFORMED / f"{case.stem}.csv")]) == 2
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert len(lines) == 1 and out == ""
    assert lines[0].startswith("peano-bayes check: error: ")
    assert case.file in lines[0] and case.message in lines[0]
    if case.row is not None:
        assert f"row {case.row}" in lines[0]


@pytest.mark.parametrize("stem", ["unknown_column", "time_not_increasing", "not_utf8_csv", "missing_key"])
def test_check_command_in_a_subprocess(stem):
    case = next(c for c in CASES if c.stem == stem)
    proc = subprocess.run([*CLI, "check", str(MALFORMED / f"{stem}.csv")], capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1
    assert case.file in lines[0] and f"row {case.row}" in lines[0] and f"column '{case.column}'" in lines[0]


# --- the valid fixture ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def valid() -> Dataset:
    return load(VALID)


def test_valid_metadata_in_si(valid):
    assert valid.material == Material("FC", "100 g/m2 fiberglass-silicone composite")
    g = valid.geometry
    assert isinstance(g, Geometry)
    assert (g.n_tubes, g.tube_width_m, g.tube_length_m, g.channel_width_frac) == (4, 0.015, 0.0495, 0.3)
    assert valid.conditions == Conditions("water", 200_000.0, 40.0, 40.0)
    assert dict(valid.provenance) == {"source": "hand-written reference dataset for the tests, not measured"}
    assert valid.source_path == VALID
    assert valid.tests == ("load_cycle", "step") and valid.specimens == ("A", "B")


def test_valid_runs_in_si(valid):
    cycle, step = valid.runs
    assert cycle.key == ("A", "load_cycle", 0) and step.key == ("B", "step", 1)
    assert valid.runs_of("load_cycle") == (cycle,) and valid.runs_of("blocking") == ()
    np.testing.assert_array_equal(cycle.time_s, [0.0, 0.5, 1.0, 1.5, 2.0, 2.5])
    kpa = [200.0, 200.1, 199.8, 200.2, 199.9, 200.0]
    np.testing.assert_allclose(cycle.pressure_pa, np.array(kpa) * 1000.0, rtol=1e-15)
    np.testing.assert_array_equal(cycle.force_n, [40.0, 55.5, 80.25, 110.0, 140.5, 160.0])
    np.testing.assert_array_equal(cycle.strain, [0.10, 0.08, 0.05, 0.02, 0.0, -0.01])
    for absent in (cycle.supply_pa, cycle.flow_m3_per_s, cycle.load_n):  # columns present, cells empty
        assert np.isnan(absent).all()
    assert np.isnan(step.force_n).all()
    assert step.pressure_pa[0] == -2500.0  # a few kPa below zero is sensor noise, not an error
    np.testing.assert_allclose(step.supply_pa, [80e3] + [500e3] * 5, rtol=1e-15)
    np.testing.assert_allclose(step.flow_m3_per_s, [0.0, 12.5e-6, 20e-6, 15e-6, 8e-6, 2e-6], rtol=1e-15)
    np.testing.assert_array_equal(step.load_n, [40.0] * 6)
    assert len(step) == 6 and step.duration_s == pytest.approx(0.05)


def test_valid_is_immutable(valid):
    run = valid.runs[0]
    for name in ("time_s", "pressure_pa", "strain", "force_n", "supply_pa", "flow_m3_per_s", "load_n"):
        arr = getattr(run, name)
        assert arr.dtype == np.float64 and not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.time_s = np.zeros(6)
    with pytest.raises(dataclasses.FrozenInstanceError):
        valid.runs = ()
    with pytest.raises(TypeError):
        valid.provenance["source"] = "changed"


def test_run_copies_its_inputs():
    t = np.arange(5.0)
    run = Run("A", "stroke", 0, t, t, t * 0.01, [math.nan] * 5)
    t[0] = 99.0
    assert run.time_s[0] == 0.0 and run.supply_pa is None
    with pytest.raises(ValueError, match="samples"):
        Run("A", "stroke", 0, t, t[:4], t, t)


def test_path_forms(tmp_path):
    assert dataset_paths("data/FC") == (Path("data/FC.csv"), Path("data/FC.toml"))
    assert dataset_paths("data/FC.toml") == (Path("data/FC.csv"), Path("data/FC.toml"))
    assert dataset_paths("v1.2") == (Path("v1.2.csv"), Path("v1.2.toml"))
    assert load(MALFORMED / "valid").runs[0].key == ("A", "load_cycle", 0)
    assert load(str(MALFORMED / "valid.toml")).material.code == "FC"


def test_unknown_test_name_in_runs_of(valid):
    with pytest.raises(ValueError, match="did you mean 'stroke'"):
        valid.runs_of("strok")


def _copy_valid(tmp_path: Path, csv_text: str, stem: str = "d") -> Path:
    (tmp_path / f"{stem}.toml").write_text((MALFORMED / "valid.toml").read_text())
    path = tmp_path / f"{stem}.csv"
    path.write_text(csv_text, newline="")
    return path


def test_interleaved_runs_are_grouped_in_order_of_first_appearance(tmp_path):
    lines = VALID.read_text().splitlines()
    header, cycle, step = lines[0], lines[1:7], lines[7:13]
    body = [x for pair in zip(step, cycle, strict=True) for x in pair]
    ds = load(_copy_valid(tmp_path, "\n".join([header, *body]) + "\n"))
    assert [r.key for r in ds.runs] == [("B", "step", 1), ("A", "load_cycle", 0)]
    np.testing.assert_array_equal(ds.runs[1].time_s, load(VALID).runs[0].time_s)


def test_lenient_about_layout_strict_about_content(tmp_path):
    """Column order, spaces around cells, a byte-order mark, CRLF line ends and blank lines are fine."""
    lines = VALID.read_text().splitlines()
    fields = [line.split(",") for line in lines]
    order = [5, 0, 9, 1, 2, 3, 4, 6, 7, 8]
    text = "\r\n".join(" , ".join(f[i] for i in order) for f in fields) + "\r\n\r\n"
    path = tmp_path / "d.csv"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / "d.toml").write_text((MALFORMED / "valid.toml").read_text())
    ds, ref = load(path), load(VALID)
    for a, b in zip(ds.runs, ref.runs, strict=True):
        np.testing.assert_array_equal(a.pressure_pa, b.pressure_pa)
        np.testing.assert_array_equal(a.load_n, b.load_n)
    # CRLF does not shift row numbers
    path.write_bytes(text.replace("0.08", "0.9", 1).encode())
    with pytest.raises(DataFormatError) as info:
        load(path)
    assert (info.value.row, info.value.column) == (3, "strain")


def test_optional_columns_absent_are_none(tmp_path):
    lines = [",".join(line.split(",")[:7]) for line in VALID.read_text().splitlines()]
    ds = load(_copy_valid(tmp_path, "\n".join(lines) + "\n"))
    assert all(r.supply_pa is None and r.flow_m3_per_s is None and r.load_n is None for r in ds.runs)


# --- save -------------------------------------------------------------------------------------------------


def _assert_same(a: Dataset, b: Dataset):
    assert a.material == b.material and a.conditions == b.conditions
    assert dict(a.provenance) == dict(b.provenance)
    for name in ("n_tubes", "tube_width_m", "tube_length_m", "channel_width_frac"):
        assert getattr(a.geometry, name) == pytest.approx(getattr(b.geometry, name), rel=1e-15)
    assert len(a.runs) == len(b.runs)
    for ra, rb in zip(a.runs, b.runs, strict=True):
        assert ra.key == rb.key
        for name in ("time_s", "pressure_pa", "strain", "force_n", "supply_pa", "flow_m3_per_s", "load_n"):
            xa, xb = getattr(ra, name), getattr(rb, name)
            assert (xa is None) == (xb is None), name
            if xa is not None:
                # float precision: kPa <-> Pa and mL/s <-> m^3/s scaling may move the last bit
                np.testing.assert_array_max_ulp(xa, xb, maxulp=1)
                np.testing.assert_array_equal(np.isnan(xa), np.isnan(xb))


def test_save_load_round_trip(valid, tmp_path):
    out = save(valid, tmp_path / "sub" / "FC.csv")
    assert out == tmp_path / "sub" / "FC.csv" and (tmp_path / "sub" / "FC.toml").is_file()
    back = load(out)
    _assert_same(valid, back)
    assert back.source_path == out
    assert sorted(p.name for p in out.parent.iterdir()) == ["FC.csv", "FC.toml"]  # no temporaries left
    # and again: text written from a loaded dataset reads back the same
    _assert_same(back, load(save(back, tmp_path / "again")))


def test_save_round_trips_full_precision_and_missing_columns(tmp_path, rng):
    n = 50
    t = np.cumsum(rng.uniform(1e-3, 1.0, n))
    runs = [
        Run("s 1, \"quoted\"", "blocking", 2, t, rng.uniform(-1e4, 2e6, n), rng.uniform(-0.5, 0.5, n),
            rng.uniform(-100, 5000, n)),
        Run("s2", "stroke", 0, t, rng.uniform(0, 2e6, n), rng.uniform(-0.5, 0.5, n), np.full(n, np.nan)),
    ]
    ds = Dataset(Material("X", "test material"), Geometry(3, 0.0123456789, 0.0456789, 0.123456789),
                 Conditions("air", 123456.789, 1.0 / 3.0, 0.0), runs, {"source": "rng", "note": "ü ✓"})
    _assert_same(ds, load(save(ds, tmp_path / "x.csv")))
    np.testing.assert_array_equal(load(tmp_path / "x").runs[0].time_s, t)  # unscaled columns are exact


def test_save_refuses_an_invalid_dataset_and_writes_nothing(valid, tmp_path):
    target = save(valid, tmp_path / "FC.csv")
    before = target.read_bytes(), target.with_suffix(".toml").read_bytes()
    backwards = dataclasses.replace(valid.runs[0], time_s=valid.runs[0].time_s[::-1])
    with pytest.raises(DataFormatError) as info:
        save(dataclasses.replace(valid, runs=[backwards]), target)
    assert info.value.file == str(target) and info.value.row == 3 and info.value.column == "time_s"
    assert (target.read_bytes(), target.with_suffix(".toml").read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FC.csv", "FC.toml"]


def test_interrupted_save_leaves_old_files_and_no_temporaries(valid, tmp_path, monkeypatch):
    target = save(valid, tmp_path / "FC.csv")
    before = target.read_bytes()
    changed = dataclasses.replace(valid, material=Material("FC", "renamed"))
    calls = []

    def interrupted_replace(src, dst):
        calls.append(dst)
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted_replace)
    with pytest.raises(KeyboardInterrupt):
        save(changed, target)
    monkeypatch.undo()
    assert calls and target.read_bytes() == before and load(target).material.name == valid.material.name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FC.csv", "FC.toml"]


# --- the check command and the docs -----------------------------------------------------------------------


def test_check_command_summary_and_json(capsys):
    assert main(["check", str(VALID), "--json"]) == 0
    out, err = capsys.readouterr()
    lines = err.splitlines()  # under --json the summary a person reads goes to stderr
    assert "FC (100 g/m2 fiberglass-silicone composite)" in lines[0]
    assert any("load_cycle" in line and "6 samples" in line for line in lines)
    facts = json.loads(out)  # and stdout holds the JSON object alone
    assert facts["material"] == {"code": "FC", "name": "100 g/m2 fiberglass-silicone composite"}
    assert facts["geometry"]["tube_width_m"] == 0.015 and facts["geometry"]["n_tubes"] == 4
    assert facts["conditions"]["test_pressure_pa"] == 200_000.0
    assert facts["tests"]["step"] == {"runs": 1, "samples": 6, "specimens": ["B"], "time_s": [0.0, 0.05],
                                      "longest_run_s": 0.05}
    assert facts["specimens"] == ["A", "B"]


def test_check_command_in_a_subprocess_json():
    proc = subprocess.run([*CLI, "check", str(VALID), "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.splitlines()[-1])["tests"]["load_cycle"]["runs"] == 1


def test_docs_follow_the_format_table():
    docs = DOCS.read_text()
    assert markdown_tables() in docs, "paste peano_bayes.data.format.markdown_tables() into the docs"
    for test in TESTS:
        assert f"`{test}`" in docs
    for item in [*COLUMNS, *KEYS]:
        assert f"`{item.name}`" in docs
    for kind in ERROR_KINDS:
        assert kind in docs, kind
        assert any(kind in c.message for c in CASES), kind


#: Every kind of error the reader raises: each is documented and has a fixture.
ERROR_KINDS = (
    "file not found", "missing sidecar", "not UTF-8 text", "empty file", "empty header line",
    "has no column name", "duplicate column", "unknown column", "missing required column", "no data rows",
    "wrong number of fields", "unknown test type", "empty cell", "not a number", "NaN or infinity",
    "not finite", "outside the physical range", "not a valid run index", "not strictly increasing",
    "duplicate sample", "too few samples", "differs between the rows of run", "not valid TOML", "missing section",
    "missing key", "unknown key",
    "unknown section", "must be a [", "wrong type", "empty string", "outside the valid range",
    "not a finite number",
)
