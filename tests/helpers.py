"""Test helpers shared across modules."""

from __future__ import annotations


def jit_lean(fn, **kwargs):
    """``jax.jit(fn)`` compiled at XLA's backend optimization level 0, for a program a test builds once and
    runs a handful of times (a gradient check, a sweep of the parameter box): compiling is then most of its
    cost, and level 0 compiles such programs about a quarter faster. XLA's CPU fast-math is off, so the level
    changes results by round-off only. The sampling tests, which run their programs thousands of times, keep
    the suite's level (``tests/conftest.py``)."""
    import jax

    return jax.jit(fn, compiler_options={"xla_backend_optimization_level": 0}, **kwargs)


def central_difference(fn, params: dict, name: str, rel_step: float = 1e-6, abs_step: float = 1e-9):
    """d fn(params) / d params[name] by a fourth-order central difference.

    The step is ``rel_step * |x|``, or ``abs_step`` when x is 0. Truncation error is O(h^4), so a step large
    enough to stay clear of round-off noise still gives an accurate derivative.
    """
    x = float(params[name])
    h = abs(x) * rel_step if x != 0.0 else abs_step

    def at(dx):
        return float(fn(dict(params, **{name: x + dx})))

    return (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h)


# The recovery case (tests/conftest.py ``recovered``): TP load cycles from known parameters, three of them free.
RECOVERY_FREE = ("tensile_ka_n_per_m", "bending_k1_n", "friction_pressure_fraction")


def recovery_truth() -> dict:
    from peano_bayes.physics import DEFAULT_CONFIG

    return dict(DEFAULT_CONFIG.nominal_parameters(), tensile_ka_n_per_m=8e3, bending_k1_n=1.0)


def minimal_summary(**fields) -> dict:
    """A ``summary.json`` with the fields a fit always writes (:class:`~peano_bayes.inference.summary.Summary`'s
    required ones, for material TP) and ``fields`` over them: what a test writes beside a result."""
    return {
        "material": "TP",
        "label": "TP",
        "dataset": "virtual",
        "prior": "TP",
        "tests": ["load_cycle", "blocking", "stroke"],
        "model": {},
        "seed": 0,
        "n_walkers": 32,
        "steps": 100,
        "convergence": {"converged": True},
        "parameters": {},
        "units": {},
        **fields,
    }
