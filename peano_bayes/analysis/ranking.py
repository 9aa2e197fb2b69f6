"""Design ranking with uncertainty: which material is best by each Table 3 criterion, and how sure we are.

Works on posterior predictive metric draws (:mod:`peano_bayes.analysis.metrics`: a new specimen's, with the model
discrepancy of a test that misfits where a metric is read off one), one independent posterior per material, so
draws of different materials are paired by index (any pairing of independent draws is a draw from the joint).
Per criterion: the probability each material is best, the pairwise matrix P(row better than column), the
expected rank with a 94 % interval; over :data:`PARETO_CRITERIA` jointly, the probability each material is
Pareto-optimal; and the paper's stated orderings (:data:`PUBLISHED_ORDERINGS`) as probabilities.

One practical-equivalence margin (:data:`PRACTICAL_MARGIN`) defines *best*, *clearly best* and the orderings'
``>`` and ``=``. Every probability is an average over ``n`` joint draws and carries its Monte Carlo standard
error ``sqrt(p (1 - p) / n)`` (:func:`mc_se`; the draws are evenly spaced over long chains, so taken as
independent); a verdict is given only where the probability is more than two standard errors from its threshold
(:func:`verdict`), otherwise it is ``undecided``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Criterion -> +1 where larger is better, -1 where smaller is better (SI names of ``metrics.METRIC_UNITS``).
CRITERIA = {
    "blocking_force_per_pressure": +1,
    "free_strain": +1,
    "stroke": +1,
    "energy_per_pressure": +1,
    "hysteresis_loss": -1,
    "speed": +1,
    "power_per_pressure": +1,
    "efficiency": +1,
}
#: The joint criteria of the Pareto set (force, stroke, energy, hysteresis, speed).
PARETO_CRITERIA = ("blocking_force_per_pressure", "stroke", "energy_per_pressure", "hysteresis_loss", "speed")
#: Practical-equivalence margin: material a is *better than b by more than the margin* when its oriented value
#: exceeds b's by more than this fraction of b's magnitude (5 %: about what separates two specimens of one
#: material, so smaller differences do not decide a design). The paper's ``a > b`` is checked as a exceeding b
#: by more than it, ``a = b`` as the two within it of each other; ``recommend`` asks the force with it to spare.
PRACTICAL_MARGIN = 0.05
#: A claim (an ordering, *best*, *clearly best*) holds when its probability is at least this, and fails when it
#: is at most one minus it, each by more than two Monte Carlo standard errors (:func:`verdict`).
AGREEMENT = 0.9
#: Monte Carlo standard errors a probability must clear its threshold by before a verdict is given.
SE_CLEARANCE = 2.0
STIFFNESS = "stiffness_at_minus_1.5pct_0kPa"
#: The paper's free strains were read by extrapolating its load cycles to zero force: its orderings are checked
#: against the same reading of the predicted cycles, while the ranking's criterion is the muscle's own free strain.
PAPER_FREE_STRAIN = "free_strain_paper_reading"


#: The paper's orderings (``published_orderings.csv``, by row) as checks (metric, a, relation, b), relation
#: ``">"`` (a larger) or ``"="`` (about equal), each within :data:`PRACTICAL_MARGIN` (:func:`ordering_checks`).
PUBLISHED_ORDERINGS = [
    [("speed", "TP", ">", "P"), ("speed", "P", ">", "TFC"), ("speed", "TFC", ">", "PR")],
    [("speed", "FC", ">", "PCS"), ("speed", "PCS", ">", "TPC"), ("speed", "TPC", ">", "PC")],
    [("efficiency", "TP", ">", "P"), ("efficiency", "P", ">", "TFC"), ("efficiency", "TFC", ">", "PR")],
    [("efficiency", "FC", ">", "TPC"), ("efficiency", "PC", "=", "PCS")],
    [("power_per_pressure", "FC", ">", b) for b in ("TP", "P", "PR", "TPC", "PC", "PCS", "TFC")]
    + [("power_per_pressure", a, ">", "PR") for a in ("TP", "P", "TPC", "PC", "PCS", "TFC")]
    + [("power_per_pressure", "PCS", "=", "PC")],
    [(STIFFNESS, "PR", ">", "P"), (STIFFNESS, "P", ">", "TP")],
    [(STIFFNESS, "FC", ">", b) for b in ("TPC", "PC", "PCS", "TFC")]
    + [(STIFFNESS, "TPC", ">", "PC"), (STIFFNESS, "PC", ">", "PCS")]
    + [(STIFFNESS, "TPC", ">", "TFC"), (STIFFNESS, "PC", ">", "TFC")],
    [(PAPER_FREE_STRAIN, a, ">", b) for a, b in (("TP", "TFC"), ("P", "TFC"), ("TFC", "PR"))],
    [(PAPER_FREE_STRAIN, a, ">", b) for a in ("TPC", "FC") for b in ("PC", "PCS")],
    [("blocking_force_per_pressure", a, ">", b) for a, b in (("PR", "P"), ("P", "TP"))]
    + [("blocking_force_per_pressure", a, ">", b) for a, b in (("FC", "TPC"), ("TPC", "PC"), ("PC", "PCS"))],
    [("blocking_force_per_pressure", "TP", ">", "FC"), ("blocking_force_per_pressure", "TFC", ">", "FC")],
    [("hysteresis_loss", "PR", ">", "TP"), ("hysteresis_loss", "PR", ">", "P"), ("hysteresis_loss", "TP", "=", "P")],
    [("hysteresis_loss", "PC", ">", "TPC"), ("hysteresis_loss", "TFC", "=", "FC")],
    [("energy_per_pressure", "TP", "=", "P"), ("energy_per_pressure", "P", ">", "TFC")]
    + [("energy_per_pressure", "TFC", ">", "PR")],
    [("energy_per_pressure", "PCS", ">", b) for b in ("TPC", "PC", "FC")]
    + [("energy_per_pressure", "TPC", "=", "PC"), ("energy_per_pressure", "PC", "=", "FC")],
]


def mc_se(p: float, n: int) -> float:
    """Monte Carlo standard error of a probability ``p`` estimated as the share of ``n`` independent draws."""
    if n < 1 or not math.isfinite(p):
        return math.nan
    return math.sqrt(max(p * (1.0 - p), 0.0) / n)


def verdict(p: float, se: float, threshold: float = AGREEMENT, *, fails: bool = True) -> str:
    """``"holds"`` when ``p`` exceeds ``threshold`` by more than :data:`SE_CLEARANCE` standard errors,
    ``"fails"`` (if ``fails``) when it is below ``1 - threshold`` by as much, else ``"undecided"``."""
    if not (math.isfinite(p) and math.isfinite(se)):
        return "undecided"
    if p - SE_CLEARANCE * se >= threshold:
        return "holds"
    if fails and p + SE_CLEARANCE * se <= 1.0 - threshold:
        return "fails"
    return "undecided"


@dataclass(frozen=True)
class CriterionRanking:
    """One criterion over ``materials`` (m,), with the practical margin ``margin``: ``p_best`` (m,), P(best):
    no other material better than it by more than the margin (several materials can be best together);
    ``p_clearly_best`` (m,), P(better than every other by more than the margin); ``p_better`` (m, m),
    P(row better than column); ``p_better_by_margin`` (m, m), P(row better than column by more than the margin);
    ``mean_rank`` (m,) with ``rank_low``/``rank_high`` (94 % interval of the rank by value; 1 = best); ``n``
    joint draws used (the Monte Carlo standard error of each probability is :func:`mc_se` of it and ``n``)."""

    criterion: str
    materials: tuple
    p_best: np.ndarray
    p_clearly_best: np.ndarray
    p_better: np.ndarray
    p_better_by_margin: np.ndarray
    mean_rank: np.ndarray
    rank_low: np.ndarray
    rank_high: np.ndarray
    n: int
    margin: float = PRACTICAL_MARGIN

    def verdict(self) -> dict:
        """The criterion's verdict: ``{"verdict": "clearly best" | "best" | "undecided", "materials": [...]}``:
        *clearly best* when one material's P(clearly best) clears :data:`AGREEMENT` by two standard errors;
        else *best*, naming every material whose P(best) does (more than one: equal within the margin);
        else undecided."""
        se = lambda p: mc_se(float(p), self.n)  # noqa: E731
        for name, p in (("clearly best", self.p_clearly_best), ("best", self.p_best)):
            holds = [c for c, q in zip(self.materials, p, strict=True) if verdict(q, se(q), fails=False) == "holds"]
            if holds:
                return {"verdict": name, "materials": holds}
        return {"verdict": "undecided", "materials": []}


def _joint(draws: dict, materials, names) -> np.ndarray:
    """(n, m, k) joint draws of criteria ``names``, oriented so larger is better, over draws finite everywhere."""
    n = min(len(draws[code][names[0]]) for code in materials)
    per_material = [
        np.stack([CRITERIA.get(c, 1) * np.asarray(draws[code][c][:n], float) for c in names], -1) for code in materials
    ]
    stack = np.stack(per_material, axis=1)
    return stack[np.all(np.isfinite(stack), axis=(1, 2))]


def rank_criterion(draws: dict, criterion: str, materials=None, margin: float = PRACTICAL_MARGIN) -> CriterionRanking:
    """Rank ``materials`` (default: all keys of ``draws``) by ``criterion``; ``draws`` maps code -> metric ->
    (n,) posterior predictive draws. Ties (equal draws) count as not better; materials tied for best in a
    draw share it equally, and tied materials share the better rank (1 + the number strictly better).
    ``margin``: the practical-equivalence margin (:data:`PRACTICAL_MARGIN`) of *best* and *clearly best*."""
    materials = tuple(materials or draws)
    values = _joint(draws, materials, (criterion,))[..., 0]  # (n, m)
    if values.shape[0] == 0:
        raise ValueError(f"no draw has a finite {criterion} for every material")
    better = values[:, :, None] > values[:, None, :]  # [d, i, j]: i better than j in draw d
    clearly = values[:, :, None] - values[:, None, :] > margin * np.abs(values[:, None, :])
    others = ~np.eye(len(materials), dtype=bool)[None]
    order = 1 + better.sum(axis=1)  # rank per draw, 1 = best
    return CriterionRanking(
        criterion,
        materials,
        p_best=np.mean(~np.any(clearly & others, axis=1), axis=0),
        p_clearly_best=np.all(clearly | ~others, axis=2).mean(axis=0),
        p_better=better.mean(axis=0),
        p_better_by_margin=clearly.mean(axis=0),
        mean_rank=order.mean(axis=0),
        rank_low=np.quantile(order, 0.03, axis=0, method="inverted_cdf"),
        rank_high=np.quantile(order, 0.97, axis=0, method="inverted_cdf"),
        n=values.shape[0],
        margin=margin,
    )


def pareto_probability(draws: dict, materials=None, criteria=PARETO_CRITERIA) -> dict[str, float]:
    """code -> probability of being Pareto-optimal (no other material at least as good on every criterion and
    better on one) over ``criteria`` jointly."""
    materials = tuple(materials or draws)
    return _pareto(_joint(draws, materials, tuple(criteria)), materials)


def _pareto(x: np.ndarray, materials: tuple) -> dict[str, float]:
    """:func:`pareto_probability` of joint draws ``x`` (n, m, k), oriented so larger is better."""
    geq = np.all(x[:, :, None, :] >= x[:, None, :, :], axis=-1)  # [d, i, j]: i >= j everywhere
    gt = np.any(x[:, :, None, :] > x[:, None, :, :], axis=-1)
    dominated = np.any(geq & gt, axis=1)  # some i dominates j
    return {code: float(np.mean(~dominated[:, j])) for j, code in enumerate(materials)}


def ordering_counts(orderings: list[dict]) -> dict[str, int]:
    """How many relations of ``orderings`` (:func:`ordering_checks` rows) each verdict has: ``agrees``,
    ``contradicts``, ``undecided``, and ``not informed`` (the metric rests on the prior only)."""
    counts = dict.fromkeys(("agrees", "contradicts", "undecided", "not informed"), 0)
    for o in orderings:
        said = o.get("verdict", "undecided")
        if said not in counts:
            raise ValueError(f"ordering {o.get('a')} {o.get('relation')} {o.get('b')}: unknown verdict {said!r}")
        counts[said] += 1
    return counts


def ordering_summary(orderings: list[dict]) -> str:
    """One sentence counting the verdicts of :func:`ordering_checks` rows."""
    c = ordering_counts(orderings)
    informed = len(orderings) - c["not informed"]
    text = (
        f"Of the {informed} relations the fitted tests inform, the posteriors support {c['agrees']} at"
        f" P >= {AGREEMENT:g}, contradict {c['contradicts']} at P <= {1 - AGREEMENT:.1f} (each by more than"
        f" {SE_CLEARANCE:g} Monte Carlo standard errors), and leave {c['undecided']} undecided."
    )
    if c["not informed"]:
        text += f" {c['not informed']} more rest on the prior only (their metric was not fitted)."
    return text


def ordering_checks(draws: dict, margin: float = PRACTICAL_MARGIN) -> list[dict]:
    """The paper's orderings checked on the posterior: per row of ``published_orderings.csv``, each relation
    whose two materials are in ``draws``, with its ``probability`` over ``n`` paired draws (``a > b``: a exceeds
    b by more than ``margin`` of b; ``a = b``: |log a/b| <= log(1 + margin)), its Monte Carlo standard error
    ``se``, the ``margin`` and the ``verdict`` (agrees / contradicts / undecided, :func:`verdict`)."""
    out = []
    for row, checks in enumerate(PUBLISHED_ORDERINGS):
        for metric, a, relation, b in checks:
            if a not in draws or b not in draws or metric not in draws[a] or metric not in draws[b]:
                continue
            va = np.asarray(draws[a][metric], float)
            vb = np.asarray(draws[b][metric], float)
            n = min(va.size, vb.size)
            va, vb = va[:n], vb[:n]
            ok = np.isfinite(va) & np.isfinite(vb) & (va > 0) & (vb > 0)
            if not ok.any():
                p = math.nan
            elif relation == ">":
                p = float(np.mean(va[ok] > (1.0 + margin) * vb[ok]))
            else:
                p = float(np.mean(np.abs(np.log(va[ok] / vb[ok])) <= math.log1p(margin)))
            se = mc_se(p, int(ok.sum()))
            said = {"holds": "agrees", "fails": "contradicts"}.get(verdict(p, se), "undecided")
            out.append(
                {
                    "row": row,
                    "metric": metric,
                    "a": a,
                    "relation": relation,
                    "b": b,
                    "probability": p,
                    "se": se,
                    "n": int(ok.sum()),
                    "margin": margin,
                    "verdict": said,
                }
            )
    return out


def failed_draw_counts(metrics: dict) -> dict:
    """code -> ``(failed, drawn)`` of each material's metrics file contents (code -> ``metrics.json``), for
    :func:`rank_materials`'s ``failed_draws``."""
    return {code: (m.get("n_failed", 0), m.get("draws", 0)) for code, m in metrics.items()}


def rank_materials(
    draws: dict,
    from_prior=(),
    test_pressure_kpa: dict | None = None,
    own_test_pressure_kpa: dict | None = None,
    failed_draws: dict | None = None,
) -> dict:
    """Everything :mod:`peano_bayes.analysis.ranking` computes, as plain data: ``materials``; ``margin`` (the
    practical-equivalence margin); ``draws`` (the fewest joint draws any criterion is ranked over); ``criteria``
    (per criterion: ``p_best`` and ``p_clearly_best`` by material with their standard errors ``*_se``, its
    ``verdict`` and the ``materials`` it names (:meth:`CriterionRanking.verdict`), ``mean_rank``,
    ``rank_interval``, ``p_better`` and ``p_better_by_margin`` matrix rows by material, ``margin``, ``n`` draws;
    criteria no draw defines are left out); ``pareto`` (P(Pareto-optimal)
    by material, over the Pareto criteria that are ranked); ``orderings`` (:func:`ordering_checks`);
    ``left_out`` (criterion -> why it is not ranked). ``draws``: code -> metric -> (n,) values; ``from_prior``:
    metrics the data did not inform in some material (e.g. the step metrics of fits without the step test):
    they are **not ranked**, since their draws are the prior's and a ranking of them would rank the priors.
    ``test_pressure_kpa``: code -> the pressure each material's metrics were simulated at (each at its own test
    pressure, or all at a common one); kept in the report so that :func:`ranking_markdown` can say when they
    differ. ``own_test_pressure_kpa``: code -> the pressure each material was tested at, where the metrics were
    simulated at a common pressure instead. ``failed_draws``: code -> ``(failed, drawn)``, the posterior draws
    whose metrics could not be simulated; kept so that :func:`ranking_markdown` says whose metrics rest on
    fewer draws (those the model can simulate there, not a random subset)."""
    materials = tuple(draws)
    from_prior = set(from_prior)
    criteria = {}
    left_out = {
        c: "not informed by the fitted tests (the step response was not fitted): its draws are the prior's"
        for c in CRITERIA
        if c in from_prior
    }
    for criterion in CRITERIA:
        if criterion in left_out:
            continue
        try:
            r = rank_criterion(draws, criterion, materials)
        except ValueError:
            continue
        by = lambda values: dict(zip(materials, values, strict=True))  # noqa: E731
        se = lambda values, n=r.n, by=by: by([mc_se(float(p), n) for p in values])  # noqa: E731
        criteria[criterion] = {
            "p_best": by(r.p_best.tolist()),
            "p_best_se": se(r.p_best),
            "p_clearly_best": by(r.p_clearly_best.tolist()),
            "p_clearly_best_se": se(r.p_clearly_best),
            **r.verdict(),
            "mean_rank": by(r.mean_rank.tolist()),
            "rank_interval": by([[int(lo), int(hi)] for lo, hi in zip(r.rank_low, r.rank_high, strict=True)]),
            "p_better": by([by(row.tolist()) for row in r.p_better]),
            "p_better_by_margin": by([by(row.tolist()) for row in r.p_better_by_margin]),
            "margin": r.margin,
            "n": r.n,
            "from_prior": criterion in from_prior,
        }
    pareto_criteria = tuple(c for c in PARETO_CRITERIA if c not in left_out)
    try:
        joint = _joint(draws, materials, pareto_criteria)
        pareto, pareto_n = _pareto(joint, materials), len(joint)
    except (ValueError, IndexError, KeyError):
        pareto, pareto_n = {}, 0
    orderings = [
        {**o, "from_prior": True, "verdict": "not informed"}
        if o["metric"] in from_prior
        else {**o, "from_prior": False}
        for o in ordering_checks(draws)
    ]
    return {
        "materials": list(materials),
        "margin": PRACTICAL_MARGIN,
        "draws": min((r["n"] for r in criteria.values()), default=0),
        "criteria": criteria,
        "pareto": pareto,
        "pareto_se": {c: mc_se(p, pareto_n) for c, p in pareto.items()},
        "pareto_criteria": list(pareto_criteria),
        "orderings": orderings,
        "left_out": left_out,
        "test_pressure_kpa": dict(test_pressure_kpa or {}),
        "own_test_pressure_kpa": dict(own_test_pressure_kpa or test_pressure_kpa or {}),
        "failed_draws": {c: [int(f), int(n)] for c, (f, n) in (failed_draws or {}).items() if f},
    }


def ranking_markdown(report: dict) -> str:
    """Markdown of :func:`rank_materials`: per criterion P(best) and expected rank; the Pareto set; orderings."""
    materials = report["materials"]
    margin = report["margin"]
    lines = [
        "### Per criterion: P(best), P(clearly best) and expected rank (94 % interval)",
        "",
        f"*Best*: no material better than it by more than {100 * margin:g} % (the practical-equivalence margin; "
        f"several materials can be best together); *clearly best*: better than every other by more than "
        f"{100 * margin:g} %. Each probability is over {report['draws']} joint posterior draws, "
        f"± its Monte Carlo standard error; a verdict needs the probability above {AGREEMENT:g} by more than "
        f"{SE_CLEARANCE:g} standard errors, else it is undecided.",
        "",
    ]
    pressures = {c: p for c, p in report.get("test_pressure_kpa", {}).items() if p is not None}
    own = report.get("own_test_pressure_kpa", pressures)
    away = {c: own[c] for c, p in pressures.items() if own.get(c) is not None and own[c] != p}
    if away:
        common = sorted(set(pressures.values()))
        listed = "; ".join(f"{c} at {p:g} kPa" for c, p in away.items())
        lines += [
            f"*Compared at a common pressure* ({', '.join(f'{p:g}' for p in common)} kPa). Tested elsewhere: "
            f"{listed}; their metrics here are their fitted models simulated away from the pressure their data "
            "cover, an extrapolation the data do not check.",
            "",
        ]
    elif len(set(pressures.values())) > 1:
        groups = {}
        for code, p in pressures.items():
            groups.setdefault(p, []).append(code)
        listed = "; ".join(f"{p:g} kPa: {', '.join(codes)}" for p, codes in sorted(groups.items()))
        lines += [
            f"*Test pressures differ* ({listed}). Each material is compared at its own test pressure: a per-MPa "
            "criterion is its value there divided by that pressure, and comparing those across pressures assumes "
            "the per-MPa value does not change with pressure (the paper's Table 3 makes the same assumption).",
            "",
        ]
    failed = report.get("failed_draws", {})
    if failed:
        listed = "; ".join(f"{c}: {f} of {n}" for c, (f, n) in failed.items())
        lines += [
            f"*Draws that could not be simulated* ({listed}): those materials' metrics rest on the draws the model "
            "could simulate here, which leans them towards the parameters it simulates most easily.",
            "",
        ]
    lines.append("| criterion | verdict | " + " | ".join(materials) + " |")
    lines.append("|---|---|" + "---|" * len(materials))
    for criterion, r in report["criteria"].items():
        label = f"{criterion} ({'lower' if CRITERIA[criterion] < 0 else 'higher'} is better)"
        label += " (prior only: not fitted)" if r.get("from_prior") else ""
        said = f"{r['verdict']}: {', '.join(r['materials'])}" if r["materials"] else r["verdict"]
        cells = []
        for c in materials:
            low, high = r["rank_interval"][c]
            cells.append(
                f"{_with_se(r['p_best'][c], r['p_best_se'][c])} / "
                f"{_with_se(r['p_clearly_best'][c], r['p_clearly_best_se'][c])}, "
                f"rank {r['mean_rank'][c]:.1f} ({low}-{high})"
            )
        lines.append(f"| {label} | {said} | " + " | ".join(cells) + " |")
    for criterion, why in report.get("left_out", {}).items():
        lines += ["", f"Not ranked: {criterion}, {why}."]
    if report["pareto"]:
        over = report.get("pareto_criteria", PARETO_CRITERIA)
        lines += ["", f"### P(Pareto-optimal) over {', '.join(over)}", ""]
        lines.append("| " + " | ".join(materials) + " |")
        lines.append("|" + "---|" * len(materials))
        se = report["pareto_se"]
        lines.append("| " + " | ".join(_with_se(report["pareto"][c], se[c]) for c in materials) + " |")
        likely = [c for c in materials if verdict(report["pareto"][c], se[c], fails=False) == "holds"]
        lines += [
            "",
            f"Pareto-optimal with probability >= {AGREEMENT:g} (by more than {SE_CLEARANCE:g} standard errors): "
            f"{', '.join(likely) or 'none'}.",
        ]
    if report["orderings"]:
        lines += [
            "",
            "### The paper's orderings on the posterior",
            "",
            f"*a > b*: a exceeds b by more than {100 * margin:g} %; *about equal*: within {100 * margin:g} % of each "
            f"other. Agrees: probability >= {AGREEMENT:g}; contradicts: <= {1 - AGREEMENT:.1f}, each by more than "
            f"{SE_CLEARANCE:g} Monte Carlo standard errors; undecided otherwise.",
            "",
            ordering_summary(report["orderings"]),
            "",
            "| metric | paper's ordering | inferred probability | agree? |",
        ]
        lines.append("|---|---|---|---|")
        for o in report["orderings"]:
            shown = "about equal to" if o["relation"] == "=" else ">"
            flag = " (prior only: not fitted)" if o.get("from_prior") else ""
            said = o.get("verdict", "")
            said = f"**{said}**" if said == "contradicts" else said
            lines.append(
                f"| {o['metric']}{flag} | {o['a']} {shown} {o['b']} | {_with_se(o['probability'], o['se'])} | {said} |"
            )
    return "\n".join(lines)


def _with_se(p: float, se: float) -> str:
    """A probability with its Monte Carlo standard error, e.g. ``0.93 ± 0.01``."""
    return f"{p:.2f} ± {se:.2f}" if math.isfinite(se) else f"{p:.2f}"


__all__ = [
    "AGREEMENT",
    "PRACTICAL_MARGIN",
    "CRITERIA",
    "failed_draw_counts",
    "SE_CLEARANCE",
    "PARETO_CRITERIA",
    "PUBLISHED_ORDERINGS",
    "CriterionRanking",
    "mc_se",
    "ordering_checks",
    "ordering_counts",
    "ordering_summary",
    "pareto_probability",
    "rank_criterion",
    "rank_materials",
    "ranking_markdown",
    "verdict",
]
