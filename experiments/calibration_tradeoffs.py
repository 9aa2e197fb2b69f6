"""Measure what each "compromise" miss of the calibration costs: force it to pass, see what fails instead.

``experiments/datasets/CALIBRATION.md`` lists published numbers and orderings that the bundled datasets miss.
Some misses are definitional (energy, free strain: explained in their own sections); the others are called
compromises: the calibration (``experiments/calibrate.py``) traded them against other targets of the same
parameters. This script measures each such trade. For every probe below it re-runs the calibration of one
material (for an ordering, of each of its two in turn) from its calibrated parameters with one extra residual:
a hinge of weight ``WEIGHT`` that is zero once the missed target sits inside its tolerance (by ``INSIDE`` of the
tolerance) and grows outside it. Every ordering with every other material is active (their calibrated metrics,
from the calibration cache). Then it compares the Table 3 metrics of noise-free rig signals before and after:
which targets and orderings of that material the forced fit passes and fails.

Run ``python experiments/calibration_tradeoffs.py`` (about 3 min on 2 cores); writes
``experiments/datasets/calibration_tradeoffs.json``, which ``experiments/calibration_report.py`` reads to put the
measured cost beside each compromise in CALIBRATION.md. Verdicts here are on noise-free signals of one specimen,
so they can differ from the report's (noisy files, two specimens) near a tolerance edge.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from calibrate import (
    CACHE,
    EQUAL_BAND,
    ORDERINGS,
    free_box,
    model_metrics,
    read_targets,
    residuals,
)
from scipy.optimize import least_squares

from peano_bayes.rig import RigSimulationError

OUT = Path(__file__).parent / "datasets" / "calibration_tradeoffs.json"
#: Weight of the forcing hinge against the calibration's own residuals (each ~1 at a tolerance edge).
WEIGHT = 10.0
#: The forced value must sit this fraction of its tolerance inside the edge (a margin against the noisy files).
INSIDE = 0.2
#: Function evaluations of each forced fit (the calibration's own budget).
MAX_NFEV = 60

#: The compromise misses of CALIBRATION.md: (label as the report writes it, forced check, materials refitted).
#: A check is ("metric", name) for a published number, or ("ordering", metric, a, relation, b). An ordering is
#: forced once on each of its two materials: either one's fit may be the one that gave it away.
PROBES = (
    ("FC hysteresis_loss", ("metric", "hysteresis_loss"), ("FC",)),
    ("TP efficiency", ("metric", "efficiency"), ("TP",)),
    ("FC efficiency", ("metric", "efficiency"), ("FC",)),
    ("ordering speed: PCS > TPC", ("ordering", "speed", "PCS", ">", "TPC"), ("PCS", "TPC")),
    (
        "ordering power_per_pressure: PCS about equal to PC",
        ("ordering", "power_per_pressure", "PCS", "=", "PC"),
        ("PCS", "PC"),
    ),
    (
        "ordering blocking_force_per_pressure: PC > PCS",
        ("ordering", "blocking_force_per_pressure", "PC", ">", "PCS"),
        ("PCS", "PC"),
    ),
    (
        "ordering hysteresis_loss: TFC about equal to FC",
        ("ordering", "hysteresis_loss", "TFC", "=", "FC"),
        ("FC", "TFC"),
    ),
)


def _gap(values: dict, others: dict, metric: str, a: str, b: str, code: str) -> float:
    va = values[metric] if a == code else others[a]["metrics"][metric]
    vb = values[metric] if b == code else others[b]["metrics"][metric]
    return math.log(va / vb)


def verdicts(code: str, values: dict, others: dict, targets) -> dict[str, tuple[bool, float]]:
    """Every published target and ordering of ``code``: label -> (passes, value) on noise-free metrics.

    A target passes within its tolerance; an ordering ``>`` passes when the log ratio is positive, ``=`` when
    it is within ``EQUAL_BAND`` (the report's rules). The value is the relative error, or the log ratio.
    """
    out = {}
    for metric, target, tol in targets.get(code, []):
        error = values[metric] / target - 1.0
        out[f"{code} {metric}"] = (abs(error) <= tol, error)
    for metric, a, relation, b in ORDERINGS:
        if code not in (a, b):
            continue
        gap = _gap(values, others, metric, a, b, code)
        shown = "about equal to" if relation == "=" else ">"
        out[f"ordering {metric}: {a} {shown} {b}"] = (gap > 0 if relation == ">" else abs(gap) <= EQUAL_BAND, gap)
    return out


def forcing(code: str, check: tuple, others: dict, targets):
    """The hinge residual [-] that is zero once ``check`` holds with margin, as a function of the metrics."""
    if check[0] == "metric":
        metric = check[1]
        target, tol = next((t, tol) for m, t, tol in targets[code] if m == metric)
        edge = math.log1p(tol * (1.0 - INSIDE))

        def hinge(values):
            return max(0.0, abs(math.log(values[metric] / target)) - edge) / tol

        return hinge
    _, metric, a, relation, b = check

    def hinge(values):
        gap = _gap(values, others, metric, a, b, code)
        if relation == ">":
            return max(0.0, INSIDE * EQUAL_BAND - gap) / EQUAL_BAND
        return max(0.0, abs(gap) - (1.0 - INSIDE) * EQUAL_BAND) / EQUAL_BAND

    return hinge


def probe(code: str, check: tuple, others: dict, targets) -> dict:
    """Refit ``code`` with ``check`` forced; the before/after verdicts, parameters and costs."""
    box = free_box(code)
    names = list(box)
    lo, hi = np.log([box[n][0] for n in names]), np.log([box[n][1] for n in names])
    start = others[code]["parameters"]
    x0 = np.clip(np.log([start[n] for n in names]), lo + 1e-6, hi - 1e-6)
    hinge = forcing(code, check, others, targets)
    fitted = {c: v for c, v in others.items() if c != code}

    def fun(x):
        params = dict(zip(names, np.exp(x), strict=True))
        try:
            values = model_metrics(code, params)
        except RigSimulationError:
            values = {}
        # A failed simulation: the calibration's own residuals say 30, and so does the forcing term.
        extra = WEIGHT * hinge(values) if values else 30.0
        return np.append(residuals(code, params, fitted, targets, values=values), extra)

    tic = time.perf_counter()
    result = least_squares(fun, x0, bounds=(lo, hi), method="trf", diff_step=1e-2, max_nfev=MAX_NFEV)
    params = {n: float(v) for n, v in zip(names, np.exp(result.x), strict=True)}
    after = model_metrics(code, params)
    before = others[code]["metrics"]
    at_edge = [n for n, x, a, b in zip(names, result.x, lo, hi, strict=True) if min(x - a, b - x) < 0.05 * (b - a)]
    return {
        "material": code,
        "check": list(check),
        "before": {k: [bool(p), float(v)] for k, (p, v) in verdicts(code, before, fitted, targets).items()},
        "after": {k: [bool(p), float(v)] for k, (p, v) in verdicts(code, after, fitted, targets).items()},
        "forcing_residual": float(result.fun[-1]),
        "cost_before": float(others[code]["cost"]),
        "cost_after_without_forcing": float(0.5 * result.fun[:-1] @ result.fun[:-1]),
        "parameters": params,
        "parameters_at_box_edge": at_edge,
        "seconds": time.perf_counter() - tic,
    }


def main(argv=None) -> None:
    """Run every probe and write ``calibration_tradeoffs.json`` atomically."""
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    targets = read_targets()
    others = {p.stem: json.loads(p.read_text()) for p in sorted(CACHE.glob("*.json"))}
    results: dict[str, dict[str, dict]] = {}
    for label, check, codes in PROBES:
        for code in codes:
            print(f"{label}: refitting {code} with it forced", flush=True)
            r = results.setdefault(label, {})[code] = probe(code, check, others, targets)
            lost = [k for k, (p, _) in r["after"].items() if not p and r["before"][k][0]]
            print(f"  forced {'held' if r['after'][label][0] else 'did NOT hold'}; now failing: {lost}", flush=True)
    payload = {"weight": WEIGHT, "inside": INSIDE, "max_nfev": MAX_NFEV, "probes": results}
    fd, tmp = tempfile.mkstemp(dir=OUT.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(payload, f, indent=1)
    os.replace(tmp, OUT)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
