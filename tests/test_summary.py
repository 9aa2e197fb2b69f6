"""summary.json through one typed schema (peano_bayes/inference/summary.py), and the stage statuses."""

import json
import pickle

import pytest

from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.status import FitStatus, ModeStatus, SampleStatus
from peano_bayes.inference.summary import Summary, read_summary, write_summary

from .helpers import minimal_summary


def test_a_summary_round_trips_and_reads_as_a_mapping(tmp_path):
    written = Summary.from_json(minimal_summary(steps=250, timings_s={"sampling_s": 12.5}))
    write_summary(tmp_path / "summary.json", written)
    back = read_summary(tmp_path)  # the result folder or the file
    as_text = lambda summary: json.dumps(summary.to_json())  # noqa: E731  (NaN defaults compare as text)
    assert as_text(back) == as_text(written) == json.dumps(json.loads((tmp_path / "summary.json").read_text()))
    assert back.steps == back["steps"] == 250 and back.get("timings_s") == {"sampling_s": 12.5}
    assert back.converged and back["posterior_mode"] is None  # an optional field absent from the file
    assert json.dumps(dict(back)) == as_text(back) == as_text(pickle.loads(pickle.dumps(back)))
    with pytest.raises(KeyError):
        back["not_a_field"]


def test_a_file_that_is_not_a_summary_is_refused_naming_it_and_what_is_missing(tmp_path):
    bad = tmp_path / "summary.json"
    bad.write_text(json.dumps({"material": "TP", "steps": 3}))
    with pytest.raises(PeanoBayesInputError, match=r"summary.json: not a fit's summary: missing label, dataset"):
        read_summary(bad)
    bad.write_text(json.dumps(minimal_summary(steps="many")))
    with pytest.raises(PeanoBayesInputError, match="'steps' is str, expected int"):
        read_summary(bad)
    bad.write_text("[1]")
    with pytest.raises(PeanoBayesInputError, match="expected a JSON object"):
        read_summary(bad)
    with pytest.raises(PeanoBayesInputError, match="no such file"):
        read_summary(tmp_path / "elsewhere")
    newer = minimal_summary(a_field_from_a_newer_version=1)
    assert "a_field_from_a_newer_version" not in Summary.from_json(newer)
    with pytest.raises(TypeError):  # the writer cannot add a key the schema does not have
        Summary(**newer)


def test_stage_statuses_are_codes_with_messages():
    assert FitStatus.SUCCESSFUL.ok and not FitStatus.STEP_LIMIT.ok
    assert SampleStatus("step_limit") is SampleStatus.STEP_LIMIT and "step limit" in SampleStatus.STEP_LIMIT.message
    assert json.dumps({"s": ModeStatus.BELOW_START}) == '{"s": "below_start"}'
    assert [s.ok for s in ModeStatus] == [True, False, False, False, False]
