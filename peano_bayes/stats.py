"""Small frequentist helpers the validation studies and discovery share: Holm's multiplicity adjustment and the
Wilson interval of a binomial proportion. Pure numpy/scipy, no I/O."""

from __future__ import annotations

from scipy import stats


def holm(p: dict) -> dict:
    """Holm's step-down adjustment of the p-values ``p`` (name -> p): the i-th smallest times (m - i), made
    non-decreasing, capped at 1 (name -> adjusted p)."""
    names = sorted(p, key=p.get)
    out, running = {}, 0.0
    for i, name in enumerate(names):
        running = max(running, min(1.0, (len(names) - i) * p[name]))
        out[name] = running
    return out


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval (low, high) of a proportion seen ``k`` times in ``n`` trials."""
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


__all__ = ["holm", "wilson_interval"]
