"""The main job's plumbing: the run log and the results page's parameter table (population, new specimen,
posterior contraction)."""

import json
import pickle
from types import SimpleNamespace

import numpy as np
import pytest

from peano_bayes.app.batch import RunLog
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.driver import linearisation_point
from peano_bayes.report.index import index_markdown


def test_run_log_prints_and_appends_timestamped_lines_and_pickles(tmp_path):
    seen = []
    log = RunLog(tmp_path / "run.log", seen.append)
    log("TP: least squares ...")
    again = pickle.loads(pickle.dumps(RunLog(tmp_path / "run.log")))  # what a worker process receives
    again.echo = None
    again("P: sampling")
    lines = (tmp_path / "run.log").read_text().splitlines()
    assert seen == ["TP: least squares ..."]
    assert [line.split(" ", 1)[1] for line in lines] == ["TP: least squares ...", "P: sampling"]
    assert all(line[:4].isdigit() and line[19] == "Z" for line in lines)


def _summary(contraction):
    row = {"mean": 500.0, "sd": 10.0, "hdi_low": 480.0, "hdi_high": 520.0}
    spread = {"mean": 0.05, "sd": 0.02, "hdi_low": 0.01, "hdi_high": 0.09}
    names = ("tensile_ka_n_per_m", "specimen_log_sd")
    return {
        "material": "TP",
        "dataset": "TP.csv",
        "tests": ["load_cycle"],
        "n_walkers": 32,
        "n_ensembles": 4,
        "steps": 2000,
        "convergence": {
            "converged": True,
            "problems": [],
            "rhat": dict.fromkeys(names, 1.002),
            "ess_bulk": dict.fromkeys(names, 3000.0),
            "tau_lengths": 60.0,
        },
        "parameters": {"tensile_ka_n_per_m": row, "specimen_log_sd": spread},
        "new_specimen": {"tensile_ka_n_per_m": {**row, "hdi_low": 450.0, "hdi_high": 560.0}},
        "contraction": {"tensile_ka_n_per_m": 0.99, "specimen_log_sd": contraction},
        "units": {"tensile_ka_n_per_m": "N/m", "specimen_log_sd": "-"},
        "fit_quality_posterior_mean": {},
        "timings_s": {"least_squares_s": 1.0, "compile_s": 1.0, "sampling_s": 1.0},
    }


def test_results_page_shows_population_new_specimen_and_weakly_informed_parameters():
    page = index_markdown([_summary(0.2)])
    assert "4 ensembles of 32 walkers x 2000 steps; converged" in page  # an old summary: no warm-up, no tau
    sampled = {**_summary(0.2), "warmup": 900}
    sampled["convergence"] = {**sampled["convergence"], "tau_steps": {"a": 12.34, "b": 31.0}, "discard_steps": 962}
    assert "x 2000 steps (900 warm-up, tau_max 31.0 steps, first 962 discarded); converged" in index_markdown([sampled])
    assert "| tensile_ka_n_per_m | N/m | 500 | 480 to 520 | 450 to 560 | 0.99 | 1.002 | 3000 |" in page
    assert "**Posterior close to its prior** (contraction below 0.5): specimen_log_sd." in page
    assert "close to its prior" not in index_markdown([_summary(0.8)])
    assert "Held, not sampled" not in page  # an old summary, or one that held nothing
    fixed = {"length_fraction": 0.8, "friction_force_n": 1.5, "orifice_area_m2": 5e-06}
    held = index_markdown([{**_summary(0.8), "fixed": fixed}])
    assert "**Held, not sampled** (every interval here is conditional on these values): length_fraction = 0.8, " in held
    assert "friction_force_n = 1.5." in held and "The shape constants (length_fraction) were held at nominal" in held
    assert "orifice_area_m2" not in held  # step-only, not fitted: the step metrics draw it from the prior
    with_step = index_markdown([{**_summary(0.8), "tests": ["load_cycle", "step"], "fixed": fixed}])
    assert "friction_force_n = 1.5, orifice_area_m2 = 5e-06." in with_step
    assert "shape constants" not in index_markdown([{**_summary(0.8), "fixed": {"friction_force_n": 1.5}}])
    assert "Held, not sampled" not in index_markdown([{**_summary(0.8), "fixed": {"orifice_area_m2": 5e-06}}])
    assert "Timings: least squares 1.0 s," in page  # chosen without discovery
    timed = {**_summary(0.2), "timings_s": {**_summary(0.2)["timings_s"], "discovery_s": 107.54}}
    assert "Timings: discovery 107.5 s, least squares 1.0 s," in index_markdown([timed])


def test_the_results_page_flags_a_test_whose_residuals_have_structure():
    quality = {"unit": "N", "rmse": 2.1, "max_error": 5.4, "r2": 0.9975, "excess_rmse": 2.05}
    correlated = {"lag1": 0.95, "pairs": 2388, "interval_factor": 6.2, "consistent_with_noise": False}
    white = {"lag1": -0.03, "pairs": 2388, "interval_factor": 1.0, "consistent_with_noise": True}
    summary = {**_summary(0.9), "fit_quality_posterior_mean": {"load_cycle": quality}}
    page = index_markdown([{**summary, "residual_correlation": {"load_cycle": correlated}}])
    assert "| load_cycle | 2.1 N | 5.4 N | 0.9975 | 2.05 N | 0.95 (structured) |" in page
    assert "off the model's prediction by roughly that test's RMSE beyond the sensor noise" in page
    assert "the parameter intervals above do not include it; the Table 3 metrics below do" in page
    assert "**Misfit with structure** in load_cycle" in page
    assert "The intervals that load_cycle inform are narrower than the data justify" in page
    adopted = index_markdown(
        [{**summary, "residual_correlation": {"load_cycle": {**correlated, "likelihood_lag1": 0.93}}}]
    )
    assert "| 0.95 (structured; sampled as AR(1), lag-1 0.93) |" in adopted
    assert "took the residuals of load_cycle as AR(1)" in adopted and "narrower than the data" not in adopted
    white_at_mean = {**white, "likelihood_lag1": 0.93}  # structured at the mode, not at the posterior mean
    marked = index_markdown([{**summary, "residual_correlation": {"load_cycle": white_at_mean}}])
    assert "| -0.03 (sampled as AR(1), lag-1 0.93: structured at the mode) |" in marked
    assert "took the residuals of load_cycle as AR(1)" in marked
    before_column = {k: v for k, v in quality.items() if k != "excess_rmse"}
    older = {**summary, "fit_quality_posterior_mean": {"load_cycle": before_column}}
    old_page = index_markdown([{**older, "residual_correlation": {"load_cycle": correlated}}])
    assert "| load_cycle | 2.1 N | 5.4 N | 0.9975 |  | 0.95 (structured) |" in old_page  # sampled before the column
    assert "beyond the sensor noise: the parameter" not in old_page and "Try `--discover`." in old_page
    quiet = index_markdown([{**summary, "residual_correlation": {"load_cycle": white}}])
    assert "| load_cycle | 2.1 N | 5.4 N | 0.9975 | 2.05 N | -0.03 |" in quiet and "Misfit with structure" not in quiet


def test_a_ridge_is_named_with_the_combination_the_data_determine():
    import arviz as az
    import numpy as np

    from peano_bayes.inference.results import posterior_ridges

    rng = np.random.default_rng(5)
    z, e = rng.normal(0.0, 0.1, (4, 2000)), rng.normal(0.0, 0.001, (4, 2000))
    # log b = -0.5 log a + e: a * b^2 = exp(2 e), relative sd 0.002; c is independent and signed (not logged)
    draws = {"a": np.exp(z), "b": np.exp(-0.5 * z + e), "c": rng.normal(-1.0, 1.0, (4, 2000))}
    ridges = posterior_ridges(az.from_dict(posterior=draws), ["a", "b", "c"])
    assert [(r["a"], r["b"]) for r in ridges] == [("a", "b")]
    r = ridges[0]
    assert r["correlation"] < -0.99 and r["log_a"] and r["log_b"]
    np.testing.assert_allclose(r["exponent"], 2.0, rtol=0.01)
    np.testing.assert_allclose(r["sd_combination"], 0.002, rtol=0.05)
    np.testing.assert_allclose([r["sd_a"], r["sd_b"]], [0.1, 0.05], rtol=0.05)
    page = index_markdown([{**_summary(0.9), "ridges": ridges}])
    assert "- a and b: correlation -1.00; a × b^2.00 is determined to ±0.2 % (1 sd), each alone to ±10 %" in page
    assert "Ridges" not in index_markdown([_summary(0.9)])


def test_the_results_page_names_a_bundled_dataset_by_its_place_in_the_package():
    from peano_bayes.bundled import dataset_path

    bundled = index_markdown([{**_summary(0.9), "dataset": str(dataset_path("TP"))}])
    assert "Data: `peano_bayes/bundled/data/TP.csv`" in bundled
    assert str(dataset_path("TP").parent) not in bundled  # not the absolute path of the machine
    own = index_markdown([{**_summary(0.9), "dataset": "/data/rig/my.csv"}])
    assert "Data: `/data/rig/my.csv`" in own
    clone = index_markdown([{**_summary(0.9), "dataset": "/tmp/job/clone/peano_bayes/bundled/data/FC.csv"}])
    assert "Data: `peano_bayes/bundled/data/FC.csv`" in clone  # the job ran from another copy of the package


def test_a_resumed_state_needs_the_point_its_input_error_was_linearised_at(tmp_path):
    """A resume reads the linearisation point, the AR(1) residual correlations taken there and the contrasts sampled
    non-centred back (none in a file written before they existed); a state without it (an earlier version's
    likelihood) or with other parameters is refused with a message naming the file and what to do."""
    posterior = SimpleNamespace(names=("a", "b"))
    path, state = tmp_path / "input_error_point.json", tmp_path / "sampler_state.npz"
    with pytest.raises(PeanoBayesInputError, match="earlier version.*without --resume"):
        linearisation_point(path, state, posterior)
    path.write_text(json.dumps({"names": ["a", "c"], "theta": [1.0, 2.0]}))
    with pytest.raises(PeanoBayesInputError, match="linearised over the parameters a, c; this fit samples a, b"):
        linearisation_point(path, state, posterior)
    path.write_text(json.dumps({"names": ["a", "b"], "theta": [1.0, 0.1 + 0.2]}))  # written before AR(1) residuals
    theta, lag1, noncentred = linearisation_point(path, state, posterior)
    np.testing.assert_array_equal(theta, [1.0, 0.1 + 0.2])
    assert lag1 == {} and noncentred == ()
    path.write_text(json.dumps({"names": ["a", "b"], "theta": [1.0, 2.0], "residual_lag1": {"blocking": 0.97},
                                "noncentred": [True, False]}))  # fmt: skip
    assert linearisation_point(path, state, posterior)[1:] == ({"blocking": 0.97}, (True, False))


def test_a_main_job_unit_reports_its_material_in_the_worker(tmp_path, monkeypatch):
    """The main job's unit samples and then computes its own metrics and figures (not the parent, one material
    at a time); a fit-many unit does not."""
    from peano_bayes.app import batch

    calls = []
    monkeypatch.setattr(batch, "infer", lambda source, out, **kw: {"material": "TP", "label": kw["label"]})
    monkeypatch.setattr(batch, "material_report", lambda d, s, **kw: calls.append((d, s["label"], kw["n_draws"])))
    batch._infer_unit("TP.csv", str(tmp_path), "TP", {"log": print}, report_draws=batch.REPORT_DRAWS)
    assert calls == [(tmp_path / "TP", "TP", batch.REPORT_DRAWS)]
    batch._infer_unit("TP.csv", str(tmp_path), "TP", {"log": print})
    assert len(calls) == 1


def test_a_posterior_far_in_a_tail_of_its_prior_is_placed_in_prior_sd_and_flagged_on_the_page():
    """Known answers for where a value sits in its prior (prior sd), which positions count as a prior-data
    conflict, and the results page that names them."""
    from scipy import stats

    from peano_bayes.inference import Prior, parse_entry
    from peano_bayes.inference.results import PRIOR_CONFLICT_SD, prior_conflicts

    def marginal(name, unit, **entry):
        return parse_entry("test.toml", name, {"unit": unit, "provenance": "test", **entry})

    lognormal = marginal("extension_k_n_per_m", "N/m", distribution="lognormal", median=320.0, sigma_log=2.3, high=1e5)
    # a lognormal: the distance from the median in sigma_log, with the mass its cut at 1e5 removes accounted for
    top = stats.norm.cdf(np.log(1e5 / 320.0) / 2.3)
    expected = stats.norm.ppf(stats.norm.cdf(-4.0) / top)
    assert lognormal.position(320.0 * np.exp(-4.0 * 2.3)) == pytest.approx(expected, abs=1e-9)
    assert -4.0 < expected < -3.99  # the cut, 2.5 sd above the median, moves it by little
    # a truncated normal: its own CDF (scipy's truncnorm), not the uncut normal's 0.5 at its mean
    cut = marginal("length_fraction", "-", distribution="truncnormal", mean=0.7, sd=0.15, low=0.3, high=1.0)
    expected = stats.norm.ppf(stats.truncnorm((0.3 - 0.7) / 0.15, (1.0 - 0.7) / 0.15, loc=0.7, scale=0.15).cdf(0.7))
    assert cut.position(0.7) == pytest.approx(expected, abs=1e-12) and expected > 0.02  # uncut: 0
    assert cut.position(1.0) == np.inf and cut.position(2.0) == np.inf  # on or past a bound: the end
    half = marginal("noise_blocking_force_n", "N", distribution="halfnormal", scale=1.0)
    assert half.position(1e-9) < -PRIOR_CONFLICT_SD  # near zero: its lower end, which is its mode ...
    assert half.position(stats.halfnorm.ppf(stats.norm.cdf(3.5))) == pytest.approx(3.5, abs=1e-9)
    assert half.position(9.0) == pytest.approx(stats.norm.isf(stats.halfnorm.sf(9.0)), rel=1e-9)  # far out: finite

    marginals = {"extension_k_n_per_m": lognormal, "length_fraction": cut, "noise_blocking_force_n": half}
    prior = Prior(tuple(marginals), marginals, {}, (), "", "test")
    positions = {"extension_k_n_per_m": -4.0, "length_fraction": 2.9, "noise_blocking_force_n": -6.0}
    assert prior_conflicts(prior, positions) == ["extension_k_n_per_m"]  # ... so not flagged there
    high_noise = {**positions, "noise_blocking_force_n": 3.2}
    assert prior_conflicts(prior, high_noise) == ["extension_k_n_per_m", "noise_blocking_force_n"]

    summary = {**_summary(0.8), "prior_z": {"tensile_ka_n_per_m": -4.03}, "prior_conflicts": ["tensile_ka_n_per_m"]}
    page = index_markdown([summary])
    assert "**Prior and data disagree**" in page and "tensile_ka_n_per_m (-4.0 prior sd)" in page
    assert "Prior and data disagree" not in index_markdown([_summary(0.8)])  # an older summary: none recorded
