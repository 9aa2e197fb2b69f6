"""Virtual test rig: runs the paper's test protocol on the JAX physics and returns a rig :class:`Dataset`.

The protocol follows Veale, Xie, Anderson (2016), sections 3-4 and Table 4: two specimens of a material, three
repeats of every test on each; load cycles at 0 kPa and at the material's test pressure, starting at the strain
where the relaxed muscle carries the Table 4 start tension and stretching to -1.5 % strain and back; a blocking
test (pressure ramp at zero strain); a stroke test (pressure ramp lifting 5.5 N); a step response (supply step
through the inlet restriction lifting the Table 4 step load). Specimens differ by a seeded log-normal factor on
their stiffness-like parameters; repeats differ by sensor noise only (and by the force sensor's drift, if on).

Sampling (the paper does not state its rates; these are typical of such a rig): **20 Hz** for the quasi-static
tests (load cycles of 40 s: 801 samples; ramps of 20 s: 401 samples), which resolves a 40 s cycle far better
than the few-percent features a fit needs, and **1 kHz** for the 0.8 s step response (801 samples), ten to a
hundred samples per period of the 10-100 Hz load oscillation (two integration substeps per sample).

The physics is pure JAX (:mod:`peano_bayes.physics`); this module only drives it, adds seeded sensor noise
with NumPy, and builds the dataset. Write it with :func:`peano_bayes.data.save`.

The package's rooms: :mod:`.protocol` (noise, protocol, quirks, generating parameters), :mod:`.measure` (what
the rigs share: sensor noise, checks, provenance), :mod:`.peano` (the rig on this package's physics),
:mod:`.veale` (the rig on Veale's static model), :mod:`.surface` (the rig on a Sarosi-type force surface, all four
tests), :mod:`.conditions` (sampling rate and test pressure drawn per seed, for benchmarks).
"""

from .conditions import (
    CONDITIONS_STREAM,
    PRESSURE_RANGE_PA,
    RATE_GRID_HZ,
    RATE_RANGE_HZ,
    DrawnConditions,
    draw_conditions,
)
from .measure import MAX_FORCE_ERROR_N, MAX_POSITION_ERROR_M, RigSimulationError
from .peano import simulate_dataset
from .protocol import (
    DEFAULT_NOISE,
    DEFAULT_PROTOCOL,
    QUIRKS,
    RIG_TESTS,
    RigNoise,
    RigProtocol,
    apply_quirks,
    check_parameter,
    check_quirks,
    read_parameter_file,
    resolve_parameters,
    specimen_parameters,
)
from .surface import SURFACE_TESTS, SURFACE_VARYING, simulate_surface_dataset
from .veale import VEALE_TESTS, VEALE_VARYING, simulate_veale_dataset

__all__ = [
    "CONDITIONS_STREAM",
    "DEFAULT_NOISE",
    "DEFAULT_PROTOCOL",
    "DrawnConditions",
    "MAX_FORCE_ERROR_N",
    "MAX_POSITION_ERROR_M",
    "PRESSURE_RANGE_PA",
    "QUIRKS",
    "RATE_GRID_HZ",
    "RATE_RANGE_HZ",
    "RIG_TESTS",
    "RigNoise",
    "RigProtocol",
    "RigSimulationError",
    "SURFACE_TESTS",
    "SURFACE_VARYING",
    "VEALE_TESTS",
    "VEALE_VARYING",
    "apply_quirks",
    "check_parameter",
    "check_quirks",
    "draw_conditions",
    "read_parameter_file",
    "resolve_parameters",
    "simulate_dataset",
    "simulate_surface_dataset",
    "simulate_veale_dataset",
    "specimen_parameters",
]
