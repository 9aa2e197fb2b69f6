"""The paper's four rig tests (Veale et al. 2016, Tables 3 and 4) as pure functions (params, protocol) -> signals.

Every function is ``jit``-, ``vmap``- and ``grad``-able in ``params`` (a dict of named scalars, see
:data:`peano_bayes.physics.model.PARAMETERS`). Each time step solves one monotone scalar equation for the tube
half-angle, with implicit-function gradients (``jax.lax.custom_root``). The quasi-static tests take three plain
Newton steps from the root extrapolated from the previous two samples and keep them where they converge
(:func:`_newton_first`); a member where they do not (very stiff stiffening springs, friction at rest, ramps from
0 kPa where the half-angle changes by decades) takes a bracket in log(theta) narrower than 1e-3 around the
extrapolated root, then safeguarded Newton (:func:`_predicted_bracket`). The step test bisects a bracket around
the previous sample's root, or the whole range, at every substep.
Each result carries ``max_residual``, the largest equilibrium error left by the solver.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .geometry import PAPER_GEOMETRY, Geometry
from .model import (
    DEFAULT_CONFIG,
    GRAVITY_M_PER_S2,
    THETA_MAX,
    THETA_MIN,
    WATER_DENSITY_KG_PER_M3,
    ModelConfig,
    chain,
    initial_state,
    total_force,
    volume_m3,
)

_LOG_THETA = (float(jnp.log(THETA_MIN)), float(jnp.log(THETA_MAX)))
#: Newton corrections per sample after the bisection; quasi-static tests converge to ~1e-12 m in three.
QUASI_STATIC_ITERATIONS = 3
#: Newton corrections per step-test substep after its bisection (see :data:`_DYNAMIC_BRACKET_ATOL`).
DYNAMIC_ITERATIONS = 3
COLD_START_ITERATIONS = 4
#: A Newton step shorter than this (in log theta) ends the loop once the minimum number of steps is taken; the
#: safeguarded steps stop at the latest after _NEWTON_MAX_STEPS (a bracket of 1e-3 bisected to round-off).
_NEWTON_XTOL = 1e-10
_NEWTON_MAX_STEPS = 48
_BISECTION_MAX_STEPS = 256
_BRACKET_ATOL = 1e-3
_LOCAL_HALF_WIDTH = 0.01
#: The predicted bracket's half-width and the outward search's first step, in units of the bracket tolerance:
#: a bracket narrower than the tolerance needs no bisection, and 80 % of TP's posterior solves fall inside it.
_PREDICTED_HALF_WIDTH = 0.45
_SEARCH_FIRST_STEP = 2.0
#: How the quasi-static scans start each sample's solve (read when a simulation is traced, so that
#: ``experiments/bench_solve.py`` can time the routes in one process):
#:
#: - ``"newton_first"``: three plain Newton steps from the root extrapolated from the previous two samples,
#:   accepted where they converge (:func:`_newton_first`); the bracketed route only at the samples where some
#:   member's did not;
#: - ``"bracket_first"``: a bracket around the extrapolated root at every sample, then safeguarded Newton;
#: - ``"previous"``: a bracket of +-0.01 around the previous sample's root, bisected, then Newton.
QUASI_STATIC_ROUTE = "newton_first"
#: Plain Newton steps the fast route takes, and the largest last step (in log theta) it accepts: Newton
#: converges quadratically, so the root is then within about (f''/2f') 1e-12 of the last iterate. From the
#: extrapolated root, two steps leave the stroke test's last step at a median 6e-6 (99 % of TP's members
#: fail the tolerance), three at 1.5e-10 (3 % fail).
_FAST_NEWTON_STEPS = 3
_FAST_XTOL = 1e-6
#: Steps this short (in log theta, about 1e-12 relative in theta) are round-off, which need not contract.
_ROUND_OFF_STEP = 1e-12
#: The step test's residual (the inertial term m/dt^2 makes it steep) and the sub-micrometre smoothing of
#: friction at rest make Newton unreliable from 1e-3 (and, on TP, from 1e-5); bisect to 1e-7 first, after
#: which three Newton steps reach the root that bisecting to 1e-9 and five steps reach (predicted strain within
#: 1.7e-8, the same force imbalance) at 1.2-1.8x the speed: ``experiments/bench_step_solve.py``.
_DYNAMIC_BRACKET_ATOL = 1e-7


# --- protocols ----------------------------------------------------------------------------------------------


class LoadCycle(eqx.Module):
    """Imposed strain history at a pressure: the rig stretches and relaxes the muscle slowly.

    ``time_s``, ``strain`` [-] and ``pressure_pa`` are arrays of shape (n,); the first sample is the start
    (the paper starts from the start tension, see :func:`static_strain`).
    """

    time_s: jnp.ndarray
    strain: jnp.ndarray
    pressure_pa: jnp.ndarray


class Blocking(eqx.Module):
    """Pressure ramp ``pressure_pa`` (n,) over ``time_s`` (n,) with the muscle held at zero strain."""

    time_s: jnp.ndarray
    pressure_pa: jnp.ndarray


class Stroke(eqx.Module):
    """Pressure ramp ``pressure_pa`` (n,) over ``time_s`` (n,) lifting a hanging load ``load_n`` [N] (paper: 5.5 N)."""

    time_s: jnp.ndarray
    pressure_pa: jnp.ndarray
    load_n: float = 5.5


class Step(eqx.Module):
    """Supply pressure step ``supply_pa`` (n,) over ``time_s`` (n,) through the inlet restriction into the
    muscle, lifting an inertial load of weight ``load_n`` [N]. The muscle starts at rest, in equilibrium with the
    load at ``supply_pa[0]``. ``substeps`` integration steps are taken per sample interval."""

    time_s: jnp.ndarray
    supply_pa: jnp.ndarray
    load_n: float
    substeps: int = eqx.field(static=True, default=1)


# --- results ------------------------------------------------------------------------------------------------


class ForceResult(NamedTuple):
    force_n: jnp.ndarray  # (n,) force at the load cell
    half_angle_rad: jnp.ndarray  # (n,)
    max_residual: jnp.ndarray  # () largest equilibrium error [m or N]


class StrokeResult(NamedTuple):
    strain: jnp.ndarray  # (n,)
    half_angle_rad: jnp.ndarray
    max_residual: jnp.ndarray


class StepResult(NamedTuple):
    strain: jnp.ndarray  # (n,) contraction strain
    velocity_m_per_s: jnp.ndarray  # (n,) load velocity, positive when lifting
    pressure_pa: jnp.ndarray  # (n,) muscle pressure
    flow_m3_per_s: jnp.ndarray  # (n,) flow into the muscle
    force_n: jnp.ndarray  # (n,) muscle force on the load
    max_residual: jnp.ndarray


# --- the scalar solve ---------------------------------------------------------------------------------------


def _newton_steps(fn, z, iterations: int, lo, hi, increasing: bool):
    """Safeguarded Newton on ``fn(z) = 0`` inside the bracket ``[lo, hi]`` that holds the root: at least
    ``iterations`` steps, then more (up to :data:`_NEWTON_MAX_STEPS`) while the last step was longer than
    :data:`_NEWTON_XTOL`. Each evaluation narrows the bracket by the residual's sign, and a Newton step that
    would leave it is replaced by the bracket's midpoint. Where the residual is smooth on the bracket's scale the
    steps are plain Newton steps and stop after ``iterations``; where it is nearly a step (stiff friction at rest:
    its force changes over the sub-micrometre Dahl length), plain Newton overshoots and stops far from the root
    (0.9 N of force imbalance in a stroke test, against its 0.01 N tolerance), and the bracket then bisects.
    A loop, not unrolled: each copy of the residual in a scan's body is traced, differentiated and compiled
    again. ``increasing`` says whether the residual rises with ``z``."""

    def unfinished(carry):
        _, _, _, step, k = carry
        return (k < iterations) | ((jnp.abs(step) > _NEWTON_XTOL) & (k < _NEWTON_MAX_STEPS))

    def newton(carry):
        z, lo, hi, _, k = carry
        r, dr = jax.jvp(fn, (z,), (jnp.ones_like(z),))
        root_above = (r < 0.0) == increasing
        lo, hi = jnp.where(root_above, jnp.maximum(lo, z), lo), jnp.where(root_above, hi, jnp.minimum(hi, z))
        candidate = z - r / dr
        inside = jnp.isfinite(candidate) & (candidate >= lo) & (candidate <= hi)
        new = jnp.clip(jnp.where(inside, candidate, 0.5 * (lo + hi)), *_LOG_THETA)
        return new, lo, hi, new - z, k + 1

    start = (z, jnp.minimum(lo, z), jnp.maximum(hi, z), jnp.asarray(jnp.inf, dtype=jnp.result_type(z)), 0)
    return jax.lax.while_loop(unfinished, newton, start)[0]


def _root_above(residual, z, increasing: bool):
    """Whether the root of the monotone ``residual`` lies above ``z`` (read from the residual's sign)."""
    return (residual(z) < 0.0) == increasing


def _bisect(residual, lo, hi, atol: float, increasing: bool):
    """``(lo, hi)`` halved until narrower than ``atol`` (at most ``_BISECTION_MAX_STEPS`` halvings), keeping
    the root inside; an interval already narrower costs nothing (under ``vmap``, only the members that need
    halving make the batch loop). Only the residual's sign is read, so no tangent flows through the loop."""

    def wide(carry):
        lo, hi, k = carry
        return (hi - lo >= atol) & (k < _BISECTION_MAX_STEPS)

    def halve(carry):
        lo, hi, k = carry
        mid = lo + 0.5 * (hi - lo)
        above = _root_above(residual, mid, increasing)
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid), k + 1

    lo, hi, _ = jax.lax.while_loop(wide, halve, (jnp.asarray(lo), jnp.asarray(hi), 0))
    return lo, hi


def _bisection(residual, atol: float, increasing: bool, lower=_LOG_THETA[0], upper=_LOG_THETA[1]):
    """Bracketed bisection over ``[lower, upper]`` in log(theta), by default the whole range; the midpoint of
    the last interval, once it is narrower than ``atol`` (:func:`_bisect`).

    The orientation is known (no detection), so a root beyond the range converges to its nearest end:
    an ideal muscle with no bending reaches its free strain only at theta = pi/2. This is a ``lax.while_loop``
    of our own rather than ``optimistix.root_find`` because the latter's implicit-function rule is traced under
    every derivative of the simulation and puts a host callback (a runtime check) into the program, which bars
    it from the persistent compilation cache and costs seconds of tracing per simulation.
    """
    lo, hi = _bisect(residual, lower, upper, atol, increasing)
    return lo + 0.5 * (hi - lo)


def _predicted_bracket(residual, increasing: bool, z_pred, atol: float):
    """A bracket ``(lo, hi)`` narrower than ``atol`` that holds the root, found from a predicted root ``z_pred``.

    Two residuals at ``z_pred +- 0.45 atol``; where they straddle the root that is the bracket. Where they do not,
    the missing side is searched outward in steps that grow eightfold from ``2 atol`` (to the range end, where a
    root beyond the range converges to the end as in :func:`_bisection`), and the bracket found is bisected to
    ``atol``. Both searches are while loops, so under ``vmap`` a batch pays for them only at the samples where
    some member's prediction missed. A prediction that is not finite, or residual signs that contradict each
    other (a residual flat to round-off), start from the whole range; like :func:`_bisection`, each loop stops
    after :data:`_BISECTION_MAX_STEPS` at most.
    """
    h = _PREDICTED_HALF_WIDTH * atol
    a, b = jnp.clip(z_pred - h, *_LOG_THETA), jnp.clip(z_pred + h, *_LOG_THETA)
    above_a, above_b = _root_above(residual, a, increasing), _root_above(residual, b, increasing)
    lo = jnp.where(above_b, b, jnp.where(above_a, a, _LOG_THETA[0]))
    hi = jnp.where(~above_a, a, jnp.where(~above_b, b, _LOG_THETA[1]))
    lo_known, hi_known = above_a | (a <= _LOG_THETA[0]), ~above_b | (b >= _LOG_THETA[1])
    # A residual flat to round-off across the pair can give inconsistent signs: fall back to the whole range.
    muddled = ~(lo <= hi) | ~jnp.isfinite(z_pred)
    lo, hi = jnp.where(muddled, _LOG_THETA[0], lo), jnp.where(muddled, _LOG_THETA[1], hi)
    lo_known, hi_known = lo_known | muddled, hi_known | muddled

    def searching(carry):
        _, _, lo_known, hi_known, _, k = carry
        return ~(lo_known & hi_known) & (k < _BISECTION_MAX_STEPS)

    def search(carry):
        lo, hi, lo_known, hi_known, step, k = carry
        x = jnp.where(lo_known, jnp.minimum(lo + step, _LOG_THETA[1]), jnp.maximum(hi - step, _LOG_THETA[0]))
        above = _root_above(residual, x, increasing)
        at_end = jnp.where(lo_known, x >= _LOG_THETA[1], x <= _LOG_THETA[0])
        lo = jnp.where(above | (at_end & ~lo_known), x, lo)
        hi = jnp.where(~above | (at_end & lo_known), x, hi)
        return lo, hi, lo_known | above | at_end, hi_known | ~above | at_end, 8.0 * step, k + 1

    first_step = jnp.asarray(_SEARCH_FIRST_STEP * atol, dtype=jnp.result_type(lo))
    lo, hi, *_ = jax.lax.while_loop(searching, search, (lo, hi, lo_known, hi_known, first_step, 0))
    return _bisect(residual, lo, hi, atol, increasing)


def _newton_first(fn, z_pred, increasing: bool, iterations: int, atol: float):
    """Root of the monotone ``fn(log theta)`` from a predicted root ``z_pred``: plain Newton first, the bracket
    only where it fails.

    :data:`_FAST_NEWTON_STEPS` Newton steps from ``z_pred``; a member is done where its iterate is finite, the
    last step was shorter than :data:`_FAST_XTOL` and no longer than half the step before it (the iterates
    contract, as Newton's do near a root), unless it is round-off. The residual is monotone, so its one root
    is where Newton converges. Members that are not done take the bracketed route (:func:`_predicted_bracket`,
    then :func:`_newton_steps`). That route sits in a while loop that runs at most once, so under ``vmap`` a
    batch pays for it only at the samples where some member needs it (a ``lax.cond`` would become a select and
    run it at every sample). On TP's default tests 97-99 % of the members finish on the fast route, and 3-6 of
    its 200-427 samples per row group need the bracket for some member of a 152-walker batch. Checking each
    step's slope sign as well made the fast route about 1.8x slower on TP (inside XLA; not pursued).
    """
    z = jnp.clip(z_pred, *_LOG_THETA)
    step = previous = jnp.zeros_like(z)
    for _ in range(_FAST_NEWTON_STEPS):
        r, dr = jax.jvp(fn, (z,), (jnp.ones_like(z),))
        previous, step = step, -r / dr
        z = jnp.clip(z + step, *_LOG_THETA)  # a step that is not finite leaves z NaN, and the member not done
    contracting = (jnp.abs(step) <= 0.5 * jnp.abs(previous)) | (jnp.abs(step) < _ROUND_OFF_STEP)
    done = jnp.isfinite(z) & (jnp.abs(step) < _FAST_XTOL) & contracting

    def bracketed(carry):
        z_fast, done = carry
        start = jnp.where(done, z_fast, z_pred)  # members already done start at their root: a cheap bracket
        lo, hi = _predicted_bracket(fn, increasing, start, atol)
        z_slow = _newton_steps(fn, 0.5 * (lo + hi), iterations, lo, hi, increasing)
        return jnp.where(done, z_fast, z_slow), jnp.ones_like(done)

    return jax.lax.while_loop(lambda carry: ~carry[1], bracketed, (z, done))[0]


def _solve_log_theta(
    residual,
    increasing: bool,
    iterations: int = QUASI_STATIC_ITERATIONS,
    z_prev=None,
    atol: float = _BRACKET_ATOL,
    z_pred=None,
):
    """Root of a monotone ``residual(log theta)``, with implicit-function gradients.

    A bracket narrower than ``atol`` in log(theta), then ``iterations`` Newton steps (more while they still move
    the root, :func:`_newton_steps`). ``increasing`` says whether the residual rises with theta. Three ways to the
    bracket, by what the caller knows:

    - ``z_pred``, a predicted root (the quasi-static scans extrapolate the previous two samples' roots):
      :func:`_predicted_bracket`. On TP's posterior (152 walkers drawn from its Laplace approximation) this costs
      4.4 residuals per sample against 9.6 for the ``z_prev`` route, and Newton 3.5 steps against 5.6; the
      bundled materials' quasi-static simulations run 1.05-2.1x faster (``experiments/bench_solve.py``).
    - ``z_prev``, the previous sample's root (the step test, whose 1e-7 bracket no extrapolation hits):
      ``z_prev +- _LOCAL_HALF_WIDTH`` is tried first, and where it holds the root a fixed number of bisection
      steps (a ``fori_loop``: one copy of the residual in the program) finishes the job. Members whose local
      bracket misses get the whole range from :func:`_bisection` first; the others hand it an empty interval, so
      under ``vmap`` its loop costs a batch something only at the samples where some member needs it.
    - neither (a cold start): :func:`_bisection` over the whole range.
    """
    if z_pred is not None and QUASI_STATIC_ROUTE == "newton_first":
        solve = lambda fn, z: _newton_first(fn, z, increasing, iterations, atol)  # noqa: E731
        return _implicit_root(residual, z_pred, solve)
    if z_pred is not None:
        lo, hi = _predicted_bracket(residual, increasing, jax.lax.stop_gradient(z_pred), atol)
        z_guess = 0.5 * (lo + hi)
    elif z_prev is None:
        z_guess = _bisection(residual, atol, increasing)
        lo, hi = z_guess - atol, z_guess + atol
    else:
        z_prev = jax.lax.stop_gradient(z_prev)
        near_lo = jnp.clip(z_prev - _LOCAL_HALF_WIDTH, *_LOG_THETA)
        near_hi = jnp.clip(z_prev + _LOCAL_HALF_WIDTH, *_LOG_THETA)
        r_lo, r_hi = residual(near_lo), residual(near_hi)
        holds = (r_lo <= 0.0) & (r_hi >= 0.0) if increasing else (r_lo >= 0.0) & (r_hi <= 0.0)
        lower = jnp.where(holds, z_prev, _LOG_THETA[0])
        upper = jnp.where(holds, z_prev, _LOG_THETA[1])
        z_far = _bisection(residual, atol, increasing, lower, upper)
        lo = jnp.where(holds, near_lo, z_far - atol)
        hi = jnp.where(holds, near_hi, z_far + atol)
        def halve(_, bracket):
            lo, hi = bracket
            mid = 0.5 * (lo + hi)
            below = (residual(mid) > 0.0) == increasing  # the root lies below mid
            return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

        lo, hi = jax.lax.fori_loop(0, math.ceil(math.log2(2.0 * _LOCAL_HALF_WIDTH / atol)), halve, (lo, hi))
        z_guess = 0.5 * (lo + hi)
    lo, hi = jax.lax.stop_gradient(lo), jax.lax.stop_gradient(hi)
    solve = lambda fn, z: _newton_steps(fn, z, iterations, lo, hi, increasing)  # noqa: E731
    return _implicit_root(residual, z_guess, solve)


def _implicit_root(residual, z_guess, solve):
    """``solve(residual, z_guess)`` with implicit-function gradients (a scalar root: the tangent is y / f')."""
    return jax.lax.custom_root(residual, jax.lax.stop_gradient(z_guess), solve, lambda g, y: y / g(1.0))


def _warm_start(z_prev, z_prev2) -> dict:
    """The quasi-static scans' start for :func:`_solve_log_theta` from the previous two samples' roots."""
    if QUASI_STATIC_ROUTE not in ("newton_first", "bracket_first", "previous"):
        raise ValueError(
            f"QUASI_STATIC_ROUTE must be 'newton_first', 'bracket_first' or 'previous', got {QUASI_STATIC_ROUTE!r}"
        )
    return {"z_prev": z_prev} if QUASI_STATIC_ROUTE == "previous" else {"z_pred": 2.0 * z_prev - z_prev2}


def _strain_residual(strain, pressure_pa, dt_s, state, params, config, geometry, relaxed=False):
    l0 = geometry.flat_length_m

    def residual(z):
        link = chain(jnp.exp(z), pressure_pa, dt_s, state, params, config, geometry, relaxed)
        return link.shortening_m - strain * l0

    return residual


def _force_residual(load_n, pressure_pa, dt_s, state, params, config, geometry, relaxed=False):
    def residual(z):
        link = chain(jnp.exp(z), pressure_pa, dt_s, state, params, config, geometry, relaxed)
        return total_force(link.shortening_m / geometry.flat_length_m, link, params, config, geometry)[0] - load_n

    return residual


def _relaxed_start(residual_fn, target, pressure_pa, params, config, geometry, increasing):
    """Solve the first sample from the relaxed state; returns (log theta, chain)."""
    state = initial_state(config)
    z = _solve_log_theta(
        residual_fn(target, pressure_pa, 1.0, state, params, config, geometry, True),
        increasing,
        COLD_START_ITERATIONS,
    )
    link = chain(jnp.exp(z), pressure_pa, 1.0, state, params, config, geometry, relaxed=True)
    return z, link


def static_strain(
    params, pressure_pa, force_n, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
):
    """Equilibrium strain [-] of a relaxed muscle (no history) at ``pressure_pa`` [Pa] under tension ``force_n`` [N].

    Used to place the start of a load cycle at the start tension, and for the free strain (``force_n = 0``).
    """
    _, link = _relaxed_start(_force_residual, force_n, pressure_pa, params, config, geometry, increasing=False)
    return link.shortening_m / geometry.flat_length_m


def static_force(
    params, pressure_pa, strain, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
):
    """Force [N] of a relaxed muscle (no history) held at contraction ``strain`` [-] at ``pressure_pa`` [Pa].

    The counterpart of :func:`static_strain`; at ``strain = 0`` it is the blocking force.
    """
    _, link = _relaxed_start(_strain_residual, strain, pressure_pa, params, config, geometry, increasing=True)
    return total_force(strain, link, params, config, geometry)[0]


def _strain_controlled(params, time_s, strain, pressure_pa, config, geometry) -> ForceResult:
    z0, link0 = _relaxed_start(_strain_residual, strain[0], pressure_pa[0], params, config, geometry, True)
    force0, state0 = total_force(strain[0], link0, params, config, geometry)
    dts = jnp.diff(time_s)

    def step(carry, inputs):
        state, z_prev, z_prev2 = carry
        eps, p, dt = inputs
        residual = _strain_residual(eps, p, dt, state, params, config, geometry)
        z = _solve_log_theta(residual, increasing=True, **_warm_start(z_prev, z_prev2))
        link = chain(jnp.exp(z), p, dt, state, params, config, geometry)
        force, state = total_force(eps, link, params, config, geometry)
        return (state, z, z_prev), (force, z, jnp.abs(link.shortening_m - eps * geometry.flat_length_m))

    _, (force, z, err) = jax.lax.scan(step, (state0, z0, z0), (strain[1:], pressure_pa[1:], dts))
    return ForceResult(jnp.concatenate([force0[None], force]), jnp.exp(jnp.concatenate([z0[None], z])), jnp.max(err))


# --- the four tests -----------------------------------------------------------------------------------------


def simulate_load_cycle(
    params, protocol: LoadCycle, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
) -> ForceResult:
    """Load cycle: force [N] along an imposed strain history at the protocol's pressure.

    Hysteresis comes out of the loss elements of ``config`` (friction, Maxwell, Kelvin), not from two curves.
    """
    return _strain_controlled(params, protocol.time_s, protocol.strain, protocol.pressure_pa, config, geometry)


#: The quasi-static sweep of :func:`free_strain`: samples and duration [s] of the contraction from zero strain to
#: :data:`FREE_STRAIN_SWEEP_END`. At 801 samples the zero crossing is within 5e-6 of that at 3201 on every
#: bundled muscle, and ten times slower (4000 s) changes it by less than 1e-6 (no rate effect left).
FREE_STRAIN_SAMPLES = 801
FREE_STRAIN_DURATION_S = 400.0
#: Where the sweep ends: just short of the ideal Peano unit's full contraction, 1 - 2/pi.
FREE_STRAIN_SWEEP_END = 0.999 * (1.0 - 2.0 / math.pi)


def free_strain(params, pressure_pa, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY):
    """Free strain [-]: the contraction at which the force of a muscle held at ``pressure_pa`` [Pa] falls to zero
    as it contracts quasi-statically from zero strain (strain-controlled, :data:`FREE_STRAIN_SAMPLES` over
    :data:`FREE_STRAIN_DURATION_S`): the contracting branch of a load cycle at that pressure, followed to zero
    force instead of read off by extrapolation. Friction is developed against the contraction, so with
    friction this is below the relaxed equilibrium :func:`static_strain` at zero force; without friction or
    viscous loss it equals it. The zero crossing is interpolated linearly between samples; a muscle whose force
    stays positive to :data:`FREE_STRAIN_SWEEP_END` returns that strain, and NaN where the simulation is not
    finite before any crossing."""
    time_s = jnp.linspace(0.0, FREE_STRAIN_DURATION_S, FREE_STRAIN_SAMPLES)
    strain = time_s / FREE_STRAIN_DURATION_S * FREE_STRAIN_SWEEP_END
    pressure = jnp.full_like(time_s, 1.0) * pressure_pa
    force = simulate_load_cycle(params, LoadCycle(time_s, strain, pressure), config=config, geometry=geometry).force_n
    crosses = (force[:-1] > 0) & (force[1:] <= 0)
    i = jnp.argmax(crosses)
    f0, f1 = force[i], force[i + 1]
    at_zero = strain[i] + (strain[i + 1] - strain[i]) * f0 / jnp.where(f0 - f1 > 0, f0 - f1, 1.0)
    finite = jnp.all(jnp.isfinite(force))
    never = jnp.where(finite & (force[-1] > 0), FREE_STRAIN_SWEEP_END, jnp.nan)
    return jnp.where(jnp.any(crosses), at_zero, jnp.where(force[0] <= 0, 0.0, never))


def simulate_blocking(
    params, protocol: Blocking, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
) -> ForceResult:
    """Blocking test: force [N] of the muscle held at its unstretched length (strain 0) along a pressure ramp."""
    strain = jnp.zeros_like(protocol.pressure_pa)
    return _strain_controlled(params, protocol.time_s, strain, protocol.pressure_pa, config, geometry)


def simulate_stroke(
    params, protocol: Stroke, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
) -> StrokeResult:
    """Stroke test: strain [-] of the muscle lifting a hanging load quasi-statically along a pressure ramp."""
    l0 = geometry.flat_length_m
    load = protocol.load_n
    z0, link0 = _relaxed_start(_force_residual, load, protocol.pressure_pa[0], params, config, geometry, False)
    _, state0 = total_force(link0.shortening_m / l0, link0, params, config, geometry)

    def step(carry, inputs):
        state, z_prev, z_prev2 = carry
        p, dt = inputs
        residual = _force_residual(load, p, dt, state, params, config, geometry)
        z = _solve_log_theta(residual, increasing=False, **_warm_start(z_prev, z_prev2))
        link = chain(jnp.exp(z), p, dt, state, params, config, geometry)
        strain = link.shortening_m / l0
        force, state = total_force(strain, link, params, config, geometry)
        return (state, z, z_prev), (strain, z, jnp.abs(force - load))

    carry0 = (state0, z0, z0)
    _, (strain, z, err) = jax.lax.scan(step, carry0, (protocol.pressure_pa[1:], jnp.diff(protocol.time_s)))
    return StrokeResult(
        jnp.concatenate([(link0.shortening_m / l0)[None], strain]),
        jnp.exp(jnp.concatenate([z0[None], z])),
        jnp.max(err),
    )


def _pressure_drop_pa(flow_m3_per_s, params, config: ModelConfig):
    """Pressure lost across the inlet restriction [Pa] at ``flow_m3_per_s`` (signed, water)."""
    if config.flow == "laminar":
        return flow_m3_per_s / params["laminar_conductance_m3_per_s_pa"]
    velocity = flow_m3_per_s / params["orifice_area_m2"]
    return 0.5 * WATER_DENSITY_KG_PER_M3 * velocity * jnp.abs(velocity)


def _load_damping_n(velocity, params, config: ModelConfig):
    if not config.damping:
        return jnp.zeros_like(velocity)
    up = jnp.maximum(velocity, 0.0)
    down = jnp.minimum(velocity, 0.0)
    return (
        params["damping_up_ns_per_m"] * up
        + params["damping_down_ns_per_m"] * down
        + params["damping_quadratic_ns2_per_m2"] * jnp.abs(velocity) * velocity
    )


def simulate_step(
    params, protocol: Step, *, config: ModelConfig = DEFAULT_CONFIG, geometry: Geometry = PAPER_GEOMETRY
) -> StepResult:
    """Step response: the supply pressure steps, water flows through the inlet restriction into the changing
    muscle volume, and the muscle lifts the inertial load of weight ``protocol.load_n``.

    Load: ``m y'' = F - m g - damping(y')``. Water is incompressible, so the muscle pressure follows from the
    flow the volume change demands: ``p = p_supply - dp(dV/dt)``. Both are integrated by backward Euler, which
    reduces each substep to one monotone equation in the half-angle and stays stable for any stiffness (an
    explicit load update diverged in stiff corners of the parameter box). Backward Euler adds numerical damping
    of about ``omega dt / 2`` to a mode of frequency ``omega``; ``substeps`` keeps it small. ``max_residual`` is
    the largest force imbalance [N]. Returns strain, velocity, muscle pressure, flow, force.
    """
    l0 = geometry.flat_length_m
    load = protocol.load_n
    mass = load / GRAVITY_M_PER_S2
    n_sub = protocol.substeps
    supply0 = protocol.supply_pa[0]
    z0, link0 = _relaxed_start(_force_residual, load, supply0, params, config, geometry, False)
    y0 = link0.shortening_m
    force0, state0 = total_force(y0 / l0, link0, params, config, geometry)
    volume0 = volume_m3(jnp.exp(z0), params, geometry)

    def substep(carry, inputs):
        state, y, v, volume, z_prev = carry
        supply, dt = inputs

        def advance(z_):
            """Everything at the end of the substep, given the half-angle there."""
            flow = (volume_m3(jnp.exp(z_), params, geometry) - volume) / dt
            p = supply - _pressure_drop_pa(flow, params, config)
            link = chain(jnp.exp(z_), p, dt, state, params, config, geometry)
            y_new = link.shortening_m
            force, new_state = total_force(y_new / l0, link, params, config, geometry)
            return y_new, force, new_state, p, flow

        def residual(z_):
            # Backward Euler on the load: m (v_new - v) / dt = F - m g - damping(v_new), v_new = (y_new - y) / dt.
            # Every term rises with theta, so the root is unique and bracketed.
            y_new, force, *_ = advance(z_)
            v_new = (y_new - y) / dt
            return mass * (v_new - v) / dt - force + load + _load_damping_n(v_new, params, config)

        z = _solve_log_theta(
            residual, increasing=True, iterations=DYNAMIC_ITERATIONS, z_prev=z_prev, atol=_DYNAMIC_BRACKET_ATOL
        )
        y_new, force, new_state, p, flow = advance(z)
        v_new = (y_new - y) / dt
        err = jnp.abs(residual(z))
        return (new_state, y_new, v_new, volume_m3(jnp.exp(z), params, geometry), z), (p, flow, force, err)

    def sample(carry, inputs):
        supply, dt = inputs
        sub_inputs = (jnp.full(n_sub, supply), jnp.full(n_sub, dt / n_sub))
        carry, (p, flow, force, err) = jax.lax.scan(substep, carry, sub_inputs)
        _, y, v, _, _ = carry
        return carry, (y / l0, v, p[-1], flow[-1], force[-1], jnp.max(err))

    carry0 = (state0, y0, jnp.zeros(()), volume0, z0)
    _, (strain, v, p, flow, force, err) = jax.lax.scan(
        sample, carry0, (protocol.supply_pa[1:], jnp.diff(protocol.time_s))
    )
    first = lambda a0, a: jnp.concatenate([jnp.asarray(a0, dtype=a.dtype)[None], a])  # noqa: E731
    return StepResult(
        first(y0 / l0, strain),
        first(0.0, v),
        first(supply0, p),
        first(0.0, flow),
        first(force0, force),
        jnp.max(err),
    )


__all__ = [
    "Blocking",
    "ForceResult",
    "LoadCycle",
    "Step",
    "StepResult",
    "Stroke",
    "StrokeResult",
    "free_strain",
    "simulate_blocking",
    "simulate_load_cycle",
    "simulate_step",
    "simulate_stroke",
    "static_force",
    "static_strain",
]
