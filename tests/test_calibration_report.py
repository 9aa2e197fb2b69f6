"""The calibration report's reading of the forced refits (``experiments/calibration_tradeoffs.py``)."""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))
import calibration_report  # noqa: E402

LABEL = "ordering speed: PCS > TPC"


def _probe(after_label, after_other, before_other=(True, 0.05)):
    return {
        "before": {LABEL: [False, -0.03], "PCS speed": list(before_other)},
        "after": {LABEL: list(after_label), "PCS speed": list(after_other)},
        "cost_before": 2.0,
        "cost_after_without_forcing": 2.5,
    }


def _write(tmp_path, monkeypatch, probes):
    path = tmp_path / "tradeoffs.json"
    path.write_text(json.dumps({"probes": {LABEL: probes}}))
    monkeypatch.setattr(calibration_report, "TRADEOFFS", path)


def test_a_forced_refit_that_costs_another_check_is_a_measured_compromise(tmp_path, monkeypatch):
    _write(tmp_path, monkeypatch, {"PCS": _probe((True, 0.02), (False, 0.15))})
    text = calibration_report.measured_tradeoff(LABEL, "compromise: claimed")
    assert text.startswith("compromise, measured")
    assert "PCS speed now fails (+0.050 -> +0.150)" in text and "claimed" not in text


def test_a_forced_refit_that_costs_nothing_calls_the_miss_avoidable(tmp_path, monkeypatch):
    # One refit costs another check, the other refit costs nothing: the miss is avoidable.
    _write(
        tmp_path, monkeypatch, {"PCS": _probe((True, 0.02), (False, 0.15)), "TPC": _probe((True, 0.04), (True, 0.052))}
    )
    text = calibration_report.measured_tradeoff(LABEL, "compromise: claimed")
    assert text.startswith("avoidable, not a compromise")
    assert "no other check of TPC fails or worsens" in text


def test_a_forced_refit_that_does_not_hold_is_never_avoidable(tmp_path, monkeypatch):
    _write(tmp_path, monkeypatch, {"PCS": _probe((False, -0.01), (True, 0.05))})
    assert calibration_report.measured_tradeoff(LABEL, "compromise: x").startswith("compromise, measured")


def test_reasons_other_than_compromise_pass_through_and_a_missing_probe_is_said(tmp_path, monkeypatch):
    _write(tmp_path, monkeypatch, {})
    assert calibration_report.measured_tradeoff(LABEL, "definition: y") == "definition: y"
    assert "not measured" in calibration_report.measured_tradeoff(LABEL, "compromise: x")
    monkeypatch.setattr(calibration_report, "TRADEOFFS", tmp_path / "absent.json")
    assert "run experiments/calibration_tradeoffs.py" in calibration_report.measured_tradeoff(LABEL, "compromise: x")
