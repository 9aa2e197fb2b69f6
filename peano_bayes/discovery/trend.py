"""Whether misfit trends in time within test conditions: the evidence discovery asks before it calls a structure
that a smooth session baseline absorbed a drift (:func:`within_condition_trend`), rather than a misfit ordered
with the conditions."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
from scipy import stats

from .data import Covariates

#: Run-mean pressures of one test within this fraction (plus :data:`CONDITION_ATOL_PA`) of the previous run's
#: are one test condition (repeats of one commanded level or ramp).
CONDITION_RTOL = 0.05
CONDITION_ATOL_PA = 1000.0


def joined_covariates(first: Covariates, second: Covariates) -> Covariates:
    """The covariates of two residual vectors laid end to end (fit runs, then held-out runs)."""
    return Covariates(
        **{f.name: np.concatenate([getattr(first, f.name), getattr(second, f.name)]) for f in fields(Covariates)}
    )


def within_condition_trend(r: np.ndarray, covariates, alpha: float) -> dict:
    """Whether residuals ``r`` (n,) trend with session time **within** test conditions, across their repeats.

    When conditions run in order of pressure, a trend over the session and a pressure-dependent misfit are the
    same pattern; only repeats of one condition at different times separate them. The discovery loop passes the
    fitted and the held-out runs together (:func:`joined_covariates`): the held-out repeat is each condition's
    last, the one furthest in time. Each run is reduced to its
    mean residual and mean session time; runs of one test whose mean pressures agree (:data:`CONDITION_RTOL`)
    form a condition; the pooled within-condition slope of residual on time (each condition centred on its own
    means) is tested with a t test whose variance comes from the scatter about that slope (so correlated noise
    within a run does not inflate it). Returns ``slope_per_hour`` [residual units per hour], ``t``, ``p``
    (two-sided), ``runs``, ``conditions`` (with two or more runs), ``df`` and ``shows_in_time`` (``p < alpha``;
    False when no condition has repeats at two times, ``df < 1``).
    """
    keys = list(zip(covariates.test, covariates.run, strict=True))
    runs = sorted(set(keys), key=lambda k: (str(k[0]), int(k[1])))
    index = {k: i for i, k in enumerate(runs)}
    member = np.array([index[k] for k in keys])
    ok = np.isfinite(r)
    count = np.bincount(member[ok], minlength=len(runs))
    mean = lambda v: np.bincount(member[ok], weights=v[ok], minlength=len(runs)) / np.maximum(count, 1)  # noqa: E731
    run_r, run_t, run_p = mean(r), mean(covariates.session_s), mean(covariates.pressure_pa)
    condition = np.full(len(runs), -1)
    label = 0
    for test in sorted({str(k[0]) for k in runs}):
        mine = [i for i, k in enumerate(runs) if str(k[0]) == test and count[i] > 0]
        previous = None
        for i in sorted(mine, key=lambda i: run_p[i]):
            if previous is not None and run_p[i] - previous > CONDITION_RTOL * abs(previous) + CONDITION_ATOL_PA:
                label += 1
            condition[i] = label
            previous = run_p[i]
        label += 1
    dt, dr, conditions = [], [], 0
    for c in np.unique(condition[condition >= 0]):
        rows = condition == c
        if rows.sum() < 2 or np.ptp(run_t[rows]) <= 0:
            continue
        conditions += 1
        dt.append(run_t[rows] - run_t[rows].mean())
        dr.append(run_r[rows] - run_r[rows].mean())
    n_runs = int(sum(len(x) for x in dt))
    df = n_runs - conditions - 1
    out = {"runs": n_runs, "conditions": conditions, "df": df}
    if df < 1:
        return out | {"slope_per_hour": float("nan"), "t": float("nan"), "p": float("nan"), "shows_in_time": False}
    dt, dr = np.concatenate(dt), np.concatenate(dr)
    slope = float(dt @ dr / (dt @ dt))
    scatter = float(np.sum((dr - slope * dt) ** 2) / df)
    se = np.sqrt(scatter / (dt @ dt)) if scatter > 0 else 0.0
    t = slope / se if se > 0 else float("inf") * np.sign(slope)
    p = float(2.0 * stats.t.sf(abs(t), df)) if np.isfinite(t) else 0.0
    return out | {"slope_per_hour": 3600.0 * slope, "t": float(t), "p": p, "shows_in_time": bool(p < alpha)}


__all__ = ["CONDITION_ATOL_PA", "CONDITION_RTOL", "joined_covariates", "within_condition_trend"]
