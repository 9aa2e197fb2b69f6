"""The effect registry: every effect a Peano muscle's data may show, defined once.

An :class:`Effect` says everything the package knows about one effect: its parameters and the ``off`` values at
which it changes nothing; the :class:`~peano_bayes.physics.ModelConfig` fields that put its element into a model
(``model``; :meth:`Effect.switch_on`); whether the virtual rig can switch it on as a hidden effect (a *quirk*,
:attr:`Effect.switchable`) and the parameters at which the validation benchmark hides it at strength ``s``
(``hidden_at``); the residual pattern its absence leaves (``signature``, :mod:`~peano_bayes.discovery.diagnose`)
and the tests it shows in (``shows_in``, scored on :attr:`Effect.scored_test`); and, across effects, the pairs
the rig's tests cannot tell apart (:data:`CONFUSABLE`) and the effects one stands in for (:data:`ABSORBS`).

Everything else derives from here: the rig's quirks (:func:`peano_bayes.rig.check_quirks`), the discovery
model's superset (:func:`superset_config`), discovery's candidates (:data:`LIBRARY`), the model a fit samples
when discovery names an effect (:func:`adopt`, :func:`effects_in`), the benchmark's hideable effects
(:func:`hideable`) and the discovery report. A new effect is one :class:`Effect` in ``_LIST`` below (or, for a
test or a plug-in, :func:`register`); an effect whose element the physics lacks needs that element in
:mod:`peano_bayes.physics` first. The discovery model compiles the superset of the effects registered when it is
first imported.

Kinds: physics effects are elements of :class:`~peano_bayes.physics.ModelConfig` (or, for
``cyclic_softening``, a per-cycle stiffness factor); noise-side effects change only the sensor or the noise
model, so that a sensor problem is never reported as physics. The one flexible term, ``session_baseline``,
describes slow structure against time in the session that no library effect produces (a flexible term may
compete, but never names an effect); the workflow reports it as unexplained structure.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal

from .errors import PeanoBayesInputError, did_you_mean
from .physics.model import PARAMETERS, ModelConfig, Parameter

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
    """One effect.

    **Fields:** ``name``; ``meaning``; ``kind`` ``"physics"``, ``"noise"`` or ``"flexible"`` (describes
    structure, never named); ``params`` the parameters it frees; ``off`` name -> value at which it changes
    nothing (the others of ``params`` are held at ``hold`` while inactive); ``start`` name -> weak but non-zero
    value its screening fit starts from; ``strength`` the parameters tested against ``off``; ``signature`` the
    residual pattern its absence leaves (a key of :data:`~peano_bayes.discovery.diagnose.SIGNATURES`);
    ``shows_in`` the rig tests where that pattern appears, the first the one the effect acts on most
    (:attr:`scored_test`); ``model`` the :class:`~peano_bayes.physics.ModelConfig` fields that put the effect
    into a model (empty where the physics has no such element: the noise-side and flexible terms, and
    ``cyclic_softening``); ``not_a_switch`` why the virtual rig cannot switch it on as a quirk (an element of
    every model, set through its parameters, or no element), empty where it can; ``hidden_at`` ``s -> {name:
    value [SI]}``, the parameters at which the validation benchmark hides it at strength ``s`` (``None``: the
    benchmark does not hide it).
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
    not_a_switch: str = ""
    hidden_at: Callable[[float], dict] | None = None

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

    @property
    def switchable(self) -> bool:
        """Whether the virtual rig can switch the effect's element on (a quirk): a physics effect with an
        element (``model``) that is not in every model."""
        return self.kind == "physics" and bool(self.model) and not self.not_a_switch

    def held_by(self, config: ModelConfig) -> bool:
        """Whether ``config`` contains the effect's element (every field of ``model``, :func:`_holds`)."""
        return bool(self.model) and all(_holds(config, f, v) for f, v in self.model.items())

    def switch_on(self, config: ModelConfig) -> ModelConfig:
        """``config`` with the effect's element on; unchanged where it already holds it (a friction or inlet
        law already chosen is kept, a number of branches only grows)."""
        changes = {f: v for f, v in self.model.items() if not _holds(config, f, v)}
        return dataclasses.replace(config, **changes) if changes else config


def _holds(config: ModelConfig, field: str, value) -> bool:
    """Whether ``config`` contains what ``field = value`` switches on. A field naming a law counts with any law
    but ``"none"`` (Dahl friction across the tubes or the whole muscle; an orifice or a laminar inlet, so
    ``flow_restriction`` is in every model and ``value`` only says which law :meth:`Effect.switch_on` would
    choose), so an effect never replaces the law a model has; a number of branches counts when at least
    ``value``."""
    current = getattr(config, field)
    if isinstance(value, str):
        return current != "none"
    if isinstance(value, bool):
        return bool(current) or not value
    if isinstance(value, int):
        return current >= value
    return current == value


def _effect(name, meaning, kind, params, off, start, strength, signature, shows_in, hold=None, model=None,
            not_a_switch="", hidden_at=None) -> Effect:  # fmt: skip
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
        not_a_switch,
        hidden_at,
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
        hidden_at=lambda s: {
            "friction_force_n": 0.5 * s,
            "friction_pressure_fraction": 0.05 * s,
            "friction_stiffness_n_per_m": 2e4,
        },
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
        ("step",),
        {"parallel_maxwell1_tau_s": 1.0},
        model={"parallel_maxwell": 1},
        hidden_at=lambda s: {"parallel_maxwell1_k_n_per_m": 500.0 * s, "parallel_maxwell1_tau_s": 2.0},
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
        hidden_at=lambda s: {"series_kelvin1_k_n_per_m": 2e4 / s, "series_kelvin1_tau_s": 2.0},
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
        hidden_at=lambda s: {"mount_compliance_m_per_n": 1e-5 * s},
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
        not_a_switch="set bending_k1_n / bending_k2_n instead",
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
        not_a_switch="set tensile_ka_n_per_m / tensile_kb_n_per_m2 instead",
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
        hidden_at=lambda s: {"extension_k_n_per_m": 200.0 * s, "extension_rate": 50.0},
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
        hidden_at=lambda s: {"threshold_pressure_pa": 5e3 * s},
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
        not_a_switch='set orifice_area_m2 (or [config] flow = "laminar") instead',
        hidden_at=lambda s: {"orifice_area_m2": max(OPEN_ORIFICE_M2 / (1.0 + 10.0 * s), 1e-7)},
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
        hidden_at=lambda s: {
            "damping_up_ns_per_m": 20.0 * s,
            "damping_down_ns_per_m": 5.0 * s,
            "damping_quadratic_ns2_per_m2": 50.0 * s,
        },
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
        not_a_switch="the physics has no such element yet",
        hidden_at=lambda s: {"cyclic_softening_fraction": 0.1 * s},
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

_REGISTRY: dict[str, Effect] = {e.name: e for e in _LIST}
#: name -> :class:`Effect`: every registered effect, in registration order (a live, read-only view: what
#: :func:`register` adds appears here). Discovery screens every effect of it not in the model.
LIBRARY: Mapping[str, Effect] = MappingProxyType(_REGISTRY)


def of_kind(kind: str) -> tuple[str, ...]:
    """Names of the registered effects of ``kind`` (``"physics"``, ``"noise"`` or ``"flexible"``), in registry
    order; read from the live registry, so an effect :func:`register` adds is among them."""
    return tuple(e.name for e in LIBRARY.values() if e.kind == kind)


def physics_effects() -> tuple[str, ...]:
    """The physics effects (elements of the muscle model): the only kind discovery names."""
    return of_kind("physics")


def noise_effects() -> tuple[str, ...]:
    """Noise-side alternatives: never reported as physics."""
    return of_kind("noise")


def flexible_terms() -> tuple[str, ...]:
    """Flexible terms: they describe leftover structure and never name an effect."""
    return of_kind("flexible")


#: Noise-side effects that widen the noise instead of moving the prediction: they can mimic any misfit, so the
#: workflow accepts them only when nothing else passes (a sensor offset or gain moves the prediction and competes
#: with physics on held-out gain).
WIDENING_NOISE: tuple[str, ...] = ("heteroscedastic_noise",)
assert set(WIDENING_NOISE) <= set(noise_effects())

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
    out = tuple(dict.fromkeys(names))
    for name in out:
        if name not in LIBRARY:
            raise PeanoBayesInputError(
                f"unknown effect {name!r}{did_you_mean(name, LIBRARY)}; known effects: {', '.join(LIBRARY)}"
            )
    return out


def register(effect: Effect) -> Effect:
    """Add ``effect`` to the registry (a plug-in's or a test's effect); refuses a name already taken, an unknown
    parameter or an ``off`` value for a parameter the effect does not free. Returns ``effect``."""
    if effect.name in _REGISTRY:
        raise PeanoBayesInputError(f"effect {effect.name!r} is already registered")
    unknown = [p for p in effect.params if p not in PARAMETERS and p not in EXTRA_PARAMETERS]
    if unknown:
        raise PeanoBayesInputError(f"effect {effect.name!r}: unknown parameter(s) {', '.join(unknown)}")
    stray = [p for p in (*effect.off, *effect.hold, *effect.strength) if p not in effect.params]
    if stray:
        raise PeanoBayesInputError(f"effect {effect.name!r}: {', '.join(stray)} not among its params")
    _REGISTRY[effect.name] = effect
    return effect


@contextmanager
def registered(effect: Effect) -> Iterator[Effect]:
    """``effect`` registered for the duration of a ``with`` block (tests), removed afterwards."""
    register(effect)
    try:
        yield effect
    finally:
        _REGISTRY.pop(effect.name, None)


def effects_in(config: ModelConfig) -> tuple[str, ...]:
    """The registered physics effects whose element ``config`` contains, in registry order."""
    return tuple(e.name for e in LIBRARY.values() if e.kind == "physics" and e.held_by(config))


def adopt(config: ModelConfig, named) -> ModelConfig:
    """``config`` with the elements of the ``named`` effects switched on (effects without an element, and those
    already contained, change nothing)."""
    for name in named:
        config = LIBRARY[name].switch_on(config)
    return config


def switchable() -> dict[str, Effect]:
    """name -> :class:`Effect` of every effect the virtual rig can switch on (:attr:`Effect.switchable`)."""
    return {n: e for n, e in LIBRARY.items() if e.switchable}


def hideable() -> dict[str, Effect]:
    """name -> :class:`Effect` of every effect the validation benchmark can hide (it has ``hidden_at``)."""
    return {n: e for n, e in LIBRARY.items() if e.hidden_at is not None}


def superset_config(effects: Mapping[str, Effect] | None = None) -> ModelConfig:
    """The smallest :class:`ModelConfig` that holds the element of every physics effect of ``effects`` (default:
    the registry), each element on: the discovery model's superset."""
    config = ModelConfig(
        bending=False, tensile=False, extension=False, mount=False, parallel_maxwell=0, series_kelvin=0,
        friction="none", threshold=False, flow="orifice", damping=False,
    )  # fmt: skip
    for effect in (LIBRARY if effects is None else effects).values():
        if effect.kind == "physics":
            config = effect.switch_on(config)
    return config


__all__ = [
    "ABSORBS",
    "adopt",
    "effects_in",
    "hideable",
    "register",
    "registered",
    "superset_config",
    "switchable",
    "BASELINE_PARAMETERS",
    "CONFUSABLE",
    "EXTRA_PARAMETERS",
    "Effect",
    "flexible_terms",
    "LIBRARY",
    "noise_effects",
    "of_kind",
    "OPEN_ORIFICE_M2",
    "physics_effects",
    "RIGID_TENSILE_N_PER_M",
    "WIDENING_NOISE",
    "check_effects",
    "parameter_spec",
]
