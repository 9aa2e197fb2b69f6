"""Peano muscle geometry: n identical tubes in series along the load."""

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
