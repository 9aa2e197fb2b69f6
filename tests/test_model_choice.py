"""The model a fit samples when discovery chooses it: the effect registry's model fields, adoption, the record
in summary.json and index.md, and the resumed fit that reads the discovery report back."""

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from peano_bayes.discovery.choice import choice_from_report, configured_model
from peano_bayes.effects import LIBRARY, adopt, effects_in, physics_effects
from peano_bayes.inference.fit import FitResult
from peano_bayes.physics.model import PARAMETERS, ModelConfig

#: A model with no element a library effect can switch on (the flow law is always present).
BARE = ModelConfig(bending=False, tensile=False, extension=False, friction="none")
WITH_ELEMENT = [n for n in physics_effects() if LIBRARY[n].model]


def test_only_effects_without_an_inference_element_have_no_model_fields():
    assert set(physics_effects()) - set(WITH_ELEMENT) == {"cyclic_softening"}
    for name, effect in LIBRARY.items():
        if effect.kind != "physics":
            assert not effect.model, name


@pytest.mark.parametrize("name", WITH_ELEMENT)
def test_adopting_an_effect_puts_its_physics_parameters_into_the_model(name):
    """The registry's model fields switch on the element that reads the effect's own parameters (a field
    mapped to the wrong element fails here)."""
    config = adopt(BARE, [name])
    assert name in effects_in(config)
    physics_params = {p for p in LIBRARY[name].params if p in PARAMETERS}
    assert physics_params and physics_params <= set(config.parameter_names()), name
    if name != "flow_restriction":  # the orifice is in every model
        assert not physics_params <= set(BARE.parameter_names()), name


configs = st.builds(
    ModelConfig,
    bending=st.booleans(),
    tensile=st.booleans(),
    extension=st.booleans(),
    mount=st.booleans(),
    parallel_maxwell=st.integers(0, 3),
    series_kelvin=st.integers(0, 3),
    friction=st.sampled_from(["none", "parallel", "whole"]),
    threshold=st.booleans(),
    flow=st.sampled_from(["orifice", "laminar"]),
    damping=st.booleans(),
)


@given(configs, st.lists(st.sampled_from(list(LIBRARY)), max_size=5))
def test_adoption_only_adds_and_contains_every_named_element(config, named):
    chosen = adopt(config, named)
    assert set(effects_in(config)) <= set(effects_in(chosen))
    assert {n for n in named if LIBRARY[n].model} <= set(effects_in(chosen))
    assert set(config.parameter_names()) <= set(chosen.parameter_names())
    # nothing named that the model already has: the same model (friction kind and branch counts kept)
    if set(named) <= set(effects_in(config)):
        assert chosen == config


def test_a_report_becomes_a_choice_with_its_record():
    # the shape of a real report (discovery/workflow.py): physics effects under "named", noise-side ones apart
    report = {
        "verdict": "named",
        "named": ["hysteresis", "cyclic_softening"],
        "noise_model": ["sensor_offset"],
        "described": [],
        "structure_left": False,
    }
    choice = choice_from_report(BARE, report, "out/TP/discovery")
    assert choice.config.friction == "parallel" and choice.adopted == ("hysteresis",)
    assert choice.named == ("hysteresis", "cyclic_softening") and choice.not_in_model == ("cyclic_softening",)
    assert not choice.unexplained
    record = json.loads(json.dumps(choice.as_dict()))
    assert record["discovery"]["report"] == "out/TP/discovery" and record["discovery"]["verdict"] == "named"
    assert record["config"]["friction"] == "parallel" and record["config"]["bending"] is False
    assert record["effects"] == ["hysteresis", "flow_restriction"] and record["configured"] == ["flow_restriction"]
    assert configured_model(BARE).as_dict()["discovery"] is None
    # structure left after the last named effect, or a flexible term the data needed, is unexplained structure
    assert choice_from_report(BARE, {**report, "structure_left": True}, None).unexplained
    described = {"verdict": "unexplained", "named": [], "described": ["session_baseline"], "structure_left": False}
    assert choice_from_report(BARE, described, None).unexplained


def test_naming_the_inlet_restriction_keeps_a_laminar_inlet():
    laminar = ModelConfig(flow="laminar")
    assert "flow_restriction" in effects_in(laminar)
    assert adopt(laminar, ["flow_restriction"]).flow == "laminar"
    assert "laminar_conductance_m3_per_s_pa" in adopt(laminar, ["flow_restriction"]).parameter_names()


def test_index_shows_the_sampled_model_beside_what_discovery_named():
    from peano_bayes.report.index import model_table

    report = {"verdict": "named", "named": ["series_compliance"], "described": [], "structure_left": True}
    found = choice_from_report(BARE, report, "discovery")  # as a fit records it: relative to its result folder
    text = "\n".join(
        model_table(
            [
                {"material": "PC", "label": "PC_run2", "model": found.as_dict()},
                {"material": "TP", "model": configured_model(BARE).as_dict()},
            ]
        )
    )
    assert "| PC | series_compliance, flow_restriction | named | series_compliance | series_compliance |" in text
    assert "| TP | flow_restriction | not run (the configured model) |" in text
    assert "**PC**: discovery left structure it could not name" in text and "(`PC_run2/discovery/report.md`)" in text


def test_a_resumed_fit_reads_the_discovery_report_instead_of_running_discovery(tmp_path, monkeypatch):
    from peano_bayes import bundled
    from peano_bayes.app.pipeline import _discovery_seconds, _model_choice
    from peano_bayes.data import load
    from peano_bayes.discovery import choice as choice_module

    def never(*args, **kwargs):
        raise AssertionError("discovery ran again")

    monkeypatch.setattr(choice_module, "choose_model", never)
    folder = tmp_path / "TP" / "discovery"
    folder.mkdir(parents=True)
    (folder / "report.json").write_text(json.dumps({"verdict": "named", "named": ["nonlinear_damping"]}))
    lines = []
    choice = _model_choice(
        load(bundled.dataset_path("TP")), BARE, tmp_path / "TP", discover=True, resume=True, log=lines.append
    )
    assert choice.config.damping and choice.adopted == ("nonlinear_damping",) and choice.report == str(folder)
    assert any("discovery report read from" in line for line in lines)
    assert _discovery_seconds(choice) is None  # this report does not say how long discovery took
    (folder / "report.json").write_text(json.dumps({"verdict": "none", "named": [], "seconds": 107.5}))
    assert _discovery_seconds(choice) == 107.5 and _discovery_seconds(configured_model(BARE)) is None
    assert _model_choice(None, BARE, tmp_path, discover=False, resume=False, log=print).verdict is None


def test_a_resumed_fit_keeps_the_model_of_its_saved_state(tmp_path):
    """Resuming a fit sampled without discovery does not run discovery (its saved state belongs to the configured
    model), and resuming one sampled with discovery keeps the report's model without the flag."""
    from peano_bayes import bundled
    from peano_bayes.app.pipeline import _model_choice
    from peano_bayes.data import load

    dataset = load(bundled.dataset_path("TP"))
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "fit.json").write_text("{}")
    lines = []
    choice = _model_choice(dataset, BARE, plain, discover=True, resume=True, log=lines.append)
    assert choice.verdict is None and choice.config == BARE
    assert any("resuming a fit sampled without discovery" in line for line in lines)

    found = tmp_path / "found"
    (found / "discovery").mkdir(parents=True)
    (found / "discovery" / "report.json").write_text(json.dumps({"verdict": "named", "named": ["hysteresis"]}))
    choice = _model_choice(dataset, BARE, found, discover=False, resume=True, log=lambda m: None)
    assert choice.config.friction == "parallel" and choice.verdict == "named"


@pytest.mark.parametrize("adopts", [False, True])
def test_discovery_starts_from_the_fits_least_squares_which_also_serves_the_sampler(tmp_path, monkeypatch, adopts):
    """``fit --discover``: the configured model's least squares runs once, discovery's base fit starts at its
    optimum, and the same least squares seeds the sampler (``fit.json``) unless discovery adds an effect, when the
    larger model gets its own least squares."""
    from peano_bayes import bundled
    from peano_bayes.app import pipeline
    from peano_bayes.discovery import choice as choice_module

    class Stop(Exception):
        pass

    fits, starts = [], []

    def least_squares(posterior, prior, **kw):
        fits.append(posterior.config)
        return FitResult(
            names=("bending_k1_n",), u=np.zeros(1), params={"bending_k1_n": 40.0 + len(fits)}, covariance=np.eye(1),
            cost=1.0, n_starts=4, n_failed=0, n_step_limit=0, start_costs=np.ones(4), noise={}, noise_estimate={},
            seconds=1.0,
        )  # fmt: skip

    def choose_model(dataset, config, out_dir, *, start, **kw):
        starts.append(start)
        extra = next(e for e in physics_effects() if LIBRARY[e].model and e not in effects_in(config))
        report = {"verdict": "named" if adopts else "none", "named": [extra] if adopts else []}
        return choice_from_report(config, report, out_dir)

    def stop(*args, **kw):
        raise Stop

    monkeypatch.setattr(pipeline, "least_squares", least_squares)
    monkeypatch.setattr(choice_module, "choose_model", choose_model)
    monkeypatch.setattr(pipeline, "walker_start", stop)
    with pytest.raises(Stop):
        pipeline.infer(bundled.dataset_path("TP"), tmp_path, discover=True, figures=False, log=lambda m: None)
    assert starts == [{"bending_k1_n": 41.0}]  # discovery started at the first least squares' optimum
    assert len(fits) == (2 if adopts else 1)
    if adopts:
        assert effects_in(fits[1]) != effects_in(fits[0])  # the second fit is of the larger model
    saved = json.loads((tmp_path / "TP" / "fit.json").read_text())
    assert saved["params"] == {"bending_k1_n": 40.0 + len(fits)}  # the sampler starts from the sampled model's fit
