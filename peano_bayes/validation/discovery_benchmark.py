"""Validation of discovery on virtual-rig data with a hidden effect: the effect is known, discovery must name it.

A :class:`Case` says what the rig hides: one library effect at a signal-to-noise ratio, none, two effects, or
slow load-cell drift (an effect outside the library). :func:`hidden_dataset` simulates it; the label never
reaches :func:`~peano_bayes.discovery.workflow.discover`, only :func:`score` sees it.

**Truth:** Veale's elastic model (:data:`TRUTH_CONFIG`, the discovery base) at nominal parameters with an open
inlet, on material PC's protocol (200 kPa), shortened (:data:`PROTOCOL`), one specimen, three repeats.
``bending_stiffness`` and ``tensile_stiffness`` are part of every base (see
:data:`~peano_bayes.discovery.model.DEFAULT_BASE`) and so cannot be hidden.

**Signal-to-noise ratio:** for strength factor ``s`` of an effect's reference parameters (``hidden_at`` of
:mod:`peano_bayes.effects`), ``SNR = max over tests of RMS(y_with - y_without) / sigma_test`` from noise-free
simulations at equal base parameters, with ``sigma_test`` the rig's per-sample noise of that test's signal.
:func:`strength_for_snr` finds ``s`` by bisection in log ``s``.

**Other physics** (``Case.physics``): ``"veale"``, Veale's force-balance model (Table 2; static, so load cycles,
blocking and stroke only; :func:`~peano_bayes.rig.simulate_veale_dataset`) and ``"surface"``, a Sarosi-type force
surface with all four tests (Table 1; :func:`~peano_bayes.rig.simulate_surface_dataset`). With nothing hidden a
case is a null on data no model of this package made. An effect is hidden on them by transplanting it: the other
physics' noise-free signals plus the effect's own contribution in the package's physics at the same inputs
(:func:`effect_contribution`: the noise-free truth with the effect at its strength minus without, one specimen at
seed 0, on the case's conditions), then the rig's noise. The strength is calibrated on that contribution over
the tests the physics runs (:func:`case_strengths`), so the nominal SNR is the transplanted signal's. On Veale's
model an effect whose signal shows only in the step test (the registry's ``shows_in``: ``viscoelastic_relaxation``,
``flow_restriction``, ``nonlinear_damping``) cannot be hidden.

**Drawn conditions** (``Case.conditions = "drawn"``): the quasi-static sampling rate (10-100 Hz) and the test
pressure (100-400 kPa, peak forces about 100-300 N) drawn from the seed (:func:`~peano_bayes.rig.draw_conditions`,
its own seed stream), recorded in the dataset's provenance (``drawn_conditions``) and the row (``conditions``);
the strengths are calibrated on each seed's conditions. The default, ``"fixed"``, is material PC's pressure on
:data:`PROTOCOL`, and every case with the defaults makes the data it made before these options existed.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import time
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ..data import Dataset
from ..discovery.model import DEFAULT_BASE, NAMES, ModelSpec, model_spec
from ..effects import CONFUSABLE, LIBRARY, OPEN_ORIFICE_M2, hideable, physics_effects
from ..errors import did_you_mean
from ..inference.reduce import OBSERVED, SPECIMEN_SCALED
from ..physics import ModelConfig
from ..rig import (
    RIG_TESTS,
    SURFACE_TESTS,
    VEALE_TESTS,
    DrawnConditions,
    RigNoise,
    RigProtocol,
    RigSimulationError,
    draw_conditions,
    simulate_dataset,
    simulate_surface_dataset,
    simulate_veale_dataset,
)

MATERIAL = "PC"
TRUTH_CONFIG = ModelConfig(bending=True, tensile=True, extension=False, friction="none")
TRUTH_PARAMS = {**TRUTH_CONFIG.nominal_parameters(), "orifice_area_m2": OPEN_ORIFICE_M2}
PROTOCOL = RigProtocol(
    quasi_static_rate_hz=10.0,
    cycle_duration_s=16.0,
    ramp_duration_s=8.0,
    step_rate_hz=250.0,
    step_duration_s=0.3,
    step_substeps=2,
)
REPEATS = 3
#: A rig without sensor noise or drift.
QUIET = RigNoise(0.0, 0.0, 0.0, 0.0, 0.0)
#: Where a case's data come from: the package's own physics, Veale's force-balance model, or a Sarosi-type surface.
PHYSICS = ("peano", "veale", "surface")
#: The rig tests each physics runs (Veale's model is static: no step test).
PHYSICS_TESTS = MappingProxyType({"peano": RIG_TESTS, "veale": VEALE_TESTS, "surface": SURFACE_TESTS})
#: How a case's conditions are set: material PC's on :data:`PROTOCOL`, or drawn per seed.
CONDITIONS = ("fixed", "drawn")
#: The signals of an effect's contribution transplanted onto another physics (what every physics measures).
TRANSPLANTED = ("strain", "pressure_pa", "force_n")
#: Reference force noise [N] at which SNRs are calibrated; strain noise scales with it (2e-4 per 0.2 N).
REFERENCE_FORCE_SD_N = 0.2
#: The second mount of the two-mount cases [m/N]: twice the series compliance the benchmark hides at SNR 2.
SECOND_MOUNT_M_PER_N = 2e-5
TWO_MOUNTS = (0.0, SECOND_MOUNT_M_PER_N)
#: Load-cell drift of the out-of-library case [N/s] (about 0.7 N over one specimen's session).
DRIFT_N_PER_S = 0.005


#: Effects the benchmark can hide (:func:`~peano_bayes.effects.hideable`: each registry entry's ``hidden_at``
#: gives its parameters at strength ``s``; the rig switches the element on where it is a quirk).
def not_hideable() -> tuple[str, ...]:
    """The registered physics effects the benchmark never hides: part of every base model."""
    return tuple(e for e in physics_effects() if e not in hideable())


@dataclass(frozen=True)
class Case:
    """What the rig hides. ``effects`` names (empty: none); ``snr`` of each; ``drift`` load-cell drift (out of
    library); ``force_sd_n`` the load cell's noise [N] (strain noise scales with it); ``pressure_sd_pa`` the
    pressure sensors' noise [Pa] (default the rig's, :class:`~peano_bayes.rig.RigNoise`; probes shrink it).
    ``physics``: ``"peano"`` (the package's own model, the default), ``"veale"`` (Veale's force-balance model,
    Table 2, quasi-static tests only) or ``"surface"`` (a Sarosi-type force surface, all four tests): data from
    another model of the muscle, a null when nothing is hidden (naming an effect is then a false positive), and
    with ``effects`` each transplanted onto it (module docstring); on one mount, without drift. ``mounts``: the
    known compliances the specimen is tested on (:data:`TWO_MOUNTS` runs the protocol on the rig's mount and
    on one :data:`SECOND_MOUNT_M_PER_N` softer; every run records its mount, see ``docs/data-format.md``).
    ``conditions``: ``"fixed"`` (material PC's on :data:`PROTOCOL`) or ``"drawn"`` per seed (module docstring).
    Raises ``ValueError`` for an unknown physics or conditions, drift or mounts on another physics, and an
    effect that cannot be hidden on the case's physics (with the reason)."""

    effects: tuple[str, ...] = ()
    snr: float = 0.0
    drift: bool = False
    force_sd_n: float = REFERENCE_FORCE_SD_N
    pressure_sd_pa: float = RigNoise.pressure_sd_pa
    physics: str = "peano"
    mounts: tuple[float, ...] = (0.0,)
    conditions: str = "fixed"

    def __post_init__(self):
        if self.physics not in PHYSICS:
            raise ValueError(
                f"Case.physics must be one of {', '.join(PHYSICS)}, got {self.physics!r}"
                + did_you_mean(str(self.physics), PHYSICS)
            )
        if self.conditions not in CONDITIONS:
            raise ValueError(f"Case.conditions must be one of {', '.join(CONDITIONS)}, got {self.conditions!r}")
        if self.physics != "peano":
            if self.drift or self.mounts != (0.0,):
                raise ValueError(
                    f"a case on {self.physics}'s physics runs on one mount without drift (drift and mounts are the "
                    "package rig's)"
                )
            for effect in self.effects:
                _check_transplant(effect, self.physics)

    @property
    def label(self) -> str:
        drawn = "@drawn" if self.conditions == "drawn" else ""
        name = "+".join(self.effects) if self.effects else "none"
        if self.physics != "peano":
            return f"{name}-{self.physics}{drawn}"
        if self.drift:
            return "drift" + drawn
        return name + (f"@{len(self.mounts)}mounts" if self.mounts != (0.0,) else "") + drawn

    @property
    def own_calibration(self) -> bool:
        """Whether the case hides effects whose strengths depend on more than (effect, SNR): calibrated on its
        own conditions and tests (:func:`case_strengths`), not by :func:`strength_for_snr` on the fixed
        protocol."""
        return bool(self.effects) and (self.conditions != "fixed" or PHYSICS_TESTS[self.physics] != RIG_TESTS)


#: What each physics is, for messages.
_PHYSICS_NAMES = {
    "peano": "the package's model",
    "veale": "Veale's force-balance model",
    "surface": "the Sarosi-type surface",
}


def _check_transplant(effect: str, physics: str) -> None:
    """Raise ``ValueError`` unless ``effect`` can be hidden on ``physics`` (another physics than the package's)."""
    if effect not in hideable():
        raise ValueError(
            f"effect {effect!r} cannot be hidden{did_you_mean(str(effect), hideable())}; hideable effects: "
            + ", ".join(hideable())
        )
    runs = PHYSICS_TESTS[physics]
    shows_in = LIBRARY[effect].shows_in
    if not set(shows_in) & set(runs):
        static = " (it is static: no step test)" if "step" not in runs else ""
        raise ValueError(
            f"effect {effect!r} cannot be hidden on {physics}: its signal shows only in the {', '.join(shows_in)} "
            f"test (the registry's shows_in), and {_PHYSICS_NAMES[physics]} runs only {', '.join(runs)}{static}"
        )


def hideable_on(physics: str) -> tuple[str, ...]:
    """The effects a case on ``physics`` can hide: every hideable effect on the package's physics and on the
    surface; on Veale's model those whose signal shows in a quasi-static test."""
    if physics == "peano":
        return tuple(hideable())
    out = []
    for effect in hideable():
        try:
            _check_transplant(effect, physics)
        except ValueError:
            continue
        out.append(effect)
    return tuple(out)


def case_conditions(case: Case, seed: int) -> DrawnConditions | None:
    """The conditions ``case`` draws at ``seed`` (:func:`~peano_bayes.rig.draw_conditions`), ``None`` when fixed."""
    return draw_conditions(seed) if case.conditions == "drawn" else None


def _setting(drawn: DrawnConditions | None):
    """The material (code or spec) and protocol of a session on ``drawn`` conditions (``None``: the fixed ones)."""
    if drawn is None:
        return MATERIAL, PROTOCOL
    return drawn.material(MATERIAL), drawn.protocol(PROTOCOL)


def rig_noise(force_sd_n: float, pressure_sd_pa: float = RigNoise.pressure_sd_pa) -> RigNoise:
    scale = force_sd_n / REFERENCE_FORCE_SD_N
    return RigNoise(
        force_sd_n=force_sd_n,
        strain_sd=2e-4 * scale,
        pressure_sd_pa=pressure_sd_pa,
        force_drift_n_per_s=DRIFT_N_PER_S,
    )


def _simulate(
    params: dict,
    quirks: tuple,
    seed: int,
    noise: RigNoise,
    drift: bool,
    softening: float,
    mounts=(0.0,),
    drawn: DrawnConditions | None = None,
    tests: tuple[str, ...] | None = None,
) -> Dataset:
    material, protocol = _setting(drawn)
    kw = dict(
        added_compliances=mounts,
        config=TRUTH_CONFIG,
        quirks=quirks,
        seed=seed,
        noise=noise,
        drift=drift,
        specimens=1,
        repeats=REPEATS,
        protocol=protocol,
    )
    if tests is not None:
        kw["tests"] = tests
    if softening == 0.0:
        return simulate_dataset(material, params, **kw)
    # Cyclic softening: run n (its cycle index) of every condition has its wall stiffness scaled by 1 + a e^-n.
    runs = []
    for n in range(REPEATS):
        factor = 1.0 + softening * math.exp(-n)
        scaled = {k: v * factor if k in SPECIMEN_SCALED else v for k, v in params.items()}
        ds = simulate_dataset(material, scaled, **kw)
        runs += [r for r in ds.runs if r.run % REPEATS == n]
    order = {r.key: i for i, r in enumerate(simulate_dataset(material, params, **kw).runs)}
    return dataclasses.replace(ds, runs=tuple(sorted(runs, key=lambda r: order[r.key])))


def _truth(effects: tuple[str, ...], strengths: dict) -> tuple[dict, tuple, float]:
    params, quirks, softening = dict(TRUTH_PARAMS), (), 0.0
    for e in effects:
        effect = LIBRARY[e]
        values = dict(effect.hidden_at(strengths[e]))
        q = (e,) if effect.switchable else ()
        softening = values.pop("cyclic_softening_fraction", softening)
        params.update(values)
        quirks += q
    return params, quirks, softening


def true_parameters(effects: tuple[str, ...], strengths: dict) -> dict:
    """The hidden truth in the discovery model's parameter names (SI units): the rig's parameters with
    ``effects`` at ``strengths`` (cyclic softening as ``cyclic_softening_fraction``)."""
    params, _, softening = _truth(effects, strengths)
    if softening:
        params["cyclic_softening_fraction"] = softening
    return params


def true_model(effect: str, strength: float) -> tuple[ModelSpec, np.ndarray]:
    """The discovery model with the default base plus ``effect``, and its start (d,) at the hidden truth
    (:func:`true_parameters`): what probes fit to measure the misfit the true structure leaves."""
    truth = {n: v for n, v in true_parameters((effect,), {effect: strength}).items() if n in NAMES}
    spec = model_spec((*DEFAULT_BASE, effect), truth)
    start = spec.pinned.copy()
    for name, value in truth.items():
        start[NAMES.index(name)] = value
    return spec, start


def reference_sigma(test: str) -> float:
    """The rig's per-sample noise sd of ``test``'s observed signal at :data:`REFERENCE_FORCE_SD_N` [N or -]."""
    noise = rig_noise(REFERENCE_FORCE_SD_N)
    return noise.force_sd_n if OBSERVED[test][0] == "force_n" else noise.strain_sd


@functools.lru_cache(maxsize=8)
def _package_null(drawn: DrawnConditions | None, tests: tuple[str, ...] | None) -> Dataset:
    """The noise-free truth without a hidden effect, one specimen at seed 0, on ``drawn`` conditions and ``tests``
    (``None``: every test): what calibration and transplanting subtract."""
    return _simulate(dict(TRUTH_PARAMS), (), 0, QUIET, False, 0.0, drawn=drawn, tests=tests)


def snr_by_test(
    effect: str, strength: float, drawn: DrawnConditions | None = None, tests: tuple[str, ...] | None = None
) -> dict[str, float]:
    """Per rig test: RMS(y_with - y_without) / sigma of ``effect`` at ``strength``, at equal base parameters,
    noise-free (sigma: the rig's per-sample noise at :data:`REFERENCE_FORCE_SD_N`); on ``drawn`` conditions
    (default the fixed ones) and ``tests`` (default all four)."""
    without = _package_null(drawn, tests)
    params, quirks, softening = _truth((effect,), {effect: strength})
    with_ = _simulate(params, quirks, 0, QUIET, False, softening, drawn=drawn, tests=tests)
    out = {}
    for test in sorted({r.test for r in without.runs}):
        signal = OBSERVED[test][0]
        a = np.concatenate([getattr(r, signal) for r in with_.runs if r.test == test])
        b = np.concatenate([getattr(r, signal) for r in without.runs if r.test == test])
        out[test] = float(np.sqrt(np.mean((a - b) ** 2))) / reference_sigma(test)
    return out


def _snr(effect: str, s: float, drawn: DrawnConditions | None = None, tests: tuple[str, ...] | None = None) -> float:
    return max(snr_by_test(effect, s, drawn, tests).values())


def _bisect_strength(snr_at, snr: float, iterations: int) -> float:
    """The strength ``s`` with ``snr_at(s) = snr`` by bisection in log s on [1e-3, 1e2]."""
    lo, hi = math.log(1e-3), math.log(1e2)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        try:
            value = snr_at(math.exp(mid))
        except RigSimulationError:  # a strength the physics solver cannot simulate counts as too strong
            value = math.inf
        lo, hi = (mid, hi) if value < snr else (lo, mid)
    return math.exp(0.5 * (lo + hi))


@functools.cache
def strength_for_snr(effect: str, snr: float, iterations: int = 12) -> float:
    """Strength factor ``s`` of ``effect`` whose SNR is ``snr`` (bisection in log s on [1e-3, 1e2])."""
    return _bisect_strength(lambda s: _snr(effect, s), snr, iterations)


@functools.cache
def strength_for_conditions(
    effect: str,
    snr: float,
    drawn: DrawnConditions | None = None,
    tests: tuple[str, ...] = RIG_TESTS,
    iterations: int = 12,
) -> float:
    """:func:`strength_for_snr` on ``drawn`` conditions (``None``: the fixed ones) with the SNR taken over
    ``tests`` only (the tests a case's physics runs); the fixed protocol on every test is
    :func:`strength_for_snr` itself. Cached by its arguments (the conditions carry their seed)."""
    tests = tuple(tests)
    if drawn is None and tests == RIG_TESTS:
        return strength_for_snr(effect, snr, iterations)
    return _bisect_strength(lambda s: _snr(effect, s, drawn, tests), snr, iterations)


def case_strengths(case: Case, seed: int) -> dict[str, float]:
    """The strength of each effect ``case`` hides at ``seed``: calibrated to ``case.snr`` on the case's
    conditions at that seed, over the tests its physics runs (:func:`strength_for_conditions`)."""
    drawn = case_conditions(case, seed)
    tests = PHYSICS_TESTS[case.physics]
    return {e: strength_for_conditions(e, case.snr, drawn, tests) for e in case.effects}


def effect_contribution(
    effects: tuple[str, ...], strengths: dict, drawn: DrawnConditions | None = None, tests=RIG_TESTS
) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """What ``effects`` at ``strengths`` add to the package's physics, noise-free: the truth with them minus the
    truth without (one specimen at seed 0, as calibrated), on ``drawn`` conditions and ``tests``. By ``(test,
    run)``: each signal of :data:`TRANSPLANTED` the test measures, (n,) [its SI unit] (the step's muscle pressure
    included: a restricted inlet lags it). What :func:`hidden_dataset` adds to another physics' signals."""
    tests = tuple(tests)
    without = _package_null(drawn, tests)
    params, quirks, softening = _truth(tuple(effects), strengths)
    with_ = _simulate(params, quirks, 0, QUIET, False, softening, drawn=drawn, tests=tests)
    out = {}
    for a, b in zip(with_.runs, without.runs, strict=True):
        if a.key != b.key:
            raise RuntimeError(f"the sessions with and without {', '.join(effects)} differ in their runs")
        deltas = {name: getattr(a, name) - getattr(b, name) for name in TRANSPLANTED}
        out[(a.test, a.run)] = {name: d for name, d in deltas.items() if np.all(np.isfinite(d))}
    return out


def hidden_dataset(case: Case, seed: int, strengths: dict | None = None, *, quiet: bool = False) -> Dataset:
    """The rig dataset of ``case`` at ``seed`` (strengths by effect, default calibrated by :func:`case_strengths`,
    which is :func:`strength_for_snr` for a case of the fixed protocol on every test). With ``quiet``, the same
    session without sensor noise or load-cell drift: the same specimens and inputs (the rig draws specimens and
    noise from separate streams), the signals as the muscle made them. A case on another physics is that physics'
    session with its effects' contributions added (:func:`effect_contribution`), recorded in the provenance
    (``transplanted``); drawn conditions are recorded too (``drawn_conditions``)."""
    noise = QUIET if quiet else rig_noise(case.force_sd_n, case.pressure_sd_pa)
    drawn = case_conditions(case, seed)
    if case.effects:
        strengths = strengths or case_strengths(case, seed)
    if case.physics == "peano":
        params, quirks, softening = _truth(case.effects, strengths or {})
        dataset = _simulate(params, quirks, seed, noise, case.drift and not quiet, softening, case.mounts, drawn=drawn)
    else:
        dataset = _other_physics(case, seed, noise, drawn, strengths)
    return dataset if drawn is None else drawn.record(dataset)


def _other_physics(case: Case, seed: int, noise: RigNoise, drawn, strengths) -> Dataset:
    """The session of ``case`` on another physics, its hidden effects transplanted (:func:`effect_contribution`)."""
    material, protocol = _setting(drawn)
    simulate = simulate_veale_dataset if case.physics == "veale" else simulate_surface_dataset
    kw = dict(seed=seed, noise=noise, specimens=1, repeats=REPEATS, protocol=protocol)
    if not case.effects:
        return simulate(material, **kw)
    added = effect_contribution(case.effects, strengths, drawn, PHYSICS_TESTS[case.physics])
    dataset = simulate(material, added=added, **kw)
    provenance = {
        **dataset.provenance,
        "transplanted": json.dumps(
            {
                "effects": {e: float(strengths[e]) for e in case.effects},
                "from": "peano_bayes' physics (discovery benchmark truth), noise-free, with minus without, one "
                "specimen at seed 0, on the same conditions",
            }
        ),
    }
    return dataclasses.replace(dataset, provenance=provenance)


def outcome_label(report: dict) -> str:
    """The confusion-matrix column of a discovery report."""
    if report["verdict"] == "ambiguous":
        return "ambiguous{" + ",".join(sorted(report["ambiguous"][0]["effects"])) + "}"
    if report["verdict"] == "named":
        return "+".join(sorted(report["named"]))
    return report["verdict"]


def score(case: Case, report: dict) -> dict:
    """Whether ``report`` is right about ``case``: ``correct`` and ``false_positive`` (a physics effect named
    when none or only drift is hidden). A drift is found only by an ``unexplained`` verdict that shows it in time
    (``drift_shown``; a report without the field has not shown it); a verdict ``unconverged`` is never correct.
    How much of the effect the model recovers is :func:`truth_gap`'s."""
    named = set(report["named"])
    for a in report["ambiguous"]:
        named |= set(a["effects"])
    truth = set(case.effects)
    if case.drift:  # out of the library: nothing to name, and the drift must be found and shown in time
        correct = report["verdict"] == "unexplained" and not named and bool(report.get("drift_shown", False))
    elif case.physics != "peano" and not truth:  # another physics, nothing hidden: nothing to name, a misfit may remain
        correct = report["verdict"] in ("none", "unexplained") and not named
    elif not truth:
        correct = report["verdict"] == "none"
    elif report["verdict"] == "ambiguous":
        sets = [frozenset(a["effects"]) for a in report["ambiguous"]]
        correct = (
            len(truth) == 1
            and any(s in CONFUSABLE and truth <= s for s in sets)
            and set(report["named"]) <= (truth | set().union(*sets))
        )
    else:
        correct = set(report["named"]) == truth
    return {
        "label": case.label,
        "outcome": outcome_label(report),
        "correct": bool(correct),
        "false_positive": bool((case.drift or not truth) and bool(named)),
    }


def noise_free_dataset(case: Case, seed: int, strengths: dict | None = None) -> Dataset:
    """``hidden_dataset(case, seed, strengths, quiet=True)``: the truth the benchmark scores models against."""
    return hidden_dataset(case, seed, strengths, quiet=True)


def _rmse(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def truth_gap(case: Case, seed: int, result, strengths: dict | None = None, tests=None) -> dict:
    """How much of the hidden effect the discovered model recovers, against the noise-free truth
    (:func:`noise_free_dataset`), on each hidden effect's scored test (fixed in the registry,
    :attr:`~peano_bayes.effects.Effect.scored_test`).

    ``result`` is the :class:`~peano_bayes.discovery.workflow.Discovery` of ``hidden_dataset(case, seed,
    strengths)`` on ``tests``. Per hidden effect: ``test``; ``before`` and ``after``, the held-out RMSE of the
    base and final models' predictions against the noise-free bin means [signal unit]; ``ratio`` after /
    before (target <= 0.5); ``effective_snr``, RMS(truth - base model) over all bins of that test (fitted and
    held-out) divided by the rig's per-sample noise sd: what is left of the effect for discovery to find once
    the base has absorbed what it can (the nominal SNR is before any refit). The row's ``gap_test`` and
    ``gap_ratio`` are the first hidden effect's; NaN where nothing is hidden or its test was not fitted."""
    from ..discovery import discovery_data

    rows = {"gap_test": None, "gap_ratio": float("nan"), "truth_gap": {}}
    if not case.effects:
        return rows
    split = result.split
    # The noise-free signals have no sensor noise to estimate (their second differences can be exactly 0); only
    # their bin means are read here, binned as the noisy session's, with its noise.
    quiet = discovery_data(noise_free_dataset(case, seed, strengths), tests=tests, noise=split.noise_sd)
    if quiet.fit_runs != split.fit_runs or quiet.held_out_runs != split.held_out_runs:
        raise RuntimeError("the noise-free session's runs do not match the noisy session's")
    truth = {
        part: np.concatenate([np.ravel(g.observed) for g in data.groups])
        for part, data in (("fit", quiet.fit), ("held_out", quiet.held_out))
    }
    if truth["fit"].size != result.before.predicted.size or truth["held_out"].size != result.held_before.predicted.size:
        raise RuntimeError("the noise-free session's bins do not match the noisy session's")
    sigma = rig_noise(case.force_sd_n, case.pressure_sd_pa)
    for effect in case.effects:
        test = LIBRARY[effect].scored_test
        held = split.held_out_covariates.test == test
        fitted = split.fit_covariates.test == test
        if not held.any():
            continue
        before = _rmse(result.held_before.predicted[held] - truth["held_out"][held])
        after = _rmse(result.held_after.predicted[held] - truth["held_out"][held])
        left = np.concatenate(
            [
                result.before.predicted[fitted] - truth["fit"][fitted],
                result.held_before.predicted[held] - truth["held_out"][held],
            ]
        )
        sd = sigma.force_sd_n if OBSERVED[test][0] == "force_n" else sigma.strain_sd
        rows["truth_gap"][effect] = {
            "test": test,
            "before": before,
            "after": after,
            "ratio": after / before if before > 0 else float("nan"),
            "effective_snr": _rmse(left) / sd,
        }
    first = rows["truth_gap"].get(case.effects[0])
    if first:
        rows.update(gap_test=first["test"], gap_ratio=first["ratio"])
    return rows


def run_key(case: Case, seed: int) -> str:
    """The stable name of one benchmark run (its work-unit key and its row's ``key``)."""
    return f"{case.label}|{case.snr:g}|{case.force_sd_n:g}|{int(case.drift)}|{seed}"  # mounts: in the label


def run_case(
    case: Case, seed: int, strengths: dict, tests: tuple[str, ...] | None = None, *, least_squares_start: bool = True
) -> dict:
    """One benchmark run as a work unit of :func:`peano_bayes.app.fanout.run_units`: the hidden-effect dataset of
    ``case`` at ``seed`` (``strengths`` by effect), discovery on its ``tests`` (default: all it has), and its
    JSON-ready scored row (:func:`score`, :func:`truth_gap`, the report's verdict, named effects, noise model,
    screening and diagnoses, and the seconds it took).

    A case with :attr:`Case.own_calibration` (drawn conditions, or a physics without the step test) calibrates
    its own strengths (:func:`case_strengths`; ``strengths`` is not read) and its row records them
    (``strengths``) and the calibration's seconds; a drawn-condition row records the draw (``conditions``); the
    label names the physics. A row of a case with the default conditions and physics has the fields it always
    had, and ``base_start``.

    ``least_squares_start``: discovery's base fit starts at the inference least squares of the base model under
    the material's bundled prior, as ``peano-bayes discover`` runs it for a user
    (:func:`~peano_bayes.discovery.choice.base_least_squares`); False: discovery's own multi-start (how runs
    before 2026-12-06 were made)."""
    from ..discovery import DEFAULT_BASE, discover, discovery_data
    from ..discovery.choice import base_least_squares
    from ..inference.prior_files import load_prior

    extra = {}
    if case.own_calibration:
        began = time.perf_counter()
        strengths = case_strengths(case, seed)
        extra.update(strengths=strengths, calibration_seconds=time.perf_counter() - began)
    drawn = case_conditions(case, seed)
    if drawn is not None:
        extra["conditions"] = drawn.as_dict()
    start = time.perf_counter()
    strengths = {e: strengths[e] for e in case.effects}
    dataset = hidden_dataset(case, seed, strengths)
    split = discovery_data(dataset, tests=tests)
    begin = None
    if least_squares_start:
        prior = load_prior(dataset.material.code)
        begin = base_least_squares(dataset, DEFAULT_BASE, prior, specimen=split.specimen, tests=tests, seed=seed).params
    result = discover(split, seed=seed, start=begin)
    row = score(case, result.report) | truth_gap(case, seed, result, strengths, tests)
    row.update(
        key=run_key(case, seed),
        effects=list(case.effects),
        snr=case.snr,
        force_sd_n=case.force_sd_n,
        drift=case.drift,
        seed=seed,
        verdict=result.report["verdict"],
        named=result.report["named"],
        described=result.report["described"],
        withheld=result.report["withheld"],
        drift_shown=result.report["drift_shown"],
        noise_model=result.report["noise_model"],
        screened=result.report["screened"],
        diagnoses=result.report["diagnoses"],
        base_start=result.report["base_start"],
        seconds=time.perf_counter() - start,
        **extra,
    )
    return row


def failed_row(case: Case, seed: int, error: str) -> dict:
    """The row of a run that raised: recorded, not hidden (it counts as wrong)."""
    return {
        "key": run_key(case, seed),
        "label": case.label,
        "snr": case.snr,
        "force_sd_n": case.force_sd_n,
        "drift": case.drift,
        "seed": seed,
        "outcome": f"error: {error}"[:200],
        "correct": False,
        "false_positive": False,
        "gap_ratio": float("nan"),
        "effects": list(case.effects),
        **({"conditions": draw_conditions(seed).as_dict()} if case.conditions == "drawn" else {}),
    }


__all__ = [
    "CONDITIONS",
    "Case",
    "not_hideable",
    "PHYSICS",
    "PHYSICS_TESTS",
    "PROTOCOL",
    "TRANSPLANTED",
    "TRUTH_CONFIG",
    "case_conditions",
    "case_strengths",
    "effect_contribution",
    "failed_row",
    "hidden_dataset",
    "hideable_on",
    "noise_free_dataset",
    "outcome_label",
    "reference_sigma",
    "rig_noise",
    "run_case",
    "run_key",
    "score",
    "snr_by_test",
    "strength_for_conditions",
    "strength_for_snr",
    "true_model",
    "truth_gap",
    "true_parameters",
]
