"""Property tests of the rig data reader.

Corrupt a valid dataset at random: ``load`` either succeeds (with a dataset that keeps the format's promises)
or raises ``DataFormatError``, never any other exception. Any valid dataset survives ``save`` then ``load``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from peano_bayes.data import Conditions, DataFormatError, Dataset, Material, Run, load, save
from peano_bayes.data.format import TESTS
from peano_bayes.physics.geometry import Geometry

MALFORMED = Path(__file__).parent / "malformed"
BASE_CSV = (MALFORMED / "valid.csv").read_text()
BASE_TOML = (MALFORMED / "valid.toml").read_text()
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

JUNK = st.one_of(
    st.sampled_from([
        "", " ", "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e999", "-1e999", "1e308", "-1e308",
        "1e-320", "abc", "0x10", "1_000", "\uff11", "\u0663", "1,5", '"', '""', '"1"', "\x00", "-0", "+0.0",
        ".", "e5", "1e", "--1", "None", "null", "true", "\ufeff1", "\r", "\n", "9" * 400, "load_cycle",
        "step", "-1", "2.5",
        "99999999999999999999999", "0.49999999999999994", "2000.0000000000002", "-10.000000000000002",
    ]),
    st.text(max_size=12),
    st.floats().map(repr),
    st.integers().map(str),
)
TOML_JUNK = st.one_of(
    st.sampled_from([
        "nan", "inf", "-inf", "0", "-1", "1.0", "4", "4.0", '"4"', '""', "true", "[1, 2]", "{a = 1}",
        "1979-05-27", "1e999", "0.9999999999999999", "1.0e-300", '"water"', "'x'", "", "=", "[",
        '"unterminated',
    ]),
    st.text(max_size=10),
)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def _check(directory: Path, csv_text: str | bytes, toml_text: str | bytes | None = BASE_TOML):
    """Write the pair and load it: a DataFormatError or a dataset that keeps the format's promises."""
    csv_path, toml_path = directory / "d.csv", directory / "d.toml"
    for path, content in ((csv_path, csv_text), (toml_path, toml_text)):
        if content is None:
            path.unlink(missing_ok=True)
        elif isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8", newline="")
    try:
        ds = load(csv_path)
    except DataFormatError as err:
        assert str(err) and Path(err.file).name in ("d.csv", "d.toml")
        if err.row is not None:
            size = csv_path.read_bytes() if err.file.endswith(".csv") else toml_path.read_bytes()
            assert 1 <= err.row <= size.count(b"\n") + size.count(b"\r") + 1
        return None
    assert isinstance(ds, Dataset) and ds.runs
    for run in ds.runs:
        assert run.test in TESTS and run.run >= 0 and len(run) >= 5
        assert np.all(np.diff(run.time_s) > 0)
        for signal in (run.time_s, run.pressure_pa, run.strain):
            assert np.isfinite(signal).all()
        assert not run.time_s.flags.writeable
    return ds


def _table(text: str) -> list[list[str]]:
    return [line.split(",") for line in text.splitlines()]


def _text(rows: list[list[str]]) -> str:
    return "\n".join(",".join(r) for r in rows) + "\n"


@st.composite
def corrupted_csv(draw) -> str:
    rows = _table(BASE_CSV)
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(
            ["cell", "cell", "cell", "drop", "duplicate", "swap_lines", "delete_column", "swap_header",
             "rename_header", "insert", "truncate"]
        ))
        if not rows:
            break
        i = draw(st.integers(0, len(rows) - 1))
        if op == "cell" and rows[i]:
            rows[i][draw(st.integers(0, len(rows[i]) - 1))] = draw(JUNK)
        elif op == "drop":
            del rows[i]
        elif op == "duplicate":
            rows.insert(i, list(rows[i]))
        elif op == "swap_lines":
            k = draw(st.integers(0, len(rows) - 1))
            rows[i], rows[k] = rows[k], rows[i]
        elif op in ("delete_column", "swap_header", "rename_header") and rows[0]:
            j = draw(st.integers(0, len(rows[0]) - 1))
            if op == "delete_column":
                rows = [[c for n, c in enumerate(r) if n != j] for r in rows]
            elif op == "swap_header":
                k = draw(st.integers(0, len(rows[0]) - 1))
                rows[0][j], rows[0][k] = rows[0][k], rows[0][j]
            else:
                rows[0][j] = draw(JUNK)
        elif op == "insert":
            rows.insert(i, draw(st.lists(JUNK, max_size=12)))
        elif op == "truncate":
            text = _text(rows)
            rows = _table(text[: draw(st.integers(0, len(text)))])
    return _text(rows)


@FUZZ
@given(csv_text=corrupted_csv())
def test_corrupted_csv_loads_or_raises_data_format_error(workdir, csv_text):
    _check(workdir, csv_text)


@st.composite
def corrupted_toml(draw) -> str:
    lines = BASE_TOML.splitlines()
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["value", "value", "drop", "duplicate", "rename", "insert", "truncate"]))
        if not lines:
            break
        i = draw(st.integers(0, len(lines) - 1))
        if op == "value" and "=" in lines[i]:
            lines[i] = lines[i].split("=", 1)[0] + "= " + draw(TOML_JUNK)
        elif op == "drop":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        elif op == "rename":
            word = draw(st.sampled_from(["material", "geometry", "n_tubes", "code", "fluid", "source", "mm"]))
            new = draw(st.sampled_from(["materials", "geometri", "x", "", "n tubes"]))
            lines[i] = lines[i].replace(word, new)
        elif op == "insert":
            lines.insert(i, draw(st.text(max_size=20)))
        elif op == "truncate":
            text = "\n".join(lines)
            lines = text[: draw(st.integers(0, len(text)))].splitlines()
    return "\n".join(lines) + "\n"


@FUZZ
@given(toml_text=corrupted_toml())
def test_corrupted_sidecar_loads_or_raises_data_format_error(workdir, toml_text):
    _check(workdir, BASE_CSV, toml_text)


@FUZZ
@given(
    which=st.sampled_from(["csv", "toml", "both"]),
    edits=st.lists(st.tuples(st.floats(0, 1), st.binary(max_size=4), st.integers(0, 3)), max_size=4),
)
def test_corrupted_bytes_load_or_raise_data_format_error(workdir, which, edits):
    """Raw byte edits: invalid UTF-8, NUL bytes, stray quotes, cut multi-byte characters."""

    def mangle(data: bytes) -> bytes:
        for where, insert, cut in edits:
            k = int(where * len(data))
            data = data[:k] + insert + data[k + cut :]
        return data

    csv_bytes, toml_bytes = BASE_CSV.encode(), BASE_TOML.encode()
    _check(
        workdir,
        mangle(csv_bytes) if which in ("csv", "both") else csv_bytes,
        mangle(toml_bytes) if which in ("toml", "both") else toml_bytes,
    )


def test_missing_files_are_data_format_errors(workdir):
    (workdir / "d.csv").write_text(BASE_CSV, encoding="utf-8", newline="")
    (workdir / "d.toml").unlink(missing_ok=True)
    with pytest.raises(DataFormatError, match="missing sidecar") as err:
        load(workdir / "d.csv")
    assert Path(err.value.file).name == "d.toml"
    with pytest.raises(DataFormatError, match="file not found"):
        load(workdir / "nothing_here.csv")
    (workdir / "dir.csv").mkdir()
    (workdir / "dir.toml").write_text(BASE_TOML)
    with pytest.raises(DataFormatError, match="directory"):
        load(workdir / "dir.csv")


# --- round trip of arbitrary valid datasets ---------------------------------------------------------------


def _floats(low: float, high: float):
    return st.floats(low, high, allow_nan=False, allow_infinity=False, allow_subnormal=False)


@st.composite
def runs(draw, key) -> Run:
    specimen, test, index = key
    n = draw(st.integers(5, 12))
    time_s = np.cumsum([draw(_floats(1e-3, 100.0)) for _ in range(n)]) - draw(_floats(0.0, 1e-3))
    time_s[0] = max(time_s[0], 0.0)

    def signal(low, high, may_be_missing=True):
        values = np.array([draw(_floats(low, high)) for _ in range(n)])
        if may_be_missing:
            values[np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))] = math.nan
        return values

    needs_force = test in ("load_cycle", "blocking")
    optional = {name: draw(st.one_of(st.none(), st.just(bounds))) for name, bounds in (
        ("supply_pa", (-1e4, 2e6)), ("flow_m3_per_s", (-9e-3, 9e-3)), ("load_n", (-100.0, 5000.0)))}
    return Run(
        specimen, test, index, time_s,
        pressure_pa=signal(-1e4, 2e6, False),
        strain=signal(-0.5, 0.5, False),
        force_n=signal(-100.0, 5000.0, not needs_force),
        **{name: None if bounds is None else signal(*bounds) for name, bounds in optional.items()},
    )


TEXT = st.text(st.characters(blacklist_categories=("Cs", "Cc", "Zs", "Zl", "Zp")), min_size=1, max_size=8)


@st.composite
def datasets(draw) -> Dataset:
    keys = draw(st.lists(st.tuples(TEXT, st.sampled_from(list(TESTS)), st.integers(0, 10**6)), min_size=1,
                         max_size=4, unique=True))
    return Dataset(
        material=Material(draw(TEXT), draw(st.text(min_size=1).filter(str.strip))),
        geometry=Geometry(draw(st.integers(1, 20)), draw(_floats(1e-5, 1.0)), draw(_floats(1e-5, 1.0)),
                          draw(_floats(0.0, 0.99))),
        conditions=Conditions(draw(TEXT), draw(_floats(1.0, 2e6)), draw(_floats(0.0, 1e4)),
                              draw(_floats(0.0, 1e4))),
        runs=[draw(runs(key)) for key in keys],
        provenance={"source": draw(TEXT), **draw(st.dictionaries(TEXT, st.text(), max_size=2))},
    )


def _optional_as_loaded(runs_, name):
    """An optional signal present in some run comes back as an all-NaN array in the runs without it."""
    return any(getattr(r, name) is not None for r in runs_)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ds=datasets())
def test_any_valid_dataset_survives_save_and_load(workdir, ds):
    back = load(save(ds, workdir / "roundtrip.csv"))
    assert back.material == ds.material and back.conditions.fluid == ds.conditions.fluid
    assert dict(back.provenance) == dict(ds.provenance)
    for part, names in (
        ("conditions", ("test_pressure_pa", "step_load_n", "start_tension_n")),
        ("geometry", ("tube_width_m", "tube_length_m", "channel_width_frac")),
    ):
        for name in names:
            x, y = getattr(getattr(ds, part), name), getattr(getattr(back, part), name)
            np.testing.assert_array_max_ulp(x, y, maxulp=1)
    assert back.geometry.n_tubes == ds.geometry.n_tubes
    assert [r.key for r in back.runs] == [r.key for r in ds.runs]
    for a, b in zip(ds.runs, back.runs, strict=True):
        np.testing.assert_array_equal(a.time_s, b.time_s)
        for name in ("pressure_pa", "strain", "force_n", "supply_pa", "flow_m3_per_s", "load_n"):
            x, y = getattr(a, name), getattr(b, name)
            if x is None:
                assert (y is None) != _optional_as_loaded(ds.runs, name)
                assert y is None or np.isnan(y).all()
                continue
            np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
            # float precision: scaling kPa <-> Pa and mL/s <-> m^3/s may move the last bit
            np.testing.assert_allclose(y, x, rtol=2.5e-16, atol=1e-290)
