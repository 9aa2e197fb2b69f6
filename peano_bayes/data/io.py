"""Read and write rig datasets (``NAME.csv`` + ``NAME.toml``): :func:`load` and :func:`save`.

The reader is strict: the first problem, in file order, raises
:class:`~peano_bayes.errors.DataFormatError` naming the file, the row (1-based line number, header = 1),
the column (or sidecar key), the value seen and what was expected. The format itself (columns, units,
ranges, sidecar keys) is the table in :mod:`peano_bayes.data.format`.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w

from ..atomic import replacing, write_into
from ..errors import DataFormatError, did_you_mean
from ..physics.geometry import Geometry
from .dataset import Conditions, Dataset, Material, Run
from .format import (
    COLUMN_BY_NAME,
    COLUMNS,
    HEADER_COLUMNS,
    KEYS,
    MIN_SAMPLES_PER_RUN,
    OPEN_SECTIONS,
    PER_RUN_COLUMNS,
    SECTIONS,
    TESTS,
    Column,
    Key,
    keys_of,
)

__all__ = ["load", "save", "dataset_paths"]

_FLOAT = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_INT = re.compile(r"\+?\d+")
_NONFINITE = frozenset({"nan", "inf", "infinity"})
_HEADER_HINT = (
    "a header line naming the columns "
    + ", ".join(HEADER_COLUMNS)
    + " (optional: "
    + ", ".join(c.name for c in COLUMNS if not c.in_header)
    + ")"
)
_TOML_POSITION = re.compile(r"\s*\(at (?:line (\d+), column \d+|end of document)\)\s*$")


def dataset_paths(path: str | os.PathLike) -> tuple[Path, Path]:
    """``(csv_path, toml_path)`` of a dataset given its CSV path, its sidecar path or its stem."""
    p = Path(path)
    if not p.name or (p.is_dir() and not p.with_name(p.name + ".csv").exists()):  # a stem beside its result folder
        raise DataFormatError(
            "a directory, not a dataset",
            file=str(path) or "''",
            expected="a dataset CSV (or its stem) with its TOML sidecar",
        )
    suffix = p.suffix.lower()
    if p.is_file() and suffix not in (".csv", ".toml"):
        raise DataFormatError(f"not a dataset file (suffix {p.suffix!r})", file=str(path), expected="a .csv file")
    if suffix == ".csv":
        csv_path = p
    elif suffix == ".toml":
        csv_path = p.with_suffix(".csv")
    else:
        csv_path = p.with_name(p.name + ".csv")
    return csv_path, csv_path.with_suffix(".toml")


def load(path: str | os.PathLike) -> Dataset:
    """Read and validate a rig dataset; return it in SI units.

    **Arguments:** ``path``, the CSV file (``FC.csv``) or its stem (``FC``); the sidecar is the same stem with
    ``.toml``.

    **Returns:** a :class:`~peano_bayes.data.dataset.Dataset` whose runs are in order of first appearance,
    each in time order, with read-only float64 arrays (kPa -> Pa, mL/s -> m^3/s, mm -> m).

    **Raises:** :class:`~peano_bayes.errors.DataFormatError` (a ``ValueError``) for the first problem found:
    files first, then the CSV row by row, then whole runs, then the sidecar.
    """
    csv_path, toml_path = dataset_paths(path)
    return _read(csv_path, toml_path, str(csv_path), str(toml_path))


def save(dataset: Dataset, path: str | os.PathLike) -> Path:
    """Write ``dataset`` as ``path`` (``.csv``, or a stem) plus its ``.toml`` sidecar; return the CSV path.

    Values are converted back to the file units and written with ``repr`` precision, so :func:`load`
    returns the same arrays to float precision; NaN becomes an empty cell; an optional signal that is
    ``None`` in every run has no column. Each file is written to a temporary file in the same directory
    and moved into place with ``os.replace``, so an interrupted save never leaves a half-written file.
    The written text is read back before it replaces anything: a dataset that breaks the format raises
    ``DataFormatError`` and writes nothing.
    """
    csv_path, toml_path = dataset_paths(path)
    csv_text = _csv_text(dataset)
    toml_text = tomli_w.dumps(_sidecar_document(dataset))
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    # Both files are written and checked before either replaces anything; on any failure both temporaries go.
    with replacing(csv_path) as tmp_csv, replacing(toml_path) as tmp_toml:
        write_into(tmp_csv, csv_text.encode("utf-8"))
        write_into(tmp_toml, toml_text.encode("utf-8"))
        _read(tmp_csv, tmp_toml, str(csv_path), str(toml_path))
    return csv_path


# --- reading ------------------------------------------------------------------------------------------------


def _read(csv_path: Path, toml_path: Path, csv_name: str, toml_name: str) -> Dataset:
    csv_bytes = _read_bytes(csv_path, csv_name)
    if not toml_path.is_file():
        raise DataFormatError(
            "missing sidecar: a dataset is a CSV plus a TOML file with the same stem",
            file=toml_name,
            expected=f"{Path(toml_name).name} next to {Path(csv_name).name}, with sections "
            + ", ".join(f"[{s}]" for s in SECTIONS),
        )
    toml_bytes = _read_bytes(toml_path, toml_name)
    runs = _parse_csv(_decode(csv_bytes, csv_name, csv_header=True), csv_name)
    material, geometry, conditions, provenance = _parse_sidecar(_decode(toml_bytes, toml_name), toml_name)
    return Dataset(
        material=material,
        geometry=geometry,
        conditions=conditions,
        runs=runs,
        provenance=provenance,
        source_path=Path(csv_name),
    )


def _read_bytes(path: Path, name: str) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise DataFormatError(
            "file not found", file=name, expected="an existing dataset CSV with its TOML sidecar next to it"
        ) from None
    except IsADirectoryError:
        raise DataFormatError("a directory, not a file", file=name, expected="a dataset CSV file") from None
    except OSError as err:
        raise DataFormatError(f"cannot read the file ({err.strerror})", file=name) from None


def _decode(data: bytes, name: str, *, csv_header: bool = False) -> str:
    """UTF-8 (a byte-order mark is dropped) -> text; the error names the line and, in a CSV, the column."""
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        row = data.count(b"\n", 0, err.start) + 1
        column = None
        if csv_header and row > 1:
            line_start = data.rfind(b"\n", 0, err.start) + 1
            index = data[line_start : err.start].decode("utf-8", "replace").count(",")
            header = data.split(b"\n", 1)[0].decode("utf-8", "replace").split(",")
            if index < len(header):
                column = header[index].strip()
        raise DataFormatError(
            "not UTF-8 text",
            file=name,
            row=row,
            column=column,
            value=data[err.start : err.end],
            expected="a UTF-8 encoded text file (save or export it as UTF-8)",
        ) from None


@dataclass
class _RunRows:
    """The rows of one run as they are read: first line number, values per column, times seen -> line."""

    first_row: int
    values: dict[str, list] = field(default_factory=dict)
    times: dict[float, int] = field(default_factory=dict)
    last_time: float = -math.inf
    last_row: int = 0


def _parse_csv(text: str, name: str) -> tuple[Run, ...]:
    if not text.strip():
        raise DataFormatError(
            "empty file: no header line",
            file=name,
            row=1,
            expected=_HEADER_HINT,
        )
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        names = [h.strip() for h in next(reader)]
        header_lines = reader.line_num
        columns = _check_header(names, name)
        runs = _parse_rows(reader, names, columns, header_lines, name)
    except csv.Error as err:
        raise DataFormatError(
            f"unreadable CSV ({err})", file=name, row=reader.line_num, expected="comma-separated values"
        ) from None
    return runs


def _check_header(names: list[str], name: str) -> list[Column]:
    if not any(names):
        raise DataFormatError("empty header line", file=name, row=1, value="", expected=_HEADER_HINT)
    separator = next((sep for sep in (";", "\t", "|") if len(names) == 1 and sep in names[0]), None)
    if separator is not None:
        raise DataFormatError(
            f"the header is one field: the columns look separated by {separator!r}",
            file=name,
            row=1,
            value=names[0],
            expected="comma-separated columns (save the sheet as CSV with ',' between fields and '.' as decimal point)",
        )
    seen: set[str] = set()
    for position, col in enumerate(names, start=1):
        if not col:
            raise DataFormatError(
                f"header field {position} has no column name",
                file=name,
                row=1,
                value="",
                expected="a name for every column (no empty or trailing fields)",
            )
        if col in seen:
            raise DataFormatError("duplicate column", file=name, row=1, column=col, expected="each name once")
        seen.add(col)
        if col not in COLUMN_BY_NAME:
            raise DataFormatError(
                "unknown column" + did_you_mean(col, COLUMN_BY_NAME),
                file=name,
                row=1,
                column=col,
                value=col,
                expected="one of the columns " + ", ".join(c.name for c in COLUMNS),
            )
    for required in HEADER_COLUMNS:
        if required not in seen:
            raise DataFormatError(
                "missing required column",
                file=name,
                row=1,
                column=required,
                expected="a header with " + ", ".join(HEADER_COLUMNS),
            )
    return [COLUMN_BY_NAME[n] for n in names]


def _parse_rows(
    reader, names: list[str], columns: list[Column], header_lines: int, name: str
)  -> tuple[Run, ...]:
    n_fields = len(names)
    test_index = names.index("test")
    cells = [(i, c) for i, c in enumerate(columns) if c.name != "test"]
    float_columns = [c.name for c in columns if c.kind == "float"]
    runs: dict[tuple[str, str, int], _RunRows] = {}
    previous_line = header_lines
    for fields in reader:
        row, previous_line = previous_line + 1, reader.line_num
        if not fields or (len(fields) == 1 and not fields[0].strip()):
            continue  # blank line
        if len(fields) != n_fields:
            comma = "; if the numbers use a decimal comma (0,5 for 0.5), write them with '.'"
            raise DataFormatError(
                "wrong number of fields",
                file=name,
                row=row,
                value=len(fields),
                expected=f"{n_fields} fields, as in the header" + (comma if len(fields) > n_fields else ""),
            )
        test = fields[test_index].strip()
        if test not in TESTS:
            raise DataFormatError(
                ("empty cell" if not test else "unknown test type" + did_you_mean(test, TESTS)),
                file=name,
                row=row,
                column="test",
                value=test,
                expected="one of " + ", ".join(TESTS),
            )
        values: dict[str, object] = {"test": test}
        for i, col in cells:
            cell = fields[i].strip()
            if not cell:
                if test in col.needed_by:
                    raise DataFormatError(
                        f"empty cell, but every {test} row needs {col.name}",
                        file=name,
                        row=row,
                        column=col.name,
                        value="",
                        expected=_describe_cell(col),
                    )
                values[col.name] = math.nan
                continue
            values[col.name] = _parse_cell(cell, col, name, row)
        key = (values["specimen"], test, values["run"])
        acc = runs.get(key)
        if acc is None:
            acc = runs[key] = _RunRows(first_row=row, values={c: [] for c in float_columns})
        time = values["time_s"]
        if time in acc.times:
            raise DataFormatError(
                f"duplicate sample: same specimen, test, run and time_s as row {acc.times[time]}",
                file=name,
                row=row,
                column="time_s",
                value=fields[names.index("time_s")].strip(),
                expected="one row per sample",
            )
        if time < acc.last_time:
            raise DataFormatError(
                f"time_s not strictly increasing within run {_run_label(key)}, after row {acc.last_row}",
                file=name,
                row=row,
                column="time_s",
                value=fields[names.index("time_s")].strip(),
                expected=f"> {acc.last_time!r}",
            )
        acc.times[time] = row
        acc.last_time, acc.last_row = time, row
        for c in float_columns:
            acc.values[c].append(values[c])
    if not runs:
        raise DataFormatError(
            "no data rows after the header",
            file=name,
            expected=f"at least one run of at least {MIN_SAMPLES_PER_RUN} samples",
        )
    for key, acc in runs.items():
        for c in PER_RUN_COLUMNS & set(float_columns):
            values, rows = acc.values[c], list(acc.times.values())
            filled = [i for i, v in enumerate(values) if v == v]
            odd = next((i for i, v in enumerate(values) if filled and not v == values[filled[0]]), None)
            if odd is not None:
                first = values[filled[0]]
                raise DataFormatError(
                    f"{c} differs between the rows of run {_run_label(key)}",
                    file=name,
                    row=rows[odd],
                    column=c,
                    value="" if values[odd] != values[odd] else f"{values[odd]:g}",
                    expected=f"{first:g} {COLUMN_BY_NAME[c].unit} as in row {rows[filled[0]]}: one value per run",
                )
        if len(acc.times) < MIN_SAMPLES_PER_RUN:
            raise DataFormatError(
                f"run {_run_label(key)} has too few samples",
                file=name,
                row=acc.first_row,
                column="run",
                value=len(acc.times),
                expected=f"at least {MIN_SAMPLES_PER_RUN} samples per run",
            )
    return tuple(_build_run(key, acc, float_columns) for key, acc in runs.items())


def _parse_cell(cell: str, col: Column, name: str, row: int):
    if col.kind == "text":
        return cell
    if col.kind == "int":
        if not _INT.fullmatch(cell):
            raise DataFormatError(
                "not a valid run index", file=name, row=row, column=col.name, value=cell,
                expected=_describe_cell(col),
            )
        value = int(cell)
    elif _FLOAT.fullmatch(cell):
        value = float(cell)
        if not math.isfinite(value):
            raise DataFormatError(
                "number too large (not finite)", file=name, row=row, column=col.name, value=cell,
                expected=_describe_cell(col),
            )
    elif cell.lower().lstrip("+-") in _NONFINITE:
        raise DataFormatError(
            "NaN or infinity is not a measurement (leave the cell empty where the test does not measure it)",
            file=name, row=row, column=col.name, value=cell, expected=_describe_cell(col),
        )
    else:
        raise DataFormatError(
            "not a number", file=name, row=row, column=col.name, value=cell, expected=_describe_cell(col)
        )
    if col.range is not None and value not in col.range:
        raise DataFormatError(
            f"{col.name} outside the physical range", file=name, row=row, column=col.name, value=cell,
            expected=_describe_cell(col),
        )
    return value


def _describe_cell(col: Column) -> str:
    if col.kind == "text":
        return "a non-empty text" if col.name != "test" else "one of " + ", ".join(TESTS)
    kind = "a whole number" if col.kind == "int" else "a decimal number"
    unit = f" {col.unit}" if col.unit != "-" else ""
    return f"{kind} {col.range}{unit}" if col.range is not None else kind + unit


def _run_label(key: tuple[str, str, int]) -> str:
    specimen, test, run = key
    return f"(specimen {specimen!r}, test {test!r}, run {run})"


def _build_run(key: tuple[str, str, int], acc: _RunRows, float_columns: list[str]) -> Run:
    specimen, test, run = key
    signals = {}
    for c in float_columns:
        column = COLUMN_BY_NAME[c]
        signals[column.field] = column.to_si(np.asarray(acc.values[c], dtype=np.float64))
    return Run(specimen=specimen, test=test, run=run, **signals)


def _parse_sidecar(text: str, name: str) -> tuple[Material, Geometry, Conditions, dict[str, str]]:
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        message = str(err)
        match = _TOML_POSITION.search(message)
        lines = text.splitlines()
        row = int(match.group(1)) if match and match.group(1) else max(len(lines), 1)
        detail = message[: match.start()] if match else message
        line = lines[row - 1].strip() if 0 < row <= len(lines) else ""
        raise DataFormatError(
            f"not valid TOML ({detail})",
            file=name,
            row=row,
            value=line[:80] if line else None,
            expected="valid TOML (https://toml.io), e.g. key = 1.0 or key = \"text\" under [section] headers",
        ) from None
    for section in document:
        if section not in SECTIONS:
            raise DataFormatError(
                "unknown section" + did_you_mean(section, SECTIONS, brackets=True),
                file=name,
                row=_toml_line(text, section),
                column=section,
                value=section,
                expected="the sections " + ", ".join(f"[{s}]" for s in SECTIONS),
            )
    values: dict[str, object] = {}
    provenance: dict[str, str] = {}
    for section in SECTIONS:
        specs = keys_of(section)
        key_names = [k.name for k in specs]
        if section not in document:
            raise DataFormatError(
                f"missing section [{section}]",
                file=name,
                column=section,
                expected=f"a [{section}] table with keys {', '.join(key_names)}",
            )
        content = document[section]
        if not isinstance(content, dict):
            raise DataFormatError(
                f"{section} must be a [{section}] table",
                file=name,
                row=_toml_line(text, None, section),
                column=section,
                value=content,
                expected=f"a [{section}] table with keys {', '.join(key_names)}",
            )
        for key, value in content.items():
            if key in key_names:
                continue
            if section in OPEN_SECTIONS:
                if not isinstance(value, str):
                    raise DataFormatError(
                        "wrong type",
                        file=name,
                        row=_toml_line(text, section, key),
                        column=f"{section}.{key}",
                        value=value,
                        expected=f"a string (every [{section}] value is text)",
                    )
                continue
            raise DataFormatError(
                f"unknown key in [{section}]" + did_you_mean(key, key_names),
                file=name,
                row=_toml_line(text, section, key),
                column=f"{section}.{key}",
                value=key,
                expected="one of " + ", ".join(key_names),
            )
        for spec in specs:
            if spec.name not in content:
                if spec.required:
                    raise DataFormatError(
                        f"missing key {spec.name} in [{section}]",
                        file=name,
                        row=_toml_line(text, section),
                        column=spec.path,
                        expected=f"{spec.name} = {spec.describe()}: {spec.meaning}",
                    )
                continue
            row = _toml_line(text, section, spec.name)
            values[spec.path] = _check_key(spec, content[spec.name], name, row)
        if section in OPEN_SECTIONS:
            provenance = {k: v for k, v in content.items()}
    try:
        geometry = Geometry(**{k.field: k.to_si(values[k.path]) for k in keys_of("geometry")})
    except ValueError as err:  # pragma: no cover - the key checks above are stricter
        raise DataFormatError(str(err), file=name, column="geometry") from None
    material = Material(**{k.field: values[k.path] for k in keys_of("material")})
    conditions = Conditions(**{k.field: k.to_si(values[k.path]) for k in keys_of("conditions")})
    return material, geometry, conditions, provenance


def _check_key(spec: Key, value, name: str, row: int | None):
    def fail(message: str):
        return DataFormatError(
            message, file=name, row=row, column=spec.path, value=value, expected=spec.describe()
        )

    if spec.kind == "str":
        if not isinstance(value, str):
            raise fail("wrong type")
        if not value.strip():
            raise fail("empty string")
        return value
    number = isinstance(value, int) if spec.kind == "int" else isinstance(value, int | float)
    if isinstance(value, bool) or not number:
        raise fail("wrong type")
    if spec.kind == "float":
        value = float(value)
        if not math.isfinite(value):
            raise fail("not a finite number")
    if spec.range is not None and value not in spec.range:
        raise fail("outside the valid range")
    return value


def _toml_line(text: str, section: str | None, key: str | None = None) -> int | None:
    """Line number of ``[section]`` (``key`` None), of ``key =`` inside it, or of top-level ``key =``."""
    current = None
    key_pattern = None if key is None else re.compile(rf"\s*(['\"]?){re.escape(key)}\1\s*=")
    for number, line in enumerate(text.splitlines(), start=1):
        header = re.match(r"\s*\[\s*([^\[\]]+?)\s*\]", line)
        if header:
            current = header.group(1).strip("'\"")
            if key is None and current == section:
                return number
            continue
        if key_pattern is not None and current == section and key_pattern.match(line):
            return number
    return None


# --- writing ------------------------------------------------------------------------------------------------


def _csv_text(dataset: Dataset) -> str:
    present = [
        c for c in COLUMNS
        if c.in_header or c.kind != "float" or any(getattr(r, c.field) is not None for r in dataset.runs)
    ]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow([c.name for c in present])
    for run in dataset.runs:
        n = len(run)
        columns = []
        for c in present:
            if c.name == "specimen":
                columns.append([run.specimen] * n)
            elif c.name == "test":
                columns.append([run.test] * n)
            elif c.name == "run":
                columns.append([str(run.run)] * n)
            else:
                signal = getattr(run, c.field)
                if signal is None:
                    columns.append([""] * n)
                else:
                    columns.append([_format_float(x) for x in c.from_si(np.asarray(signal)).tolist()])
        writer.writerows(zip(*columns, strict=True))
    return out.getvalue()


def _format_float(x: float) -> str:
    """Shortest text that reads back as exactly ``x``; NaN -> empty cell."""
    return "" if x != x else repr(x)


def _sidecar_document(dataset: Dataset) -> dict:
    sources = {
        "material": lambda k: getattr(dataset.material, k.field),
        "geometry": lambda k: getattr(dataset.geometry, k.field),
        "conditions": lambda k: getattr(dataset.conditions, k.field),
        "provenance": lambda k: dataset.provenance.get(k.field),
    }
    document: dict[str, dict] = {section: {} for section in SECTIONS}
    for k in KEYS:
        value = sources[k.section](k)
        if value is None:
            continue
        if k.kind == "int":
            value = int(value)
        elif k.kind == "float":
            value = float(k.from_si(float(value)))
        document[k.section][k.name] = value
    for section in OPEN_SECTIONS:
        extra = dataset.provenance if section == "provenance" else {}
        document[section].update({key: v for key, v in extra.items() if key not in document[section]})
    return document

