"""The results index (``index.md``): one section per fitted material, from its ``summary.json``, with the
sampled model beside what discovery named, the convergence and timings, and links to the figures."""

from __future__ import annotations

import math
from pathlib import Path

from ..formatting import format_number
from ..inference.fit import structured_tests
from ..inference.posterior import DEFAULT_HELD, STEP_ONLY_PARAMETERS
from ..inference.results import (
    RIDGE_CORRELATION,
)

#: Where in a result folder ``fit --discover`` and ``run`` write the discovery report.
DISCOVERY_FOLDER = "discovery"

#: Posterior contraction below which ``index.md`` says a parameter's posterior is close to its prior.
WEAKLY_INFORMED = 0.5


def prior_conflict_lines(conflicts: list, positions: dict) -> list[str]:
    """``index.md`` lines naming the parameters whose posterior median lies far in a tail of its prior
    (``summary.json``'s ``prior_conflicts``, positions in prior sd from ``prior_z``); none if there are none."""
    if not conflicts:
        return []
    named = ", ".join(f"{n} ({positions[n]:+.1f} prior sd)" if n in positions else n for n in conflicts)
    return [
        "",
        f"**Prior and data disagree**: the posterior median lies far in a tail of the prior (or against a bound "
        f"of its support) for {named}. Along "
        "any direction the fitted tests leave open (a ridge) the interval follows the prior, so it may not hold "
        "the value 94 % of the time; check that prior's entry and its provenance.",
    ]


def held_lines(fixed: dict, tests=()) -> list[str]:
    """``index.md`` lines naming the model parameters a fit held instead of sampling (``summary.json``'s
    ``fixed``, SI units as in their names), but for the step-only parameters of a fit without the step test
    (``tests``: the fitted tests), which the step metrics draw from the prior: every interval of the result is
    conditional on these values. The shape constants of :data:`~peano_bayes.inference.posterior.DEFAULT_HELD`
    are held at nominal with ``--no-sample-all``; where a muscle's differ, intervals that hold them can sit far
    from the truth."""
    fixed = {k: v for k, v in fixed.items() if "step" in tests or k not in STEP_ONLY_PARAMETERS}
    if not fixed:
        return []
    values = ", ".join(f"{name} = {format_number(value)}" for name, value in fixed.items())
    line = f"**Held, not sampled** (every interval here is conditional on these values): {values}."
    shape = [name for name in DEFAULT_HELD if name in fixed]
    if shape:
        line += (
            f" The shape constants ({', '.join(shape)}) were held at nominal (`--no-sample-all`): on a muscle "
            "whose constants differ, intervals that hold them can sit far from the truth; the default, "
            "`--sample-all`, samples them, for about 1.6-2 times the time (docs/validation.md, recovery with "
            "the constants sampled)."
        )
    return ["", line]


def ridge_lines(ridges: list[dict]) -> list[str]:
    """``index.md`` lines naming each ridge of :func:`~peano_bayes.inference.results.posterior_ridges`: the
    pair, its correlation, and the combination the data determine against each parameter alone."""
    if not ridges:
        return []
    lines = [
        "",
        f"**Ridges** (posterior correlation beyond {RIDGE_CORRELATION:g}): the tests determine a combination of "
        "each pair better than either alone; read their intervals together.",
        "",
    ]
    for r in ridges:
        spread = lambda sd, log: f"±{100 * sd:.2g} %" if log else f"±{sd:.2g}"  # noqa: E731
        if r["log_a"] and r["log_b"]:
            combination = f"{r['a']} × {r['b']}^{r['exponent']:.2f}"
        else:  # a signed parameter: the combination in the sampler's scale (logs of the positive ones)
            combination = f"{r['a']} {'+' if r['exponent'] >= 0 else '-'} {abs(r['exponent']):.2f} {r['b']}"
        lines.append(
            f"- {r['a']} and {r['b']}: correlation {r['correlation']:+.2f}; {combination} is determined to "
            f"{spread(r['sd_combination'], r['log_a'] and r['log_b'])} (1 sd), each alone to "
            f"{spread(r['sd_a'], r['log_a'])} and {spread(r['sd_b'], r['log_b'])}."
        )
    return lines


def model_table(summaries: list[dict]) -> list[str]:
    """Markdown lines: per material, the effects of the sampled model beside what discovery named (a fit
    without discovery says so), and what discovery left unexplained."""
    lines = [
        "## Models sampled",
        "",
        "| material | effects sampled | discovery verdict | discovery named | added by discovery | not in the "
        "inference model |",
        "|---|---|---|---|---|---|",
    ]
    notes = []
    for s in summaries:
        model = s.get("model")
        if model is None:  # a summary written before the model was recorded
            lines.append(f"| {s['material']} | (not recorded) | | | | |")
            continue
        found = model["discovery"]
        sampled = ", ".join(model["effects"])
        if found is None:
            lines.append(f"| {s['material']} | {sampled} | not run (the configured model) | | | |")
            continue
        lines.append(
            f"| {s['material']} | {sampled} | {found['verdict']} | {', '.join(found['named']) or 'none'} | "
            f"{', '.join(found['adopted']) or 'nothing'} | {', '.join(found['not_in_model'])} |"
        )
        if found["unexplained"]:
            report = Path(found["report"] or DISCOVERY_FOLDER)
            if not report.is_absolute():  # relative to the result folder, which index.md names by its label
                report = Path(s.get("label", s["material"])) / report
            notes.append(
                f"**{s['material']}**: discovery left structure it could not name; see its report "
                f"(`{report.as_posix()}/report.md`). The sampled model does not explain all of the data."
            )
    return [*lines, "", *(f"{n}\n" for n in notes)]


def shown_dataset_path(path: str) -> str:
    """A dataset path as a reader of ``index.md`` can use it: a bundled file by its place in the package
    (``peano_bayes/bundled/data/TP.csv``), not the absolute path of the machine that ran the job, also when
    the job ran from another copy of the package (a clone elsewhere, an installed wheel)."""
    parts = Path(path).parts
    for i in range(len(parts) - 3, -1, -1):
        if parts[i : i + 3] == ("peano_bayes", "bundled", "data"):
            return str(Path(*parts[i:]))
    return path


#: A material's figures that ``index.md`` links where they exist, in order: file stem -> what it shows.
MATERIAL_FIGURES = {
    "predictive": "data over the predictive band",
    "response": "force-strain loops per pressure, blocking force and stroke against pressure, with residuals",
    "step": "step response against the model",
    "corner": "corner plot",
    "trace": "trace plot per ensemble",
    "rank": "rank plot per ensemble",
}


def _finite(x) -> bool:
    return x is not None and math.isfinite(x)


def _with_unit(x, unit: str) -> str:
    """``x`` to three significant digits with its unit; empty where ``x`` is missing or not finite."""
    return f"{format_number(x)} {unit}" if _finite(x) else ""


def _sampler_run(summary: dict) -> str:
    """`` (W warm-up, tau_max T steps, first D discarded)`` for one material's index line: the sampler's warm-up,
    the largest integrated autocorrelation time (so a reader sees how hard the posterior was to sample) and the
    burn-in D counted from the chain's first step (the warm-up and a further ``2 tau_max``); parts a summary
    written before they were recorded lacks are left out."""
    conv = summary["convergence"]
    parts = []
    if summary.get("warmup") is not None:
        parts.append(f"{summary['warmup']} warm-up")
    taus = [t for t in conv.get("tau_steps", {}).values() if _finite(t)]
    if taus:
        parts.append(f"tau_max {max(taus):.1f} steps")
    if conv.get("discard_steps") is not None:
        parts.append(f"first {conv['discard_steps']} discarded")
    return f" ({', '.join(parts)})" if parts else ""


def index_markdown(
    summaries: list[dict],
    metrics: dict | None = None,
    ranking: dict | None = None,
    references: dict | None = None,
    figures: dict | None = None,
) -> str:
    """``results/index.md``: per material, a parameter table with 94 % intervals, fit quality, convergence,
    (given ``references``: code -> reference_models.json) the load-cycle fit against the paper's reference
    models, and (given ``metrics``: code -> metrics.json) the Table 3 metrics against the paper with links to
    the figures (``figures``: code -> names of :data:`MATERIAL_FIGURES` that exist; default: predictive and
    corner); then (given ``ranking``, :func:`~peano_bayes.analysis.ranking.rank_materials`) the cross-material
    ranking."""
    from ..analysis.metrics import metrics_markdown
    from ..analysis.ranking import ranking_markdown

    metrics = metrics or {}
    lines = ["# peano_bayes results", "", "Posterior means with 94 % highest-density intervals (SI units).", ""]
    lines += model_table(summaries)
    for s in summaries:
        conv = s["convergence"]
        verdict = "converged" if conv["converged"] else "**NOT CONVERGED**: " + "; ".join(conv["problems"])
        lines += [
            f"## {s['material']}",
            "",
            f"Data: `{shown_dataset_path(s['dataset'])}` ({', '.join(s['tests'])}); "
            f"{s.get('n_ensembles', 1)} ensembles of {s['n_walkers']} walkers x {s['steps']} steps"
            f"{_sampler_run(s)}; {verdict}. Max R-hat {max(conv['rhat'].values()):.3f}, "
            f"min bulk ESS {min(conv['ess_bulk'].values()):.0f}, "
            f"chain {conv['tau_lengths']:.0f} autocorrelation times long.",
            "",
            "Population values (the material), a new specimen's value (what one more muscle made of it would "
            "have: the population plus the between-specimen spread), and the posterior contraction "
            "(1 - posterior variance / prior variance, in the sampler's unconstrained space: near 0 means the data "
            "said little and the interval is the prior's).",
            "",
            "| parameter | unit | population mean | population 94 % | new specimen 94 % | contraction | R-hat | "
            "bulk ESS |",
            "|---|---|---|---|---|---|---|---|",
        ]

        def interval(row):
            low, high = (format_number(row[k], nonfinite=None) for k in ("hdi_low", "hdi_high"))
            return f"{low} to {high}"

        weak = []
        for name, row in s["parameters"].items():
            new = s.get("new_specimen", {}).get(name)
            contraction = s.get("contraction", {}).get(name)
            if contraction is not None and contraction < WEAKLY_INFORMED:
                weak.append(name)
            lines.append(
                f"| {name} | {s['units'].get(name, '')} | {format_number(row['mean'], nonfinite=None)} | "
                f"{interval(row)} | {interval(new) if new else ''} | "
                f"{'' if contraction is None else f'{contraction:.2f}'} | "
                f"{conv['rhat'][name]:.3f} | {conv['ess_bulk'][name]:.0f} |"
            )
        if weak:
            lines += [
                "",
                f"**Posterior close to its prior** (contraction below {WEAKLY_INFORMED:g}): {', '.join(weak)}. "
                "The fitted tests say little about these; their intervals are mostly the prior's.",
            ]
        lines += prior_conflict_lines(s.get("prior_conflicts", []), s.get("prior_z", {}))
        lines += ridge_lines(s.get("ridges", []))
        lines += held_lines(s.get("fixed", {}), s["tests"])
        correlation = s.get("residual_correlation", {})
        lines += [
            "",
            "| test | RMSE | max error | R² | RMSE beyond the sensor noise | residual lag-1 correlation |",
            "|---|---|---|---|---|---|",
        ]
        for test, q in s["fit_quality_posterior_mean"].items():
            c = correlation.get(test)
            lag = "" if c is None or c["lag1"] is None else f"{c['lag1']:.2f}"
            used = None if c is None else c.get("likelihood_lag1")
            if c is not None and not c["consistent_with_noise"]:
                lag += " (structured)" if used is None else f" (structured; sampled as AR(1), lag-1 {used:.2f})"
            elif used is not None:
                lag += f" (sampled as AR(1), lag-1 {used:.2f}: structured at the mode)"
            lines.append(
                f"| {test} | {format_number(q['rmse'], nonfinite=None)} {q['unit']} | "
                f"{format_number(q['max_error'], nonfinite=None)} {q['unit']} | {q['r2']:.4f} | "
                f"{_with_unit(q.get('excess_rmse'), q['unit'])} | {lag} |"
            )
        adopted = [t for t, c in correlation.items() if c.get("likelihood_lag1") is not None]
        structured = structured_tests(correlation)
        unadopted = [t for t in structured if t not in adopted]
        if structured:
            lines += [
                "",
                f"**Misfit with structure** in {', '.join(structured)}: the whitened residuals are correlated "
                "from bin to bin, so the model misses something these data show. "
                + (
                    f"The likelihood took the residuals of {', '.join(adopted)} as AR(1) from bin to bin, with "
                    "the correlation found at the posterior mode, so neighbouring bins do not count as independent "
                    "evidence; the values are those of the closest model in the family, not of a model that "
                    "explains the data. "
                    if adopted
                    else ""
                )
                + (
                    f"The intervals that {', '.join(unadopted)} inform are narrower than the data justify "
                    "(`residual_correlation` in `summary.json` gives a rough factor, as for AR(1) residuals). "
                    if unadopted
                    else ""
                )
                + (
                    "A quantity read off one of these tests can be off the model's prediction by roughly that "
                    "test's RMSE beyond the sensor noise: the parameter intervals above do not include it; the "
                    "Table 3 metrics below do where a metric is read off such a test (their *model misfit* "
                    "column; *Model discrepancy* in the project's docs/inference.md). "
                    if any(_finite(s["fit_quality_posterior_mean"].get(t, {}).get("excess_rmse")) for t in structured)
                    else ""
                )
                + "Try `--discover`.",
            ]
        reference = (references or {}).get(s["material"])
        ours = s["fit_quality_posterior_mean"].get("load_cycle")
        if reference and ours:
            lines += [
                "",
                "Load cycles against the paper's reference models fitted to the same bins "
                "(`inference/reference_fit.py`):",
                "",
                "| model | RMSE | max error | R² |",
                "|---|---|---|---|",
                f"| peano_bayes (posterior mean) | {format_number(ours['rmse'], nonfinite=None)} N | "
                f"{format_number(ours['max_error'], nonfinite=None)} N | {ours['r2']:.4f} |",
            ]
            for name, label in (("sarosi", "Sarosi static, 12 coefficients"), ("veale", "Veale force balance")):
                q = reference[name]["quality"]
                lines.append(
                    f"| {label} | {format_number(q['rmse'], nonfinite=None)} N | "
                    f"{format_number(q['max_error'], nonfinite=None)} N | {q['r2']:.4f} |"
                )
        t = s["timings_s"]
        lines += [
            "",
            "Timings: "
            + (f"discovery {t['discovery_s']:.1f} s, " if "discovery_s" in t else "")
            + f"least squares {t['least_squares_s']:.1f} s, posterior mode {t.get('mode_s', 0.0):.1f} s, "
            f"compile {t['compile_s']:.1f} s, sampling {t['sampling_s']:.1f} s.",
            "",
        ]
        m = metrics.get(s["material"])
        if m:
            code = s["material"]
            lines += [
                f"Table 3 metrics: posterior predictive median and 94 % HDI over {m['draws']} draws "
                f"({m['n_failed']} failed to simulate), beside the paper's values:",
                "",
                metrics_markdown(code, m["summary"], m["published"]),
                "",
                "Figures: "
                + ", ".join(
                    f"[{what}]({code}/figures/{name}.png)"
                    for name, what in MATERIAL_FIGURES.items()
                    if name in (figures or {}).get(code, ("predictive", "corner"))
                )
                + ".",
                "",
            ]
    if ranking and ranking.get("criteria"):
        unconverged = [s["material"] for s in summaries if not s["convergence"]["converged"]]
        lines += ["## Ranking across materials", ""]
        if unconverged:
            lines += [
                f"**Provisional for {', '.join(unconverged)}:** chains not converged (see above), so the "
                "probabilities involving them rest on an unconverged posterior.",
                "",
            ]
        lines += [
            "Figures: [parameters across materials](figures/forest.png), "
            "[metrics against the paper](figures/published.png), [P(best) per criterion](figures/ranking.png).",
            "",
            ranking_markdown(ranking),
            "",
        ]
    return "\n".join(lines)


__all__ = [
    "DISCOVERY_FOLDER",
    "WEAKLY_INFORMED",
    "MATERIAL_FIGURES",
    "index_markdown",
    "model_table",
    "ridge_lines",
    "shown_dataset_path",
]
