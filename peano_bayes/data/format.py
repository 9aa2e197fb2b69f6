"""The rig data format in one place: every CSV column and sidecar key, unit, SI conversion, valid range.

The reader (:mod:`peano_bayes.data.io`), the writer and the user documentation (``docs/data-format.md``, whose
tables are :func:`markdown_tables`) all follow these tables; change the format here and nowhere else.

A dataset is ``NAME.csv`` (one row per sample, long form) plus ``NAME.toml`` (material, geometry, test
conditions, provenance). Numbers in the files are in the units named by the column or key (kPa, mL/s,
mm); the loaded :class:`~peano_bayes.data.dataset.Dataset` is in SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The rig tests (Veale, Xie, Anderson 2016, section 4 and Table 3), name -> what the rig does.
TESTS: dict[str, str] = {
    "load_cycle": "the rig slowly stretches and relaxes the muscle at constant pressure: force vs strain",
    "blocking": "the muscle is held at its unstretched length and pressurized: force vs pressure",
    "stroke": "the muscle is slowly pressurized and lifts a hanging load: strain vs pressure",
    "step": "the supply pressure steps and the muscle lifts an inertial load: strain, pressure vs time",
}

#: Fewest samples a run may have.
MIN_SAMPLES_PER_RUN = 5


@dataclass(frozen=True)
class Range:
    """A closed or half-open interval of valid values, in the unit of the column or key it belongs to."""

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False

    def __contains__(self, value: float) -> bool:
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __str__(self) -> str:
        if math.isinf(self.high):
            return f"{'>' if self.low_open else '>='} {_num(self.low)}"
        if math.isinf(self.low):
            return f"{'<' if self.high_open else '<='} {_num(self.high)}"
        left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
        return f"in {left}{_num(self.low)}, {_num(self.high)}{right}"


def _num(x: float) -> str:
    return f"{x:g}".replace("e+0", "e").replace("e+", "e")


@dataclass(frozen=True)
class Column:
    """One CSV column.

    **Fields:** ``name`` in the header; ``kind`` ``"text"``, ``"int"`` or ``"float"``; ``unit`` in the file;
    ``field``, the :class:`~peano_bayes.data.dataset.Run` attribute it becomes; ``si_unit`` of that attribute;
    ``si_exponent``, SI value = file value x 10**si_exponent; ``range`` of valid file values; ``in_header``,
    the header must name it; ``needed_by``, the tests whose rows must fill the cell (elsewhere empty -> NaN);
    ``meaning`` for the docs.
    """

    name: str
    kind: str
    unit: str
    field: str
    si_unit: str
    si_exponent: int
    range: Range | None
    in_header: bool
    needed_by: frozenset[str]
    meaning: str

    def to_si(self, value):
        """File units -> SI (exact powers of ten: multiply by 10**n or divide by 10**-n)."""
        return _scale(value, self.si_exponent)

    def from_si(self, value):
        """SI -> file units, the inverse of :meth:`to_si`."""
        return _scale(value, -self.si_exponent)


def _scale(value, exponent: int):
    if exponent == 0:
        return value
    return value * 10.0**exponent if exponent > 0 else value / 10.0**-exponent


_ALL = frozenset(TESTS)

#: The CSV columns, in the order the writer puts them.
COLUMNS: tuple[Column, ...] = (
    Column("specimen", "text", "-", "specimen", "-", 0, None, True, _ALL,
           "which physical muscle (the paper tested two of each material)"),
    Column("test", "text", "-", "test", "-", 0, None, True, _ALL,
           "the rig test: " + ", ".join(f"`{t}`" for t in TESTS)),
    Column("run", "int", "-", "run", "-", 0, Range(0), True, _ALL,
           "repeat index within specimen and test (the paper ran three)"),
    Column("time_s", "float", "s", "time_s", "s", 0, Range(0.0, 1e6), True, _ALL,
           "time since the start of the run, strictly increasing within a run"),
    Column("pressure_kpa", "float", "kPa", "pressure_pa", "Pa", 3, Range(-10.0, 2000.0), True, _ALL,
           "gauge pressure inside the muscle (down to -10 kPa is accepted as sensor noise around 0)"),
    Column("strain", "float", "-", "strain", "-", 0, Range(-0.5, 0.5), True, _ALL,
           "contraction strain, fraction of the flat length l0 (positive = shorter)"),
    Column("force_n", "float", "N", "force_n", "N", 0, Range(-100.0, 5000.0), True,
           frozenset({"load_cycle", "blocking"}),
           "tension at the load cell"),
    Column("supply_kpa", "float", "kPa", "supply_pa", "Pa", 3, Range(-10.0, 2000.0), False, frozenset(),
           "supply pressure upstream of the inlet restriction (step tests)"),
    Column("flow_ml_s", "float", "mL/s", "flow_m3_per_s", "m^3/s", -6, Range(-1e4, 1e4), False, frozenset(),
           "flow into the muscle (negative = out)"),
    Column("load_n", "float", "N", "load_n", "N", 0, Range(-100.0, 5000.0), False, frozenset(),
           "hanging or inertial load (weight) on the muscle"),
    Column("added_compliance_mm_per_n", "float", "mm/N", "added_compliance_m_per_n", "m/N", -3, Range(0.0, 100.0),
           False, frozenset(),
           "known series compliance added between muscle and load cell for this run (a second, softer mount), "
           "the same in every row of the run; empty or absent: none"),
)
#: Columns whose value is one per run (every filled row of a run must repeat it).
PER_RUN_COLUMNS: frozenset[str] = frozenset({"added_compliance_mm_per_n"})
COLUMN_BY_NAME: dict[str, Column] = {c.name: c for c in COLUMNS}
#: Columns every header must name.
HEADER_COLUMNS: tuple[str, ...] = tuple(c.name for c in COLUMNS if c.in_header)
#: Columns that identify a run.
RUN_KEY: tuple[str, ...] = ("specimen", "test", "run")


def needed_columns(test: str) -> tuple[str, ...]:
    """The columns whose cells a row of ``test`` must fill."""
    return tuple(c.name for c in COLUMNS if test in c.needed_by)


@dataclass(frozen=True)
class Key:
    """One key of the TOML sidecar.

    **Fields:** ``section`` and ``name``; ``kind`` ``"str"``, ``"int"`` or ``"float"`` (an integer is accepted
    for a float); ``unit`` in the file; ``field``, the attribute it becomes; ``si_exponent``, SI value = file
    value x 10**si_exponent; ``range`` of valid file values (``None``: any; strings must be non-empty);
    ``required``; ``meaning`` for the docs.
    """

    section: str
    name: str
    kind: str
    unit: str
    field: str
    si_exponent: int
    range: Range | None
    required: bool
    meaning: str

    @property
    def path(self) -> str:
        """``section.name``, the key as errors name it."""
        return f"{self.section}.{self.name}"

    def to_si(self, value):
        """File units -> SI."""
        return _scale(value, self.si_exponent)

    def from_si(self, value):
        """SI -> file units."""
        return _scale(value, -self.si_exponent)

    def describe(self) -> str:
        """What a valid value looks like, e.g. ``a number > 0 (mm)``."""
        kind = {"str": "a non-empty string", "int": "an integer", "float": "a number"}[self.kind]
        text = kind if self.range is None else f"{kind} {self.range}"
        return f"{text} ({self.unit})" if self.unit != "-" else text


#: The sidecar keys, in the order the writer puts them.
KEYS: tuple[Key, ...] = (
    Key("material", "code", "str", "-", "code", 0, None, True,
        "short material code; the paper's are TP P PR TPC PC PCS TFC FC"),
    Key("material", "name", "str", "-", "name", 0, None, True, "material description"),
    Key("geometry", "n_tubes", "int", "-", "n_tubes", 0, Range(1), True, "number of tubes in series"),
    Key("geometry", "tube_width_mm", "float", "mm", "tube_width_m", -3, Range(0.0, low_open=True), True,
        "flat width of one tube, along the load"),
    Key("geometry", "tube_length_mm", "float", "mm", "tube_length_m", -3, Range(0.0, low_open=True), True,
        "tube length across the muscle"),
    Key("geometry", "channel_width_frac", "float", "-", "channel_width_frac", 0,
        Range(0.0, 1.0, high_open=True), True, "fluid channel width over tube length"),
    Key("conditions", "fluid", "str", "-", "fluid", 0, None, True, "working fluid, e.g. `water` or `air`"),
    Key("conditions", "test_pressure_kpa", "float", "kPa", "test_pressure_pa", 3,
        Range(0.0, 2000.0, low_open=True), True, "the material's test pressure (Table 4)"),
    Key("conditions", "step_load_n", "float", "N", "step_load_n", 0, Range(0.0), True,
        "inertial load (weight) of the step test (Table 4)"),
    Key("conditions", "start_tension_n", "float", "N", "start_tension_n", 0, Range(0.0), True,
        "start tension of the load cycles (Table 4)"),
    Key("provenance", "source", "str", "-", "source", 0, None, True, "where these numbers came from"),
)
SECTIONS: tuple[str, ...] = tuple(dict.fromkeys(k.section for k in KEYS))
#: Sections that accept further keys of their own (all strings).
OPEN_SECTIONS: frozenset[str] = frozenset({"provenance"})


def keys_of(section: str) -> tuple[Key, ...]:
    """The specified keys of one sidecar section."""
    return tuple(k for k in KEYS if k.section == section)


def markdown_tables() -> str:
    """The column, test and sidecar tables of ``docs/data-format.md``, generated from this module."""
    lines = [
        "| column | type | unit | in header | cell must be filled for | valid range | meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in COLUMNS:
        need = "every test" if c.needed_by == _ALL else ", ".join(f"`{t}`" for t in TESTS if t in c.needed_by)
        header = "required" if c.in_header else "optional"
        valid = c.range if c.range is not None else ("a test below" if c.name == "test" else "non-empty")
        cells = (f"`{c.name}`", c.kind, c.unit, header, need or "-", valid, c.meaning)
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    lines += ["", "| test | what the rig does | cells that must be filled |", "|---|---|---|"]
    for t, meaning in TESTS.items():
        lines.append(f"| `{t}` | {meaning} | {', '.join(f'`{n}`' for n in needed_columns(t))} |")
    lines += [
        "",
        "| section | key | type | unit | required | valid | meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for k in KEYS:
        valid = "non-empty" if k.range is None else str(k.range)
        required = "yes" if k.required else "no"
        cells = (f"`[{k.section}]`", f"`{k.name}`", k.kind, k.unit, required, valid, k.meaning)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
