"""Design limits: the pressures beyond which a material is not recommended (its highest tested pressure, where the
posterior would extrapolate, and a burst pressure where the paper or the spec states one), and the inflated
thickness of a candidate from the wall build-up data of ``bundled/data/design_limits.toml``."""

from __future__ import annotations

import functools
import json
import math
import tomllib

from .. import bundled
from ..materials import MATERIALS
from ..physics import Geometry


@functools.cache
def design_limits() -> dict:
    """The bundled ``design_limits.toml``: ``construction`` (wall build-up data) and ``pressure`` (per material
    ``max_tested_kpa``, optional ``burst_kpa``, ``source``)."""
    return tomllib.loads((bundled.DATA_DIR / "design_limits.toml").read_text(encoding="utf-8"))


def wall_thickness_m(code: str) -> float | None:
    """One wall's thickness [m] of a bundled material, from its construction: film (plastics) or silicone liner
    (composites) plus its textile wraps, each ``areal density / (fibre density x fibre volume fraction)``;
    ``None`` for a material of one's own."""
    if code not in MATERIALS:
        return None
    spec, c = MATERIALS[code], design_limits()["construction"]
    composite = spec.film_thickness_m is None
    base = 1e-3 * c["composite_liner_mm"] if composite else spec.film_thickness_m
    if spec.textile is None:
        return base
    wraps = c["composite_textile_wraps"] if composite else c["plastic_textile_wraps"]
    layer = spec.textile_areal_density_kg_per_m2 / (
        c["fibre_density_kg_per_m3"][spec.textile] * c["fabric_fibre_volume_fraction"]
    )
    return base + wraps * layer


def thickness_m(geometry: Geometry, code: str | None = None) -> float:
    """Fully inflated thickness [m] of a muscle of material ``code``: the tube's inextensible internal perimeter
    ``2 (w + h0)`` (``h0`` the uninflated internal height: 3 mm for the composites' foam core, 0 for the
    sealed films) rounded to a circle of diameter ``2 (w + h0) / pi``, plus both walls
    (:func:`wall_thickness_m`). For a material of one's own (walls unknown) the bound ``2 w / pi`` of thin
    walls and no internal height."""
    walls = wall_thickness_m(code) if code is not None else None
    if walls is None:
        return 2.0 * geometry.tube_width_m / math.pi
    composite = MATERIALS[code].film_thickness_m is None
    h0 = 1e-3 * design_limits()["construction"]["composite_core_height_mm"] if composite else 0.0
    return 2.0 * (geometry.tube_width_m + h0) / math.pi + 2.0 * walls


def material_limits(
    code: str, idata=None, burst_kpa: float | None = None, stated_in: str = "the spec"
) -> dict | None:
    """The pressure limits of material ``code``: ``max_tested_kpa`` with its ``source``, and ``burst_kpa`` with
    its ``burst_source`` where one is known. The tested pressure: the bundled ``design_limits.toml`` for the
    paper's materials; for any other, the test pressure of the data its result was fitted to (``idata``'s
    ``conditions``), the highest pressure its posterior has seen. The burst pressure: the lower of the paper's
    and ``burst_kpa`` (stated in ``stated_in``). ``None`` where no tested pressure is known (then
    :func:`limit_violations` refuses every pressure: a material is never extrapolated silently)."""
    limits = design_limits()["pressure"].get(code)
    limits = None if limits is None else dict(limits)
    if limits is None:
        raw = None if idata is None else idata.posterior.attrs.get("conditions")
        tested = json.loads(raw).get("test_pressure_pa") if raw else None
        if tested is None:
            return None
        source = "the test pressure of the data its result was fitted to"
        limits = {"max_tested_kpa": float(tested) / 1e3, "source": source}
    if "burst_kpa" in limits:
        limits.setdefault("burst_source", limits["source"])
    if burst_kpa is not None and burst_kpa < limits.get("burst_kpa", math.inf):
        limits["burst_kpa"], limits["burst_source"] = float(burst_kpa), f"stated in {stated_in}"
    return limits


def limit_violations(
    code: str, max_pressure_pa: float, idata=None, burst_kpa: float | None = None, stated_in: str = "the spec"
) -> list[str]:
    """Why a material cannot be used at ``max_pressure_pa``: above its highest tested pressure or a known burst
    pressure (:func:`material_limits` of ``code``, its result ``idata`` and a stated ``burst_kpa``); empty when
    it can. With no tested pressure known every pressure is refused: the posterior's validity there is unknown."""
    return violations(code, max_pressure_pa, material_limits(code, idata, burst_kpa, stated_in))


def violations(code: str, max_pressure_pa: float, limits: dict | None) -> list[str]:
    """Why material ``code`` cannot be used at ``max_pressure_pa`` [Pa] under its ``limits``
    (:func:`material_limits`); every pressure where they are ``None``."""
    kpa = max_pressure_pa / 1e3
    if limits is None:
        return [f"{kpa:g} kPa cannot be checked against the pressure {code} was tested at: none is known"]
    reasons = []
    if "burst_kpa" in limits and kpa > limits["burst_kpa"]:
        reasons.append(
            f"{kpa:g} kPa is above {code}'s burst pressure of {limits['burst_kpa']:g} kPa ({limits['burst_source']})"
        )
    if kpa > limits["max_tested_kpa"]:
        reasons.append(
            f"{kpa:g} kPa is above the {limits['max_tested_kpa']:g} kPa {code} was tested at: the posterior would "
            f"extrapolate ({limits['source']})"
        )
    return reasons


__all__ = ["design_limits", "limit_violations", "material_limits", "thickness_m", "violations", "wall_thickness_m"]
