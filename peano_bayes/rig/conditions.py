"""Test conditions drawn per seed: the quasi-static sampling rate and the test pressure of a session, so that a
benchmark is not run (nor tuned) on one protocol alone.

:func:`draw_conditions` is a pure function of the seed: a NumPy generator on the stream
``[seed, CONDITIONS_STREAM]``, apart from the rig's specimen (``[seed, 0, ...]``) and noise (``[seed, 1, ...]``)
streams, so drawing conditions leaves a session's specimens and noise draws as they were. It draws two uniforms,
in this order:

- the quasi-static sampling rate [Hz] (load cycles, blocking and stroke tests), one of the five log-spaced rates
  of :data:`RATE_GRID_HZ` (10 to 100 Hz, rates a load cell and a pressure transducer on such a rig log at), each
  with probability 1/5. A grid, not a continuum: every rate gives the data their own array shapes, and each new
  shape compiles the models afresh (a run on a continuously drawn rate took 541 s against about 60 s on a shape
  already compiled, on 2026-12-06); on five rates the persistent compilation cache serves all but the first
  run at each;
- the test pressure [Pa] (load cycles at pressure, the blocking and stroke ramps' end, the step's supply),
  uniform on :data:`PRESSURE_RANGE_PA` (100 to 400 kPa, within ``defaults.MAX_PRESSURE_KPA``).

The pressure is the force scale: peak forces grow about linearly with it. Measured on material PC's protocol,
noise-free, one specimen at nominal values, the largest force of a session (the pressurized load cycle at -1.5 %
strain) is 123, 194, 253 and 305 N at 100, 200, 300 and 400 kPa on the package's own physics (Veale's elastic
truth of the discovery benchmark), 126, 194, 251 and 303 N on Veale's force-balance model (Table 2), and 101,
169, 237 and 305 N on the Sarosi-type surface (:func:`~peano_bayes.physics.reference.surface_force`): peak
forces from about 100 N up to about 300 N. The muscle's geometry, the loads (start tension, stroke and step
loads) and the step test's sampling stay the protocol's.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

import numpy as np

from .. import materials
from ..data import Dataset
from ..materials import MaterialSpec
from .measure import _check_count
from .protocol import RigProtocol

#: Seed stream of the drawn conditions: ``np.random.default_rng([seed, CONDITIONS_STREAM])``.
CONDITIONS_STREAM = 2
#: Quasi-static sampling rate [Hz]: the range, and the five log-spaced rates drawn from it with equal probability.
RATE_RANGE_HZ = (10.0, 100.0)
RATE_GRID_HZ = tuple(float(10.0 ** (1.0 + k / 4.0)) for k in range(5))
#: Test pressure [Pa], drawn uniform between these (within ``defaults.MAX_PRESSURE_KPA``, 1 MPa).
PRESSURE_RANGE_PA = (100e3, 400e3)


@dataclass(frozen=True)
class DrawnConditions:
    """One seed's drawn conditions: ``quasi_static_rate_hz`` [Hz] and ``test_pressure_pa`` [Pa]."""

    seed: int
    quasi_static_rate_hz: float
    test_pressure_pa: float

    def protocol(self, base: RigProtocol) -> RigProtocol:
        """``base`` sampled at the drawn quasi-static rate (its durations, loads and step test unchanged)."""
        return dataclasses.replace(base, quasi_static_rate_hz=self.quasi_static_rate_hz)

    def material(self, material: str | MaterialSpec) -> MaterialSpec:
        """``material``'s Table 4 conditions at the drawn test pressure (its loads unchanged): the dataset's
        ``[conditions]`` then declare the pressure the session ran at."""
        return dataclasses.replace(materials.material(material), test_pressure_pa=self.test_pressure_pa)

    def as_dict(self) -> dict:
        """The draw and how it was made, JSON-ready."""
        return {
            **dataclasses.asdict(self),
            "stream": CONDITIONS_STREAM,
            "rate_range_hz": list(RATE_RANGE_HZ),
            "rate_grid_hz": list(RATE_GRID_HZ),
            "rate_distribution": "uniform over the log-spaced grid",
            "pressure_range_pa": list(PRESSURE_RANGE_PA),
            "pressure_distribution": "uniform",
        }

    def record(self, dataset: Dataset) -> Dataset:
        """``dataset`` with the draw in its provenance (``drawn_conditions``, JSON)."""
        provenance = {**dataset.provenance, "drawn_conditions": json.dumps(self.as_dict())}
        return dataclasses.replace(dataset, provenance=provenance)


def draw_conditions(seed: int) -> DrawnConditions:
    """The conditions of seed ``seed`` (an integer in [0, 2^63 - 1]): see the module docstring."""
    seed = _check_count("seed", seed, 0, 2**63 - 1)
    u_rate, u_pressure = np.random.default_rng([seed, CONDITIONS_STREAM]).random(2)
    rate = RATE_GRID_HZ[min(int(float(u_rate) * len(RATE_GRID_HZ)), len(RATE_GRID_HZ) - 1)]
    pressure = PRESSURE_RANGE_PA[0] + float(u_pressure) * (PRESSURE_RANGE_PA[1] - PRESSURE_RANGE_PA[0])
    return DrawnConditions(seed, rate, pressure)


__all__ = [
    "CONDITIONS_STREAM",
    "PRESSURE_RANGE_PA",
    "RATE_GRID_HZ",
    "RATE_RANGE_HZ",
    "DrawnConditions",
    "draw_conditions",
]
