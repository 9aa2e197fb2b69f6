"""Check the bundled datasets against the paper: measure Table 3 metrics from the files, write CALIBRATION.md.

Loads every bundled ``<CODE>.csv`` with ``peano_bayes.data.load``, measures each metric from the loaded signals
(``peano_bayes.analysis.metrics``: Table 3 definitions, mean over specimens and repeats) and compares it with
every row of the bundled ``published_metrics.csv`` and ``published_orderings.csv`` (copies of the paper's
extracted numbers).
Tolerances: +-10 % explicit, +-20 % approximate, +-30 % ambiguous; "about equal" means within +-10 % (|log ratio|
<= 0.1). Run ``python experiments/calibration_report.py``; writes ``experiments/datasets/CALIBRATION.md``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
from calibrate import FIT_ORDER, STIFFNESS, TOLERANCE, free_box, zero_kpa_stiffness

from peano_bayes import bundled
from peano_bayes.analysis import readouts as table3
from peano_bayes.analysis.metrics import NOISELESS, run_metrics
from peano_bayes.analysis.ranking import PUBLISHED_ORDERINGS
from peano_bayes.data import load
from peano_bayes.materials import material
from peano_bayes.physics import ModelConfig
from peano_bayes.rig import DEFAULT_PROTOCOL, simulate_dataset

DATA = bundled.DATA_DIR
OUT = Path(__file__).parent / "datasets"
EQUAL_BAND = 0.10
#: Stroke-test pressure at which the strain has risen by this fraction of the stroke = threshold pressure.
THRESHOLD_RISE = 0.05
#: Table 5's actuated area for maximum stress: tube length (across the muscle) x Table 5 thickness [m^2].
ACTUATED_AREA_M2 = 0.0495 * 0.013
CONDITIONS = {"test_pressure": ("test_pressure_pa", 1e-3), "step_load": ("step_load_n", 1.0)}
CONDITIONS["start_tension"] = ("start_tension_n", 1.0)
#: Free strain is measured only where the data reach a force at most this fraction of the blocking force at the
#: test pressure (the load cycle's relaxing end, or the stroke test lifting its 5.5 N load); else not measurable.
REACHED_FRACTION = 0.10
#: Start tension [N] of the noise-free reference cycle that shows the generating model's own free strain.
REFERENCE_START_N = 0.5
#: Lowest strains of the noise-free cycles that show how the stretched-end energy grows with the stretch [-].
STRETCHES = (-0.015, -0.03, -0.05, -0.08)
#: Table 5 (FC at 200 kPa, l0 = 0.06 m): energy and power per MPa of Figure 9 and the text, and the densities.
TABLE5 = {"energy_j": 3.2, "power_w": 19.0, "energy_j_per_kg": 51.0, "energy_kj_per_m3": 42.5,
          "power_w_per_kg": 315.0, "power_kw_per_m3": 270.0, "blocking_n": 350.0, "free_strain": 0.18, "l0_m": 0.06}

#: The checks of each published_orderings.csv row (by row order): (metric, a, relation, b).
ORDERING_CHECKS = PUBLISHED_ORDERINGS
#: Reasons for misses, by metric; (code, metric) entries override. Each names the limit the fit ran into.
REASONS = {
    "energy_per_pressure": "definition: read from zero strain (as these files were calibrated), energy = fill "
    "factor x blocking force x free strain x l0, and these curves are not full enough for the published value "
    "(section 'The paper's energy definition against its own numbers'); the paper's numbers fit only the "
    "stretched-end reading, whose value depends on the stretch of Figure 8's cycles",
    ("PCS", "energy_per_pressure"): "definition: from zero strain no curve reaches 4.8 J/MPa within the paper's own "
    "blocking force and free strain bounds (at most 3.78); the paper credits it to recoverable extension, which "
    "only the stretched-end reading counts",
    "hysteresis_loss": "compromise: more friction raises the loss but lowers the relaxing curve, and with it the "
    "energy, which is already below target",
    "efficiency": "compromise: speed, power and efficiency share the inlet orifice and the inertial load; with speed "
    "and power on target the model loses more fluid power across the orifice than the published efficiency allows",
    "speed": "compromise: speed shares the orifice and load with power and efficiency",
    "power_per_pressure": "compromise: power shares the orifice and load with speed and efficiency",
    "blocking_force_per_pressure": "compromise: blocking force shares the tensile spring with the 0 kPa stiffness",
    "free_strain": "calibration measure: the files were calibrated to the load cycles' linear extrapolation, "
    "which reads free strain low (section 'Free strain where the data reach it'); the strain at the stroke "
    "test's end, a lower bound on the free strain, is already above the published value's tolerance",
    STIFFNESS: "compromise: the 0 kPa stiffness shares the tensile spring with the blocking force",
}


def measure(code: str) -> dict:
    """Load ``data/<code>.csv``; return metric -> (mean, per-run values) plus extras used by the report."""
    dataset = load(DATA / f"{code}.csv")
    values = run_metrics(dataset)
    out = {name: _mean(v) for name, v in values.items()}
    zero = [r for r in dataset.runs_of("load_cycle") if np.median(r.pressure_pa) < 0.5e3]
    out["_start_strain_0kpa"] = float(np.mean([r.strain[0] for r in zero]))
    truth = json.loads(dataset.provenance["parameters"])
    config = ModelConfig(**json.loads(dataset.provenance["config"]))
    out["_stiffness_truth"] = zero_kpa_stiffness(truth, config)
    strokes = dataset.runs_of("stroke")
    out["_threshold_pa"] = float(np.mean([_threshold(r.pressure_pa, r.strain) for r in strokes]))
    out["_dataset"] = dataset
    out.update(_free_strain_reached(dataset, out, strokes))
    out.update(_energy_definitions(dataset))
    out["_free_strain_truth"], out["_energy_truth_full"] = _reference_cycle(code, truth, config)
    out["_energy_by_stretch"] = [_stretched_energy(code, truth, config, low) for low in STRETCHES]
    return out


def _pressurized_cycles(dataset):
    p_test = dataset.conditions.test_pressure_pa
    return [r for r in dataset.runs_of("load_cycle") if np.median(r.pressure_pa) >= 0.5 * p_test]


def _free_strain_reached(dataset, out: dict, strokes) -> dict:
    """Free strain where the data reach a small force, else NaN; with where each test ends.

    The load cycles stop at the start tension, so their free strain (``run_metrics``) is a linear extrapolation.
    The stroke test ends lifting its 5.5 N load at the test pressure. Whichever ends at the lower force gives the
    strain there, counted as the free strain if that force is at most ``REACHED_FRACTION`` of the blocking force.
    """
    ends = []
    for run in _pressurized_cycles(dataset):
        (_, _), (s_down, f_down) = table3.loop_branches(run.strain, run.force_n)
        i = int(np.argmin(f_down))
        ends.append((float(s_down[i]), float(f_down[i])))
    cycle_strain, cycle_force = (float(np.mean(v)) for v in zip(*ends, strict=True))
    n_tail = [max(len(r.strain) // 50, 1) for r in strokes]
    stroke_strain = float(np.mean([np.median(r.strain[-n:]) for r, n in zip(strokes, n_tail, strict=True)]))
    stroke_force = float(json.loads(dataset.provenance["protocol"])["stroke_load_n"])
    blocking_n = out["blocking_force_per_pressure"] * dataset.conditions.test_pressure_pa / 1e6
    by_stroke = stroke_force < cycle_force
    strain, force = (stroke_strain, stroke_force) if by_stroke else (cycle_strain, cycle_force)
    reached = force <= REACHED_FRACTION * blocking_n
    return {
        "_free_strain_extrapolated": out["free_strain"],
        "free_strain": strain if reached else float("nan"),
        "_cycle_end": (cycle_strain, cycle_force),
        "_stroke_end": (stroke_strain, stroke_force),
        "_blocking_n": blocking_n,
        "_reached_at": ("stroke test's end" if by_stroke else "load cycle's end", force),
    }


def _energy_definitions(dataset) -> dict:
    """Energy per MPa of the relaxing branch read from the most stretched point of the cycle instead of zero
    strain (``run_metrics``), to the extrapolated free strain [J/MPa]."""
    l0 = dataset.geometry.flat_length_m
    from_stretch = [
        table3.energy_per_pressure(run.strain, run.force_n, run.pressure_pa, l0, from_strain=None)
        for run in _pressurized_cycles(dataset)
    ]
    return {"_energy_from_stretch": float(np.mean(from_stretch))}


def _stretched_energy(code: str, truth: dict, config: ModelConfig, low: float) -> float:
    """The generating model's energy per MPa from the stretched end [J/MPa] of a noise-free cycle down to ``low``."""
    dataset = simulate_dataset(
        code, truth, config=config, noise=NOISELESS, specimen_spread=0.0, repeats=1, specimens=1,
        tests=("load_cycle",), protocol=dataclasses.replace(DEFAULT_PROTOCOL, stretch_strain=low),
    )
    return _energy_definitions(dataset)["_energy_from_stretch"]


def _reference_cycle(code: str, truth: dict, config: ModelConfig) -> tuple[float, float]:
    """The generating model's free strain and energy per MPa from one noise-free pressurized load cycle that
    starts at ``REFERENCE_START_N`` instead of the start tension, so it relaxes to almost zero force."""
    spec = dataclasses.replace(material(code), start_tension_n=REFERENCE_START_N)
    dataset = simulate_dataset(
        spec, truth, config=config, noise=NOISELESS, specimen_spread=0.0, repeats=1, specimens=1,
        tests=("load_cycle",),
    )
    cycle = _pressurized_cycles(dataset)[0]
    l0 = dataset.geometry.flat_length_m
    return (
        table3.extrapolated_free_strain(cycle.strain, cycle.force_n),
        table3.energy_per_pressure(cycle.strain, cycle.force_n, cycle.pressure_pa, l0),
    )


def _mean(values) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def _threshold(pressure_pa, strain) -> float:
    """Pressure [Pa] at which the stroke-test strain first rises by ``THRESHOLD_RISE`` of its stroke."""
    n = max(len(strain) // 50, 1)
    s0, s1 = np.median(strain[:n]), np.median(strain[-n:])
    return float(pressure_pa[int(np.argmax(strain - s0 >= THRESHOLD_RISE * (s1 - s0)))])


def compare(published: float, measured: float, tol: float) -> tuple[str, float]:
    """``("pass" | "FAIL" | "n/a", relative error)`` of a measurement against a published value."""
    if not math.isfinite(measured):
        return "n/a", float("nan")
    error = measured / published - 1.0
    return ("pass" if abs(error) <= tol else "FAIL"), error


def metric_rows(measured: dict) -> tuple[list[str], list[tuple[str, str]]]:
    """Markdown table rows for published_metrics.csv, and the misses as (row label, reason)."""
    rows, misses = [], []
    with open(DATA / "published_metrics.csv", newline="") as f:
        for row in csv.DictReader(f):
            code, metric, value, kind = row["material"], row["metric"], float(row["value"]), row["kind"]
            label = f"{code} {metric}"
            got = measured[code]
            if kind == "condition":
                field, scale = CONDITIONS[metric]
                seen = getattr(got["_dataset"].conditions, field) * scale
                verdict = "pass" if math.isclose(seen, value) else "FAIL"
                rows.append(f"| {code} | {metric} | {value:g} {row['unit']} | {seen:g} (sidecar) | exact | {verdict} |")
                continue
            short = kind.split()[0]
            tol = TOLERANCE.get(short, 0.10)
            note, measured_value = "", got.get(metric, float("nan"))
            if metric == STIFFNESS and not math.isfinite(measured_value):
                # Not a measurement, so not a pass: the generating model's value is shown for reference only.
                model_value = got["_stiffness_truth"]
                _, error = compare(value, model_value, tol)
                rows.append(
                    f"| {code} | {metric} | {value:g} {row['unit']} | not measurable from rig signals (the 0 kPa"
                    f" cycle starts at {100 * got['_start_strain_0kpa']:.1f} % strain, past -1.5 %, at the start"
                    f" tension); the generating model's tangent on a 0 to -3 % stretch is {model_value:.4g}"
                    f" ({100 * error:+.0f} %) | - | n/a |"
                )
                continue
            elif metric == "free_strain":
                where, force = got["_reached_at"]
                if not math.isfinite(measured_value):
                    _, error = compare(value, got["_free_strain_truth"], tol)
                    rows.append(
                        f"| {code} | {metric} | {value:g} {row['unit']} | not measurable from rig signals (the lowest"
                        f" force reached, {force:.1f} N at the {where}, is {100 * force / got['_blocking_n']:.0f} % of"
                        f" the blocking force); the generating model's is {got['_free_strain_truth']:.3f}"
                        f" ({100 * error:+.0f} %) | - | n/a |"
                    )
                    continue
                note = (
                    f" (a lower bound: the strain at the {where}, {force:.1f} N ="
                    f" {100 * force / got['_blocking_n']:.0f} % of the blocking force; the load cycle's linear"
                    f" extrapolation gave {got['_free_strain_extrapolated']:.3f})"
                )
            elif metric == "max_stress_per_pressure":
                measured_value = got["blocking_force_per_pressure"] / ACTUATED_AREA_M2 / 1e3
                note = " (blocking force per MPa over an assumed area: tube length 49.5 mm x Table 5 thickness 13 mm)"
            elif metric == "threshold_pressure_upper_bound":
                seen = got["_threshold_pa"] / 1e3
                verdict = "pass" if seen < value else "FAIL"
                rows.append(
                    f"| {code} | {metric} | < {value:g} kPa | {seen:.2f} kPa (stroke test: pressure at"
                    f" {100 * THRESHOLD_RISE:g} % of the stroke, lifting 5.5 N) | bound | {verdict} |"
                )
                if verdict == "FAIL":
                    misses.append((label, "lifting the 5.5 N stroke load takes more pressure than the bound"))
                continue
            elif metric in ("energy_density_mass_per_pressure", "power_density_mass_per_pressure", "max_thickness"):
                need = "the muscle mass" if "mass" in metric else "the inflated thickness"
                rows.append(
                    f"| {code} | {metric} | {value:g} {row['unit']} | not measurable from rig signals (needs {need}, "
                    "which neither the CSV nor the sidecar holds) | - | n/a |"
                )
                continue
            verdict, error = compare(value, measured_value, tol)
            if short == "ambiguous":
                note += " (ambiguous: the text gives 570 for 'TFC or TP'; checked against both at +-30 %)"
            rows.append(
                f"| {code} | {metric} | {value:g} {row['unit']} | {measured_value:.4g}{note} | +-{100 * tol:g} % "
                f"({short}) | {verdict} ({100 * error:+.0f} %) |"
            )
            if verdict != "pass":
                reason = REASONS.get((code, metric), REASONS.get(metric, "see true_parameters.toml"))
                if metric == "energy_per_pressure":
                    fill, need = _fill_factors(measured, code, value)
                    reason += f" (fill factor {fill:.2f}, needed {need:.2f})"
                misses.append((label, measured_tradeoff(label, reason)))
    return rows, misses


def ordering_rows(measured: dict) -> tuple[list[str], list[tuple[str, str]]]:
    """Markdown rows for published_orderings.csv: every encoded relation checked on measured means."""
    rows, misses = [], []
    with open(DATA / "published_orderings.csv", newline="") as f:
        orderings = list(csv.DictReader(f))
    for row, checks in zip(orderings, ORDERING_CHECKS, strict=True):
        parts, ok, modelled = [], True, False
        for metric, a, relation, b in checks:
            modelled |= metric in MODEL_REFERENCE and not all(
                math.isfinite(measured[c].get(metric, float("nan"))) for c in (a, b)
            )
            va, vb = _ordering_value(measured, a, metric), _ordering_value(measured, b, metric)
            gap = math.log(va / vb)
            good = gap > 0 if relation == ">" else abs(gap) <= EQUAL_BAND
            ok &= good
            shown = "about equal to" if relation == "=" else ">"
            parts.append(f"{a} {shown} {b} ({va:.3g} vs {vb:.3g}: {'pass' if good else 'FAIL'})")
            if not good and not modelled:
                label = f"ordering {metric}: {a} {shown} {b}"
                reason = ORDER_REASONS.get(
                    metric, "compromise: orderings are soft hinges (5 % margin) traded against the numeric targets"
                )
                misses.append((label, measured_tradeoff(label, reason)))
        verdict = "pass" if ok else "FAIL"
        if modelled:  # values from the generating model, not measured on the files: reference only
            verdict = f"n/a (not measurable from rig signals; the generating model's values: {verdict})"
        rows.append(f"| {row['metric']} | {row['group']} | {row['ordering']} | {'; '.join(parts)} | {verdict} |")
    return rows, misses


TRADEOFFS = OUT / "calibration_tradeoffs.json"


def _badness(label: str, value: float) -> float:
    """How far a check of ``calibration_tradeoffs.json`` is from passing, growing as it gets worse."""
    if " > " in label:
        return -value  # an ordering's log ratio should be positive
    return abs(value)  # a relative error, or an 'about equal' log ratio


def measured_tradeoff(label: str, reason: str) -> str:
    """``reason``, with the forced refits of ``experiments/calibration_tradeoffs.py`` in place of a claimed
    compromise: what forcing the miss to pass did to every other check of the refitted material.

    A refit that meets the miss without failing or worsening (by more than 0.01) any other check shows the miss
    is avoidable; the text then says so instead of calling it a compromise.
    """
    if not reason.startswith("compromise"):
        return reason
    if not TRADEOFFS.exists():
        return reason + " (not measured: run experiments/calibration_tradeoffs.py)"
    probes = json.loads(TRADEOFFS.read_text())["probes"].get(label)
    if not probes:
        return reason + " (not measured: no probe in experiments/calibration_tradeoffs.py)"
    parts, free = [], []
    for code, r in probes.items():
        (_, v0), (held, v1) = r["before"][label], r["after"][label]
        costs = []
        for other, (passes, value) in r["after"].items():
            was_passing, was = r["before"][other]
            if other == label or _badness(other, value) <= _badness(other, was) + 0.01:
                continue
            if was_passing and not passes:
                costs.append(f"{other} now fails ({was:+.3f} -> {value:+.3f})")
            elif not was_passing:
                costs.append(f"{other}, already failing, worsens ({was:+.3f} -> {value:+.3f})")
        text = (
            f"refitting {code} with it forced {'meets it' if held else 'does not meet it'} ({v0:+.3f} -> {v1:+.3f});"
            f" calibration cost {r['cost_before']:.2f} -> {r['cost_after_without_forcing']:.2f}; "
            + ("; ".join(costs) if costs else "no other check of " + code + " fails or worsens")
        )
        parts.append(text)
        if held and not costs:
            free.append(code)
    if free:
        head = (
            "avoidable, not a compromise: a refit meets it without failing or worsening any other check of the"
            " refitted material; the sequential calibration (calibrate.FIT_ORDER; an ordering is active only once"
            " both materials are fitted) and its soft 5 % hinges left it. The bundled files were not re-generated,"
            " since every figure in docs/validation.md is measured on them"
        )
    else:
        head = "compromise, measured"
    return f"{head} (experiments/calibration_tradeoffs.py, noise-free signals): " + "; ".join(parts)


def miss_summary(misses: list[tuple[str, str]]) -> str:
    """One sentence: how many misses each kind of reason explains (the word before the first colon)."""
    kinds: dict[str, int] = {}
    for _, reason in misses:
        kind = reason.split(":")[0].split(" (")[0].split(",")[0]
        kinds[kind] = kinds.get(kind, 0) + 1
    shown = ", ".join(f"{kind} {n}" for kind, n in sorted(kinds.items(), key=lambda kv: -kv[1]))
    return f"{len(misses)} misses, by kind of reason: {shown}."


#: Reasons for ordering misses of one metric, where the generic trade-off is not the cause.
ORDER_REASONS = {
    "free_strain": "calibration measure: the files were calibrated to the load cycles' extrapolated free strain, "
    "which keeps this ordering; measured where the data reach it (section 'Free strain where the data reach it'), "
    "it reverses",
}

#: Metrics that rig signals may not measure, with the generating model's value shown for reference instead.
MODEL_REFERENCE = {STIFFNESS: "_stiffness_truth", "free_strain": "_free_strain_truth"}


def _ordering_value(measured: dict, code: str, metric: str) -> float:
    value = measured[code].get(metric, float("nan"))
    if metric in MODEL_REFERENCE and not math.isfinite(value):
        return measured[code][MODEL_REFERENCE[metric]]
    return value


def free_strain_lines(measured: dict) -> list[str]:
    """Where each material's data end, and the free strain each reading gives [-]."""
    lines = []
    for code in FIT_ORDER:
        got = measured[code]
        (cs, cf), (ss, sf) = got["_cycle_end"], got["_stroke_end"]
        shown = f"{got['free_strain']:.3f}" if math.isfinite(got["free_strain"]) else "not measurable"
        lines.append(
            f"| {code} | {got['_blocking_n']:.1f} | {cs:.3f} at {cf:.1f} N | {got['_free_strain_extrapolated']:.3f} |"
            f" {ss:.3f} at {sf:.1f} N | {shown} | {got['_free_strain_truth']:.3f} |"
        )
    return lines


def energy_lines(measured: dict) -> list[str]:
    """Energy per MPa under each reading of Table 3, with the fill factor it implies [J/MPa, -]."""
    published = _published("energy_per_pressure")
    lines = []
    for code in FIT_ORDER:
        got = measured[code]
        free = _ordering_value(measured, code, "free_strain")
        fill, need = _fill_factors(measured, code, published[code])
        lines.append(
            f"| {code} | {published[code]:g} | {got['energy_per_pressure']:.2f} | {got['_energy_from_stretch']:.2f} |"
            f" {got['_energy_truth_full']:.2f} | {free:.3f} | {fill:.2f} | {need:.2f} |"
        )
    return lines


def _fill_factors(measured: dict, code: str, published: float) -> tuple[float, float]:
    """Energy / (blocking force x free strain x l0) of the file's energy and of the published one [-]."""
    got = measured[code]
    l0 = got["_dataset"].geometry.flat_length_m
    scale = got["blocking_force_per_pressure"] * _ordering_value(measured, code, "free_strain") * l0
    return got["energy_per_pressure"] / scale, published / scale


def stretch_needed(energies, published: float) -> str:
    """The cycle's lowest strain at which the stretched-end energy equals ``published`` (linear between the
    simulated stretches), as text; outside their range, the side it lies on."""
    depth = [-100 * low for low in STRETCHES]  # percent, increasing; energies increase with it
    if published < energies[0]:
        return f"less than {depth[0]:g} %"
    if published > energies[-1]:
        return f"more than {depth[-1]:g} %"
    return f"{np.interp(published, energies, depth):.1f} %"


def stretch_lines(measured: dict) -> list[str]:
    """The generating models' stretched-end energy per MPa against the cycle's lowest strain [J/MPa], and the
    stretch at which it equals the published value."""
    published = _published("energy_per_pressure")
    return [
        f"| {code} | {published[code]:g} | "
        + " | ".join(f"{e:.2f}" for e in measured[code]["_energy_by_stretch"])
        + f" | {stretch_needed(measured[code]['_energy_by_stretch'], published[code])} |"
        for code in FIT_ORDER
    ]


def _published(metric: str) -> dict[str, float]:
    with open(DATA / "published_metrics.csv", newline="") as f:
        return {row["material"]: float(row["value"]) for row in csv.DictReader(f) if row["metric"] == metric}


def table5_lines() -> list[str]:
    """Table 5's FC densities turned back into the mass and volume they imply: do its energy and power agree?"""
    t = TABLE5
    mass_e, mass_p = t["energy_j"] / t["energy_j_per_kg"], t["power_w"] / t["power_w_per_kg"]
    vol_e, vol_p = t["energy_j"] / (t["energy_kj_per_m3"] * 1e3), t["power_w"] / (t["power_kw_per_m3"] * 1e3)
    fill = t["energy_j"] / (t["blocking_n"] * t["free_strain"] * t["l0_m"])
    return [
        f"- Table 5 gives FC {t['energy_j_per_kg']:g} J/(kg MPa) and {t['power_w_per_kg']:g} W/(kg MPa). With the"
        f" text's {t['energy_j']:g} J/MPa and {t['power_w']:g} W/MPa these imply a muscle of {1e3 * mass_e:.1f} g and"
        f" {1e3 * mass_p:.1f} g; by volume, {1e6 * vol_e:.1f} and {1e6 * vol_p:.1f} cm^3. The two agree within"
        f" {100 * abs(math.log(mass_e / mass_p)):.0f} % and {100 * abs(math.log(vol_e / vol_p)):.0f} %, so Table 5 and"
        " Figure 9 use the same energy: the 3.2 J/MPa is not a typo.",
        f"- Table 3 defines energy as the work of contracting quasi-statically to the free-strain length. Read from"
        f" the unstretched length (zero strain), a curve that starts at the blocking force ({t['blocking_n']:g} N/MPa)"
        f" and ends at the free strain ({100 * t['free_strain']:g} %) over l0 = {t['l0_m']:g} m holds at most"
        f" {t['blocking_n'] * t['free_strain'] * t['l0_m']:.2f} J/MPa (a rectangle); 3.2 J/MPa is {fill:.2f} of it."
        " A force that falls from the blocking force the way an ideal Peano muscle's does (steeply at first) fills"
        " about half; 0.85 needs a force nearly flat at the blocking force almost to the free strain.",
        "- The paper credits the slanted weave's higher energy (PCS, 4.8 J/MPa) to recoverable extension, which only"
        " counts if the work is taken from the stretched end of the cycle, not from zero strain. That reading is"
        " the second column below. How far the paper's cycles stretched is in Figure 8 only, not in the text; the"
        f" bundled protocol stretches to {100 * DEFAULT_PROTOCOL.stretch_strain:g} %.",
    ]


def edge_lines(measured: dict, margin: float = 0.05) -> list[str]:
    """Freed parameters within ``margin`` (in log, of the box width) of their calibration box edge."""
    lines = []
    for code in FIT_ORDER:
        truth = json.loads(measured[code]["_dataset"].provenance["parameters"])
        for name, (lo, hi) in free_box(code).items():
            x = (math.log(truth[name]) - math.log(lo)) / (math.log(hi) - math.log(lo))
            if x < margin or x > 1 - margin:
                edge = f"lower edge {lo:g}" if x < margin else f"upper edge {hi:g}"
                lines.append(f"- {code} `{name}` = {truth[name]:.4g} at the {edge} of its calibration box")
    return lines or ["- none"]


def main() -> None:
    """Measure every dataset and write ``experiments/datasets/CALIBRATION.md``."""
    argparse.ArgumentParser(description=__doc__).parse_args()  # --help, and no stray arguments
    measured = {code: measure(code) for code in FIT_ORDER}
    metric_table, metric_misses = metric_rows(measured)
    order_table, order_misses = ordering_rows(measured)
    conditions = [r for r in metric_table if "(sidecar)" in r]
    values = [r for r in metric_table if "(sidecar)" not in r]
    count = {k: sum(f"| {k}" in r for r in values) for k in ("pass", "FAIL", "n/a")}
    ccount = sum(r.endswith("| pass |") for r in conditions)
    ocount = {k: sum(r.endswith(f"| {k} |") for r in order_table) for k in ("pass", "FAIL")}
    ocount["n/a"] = sum("| n/a (" in r for r in order_table)
    shortfall = [measured[c]["_free_strain_truth"] - measured[c]["_free_strain_extrapolated"] for c in FIT_ORDER]
    ends = [measured[c]["_cycle_end"][1] for c in FIT_ORDER]
    rectangle = TABLE5["blocking_n"] * TABLE5["free_strain"] * TABLE5["l0_m"]  # FC's, PCS's bound [J/MPa]
    published_energy = _published("energy_per_pressure")
    short = {
        c: _fill_factors(measured, c, published_energy[c])
        for c in FIT_ORDER
        if measured[c]["energy_per_pressure"] < published_energy[c]
    }
    lines = [
        "# Calibration of the bundled datasets against the paper",
        "",
        "Generated by `experiments/calibration_report.py` from the files `peano_bayes/bundled/data/<CODE>.csv` (loaded",
        "with `peano_bayes.data.load`; metrics measured from the noisy signals with the Table 3 definitions of",
        "`peano_bayes.analysis.readouts`, see `peano_bayes/analysis/metrics.py` for the interpretation choices and the",
        "smoothing of step signals; means over 2 specimens x 3 repeats). Published values: Veale, Xie, Anderson",
        "(2016), as extracted in `published_metrics.csv` / `published_orderings.csv`. Tolerances: +-10 % explicit,",
        "+-20 % approximate, +-30 % ambiguous; conditions must match exactly; 'about equal' is within +-10 %.",
        "Hysteresis loss, free strain and energy come from the load cycles at the test pressure.",
        "",
        f"Summary: conditions {ccount}/{len(conditions)} match; metrics {count['pass']} pass, {count['FAIL']} fail,"
        f" {count['n/a']} not measurable;"
        f" orderings {ocount['pass']} pass, {ocount['FAIL']} fail, {ocount['n/a']} not measurable.",
        "",
        "## Published metrics and conditions",
        "",
        "| material | metric | published | measured | tolerance | verdict |",
        "|---|---|---|---|---|---|",
        *metric_table,
        "",
        "## Published orderings",
        "",
        "| metric | group | published ordering | checks (measured means) | verdict |",
        "|---|---|---|---|---|",
        *order_table,
        "",
        "## Free strain where the data reach it",
        "",
        "The load cycles run from the start tension's strain into extension and back to that strain; with the",
        f"loss, the relaxing branch ends at {min(ends):.1f}-{max(ends):.1f} N, below the start tension but far from",
        "zero, so their zero-force strain is a linear extrapolation over a curve that still bends. The stroke test",
        "ends lifting 5.5 N, nearer zero force for the 200 kPa muscles: the strain there is a lower bound on the free",
        "strain. Free strain counts as measured (as that lower bound) only where the lower of the two end forces is",
        f"at most {100 * REACHED_FRACTION:g} % of the blocking force at the test pressure; the metric tables above",
        "use that value, or the generating model's (a noise-free cycle started at"
        f" {REFERENCE_START_N:g} N) for reference where it is not measurable.",
        "",
        "| material | blocking force [N] | load cycle ends | its extrapolation | stroke test ends |"
        " free strain measured (lower bound) | generating model |",
        "|---|---|---|---|---|---|---|",
        *free_strain_lines(measured),
        "",
        "The extrapolation falls short of the generating model's own free strain by"
        f" {min(shortfall):.2f}-{max(shortfall):.2f}: the earlier",
        "calibration matched the paper's free strains with a measure that reads them low.",
        "",
        "## The paper's energy definition against its own numbers",
        "",
        *table5_lines(),
        "",
        "Energy per MPa of the bundled files under the two readings (relaxing branch, to the extrapolated free",
        f"strain), the generating model's from a cycle that relaxes to {REFERENCE_START_N:g} N, and the fill factor",
        "energy / (blocking force x free strain x l0) with the free strain of the section above (its lower bound or",
        "the model's); the last column is the fill factor the published energy would need. Both share the",
        "denominator, so their ratio, not their level, is the finding:",
        "",
        "| material | published | from zero strain | from the stretched end | model, full relaxation |"
        " free strain | fill factor | needed |",
        "|---|---|---|---|---|---|---|---|",
        *energy_lines(measured),
        "",
        f"Read from zero strain, the {len(short)} materials short of the paper need fill factors of"
        f" {min(need for _, need in short.values()):.2f}-{max(need for _, need in short.values()):.2f} against the"
        f" {min(fill for fill, _ in short.values()):.2f}-{max(fill for fill, _ in short.values()):.2f} of their",
        "curves, and PCS's needs more than a rectangle. That holds by the paper's own numbers too: the paper puts",
        "PCS's blocking force below PC's and its free strain below FC's, and FC has the highest blocking force of",
        f"the 200 kPa group ({TABLE5['blocking_n']:g} N/MPa) and {100 * TABLE5['free_strain']:g} % free strain, so"
        f" a PCS curve from zero strain holds at most {rectangle:.2f} J/MPa, below the",
        "4.8 J/MPa the paper reports. No curve reaches it. Read from the",
        "stretched end, the energy grows with how far the cycle stretched. The generating models' energy per MPa",
        "from noise-free cycles stretched to each lowest strain:",
        "",
        "| material | published | " + " | ".join(f"to {100 * low:g} %" for low in STRETCHES)
        + " | stretch that gives the published value |",
        "|---|---|" + "---|" * (len(STRETCHES) + 1),
        *stretch_lines(measured),
        "",
        "So the stretched-end reading is the only one consistent with the paper's numbers, but the stretch it needs",
        "differs from material to material (last column): no single stretch fits all eight. The paper's stretches",
        "are in Figure 8 only, so these files keep the zero-strain reading they were calibrated to. Adopting the",
        "stretched-end reading means re-calibrating with the stretches read off Figure 8.",
        "",
        "## Step responses",
        "",
        "Table 3 times speed, power and efficiency to the maximum overshoot. Where a response overshoots by less",
        "than 1 % of its rise, `peano_bayes.analysis.metrics.smoothed_step_metrics` ends the window at 99 % of "
        "the rise",
        "instead (both on these files and in the calibration): `peano_bayes.analysis.readouts.step_window` with",
        "`overshoot_fraction`. Without it, the window ends at the global maximum (the end of the record for a",
        "monotone response), which gives lower speeds for those materials.",
        "",
        "| material | overshoot (fraction of rise) | window end |",
        "|---|---|---|",
        *[
            f"| {code} | {measured[code]['overshoot']:.3f} |"
            f" {'first overshoot peak' if measured[code]['overshoot'] >= 0.01 else '99 % of the rise'} |"
            for code in FIT_ORDER
        ],
        "",
        "## Calibrated parameters at the edge of their box",
        "",
        "The box is the calibration's physically sensible range (`experiments/calibrate.py`, `FREE`), much",
        "narrower than `PARAMETERS` bounds. A parameter at its edge is where the fit wanted to go further:",
        "",
        *edge_lines(measured),
        "",
        "## Misses and reasons",
        "",
        miss_summary(metric_misses + order_misses),
        "",
        *[f"- {label}: {reason}" for label, reason in metric_misses + order_misses],
        "",
    ]
    (OUT / "CALIBRATION.md").write_text("\n".join(lines), encoding="utf-8")
    print(lines[10])
    print(f"wrote {OUT / 'CALIBRATION.md'}")


if __name__ == "__main__":
    main()
