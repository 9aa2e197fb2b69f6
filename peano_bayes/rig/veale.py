"""A virtual rig on another physics: Veale's static force-balance model (:mod:`peano_bayes.physics.reference`),
for data no model of peano_bayes generated."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from .. import materials
from ..data import Dataset
from ..defaults import MAX_PRESSURE_KPA
from ..errors import PeanoBayesInputError
from ..materials import GEOMETRY, MaterialSpec
from ..physics.reference import VEALE_TABLE2, veale_blocking_force, veale_force, veale_free_strain
from .measure import (
    _check_added,
    _check_run,
    _check_signals,
    _other_physics_dataset,
    _other_physics_runs,
    _static_truths,
    _Truth,
)
from .protocol import DEFAULT_NOISE, DEFAULT_PROTOCOL, RigNoise, RigProtocol

# --- the same protocol on another physics: Veale's force-balance model ------------------------------------------

#: The tests Veale's static model can run (it has no dynamics, so no step response).
VEALE_TESTS: tuple[str, ...] = ("load_cycle", "blocking", "stroke")
#: Fields of :class:`~peano_bayes.physics.reference.VealeParameters` that vary between specimens (stiffnesses).
VEALE_VARYING = ("tensile_ka_n_per_m", "tensile_kb_n_per_m2", "bending_quartic_n_per_m5", "bending_linear_n_per_m2")
#: Halvings of the strain bracket in :func:`_veale_strain_at_force` (0.5 in strain to below 1e-15).
_VEALE_BISECTIONS = 60


@jax.jit
def _veale_strain_at_force(pressure_pa, force_n, params):
    """Strain [-] at which Veale's muscle carries ``force_n`` [N] at each ``pressure_pa`` [Pa] (any shape).

    The force falls monotonically with strain between a strongly stretched muscle (-0.3) and the free strain
    (force 0), so bisection over that bracket finds the one root of a positive ``force_n``."""
    pressure_pa = jnp.asarray(pressure_pa, dtype=jnp.float64)

    def halve(_, bracket):
        low, high = bracket
        mid = 0.5 * (low + high)
        above = veale_force(pressure_pa, mid, params) > force_n
        return jnp.where(above, mid, low), jnp.where(above, high, mid)

    start = (jnp.full(pressure_pa.shape, -0.3), veale_free_strain(pressure_pa, params))
    low, high = jax.lax.fori_loop(0, _VEALE_BISECTIONS, halve, start)
    return 0.5 * (low + high)


_veale_force = jax.jit(veale_force)
_veale_blocking_force = jax.jit(veale_blocking_force)


def _veale_truths(params, spec: MaterialSpec, protocol: RigProtocol, tests, cycle_pressures=None) -> list[_Truth]:
    """The noise-free signals of every test condition of one specimen of Veale's model, in session order; load
    cycles at ``cycle_pressures`` [Pa] (default: 0 and the test pressure)."""
    truths = _static_truths(
        lambda p, strain: _veale_force(p, strain, params),
        lambda p, force: _veale_strain_at_force(p, force, params),
        lambda p: _veale_blocking_force(p, params),
        spec,
        protocol,
        tests,
        cycle_pressures,
    )
    _check_signals("Veale's model", truths)
    return truths


def simulate_veale_dataset(
    material: str | MaterialSpec,
    params=None,
    *,
    seed: int = 0,
    noise: RigNoise = DEFAULT_NOISE,
    specimen_spread: float = 0.05,
    repeats: int = 3,
    specimens: int = 2,
    tests: Iterable[str] = VEALE_TESTS,
    protocol: RigProtocol = DEFAULT_PROTOCOL,
    cycle_pressures_pa: Iterable[float] | None = None,
    added: Mapping[tuple[str, int], Mapping[str, np.ndarray]] | None = None,
) -> Dataset:
    """The rig's quasi-static protocol run on Veale's force-balance model instead of peano_bayes' own physics:
    data from another model of the same muscle, for checks that must not share the fitted model's assumptions
    (an inference on it cannot succeed by construction).

    Same protocol, conditions, sensor noise, seeding and file layout as :func:`simulate_dataset`, with the
    signals of :func:`~peano_bayes.physics.reference.veale_force`: load cycles from the strain at the start
    tension down to ``stretch_strain`` and back (static: no hysteresis), the blocking force along the pressure
    ramp, and the stroke test's strain where the muscle carries the hanging load. ``params``: a
    :class:`~peano_bayes.physics.reference.VealeParameters` (default: the paper's Table 2); each specimen
    multiplies the stiffnesses of :data:`VEALE_VARYING` by its own log-normal factor of sigma
    ``specimen_spread``. ``tests``: some of :data:`VEALE_TESTS`. ``cycle_pressures_pa``: the load cycles'
    pressures [Pa], one condition each (default: 0 and the material's test pressure; each in [0, 1 MPa]).
    ``added``: ``(test, run) -> {signal: (n,) array}`` added to those runs' noise-free signals before the sensor
    noise (strain, pressure or force; for a benchmark that transplants an effect onto this physics), recorded in
    the provenance (only with the default load-cycle pressures). The provenance names the generating model and
    every specimen's parameters. Raises :class:`~peano_bayes.errors.PeanoBayesInputError` for bad input (a step
    test among them: the static model has no dynamics), before anything is simulated.
    """
    params = VEALE_TABLE2 if params is None else params
    spec = materials.material(material)
    seed, repeats, specimens, tests = _check_run(seed, repeats, specimens, tests, specimen_spread)
    if "step" in tests:
        raise PeanoBayesInputError(
            "Veale's force-balance model is static and cannot run a step test; expected some of "
            + ", ".join(VEALE_TESTS)
        )
    if cycle_pressures_pa is not None:
        cycle_pressures_pa = tuple(float(p) for p in cycle_pressures_pa)
        limit_pa = MAX_PRESSURE_KPA * 1e3
        if not cycle_pressures_pa or not all(math.isfinite(p) and 0 <= p <= limit_pa for p in cycle_pressures_pa):
            raise PeanoBayesInputError(
                f"cycle_pressures_pa must be one or more pressures in [0, {limit_pa:g}] Pa, got {cycle_pressures_pa!r}"
            )
    n_conditions = 2 if cycle_pressures_pa is None else len(cycle_pressures_pa)
    if added is not None and n_conditions != 2:
        raise PeanoBayesInputError("added: give it with the default load-cycle pressures only")
    added = _check_added(added, tests, repeats)
    base, runs, per_specimen = _other_physics_runs(
        params,
        VEALE_VARYING,
        lambda own: _veale_truths(own, spec, protocol, tests, cycle_pressures_pa),
        seed=seed,
        specimens=specimens,
        spread=specimen_spread,
        noise=noise,
        repeats=repeats,
        added=added,
    )
    runs_note = None
    if cycle_pressures_pa is not None:
        runs_note = "; ".join(
            f"load_cycle runs {c * repeats}-{(c + 1) * repeats - 1} at {p / 1e3:g} kPa"
            for c, p in enumerate(cycle_pressures_pa)
        )
    return _other_physics_dataset(
        spec,
        GEOMETRY,
        runs,
        source="synthetic: Veale's force-balance model (peano_bayes.rig.simulate_veale_dataset), not a "
        "measurement and not peano_bayes' own physics",
        model={"model": "veale_force_balance", "parameters": json.dumps(base)},
        per_specimen=per_specimen,
        seed=seed,
        noise=noise,
        spread=specimen_spread,
        protocol=protocol,
        repeats=repeats,
        added=added,
        runs_note=runs_note,
    )


__all__ = ["VEALE_TESTS", "VEALE_VARYING", "simulate_veale_dataset"]
