"""Numbers in the generated markdown reports: one format, so every table rounds alike."""

from __future__ import annotations

import math


def format_number(x, *, nonfinite: str | None = "n/a") -> str:
    """``x`` to three significant digits (``f"{x:.3g}"``); ``None``, NaN or an infinity as ``nonfinite``, or, if
    that is None, as Python writes them (``None``, ``nan``, ``inf``, ``-inf``)."""
    if x is None or not math.isfinite(x):
        return str(x) if nonfinite is None else nonfinite
    return f"{x:.3g}"


__all__ = ["format_number"]
