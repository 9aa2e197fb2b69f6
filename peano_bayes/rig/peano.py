"""The virtual rig on peano_bayes's own physics: the paper's four tests on a modelled muscle."""

from __future__ import annotations

import collections
import dataclasses
import string
from collections.abc import Callable, Iterable, Mapping, Sequence
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .. import materials
from ..data import Dataset
from ..errors import PeanoBayesInputError
from ..materials import GEOMETRY, MaterialSpec
from ..physics import DEFAULT_CONFIG, PARAMETERS, ModelConfig, simulate
from ..physics.simulate import static_strain
from .measure import (
    MAX_FORCE_ERROR_N,
    MAX_POSITION_ERROR_M,
    _check_mounts,
    _check_run,
    _check_specimen_values,
    _checked,
    _fill_optional,
    _model_provenance,
    _provenance,
    _sample_times,
    _session_runs,
    _Truth,
)
from .protocol import (
    _SPECIMEN_STREAM,
    DEFAULT_NOISE,
    DEFAULT_PROTOCOL,
    RIG_TESTS,
    RigNoise,
    RigProtocol,
    apply_quirks,
    check_quirks,
    resolve_parameters,
    specimen_parameters,
)


@partial(jax.jit, static_argnames="config")
def _load_cycle(params, time_s, pressure_pa, start_tension_n, stretch_strain, min_stretch, *, config):
    """Imposed strain (n,) and force [N] (n,) of a cycle from the start-tension strain down and back."""
    start = static_strain(params, pressure_pa, start_tension_n, config=config)
    low = jnp.minimum(stretch_strain, start - min_stretch)
    end_s = time_s[-1]
    strain = jnp.interp(time_s, jnp.stack([0.0, 0.5 * end_s, end_s]), jnp.stack([start, low, start]))
    result = simulate.simulate_load_cycle(
        params, simulate.LoadCycle(time_s, strain, jnp.full_like(time_s, pressure_pa)), config=config
    )
    return (strain, result.force_n), result.max_residual


@partial(jax.jit, static_argnames="config")
def _blocking(params, time_s, pressure_pa, *, config):
    result = simulate.simulate_blocking(params, simulate.Blocking(time_s, pressure_pa), config=config)
    return (result.force_n,), result.max_residual


@partial(jax.jit, static_argnames="config")
def _stroke(params, time_s, pressure_pa, load_n, *, config):
    result = simulate.simulate_stroke(params, simulate.Stroke(time_s, pressure_pa, load_n), config=config)
    return (result.strain,), result.max_residual


@partial(jax.jit, static_argnames=("config", "substeps"))
def _step(params, time_s, supply_pa, load_n, *, config, substeps):
    result = simulate.simulate_step(params, simulate.Step(time_s, supply_pa, load_n, substeps), config=config)
    return (result.strain, result.pressure_pa, result.flow_m3_per_s), result.max_residual


def _specimen_truths(params, spec: MaterialSpec, config, protocol: RigProtocol, tests, progress, label):
    """The noise-free signals of every test condition of one specimen, in session order."""
    jparams = {k: jnp.asarray(v, dtype=jnp.float64) for k, v in params.items()}
    p_test = spec.test_pressure_pa
    slow = partial(_sample_times, protocol.quasi_static_rate_hz)
    truths = []
    if "load_cycle" in tests:
        t = slow(protocol.cycle_duration_s)
        for condition, p in enumerate((0.0, p_test)):
            output = _load_cycle(
                jparams, t, p, spec.start_tension_n, protocol.stretch_strain, protocol.min_stretch, config=config
            )
            strain, force = _checked(f"{label}: load cycle at {p / 1e3:g} kPa", output, MAX_POSITION_ERROR_M, "m")
            truths.append(_Truth("load_cycle", condition, t, np.full_like(t, p), strain, force))
            progress(f"{label}: load cycle at {p / 1e3:g} kPa")
    if "blocking" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        output = _blocking(jparams, t, ramp, config=config)
        (force,) = _checked(f"{label}: blocking", output, MAX_POSITION_ERROR_M, "m")
        truths.append(_Truth("blocking", 0, t, ramp, np.zeros_like(t), force))
        progress(f"{label}: blocking to {p_test / 1e3:g} kPa")
    if "stroke" in tests:
        t = slow(protocol.ramp_duration_s)
        ramp = p_test * t / t[-1]
        output = _stroke(jparams, t, ramp, protocol.stroke_load_n, config=config)
        (strain,) = _checked(f"{label}: stroke", output, MAX_FORCE_ERROR_N, "N")
        truths.append(_Truth("stroke", 0, t, ramp, strain, load_n=protocol.stroke_load_n))
        progress(f"{label}: stroke lifting {protocol.stroke_load_n:g} N")
    if "step" in tests:
        t = _sample_times(protocol.step_rate_hz, protocol.step_duration_s)
        supply = np.where(t >= protocol.step_delay_s, p_test, 0.0)
        output = _step(jparams, t, supply, spec.step_load_n, config=config, substeps=protocol.step_substeps)
        strain, pressure, flow = _checked(f"{label}: step", output, MAX_FORCE_ERROR_N, "N")
        truths.append(_Truth("step", 0, t, pressure, strain, None, supply, flow, spec.step_load_n))
        progress(f"{label}: step to {p_test / 1e3:g} kPa lifting {spec.step_load_n:g} N")
    return truths


def simulate_dataset(
    material: str | MaterialSpec,
    true_params: Mapping[str, float] | None = None,
    *,
    config: ModelConfig = DEFAULT_CONFIG,
    quirks: Iterable[str] = (),
    seed: int = 0,
    noise: RigNoise = DEFAULT_NOISE,
    drift: bool = False,
    specimen_spread: float = 0.05,
    repeats: int = 3,
    specimens: int = 2,
    tests: Iterable[str] = RIG_TESTS,
    protocol: RigProtocol = DEFAULT_PROTOCOL,
    progress: Callable[[str], None] | None = None,
    added_compliances: Iterable[float] = (0.0,),
    specimen_values: Sequence[Mapping[str, float]] | None = None,
) -> Dataset:
    """Run the paper's test protocol on virtual specimens of a material; return the rig dataset.

    **Arguments:**
    - ``material``: a Table 4 code (``"FC"``) or a :class:`~peano_bayes.materials.MaterialSpec`; it sets
      the test pressure, step load and start tension (:mod:`peano_bayes.materials`).
    - ``true_params``: parameter values [SI units, names of :data:`~peano_bayes.physics.PARAMETERS`]. Every
      parameter the final configuration reads and ``true_params`` lacks takes ``PARAMETERS[name].nominal``,
      also for quirks (note: the nominal load damping is 0, so ``nonlinear_damping`` needs
      ``damping_*`` values to have an effect). Names the configuration does not read are ignored.
    - ``config``: the model the data come from; ``quirks``: names of :data:`QUIRKS` (effects) whose elements
      are switched on in ``config`` (``series_compliance`` -> ``mount``, ``hysteresis`` -> Dahl friction,
      ``viscoelastic_relaxation`` -> one parallel Maxwell branch, ``series_viscoelastic`` -> one series
      Kelvin-Voigt unit, ``strain_stiffening`` -> ``extension``,
      ``threshold_pressure`` -> ``threshold``, ``nonlinear_damping`` -> ``damping``).
    - ``seed``: every random draw derives from it; the same arguments give the same dataset, and the same bytes
      through :func:`peano_bayes.data.save`. Streams are keyed by (specimen, test, run), so a
      smaller run reproduces the matching part of a larger one.
    - ``noise``: :class:`RigNoise`; ``drift``: add the force sensor's linear drift, zeroed at the start of each
      specimen's session and growing through the runs in session order (runs follow without pauses).
    - ``specimen_spread``: sigma of the log-normal factor on each stiffness-like parameter per specimen
      (:func:`specimen_parameters`); ``specimens`` (named A, B, ...) and ``repeats`` per test (paper: 2 and 3).
    - ``tests``: which of ``load_cycle``, ``blocking``, ``stroke``, ``step`` to run (default: all);
      ``protocol``: :class:`RigProtocol`; ``progress``: called with a line of text after each simulated test.
    - ``added_compliances`` [m/N]: the mounts each specimen is tested on, as the known compliance each adds in
      series with the specimen's own mount (default one mount, nothing added). With several, the whole
      protocol runs once per mount, in this order, and every run records its mount in
      ``added_compliance_m_per_n``; run numbers continue across mounts (the second mount's load cycles at
      0 kPa are runs ``2 repeats .. 3 repeats-1``). A positive one switches the mount element on (the
      specimen's own mount then defaults to 0, rigid).
    - ``specimen_values``: one mapping per specimen (``specimens`` of them) of parameter values [SI] that
      specimen has, replacing its drawn value of each name given (for studies that draw the specimens
      themselves, such as the hierarchical simulation-based calibration); every name and value is checked as
      in ``true_params``, and every name must be one the final configuration reads. ``true_params`` (the
      provenance's ``parameters``) then holds the values the specimens were not given.

    **Returns:** a :class:`~peano_bayes.data.Dataset` on :data:`~peano_bayes.physics.PAPER_GEOMETRY`. Load cycle
    runs ``0 .. repeats-1`` are at 0 kPa, ``repeats .. 2 repeats-1`` at the test pressure. ``force_n`` is NaN in
    stroke and step runs (the format does not need it there); ``load_n`` holds the stroke and step loads;
    ``supply_pa`` and ``flow_m3_per_s`` are filled in step runs; an optional signal present in some run is NaN
    in the others, exactly as :func:`peano_bayes.data.load` reads it back. The provenance records that the data
    is synthetic, the seed, quirks, configuration, true and per-specimen parameters, noise and protocol.

    **Raises:** :class:`~peano_bayes.errors.PeanoBayesInputError` for an unknown material, quirk, parameter or
    test, a parameter outside its bounds, or bad counts; nothing is simulated before all inputs are checked.
    """
    spec = materials.material(material)
    quirk_names = check_quirks(quirks)
    final_config = apply_quirks(config, quirk_names)
    mounts = _check_mounts(added_compliances)
    if any(c > 0 for c in mounts) and not final_config.mount:
        final_config = dataclasses.replace(final_config, mount=True)
        true_params = {"mount_compliance_m_per_n": PARAMETERS["mount_compliance_m_per_n"].off, **(true_params or {})}
    params, fallback = resolve_parameters(true_params, final_config)
    seed, repeats, specimens, tests = _check_run(seed, repeats, specimens, tests, specimen_spread)
    overrides = _check_specimen_values(specimen_values, specimens)
    for index, mapping in enumerate(overrides):
        unread = [name for name in mapping if name not in params]
        if unread:
            raise PeanoBayesInputError(
                f"specimen_values[{index}]: the simulated model does not read {', '.join(map(repr, unread))}; "
                "switch its element on (config or quirks) or leave the name out"
            )
    report = progress or (lambda line: None)

    runs, per_specimen = [], {}
    for index in range(specimens):
        label = string.ascii_uppercase[index]
        own = specimen_parameters(params, specimen_spread, np.random.default_rng([seed, _SPECIMEN_STREAM, index]))
        own.update(overrides[index])
        per_specimen[label] = own
        truths, earlier = [], collections.Counter()  # conditions per test on the mounts before
        for added in mounts:
            mounted = dict(own)
            if added > 0:
                mounted["mount_compliance_m_per_n"] = own["mount_compliance_m_per_n"] + added
            batch = _specimen_truths(mounted, spec, final_config, protocol, tests, report, label)
            truths += [
                dataclasses.replace(
                    t,
                    condition=t.condition + earlier[t.test],
                    added_compliance_m_per_n=added if mounts != (0.0,) else None,
                )
                for t in batch
            ]
            earlier.update(t.test for t in batch)
        runs += _session_runs(label, index, truths, seed=seed, noise=noise, repeats=repeats, drift=drift)
    return Dataset(
        material=spec.data_material(),
        geometry=GEOMETRY,
        conditions=spec.conditions(),
        runs=_fill_optional(runs),
        provenance=_provenance(
            source="synthetic: peano_bayes virtual rig (peano_bayes.rig.simulate_dataset), not a measurement",
            seed=seed,
            model=_model_provenance(
                quirk_names, final_config, params, fallback, tuple(n for n in (true_params or {}) if n not in params)
            ),
            per_specimen=per_specimen,
            noise=noise,
            drift=drift,
            spread=specimen_spread,
            protocol=protocol,
            repeats=repeats,
        ),
    )


__all__ = ["simulate_dataset"]
