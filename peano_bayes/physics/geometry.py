"""Peano muscle geometry: n identical tubes in series along the load, and how wall parameters scale with it."""

from __future__ import annotations

import equinox as eqx


class Geometry(eqx.Module):
    """Flat geometry of a Peano muscle, SI units.

    **Fields:** ``n_tubes`` [-]; ``tube_width_m``, flat width of one tube along the load [m];
    ``tube_length_m``, across the muscle [m]; ``channel_width_frac``, fluid channel width over tube length [-].
    The paper's muscles (Table 4): 4 tubes, aspect ratio 1:3.3, 30 % channel, l0 = 0.06 m.
    """

    n_tubes: int = eqx.field(static=True, default=4)
    tube_width_m: float = 0.015
    tube_length_m: float = 0.0495
    channel_width_frac: float = 0.30

    def __check_init__(self):
        for name in ("tube_width_m", "tube_length_m"):
            value = getattr(self, name)
            if isinstance(value, int | float) and not value > 0:
                raise ValueError(f"Geometry.{name} must be positive, got {value!r}")
        if not (isinstance(self.n_tubes, int) and self.n_tubes >= 1):
            raise ValueError(f"Geometry.n_tubes must be a positive integer, got {self.n_tubes!r}")
        frac = self.channel_width_frac
        if isinstance(frac, int | float) and not 0.0 <= frac < 1.0:
            raise ValueError(f"Geometry.channel_width_frac must be in [0, 1), got {frac!r}")

    @property
    def flat_length_m(self):
        """Force-producing flat length l0 = n w [m]; strain is contraction over l0."""
        return self.n_tubes * self.tube_width_m


#: The common geometry of the paper's material study (Veale, Xie, Anderson 2016, section 4).
PAPER_GEOMETRY = Geometry()
#: The validation muscle of the paper's section 2 (Table 2: w = 15 mm, l = 46 mm, four tubes).
VALIDATION_GEOMETRY = Geometry(tube_width_m=0.015, tube_length_m=0.046)


#: Parameter-name stems whose value scales as l / L (force over strain: tube length l across the load, flat
#: length L = n w along it), as l / L^2, or as 1 / l; all others are wall or rig properties that do not scale.
_PER_STRAIN = ("tensile_ka_n_per_m", "extension_k_n_per_m", "friction_stiffness_n_per_m", "series_creep_c_ns_per_m")
_PER_STRAIN_SQUARED = ("tensile_kb_n_per_m2",)


def _scaling(name: str, across: float, along: float) -> float:
    if name in _PER_STRAIN or (name.startswith(("parallel_maxwell", "series_kelvin")) and name.endswith("_k_n_per_m")):
        return across / along
    if name in _PER_STRAIN_SQUARED:
        return across / along**2
    if name == "friction_force_n":
        return across
    if name == "mount_compliance_m_per_n":
        return 1.0 / across
    return 1.0


def scale_parameters(params: dict, reference: Geometry, target: Geometry) -> dict:
    """Parameters (scalars, or arrays of draws) fitted on a ``reference`` muscle, carried to a ``target``
    geometry of the same walls.

    Muscle-level stiffnesses [N/m] of the walls act in parallel across the tube length l and in series along
    the flat length L = n w, so they scale as l/L (``tensile_kb`` as l/L^2, its stretch being quadratic);
    the constant friction force and a mount tab across the muscle scale with l (its compliance as 1/l).
    Bending stiffnesses [N], pressure fractions, exponents, time constants, the threshold pressure, the
    inlet and load damping are wall, fluid or rig properties and do not change. With these rules the force at
    a given strain and pressure is exactly proportional to l and independent of n at fixed w (tested).
    """
    across = target.tube_length_m / reference.tube_length_m
    along = target.flat_length_m / reference.flat_length_m
    return {name: value * _scaling(name, across, along) for name, value in params.items()}
