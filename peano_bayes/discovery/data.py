"""Rig data for discovery: one specimen's runs, binned, split into fit and held-out runs, with covariates.

**Split (whole runs, never single samples):** the runs of one test condition (test and, for load cycles, the
pressure) are numbered in the order they were run: the cycle index. The last run of every condition that has
at least two runs is held out; the others are fitted. Held-out runs are repeats of fitted protocols, so the
held-out error measures model error plus noise, not extrapolation to new conditions; holding out the last repeat
(leave-future-out) also asks a model to predict a specimen that changes from cycle to cycle forward in time. A
held-out middle repeat would not: the refitted base interpolates a softening specimen from the runs before and
after it, and the held-out run keeps little of the effect (even a perfect model would then shrink the held-out
gap of cyclic softening only to about 0.51 of the base's).

**Noise:** each sensor's noise sd [signal unit per raw sample] is estimated from the raw signal alone
(:func:`~peano_bayes.inference.denoise.noise_sd`, second differences, in the quasi-static tests), so the
likelihood of every candidate model is measured against the same, model-free noise scale; a bin mean of ``k``
samples has sd ``sd / sqrt(k)``.

**Inputs:** every run is simulated from its own denoised strain, and from the pressure inputs (muscle and, in
steps, supply pressure) averaged over the runs of its condition. The rig's realized strain follows the specimen:
when the specimen changes between repeats (cyclic softening), so does the strain, and a strain averaged over the
repeats would put an input error that follows the cycle index into every run (the fitted softening then leaves
its own first-cycle signature at about half its size and fails that gate). The pressure follows the regulator's
one command per condition, and its sensor's denoising error is independent from run to run, so the mean is the
better input: with each run's own pressure that error blurs the onset of a threshold pressure (on the
benchmark's threshold-pressure data, named in 10 of 22 runs with each run's pressure, 13 of 22 with the
average).
Held-out runs share the average too; it uses their pressure inputs, never their observed force or strain.
In the stroke test (:data:`DISCOVERY_INPUT_ERRORS`) the averaged ramp keeps its
own error: the exact factor of the mean of the runs' fit errors, which every fit estimates from the fitted
runs and the held-out runs take (:class:`.model.Flat`).

**Bins:** 4 samples (load cycles, blocking, stroke) and 2 (steps): screening many refits must be fast. A bin's
prediction is the mean of the simulation at two quadrature nodes, exact for signals cubic in time, except in
blocking and stroke (:data:`DISCOVERY_EVERY_SAMPLE`), simulated at every sample: their pressure ramps start at
zero, where the force has kinks, and there two nodes leave a model error of 0.88 of the rig's per-sample noise
at 0-44 kPa of the harness's blocking ramp with quiet sensors, where a threshold pressure hides; every sample
leaves 0.007 (threshold pressure at SNR 2 is then named in 20 of 22 benchmark runs instead of 14). One-sample
bins reach the same floor but weigh blocking and stroke four times against the load cycles, and cost found
effects on the bundled muscles.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np

from ..data import Dataset
from ..errors import PeanoBayesInputError
from ..inference.fit import sensor_noise
from ..inference.reduce import OBSERVED, RunGroup, mean_error_factor, prepare
from .model import DiscoveryData

#: Samples per bin by test for discovery (coarser than inference: screening many refits must be fast).
DISCOVERY_BIN_SIZES = MappingProxyType({"load_cycle": 4, "blocking": 4, "stroke": 4, "step": 2})
#: Tests simulated at every sample, their predictions averaged per bin (see the module docstring, **Bins**).
DISCOVERY_EVERY_SAMPLE = frozenset({"blocking", "stroke"})
#: Tests whose fitted inputs' error discovery's fits estimate (see the module docstring): the stroke test's
#: pressure ramp, whose error moves a strain measured to 2e-4 by up to three bin sd. Discovery compares refits
#: against each other and screens hundreds of them, so the load cycles and blocking tests, where the error is
#: within noise per bin (:data:`~peano_bayes.inference.reduce.INPUT_ERROR_TESTS` integrates it there for
#: calibrated intervals), keep their fitted inputs as exact; their strain error would also need each run's own
#: input (see **Inputs**), which the shared estimate does not cover.
DISCOVERY_INPUT_ERRORS = frozenset({"stroke"})
#: Bins per block of the block tests (residuals within a block are treated as dependent).
BLOCK_BINS = 10
#: Pressure resolution [Pa] that tells load-cycle conditions apart.
_PRESSURE_CLASS_PA = 10e3


@dataclass(frozen=True, eq=False)
class Covariates:
    """Per flat bin (n,) of a :class:`DiscoveryData`, in its residual order.

    **Fields:** ``test`` (str); ``run`` run number in the dataset; ``block`` block id (runs split every
    :data:`BLOCK_BINS` bins); ``cycle`` cycle index; ``pressure_pa`` mean muscle (step: supply) pressure;
    ``strain`` mean strain (input of load cycles and blocking, observed in stroke and step) [-];
    ``rate_sign`` sign of the commanded strain rate in load cycles (0 elsewhere); ``time_since_reversal_s``
    time since the commanded strain last changed direction, or since the run began (load cycles; NaN
    elsewhere) [s]; ``time_since_step_s`` (step runs; NaN elsewhere); ``session_s`` bin time plus the durations
    of the runs before it [s].
    """

    test: np.ndarray
    run: np.ndarray
    block: np.ndarray
    cycle: np.ndarray
    pressure_pa: np.ndarray
    strain: np.ndarray
    rate_sign: np.ndarray
    time_since_reversal_s: np.ndarray
    time_since_step_s: np.ndarray
    session_s: np.ndarray


@dataclass(frozen=True, eq=False)
class SplitData:
    """What :func:`discovery_data` returns: ``fit`` and ``held_out`` data, their covariates, the noise sd per
    test [per raw sample], the specimen analysed and the run keys of each part. ``both`` holds the fit groups
    then the held-out groups (one evaluation, one compilation, for both parts)."""

    fit: DiscoveryData
    held_out: DiscoveryData
    fit_covariates: Covariates
    held_out_covariates: Covariates
    noise_sd: dict
    specimen: str
    fit_runs: tuple
    held_out_runs: tuple

    @property
    def both(self) -> DiscoveryData:
        fit, held = self.fit, self.held_out
        return replace(
            fit,
            groups=fit.groups + held.groups,
            sd=fit.sd + held.sd,
            session=fit.session + held.session,
            error_set=fit.error_set + held.error_set,
            informs=fit.informs + held.informs,
        )

    @property
    def n_fit_bins(self) -> int:
        return int(sum(g.observed.size for g in self.fit.groups))


def _conditions(dataset: Dataset, specimen: str) -> dict:
    """(specimen, test, run) -> (condition, cycle index within it, size of the condition)."""
    conditions: dict[tuple, list] = {}
    for run in dataset.runs:
        if run.specimen != specimen:
            continue
        level = round(float(np.nanmedian(run.pressure_pa)) / _PRESSURE_CLASS_PA) if run.test == "load_cycle" else 0
        conditions.setdefault((run.test, level), []).append(run)
    out = {}
    for condition, runs in conditions.items():
        for index, run in enumerate(sorted(runs, key=lambda r: r.run)):
            out[run.key] = (condition, index, len(runs))
    return out


def _share_pressure(group: RunGroup, conditions: list) -> RunGroup:
    """Each run's pressure inputs replaced by their mean over the runs of its condition in ``group``
    (``conditions`` (r,): the condition of each row).

    The regulator commands one pressure per condition and the sensor's denoising error is independent from run
    to run, so the mean is the better estimate; strain stays per run (it follows the specimen)."""
    index: dict = {}
    labels = np.array([index.setdefault(c, len(index)) for c in conditions])

    def mean(a):
        if a is None:
            return None
        a = np.asarray(a, dtype=float)
        return np.stack([a[labels == label].mean(axis=0) for label in range(len(index))])[labels]

    return replace(group, pressure_pa=mean(group.pressure_pa), supply_pa=mean(group.supply_pa))


def _condition_input_error(group: RunGroup, conditions: list) -> list:
    """Per condition of ``group`` (``conditions`` (r,) as for :func:`_share_pressure`), the (q, L) columns of
    the error of its runs' mean fitted pressure: each run's fit error ``B_i a_i`` is independent, so the mean's
    is the exact low-rank factor of ``sum_i B_i B_i^T / n^2``. Empty when the group carries no input error."""
    if not group.has_input_error:
        return []
    index: dict = {}
    labels = np.array([index.setdefault(c, len(index)) for c in conditions])
    error = np.asarray(group.pressure_error, dtype=float)  # (r, q, L): each run's own columns, zero-padded
    factors = [mean_error_factor([b.T for b in error[labels == label]], error.shape[2]) for label in range(len(index))]
    return [factors[label] for label in labels]


def _with_error_columns(group: RunGroup, columns: list, q: int) -> RunGroup:
    """``group`` with each row's pressure error columns (``columns[i]`` (q_i, L)) padded to ``q``. Only the
    pressure is shared by a condition; a group whose strain carries an error is refused."""
    if not columns:
        return group
    if group.strain_error is not None and np.any(np.asarray(group.strain_error) != 0):
        raise NotImplementedError(f"discovery takes the {group.test} test's strain as exact; it has an error basis")
    error = np.zeros((len(columns), q, group.pressure_pa.shape[1]))
    for i, c in enumerate(columns):
        error[i, : c.shape[0]] = c
    return replace(group, pressure_error=error, strain_error=None)


def _take(group: RunGroup, rows: np.ndarray, cycle: np.ndarray) -> RunGroup:
    pick = lambda a: None if a is None else np.asarray(a)[rows]  # noqa: E731
    return replace(
        group,
        keys=tuple(group.keys[i] for i in rows),
        specimen_index=np.asarray(cycle, dtype=int),
        time_s=pick(group.time_s),
        strain=pick(group.strain),
        pressure_pa=pick(group.pressure_pa),
        supply_pa=pick(group.supply_pa),
        load_n=pick(group.load_n),
        added_compliance_m_per_n=pick(group.added_compliance_m_per_n),
        observed=pick(group.observed),
        counts=pick(group.counts),
        shared=np.arange(len(rows)),
        bin_time_s=pick(group.bin_time_s),
        bin_nodes=pick(group.bin_nodes),
        strain_error=pick(group.strain_error),
        pressure_error=pick(group.pressure_error),
        input_jacobian=pick(group.input_jacobian),
        segment_start=pick(group.segment_start),
    )


def _time_since_reversal(t: np.ndarray, rate_sign: np.ndarray) -> np.ndarray:
    """Time [s] (m,) of each bin since the strain rate's sign last changed (or since the first bin). A bin of
    zero rate (at a turn, or a hold) keeps the sign before it, so a reversal through a zero restarts the clock
    once, at the first bin of the new sign."""
    sign = np.asarray(rate_sign, dtype=float).copy()
    for i in range(1, sign.size):
        if sign[i] == 0:
            sign[i] = sign[i - 1]
    start = np.zeros(t.size, dtype=int)
    changed = np.flatnonzero(np.diff(sign) != 0) + 1
    start[changed] = changed
    return t - t[np.maximum.accumulate(start)]


def _covariates(groups, cycles, session_start: dict) -> Covariates:
    cols: dict[str, list] = {k: [] for k in Covariates.__dataclass_fields__}
    block_id = 0
    for group, cycle in zip(groups, cycles, strict=True):
        r, m = group.observed.shape
        for i in range(r):
            key = group.keys[i]
            cols["test"].append(np.full(m, group.test))
            cols["run"].append(np.full(m, key[2]))
            cols["cycle"].append(np.full(m, cycle[i]))
            blocks = np.arange(m) // BLOCK_BINS
            cols["block"].append(block_id + blocks)
            block_id += int(blocks[-1]) + 1
            source = group.supply_pa if group.test == "step" else group.pressure_pa
            cols["pressure_pa"].append(group.per_bin(np.asarray(source[i]), row=i).mean(axis=1))
            strain_in = group.per_bin(np.asarray(group.strain[i]), row=i).mean(axis=1)
            observed_strain = OBSERVED[group.test][0] == "strain"
            cols["strain"].append(np.asarray(group.observed[i]) if observed_strain else strain_in)
            rate = np.sign(np.gradient(strain_in)) if group.test == "load_cycle" else np.zeros(m)
            cols["rate_sign"].append(rate)
            t = np.asarray(group.bin_time_s[i])
            cycle_test = group.test == "load_cycle"
            cols["time_since_reversal_s"].append(_time_since_reversal(t, rate) if cycle_test else np.full(m, np.nan))
            if group.test == "step":
                supply = group.per_bin(np.asarray(group.supply_pa[i]), row=i).mean(axis=1)
                edge = t[int(np.argmax(np.abs(np.diff(supply)))) + 1] if m > 1 else t[0]
                cols["time_since_step_s"].append(t - edge)
            else:
                cols["time_since_step_s"].append(np.full(m, np.nan))
            cols["session_s"].append(t + session_start[key])
    return Covariates(**{k: np.concatenate(v) for k, v in cols.items()})


def _sensor_noise(runs, specimen: str) -> dict:
    """Per test, the model-free noise sd of one raw sample of its observed signal
    (:func:`~peano_bayes.inference.fit.sensor_noise`); a signal without noise cannot scale residuals."""
    noise = sensor_noise(runs)
    for test, sd in noise.items():
        if not sd > 0:
            raise PeanoBayesInputError(
                f"the {OBSERVED[test][0]} signal of specimen {specimen!r} shows no noise; cannot scale residuals"
            )
    return noise


def discovery_data(
    dataset: Dataset,
    *,
    specimen: str | None = None,
    tests=None,
    bin_sizes=DISCOVERY_BIN_SIZES,
    every_sample=DISCOVERY_EVERY_SAMPLE,
    noise: dict | None = None,
) -> SplitData:
    """Bin ``specimen``'s runs (default: the first specimen) of ``tests`` (default: all), split them (see the
    module docstring), estimate the noise and collect covariates. Raises :class:`PeanoBayesInputError` for an
    unknown specimen or test, when no condition has a second run to hold out, or when a test's observed signal
    shows no noise to scale residuals by.

    ``noise``: test -> sensor noise sd of one raw sample [signal unit] to use instead of estimating it from the
    runs; for a noise-free copy of a session (the benchmark's truth), whose signals have no noise to estimate,
    binned with the noisy session's."""
    specimens = tuple(dataset.specimens)
    specimen = specimens[0] if specimen is None else specimen
    if specimen not in specimens:
        raise PeanoBayesInputError(f"specimen {specimen!r} is not in the dataset; it has {', '.join(specimens)}")
    present = {run.test for run in dataset.runs if run.specimen == specimen}
    tests = tuple(present) if tests is None else tuple(tests)
    missing = [t for t in tests if t not in present]
    if missing:
        raise PeanoBayesInputError(
            f"test(s) {', '.join(missing)} not in the data of specimen {specimen!r}; "
            f"it has {', '.join(sorted(present))}"
        )
    runs = [run for run in dataset.runs if run.specimen == specimen and run.test in tests]
    one = replace(dataset, runs=tuple(runs))
    conditions = _conditions(one, specimen)
    cycles = {key: (index, size) for key, (_, index, size) in conditions.items()}
    if not any(size >= 2 for _, size in cycles.values()):
        raise PeanoBayesInputError(
            f"specimen {specimen!r} has no test condition with two or more runs; discovery holds out a repeat "
            "of each condition to score candidate effects, so it needs repeated runs"
        )
    session_start, elapsed = {}, 0.0
    for run in runs:
        session_start[run.key] = elapsed
        elapsed += float(run.time_s[-1] - run.time_s[0])
    noise = _sensor_noise(runs, specimen) if noise is None else {test: float(noise[test]) for test in tests}
    observations = prepare(
        one, bin_sizes, share_repeats=False, every_sample=every_sample, input_errors=DISCOVERY_INPUT_ERRORS
    )
    of_group = [[conditions[key][0] for key in g.keys] for g in observations.groups]
    columns = [_condition_input_error(g, c) for g, c in zip(observations.groups, of_group, strict=True)]
    q = max((c.shape[0] for cs in columns for c in cs), default=0)
    sets: dict[tuple, int] = {}  # (group, condition) -> input error set
    groups, error_set = [], []
    for i, (group, conds, cols) in enumerate(zip(observations.groups, of_group, columns, strict=True)):
        group = _share_pressure(group, conds)
        has_error = bool(cols) and q > 0
        groups.append(_with_error_columns(group, cols, q) if has_error else replace(group, pressure_error=None))
        labels = [sets.setdefault((i, c), len(sets)) for c in conds] if has_error else [-1] * len(conds)
        error_set.append(np.array(labels, dtype=int))
    parts: dict[bool, tuple[list, list, list]] = {False: ([], [], []), True: ([], [], [])}
    for group, labels in zip(groups, error_set, strict=True):
        info = np.array([cycles[key] for key in group.keys])
        held = (info[:, 0] == info[:, 1] - 1) & (info[:, 1] >= 2)
        for flag in (False, True):
            rows = np.flatnonzero(held == flag)
            if rows.size:
                parts[flag][0].append(_take(group, rows, info[rows, 0]))
                parts[flag][1].append(info[rows, 0])
                parts[flag][2].append(labels[rows])
    n_cycles = int(max(index for index, _ in cycles.values()) + 1)

    def build(flag):
        groups = tuple(parts[flag][0])
        sd = tuple(noise[g.test] / np.sqrt(g.counts) for g in groups)
        # Fitted runs estimate their condition's input error; held-out runs take that estimate, never their own.
        informs = tuple(np.full(len(labels), 0.0 if flag else 1.0) for labels in parts[flag][2])
        cov = _covariates(groups, parts[flag][1], session_start)
        # The covariates' flat order is every group's (r, m) bins raveled, one group after another.
        scaled = 2.0 * cov.session_s / max(elapsed, 1e-9) - 1.0
        cuts = np.cumsum([g.observed.size for g in groups])[:-1]
        session = tuple(a.reshape(g.observed.shape) for a, g in zip(np.split(scaled, cuts), groups, strict=True))
        data = DiscoveryData(groups, sd, session, n_cycles, dataset.geometry, tuple(parts[flag][2]), informs, len(sets))
        return data, cov

    (fit, fit_cov), (held, held_cov) = build(False), build(True)
    return SplitData(
        fit,
        held,
        fit_cov,
        held_cov,
        noise,
        specimen,
        tuple(k for g in fit.groups for k in g.keys),
        tuple(k for g in held.groups for k in g.keys),
    )


__all__ = ["BLOCK_BINS", "Covariates", "DISCOVERY_BIN_SIZES", "DISCOVERY_EVERY_SAMPLE", "SplitData", "discovery_data"]
