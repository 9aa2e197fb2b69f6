"""Figures: plot functions draw what they are given with unit-carrying labels; the figure builders write PNG
and PDF for a real result (the shared recovery fit) and across materials."""

import dataclasses
import re

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from peano_bayes.analysis.metrics import evaluate_result  # noqa: E402
from peano_bayes.analysis.ranking import CRITERIA, rank_materials  # noqa: E402
from peano_bayes.inference.results import load_result  # noqa: E402
from peano_bayes.report import plots  # noqa: E402
from peano_bayes.report.figures import (  # noqa: E402
    cross_material_figures,
    forest_data,
    material_figures,
    parameter_label,
    predictive_runs,
    published_data,
    response_runs,
)

# One xdist worker runs this group, so the session fixture `recovered` (a fit and a sampling run) is built once.
pytestmark = pytest.mark.xdist_group("recovered")

UNIT = re.compile(r"\[[^\]]+\]")


def _is_picture(path):
    image = plt.imread(path)
    return image.ndim == 3 and min(image.shape[:2]) > 100 and float(np.std(image)) > 0.0


def test_predictive_band_draws_the_given_arrays_with_units():
    t = np.linspace(0.0, 1.0, 5)
    fig, ax = plt.subplots()
    plots.predictive_band(ax, t, t + 0.1, t - 1, t, t + 1, ylabel="force [N]", title="x")
    assert UNIT.search(ax.get_xlabel()) and UNIT.search(ax.get_ylabel())
    line = next(line for line in ax.get_lines() if line.get_label() == "predictive median")
    np.testing.assert_array_equal(line.get_ydata(), t)  # drawn as given: nothing recomputed
    plt.close(fig)


def test_forest_and_published_mark_each_material_and_value():
    fig, ax = plt.subplots()
    plots.published_versus_posterior(
        ax, ["A", "B"], [1.0, 2.0], [0.5, 1.5], [1.5, 2.5], [1.2, np.nan], xlabel="[N/MPa]", title="m"
    )
    assert [t.get_text() for t in ax.get_yticklabels()] == ["A", "B"]
    published = next(line for line in ax.get_lines() if line.get_label() == "published")
    np.testing.assert_array_equal(published.get_xdata(), [1.2, np.nan])
    plt.close(fig)


def test_residuals_against_keeps_noise_and_misfit_legible_and_says_when_empty():
    x = np.array([-1.0, -1.0, 1.0, 1.0])
    before = (np.array([200.0, 210.0, -300.0, -290.0]), (np.array([-1.0, 1.0]), np.array([205.0, -295.0])))
    after = (np.array([0.5, -0.5, 1.0, -1.0]), (np.array([-1.0, 1.0]), np.array([0.0, 0.0])))
    fig, (ax, empty) = plt.subplots(1, 2)
    plots.residuals_against(ax, x, before, after, xlabel="strain-rate sign [-]")
    assert ax.get_yscale() == "symlog" and UNIT.search(ax.get_ylabel())
    means = [line for line in ax.get_lines() if line.get_marker() == "o"]
    assert len(means) == 2 and all(line.get_linestyle() == "None" for line in means)  # two levels: no joining line
    nothing = (np.array([]), (np.array([]), np.array([])))
    plots.residuals_against(empty, np.array([]), nothing, nothing, xlabel="time since the step [s]")
    assert [t.get_text() for t in empty.texts] == ["no data for this covariate"]
    plt.close(fig)


def test_probability_heatmap_writes_every_finite_cell():
    fig, ax = plt.subplots()
    plots.probability_heatmap(ax, [[0.25, 0.75], [np.nan, 1.0]], ["r1", "r2"], ["c1", "c2"])
    assert sorted(t.get_text() for t in ax.texts) == ["0.25", "0.75", "1.00"]
    plt.close(fig)


def test_predictive_band_of_a_result_holds_its_observed_bins(result_dir):
    runs = predictive_runs(load_result(result_dir))
    assert {r["test"] for r in runs} == {"load_cycle"}
    for r in runs:
        assert r["time_s"].shape == r["observed"].shape == r["median"].shape
        # the band is the predictive of the bin means (noise included), so it holds most of the observed bins: a
        # 94 % band, read off a few draws and over correlated residuals, at least 80 % of them; a band of the
        # parameters alone (no noise) or of another run's bins would hold far fewer
        inside = (r["low"] <= r["observed"]) & (r["observed"] <= r["high"])
        assert inside.mean() >= 0.8, inside.mean()
        # the data scatter around the predictive median at about the noise (0.2 N per raw sample)
        assert np.sqrt(np.mean((r["observed"] - r["median"]) ** 2)) < 0.5
    # A misfit of sd 5 N on the load cycles, far above the band's own width: the band becomes that normal's 94 %,
    # 2 x 1.88 x 5 = 18.8 N wide, within the few percent its quantiles' sampling error allows; other tests are not
    # touched (none fitted here).
    for plain, wide in zip(runs, predictive_runs(load_result(result_dir), {"load_cycle": 5.0}), strict=True):
        width = np.median(wide["high"] - wide["low"])
        assert width == pytest.approx(np.hypot(18.8, np.median(plain["high"] - plain["low"])), rel=0.06), width
        assert wide["discrepancy_sd"] == 5.0 and plain["discrepancy_sd"] is None and "misfit" in wide["title"]


def test_ensemble_chains_pool_each_ensembles_walkers():
    import arviz as az

    from peano_bayes.report.figures import ensemble_chains

    values = np.arange(8 * 5, dtype=float).reshape(8, 5)  # 8 walkers (chains) x 5 draws
    idata = az.from_dict(posterior={"tensile_ka_n_per_m": values})
    idata.posterior.attrs["n_ensembles"] = 2
    draw, means, pooled = ensemble_chains(idata)
    np.testing.assert_array_equal(draw, np.arange(5))
    np.testing.assert_allclose(means["tensile_ka_n_per_m"], [values[:4].mean(0), values[4:].mean(0)])
    np.testing.assert_array_equal(pooled["tensile_ka_n_per_m"][1], values[4:].ravel())


def test_force_margins_draw_each_candidates_interval_and_say_which_are_infeasible():
    fig, ax = plt.subplots()
    plots.force_margins(ax, ["a", "b"], [0.2, -0.1], [0.1, -0.3], [0.5, 0.0], [0.9, np.nan])
    assert [t.get_text() for t in ax.texts] == ["P = 0.90", "infeasible"]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["a", "b"]
    points = [line for line in ax.get_lines() if line.get_marker() == "o"]
    np.testing.assert_allclose(sorted(np.concatenate([line.get_xdata() for line in points])), [-10.0, 20.0])
    assert UNIT.search(ax.get_xlabel())
    plt.close(fig)


def test_response_with_residuals_bands_a_loop_branch_by_branch_and_draws_what_it_is_given():
    strain = np.concatenate([np.linspace(0.0, 0.1, 6), np.linspace(0.1, 0.0, 6)[1:]])
    median = 10.0 - 20.0 * strain
    observed = median + np.linspace(-0.1, 0.1, strain.size)
    fig, (ax, res) = plt.subplots(2, 1)
    plots.response_with_residuals(
        ax, res, strain, observed, median - 1, median, median + 1, xlabel="strain [-]", ylabel="force [N]"
    )
    assert len(ax.collections) == 2 and len(res.collections) == 2  # loading and unloading branches
    (points,) = [line for line in res.get_lines() if line.get_marker() == "."]
    np.testing.assert_allclose(points.get_ydata(), observed - median)
    assert UNIT.search(res.get_xlabel()) and UNIT.search(ax.get_ylabel())
    plt.close(fig)


def test_response_runs_are_load_cycles_against_strain_at_each_pressure(result_dir):
    panels = response_runs(load_result(result_dir))
    assert [p["xlabel"] for p in panels] == ["strain [-]", "strain [-]"]
    assert [p["title"].splitlines()[0] for p in panels] == ["load cycle at 0 kPa", "load cycle at 30 kPa"]
    for p in panels:
        assert p["x"].shape == p["observed"].shape
        assert len(plots._monotone_pieces(p["x"])) == 2  # stretched, then released: one loop


def test_material_and_cross_material_figures_are_written(result_dir, tmp_path):
    written = material_figures(result_dir)
    names = sorted(p.name for p in written)
    assert names == [
        "corner.pdf", "corner.png", "predictive.pdf", "predictive.png", "rank.pdf", "rank.png",
        "response.pdf", "response.png", "trace.pdf", "trace.png",
    ]
    assert all(p.stat().st_size > 1000 for p in written)
    assert all(_is_picture(p) for p in written if p.suffix == ".png")
    assert not list((result_dir / "figures").glob(".*tmp"))  # nothing half-written left behind

    idata = load_result(result_dir)
    metrics = evaluate_result(result_dir, n_draws=8, progress=False)
    assert metrics["draws"] == 8 and all(len(v) == 8 for v in metrics["draw_values"].values())
    # Two "materials" from one result (the cross-material plumbing needs no second fit), with a known order: "P"
    # is TP with every criterion twice as good in every draw, so P is clearly best by each and TP never is.
    doubled = idata.copy()  # "P": every parameter draw twice TP's, so each material's own draws are told apart
    for name in doubled.posterior.data_vars:
        doubled.posterior[name] = 2.0 * doubled.posterior[name]
    results = {"TP": idata, "P": doubled}
    better = {c: np.asarray(metrics["draw_values"][c]) * 2.0 ** CRITERIA[c] for c in CRITERIA}
    per_material = {"TP": metrics, "P": {**metrics, "material": "P", "draw_values": better}}
    ranking = rank_materials({c: m["draw_values"] for c, m in per_material.items()})
    assert ranking["criteria"] and ranking["materials"] == ["TP", "P"]
    for criterion, r in ranking["criteria"].items():
        assert (r["verdict"], r["materials"]) == ("clearly best", ["P"]), criterion
        assert r["p_clearly_best"] == {"TP": 0.0, "P": 1.0} and r["rank_interval"] == {"TP": [2, 2], "P": [1, 1]}
    forest = forest_data(results)
    assert set(forest) == set(idata.posterior.data_vars) - {"noise_load_cycle_force_n"}
    for name, (codes, median, low, high, unit) in forest.items():
        assert codes == ["TP", "P"] and unit
        values = idata.posterior[name].values.ravel()
        assert median == [np.median(values), 2.0 * np.median(values)], name  # each one's own draws, in order
        for scale, lo, hi in zip((1.0, 2.0), low, high, strict=True):
            inside = np.mean((scale * values >= lo) & (scale * values <= hi))
            assert 0.93 <= inside <= 0.95, (name, inside)  # a 94 % interval of those draws
    assert "hysteresis_loss" in published_data(per_material)
    out = cross_material_figures(tmp_path, results, per_material, ranking)
    assert sorted(p.name for p in out) == sorted(
        f"{stem}.{ext}" for stem in ("forest", "published", "ranking") for ext in ("png", "pdf")
    )
    assert all(_is_picture(p) for p in out if p.suffix == ".png")


def test_parameter_labels_are_short_wrapped_descriptions_not_names():
    from peano_bayes.physics import PARAMETERS

    labels = {name: parameter_label(name) for name in PARAMETERS}
    assert len(set(labels.values())) == len(labels)  # every parameter told apart
    for name, label in labels.items():
        assert label != name and all(len(line) <= 30 for line in label.splitlines()), label
    assert parameter_label("bending_k1_n") == "Bending stiffness, constant\npart"
    assert parameter_label("parallel_maxwell2_tau_s") == "Maxwell branch relaxation\ntime, no. 2"
    assert parameter_label("noise_stroke_strain") == "noise_stroke_strain"  # not a model parameter: its name


@pytest.mark.parametrize("builder", [forest_data, published_data])
def test_builders_of_nothing_give_nothing(builder):
    assert builder({}) == {}


@pytest.mark.slow
def test_step_band_spreads_with_the_prior_only_parameters_and_draws_a_figure(result_dir, tmp_path):
    from peano_bayes.report.figures import step_band
    from peano_bayes.rig import simulate_dataset

    from .helpers import recovery_truth

    dataset = simulate_dataset("TP", recovery_truth(), seed=3, specimens=1, repeats=1, tests=("step",))
    band = step_band(load_result(result_dir), dataset, n_draws=6)
    assert band["n_draws"] == 6 and band["time_s"].shape == band["observed"].shape == band["median"].shape
    # The step-only parameters (inlet, damping) were not fitted: drawn from the prior, and said so; their spread
    # widens the band after the step.
    assert np.max(band["high"] - band["low"]) > 1e-3
    assert "orifice_area_m2" in band["prior_only"]
    # The muscle contracts after the step, in the data and in the model.
    assert band["observed"][-20:].mean() > band["observed"][:5].mean() + 0.01
    assert band["median"][-20:].mean() > band["median"][:5].mean() + 0.01
    assert step_band(load_result(result_dir), dataclasses.replace(dataset, runs=())) is None


def test_corner_plot_takes_population_values_not_specimen_levels():
    """A two-specimen result holds specimen__ and new_specimen__ variables beside the population values; the
    corner plot shows the population values only (with them a 7-parameter fit asked arviz for 14 panels and
    the plot failed)."""
    import arviz as az

    from peano_bayes.report.figures import physical_names

    draws = np.zeros((2, 5))
    idata = az.from_dict(
        posterior={
            "tensile_ka_n_per_m": draws,
            "specimen__tensile_ka_n_per_m": np.zeros((2, 5, 2)),
            "new_specimen__tensile_ka_n_per_m": draws,
            "specimen_log_sd": draws,
            "specimen_contrast_tensile_ka_n_per_m_1": draws,
            "noise_load_cycle_force_n": draws,
        }
    )
    assert physical_names(idata) == ["tensile_ka_n_per_m"]
