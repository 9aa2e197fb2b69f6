"""Posterior Table 3 metrics: draws from a result simulate the paper's protocol; the metrics of the generating
parameters fall inside the posterior's spread; unfitted step parameters are flagged; bad results are refused."""

import json

import arviz as az
import numpy as np
import pytest
from scipy import stats

from peano_bayes.analysis.metrics import (
    STEP_METRICS,
    compare_published,
    model_metrics,
    posterior_metrics,
    protocol_material,
)
from peano_bayes.app.cli import main
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.results import load_result, parameter_draws

from .helpers import minimal_summary

# One xdist worker runs this group, so the session fixture `recovered` (a fit and a sampling run) is built once.
pytestmark = pytest.mark.xdist_group("recovered")

#: Metrics of the load cycles at the test pressure and the 0 kPa stretch: the fitted test informs them.
LOAD_CYCLE_METRICS = ("hysteresis_loss", "free_strain", "energy_per_pressure", "stiffness_at_minus_1.5pct_0kPa")


@pytest.fixture(scope="module")
def predicted(result_dir):
    return posterior_metrics(load_result(result_dir), n_draws=12, seed=0)


def test_parameter_draws_take_sampled_fixed_and_prior_values(result_dir, recovered):
    _, _, _, truth, _ = recovered
    idata = load_result(result_dir)
    sets, prior_only = parameter_draws(idata, 5, seed=1)
    assert len(sets) == 5
    assert "orifice_area_m2" in prior_only  # the step was not fitted
    # one specimen, so no new-specimen level: the stored draws (chains one after another), evenly spaced
    stored = idata.posterior["tensile_ka_n_per_m"].values.reshape(-1)
    picked = stored[np.linspace(0, stored.size - 1, 5).round().astype(int)]
    assert [s["tensile_ka_n_per_m"] for s in sets] == picked.tolist()
    assert len(set(picked.tolist())) == 5  # five different draws, not one repeated
    assert all(s["extension_k_n_per_m"] == truth["extension_k_n_per_m"] for s in sets)  # held at the fit's value
    assert len({s["orifice_area_m2"] for s in sets}) == 5  # prior draws, not one value


def test_a_new_specimen_beyond_a_physical_bound_is_redrawn_inside_it(result_dir):
    """A population near a bound (friction stiffness 9.5e5 N/m, bound 1e6) with spread 0.2: stored new-specimen
    draws above the bound (as ``metrics`` met on Veale-model data, where the rig then refused the parameter)
    are redrawn from the hierarchy truncated to the bound, the rest kept. Known answer: the redrawn
    ``z = ln(x / mu) / tau`` are standard normal below ln(1e6 / 9.5e5) / 0.2 = 0.256, whose mean is
    -phi(0.256) / Phi(0.256) = -0.642."""
    idata = load_result(result_dir)
    post = idata.posterior
    shape = (post.sizes["chain"], post.sizes["draw"])
    name, mu, tau, high = "friction_stiffness_n_per_m", 9.5e5, 0.2, 1e6
    stored = np.where(np.arange(np.prod(shape)).reshape(shape) % 2 == 0, 2.0e6, 9.0e5)  # every other draw beyond
    idata.posterior = post.assign(
        {
            name: (("chain", "draw"), np.full(shape, mu)),
            "specimen_log_sd": (("chain", "draw"), np.full(shape, tau)),
            "new_specimen__" + name: (("chain", "draw"), stored),
        }
    )
    n = int(np.prod(shape))
    sets, _ = parameter_draws(idata, n, seed=3)
    values = np.array([s[name] for s in sets])
    assert np.all(values <= high) and np.sum(values == 9.0e5) == n // 2  # in-bound draws kept as stored
    z = np.log(values[values != 9.0e5] / mu) / tau
    bound = np.log(high / mu) / tau
    expected = -stats.norm.pdf(bound) / stats.norm.cdf(bound)
    assert z.max() <= bound and abs(z.mean() - expected) < 4 * z.std() / np.sqrt(z.size), (z.mean(), expected)
    again, _ = parameter_draws(idata, n, seed=3)
    assert [s[name] for s in again] == list(values)  # seeded


def test_unfitted_parameters_come_from_the_prior_the_fit_used(result_dir, tmp_path):
    """A result of one's own material (no bundled prior, no Table 4 conditions) draws its unfitted step
    parameters from its own prior file and simulates the protocol at its own data file's conditions."""
    prior = tmp_path / "mine.toml"
    prior.write_text(
        '[meta]\nmaterial = "VM"\nextends = "textile_composite.toml"\n\n[parameters.orifice_area_m2]\n'
        'distribution = "uniform"\nlow = 2.0e-6\nhigh = 2.1e-6\nunit = "m^2"\nprovenance = "test"\n'
    )
    idata = load_result(result_dir)
    idata.posterior.attrs.update(
        material="VM",
        prior=str(prior),
        conditions=json.dumps(
            {"fluid": "water", "test_pressure_pa": 1.5e5, "step_load_n": 20.0, "start_tension_n": 30.0}
        ),
    )
    sets, prior_only = parameter_draws(idata, 4, seed=1)
    assert "orifice_area_m2" in prior_only
    assert all(2.0e-6 <= s["orifice_area_m2"] <= 2.1e-6 for s in sets)  # from mine.toml, not TP's prior
    spec = protocol_material(idata)
    assert (spec.code, spec.test_pressure_pa, spec.step_load_n, spec.start_tension_n) == ("VM", 1.5e5, 20.0, 30.0)


@pytest.mark.slow
def test_metrics_of_the_truth_lie_within_the_posterior_spread(predicted, recovered):
    """The posterior is tight around the generating parameters, so the metrics they give must sit within
    4 sd of the predicted draws (plus 1 % of the value for the rig measurement's own discretization)."""
    _, _, _, truth, _ = recovered
    expected = model_metrics("TP", {k: v for k, v in truth.items() if not k.startswith("noise_")})
    assert predicted.n_failed == 0
    for name in LOAD_CYCLE_METRICS + ("blocking_force_per_pressure", "stroke"):
        draws = predicted.draws[name]
        assert np.all(np.isfinite(draws)), name
        tolerance = 4 * np.std(draws) + 0.01 * abs(expected[name])
        assert abs(np.mean(draws) - expected[name]) <= tolerance, (name, np.mean(draws), expected[name])


@pytest.mark.slow
def test_step_metrics_are_flagged_as_prior_when_the_step_was_not_fitted(predicted):
    assert set(predicted.from_prior) == set(STEP_METRICS)
    summary = predicted.summary()
    assert all(summary[name]["from_prior"] for name in STEP_METRICS)
    assert not summary["free_strain"]["from_prior"]
    low, high = summary["free_strain"]["hdi_low"], summary["free_strain"]["hdi_high"]
    assert low <= summary["free_strain"]["median"] <= high


def test_compare_published_reports_whether_the_interval_holds_the_value():
    summary = {
        "hysteresis_loss": {"median": 0.2, "hdi_low": 0.15, "hdi_high": 0.3, "from_prior": False},
        "energy_per_pressure": {"median": 4.5, "hdi_low": 4.0, "hdi_high": 5.0, "from_prior": False},
        "stiffness_at_minus_1.5pct_0kPa": {
            "median": 1.0,
            "hdi_low": float("nan"),
            "hdi_high": float("nan"),
            "from_prior": False,
        },
    }
    rows = {r["metric"]: r for r in compare_published("TP", summary) if r["metric"] in summary}
    assert rows["hysteresis_loss"]["value"] == 0.225 and rows["hysteresis_loss"]["inside"] is True
    assert rows["energy_per_pressure"]["value"] == 5.5 and rows["energy_per_pressure"]["inside"] is False
    assert rows["stiffness_at_minus_1.5pct_0kPa"]["inside"] is None


@pytest.mark.parametrize("case, expected", [("missing", "no such file"), ("garbage", "not a readable NetCDF")])
def test_bad_result_exits_2_with_the_path_named(tmp_path, capsys, case, expected):
    target = tmp_path / "missing"
    if case == "garbage":
        (tmp_path / "posterior.nc").write_text("not netcdf")
        target = tmp_path
    assert main(["metrics", str(target), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert expected in err and str(tmp_path) in err and "Traceback" not in err
    assert not (tmp_path / "metrics.json").exists()


def test_result_without_provenance_is_refused(tmp_path, result_dir):
    import arviz as az

    idata = az.from_netcdf(str(result_dir / "posterior.nc"))
    del idata.posterior.attrs["material"]
    idata.to_netcdf(str(tmp_path / "posterior.nc"))
    with pytest.raises(PeanoBayesInputError, match="lacks the attribute.*material"):
        load_result(tmp_path)


@pytest.mark.slow
def test_metrics_command_writes_metrics_json(result_dir, capsys):
    assert main(["metrics", str(result_dir), "--draws", "3", "--no-progress", "--json"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # stdout holds the JSON object alone
    written = json.loads((result_dir / "metrics.json").read_text())
    assert report["material"] == written["material"] == "TP" and written["draws"] == 3
    assert any(row["metric"] == "hysteresis_loss" for row in written["published"])
    assert "| metric | unit | median |" in captured.err  # the table a person reads, on stderr under --json
    assert "extrapolate" not in captured.err  # at its own test pressure


def test_metrics_at_a_common_pressure_go_to_their_own_file_and_follow_the_pressure(result_dir, capsys):
    """The same posterior draws (same seed) simulated at twice the test pressure: each draw's free strain rises
    (the pressure opens the tubes further), the file says which pressure, and the paper's values (given at the
    test pressure) are not compared."""
    assert main(["metrics", str(result_dir), "--draws", "3", "--no-progress", "--json", "--pressure-kpa", "60"]) == 0
    assert "simulated at 60 kPa; TP was tested at 30 kPa, so these metrics extrapolate" in capsys.readouterr().err
    at_60 = json.loads((result_dir / "metrics_at_60kPa.json").read_text())
    assert at_60["test_pressure_kpa"] == 60.0 and at_60["own_test_pressure_kpa"] == 30.0 and at_60["published"] == []
    from peano_bayes.analysis.metrics import evaluate_result

    own = evaluate_result(result_dir, n_draws=3, progress=False)
    assert own["test_pressure_kpa"] == own["own_test_pressure_kpa"] == 30.0 and own["published"]
    assert at_60["draws"] == own["draws"] == 3
    assert np.all(np.asarray(at_60["draw_values"]["free_strain"]) > np.asarray(own["draw_values"]["free_strain"]))
    assert main(["metrics", str(result_dir), "--pressure-kpa", "-5", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--pressure-kpa must be a pressure in kPa above 0 and at most 1000" in err and "got -5" in err


def test_metrics_of_which_no_draw_could_be_simulated_are_not_written(result_dir, tmp_path, monkeypatch, capsys):
    import shutil
    from types import SimpleNamespace

    from peano_bayes.analysis import metrics

    shutil.copy(result_dir / "posterior.nc", tmp_path / "posterior.nc")
    monkeypatch.setattr(metrics, "posterior_metrics", lambda idata, n_draws, **kw: SimpleNamespace(n_failed=n_draws))
    assert main(["metrics", str(tmp_path), "--draws", "3", "--no-progress", "--pressure-kpa", "900"]) == 1
    err = capsys.readouterr().err
    assert "TP: 0 of the 3 posterior draws could be simulated at 900 kPa" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["posterior.nc"]


# --- model discrepancy: a misfit test's excess widens what is read off it -----------------------------------

#: Half-width of a normal's 94 % HDI in sd (its 97 % quantile): the central interval of a normal is its HDI.
Z94 = 1.8807936081512509


def _summary(structured: dict, consistent: dict = None, adopted: dict = None) -> dict:
    """A ``summary.json``'s fit quality and residual correlation: tests of ``structured`` misfit with structure
    (excess RMSE as given), ``consistent`` are consistent with noise, ``adopted`` were sampled as AR(1)."""
    quality, correlation = {}, {}
    for kind, tests in (("structured", structured), ("consistent", consistent or {}), ("adopted", adopted or {})):
        for test, excess in tests.items():
            quality[test] = {"excess_rmse": excess}
            correlation[test] = {
                "consistent_with_noise": kind != "structured",
                "likelihood_lag1": 0.9 if kind == "adopted" else None,
            }
    return minimal_summary(fit_quality_posterior_mean=quality, residual_correlation=correlation)


def test_misfit_discrepancy_is_the_excess_of_the_tests_that_misfit_with_structure():
    from peano_bayes.analysis.metrics import misfit_discrepancy

    summary = _summary({"blocking": 2.0, "stroke": float("nan")}, {"load_cycle": 0.04}, {"step": 0.01})
    assert misfit_discrepancy(summary) == {"blocking": 2.0, "step": 0.01}
    assert misfit_discrepancy(_summary({"blocking": 0.0})) == {}  # structured but nothing beyond the noise
    assert misfit_discrepancy({}) == {}  # a result sampled before fits reported either


def test_each_metric_gets_the_discrepancy_of_the_test_it_is_read_off_at_its_scale():
    """The predictive spread over the parameter draws is the discrepancy alone: the blocking force per MPa carries
    the blocking test's force misfit over the pressure, the stroke the stroke test's strain misfit, the energy a
    force misfit times the free strain and length over the pressure, and the free strain the larger of the stroke
    test's strain misfit and the load cycle's force misfit over the secant slope; slopes and area ratios are
    flagged, a metric of a test that fits keeps its draws, and metrics read off one test move together."""
    from peano_bayes.analysis.metrics import METRIC_UNITS, add_discrepancy

    n, pressure_pa, length_m = 40_000, 1.5e5, 0.05
    rng = np.random.default_rng(11)
    values = {name: np.full(n, 0.5) for name in METRIC_UNITS}
    values["free_strain"] = rng.uniform(0.1, 0.3, n)
    values["blocking_force_per_pressure"] = rng.uniform(400.0, 800.0, n)  # N/MPa: 60-120 N at 0.15 MPa
    eps, blocking_n = values["free_strain"], values["blocking_force_per_pressure"] * 0.15
    for load_cycle_n, free_strain_from in ((1.0, "stroke"), (5.0, "load_cycle")):
        misfit = {"blocking": 2.0, "load_cycle": load_cycle_n, "stroke": 0.004}
        draws, added, not_carried = add_discrepancy(values, misfit, pressure_pa, length_m, np.random.default_rng(3))
        expected = {
            "blocking_force_per_pressure": ("blocking", np.full(n, 2.0 / 0.15)),  # N over MPa
            "stroke": ("stroke", np.full(n, 0.004)),
            "energy_per_pressure": ("load_cycle", load_cycle_n * eps * length_m / 0.15),  # N x strain x m / MPa
            "free_strain": {
                "stroke": ("stroke", np.full(n, 0.004)),
                "load_cycle": ("load_cycle", load_cycle_n * eps / blocking_n),  # N over N per unit strain
            }[free_strain_from],
        }
        expected["free_strain_paper_reading"] = expected["free_strain"]  # read off the same tests, at its scale
        assert set(added) == set(expected)
        for name, (test, sd) in expected.items():
            assert added[name][0] == test, name
            np.testing.assert_allclose(added[name][1], sd, rtol=1e-12, err_msg=name)
            z = (draws[name] - values[name]) / sd
            assert abs(np.mean(z)) < 4 / np.sqrt(n), name
            assert abs(np.std(z) - 1) < 0.02, name  # se of a sample sd at n = 40000: 0.35 %
        low, high = az.hdi(draws["stroke"], hdi_prob=0.94)  # constant draws plus one normal
        assert abs((high - low) / (2 * Z94 * 0.004) - 1) < 0.03
        z = {name: (draws[name] - values[name]) / added[name][1] for name in expected}
        shares = {"stroke": "stroke", "load_cycle": "energy_per_pressure"}[free_strain_from]  # same test
        np.testing.assert_allclose(z["free_strain"], z[shares], rtol=1e-9)
        assert abs(np.corrcoef(z["stroke"], z["blocking_force_per_pressure"])[0, 1]) < 4 / np.sqrt(n)
        assert set(not_carried) == {"stiffness_at_minus_1.5pct_0kPa", "hysteresis_loss"}
        for name in set(METRIC_UNITS) - set(expected):
            assert draws[name] is values[name], name
    unchanged, none, _ = add_discrepancy(values, {}, pressure_pa, length_m, np.random.default_rng(3))
    assert none == {} and all(unchanged[k] is values[k] for k in values)


@pytest.mark.slow
def test_metrics_of_a_result_that_misfits_carry_its_discrepancy(result_dir, tmp_path):
    """A result whose ``summary.json`` says the blocking and load-cycle tests misfit with structure: the
    blocking force's interval widens by the blocking excess over the pressure simulated (TP's own: 30 kPa), the
    hysteresis keeps its parameter interval and is flagged, and the table says which is which."""
    import shutil

    from peano_bayes.analysis.metrics import evaluate_result, metrics_markdown

    shutil.copy(result_dir / "posterior.nc", tmp_path / "posterior.nc")
    (tmp_path / "summary.json").write_text(json.dumps(_summary({"blocking": 3.0, "load_cycle": 1.0})))
    out = evaluate_result(tmp_path, n_draws=3, progress=False)
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert written["discrepancy"] == out["discrepancy"] == {"blocking": 3.0, "load_cycle": 1.0}
    block = out["summary"]["blocking_force_per_pressure"]
    assert block["discrepancy_test"] == "blocking" and block["discrepancy_sd"] == pytest.approx(3.0 / 0.03)
    assert block["hdi_high"] - block["hdi_low"] > block["parameter_hdi_high"] - block["parameter_hdi_low"]
    loss = out["summary"]["hysteresis_loss"]
    assert loss["misfit_not_carried"] and loss["discrepancy_sd"] is None
    assert (loss["hdi_low"], loss["hdi_high"]) == (loss["parameter_hdi_low"], loss["parameter_hdi_high"])
    stroke = out["summary"]["stroke"]  # the stroke test fits: nothing added, nothing flagged
    assert stroke["discrepancy_sd"] is None and not stroke["misfit_not_carried"]
    table = metrics_markdown(out["material"], out["summary"], out["published"])
    assert "included: sd 100 from blocking" in table and "**not included** (load_cycle misfits)" in table
    # Below the tested pressure the misfit keeps its size in newtons (twice as large per MPa at half the
    # pressure); above it, it grows with the pressure (the same per MPa).
    for kpa, per_mpa in ((15, 3.0 / 0.015), (60, 3.0 / 0.03)):
        at = evaluate_result(tmp_path, n_draws=3, progress=False, test_pressure_kpa=kpa)
        assert at["summary"]["blocking_force_per_pressure"]["discrepancy_sd"] == pytest.approx(per_mpa), kpa


@pytest.mark.parametrize("content", ["[1, 2]", '{"residual_correlation": {"blocking": 3}}', "{not json"])
def test_a_malformed_summary_beside_the_result_exits_2_naming_it(result_dir, tmp_path, capsys, content):
    import shutil

    shutil.copy(result_dir / "posterior.nc", tmp_path / "posterior.nc")
    (tmp_path / "summary.json").write_text(content)
    assert main(["metrics", str(tmp_path), "--draws", "2", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "summary.json") in err and "Traceback" not in err
    assert not (tmp_path / "metrics.json").exists()


def test_metrics_written_before_the_discrepancy_existed_are_not_current(tmp_path):
    from peano_bayes.analysis.metrics import METRICS_VERSION, metrics_current

    assert not metrics_current(tmp_path)  # none yet
    (tmp_path / "metrics.json").write_text(json.dumps({"material": "TP", "draws": {}}))
    assert not metrics_current(tmp_path)  # an older file: its intervals are the parameters' alone
    for version, current in ((1, False), (3, False), (METRICS_VERSION, True)):
        record = {"version": version, "material": "TP", "draws": 0, "draw_values": {}}
        (tmp_path / "metrics.json").write_text(json.dumps(record))
        assert metrics_current(tmp_path) == current
    assert not metrics_current(tmp_path, 60.0)  # the common pressure's file is apart
    (tmp_path / "metrics.json").write_text("{half")
    assert not metrics_current(tmp_path)


def test_a_draw_whose_scale_is_undefined_takes_the_median_sd_of_the_others():
    from peano_bayes.analysis.metrics import METRIC_UNITS, add_discrepancy

    values = {name: np.full(5, 0.5) for name in METRIC_UNITS}
    values["free_strain"] = np.array([0.1, 0.2, 0.3, 0.2, 0.2])
    values["blocking_force_per_pressure"] = np.array([500.0, np.nan, 500.0, 0.0, 500.0])  # failed, degenerate
    with np.errstate(all="raise"):  # no warning escapes
        _, added, _ = add_discrepancy(values, {"load_cycle": 5.0}, 2e5, 0.05, np.random.default_rng(0))
    test, sd = added["free_strain"]
    finite = 5.0 * np.array([0.1, 0.3, 0.2]) / 100.0  # N x strain over the 100 N blocking force
    assert test == "load_cycle"
    np.testing.assert_allclose(sd, [finite[0], np.median(finite), finite[1], np.median(finite), finite[2]])


@pytest.mark.slow
def test_rank_recomputes_metrics_of_an_older_version_with_as_many_draws(result_dir, tmp_path, capsys):
    import shutil

    from peano_bayes.analysis.metrics import METRICS_VERSION

    result = tmp_path / "TP"
    result.mkdir()
    shutil.copy(result_dir / "posterior.nc", result / "posterior.nc")
    older = {"material": "TP", "n_draws": 3, "draws": {"free_strain": [0.1, 0.1, 0.1]}, "summary": {}}
    (result / "metrics.json").write_text(json.dumps(older))
    assert main(["rank", str(result), "--out", str(tmp_path / "ranking")]) == 0
    capsys.readouterr()
    written = json.loads((result / "metrics.json").read_text())
    assert written["version"] == METRICS_VERSION and written["draws"] == 3
    assert written["draw_values"]["free_strain"] != older["draws"]["free_strain"]
