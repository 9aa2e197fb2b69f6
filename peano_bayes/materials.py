"""The paper's eight muscle materials and their test conditions (Veale, Xie, Anderson 2016, Table 4).

Source: A. J. Veale, S. Q. Xie, I. A. Anderson, *Modeling the Peano fluidic muscle and the effects of its
material properties on its static and dynamic behavior*, Smart Mater. Struct. 25 (2016), **Table 4**
("Materials and experimental conditions of Peano muscles in material tests"): material, code, test pressure,
step response inertial mass (a weight, in N) and load cycle start tension. Construction details come from the
same paper's section 3.1 (films, textiles, 90-0 and 45-45 wraps, PlatSil Gel-10 silicone) and section 4.1
(satin weave of the 105 g/m2 polyester, plain weave of the 175 g/m2 polyester). Every muscle was tested
hydraulically (water) and shares the common geometry :data:`peano_bayes.physics.PAPER_GEOMETRY`: four tubes,
w = 15 mm, tube length 49.5 mm, channel 30 %, l0 = 0.06 m. SI units throughout.
"""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass
from types import MappingProxyType

from .data import Conditions, Material
from .errors import PeanoBayesInputError, did_you_mean
from .physics import PAPER_GEOMETRY

#: The common geometry of every muscle in the material study (section 4).
GEOMETRY = PAPER_GEOMETRY
#: The working fluid of every test in the study.
FLUID = "water"
#: The silicone of the textile-elastomer composites (section 3.1).
COMPOSITE_MATRIX = "silicone (PlatSil Gel-10)"


@dataclass(frozen=True)
class MaterialSpec:
    """One material of Table 4 with its test conditions, SI units.

    **Fields:**
    - ``code``, ``label``: Table 4's code and its parenthesized meaning (``"FC"``, ``"Fiberglass composite"``).
    - ``name``: Table 4's material description (``"100 g/m2 fiberglass-silicone"``).
    - ``construction``: how the muscle is built, as text (section 3.1); ``matrix``: ``"LDPE"`` (plastic muscles)
      or the composites' silicone.
    - ``film_thickness_m``: LDPE film thickness [m] of the plastic muscles, ``None`` for the composites.
    - ``textile``: ``"polyester"``, ``"fiberglass"`` or ``None``; ``textile_areal_density_kg_per_m2`` [kg/m^2].
    - ``fiber_orientation``: ``"90-0"`` (fibres along the muscle length, inextensible) or ``"45-45"`` (slanted
      weave, stretchy); ``weave``: ``"satin"`` or ``"plain"`` where section 4.1 states it, else ``None``.
    - ``test_pressure_pa`` [Pa]; ``step_load_n``, the step test's inertial load as a weight [N];
      ``start_tension_n``, the load cycles' start tension [N].
    """

    code: str
    label: str
    name: str
    construction: str
    _: KW_ONLY
    matrix: str
    test_pressure_pa: float
    step_load_n: float
    start_tension_n: float
    film_thickness_m: float | None = None
    textile: str | None = None
    textile_areal_density_kg_per_m2: float | None = None
    fiber_orientation: str | None = None
    weave: str | None = None

    def data_material(self) -> Material:
        """The dataset sidecar's ``[material]``: code and name."""
        return Material(code=self.code, name=self.name)

    def conditions(self, fluid: str = FLUID) -> Conditions:
        """The dataset sidecar's ``[conditions]`` for this material (Table 4), SI units."""
        return Conditions(
            fluid=fluid,
            test_pressure_pa=self.test_pressure_pa,
            step_load_n=self.step_load_n,
            start_tension_n=self.start_tension_n,
        )


_PLASTIC = "two LDPE films heat-sealed into four tubes"
_COMPOSITE = (
    "silicone-impregnated textile wrapped twice around a foam core (dissolved after curing), stitched with "
    "0.234 mm UHMWPE cord; 3 mm high channels"
)


def _plastic(code, label, name, construction, thickness_m, **textile) -> MaterialSpec:
    return MaterialSpec(
        code,
        label,
        name,
        construction,
        matrix="LDPE",
        film_thickness_m=thickness_m,
        test_pressure_pa=30e3,
        step_load_n=9.0,
        start_tension_n=10.0,
        **textile,
    )


def _composite(code, label, name, construction, **conditions_and_textile) -> MaterialSpec:
    return MaterialSpec(code, label, name, construction, matrix=COMPOSITE_MATRIX, **conditions_and_textile)


_TABLE_4 = (
    _plastic("TP", "Thin plastic", "60 um LDPE", f"{_PLASTIC}, 60 um film", 60e-6),
    _plastic("P", "Plastic", "125 um LDPE", f"{_PLASTIC}, 125 um film", 125e-6),
    _plastic(
        "PR",
        "Plastic reinforced",
        "125 um LDPE reinforced with 175 g/m2 polyester",
        f"{_PLASTIC}, 125 um film roughened and wrapped once in 175 g/m2 polyester bonded by spray adhesive, "
        "fibres along the muscle length",
        125e-6,
        textile="polyester",
        textile_areal_density_kg_per_m2=0.175,
        fiber_orientation="90-0",
    ),
    _composite(
        "TPC",
        "Thin polyester composite",
        "105 g/m2 polyester-silicone",
        f"105 g/m2 satin-weave polyester, fibres along the muscle length (90-0); {_COMPOSITE}",
        test_pressure_pa=200e3,
        step_load_n=40.0,
        start_tension_n=40.0,
        textile="polyester",
        textile_areal_density_kg_per_m2=0.105,
        fiber_orientation="90-0",
        weave="satin",
    ),
    _composite(
        "PC",
        "Polyester composite",
        "175 g/m2 polyester-silicone",
        f"175 g/m2 plain-weave polyester, fibres along the muscle length (90-0); {_COMPOSITE}",
        test_pressure_pa=200e3,
        step_load_n=40.0,
        start_tension_n=40.0,
        textile="polyester",
        textile_areal_density_kg_per_m2=0.175,
        fiber_orientation="90-0",
        weave="plain",
    ),
    _composite(
        "PCS",
        "Polyester composite slanted weave",
        "175 g/m2 polyester-silicone (45-45 weave)",
        f"175 g/m2 polyester, fibres at 45 deg to the muscle length (45-45, slanted weave); {_COMPOSITE}",
        test_pressure_pa=200e3,
        step_load_n=15.0,
        start_tension_n=40.0,
        textile="polyester",
        textile_areal_density_kg_per_m2=0.175,
        fiber_orientation="45-45",
    ),
    _composite(
        "TFC",
        "Thin fiberglass composite",
        "25 g/m2 fiberglass-silicone",
        f"25 g/m2 fiberglass, fibres along the muscle length (90-0); {_COMPOSITE}",
        test_pressure_pa=30e3,
        step_load_n=9.0,
        start_tension_n=10.0,
        textile="fiberglass",
        textile_areal_density_kg_per_m2=0.025,
        fiber_orientation="90-0",
    ),
    _composite(
        "FC",
        "Fiberglass composite",
        "100 g/m2 fiberglass-silicone",
        f"100 g/m2 fiberglass, fibres along the muscle length (90-0); {_COMPOSITE}",
        test_pressure_pa=200e3,
        step_load_n=40.0,
        start_tension_n=40.0,
        textile="fiberglass",
        textile_areal_density_kg_per_m2=0.100,
        fiber_orientation="90-0",
    ),
)

#: code -> :class:`MaterialSpec`, in Table 4's order (TP P PR TPC PC PCS TFC FC). Read-only.
MATERIALS: MappingProxyType[str, MaterialSpec] = MappingProxyType({m.code: m for m in _TABLE_4})


def material(code: str | MaterialSpec) -> MaterialSpec:
    """The :class:`MaterialSpec` of a Table 4 code (case-insensitive); a spec is returned unchanged.

    **Raises:** :class:`~peano_bayes.errors.PeanoBayesInputError` for an unknown code, with a did-you-mean and
    the list of known codes.
    """
    if isinstance(code, MaterialSpec):
        return code
    key = str(code).strip().upper()
    if key in MATERIALS:
        return MATERIALS[key]
    hint = did_you_mean(key, MATERIALS, cutoff=0.5)
    raise PeanoBayesInputError(
        f"unknown material code {code!r}{hint}; expected one of {', '.join(MATERIALS)} (Table 4 of the paper)"
    )


__all__ = ["COMPOSITE_MATRIX", "FLUID", "GEOMETRY", "MATERIALS", "MaterialSpec", "material"]
