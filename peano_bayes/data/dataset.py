"""The immutable, validated, SI-unit form of a rig dataset: :class:`Dataset` of :class:`Run` s.

Build one with :func:`peano_bayes.data.load` (from files) or directly (a virtual rig); the arrays are copied
to read-only float64 arrays either way. :func:`peano_bayes.data.save` checks a dataset against the format.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..physics.geometry import Geometry
from .format import TESTS

#: The signal fields of a :class:`Run`, in order; the first four are always arrays, the rest may be ``None``.
SIGNALS: tuple[str, ...] = (
    "time_s", "pressure_pa", "strain", "force_n", "supply_pa", "flow_m3_per_s", "load_n",
    "added_compliance_m_per_n",
)
OPTIONAL_SIGNALS: tuple[str, ...] = ("supply_pa", "flow_m3_per_s", "load_n", "added_compliance_m_per_n")


def _frozen_array(value, name: str) -> np.ndarray:
    arr = np.array(value, dtype=np.float64, copy=True)
    if arr.ndim != 1:
        raise ValueError(f"Run.{name} must be one-dimensional, got shape {arr.shape}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class Run:
    """One run: the samples of one (specimen, test, run) in time order, SI units.

    **Fields:** ``specimen``; ``test`` (one of :data:`~peano_bayes.data.format.TESTS`); ``run`` index >= 0;
    ``time_s`` [s]; ``pressure_pa`` gauge pressure in the muscle [Pa]; ``strain`` contraction over l0 [-];
    ``force_n`` tension at the load cell [N]; optional ``supply_pa`` [Pa], ``flow_m3_per_s`` into the muscle
    [m^3/s], ``load_n`` [N], ``added_compliance_m_per_n`` a known series compliance added to the rig's mount for
    this run [m/N] (one value per run; it adds to the model's mount compliance), ``None`` when the
    file has no such column. All arrays are read-only float64 of
    one length; NaN marks a cell the test does not measure.
    """

    specimen: str
    test: str
    run: int
    time_s: np.ndarray
    pressure_pa: np.ndarray
    strain: np.ndarray
    force_n: np.ndarray
    supply_pa: np.ndarray | None = None
    flow_m3_per_s: np.ndarray | None = None
    load_n: np.ndarray | None = None
    added_compliance_m_per_n: np.ndarray | None = None

    def __post_init__(self):
        n = None
        for name in SIGNALS:
            value = getattr(self, name)
            if value is None:
                if name not in OPTIONAL_SIGNALS:
                    raise ValueError(f"Run.{name} is required")
                continue
            arr = _frozen_array(value, name)
            if n is not None and arr.shape[0] != n:
                raise ValueError(f"Run.{name} has {arr.shape[0]} samples, Run.time_s has {n}")
            n = arr.shape[0]
            object.__setattr__(self, name, arr)

    @property
    def added_compliance(self) -> float:
        """The run's known added series compliance [m/N]; 0 where the file has none."""
        c = self.added_compliance_m_per_n
        return float(np.nanmedian(c)) if c is not None and np.any(np.isfinite(c)) else 0.0

    def __len__(self) -> int:
        """Number of samples."""
        return self.time_s.shape[0]

    @property
    def key(self) -> tuple[str, str, int]:
        """``(specimen, test, run)``."""
        return (self.specimen, self.test, self.run)

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.time_s[-1] - self.time_s[0]) if len(self) else 0.0


@dataclass(frozen=True)
class Material:
    """The muscle's tube material: ``code`` (e.g. ``"FC"``) and descriptive ``name``."""

    code: str
    name: str


@dataclass(frozen=True)
class Conditions:
    """Test conditions (the paper's Table 4), SI units.

    **Fields:** ``fluid`` (e.g. ``"water"``); ``test_pressure_pa`` [Pa]; ``step_load_n``, the step test's
    inertial load [N]; ``start_tension_n``, the load cycles' start tension [N].
    """

    fluid: str
    test_pressure_pa: float
    step_load_n: float
    start_tension_n: float


@dataclass(frozen=True, eq=False)
class Dataset:
    """A validated rig dataset in SI units.

    **Fields:** ``material`` (:class:`Material`); ``geometry``
    (:class:`~peano_bayes.physics.geometry.Geometry`, metres); ``conditions`` (:class:`Conditions`);
    ``runs``, a tuple of :class:`Run` in order of first appearance in the file; ``provenance``, a
    read-only mapping of strings (at least ``source``); ``source_path``, the CSV it was read from
    (``None`` if built in memory).
    """

    material: Material
    geometry: Geometry
    conditions: Conditions
    runs: tuple[Run, ...]
    provenance: Mapping[str, str] = field(default_factory=dict)
    source_path: Path | None = None

    def __post_init__(self):
        object.__setattr__(self, "runs", tuple(self.runs))
        object.__setattr__(self, "provenance", MappingProxyType(dict(self.provenance)))
        if self.source_path is not None:
            object.__setattr__(self, "source_path", Path(self.source_path))

    @property
    def tests(self) -> tuple[str, ...]:
        """Test types present, in order of first appearance."""
        return tuple(dict.fromkeys(r.test for r in self.runs))

    @property
    def specimens(self) -> tuple[str, ...]:
        """Specimens present, in order of first appearance."""
        return tuple(dict.fromkeys(r.specimen for r in self.runs))

    def runs_of(self, test: str) -> tuple[Run, ...]:
        """The runs of one test type (empty if there are none); an unknown test name raises ``ValueError``."""
        if test not in TESTS:
            near = difflib.get_close_matches(test, TESTS, n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ValueError(f"unknown test type {test!r}{hint}; expected one of {', '.join(TESTS)}")
        return tuple(r for r in self.runs if r.test == test)
