"""Test helpers shared across modules."""

from __future__ import annotations


def central_difference(fn, params: dict, name: str, rel_step: float = 1e-6, abs_step: float = 1e-9):
    """d fn(params) / d params[name] by a central difference with a relative step."""
    x = float(params[name])
    h = max(abs(x) * rel_step, abs_step)
    up = dict(params, **{name: x + h})
    down = dict(params, **{name: x - h})
    return (float(fn(up)) - float(fn(down))) / (2.0 * h)
