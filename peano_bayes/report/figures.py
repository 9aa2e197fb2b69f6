"""Figures of results: prepare the data (quantiles, intervals) from results, draw with :mod:`peano_bayes.report.plots`,
save PNG and PDF atomically.

Per material (``OUT/<code>/figures/``): ``predictive`` (data over the 94 % posterior predictive band, one run
per condition of each fitted test, against time), ``response`` (the same runs against their driving input:
force-strain loops per pressure, blocking force and stroke against pressure, each over a residual panel),
``corner`` (pairs of the physical parameters, arviz), ``trace`` and ``rank`` (per ensemble,
:func:`diagnostic_figures`). Across materials (``OUT/figures/``): ``forest`` (each physical parameter's
posterior per material), ``published`` (posterior metrics against the paper's values) and ``ranking`` (P(best)
per criterion).
"""

from __future__ import annotations

import dataclasses
import json
import re
import textwrap
from pathlib import Path

import arviz as az
import equinox as eqx
import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np

from ..analysis.metrics import METRIC_UNITS
from ..atomic import replacing
from ..inference.likelihood import predict
from ..inference.reduce import NOISE_PARAMETERS, prepare
from ..physics import PARAMETERS
from . import plots

QUANTILES = (0.03, 0.5, 0.97)
SIGNAL_LABEL = {"load_cycle": "force [N]", "blocking": "force [N]", "stroke": "strain [-]", "step": "strain [-]"}
TEST_TITLE = {"load_cycle": "load cycle", "blocking": "blocking", "stroke": "stroke", "step": "step response"}


def save(fig, path_stem: Path) -> list[Path]:
    """Write ``fig`` as ``<stem>.png`` and ``<stem>.pdf``, each atomically; close it; return the paths."""
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for ext in ("png", "pdf"):
        final = path_stem.with_suffix(f".{ext}")
        with replacing(final) as tmp:
            fig.savefig(tmp, format=ext, bbox_inches="tight")
        written.append(final)
    plt.close(fig)
    return written


def parameter_label(name: str, width: int = 30) -> str:
    """A figure title for a model parameter: its meaning from :data:`~peano_bayes.physics.PARAMETERS` without
    parenthesized formulas, with the branch number of a numbered element, wrapped at ``width`` characters; the
    name itself where none is registered (noise scales, spreads)."""
    parameter = PARAMETERS.get(name)
    if parameter is None:
        return name
    text = re.sub(r"\s*\([^)]*\)", "", parameter.meaning).strip()
    branch = re.search(r"(maxwell|kelvin)(\d+)_", name)
    if branch:
        text += f", no. {branch.group(2)}"
    return textwrap.fill(text[:1].upper() + text[1:], width)


def physical_names(idata) -> list[str]:
    """The sampled physical parameters of a result, population values (no noise scales, no specimen terms, no
    specimen-level or new-specimen variables)."""
    return [
        n
        for n in idata.posterior.data_vars
        if n not in NOISE_PARAMETERS and not n.startswith(("specimen_", "new_specimen_"))
    ]


def predictive_runs(idata, discrepancy: dict | None = None) -> list[dict]:
    """Per fitted test, one run per distinct condition (the first specimen's first run, and for load cycles
    also the first run at the test pressure): ``test``, ``title``, ``time_s``, ``observed``, ``low``,
    ``median``, ``high`` (94 % predictive quantiles of the bin means, posterior_predictive group) and
    ``discrepancy_sd``. ``discrepancy``: test -> sd of its model misfit beyond the noise [signal unit]
    (:func:`~peano_bayes.analysis.metrics.misfit_discrepancy`); a test that has one gets a normal value of that
    sd added to every predictive draw of every bin (seeded), so its band holds the data the model misfits as
    the metrics' intervals do."""
    obs = idata.observed_data
    tests, specimens, runs = (np.asarray(obs[k].values) for k in ("test", "specimen", "run"))
    time_s, y = np.asarray(obs["time_s"].values), np.asarray(obs["y"].values)
    yrep = idata.posterior_predictive["y"].stack(sample=("chain", "draw")).transpose("sample", "bin").values
    out = []
    first = specimens[0]
    rng = np.random.default_rng(0)
    for test in dict.fromkeys(tests):
        sd = (discrepancy or {}).get(str(test))
        candidates = sorted({int(r) for r in runs[(tests == test) & (specimens == first)]})
        chosen = candidates[:1]
        if test == "load_cycle" and len(candidates) > 1:
            chosen.append(candidates[len(candidates) // 2])  # the paper's protocol: first half at 0 kPa
        for run in chosen:
            mask = (tests == test) & (specimens == first) & (runs == run)
            sample = yrep[:, mask]
            if sd:
                sample = sample + sd * rng.standard_normal(sample.shape)
            low, median, high = np.quantile(sample, QUANTILES, axis=0)
            out.append(
                dict(
                    test=test,
                    specimen=first,
                    run=run,
                    title=f"{TEST_TITLE.get(test, test)}: specimen {first}, run {run}" + _misfit_note(sd),
                    time_s=time_s[mask],
                    observed=y[mask],
                    low=low,
                    median=median,
                    high=high,
                    discrepancy_sd=sd,
                )
            )
    return out


def _misfit_note(sd: float | None) -> str:
    """The line a panel's title gets when its band carries a model misfit of ``sd``, else nothing."""
    return f"\n(+ model misfit, sd {sd:.3g})" if sd else ""


#: Per test: the driving input a figure plots against (observed_data variable, scale, axis label).
RESPONSE_AXIS = {
    "load_cycle": ("strain", 1.0, "strain [-]"),
    "blocking": ("pressure_pa", 1e-3, "pressure [kPa]"),
    "stroke": ("pressure_pa", 1e-3, "pressure [kPa]"),
}


def response_runs(idata, discrepancy: dict | None = None) -> list[dict]:
    """The runs of :func:`predictive_runs` of the quasi-static tests against their driving input, as engineers
    read them: load cycles as force against strain (one per pressure), blocking force and stroke against
    pressure. Each panel adds ``x`` and ``xlabel``; the title names the condition. Empty for results written
    before the inputs were stored (no ``strain`` in ``observed_data``)."""
    obs = idata.observed_data
    if "strain" not in obs:
        return []
    tests, specimens, runs = (np.asarray(obs[k].values) for k in ("test", "specimen", "run"))
    out = []
    for panel in predictive_runs(idata, discrepancy):
        if panel["test"] not in RESPONSE_AXIS:
            continue
        name, scale, xlabel = RESPONSE_AXIS[panel["test"]]
        specimen, run = panel["specimen"], panel["run"]
        mask = (tests == panel["test"]) & (specimens == specimen) & (runs == run)
        x = np.asarray(obs[name].values)[mask] * scale
        if panel["test"] == "load_cycle":
            pressure_kpa = float(np.median(np.asarray(obs["pressure_pa"].values)[mask])) / 1e3
            condition = f"load cycle at {round(pressure_kpa):d} kPa"
        else:
            condition = TEST_TITLE.get(panel["test"], panel["test"])
        title = f"{condition}\nspecimen {specimen}, run {run}" + _misfit_note(panel["discrepancy_sd"])
        out.append({**panel, "x": x, "xlabel": xlabel, "title": title})
    return out


@eqx.filter_jit
def _step_strain(stack: dict, group, config, geometry):
    return jax.vmap(lambda p: predict(p, group, config=config, geometry=geometry)[0])(stack)


def step_band(idata, dataset, n_draws: int = 40) -> dict | None:
    """The first step run of ``dataset`` (a :class:`~peano_bayes.data.Dataset`) against the model's strain
    over ``n_draws`` posterior draws: ``time_s``, ``observed``, ``low``, ``median``, ``high`` (94 % of the
    draws, noise-free), ``title`` and ``prior_only`` (parameters drawn from the prior because the fit had no
    step test). ``None`` when the dataset has no step run."""
    from ..inference.results import parameter_draws, result_config

    runs = [r for r in dataset.runs if r.test == "step"]
    if not runs:
        return None
    run = runs[0]
    observations = prepare(dataclasses.replace(dataset, runs=(run,)))
    group = observations.groups[0]
    sets, prior_only = parameter_draws(idata, n_draws)
    stack = {k: jnp.asarray([s[k] for s in sets]) for k in sets[0]}
    strain = np.asarray(_step_strain(stack, group, result_config(idata), observations.geometry))[:, 0, :]
    finite = np.all(np.isfinite(strain), axis=1)
    low, median, high = np.quantile(strain[finite], QUANTILES, axis=0)
    return dict(
        time_s=np.asarray(group.bin_time_s[0]),
        observed=np.asarray(group.observed[0]),
        low=low,
        median=median,
        high=high,
        title=f"step response: specimen {run.specimen}, run {run.run}",
        prior_only=prior_only,
        n_draws=int(finite.sum()),
    )


def material_figures(result_dir: str | Path, dataset=None) -> list[Path]:
    """``predictive`` and ``corner`` figures of one result directory into its ``figures/``; given its
    ``dataset`` with a step run, also ``step`` (:func:`step_band`)."""
    from ..inference.results import load_result

    result_dir = Path(result_dir)
    idata = load_result(result_dir)
    code = idata.posterior.attrs["material"]
    written = []
    band = step_band(idata, dataset) if dataset is not None else None
    if band is not None:
        with plt.rc_context(plots.STYLE):
            fig, ax = plt.subplots(figsize=(5.0, 3.0))
            source = "posterior"
            if band["prior_only"]:
                source += "; inlet and damping from the prior (no step fit)"
            plots.predictive_band(
                ax,
                band["time_s"],
                band["observed"],
                band["low"],
                band["median"],
                band["high"],
                ylabel="strain [-]",
                title=f"{code}: {band['title']}\nmodel: {source}",
                label_band=f"94 % of {band['n_draws']} model draws",
                label_median="model median",
            )
            ax.legend(loc="lower right", frameon=False)
            written += save(fig, result_dir / "figures" / "step")
    from ..analysis.metrics import result_discrepancy

    discrepancy = result_discrepancy(result_dir)
    panels = predictive_runs(idata, discrepancy)
    with plt.rc_context(plots.STYLE):
        fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 2.8), squeeze=False)
        for ax, p in zip(axes[0], panels, strict=True):
            plots.predictive_band(
                ax,
                p["time_s"],
                p["observed"],
                p["low"],
                p["median"],
                p["high"],
                ylabel=SIGNAL_LABEL.get(p["test"], "signal"),
                title=p["title"],
            )
        handles, labels = axes[0][0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=3, bbox_to_anchor=(0.5, -0.16), frameon=False)
        fig.suptitle(f"{code}: bin means of the data over the posterior predictive", y=1.02)
        written += save(fig, result_dir / "figures" / "predictive")
        responses = response_runs(idata, discrepancy)
        if responses:
            fig, axes = plt.subplots(
                2, len(responses), figsize=(3.4 * len(responses), 4.4), squeeze=False,
                gridspec_kw={"height_ratios": (2.4, 1.0)}, sharex="col", layout="constrained",
            )
            for top, bottom, p in zip(axes[0], axes[1], responses, strict=True):
                plots.response_with_residuals(
                    top, bottom, p["x"], p["observed"], p["low"], p["median"], p["high"],
                    xlabel=p["xlabel"], ylabel=SIGNAL_LABEL[p["test"]], title=p["title"],
                )
            handles, labels = axes[0][0].get_legend_handles_labels()
            fig.legend(handles, labels, loc="outside lower center", ncol=3, frameon=False)
            fig.suptitle(f"{code}: responses against their driving input, 94 % posterior predictive")
            written += save(fig, result_dir / "figures" / "response")
        names = physical_names(idata)
        axes = az.plot_pair(
            idata,
            var_names=names,
            kind="scatter",
            marginals=True,
            scatter_kwargs={"alpha": 0.15, "s": 1.5},
            textsize=9,
            figsize=(max(2.2 * len(names), 5.0),) * 2,
        )
        for ax in np.ravel(axes):
            ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(3))
            ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
            for axis in (ax.xaxis, ax.yaxis):  # "%.3g" labels: no "1e6" multiplier text over the axis label
                axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:.3g}"))
            ax.tick_params(axis="x", labelrotation=35)  # long labels ("2.2e+06") of neighbours would overlap
            ax.xaxis.label.set_fontsize(8)
            ax.yaxis.label.set_fontsize(8)
        for i in range(min(len(names), len(axes))):  # diagonal panels are marginal densities, not the row's y
            axes[i][i].set_ylabel("")
            axes[i][i].tick_params(axis="y", labelleft=False)
        fig = np.ravel(axes)[0].figure
        fig.subplots_adjust(top=0.96)  # arviz leaves matplotlib's default 12 % blank above the grid
        fig.suptitle(f"{code}: posterior of the physical parameters (SI units)", y=0.985)
        written += save(fig, result_dir / "figures" / "corner")
    written += diagnostic_figures(idata, result_dir / "figures", code)
    return written


def ensemble_chains(idata) -> tuple[np.ndarray, dict, dict]:
    """The population parameters of a result by **ensemble** (each ensemble's walkers pooled: the unit its
    R-hat compares), for trace and rank plots: ``(draw (k,), means, pooled)``, ``means`` name ->
    (n_ensembles, k) each ensemble's walker mean at each kept draw, ``pooled`` name -> (n_ensembles, walkers
    k) every walker's draws per ensemble. Results written before ``n_ensembles`` was recorded are taken as four
    ensembles when their walkers divide into four, else one."""
    post = idata.posterior
    chains = post.sizes["chain"]
    n = int(post.attrs.get("n_ensembles", 4 if chains % 4 == 0 else 1))
    means, pooled = {}, {}
    for name in physical_names(idata):
        by_ensemble = np.asarray(post[name].transpose("chain", "draw").values).reshape(n, chains // n, -1)
        means[name] = by_ensemble.mean(axis=1)
        pooled[name] = by_ensemble.reshape(n, -1)
    return np.asarray(post["draw"].values), means, pooled


def diagnostic_figures(idata, out_dir: Path, code: str) -> list[Path]:
    """``trace`` (each ensemble's walker mean against the step) and ``rank`` (arviz rank histograms of every
    walker's draws, one series per ensemble: flat when the ensembles agree) of the population parameters."""
    draw, means, pooled = ensemble_chains(idata)
    units = _units(idata)
    written = []
    with plt.rc_context(plots.STYLE):
        fig, axes = plt.subplots(len(means), 1, figsize=(7.0, 1.25 * len(means) + 0.8), sharex=True, squeeze=False)
        plots.ensemble_traces(axes[:, 0], draw, means, units)
        axes[0, 0].legend(loc="upper right", ncol=len(next(iter(means.values()))), frameon=False, fontsize=7)
        fig.suptitle(f"{code}: each ensemble's walker mean against the step", y=1.0)
        fig.tight_layout()
        written += save(fig, out_dir / "trace")
        cols = min(4, len(pooled))
        rows = -(-len(pooled) // cols)
        axes = az.plot_rank(
            az.from_dict(posterior=pooled), var_names=list(pooled), grid=(rows, cols), figsize=(3.0 * cols, 2.4 * rows)
        )
        for ax in np.ravel(axes):
            ax.set_ylabel("ensemble")
        fig = np.ravel(axes)[0].figure
        fig.suptitle(f"{code}: rank plots, one series per ensemble (flat = the ensembles agree)", y=1.0)
        fig.tight_layout()
        written += save(fig, out_dir / "rank")
    return written


def _units(idata) -> dict:
    return json.loads(idata.posterior.attrs.get("units", "{}"))


def forest_data(results: dict) -> dict:
    """parameter -> (materials, median, low, high, unit) over ``results`` (code -> InferenceData), 94 % HDI."""
    out = {}
    for code, idata in results.items():
        units = _units(idata)
        for name in physical_names(idata):
            values = idata.posterior[name].values.ravel()
            low, high = az.hdi(values, hdi_prob=0.94)
            entry = out.setdefault(name, ([], [], [], [], units.get(name, "")))
            for lst, v in zip(entry[:4], (code, float(np.median(values)), float(low), float(high)), strict=True):
                lst.append(v)
    return out


def published_data(metrics: dict) -> dict:
    """metric -> (materials, median, low, high, published) for metrics with a published value in any
    material; ``metrics``: code -> the ``metrics.json`` of :func:`peano_bayes.analysis.metrics.evaluate_result`."""
    out = {}
    for code, m in metrics.items():
        published = {row["metric"]: row["value"] for row in m["published"]}
        for name, s in m["summary"].items():
            if name not in published:
                continue
            entry = out.setdefault(name, ([], [], [], [], []))
            for lst, v in zip(entry, (code, s["median"], s["hdi_low"], s["hdi_high"], published[name]), strict=True):
                lst.append(v)
    return out


def _grid(n: int, width: float = 3.0, height: float = 2.3):
    cols = min(n, 4)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()[:n]


def cross_material_figures(out_dir: str | Path, results: dict, metrics: dict, ranking: dict | None) -> list[Path]:
    """``forest``, ``published`` and ``ranking`` figures into ``out_dir/figures``; ``results``: code ->
    InferenceData; ``metrics``: code -> metrics.json content; ``ranking``: the output of
    :func:`~peano_bayes.analysis.ranking.rank_materials`."""
    out_dir = Path(out_dir)
    written = []
    with plt.rc_context(plots.STYLE):
        forest = forest_data(results)
        if forest:
            fig, axes = _grid(len(forest), height=2.8)  # two-line titles
            for ax, (name, (codes, med, low, high, unit)) in zip(axes, forest.items(), strict=True):
                wide = min(low) > 0 and max(high) > 10 * min(low)  # a log axis only where it spans a decade
                title = parameter_label(name)
                plots.forest(ax, codes, med, low, high, xlabel=f"{name} [{unit}]", log=wide, title=title)
            fig.suptitle("Posterior median and 94 % HDI of each physical parameter", y=1.01)
            fig.tight_layout()
            written += save(fig, out_dir / "figures" / "forest")
        published = published_data(metrics)
        if published:
            fig, axes = _grid(len(published))
            for ax, (name, (codes, med, low, high, pub)) in zip(axes, published.items(), strict=True):
                prior_only = any(metrics[c]["summary"][name].get("from_prior") for c in codes)
                title = name + (" (prior only)" if prior_only else "")
                plots.published_versus_posterior(
                    ax, codes, med, low, high, pub, xlabel=f"[{METRIC_UNITS[name]}]", title=title
                )
            axes[0].legend(loc="best")
            fig.suptitle("Posterior predictive metrics (94 % HDI) against the published values (x)", y=1.01)
            fig.tight_layout()
            written += save(fig, out_dir / "figures" / "published")
        if ranking and ranking["criteria"]:
            codes = ranking["materials"]
            criteria = list(ranking["criteria"])
            matrix = [[ranking["criteria"][c]["p_best"][m] for m in codes] for c in criteria]
            fig, ax = plt.subplots(figsize=(1.0 * len(codes) + 3.0, 0.45 * len(criteria) + 1.2))
            rows = [c + (" (prior only)" if ranking["criteria"][c].get("from_prior") else "") for c in criteria]
            plots.probability_heatmap(
                ax, matrix, rows, codes, title=f"P(best within {100 * ranking['margin']:g} %) per criterion",
                colorbar_label="P(best) [-]",
            )
            written += save(fig, out_dir / "figures" / "ranking")
    return written


def recommendation_figure(report: dict, path_stem: Path, top: int = 12) -> list[Path]:
    """The ``top`` candidates of a :func:`~peano_bayes.analysis.recommend.recommend` report: each one's operating-force
    margin over the requirement with its 94 % interval, and its probability of meeting every requirement."""
    shown = report["candidates"][:top]
    labels = [
        f"{c['material']} {c['n_tubes']}x {c['tube_width_mm']:g}x{c['tube_length_mm']:g} mm ({c['binding']})"
        for c in shown
    ]
    intervals = [c.get("force_margin_interval") or [np.nan, np.nan] for c in shown]
    with plt.rc_context(plots.STYLE):
        fig, ax = plt.subplots(figsize=(7.0, 0.32 * len(shown) + 1.3))
        plots.force_margins(
            ax,
            labels,
            [c["margin"]["force"] if "force" in c.get("margin", {}) else np.nan for c in shown],
            [lo for lo, _ in intervals],
            [hi for _, hi in intervals],
            [np.nan if c.get("infeasible") else c["probability"] for c in shown],
            title="Candidates: force margin of a new specimen (binding requirement in brackets)",
        )
        return save(fig, Path(path_stem))


__all__ = [
    "cross_material_figures",
    "forest_data",
    "parameter_label",
    "material_figures",
    "predictive_runs",
    "published_data",
    "recommendation_figure",
    "save",
]
