"""summary.json through one typed schema (peano_bayes/inference/summary.py), fit.json as the least squares'
typed record (FitResult), and the stage statuses."""

import json
import pickle

import numpy as np
import pytest

from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.fit import FitResult
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


def test_fit_json_is_the_least_squares_record_and_reads_back_to_an_equal_result(tmp_path):
    """Every field survives the file (arrays as lists, a failed start's infinite cost included); the status is
    the code of how the best start ended; a record without a field it needs names the file and the field."""
    result = FitResult(
        names=("a", "b"), u=np.array([0.1, -2.0 / 3.0]), params={"a": 1.5, "b": 0.25, "held": 3.0},
        covariance=np.array([[0.04, 0.01], [0.01, 0.09]]), cost=12.25, n_starts=4, n_failed=1, n_step_limit=1,
        start_costs=np.array([12.25, np.inf, 13.0, 12.5]), noise={"noise_step_strain": 5e-4},
        noise_estimate={"noise_step_strain": 4e-4}, quality={"step": {"rmse": 0.01}}, seconds=3.5, converged=False,
        rounds=3, optima=({"a": 1.6, "b": 0.2},),
    )  # fmt: skip
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(result.to_json()))
    record = json.loads(path.read_text())
    assert record["status"] == FitStatus.STEP_LIMIT.value == "step_limit"
    back = FitResult.from_json(record)
    for name in ("names", "params", "cost", "n_starts", "n_failed", "n_step_limit", "noise", "noise_estimate",
                 "quality", "seconds", "converged", "rounds", "optima"):  # fmt: skip
        assert getattr(back, name) == getattr(result, name), name
    for name in ("u", "covariance", "start_costs"):
        assert np.array_equal(getattr(back, name), getattr(result, name)), name
    assert back.status is FitStatus.STEP_LIMIT
    assert back.outcome() == "best start NOT converged after 3 rounds; of 4 starts 1 failed and 1 stopped unfinished"
    del record["u"], record["noise"]
    with pytest.raises(PeanoBayesInputError, match=r"old/fit.json: no u, noise: written by an earlier version"):
        FitResult.from_json(record, where="old/fit.json")
