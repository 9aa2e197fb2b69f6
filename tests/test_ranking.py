"""Ranking with uncertainty on draws whose answer is known by construction."""

import json

import numpy as np
import pytest

from peano_bayes.analysis.ranking import CRITERIA, ordering_checks, pareto_probability, rank_criterion, rank_materials
from peano_bayes.app.cli import main


def _draws(rng, means, sd=0.1, n=4000):
    """code -> metric -> (n,) normal draws with the given mean for every criterion."""
    return {code: {c: rng.normal(mu, sd, n) for c in CRITERIA} for code, mu in means.items()}


def test_each_criterion_points_the_way_the_paper_reads_it(rng):
    """Written out from the paper's Table 3 discussion, not from ``CRITERIA``: a lower hysteresis loss is better,
    a higher value of every other criterion is. A material 20 % higher on every metric is clearly best on all of
    them but hysteresis, where the other one is."""
    higher_is_better = {
        "blocking_force_per_pressure": True,
        "free_strain": True,
        "stroke": True,
        "energy_per_pressure": True,
        "hysteresis_loss": False,
        "speed": True,
        "power_per_pressure": True,
        "efficiency": True,
    }
    assert set(higher_is_better) == set(CRITERIA)
    draws = _draws(rng, {"low": 1.0, "high": 1.2}, sd=0.01)
    for criterion, up in higher_is_better.items():
        r = rank_criterion(draws, criterion)
        expected = "high" if up else "low"
        assert r.p_clearly_best[r.materials.index(expected)] > 0.99, criterion


def test_probabilities_match_the_normal_theory(rng):
    # A ~ N(1, 0.1), B ~ N(1.1, 0.1): P(B > A) = Phi(0.1 / (0.1 sqrt 2)) = 0.760.
    draws = _draws(rng, {"A": 1.0, "B": 1.1})
    r = rank_criterion(draws, "speed")
    assert r.p_better[1, 0] == pytest.approx(0.760, abs=0.02)
    assert r.p_better[0, 1] == pytest.approx(1 - 0.760, abs=0.02)
    assert r.mean_rank[1] == pytest.approx(1.24, abs=0.02)
    # best = no other better by more than 5 %: A is, unless B - 1.05 A > 0, B ~ N(-0.05 + 0.1, 0.1 sqrt(2.1025))
    # so P(A best) = 1 - Phi(0.05 / 0.145) = 0.365; B is best unless A - 1.05 B > 0: Phi(-0.155 / 0.145) = 0.142.
    assert r.p_best[0] == pytest.approx(0.365, abs=0.02) and r.p_best[1] == pytest.approx(1 - 0.142, abs=0.02)


def test_margin_probabilities_match_the_normal_theory(rng):
    """A ~ N(1, 0.02), B ~ N(1.02, 0.02): B is larger most of the time, yet almost never by more than the
    5 % margin, so neither is *clearly* best and both are *best* (within the margin). Closed forms:
    P(B - A > 0.05 |A|) with B - 1.05 A ~ N(-0.03, 0.02 sqrt(1 + 1.05^2)) = Phi(-1.036) = 0.150."""
    draws = _draws(rng, {"A": 1.0, "B": 1.02}, sd=0.02, n=20_000)
    r = rank_criterion(draws, "speed")
    assert r.p_better[1, 0] == pytest.approx(0.760, abs=0.02)
    assert r.p_better_by_margin[1, 0] == pytest.approx(0.150, abs=0.01)
    assert r.p_clearly_best[1] == pytest.approx(0.150, abs=0.01)
    assert r.p_best[0] == pytest.approx(1 - 0.150, abs=0.01) and r.p_best[1] > 0.99
    assert r.verdict() == {"verdict": "best", "materials": ["B"]}  # A's 0.85 is short of 0.9
    wide = _draws(rng, {"A": 1.0, "B": 1.5}, sd=0.02)
    r = rank_criterion(wide, "speed")
    assert r.p_clearly_best[1] == 1.0 and r.p_best[0] == 0.0
    assert r.verdict() == {"verdict": "clearly best", "materials": ["B"]}
    # lower is better: hysteresis 1.0 beats 1.5 by far more than 5 %
    assert rank_criterion(wide, "hysteresis_loss").p_clearly_best[0] == 1.0


def test_criteria_the_data_did_not_inform_are_not_ranked(rng):
    draws = _draws(rng, {"TP": 1.0, "P": 2.0})
    report = rank_materials(draws, from_prior={"speed", "efficiency", "power_per_pressure"})
    assert not {"speed", "efficiency", "power_per_pressure"} & set(report["criteria"])
    assert set(report["left_out"]) == {"speed", "efficiency", "power_per_pressure"}
    assert "speed" not in report["pareto_criteria"] and report["pareto"]
    speed = [o for o in report["orderings"] if o["metric"] == "speed"]
    assert speed and all(o["verdict"] == "not informed" for o in speed)


def test_identical_materials_share_first_place(rng):
    draws = _draws(rng, {"A": 1.0, "C": 0.5}, n=200)
    draws["B"] = {c: v.copy() for c, v in draws["A"].items()}
    r = rank_criterion(draws, "speed")
    np.testing.assert_allclose(r.p_best, [1.0, 0.0, 1.0])  # best together: neither beats the other
    assert r.verdict() == {"verdict": "best", "materials": ["A", "B"]}
    assert r.p_better[0, 2] == r.p_better[2, 0] == 0.0
    assert r.mean_rank[0] == r.mean_rank[2] == 1.0 and r.mean_rank[1] == 3.0


def test_lower_is_better_for_hysteresis(rng):
    draws = _draws(rng, {"A": 1.0, "B": 2.0})
    assert rank_criterion(draws, "hysteresis_loss").p_best[0] == 1.0
    assert rank_criterion(draws, "speed").p_best[1] == 1.0


def test_pareto_set_by_construction(rng):
    # B beats C on every criterion (C's hysteresis is the highest); A has the lowest hysteresis, so A and B
    # are both Pareto-optimal and C never is.
    draws = _draws(rng, {"A": 1.0, "B": 2.0, "C": 1.5}, sd=0.01)
    draws["C"]["hysteresis_loss"] = draws["C"]["hysteresis_loss"] + 2.0
    p = pareto_probability(draws)
    assert p["A"] == 1.0 and p["B"] == 1.0 and p["C"] == 0.0


def test_orderings_use_only_the_materials_present(rng):
    draws = _draws(rng, {"TP": 2.0, "P": 1.0}, sd=0.01)
    checks = ordering_checks(draws)
    assert checks and all({c["a"], c["b"]} <= {"TP", "P"} for c in checks)
    speed = next(c for c in checks if c["metric"] == "speed")
    assert (speed["a"], speed["b"], speed["probability"], speed["se"]) == ("TP", "P", 1.0, 0.0)
    equal = next(c for c in checks if c["relation"] == "=")  # hysteresis: TP about equal to P
    assert equal["probability"] == 0.0  # a factor of 2 apart
    assert speed["verdict"] == "agrees" and equal["verdict"] == "contradicts"
    assert speed["margin"] == equal["margin"] == 0.05 and speed["n"] == 4000


def test_draws_not_finite_everywhere_are_left_out(rng):
    draws = _draws(rng, {"A": 1.0, "B": 1.1}, n=100)
    draws["A"]["speed"][:40] = np.nan
    assert rank_criterion(draws, "speed").n == 60
    draws["A"]["efficiency"][:] = np.nan
    assert "efficiency" not in rank_materials(draws)["criteria"]


def test_rank_command_writes_its_report_and_refuses_missing_metrics(tmp_path, rng, capsys):
    for code, mu in {"TP": 1.0, "P": 1.1}.items():
        (tmp_path / code).mkdir()
        m = {"material": code, "draw_values": {c: rng.normal(mu, 0.1, 50).tolist() for c in CRITERIA}}
        (tmp_path / code / "metrics.json").write_text(json.dumps(m))
    assert main(["rank", str(tmp_path / "TP"), str(tmp_path / "P"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report["materials"] == ["TP", "P"] and (tmp_path / "ranking.md").exists()
    assert report["draws"] == 50 and report["margin"] == 0.05
    assert main(["rank", str(tmp_path / "TP"), "--out", str(tmp_path / "alone")]) == 0
    assert "one result: it is best in every criterion by definition" in capsys.readouterr().err
    (tmp_path / "X").mkdir()
    assert main(["rank", str(tmp_path / "TP"), str(tmp_path / "X"), "--out", str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err
    assert "metrics.json: no such file" in err and "Traceback" not in err
    assert not (tmp_path / "new").exists()


def test_ranking_says_when_materials_were_tested_at_different_pressures(rng):
    from peano_bayes.analysis.ranking import ranking_markdown

    draws = _draws(rng, {"TP": 1.0, "FC": 2.0, "P": 1.5}, n=200)
    mixed = ranking_markdown(rank_materials(draws, test_pressure_kpa={"TP": 30.0, "FC": 200.0, "P": 30.0}))
    assert "*Test pressures differ* (30 kPa: TP, P; 200 kPa: FC)" in mixed
    same = ranking_markdown(rank_materials(draws, test_pressure_kpa={"TP": 30.0, "FC": 30.0, "P": 30.0}))
    unknown = ranking_markdown(rank_materials(draws))
    assert "Test pressures differ" not in same and "Test pressures differ" not in unknown
    common = ranking_markdown(
        rank_materials(
            draws,
            test_pressure_kpa={"TP": 100.0, "FC": 100.0, "P": 100.0},
            own_test_pressure_kpa={"TP": 30.0, "FC": 200.0, "P": 100.0},
        )
    )
    assert "*Compared at a common pressure* (100 kPa). Tested elsewhere: TP at 30 kPa; FC at 200 kPa;" in common
    assert " P at " not in common and "Test pressures differ" not in common  # P was tested at 100 kPa


def test_ordering_summary_counts_each_verdict_once(rng):
    from peano_bayes.analysis.ranking import ordering_counts, ordering_summary, ranking_markdown

    # With 1 % spread: "a > b" (by more than 5 %) agrees when a's mean is 30 % larger and contradicts when it is
    # 30 % smaller or equal (TP and P: a is not larger by the margin); "about equal" (within 5 %) agrees for equal
    # means, else contradicts.
    # The step metrics marked prior-only are not informed whatever their values say.
    means = {"TP": 1.5, "P": 1.5, "TFC": 1.0, "PR": 0.7}
    prior_only = ("speed", "power_per_pressure", "efficiency")
    report = rank_materials(_draws(rng, means, sd=0.01), from_prior=prior_only)
    rows = report["orderings"]
    expected = {"agrees": 0, "contradicts": 0, "undecided": 0, "not informed": 0}
    for o in rows:
        if o["metric"] in prior_only:
            verdict = "not informed"
        elif o["relation"] == "=":
            verdict = "agrees" if means[o["a"]] == means[o["b"]] else "contradicts"
        elif means[o["a"]] == means[o["b"]]:
            verdict = "contradicts"
        else:
            verdict = "agrees" if means[o["a"]] > means[o["b"]] else "contradicts"
        assert o["verdict"] == verdict, o
        expected[verdict] += 1
    assert expected["agrees"] and expected["contradicts"] and expected["not informed"], expected
    assert ordering_counts(rows) == expected
    line = ordering_summary(rows)
    informed = len(rows) - expected["not informed"]
    assert line.startswith(f"Of the {informed} relations the fitted tests inform, the posteriors support")
    assert f"support {expected['agrees']} at" in line and f"contradict {expected['contradicts']} at" in line
    assert f"leave {expected['undecided']} undecided" in line
    assert f"{expected['not informed']} more rest on the prior only" in line
    assert line in ranking_markdown(report)


def test_rank_says_whose_metrics_rest_on_fewer_draws_than_were_drawn(tmp_path, rng, capsys):
    for code, failed in {"TP": 68, "P": 0}.items():
        (tmp_path / code).mkdir()
        draws = {c: rng.normal(1.0, 0.1, 100).tolist() for c in CRITERIA}
        for values in draws.values():  # as metrics.json keeps them: NaN where a draw could not be simulated
            values[:failed] = [float("nan")] * failed
        m = {"material": code, "draws": 100, "n_failed": failed, "draw_values": draws}
        (tmp_path / code / "metrics.json").write_text(json.dumps(m))
    assert main(["rank", str(tmp_path / "TP"), str(tmp_path / "P")]) == 0
    err = capsys.readouterr().err
    assert "WARNING: TP: 68 of 100 posterior draws could not be simulated" in err and " P: " not in err
    page = (tmp_path / "ranking.md").read_text()
    assert "*Draws that could not be simulated* (TP: 68 of 100)" in page
    assert json.loads((tmp_path / "ranking.json").read_text())["failed_draws"] == {"TP": [68, 100]}


def test_a_probability_carries_its_monte_carlo_error_and_a_verdict_needs_two_of_them():
    """The binomial standard error sqrt(p (1 - p) / n); a claim at 0.9 holds only above 0.9 + 2 SE."""
    from peano_bayes.analysis.ranking import mc_se, verdict

    assert mc_se(0.9, 100) == pytest.approx(0.03) and mc_se(0.9, 1000) == pytest.approx(0.0094868, rel=1e-4)
    assert mc_se(1.0, 50) == 0.0 and np.isnan(mc_se(0.5, 0))
    assert verdict(0.93, mc_se(0.93, 100)) == "undecided"  # 0.93 - 2 x 0.0255 < 0.9
    assert verdict(0.93, mc_se(0.93, 1000)) == "holds"  # 0.93 - 2 x 0.0081 > 0.9
    assert verdict(0.07, mc_se(0.07, 1000)) == "fails" and verdict(0.07, mc_se(0.07, 100)) == "undecided"
    assert verdict(0.05, 0.01, fails=False) == "undecided" and verdict(float("nan"), 0.0) == "undecided"


def test_an_ordering_near_its_threshold_is_undecided_until_the_draws_settle_it():
    """TP's speed exceeds P's by more than 5 % in exactly 92 of 100 paired draws: 0.92 is within two standard
    errors (0.027 each) of 0.9, so undecided; the same share of 1000 draws agrees."""
    for n, said in ((100, "undecided"), (1000, "agrees")):
        tp = np.where(np.arange(n) < 0.92 * n, 2.0, 1.0)  # 2.0 beats P's 1.0 by 100 %, 1.0 ties it
        row = next(o for o in ordering_checks({"TP": {"speed": tp}, "P": {"speed": np.ones(n)}}) if o["a"] == "TP")
        assert row["probability"] == pytest.approx(0.92) and row["verdict"] == said, (n, row)
    # the margin: 1.04 is not "greater" at 5 %, 1.06 is; 1.04 is "about equal", 1.06 is not
    near = ordering_checks({"TP": {"speed": np.full(10, 1.04)}, "P": {"speed": np.ones(10)}})[0]
    far = ordering_checks({"TP": {"speed": np.full(10, 1.06)}, "P": {"speed": np.ones(10)}})[0]
    assert (near["probability"], far["probability"]) == (0.0, 1.0)
    hyst = lambda a: {"TP": {"hysteresis_loss": np.full(10, a)}, "P": {"hysteresis_loss": np.ones(10)}}  # noqa: E731
    equal = lambda a: next(o for o in ordering_checks(hyst(a)) if o["relation"] == "=")["probability"]  # noqa: E731
    assert (equal(1.04), equal(1.06)) == (1.0, 0.0)


def test_two_results_with_a_known_order_rank_that_way_in_the_report_page(rng):
    """A is faster than B by 50 % in every draw: the page names A clearly best on speed, with P = 1.00 ± 0.00 and
    rank 1.0 (1-1), and B last."""
    from peano_bayes.analysis.ranking import ranking_markdown

    report = rank_materials(_draws(rng, {"A": 1.5, "B": 1.0}, sd=0.01, n=1000))
    speed = report["criteria"]["speed"]
    assert speed["verdict"] == "clearly best" and speed["materials"] == ["A"]
    assert speed["rank_interval"] == {"A": [1, 1], "B": [2, 2]}
    row = next(line for line in ranking_markdown(report).splitlines() if line.startswith("| speed"))
    assert "| clearly best: A |" in row and "1.00 ± 0.00 / 1.00 ± 0.00, rank 1.0 (1-1)" in row
    assert "0.00 ± 0.00 / 0.00 ± 0.00, rank 2.0 (2-2)" in row
    hysteresis = report["criteria"]["hysteresis_loss"]  # lower is better: B
    assert hysteresis["materials"] == ["B"] and report["draws"] == 1000
