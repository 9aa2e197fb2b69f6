"""The effect registry (peano_bayes/effects.py): one definition per effect, from which the virtual rig's quirks,
the discovery superset and library, the model a fit adopts, the benchmark's hideable effects and the report
derive."""

import dataclasses

import pytest

from peano_bayes.discovery.choice import choice_from_report
from peano_bayes.discovery.report import report_markdown
from peano_bayes.discovery.workflow import Gates, refit_candidates
from peano_bayes.effects import (
    LIBRARY,
    Effect,
    adopt,
    check_effects,
    effects_in,
    hideable,
    physics_effects,
    register,
    registered,
    superset_config,
    switchable,
)
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.physics import DEFAULT_CONFIG, ModelConfig
from peano_bayes.rig import QUIRKS, apply_quirks, check_quirks
from peano_bayes.validation.discovery_benchmark import not_hideable

#: A toy effect: a second Maxwell branch across the tubes (an element the physics has, that no registered
#: effect switches on).
TOY = Effect(
    name="toy_second_maxwell",
    meaning="a toy second Maxwell branch across the tubes",
    kind="physics",
    params=("parallel_maxwell2_k_n_per_m", "parallel_maxwell2_tau_s"),
    off={"parallel_maxwell2_k_n_per_m": 0.0},
    start={"parallel_maxwell2_k_n_per_m": 50.0, "parallel_maxwell2_tau_s": 10.0},
    strength=("parallel_maxwell2_k_n_per_m",),
    signature="relaxation",
    shows_in=("load_cycle",),
    model={"parallel_maxwell": 2},
    hidden_at=lambda s: {"parallel_maxwell2_k_n_per_m": 100.0 * s, "parallel_maxwell2_tau_s": 10.0},
)


def test_a_toy_effect_registered_in_one_place_reaches_the_rig_superset_discovery_benchmark_and_report():
    name = TOY.name
    assert name not in LIBRARY and name not in QUIRKS
    with registered(TOY):
        # the virtual rig: a quirk, switched on through the registry's model fields
        assert name in QUIRKS and check_quirks([name]) == (name,)
        assert apply_quirks(DEFAULT_CONFIG, [name]).parallel_maxwell == 2
        # the discovery superset holds its element and parameters
        assert superset_config().parallel_maxwell == 2
        assert "parallel_maxwell2_k_n_per_m" in superset_config().parameter_names()
        # discovery's library: a known effect, refitted when its signature is significant
        assert check_effects([name]) == (name,)
        ranked, by_signature = refit_candidates([name, "sensor_offset"], {}, {"relaxation": 1e-6}, Gates())
        assert name in ranked and by_signature["relaxation"] == [name]
        # the model a fit samples when discovery names it
        assert name in effects_in(adopt(DEFAULT_CONFIG, [name]))
        # a physics effect to discovery's naming rule and the model choice; the validation benchmark can hide it
        assert name in physics_effects() and name in hideable() and name not in not_hideable()
        assert choice_from_report(DEFAULT_CONFIG, {"named": [name]}, None).adopted == (name,)
        # the report reads its kind from the registry
        text = report_markdown(_report_screening(name))
        assert f"`{name}` (physics)" in text
    assert name not in LIBRARY and name not in QUIRKS and superset_config().parallel_maxwell == 1
    assert name not in physics_effects() and name not in hideable()
    with pytest.raises(PeanoBayesInputError, match="unknown effect"):
        check_effects([name])


def test_the_superset_is_every_registered_element_on():
    """Derived from the registry, it equals the superset written out by hand."""
    by_hand = ModelConfig(
        bending=True, tensile=True, extension=True, mount=True, parallel_maxwell=1, series_kelvin=1,
        friction="parallel", threshold=True, flow="orifice", damping=True,
    )  # fmt: skip
    assert superset_config() == by_hand


def test_quirks_are_the_switchable_physics_effects_and_the_rest_say_why_not():
    assert set(QUIRKS) == set(switchable()) == {
        "hysteresis",
        "viscoelastic_relaxation",
        "series_viscoelastic",
        "series_compliance",
        "strain_stiffening",
        "threshold_pressure",
        "nonlinear_damping",
    }
    with pytest.raises(PeanoBayesInputError, match="set bending_k1_n"):
        check_quirks(["bending_stiffness"])
    with pytest.raises(PeanoBayesInputError, match="no such element"):
        check_quirks(["cyclic_softening"])
    with pytest.raises(PeanoBayesInputError, match="noise effect has no element"):
        check_quirks(["sensor_gain"])


def test_register_refuses_a_taken_name_an_unknown_parameter_and_a_stray_off_value():
    with pytest.raises(PeanoBayesInputError, match="already registered"):
        register(LIBRARY["hysteresis"])
    with pytest.raises(PeanoBayesInputError, match="unknown parameter"):
        register(dataclasses.replace(TOY, params=("no_such_parameter",), off={}, strength=()))
    with pytest.raises(PeanoBayesInputError, match="not among its params"):
        register(dataclasses.replace(TOY, off={"friction_force_n": 0.0}))
    assert TOY.name not in LIBRARY


def _report_screening(name: str) -> dict:
    """The smallest discovery report whose one round screened ``name`` (and it failed a gate)."""
    return {
        "specimen": "A",
        "verdict": "none",
        "named": [],
        "ambiguous": [],
        "described": [],
        "noise_model": [],
        "base": ["tensile_stiffness"],
        "final_model": ["tensile_stiffness"],
        "steps": [],
        "gap": {"before": {}, "after": {}},
        "screened": [{name: {"gates": {"elpd": False}, "passed": False, "delta_elpd": 0.5}}],
        "gates": {},
    }
