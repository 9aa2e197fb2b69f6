"""The closed library of candidate effects the discovery workflow may name.

Each :class:`Effect` frees a set of parameters of the discovery model (:mod:`.model`); while it is inactive
those parameters sit at its ``off`` values, at which it changes no prediction (nesting, tested in
``tests/test_discovery.py``). ``strength`` names the parameters whose posterior must exclude ``off`` before the
effect is accepted, and ``signature`` the residual pattern its absence leaves (:mod:`.diagnose`).

Physics effects are elements of :class:`~peano_bayes.physics.ModelConfig` (or, for ``cyclic_softening``, a
per-cycle stiffness factor); noise-side effects change only the sensor or the noise model, so that a sensor
problem is never reported as physics. The one flexible term, ``session_baseline``, describes slow structure
against time in the session that no library effect produces (a flexible term may compete, but never names an
effect); the workflow reports it as unexplained structure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal

from ..physics.model import PARAMETERS, Parameter

#: Coefficients of the flexible session baseline, degree 1 to 3 (length scale about a third of the session).
BASELINE_PARAMETERS: tuple[str, ...] = ("baseline_p1_n", "baseline_p2_n", "baseline_p3_n")
#: Parameters of the discovery model that are not physics parameters (not in ``PARAMETERS``):
#: unit, meaning, nominal, bounds, off; and the Gaussian regularizer (mean, sd) on the fitted scale.
EXTRA_PARAMETERS: dict[str, Parameter] = {
    "cyclic_softening_fraction": Parameter(
        "-", "extra wall stiffness of cycle n: factor 1 + a exp(-n) (Mullins-like softening)", 0.1, (0.0, 2.0), 0.0
    ),
    "sensor_offset_n": Parameter("N", "load cell zero offset", 0.0, (-50.0, 50.0), 0.0),
    "sensor_gain": Parameter("-", "load cell gain error (measured = gain x true)", 1.0, (0.5, 2.0), 1.0),
    "noise_slope_per_n": Parameter(
        "1/N", "heteroscedastic force noise: sd = sd0 (1 + slope |F|)", 0.02, (0.0, 10.0), 0.0
    ),
    **{
        name: Parameter(
            "N",
            f"slow force baseline: coefficient of the degree-{degree} Legendre polynomial of session time",
            0.0,
            (-20.0, 20.0),
            0.0,
        )
        for degree, name in enumerate(BASELINE_PARAMETERS, 1)
    },
}


def parameter_spec(name: str) -> Parameter:
    """The :class:`~peano_bayes.physics.Parameter` of a physics or discovery-only parameter."""
    return EXTRA_PARAMETERS[name] if name in EXTRA_PARAMETERS else PARAMETERS[name]


@dataclass(frozen=True)
class Effect:
    """One candidate effect.

    **Fields:** ``name``; ``meaning``; ``kind`` ``"physics"``, ``"noise"`` or
    ``"flexible"`` (describes structure, never named);
    ``params`` the parameters it frees; ``off`` name -> value at which it changes nothing (the others of
    ``params`` are held at ``hold`` while inactive); ``start`` name -> weak but non-zero value its screening
    fit starts from; ``strength`` the parameters tested against ``off``; ``signature`` the residual pattern
    its absence leaves (a key of :data:`~peano_bayes.discovery.diagnose.SIGNATURES`); ``shows_in`` the rig
    tests where that pattern appears, the first the one the effect acts on most (:attr:`scored_test`);
    ``model`` the :class:`~peano_bayes.physics.ModelConfig` fields that put the effect into the inference
    model (empty where that model has no such element: the noise-side and flexible terms, and
    ``cyclic_softening``).
    """

    name: str
    meaning: str
    kind: Literal["physics", "noise", "flexible"]
    params: tuple[str, ...]
    off: MappingProxyType
    start: MappingProxyType
    strength: tuple[str, ...]
    signature: str
    shows_in: tuple[str, ...]
    hold: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    model: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))

    @property
    def scored_test(self) -> str:
        """The rig test on which the validation benchmark scores how much of the effect a model recovers (its
        held-out gap against the noise-free truth), fixed here in advance rather than chosen after the fact as
        the test with the largest noisy gap: the first of ``shows_in``, which lists first, of the tests where the
        effect's signature appears, the one where it moves the noise-free signal most
        (``discovery_benchmark.snr_by_test`` at SNR 2: threshold pressure stroke 2.0 against blocking 1.5, a
        mount blocking 1.3 against load cycle 1.0, cyclic softening blocking 0.6 against load cycle 0.5, a series
        Kelvin-Voigt unit blocking 2.0 against load cycle 1.9)."""
        return self.shows_in[0]


def _effect(name, meaning, kind, params, off, start, strength, signature, shows_in, hold=None, model=None) -> Effect:
    return Effect(
        name,
        meaning,
        kind,
        tuple(params),
        MappingProxyType(dict(off)),
        MappingProxyType(dict(start)),
        tuple(strength),
        signature,
        tuple(shows_in),
        MappingProxyType(dict(hold or {})),
        MappingProxyType(dict(model or {})),
    )


#: Rigid-tube stand-in for "no tensile compliance": the upper bound of ``tensile_ka_n_per_m``. The ideal
#: model's blocking force is infinite; a load cycle that stretches the muscle cannot be simulated without it.
RIGID_TENSILE_N_PER_M = PARAMETERS["tensile_ka_n_per_m"].bounds[1]
#: Rigid stand-in for "no series Kelvin unit": the upper bound of ``series_kelvin1_k_n_per_m``, at which its
#: stretch is below 1e-12 m per newton.
RIGID_KELVIN_N_PER_M = PARAMETERS["series_kelvin1_k_n_per_m"].bounds[1]
#: Unrestricted inlet: the upper bound of ``orifice_area_m2`` (the pressure drop at step flows is < 1 Pa).
OPEN_ORIFICE_M2 = PARAMETERS["orifice_area_m2"].bounds[1]

_LIST = (
    _effect(
        "hysteresis",
        "rate-independent friction between the tube walls (Dahl element): loading and unloading curves split",
        "physics",
        ("friction_force_n", "friction_pressure_fraction", "friction_stiffness_n_per_m"),
        {"friction_force_n": 0.0, "friction_pressure_fraction": 0.0},
        {"friction_force_n": 0.05, "friction_pressure_fraction": 5e-4, "friction_stiffness_n_per_m": 2e4},
        ("friction_force_n", "friction_pressure_fraction"),
        "loading_split",
        ("load_cycle",),
        {"friction_stiffness_n_per_m": 2e4},
        model={"friction": "parallel"},
    ),
    _effect(
        "viscoelastic_relaxation",
        "a Maxwell branch (spring and dashpot) across the tubes: a rate-dependent loss and relaxation",
        "physics",
        ("parallel_maxwell1_k_n_per_m", "parallel_maxwell1_tau_s"),
        {"parallel_maxwell1_k_n_per_m": 0.0},
        {"parallel_maxwell1_k_n_per_m": 50.0, "parallel_maxwell1_tau_s": 1.0},
        ("parallel_maxwell1_k_n_per_m",),
        "relaxation",
        ("load_cycle",),
        {"parallel_maxwell1_tau_s": 1.0},
        model={"parallel_maxwell": 1},
    ),
    _effect(
        "series_viscoelastic",
        "a Kelvin-Voigt unit (spring and dashpot in parallel) in series with the tensile spring, the series element "
        "of the viscoelastic structure the paper proposes: the film stretches late under a changing force",
        "physics",
        ("series_kelvin1_k_n_per_m", "series_kelvin1_tau_s"),
        {"series_kelvin1_k_n_per_m": RIGID_KELVIN_N_PER_M},
        {"series_kelvin1_k_n_per_m": 2e6, "series_kelvin1_tau_s": 1.0},
        ("series_kelvin1_k_n_per_m",),
        "relaxation_at_load",
        ("blocking", "load_cycle"),
        {"series_kelvin1_tau_s": 1.0},
        model={"series_kelvin": 1},
    ),
    _effect(
        "series_compliance",
        "a compliant mount or coupling in series: measured stiffness and blocking force lower than the tubes'",
        "physics",
        ("mount_compliance_m_per_n",),
        {"mount_compliance_m_per_n": 0.0},
        {"mount_compliance_m_per_n": 1e-7},
        ("mount_compliance_m_per_n",),
        "force_level",
        ("blocking", "load_cycle"),
        model={"mount": True},
    ),
    _effect(
        "bending_stiffness",
        "bending resistance of the tube walls: free strain below the ideal tubes', most at low pressure",
        "physics",
        ("bending_k1_n", "bending_k2_n", "bending_exponent"),
        {"bending_k1_n": 0.0, "bending_k2_n": 0.0},
        {"bending_k1_n": 0.02, "bending_k2_n": 0.2, "bending_exponent": 6.0},
        ("bending_k1_n", "bending_k2_n"),
        "free_strain",
        ("stroke", "step"),
        {"bending_exponent": 6.0},
        model={"bending": True},
    ),
    _effect(
        "tensile_stiffness",
        "stretch of the tube film under load: finite blocking force, force lower near zero contraction",
        "physics",
        ("tensile_ka_n_per_m", "tensile_kb_n_per_m2"),
        {"tensile_ka_n_per_m": RIGID_TENSILE_N_PER_M, "tensile_kb_n_per_m2": 0.0},
        {"tensile_ka_n_per_m": 2e5, "tensile_kb_n_per_m2": 1e5},
        ("tensile_ka_n_per_m",),
        "blocking_pressure",
        ("blocking", "load_cycle"),
        model={"tensile": True},
    ),
    _effect(
        "strain_stiffening",
        "passive stiffening in extension as the fibres align: force rises steeply when stretched",
        "physics",
        ("extension_k_n_per_m", "extension_rate"),
        {"extension_k_n_per_m": 0.0},
        {"extension_k_n_per_m": 20.0, "extension_rate": 50.0},
        ("extension_k_n_per_m",),
        "extension",
        ("load_cycle",),
        {"extension_rate": 50.0},
        model={"extension": True},
    ),
    _effect(
        "threshold_pressure",
        "a pressure below which the flat tubes do not open: no force or stroke at low pressure",
        "physics",
        ("threshold_pressure_pa",),
        {"threshold_pressure_pa": 0.0},
        {"threshold_pressure_pa": 500.0},
        ("threshold_pressure_pa",),
        "low_pressure",
        ("stroke", "blocking"),
        model={"threshold": True},
    ),
    _effect(
        "flow_restriction",
        "a restriction of the inlet: the muscle pressure lags the supply in a step",
        "physics",
        ("orifice_area_m2",),
        {"orifice_area_m2": OPEN_ORIFICE_M2},
        {"orifice_area_m2": 0.9 * OPEN_ORIFICE_M2},
        ("orifice_area_m2",),
        "step_onset",
        ("step",),
        model={"flow": "orifice"},
    ),
    _effect(
        "nonlinear_damping",
        "direction-dependent and quadratic damping of the moving load: rise and fall differ, overshoot damped",
        "physics",
        ("damping_up_ns_per_m", "damping_down_ns_per_m", "damping_quadratic_ns2_per_m2"),
        {"damping_up_ns_per_m": 0.0, "damping_down_ns_per_m": 0.0, "damping_quadratic_ns2_per_m2": 0.0},
        {"damping_up_ns_per_m": 2.0, "damping_down_ns_per_m": 2.0, "damping_quadratic_ns2_per_m2": 5.0},
        ("damping_up_ns_per_m", "damping_down_ns_per_m", "damping_quadratic_ns2_per_m2"),
        "step_motion",
        ("step",),
        model={"damping": True},
    ),
    _effect(
        "cyclic_softening",
        "the first cycles of a test are stiffer than later ones (Mullins-like damage of the film)",
        "physics",
        ("cyclic_softening_fraction",),
        {"cyclic_softening_fraction": 0.0},
        {"cyclic_softening_fraction": 0.01},
        ("cyclic_softening_fraction",),
        "first_cycle",
        ("blocking", "load_cycle"),
    ),
    _effect(
        "sensor_offset",
        "a zero offset of the load cell (not physics)",
        "noise",
        ("sensor_offset_n",),
        {"sensor_offset_n": 0.0},
        {"sensor_offset_n": 0.0},
        ("sensor_offset_n",),
        "force_offset",
        ("load_cycle", "blocking"),
    ),
    _effect(
        "sensor_gain",
        "a gain error of the load cell (not physics)",
        "noise",
        ("sensor_gain",),
        {"sensor_gain": 1.0},
        {"sensor_gain": 1.0},
        ("sensor_gain",),
        "force_level",
        ("load_cycle", "blocking"),
    ),
    _effect(
        "heteroscedastic_noise",
        "force noise that grows with the force (not physics)",
        "noise",
        ("noise_slope_per_n",),
        {"noise_slope_per_n": 0.0},
        {"noise_slope_per_n": 0.01},
        ("noise_slope_per_n",),
        "noise_level",
        ("load_cycle", "blocking"),
    ),
    _effect(
        "session_baseline",
        "a slow force baseline over the session (a cubic in session time): structure no library effect "
        "produces, such as sensor drift; described, never named",
        "flexible",
        BASELINE_PARAMETERS,
        {p: 0.0 for p in BASELINE_PARAMETERS},
        {"baseline_p1_n": 0.01, "baseline_p2_n": 0.0, "baseline_p3_n": 0.0},
        BASELINE_PARAMETERS,
        "session_trend",
        ("load_cycle", "blocking"),
    ),
)

#: name -> :class:`Effect`, every candidate the workflow screens.
LIBRARY: MappingProxyType = MappingProxyType({e.name: e for e in _LIST})
#: The physics effects (elements of the muscle model).
PHYSICS_EFFECTS: tuple[str, ...] = tuple(e.name for e in _LIST if e.kind == "physics")
#: Noise-side alternatives: never reported as physics.
NOISE_EFFECTS: tuple[str, ...] = tuple(e.name for e in _LIST if e.kind == "noise")
#: Flexible terms: they describe leftover structure and never name an effect.
FLEXIBLE_TERMS: tuple[str, ...] = tuple(e.name for e in _LIST if e.kind == "flexible")
#: Noise-side effects that widen the noise instead of moving the prediction: they can mimic any misfit, so the
#: workflow accepts them only when nothing else passes (a sensor offset or gain moves the prediction and competes
#: with physics on held-out gain).
WIDENING_NOISE: tuple[str, ...] = ("heteroscedastic_noise",)
assert set(WIDENING_NOISE) <= set(NOISE_EFFECTS)

#: Pairs the rig's four tests cannot always tell apart, and the experiment that separates them
#: An ``ambiguous`` verdict names one of these.
CONFUSABLE: MappingProxyType = MappingProxyType(
    {
        frozenset({"hysteresis", "viscoelastic_relaxation"}): "load cycles at two or more strain rates: "
        "a viscoelastic loop grows with rate, a friction loop does not",
        frozenset({"hysteresis", "series_viscoelastic"}): "load cycles at two or more strain rates: "
        "a viscoelastic loop grows with rate, a friction loop does not",
        frozenset({"viscoelastic_relaxation", "series_viscoelastic"}): "strain holds at zero pressure and at the "
        "test pressure: a branch across the tubes relaxes where the tubes move (zero pressure), an element in "
        "series with the film where the force is high (test pressure)",
        frozenset({"series_viscoelastic", "series_compliance"}): "a constant force held on the muscle: a series "
        "viscoelastic element keeps stretching after the force settles (creep), a mount does not",
        frozenset({"flow_restriction", "nonlinear_damping"}): "isometric (blocked) steps as well as free steps: "
        "an inlet restriction delays the force of a blocked muscle, load damping does not",
        frozenset({"series_compliance", "tensile_stiffness"}): "the muscle's own strain measured on the muscle "
        "(not at the actuator), or the mount's compliance measured on its own: a second mount of known "
        "compliance adds to the same series chain and does not separate them",
        frozenset({"series_compliance", "sensor_gain"}): "a calibration weight on the load cell",
        frozenset({"cyclic_softening", "viscoelastic_relaxation"}): "the first cycle repeated after a long rest: "
        "softening that recovers is viscoelastic, softening that stays is damage",
    }
)


#: Effects that stand in for another on one specimen's rig tests: the key's parameters absorb the listed
#: effects, so a model without them is no evidence of their absence. A series mount on a linear film is exactly
#: the film at the series stiffness ka / (1 + ka c) (tests/test_simulate.py); on a stiffening film only a mount
#: large against the film departs from it, so the fitted tensile stiffness is the film and the mount together.
ABSORBS: MappingProxyType = MappingProxyType({"tensile_stiffness": ("series_compliance",)})
assert all({k, *v} <= set(LIBRARY) for k, v in ABSORBS.items())


def check_effects(names) -> tuple[str, ...]:
    """Effect names in order, duplicates removed; an unknown name raises ``PeanoBayesInputError``."""
    from ..errors import PeanoBayesInputError, did_you_mean

    out = tuple(dict.fromkeys(names))
    for name in out:
        if name not in LIBRARY:
            raise PeanoBayesInputError(
                f"unknown effect {name!r}{did_you_mean(name, LIBRARY)}; known effects: {', '.join(LIBRARY)}"
            )
    return out


__all__ = [
    "ABSORBS",
    "BASELINE_PARAMETERS",
    "CONFUSABLE",
    "EXTRA_PARAMETERS",
    "Effect",
    "FLEXIBLE_TERMS",
    "LIBRARY",
    "NOISE_EFFECTS",
    "OPEN_ORIFICE_M2",
    "PHYSICS_EFFECTS",
    "RIGID_TENSILE_N_PER_M",
    "WIDENING_NOISE",
    "check_effects",
    "parameter_spec",
]
