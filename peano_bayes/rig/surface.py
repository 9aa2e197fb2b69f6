"""A virtual rig on a third physics: the Sarosi-type force surface of :mod:`peano_bayes.physics.reference`
(:func:`~peano_bayes.physics.reference.surface_force`), with all four rig tests, for data that neither
peano_bayes' model nor Veale's generated.

The surface is Table 1's upper branch less its force at zero pressure and strain (Veale, Xie, Anderson 2016,
eq. 4), ``F(p, eps) = p (a1 exp(a3 eps) + a4 eps + a5) + a2 (exp(a3 eps) - 1)`` [N]; the step test hangs the
Table 4 step load on it with Sarosi's damping (eq. 6), ``B = 2 zeta sqrt(|dF/deps| / l0 m)``, at the damping
ratio Table 1's loop gives at the test pressure (eqs 8-10: 0.24 at 100 kPa, 0.16 at 200 kPa, 0.12 at 400 kPa).
Its muscle pressure is the supply pressure (an open inlet: the benchmark's truth has one too), so the step run
records no flow. Table 1 was fitted on the paper's four-tube validation muscle, so the dataset declares that
muscle (:data:`~peano_bayes.physics.VALIDATION_GEOMETRY`: w = 15 mm, l = 46 mm, l0 = 0.06 m).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping

import jax
import numpy as np

from .. import materials
from ..data import Dataset
from ..materials import MaterialSpec
from ..physics import VALIDATION_GEOMETRY
from ..physics.reference import (
    SURFACE_TABLE1,
    SurfaceParameters,
    sarosi_damping_ratio,
    simulate_surface_step,
    surface_force,
    surface_strain_at_force,
)
from .measure import (
    _check_added,
    _check_run,
    _check_signals,
    _other_physics_dataset,
    _other_physics_runs,
    _sample_times,
    _static_truths,
    _Truth,
)
from .protocol import DEFAULT_NOISE, DEFAULT_PROTOCOL, RIG_TESTS, RigNoise, RigProtocol

#: The tests the surface runs: all four.
SURFACE_TESTS: tuple[str, ...] = RIG_TESTS
#: Fields of :class:`~peano_bayes.physics.reference.SurfaceParameters` that vary between specimens: the relaxed
#: muscle's stretch term (a2) and the strain slope of the pressure term (a4), the surface's stiffnesses; its
#: pressure areas (a1, a5) and its exponent (a3) are shared, as Veale's rig shares his model's areas.
SURFACE_VARYING = ("stretch_force_n", "slope_area_m2")
#: RK4 steps per step-test sample interval (0.5 ms at the benchmark's 250 Hz, 0.125 ms at the rig's 1 kHz).
STEP_SUBSTEPS = 8

_surface_force = jax.jit(surface_force)
_surface_strain = jax.jit(surface_strain_at_force)
_surface_step = jax.jit(simulate_surface_step, static_argnames="substeps")


def _surface_truths(params, spec: MaterialSpec, protocol: RigProtocol, tests) -> list[_Truth]:
    """The noise-free signals of every test condition of one specimen of the surface, in session order."""
    truths = _static_truths(
        lambda p, strain: _surface_force(p, strain, params),
        lambda p, force: _surface_strain(p, force, params),
        lambda p: _surface_force(p, 0.0, params),
        spec,
        protocol,
        tests,
    )
    if "step" in tests:
        p_test = spec.test_pressure_pa
        t = _sample_times(protocol.step_rate_hz, protocol.step_duration_s)
        supply = np.where(t >= protocol.step_delay_s, p_test, 0.0)
        zeta = float(sarosi_damping_ratio(p_test))
        result = _surface_step(
            t, supply, spec.step_load_n, params, zeta, VALIDATION_GEOMETRY.flat_length_m, substeps=STEP_SUBSTEPS
        )
        strain = np.asarray(result.strain, dtype=float)
        truths.append(_Truth("step", 0, t, supply, strain, None, supply, None, spec.step_load_n))
    _check_signals("the force surface", truths)
    return truths


def simulate_surface_dataset(
    material: str | MaterialSpec,
    params: SurfaceParameters | None = None,
    *,
    seed: int = 0,
    noise: RigNoise = DEFAULT_NOISE,
    specimen_spread: float = 0.05,
    repeats: int = 3,
    specimens: int = 2,
    tests: Iterable[str] = SURFACE_TESTS,
    protocol: RigProtocol = DEFAULT_PROTOCOL,
    added: Mapping[tuple[str, int], Mapping[str, np.ndarray]] | None = None,
) -> Dataset:
    """The rig's protocol run on the Sarosi-type force surface instead of peano_bayes' own physics: data from a
    third model of the muscle (an empirical surface, not a force balance), for checks that must not share the
    fitted model's assumptions.

    Same protocol, conditions, sensor noise, seeding and file layout as :func:`~peano_bayes.rig.simulate_dataset`:
    load cycles at 0 kPa and the material's test pressure from the strain at the start tension down to
    ``stretch_strain`` and back (static: no hysteresis), the blocking force along the pressure ramp, the stroke
    test's strain where the surface carries the hanging load, and the step response of the step load to a supply
    step (module docstring). ``params``: a :class:`~peano_bayes.physics.reference.SurfaceParameters` (default
    Table 1's upper branch); each specimen multiplies the fields of :data:`SURFACE_VARYING` by its own
    log-normal factor of sigma ``specimen_spread``. ``tests``: some of :data:`SURFACE_TESTS`. ``added``:
    ``(test, run) -> {signal: (n,) array}`` added to those runs' noise-free signals before the sensor noise
    (strain, pressure or force; for a benchmark that transplants an effect onto this physics), recorded in the
    provenance. The provenance names the generating model, its parameters and every specimen's.

    Returns a :class:`~peano_bayes.data.Dataset` on :data:`~peano_bayes.physics.VALIDATION_GEOMETRY`. Raises
    :class:`~peano_bayes.errors.PeanoBayesInputError` for bad input before anything is simulated.
    """
    params = SURFACE_TABLE1 if params is None else params
    spec = materials.material(material)
    seed, repeats, specimens, tests = _check_run(seed, repeats, specimens, tests, specimen_spread)
    added = _check_added(added, tests, repeats)
    base, runs, per_specimen = _other_physics_runs(
        params,
        SURFACE_VARYING,
        lambda own: _surface_truths(own, spec, protocol, tests),
        seed=seed,
        specimens=specimens,
        spread=specimen_spread,
        noise=noise,
        repeats=repeats,
        added=added,
    )
    model = {"model": "sarosi_type_surface", "parameters": json.dumps(base)}
    if "step" in tests:
        model["step_damping_ratio"] = repr(float(sarosi_damping_ratio(spec.test_pressure_pa)))
    return _other_physics_dataset(
        spec,
        VALIDATION_GEOMETRY,
        runs,
        source="synthetic: a Sarosi-type force surface (peano_bayes.rig.simulate_surface_dataset), not a "
        "measurement and not peano_bayes' own physics",
        model=model,
        per_specimen=per_specimen,
        seed=seed,
        noise=noise,
        spread=specimen_spread,
        protocol=protocol,
        repeats=repeats,
        added=added,
    )


__all__ = ["STEP_SUBSTEPS", "SURFACE_TESTS", "SURFACE_VARYING", "simulate_surface_dataset"]
