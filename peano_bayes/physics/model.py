"""The composed muscle: which elements are on, their parameters, and one time step of the muscle.

Arrangement (Veale's force-balance topology by default)::

    load ── [ tensile spring ── mount ── Kelvin units ── creep dashpot ] ── [ contractile unit        ] ── ground
            (series chain: stretch from force)                              [ || bending             ]
                                                                            [ || Maxwell branches    ]
                                                                            [ || Dahl friction       ]
         ══ passive extension || whole-muscle friction (parallel to everything, act on the strain) ══

The paper's proposed structure (contractile unit || viscoelastic element, in series with another
viscoelastic element) is ``ModelConfig(parallel_maxwell=1, series_kelvin=1, friction="none")``: a config,
not a code change. Every element is switched by :class:`ModelConfig`; parameters are a flat ``dict`` of
named scalars with SI units in their names (see :data:`PARAMETERS`).
"""

from __future__ import annotations

import dataclasses
from typing import Literal, NamedTuple

import equinox as eqx
import jax.numpy as jnp

from . import elements, pouch
from .geometry import Geometry

#: Numerical bounds of the tube half-angle [rad]; pi/2 is the fully round tube (zero ideal force).
THETA_MIN = 1e-7
THETA_MAX = 0.5 * jnp.pi - 1e-6
#: Pressure floor [Pa] that regularizes the flat-tube limit (see elements.effective_pressure).
PRESSURE_FLOOR_PA = 100.0
GRAVITY_M_PER_S2 = 9.81
WATER_DENSITY_KG_PER_M3 = 1000.0


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One model parameter: SI unit, meaning, nominal value, physical bounds, and its inert ("off") value.

    ``bounds`` is the box the physics is tested over (no NaN or inf anywhere inside it); priors must lie in it.
    """

    unit: str
    meaning: str
    nominal: float
    bounds: tuple[float, float]
    off: float | None = None


PARAMETERS: dict[str, Parameter] = {
    "length_fraction": Parameter(
        "-", "effective fraction of the tube length that the pressure acts on", 0.8, (0.3, 1.0)
    ),
    "bending_k1_n": Parameter(
        "N", "bending stiffness, constant part (energy l k1 theta^2/2)", 0.5, (0.0, 50.0), 0.0
    ),
    "bending_k2_n": Parameter(
        "N", "bending stiffness, stiffening part (k2 theta^m)", 10.0, (0.0, 500.0), 0.0
    ),
    "bending_exponent": Parameter("-", "exponent m of the stiffening bending part", 6.0, (1.0, 12.0)),
    "tensile_ka_n_per_m": Parameter(
        "N/m", "series tensile stiffness at zero load (muscle level)", 2e4, (1e2, 1e6)
    ),
    "tensile_kb_n_per_m2": Parameter(
        "N/m^2", "series tensile stiffening, F = ka d + kb d^2", 1e7, (0.0, 1e10), 0.0
    ),
    "extension_k_n_per_m": Parameter(
        "N/m", "passive extension stiffness at zero strain (0 kPa)", 1e3, (0.0, 1e5), 0.0
    ),
    "extension_rate": Parameter(
        "-", "exponential stiffening rate of passive extension per unit strain", 50.0, (0.0, 200.0)
    ),
    "mount_compliance_m_per_n": Parameter(
        "m/N", "compliance of the mount tabs in series", 1e-5, (0.0, 1e-3), 0.0
    ),
    "series_creep_c_ns_per_m": Parameter(
        "N s/m", "Burgers series dashpot (unbounded creep)", 1e7, (1e4, 1e12), 1e12
    ),
    "friction_stiffness_n_per_m": Parameter("N/m", "Dahl friction pre-sliding stiffness", 2e4, (1e2, 1e6)),
    "friction_force_n": Parameter("N", "Dahl friction force limit, constant part", 0.5, (0.0, 50.0), 0.0),
    "friction_pressure_fraction": Parameter(
        "-",
        "Dahl friction limit per unit pressure load p w l_e (walls pressed together)",
        0.1,
        (0.0, 0.5),
        0.0,
    ),
    "threshold_pressure_pa": Parameter(
        "Pa", "pressure below which the tubes do not open", 5e3, (0.0, 5e4), 0.0
    ),
    "orifice_area_m2": Parameter(
        "m^2", "effective discharge area C_d A of the inlet restriction", 5e-6, (1e-7, 1e-4)
    ),
    "laminar_conductance_m3_per_s_pa": Parameter(
        "m^3/(s Pa)", "laminar channel conductance", 1e-9, (1e-12, 1e-7)
    ),
    "damping_up_ns_per_m": Parameter("N s/m", "load damping while contracting", 0.0, (0.0, 1e4), 0.0),
    "damping_down_ns_per_m": Parameter("N s/m", "load damping while extending", 0.0, (0.0, 1e4), 0.0),
    "damping_quadratic_ns2_per_m2": Parameter(
        "N s^2/m^2", "quadratic load damping c |v| v", 0.0, (0.0, 1e4), 0.0
    ),
}


def _indexed(prefix: str, count: int, suffixes: dict[str, Parameter]) -> None:
    for i in range(1, count + 1):
        for suffix, spec in suffixes.items():
            PARAMETERS.setdefault(f"{prefix}{i}_{suffix}", spec)


_MAXWELL = {
    "k_n_per_m": Parameter(
        "N/m", "Maxwell branch stiffness across the contractile unit", 2e3, (0.0, 1e5), 0.0
    ),
    "tau_s": Parameter("s", "Maxwell branch relaxation time", 1.0, (1e-3, 1e3)),
}
_KELVIN = {
    "k_n_per_m": Parameter("N/m", "Kelvin-Voigt unit stiffness in series", 2e4, (1e2, 1e12), 1e12),
    "tau_s": Parameter("s", "Kelvin-Voigt unit retardation time", 1.0, (1e-3, 1e3)),
}
_indexed("parallel_maxwell", 3, _MAXWELL)
_indexed("series_kelvin", 3, _KELVIN)


class ModelConfig(eqx.Module):
    """Which elements a muscle model contains. Hashable and static: one compiled function per config.

    **Fields:**
    - ``bending``: bending resistance in parallel with the contractile unit.
    - ``tensile``: tensile spring in series (off: inextensible tubes, infinite blocking force).
    - ``extension``: passive strain stiffening in extension, parallel to the whole muscle.
    - ``mount``: compliant mount in series (``series_compliance``).
    - ``parallel_maxwell``: number of Maxwell branches across the contractile unit (0-3).
    - ``series_kelvin``: number of Kelvin-Voigt units in series (0-3).
    - ``series_creep``: Burgers dashpot in series.
    - ``friction``: rate-independent Dahl friction across the contractile unit (``"parallel"``), across the
      whole muscle (``"whole"``), or ``"none"``.
    - ``threshold``: threshold pressure. ``flow``: inlet restriction law, ``"orifice"`` or ``"laminar"``.
    - ``damping``: direction-dependent and quadratic damping of the load (``nonlinear_damping``).
    """

    bending: bool = True
    tensile: bool = True
    extension: bool = True
    mount: bool = False
    parallel_maxwell: int = 0
    series_kelvin: int = 0
    series_creep: bool = False
    friction: Literal["none", "parallel", "whole"] = "parallel"
    threshold: bool = False
    flow: Literal["orifice", "laminar"] = "orifice"
    damping: bool = False

    def __check_init__(self):
        if self.friction not in ("none", "parallel", "whole"):
            raise ValueError(
                f"ModelConfig.friction must be 'none', 'parallel' or 'whole', got {self.friction!r}"
            )
        if self.flow not in ("orifice", "laminar"):
            raise ValueError(f"ModelConfig.flow must be 'orifice' or 'laminar', got {self.flow!r}")
        for name in ("parallel_maxwell", "series_kelvin"):
            if getattr(self, name) not in (0, 1, 2, 3):
                raise ValueError(f"ModelConfig.{name} must be 0, 1, 2 or 3, got {getattr(self, name)!r}")

    def parameter_names(self) -> tuple[str, ...]:
        """Names of the parameters this configuration reads, in a fixed order."""
        names = ["length_fraction"]
        if self.bending:
            names += ["bending_k1_n", "bending_k2_n", "bending_exponent"]
        if self.tensile:
            names += ["tensile_ka_n_per_m", "tensile_kb_n_per_m2"]
        if self.extension:
            names += ["extension_k_n_per_m", "extension_rate"]
        if self.mount:
            names += ["mount_compliance_m_per_n"]
        for i in range(1, self.parallel_maxwell + 1):
            names += [f"parallel_maxwell{i}_k_n_per_m", f"parallel_maxwell{i}_tau_s"]
        for i in range(1, self.series_kelvin + 1):
            names += [f"series_kelvin{i}_k_n_per_m", f"series_kelvin{i}_tau_s"]
        if self.series_creep:
            names += ["series_creep_c_ns_per_m"]
        if self.friction != "none":
            names += ["friction_stiffness_n_per_m", "friction_force_n", "friction_pressure_fraction"]
        if self.threshold:
            names += ["threshold_pressure_pa"]
        names += ["orifice_area_m2"] if self.flow == "orifice" else ["laminar_conductance_m3_per_s_pa"]
        if self.damping:
            names += ["damping_up_ns_per_m", "damping_down_ns_per_m", "damping_quadratic_ns2_per_m2"]
        return tuple(names)

    def nominal_parameters(self) -> dict[str, float]:
        """A physically sensible parameter set for this configuration (a composite muscle at 200 kPa)."""
        return {name: PARAMETERS[name].nominal for name in self.parameter_names()}

    def check_parameters(self, params) -> None:
        """Raise ``KeyError`` naming every missing parameter, with a hint (call outside ``jit``)."""
        missing = [n for n in self.parameter_names() if n not in params]
        if missing:
            raise KeyError(
                f"parameters missing for this ModelConfig: {', '.join(missing)}; "
                "start from ModelConfig.nominal_parameters() and override what you know"
            )


#: Veale's force-balance arrangement (contractile unit || bending, in series with tensile) with friction.
DEFAULT_CONFIG = ModelConfig()
#: The paper's proposed structure: contractile unit || viscoelastic element, in series with another.
PAPER_PROPOSED_CONFIG = ModelConfig(parallel_maxwell=1, series_kelvin=1, friction="none")
#: The ideal elastic model (bending + tensile, no losses), for analytic checks.
ELASTIC_CONFIG = ModelConfig(friction="none", extension=False)


class MuscleState(NamedTuple):
    """History carried between time steps (all SI). Shapes: scalars, and (n_maxwell,), (n_kelvin,)."""

    contraction_m: jnp.ndarray  # contractile-unit contraction X = n w (1 - sinc theta)
    strain: jnp.ndarray  # muscle strain y / l0
    chain_force_n: jnp.ndarray  # force through the series chain
    maxwell_n: jnp.ndarray
    kelvin_m: jnp.ndarray
    creep_m: jnp.ndarray
    friction_n: jnp.ndarray
    friction_limit_n: jnp.ndarray  # the parallel friction element's limit at the end of the last step


def initial_state(config: ModelConfig) -> MuscleState:
    """A relaxed state: no internal forces or stretches."""
    zero = jnp.zeros(())
    return MuscleState(
        zero, zero, zero, jnp.zeros(config.parallel_maxwell), jnp.zeros(config.series_kelvin), zero, zero, zero
    )


def contraction_m(theta, geometry: Geometry):
    """Contraction of the contractile unit, all tubes [m]."""
    return geometry.n_tubes * geometry.tube_width_m * pouch.strain(theta)


def volume_m3(theta, params, geometry: Geometry):
    """Fluid volume of all tubes [m^3] (ideal arcs over the effective length; dead volume excluded)."""
    w = geometry.tube_width_m
    l_e = params["length_fraction"] * geometry.tube_length_m
    return geometry.n_tubes * w**2 * l_e * pouch.volume_factor(theta)


class Chain(NamedTuple):
    """The series chain at a candidate half-angle: its force [N] and contraction X - stretch [m]."""

    force_n: jnp.ndarray
    shortening_m: jnp.ndarray
    friction_limit_n: jnp.ndarray
    state: MuscleState


def chain(
    theta,
    pressure_pa,
    dt_s,
    state: MuscleState,
    params,
    config: ModelConfig,
    geometry: Geometry,
    relaxed: bool = False,
) -> Chain:
    """Contractile unit with its parallel elements, in series with the series elements.

    ``theta`` [rad] is the tube half-angle, ``pressure_pa`` the gauge pressure in the tubes, ``dt_s`` the time
    since ``state``. The chain force is a decreasing and its shortening an increasing function of ``theta``.
    ``relaxed=True`` gives the state after a long hold (``state`` and ``dt_s`` are ignored): Maxwell branches
    and friction unloaded, Kelvin units fully crept; every test starts from it.
    """
    w, l = geometry.tube_width_m, geometry.tube_length_m
    threshold = params["threshold_pressure_pa"] if config.threshold else 0.0
    p_eff = elements.effective_pressure(pressure_pa, threshold, PRESSURE_FLOOR_PA)

    x = contraction_m(theta, geometry)
    if relaxed:
        state = initial_state(config)._replace(contraction_m=x)
    dx = x - state.contraction_m
    l_e = params["length_fraction"] * l
    active = p_eff * pouch.force_per_pressure(theta, w, l_e)
    # Friction limit: constant part plus a part set by the pressure load pressing the walls together. It is
    # constant at constant pressure, which keeps the element passive (loops never gain energy).
    friction_limit = params.get("friction_force_n", 0.0) + params.get("friction_pressure_fraction", 0.0) * (
        p_eff * w * l_e
    )
    force = active
    if config.bending:
        force = force - elements.bending_force(
            theta, params["bending_k1_n"], params["bending_k2_n"], params["bending_exponent"], w, l
        )
    maxwell = state.maxwell_n
    if config.parallel_maxwell:
        k, tau = _branches(params, "parallel_maxwell", config.parallel_maxwell)
        maxwell = elements.maxwell_update(state.maxwell_n, dx, dt_s, k, tau)
        force = force - jnp.sum(maxwell)
    friction = state.friction_n
    if config.friction == "parallel":
        limit = params["friction_force_n"] + params["friction_pressure_fraction"] * active
        # The limit changes along the step with the pressure load; the Dahl update is exact for a constant
        # one, and taking the mean of the step's two ends keeps it second order in the step.
        previous = limit if relaxed else state.friction_limit_n
        friction = elements.dahl_update(
            state.friction_n, dx, params["friction_stiffness_n_per_m"], 0.5 * (previous + limit)
        )
        force = force - friction

    stretch = jnp.zeros_like(force)
    if config.tensile:
        stretch = elements.tensile_stretch(force, params["tensile_ka_n_per_m"], params["tensile_kb_n_per_m2"])
    if config.mount:
        stretch = stretch + params["mount_compliance_m_per_n"] * force
    kelvin = state.kelvin_m
    if config.series_kelvin:
        k, tau = _branches(params, "series_kelvin", config.series_kelvin)
        if relaxed:
            kelvin = force / k
        else:
            kelvin = elements.kelvin_update(state.kelvin_m, state.chain_force_n, force, dt_s, k, tau)
        stretch = stretch + jnp.sum(kelvin)
    creep = state.creep_m
    if config.series_creep and not relaxed:
        creep = elements.creep_update(
            state.creep_m, state.chain_force_n, force, dt_s, params["series_creep_c_ns_per_m"]
        )
        stretch = stretch + creep
    new_state = state._replace(
        contraction_m=x,
        chain_force_n=force,
        maxwell_n=maxwell,
        kelvin_m=kelvin,
        creep_m=creep,
        friction_n=friction if config.friction == "parallel" else state.friction_n,
        friction_limit_n=limit if config.friction == "parallel" else state.friction_limit_n,
    )
    return Chain(force, x - stretch, friction_limit, new_state)


def total_force(strain, link: Chain, params, config: ModelConfig, geometry: Geometry):
    """Force at the load [N] for muscle ``strain`` [-]: the chain plus elements across the whole muscle.

    Returns ``(force_n, state)`` with the whole-muscle history updated.
    """
    l0 = geometry.flat_length_m
    total = link.force_n
    state = link.state
    if config.extension:
        total = total + elements.extension_force(
            strain, params["extension_k_n_per_m"], params["extension_rate"], l0
        )
    if config.friction == "whole":
        # First order in the step: this limit follows the chain force, which the state does not carry.
        limit = params["friction_force_n"] + params["friction_pressure_fraction"] * jnp.abs(link.force_n)
        dy = (strain - state.strain) * l0  # friction opposes the motion of the load
        friction = elements.dahl_update(state.friction_n, dy, params["friction_stiffness_n_per_m"], limit)
        total = total - friction
        state = state._replace(friction_n=friction)
    return total, state._replace(strain=jnp.asarray(strain, dtype=jnp.result_type(float)))


def _branches(params, prefix: str, count: int):
    k = jnp.stack([params[f"{prefix}{i}_k_n_per_m"] for i in range(1, count + 1)])
    tau = jnp.stack([params[f"{prefix}{i}_tau_s"] for i in range(1, count + 1)])
    return k, tau
