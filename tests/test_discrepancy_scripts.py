"""The discovery benchmark's check scripts, without their refits (about 100 s a row): which rows
experiments/discrepancy_truth_bound.py checks (its output reports the recomputed base's gap beside the run's, so
each row carries its own consistency check), how experiments/discrepancy_rerun.py compares a re-run row with the
record, and their bad-input messages."""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from peano_bayes.validation.discovery_benchmark import run_key

sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))
import discrepancy_benchmark as bench  # noqa: E402
import discrepancy_gate_failures as gf  # noqa: E402
import discrepancy_rerun as rerun  # noqa: E402
import discrepancy_truth_bound as tb  # noqa: E402


def _row(label, seed, ratio, *, correct=True, effects=None, outcome=None, scored=True):
    effects = effects if effects is not None else [label.split("@")[0]]
    return {"key": f"{label}|2|0.2|0|{seed}", "label": label, "effects": effects, "correct": correct,
            "outcome": outcome or "+".join(sorted(effects)), "gap_ratio": ratio, "seed": seed, "snr": 2.0,
            "force_sd_n": 0.2, "truth_gap": {effects[0]: {"ratio": ratio}} if scored and effects else None}  # fmt: skip


def test_rows_checked_are_exact_single_effect_detections_misses_first(tmp_path):
    rows = [
        _row("hysteresis", 1, 0.3),
        _row("hysteresis", 2, 0.9),
        _row("hysteresis", 3, 0.6),
        _row("hysteresis", 4, 0.7, correct=False),  # a miss of the effect: no detection to score
        _row("hysteresis", 5, float("nan")),  # no gap scored
        _row("hysteresis", 9, 0.95, outcome="ambiguous{hysteresis,viscoelastic_relaxation}"),  # may hold the rival
        _row("hysteresis", 10, 0.99, scored=False),  # a run scored before the truth-scored gap
        _row("series_compliance@2mounts", 6, 0.8),  # two mounts: rebuilt like the others
        _row("hysteresis+flow_restriction", 7, 0.8, effects=["hysteresis", "flow_restriction"]),
        _row("strain_stiffening", 8, 0.4),
    ]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    chosen = tb.candidate_rows(tmp_path, None, per_effect=2)
    assert [(r["label"], r["seed"]) for r in chosen] == [
        ("hysteresis", 2),
        ("hysteresis", 3),
        ("series_compliance@2mounts", 6),
        ("strain_stiffening", 8),
    ]
    only = tb.candidate_rows(tmp_path, ["strain_stiffening"], per_effect=5)
    assert [r["seed"] for r in only] == [8]


def test_every_recorded_case_kind_is_found_again_from_its_row():
    """Both scripts rebuild a row's case from its key: every case of the benchmark at SNR 2 and 4, each noise
    level, drift, two effects, the other-physics null and the two-mount cases, comes back as itself."""
    for snr in (2.0, 4.0):
        for case in bench.cases([snr], [0.1, 0.2, 0.4]):
            key = run_key(case, 14001)
            row = {"key": key, "seed": 14001, "snr": case.snr, "force_sd_n": case.force_sd_n}
            assert bench.case_of_row(row) == case, key
    with pytest.raises(KeyError, match="no case of today's benchmark has the key 'retired_effect"):
        bench.case_of_row({"key": "retired_effect|2|0.2|0|1", "seed": 1, "snr": 2.0, "force_sd_n": 0.2})


def test_a_folder_that_is_not_a_run_is_refused_with_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        tb.main(["--run", str(tmp_path)])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "is not a benchmark run's folder" in err and "strengths.json" in err
    assert not (tmp_path / "checks").exists()


def test_a_rerun_row_is_compared_exactly_in_names_and_relatively_in_numbers():
    recorded = {"outcome": "hysteresis", "named": ["hysteresis"], "seconds": 10.0, "n": 3, "x": 1.0,
                "screened": [{"a": {"delta_elpd": 2.0, "passed": True}}], "gap": float("nan")}  # fmt: skip
    same = {**recorded, "seconds": 99.0}
    assert rerun.differences(recorded, same) == ([], [])
    moved = {**recorded, "x": 1.01, "n": 3.0, "screened": [{"a": {"delta_elpd": 2.0, "passed": False}}]}
    exact, numeric = rerun.differences(recorded, moved)
    assert exact == ["/screened[0]/a/passed"]
    assert [p for p, *_ in numeric] == ["/x"] and numeric[0][1:] == (pytest.approx(0.01 / 1.01), 1.0, 1.01)
    assert rerun.differences(recorded, {**recorded, "named": []})[0] == ["/named (length 1 vs 0)"]
    assert rerun.differences(recorded, {k: v for k, v in recorded.items() if k != "n"})[0] == ["/n (missing)"]
    # a number that turns NaN (or from NaN into a number) is a change of kind, never round-off
    assert rerun.differences(recorded, {**recorded, "gap": 0.4}) == (["/gap (nan vs 0.4)"], [])
    assert rerun.differences(recorded, {**recorded, "x": float("inf")}) == (["/x (1.0 vs inf)"], [])


def test_a_rerun_of_an_unknown_key_is_refused_with_exit_2(tmp_path, capsys):
    (tmp_path / "strengths.json").write_text("{}")
    (tmp_path / "runs.jsonl").write_text(json.dumps(_row("hysteresis", 1, 0.3)) + "\n")
    with pytest.raises(SystemExit) as stop:
        rerun.main(["--run", str(tmp_path), "--keys", "hysteresis|2|0.2|0|2"])
    assert stop.value.code == 2
    assert "no row with key 'hysteresis|2|0.2|0|2'" in capsys.readouterr().err


def _candidate(signature, failed=(), **evidence):
    gates = {g: g not in failed for g in ("predictive_gain", "parsimony", "own_signature", "identified")}
    return {"signature": signature, "gates": gates, "delta_elpd": 50.0, "elpd_se": 20.0, "delta_bic": -100.0,
            "signature_before": 4.0, "signature_ratio": 0.9, **evidence}  # fmt: skip


def _diagnosis(**p):
    return {"signatures": {name: {"p": v, "p_holm": min(1.0, 5 * v)} for name, v in p.items()}}


def test_gate_failures_count_single_gates_by_truth_and_list_a_hidden_effects_misses(tmp_path):
    """Hand-built rows: the counts, the visibility rule's release at each level and the misses are what the
    rows say, and the table keeps a row key's separators out of its cells."""
    rows = [
        {  # relaxation hidden, missed: refitted twice, stopped by its own signature (p 0.04, then 0.3)
            "key": "viscoelastic_relaxation|2|0.2|0|1", "effects": ["viscoelastic_relaxation"], "named": [],
            "verdict": "none",
            "screened": [
                {"viscoelastic_relaxation": _candidate("relaxation", ["own_signature"]),
                 "sensor_gain": _candidate("force_level", ["parsimony"])},
                {"viscoelastic_relaxation": _candidate("relaxation", ["own_signature"])},
            ],
            "diagnoses": [_diagnosis(relaxation=0.04, force_level=0.5), _diagnosis(relaxation=0.3)],
        },
        {  # relaxation hidden and named: not a miss
            "key": "viscoelastic_relaxation|2|0.2|0|2", "effects": ["viscoelastic_relaxation"],
            "named": ["viscoelastic_relaxation"], "verdict": "named",
            "screened": [{"viscoelastic_relaxation": _candidate("relaxation")}],
            "diagnoses": [_diagnosis(relaxation=0.001)],
        },
        {  # nothing hidden: a false candidate stopped by its own signature (p 0.002), one failing two gates
            "key": "none|0|0.2|0|3", "effects": [], "named": [], "verdict": "none",
            "screened": [{"series_viscoelastic": _candidate("relaxation_at_load", ["own_signature"]),
                          "hysteresis": _candidate("loading_split", ["own_signature", "parsimony"])}],
            "diagnoses": [_diagnosis(relaxation_at_load=0.002, loading_split=0.9)],
        },
    ]  # fmt: skip
    counts = gf.single_gate_failures(rows)
    assert counts == {("own_signature", True): 2, ("parsimony", False): 1, ("own_signature", False): 1}
    release = gf.visibility_release(rows, [0.01, 0.05])
    assert release[0.01] == {"true_released": 2, "true_total": 2, "false_released": 0, "false_total": 1}
    assert release[0.05] == {"true_released": 1, "true_total": 2, "false_released": 0, "false_total": 1}
    missed = gf.misses(rows, "viscoelastic_relaxation")
    assert [m["key"] for m in missed] == ["viscoelastic_relaxation|2|0.2|0|1"]
    assert [(r["round"], r["signature_p"], r["failed"]) for r in missed[0]["rounds"]] == [
        (0, 0.04, ["own_signature"]),
        (1, 0.3, ["own_signature"]),
    ]
    table = gf.markdown(counts, release, missed, "viscoelastic_relaxation", tmp_path)
    line = next(x for x in table.splitlines() if x.startswith("| viscoelastic_relaxation"))
    assert line.replace("\\|", "").count("|") == 10  # nine cells: the key's own bars are escaped


def test_gate_failures_refuses_a_folder_without_rows_or_without_the_effect(tmp_path, capsys):
    with pytest.raises(SystemExit) as err:
        gf.main([str(tmp_path)])
    assert err.value.code == 2 and "not a benchmark run's folder" in capsys.readouterr().err
    (tmp_path / "runs.jsonl").write_text(json.dumps({"key": "none|0|0.2|0|1", "effects": [], "screened": []}) + "\n")
    with pytest.raises(SystemExit) as err:
        gf.main([str(tmp_path), "--effect", "hysteresis"])
    assert err.value.code == 2 and "no row" in capsys.readouterr().err


def test_signature_power_sets_the_hidden_case_beside_the_others_and_detection_against_visibility(tmp_path):
    """Hand-built first diagnoses: per case the statistic's median, RMS, visible and significant counts are the
    rows', and the detections of the hidden effect are split by whether its signature was visible."""

    def row(label, seed, t, p, correct, effects):
        sig = {"relaxation": {"T": t, "p": p, "p_holm": 1.0}}
        return {"key": f"{label}|2|0.2|0|{seed}", "effects": effects, "correct": correct, "named": [],
                "verdict": "none", "screened": [], "diagnoses": [{"signatures": sig}, {"signatures": {}}]}  # fmt: skip

    relax = ["viscoelastic_relaxation"]
    rows = [
        row("viscoelastic_relaxation", 1, 1.0, 0.6, True, relax),
        row("viscoelastic_relaxation", 2, 4.0, 0.01, False, relax),
        row("viscoelastic_relaxation", 3, 2.0, 0.3, True, relax),
        row("none", 4, 5.0, 0.04, False, []),
        row("none", 5, 0.5, 0.9, True, []),
    ]
    power = gf.signature_power(rows, "relaxation", 3.0)
    assert power["viscoelastic_relaxation|2|0.2|0"] == {
        "n": 3, "median_T": 2.0, "rms_T": pytest.approx((21.0 / 3.0) ** 0.5, rel=1e-12), "visible": 1,
        "p_below_0.05": 1,
    }  # fmt: skip
    assert power["none|2|0.2|0"]["median_T"] == pytest.approx(2.75, rel=1e-12)
    assert power["none|2|0.2|0"]["visible"] == 1 and power["none|2|0.2|0"]["p_below_0.05"] == 1
    detection = gf.detection_by_visibility(rows, "viscoelastic_relaxation", "relaxation", 3.0)
    assert detection == {(False, True): 2, (True, False): 1}
    table = gf.markdown(Counter(), {}, [], "viscoelastic_relaxation", tmp_path, ("relaxation", 3.0, power, detection))
    assert "| visible | 0 | 1 |" in table and "| not visible | 2 | 0 |" in table
    assert "| viscoelastic_relaxation\\|2\\|0.2\\|0 | 3 | 2.00 | 2.65 | 1 | 1 |" in table


def test_signature_power_statistic_table_and_refusals(tmp_path, capsys):
    """The matched signatures' statistic is discovery's T with its block sign-flip p (at its floor for a signal
    along w, NaN for an empty weight); the table and summary are the rows'; bad arguments exit 2."""
    import signature_power as sp

    from peano_bayes.discovery.diagnose import N_FLIPS, sign_flips

    rng = np.random.default_rng(5)
    blocks, flips = sign_flips(np.repeat(np.arange(30), 10), seed=1)
    w, noise = rng.normal(size=300), rng.normal(size=300)
    t, p = sp.signature_test(w, noise, blocks, flips)
    assert t == pytest.approx(abs(w @ noise) / np.linalg.norm(w), rel=1e-12) and 0.0 < p <= 1.0
    t, p = sp.signature_test(w, noise + 8.0 * w / np.linalg.norm(w), blocks, flips)
    assert t > 7.0 and p == pytest.approx(1.0 / (N_FLIPS + 1), rel=1e-12)
    assert all(np.isnan(sp.signature_test(np.zeros(300), noise, blocks, flips)))

    table = pd.DataFrame(
        [{"key": f"{c}|{s}", "case": c, "seed": s, "signature": "matched:x", "T": t, "p": p, "share_load_cycle": 0.1,
          "share_blocking": 0.0, "share_stroke": 0.3, "share_step": 0.6}
         for c, s, t, p in [("x", 1, 6.0, 0.001), ("x", 2, 4.0, 0.2), ("none", 1, 1.0, 0.5), ("none", 2, 2.0, 0.01)]]
    )  # fmt: skip
    assert sp.summary(table)["matched:x"] == {
        "none": {"rows": 2, "median_T": 1.5, "p_below": 0.5},
        "x": {"rows": 2, "median_T": 5.0, "p_below": 0.5},
    }
    assert "| matched:x | 1.5 / 0.50 | 5.0 / 0.50 |" in sp.markdown(table)
    assert "| matched:x | 0.10 | 0.00 | 0.30 | 0.60 |" in sp.markdown(table)

    with pytest.raises(SystemExit) as stop:
        sp.main(["--run", str(tmp_path), "--out", str(tmp_path / "o")])
    assert stop.value.code == 2 and "strengths.json" in capsys.readouterr().err
    (tmp_path / "strengths.json").write_text("{}")
    with pytest.raises(SystemExit) as stop:
        sp.main(["--run", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "no_such_case"])
    assert stop.value.code == 2 and "unknown no_such_case" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        sp.main(["--run", str(tmp_path), "--out", str(tmp_path / "o"), "--cases", "hysteresis"])
    assert stop.value.code == 2 and "no hysteresis@2" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
