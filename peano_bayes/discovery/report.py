"""Discovery outputs: ``report.json``, ``report.md`` (for a materials engineer) and residual figures
(``figures/residuals.png``/``.pdf``: base and final model residuals against each covariate)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..atomic import write_text
from ..effects import ABSORBS, CONFUSABLE, LIBRARY, flexible_terms
from ..formatting import format_number
from ..inference.fit import NOISE_CONSISTENCY_SE
from ..report import plots
from ..report.figures import save

_UNIT = {"load_cycle": "N", "blocking": "N", "stroke": "-", "step": "-"}


#: How the base model's fit was started (the report's ``base_start``), as the report page says it.
BASE_STARTS = {
    "inference_least_squares": "The base fit started at the inference least squares of the base model (the starts "
    "and solver of `fit`).",
    "multistart": "The base fit used discovery's own multi-start search, not the inference least squares (no prior "
    "to run it with).",
}


def _binned(x: np.ndarray, r: np.ndarray, bins: int = 12) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(x) & np.isfinite(r)
    if ok.sum() < 2 or np.ptp(x[ok]) == 0:
        return x[ok][:1], r[ok][:1]
    edges = np.linspace(x[ok].min(), x[ok].max(), bins + 1)
    index = np.clip(np.digitize(x[ok], edges) - 1, 0, bins - 1)
    counts = np.bincount(index, minlength=bins)
    keep = counts > 0
    centres = 0.5 * (edges[1:] + edges[:-1])
    return centres[keep], (np.bincount(index, weights=r[ok], minlength=bins) / np.maximum(counts, 1))[keep]


def covariate_panels(result) -> list[dict]:
    """Per covariate: ``x``, ``xlabel``, and ``before`` / ``after`` as ``(residuals in the base model's noise sd,
    (centres, means))``, on the bins where the covariate is defined."""
    cov = result.split.fit_covariates
    force = np.isin(cov.test, ("load_cycle", "blocking"))
    step = cov.test == "step"
    panels = [
        ("pressure [kPa]", cov.pressure_pa / 1e3, np.ones_like(force)),
        ("strain [%]", cov.strain * 100, np.ones_like(force)),
        ("strain-rate sign (load cycles) [-]", cov.rate_sign, cov.test == "load_cycle"),
        ("predicted force [N]", result.before.predicted, force),
        ("time since the step [s]", np.nan_to_num(cov.time_since_step_s), step),
        ("cycle index [-]", cov.cycle.astype(float), np.ones_like(force)),
        ("time in the session [s]", cov.session_s, force),
    ]
    # Both models' residuals in the base model's noise units: a noise-side effect (heteroscedastic noise)
    # widens the final model's own sd, and its standardized residuals would hide the misfit it absorbed.
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = np.where(result.before.r != 0.0, result.before.error / result.before.r, np.nan)
        after = result.after.error / sd
    out = []
    for label, x, where in panels:
        where = where.astype(bool)
        rb, ra = result.before.r[where], after[where]
        out.append(
            {
                "x": x[where],
                "xlabel": label,
                "before": (rb, _binned(x[where], rb)),
                "after": (ra, _binned(x[where], ra)),
            }
        )
    return out


def residual_figure(result, path_stem: Path) -> list[Path]:
    """Residuals of the base and the final model against every covariate, one panel each."""
    panels = covariate_panels(result)
    with plt.rc_context(plots.STYLE):
        fig, axes = plt.subplots(2, 4, figsize=(14, 6.5), constrained_layout=True)
        for ax, panel in zip(axes.ravel(), panels, strict=False):
            plots.residuals_against(ax, panel["x"], panel["before"], panel["after"], xlabel=panel["xlabel"])
        for ax in axes.ravel()[len(panels) :]:
            ax.set_axis_off()
        axes[0, 0].legend(loc="best", markerscale=4)
        added = [e for e in result.report["final_model"] if e not in result.report["base"]]
        fig.suptitle(
            "Residuals on the fitted runs in the base model's noise sd: base model (red) and final model (blue)\n"
            f"base: {' + '.join(result.report['base'])}; added: {', '.join(added) or 'nothing'}"
        )
    return save(fig, path_stem)


def _absorbed_notes(final_model) -> list[str]:
    """A paragraph per effect of the final model that absorbs a library effect the model lacks (:data:`ABSORBS`)."""
    lines = []
    for effect in final_model:
        for other in ABSORBS.get(effect, ()):
            if other not in final_model:
                lines += [
                    f"`{effect}` also stands for `{other}`: on one specimen's rig tests the two act almost as "
                    f"one element (exactly, for a linear film), so its fitted parameters include any `{other}` "
                    f"and only a large one would show apart. To separate them: "
                    f"{CONFUSABLE[frozenset({effect, other})]}.",
                    "",
                ]
    return lines


def _signature_lines(rounds: list) -> list[str]:
    """Each round's significant signatures with the library candidates tried for them and the gates each failed."""
    if not any(rounds):
        return []
    lines = ["", "## Significant signatures and their candidates", ""]
    for i, signatures in enumerate(rounds, 1):
        for name, entry in signatures.items():
            tried = []
            for effect, failed in entry["candidates"].items():
                if failed is None:
                    tried.append(f"`{effect}` (its fit failed)")
                else:
                    outcome = "passed every gate" if not failed else "failed: " + ", ".join(failed)
                    tried.append(f"`{effect}` ({outcome})")
            lines.append(
                f"- round {i}, `{name}` (Holm p {entry['p_holm']:.2g}): "
                + ("; ".join(tried) if tried else "no candidate left in the library (all already in the model)")
            )
    return lines


def _evidence_phrase(step: dict) -> str:
    """Whether a step's effect was named on its own signature's evidence, in words."""
    if step.get("kind", "physics") != "physics":  # (a report from before steps recorded their kind: physics)
        return "not physics, never named"
    if step.get("named", True):
        return "significant before and halved or more after, so it is named"
    if step.get("withheld", False):
        return (
            "significant before and halved or more after, but the final model still leaves a residual signature "
            "significant after Holm, so it is not named"
        )
    return "not significant before, or not halved after, so it is not named"


def _left_phrase(report: dict) -> str:
    """The signatures still significant after Holm in the last diagnosis, with their ``T``, in words."""
    alpha = report.get("gates", {}).get("alpha", 0.01)
    last = (report.get("diagnoses") or [{}])[-1].get("signatures", {})
    left = sorted((k for k, v in last.items() if v["p_holm"] < alpha), key=lambda k: -last[k]["T"])
    if not left:
        return "no signature recorded"
    return "significant after Holm: " + ", ".join(f"`{k}` T {last[k]['T']:.1f}" for k in left)


def _withheld_sentence(withheld: list) -> str:
    one = len(withheld) == 1
    return (
        ", ".join(f"`{d}`" for d in withheld)
        + (" had its" if one else " had their")
        + " own signature's evidence and reduced the misfit, but the model with "
        + ("it" if one else "them")
        + " still leaves a residual signature significant after Holm, so "
        + ("it" if one else "they")
        + " may stand for part of a misfit outside the library and "
        + ("is" if one else "are")
        + " not named. Look at the residual figure for the shape that is left."
    )


def report_markdown(report: dict) -> str:
    """The report in words a materials engineer reads."""
    lines = [f"# Discovery report: specimen {report['specimen']}", ""]
    verdict = report["verdict"]
    # what the final model needed without naming it: the session baseline, or physics without its own evidence
    described_baseline = [d for d in report["described"] if d in flexible_terms()]
    # (effects withheld for the structure left are said apart)
    withheld = report.get("withheld", [])
    described_physics = [d for d in report["described"] if d not in flexible_terms() and d not in withheld]
    if verdict == "named":
        lines.append(f"**Verdict: the data show {', '.join(report['named'])}**, which the base model lacked.")
    elif verdict == "ambiguous":
        for a in report["ambiguous"]:
            lines.append(
                f"**Verdict: ambiguous** between {' and '.join(a['effects'])}: the data cannot tell them apart."
            )
            for rival, experiment in a["experiment"].items():
                lines.append(f"- To separate them from {rival}: {experiment}.")
    elif verdict == "unconverged":
        lines.append(
            "**Verdict: not screened.** The base model's least squares neither met its tolerance nor stopped "
            "improving, so no effect is screened or named: a candidate judged against an unfinished fit may stand "
            "for the base fit's own misfit. Start the base at the inference least squares (`discover --prior`, "
            "as `fit --discover` does)."
        )
    elif verdict == "unexplained":
        if described_baseline and report.get("drift_shown", False):
            lines.append(
                "**Verdict: unexplained.** The force drifts slowly over the session in a way no effect in the "
                "library produces; a smooth baseline over session time describes it (step "
                f"{', '.join(f'`{d}`' for d in described_baseline)} below), but it names no physics. The repeats "
                "of a test condition show the trend in time, so a load-cell drift or a slow change of the specimen "
                "are likely: re-zero the load cell between tests, or repeat the first test at the end of the session."
            )
        elif described_baseline:
            lines.append(
                "**Verdict: unexplained.** The residuals follow the order of the tests in the session, which a "
                f"smooth baseline over session time describes (step {', '.join(f'`{d}`' for d in described_baseline)} "
                "below), but the repeats of each test condition show no trend in time: the misfit is ordered with "
                "the conditions (here, pressure) as much as with time, and no cause is named. Repeating a condition "
                "at the end of the session would tell a drift from a pressure-dependent misfit."
            )
        elif withheld:
            lines.append(
                "**Verdict: unexplained.** The residuals keep structure that the search did not remove "
                f"({_left_phrase(report)})."
            )
        else:
            lines.append(
                "**Verdict: unexplained.** The residuals keep structure that no effect in the library explains on "
                "its own evidence. Look at the residual figure for its shape; no cause is named."
            )
        if withheld:
            lines.append("\n" + _withheld_sentence(withheld))
        if described_physics:
            lines.append(
                "\n" + ", ".join(f"`{d}`" for d in described_physics) + " improved the prediction of the held-out "
                "runs, but its own residual signature was not significant before it was added or did not fall by half "
                "with it (see its step below): it describes the misfit here and is not named as physics."
            )
    else:
        lines.append("**Verdict: none.** No effect beyond the base model is supported by the data.")
    if described_baseline and verdict != "unexplained":
        trend = (
            "The force also drifts slowly over the session"
            if report.get("drift_shown", False)
            else "The residuals also follow the order of the tests in the session, with no trend within a "
            "condition's repeats, so no drift is claimed"
        )
        lines.append(
            f"\n{trend} (described by a smooth baseline, {', '.join(described_baseline)}; no library effect "
            "explains it)."
        )
    if described_physics and verdict != "unexplained":
        lines.append(
            f"\n{', '.join(f'`{d}`' for d in described_physics)} also improved the prediction but without its own "
            "signature's evidence: it describes the misfit and is not named."
        )
    if report["noise_model"]:
        lines.append(f"\nThe sensor or noise model needed: {', '.join(report['noise_model'])} (not physics).")
    lines += ["", f"Base model: {' + '.join(report['base'])}. Final model: {' + '.join(report['final_model'])}."]
    lines += [BASE_STARTS.get(report.get("base_start"), ""), ""]
    if not (report.get("base_converged", True) or report.get("base_stationary", False)):
        lines += [
            "The base model's least squares stopped at its step limit without converging: what the search adds "
            "may stand for a misfit of the base fit itself. Start it at the inference least squares (`--prior`).",
            "",
        ]
    lines += _absorbed_notes(report["final_model"])
    for i, step in enumerate(report["steps"], 1):
        ev = step["evidence"]
        lines += [
            f"## Step {i}: added `{step['effect']}`",
            "",
            f"{step['meaning'].capitalize()}.",
            "",
            f"- Held-out runs: log-likelihood up by {ev['delta_elpd']:.1f} (standard error {ev['elpd_se']:.1f}); "
            f"held-out RMSE x{ev['heldout_rmse_ratio']:.2f}.",
            f"- BIC change {ev['delta_bic']:.1f} (effective sample size {ev['n_eff']:.0f}).",
            f"- Its residual signature `{ev['signature']}`: {ev['signature_before']:.1f} before (Holm p "
            f"{format_number(ev.get('signature_p_holm', float('nan')))}), {ev['signature_after']:.1f} after "
            f"(noise-level units): {_evidence_phrase(step)}.",
            "- Strength: "
            + ", ".join(
                f"`{p}` = {format_number(v['value'])} ± {format_number(v['sd'])}" for p, v in step["parameters"].items()
            )
            + f" ({', '.join(f'{k} {z:.1f} sd from off' for k, z in ev['strength_z'].items())}; joint Wald "
            f"statistic {ev['strength_wald']:.1f}, threshold {ev['strength_wald_threshold']:.1f}).",
            f"- Largest correlation with a parameter already in the model: {ev['max_correlation_with_base']:.2f}.",
        ]
        check = step.get("time_check")
        if check:
            shown = "shown" if check["shows_in_time"] else "not shown"
            lines.append(
                f"- Trend in time within test conditions ({check['runs']} runs in {check['conditions']} "
                f"conditions with repeats): {format_number(check['slope_per_hour'])} per hour (noise-level "
                f"units), p = {format_number(check['p'])}: {shown}."
            )
        if step["rivals"]:
            lines.append(f"- Rivals within two standard errors: {', '.join(step['rivals'])}.")
        if step.get("close_calls"):
            lines.append(
                f"- Also passed every gate and predicted the held-out runs as well within two standard errors: "
                f"{', '.join(step['close_calls'])}. The library declares no confusion with `{step['effect']}`, "
                "so the verdict stands, but these tests hardly tell them apart."
            )
        lines.append("")
    lines += [
        "## Gap before and after",
        "",
        "*Noise floor*: the RMSE that the sensor noise alone gives (the model-free noise estimate over each bin's "
        "samples); *excess*: sqrt(max(RMSE^2 - floor^2, 0)), what the model misses beyond the noise; *noise?*: "
        "whether the final model's residuals are consistent with noise (mean square within "
        f"{NOISE_CONSISTENCY_SE:g} standard errors of the floor's).",
        "",
        "| test | part | RMSE base | RMSE final | noise floor | excess base | excess final | noise? "
        "| max error base | max error final | unit |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    before, after = report["gap"]["before"], report["gap"]["after"]
    unexplained = []
    for test in before:
        for part in ("fit", "held_out"):
            b, a = before[test].get(part), after[test].get(part)
            if b is None or a is None:
                continue
            consistent = a.get("consistent_with_noise")
            verdict = "-" if consistent is None else ("yes" if consistent else "no")
            if consistent is False:
                unexplained.append(f"{test} ({part.replace('_', '-')})")
            lines.append(
                f"| {test} | {part.replace('_', '-')} | {format_number(b['rmse'])} | {format_number(a['rmse'])} | "
                f"{format_number(a.get('noise_floor_rmse', float('nan')))} | "
                f"{format_number(b.get('excess_rmse', float('nan')))} | "
                f"{format_number(a.get('excess_rmse', float('nan')))} | {verdict} | "
                f"{format_number(b['max_error'])} | {format_number(a['max_error'])} | {_UNIT.get(test, '')} |"
            )
    if unexplained:
        lines += ["", f"The final model's residuals are **not** consistent with noise in: {', '.join(unexplained)}."]
    elif any("consistent_with_noise" in p for t in after.values() for p in t.values()):
        lines += ["", "The final model's residuals are consistent with noise in every test."]
    lines += ["", "## Candidates screened", ""]
    for i, screened in enumerate(report["screened"], 1):
        for name, ev in screened.items():
            failed = [g for g, ok in ev["gates"].items() if not ok]
            status = "passed every gate" if ev["passed"] else f"failed: {', '.join(failed)}"
            lines.append(f"- round {i}, `{name}` ({LIBRARY[name].kind}): delta elpd {ev['delta_elpd']:.1f}; {status}")
    lines += _signature_lines(report.get("signatures", []))
    lines += [
        "",
        "Held-out runs are the last repeat of every test condition; gates and thresholds: "
        + ", ".join(f"{k} {v}" for k, v in report["gates"].items())
        + ".",
        "",
    ]
    return "\n".join(lines)


def write_report(result, out: Path) -> list[Path]:
    """Write ``report.json``, ``report.md`` and ``figures/residuals.{png,pdf}`` into ``out`` (each atomic)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "report.json", json.dumps(result.report, indent=1, default=float))
    write_text(out / "report.md", report_markdown(result.report))
    return [out / "report.json", out / "report.md", *residual_figure(result, out / "figures" / "residuals")]


__all__ = ["covariate_panels", "report_markdown", "residual_figure", "write_report"]
