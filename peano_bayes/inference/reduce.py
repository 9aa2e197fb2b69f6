"""Data reduction: a validated rig dataset to the binned observations the likelihood compares with the model
(:func:`prepare` -> :class:`Observations`), and the definitions both sides share (observed signal and noise
parameter per test, driving inputs, which parameters vary per specimen).

**Observed signal per test:** force [N] in the load cycle and blocking tests (strain-controlled), strain [-] in
the stroke and step tests (load-controlled). Each test has its own noise scale (:data:`OBSERVED`, e.g.
``noise_stroke_strain`` [-]), the standard deviation of one raw sample's residual: sensor noise plus whatever
the model misses in that test.

**Data reduction (binning):** a rig samples far faster than quasi-static physics changes, and the cost of a
likelihood evaluation grows with the number of simulated samples. Consecutive samples are averaged in bins; a
bin mean of ``k`` samples carries noise ``sigma / sqrt(k)``. By default each run is cut into its **segments**
(the ramps and holds of its commanded inputs: where the denoised driving inputs change slope, see
:func:`segment_starts`) and each segment into :data:`DEFAULT_BINS_PER_SEGMENT` bins of equal sample count, so
the cost of an evaluation is set by the number of runs and segments, not by the rig's sampling rate (a 100 Hz
file costs what a 10 Hz file costs); no bin straddles a reversal. ``bin_sizes`` instead bins every ``k``
samples (discovery uses this). The simulation runs at two points per
bin (:func:`quadrature_times`) and their mean is compared with the bin mean: exact for any signal cubic in time
within a bin. (Simulating once at the bin's mean input instead biased a stiffness by 1.5 %, several posterior
sd, on virtual-rig data.) The friction state remembers the path, so the simulation also passes through the run's
first sample and, with segment bins, the samples around each turn of the inputs (:func:`with_path_samples`); their
predictions are not compared with data. The step response is not binned by default (its dynamics need every
sample).

**Driving inputs (errors in variables):** before binning, the measured inputs that drive a simulation
(:data:`DRIVING_INPUTS`) are replaced by their piecewise-linear least-squares fit (ramps, holds and steps, see
:mod:`~peano_bayes.inference.denoise`). Raw, their sensor noise is amplified by the model's sensitivity: on the
bundled TP data at the true parameters, stroke and step residuals are 14 and 21 times the strain noise, and
1.0 times with the fitted inputs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType

import jax.numpy as jnp
import numpy as np

from ..data import Dataset
from ..physics import (
    Geometry,
)
from .denoise import fit_error_basis, noise_sd, piecewise_linear_segments

#: Samples averaged per bin, by test, when binning by a fixed count (``prepare(..., bin_sizes=...)``).
DEFAULT_BIN_SIZES = MappingProxyType({"load_cycle": 4, "blocking": 4, "stroke": 4, "step": 1})
#: Bins per segment of a run's commanded inputs, by test (the default binning; see the module docstring). A
#: test not listed (the step response, whose dynamics need every sample) is not binned. Chosen by the model
#: error it leaves: on virtual-rig data of TP, PR and FC at their bundled true parameters (one specimen, three
#: repeats, the rig's default noise), the rms residual at the truth over the bin's noise sd is 0.95-1.14 with
#: 100 bins per segment, 0.94-1.14 with bins of four samples; 64 bins per segment give up to 1.30 and 24 up to
#: 5.3 (wide bins hold curvature the two-node quadrature misses). At the bundled 20 Hz a segment of 400
#: samples then costs what bins of four did; at 100 Hz, a fifth.
DEFAULT_BINS_PER_SEGMENT = MappingProxyType({"load_cycle": 100, "blocking": 100, "stroke": 100})
#: The observed signal and its noise parameter, by test.
OBSERVED = MappingProxyType(
    {
        "load_cycle": ("force_n", "noise_load_cycle_force_n"),
        "blocking": ("force_n", "noise_blocking_force_n"),
        "stroke": ("strain", "noise_stroke_strain"),
        "step": ("strain", "noise_step_strain"),
    }
)
NOISE_PARAMETERS = tuple(noise for _, noise in OBSERVED.values())
#: The measured signals that drive each test's simulation; :func:`prepare` replaces them by their
#: piecewise-linear fit (:mod:`peano_bayes.inference.denoise`) so their sensor noise does not drive the model.
DRIVING_INPUTS = MappingProxyType(
    {
        "load_cycle": ("strain", "pressure_pa"),
        "blocking": ("pressure_pa",),
        "stroke": ("pressure_pa",),
        "step": ("supply_pa",),
    }
)
#: Tests whose fitted driving inputs' error enters the likelihood (see the module docstring). In the stroke test
#: it is large per bin: on the bundled TP data at the true parameters with the inputs treated as exact, the rms of
#: the bin residuals over their noise sd is 1.78 (the fitted pressure ramp's offset and slope error, about 30 Pa
#: in 30 kPa, moves a strain whose noise is 2e-4 by up to 3 bin sd). In the load cycles (1.02) and blocking
#: (1.03) it is within noise per bin but common to every bin of a run, so it shifts a specimen's stiffness by
#: more than its posterior sd: on the hierarchical SBC problem (``experiments/sbc_laplace.py``, 60 replicates) the
#: Laplace 90 % interval of ``tensile_ka`` covers 0.80 of the truths with the load cycles' inputs taken as exact,
#: 0.87 with their error integrated and 0.90 with noiseless inputs (its specimen contrast 0.75, 0.87, 0.88). Each
#: column of the error costs a forward-mode derivative: on TP's default tests a log-posterior evaluation costs
#: 1.8-2.0 times the inputs-exact one (``experiments/bench_input_error.py``), so ``fit`` computes the Jacobian
#: once, at the exact-input mode (:func:`~.likelihood.linearise_input_error`), and then costs about what the
#: inputs-exact one does.
INPUT_ERROR_TESTS = frozenset({"load_cycle", "blocking", "stroke"})
#: Driving inputs whose fit error can be modelled (the step's supply pressure is not).
ERROR_INPUTS = ("strain", "pressure_pa")
#: Relative size below which an eigenvalue of a fitted input's error covariance is dropped (exact rank).
_ERROR_RANK_TOLERANCE = 1e-10
#: Per-specimen log factors, an optional entry of the parameters (see :func:`~.likelihood.predict`): either
#: one (n_specimens,) array applied to every :data:`SPECIMEN_SCALED` parameter, or a mapping name ->
#: (n_specimens,) log factor of that parameter alone.
SPECIMEN_OFFSET = "specimen_log_offset"
#: Parameters scaled by a specimen's stiffness factor: every stiffness of the tube wall (the rig's specimens
#: differ by hand-making: film thickness, bonding).
SPECIMEN_SCALED = frozenset(
    {"tensile_ka_n_per_m", "tensile_kb_n_per_m2", "bending_k1_n", "bending_k2_n", "extension_k_n_per_m"}
)
#: Parameters that differ between specimens of one material in the hierarchical model: the wall stiffnesses, the
#: friction element's pre-sliding stiffness and the compliance of the mount each specimen was clamped in. The
#: virtual rig draws its own factor for each of these per specimen (``rig.specimen_parameters``); on the bundled
#: PR data, whose friction force is 3.5 N, one common friction stiffness at the specimens' geometric mean costs
#: 116 in the blocking test's log-likelihood at the generating values, and the nominal one 433.
SPECIMEN_VARYING = SPECIMEN_SCALED | {"friction_stiffness_n_per_m", "mount_compliance_m_per_n"}


@dataclass(frozen=True, eq=False)
class RunGroup:
    """Runs of one test with equal reduced length, stacked for one vmapped simulation of ``u <= r`` inputs.

    **Fields:** ``test``; ``keys`` (r,) of ``(specimen, test, run)``; ``observed`` (r, m) bin means of the
    observed signal; ``counts`` (r, m) raw samples per bin; ``shared`` (r,) int, the simulated input row of
    each run (repeats of one protocol share one). Per simulated row: ``specimen_index`` (u,) int into
    :attr:`Observations.specimens`; ``time_s``, ``strain``, ``pressure_pa``, ``supply_pa`` (u, p m) the
    simulation's times and inputs, ``p`` = :attr:`points_per_bin` per bin (``supply_pa`` only for steps);
    ``bin_time_s`` (u, m) mean time of each bin; ``load_n`` (u,) hanging or inertial load [N];
    ``added_compliance_m_per_n`` (u,) known series compliance added to the mount's for the run [m/N] (0: none;
    it adds to ``mount_compliance_m_per_n``, so the model's configuration needs its mount element);
    ``strain_error``, ``pressure_error`` (u, q, p m) or ``None``: the columns of the fitted inputs' error at
    the simulation's times (``a ~ N(0, I_q)``, zero columns pad sets with fewer; see the module docstring);
    ``bin_nodes`` (u, p m) int: where each bin's ``p`` points sit among a row's ``L >= p m`` simulated points
    (the others are samples where the input path turns, :func:`with_path_samples`), so the simulated arrays
    are (u, L); ``input_jacobian`` (u, q, m) or ``None``: the predictions' derivative along the error columns,
    held fixed when set (:func:`~.likelihood.linearise_input_error`), else computed at every evaluation;
    ``residual_lag1`` () or ``None``: the lag-1 correlation of the residuals from bin to bin within a run, when
    the likelihood takes them as AR(1) (:func:`~.likelihood.with_residual_lag1`), else independent;
    ``segment_start`` (r, m) bool or ``None``: the bins that begin a segment of the run's commanded inputs
    (per-segment binning only; an AR(1) chain starts afresh there).
    """

    test: str
    keys: tuple
    specimen_index: np.ndarray
    time_s: np.ndarray
    strain: np.ndarray
    pressure_pa: np.ndarray
    supply_pa: np.ndarray | None
    load_n: np.ndarray
    observed: np.ndarray
    counts: np.ndarray
    shared: np.ndarray
    bin_time_s: np.ndarray
    bin_nodes: np.ndarray
    strain_error: np.ndarray | None = None
    pressure_error: np.ndarray | None = None
    added_compliance_m_per_n: np.ndarray | None = None
    input_jacobian: np.ndarray | None = None
    residual_lag1: np.ndarray | None = None
    segment_start: np.ndarray | None = None

    @property
    def has_input_error(self) -> bool:
        """Whether the fitted inputs' error enters this group's likelihood."""
        return self.pressure_error is not None

    @property
    def points_per_bin(self) -> int:
        """Simulated points per bin: 1 for one-sample bins, else 2 (quadrature) or the bin size (every
        sample simulated)."""
        return self.bin_nodes.shape[1] // self.observed.shape[1]

    def per_bin(self, values, row: int | None = None):
        """Simulated-point values as (..., m, p), one row per bin: ``values`` (u, L) of every simulated row, or
        with ``row`` (L,) of that row. NumPy or JAX arrays."""
        index = self.bin_nodes if row is None else self.bin_nodes[row]
        xp = np if isinstance(values, np.ndarray) else jnp
        picked = xp.take_along_axis(values, xp.broadcast_to(index, values.shape[:-1] + index.shape[-1:]), -1)
        return picked.reshape(picked.shape[:-1] + (self.observed.shape[1], self.points_per_bin))

    @property
    def n_bins(self) -> int:
        return int(self.observed.size)

    @property
    def run_specimen_index(self) -> np.ndarray:
        """(r,) specimen of every run."""
        return self.specimen_index[self.shared]


@dataclass(frozen=True, eq=False)
class Observations:
    """A dataset reduced for the likelihood: run groups and the specimen names they index; ``bin_sizes``
    (test -> samples per bin) for tests binned by count, ``bins_per_segment`` (test -> bins per input
    segment) for the others."""

    specimens: tuple[str, ...]
    groups: tuple[RunGroup, ...]
    bin_sizes: MappingProxyType
    geometry: Geometry
    bins_per_segment: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))

    @property
    def n_bins(self) -> int:
        return sum(g.n_bins for g in self.groups)


def bin_means(values: np.ndarray, k: int | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Means of consecutive bins of ``values`` (n,): bins of ``k`` samples (the last possibly shorter), or,
    with ``k`` an int array (m,), bins starting at those sample indices (increasing, first 0).

    Returns ``(means (m,), counts (m,))``; NaN samples are left out of their bin's mean and count.
    """
    values = np.asarray(values, dtype=float)
    n = values.shape[0]
    starts = np.arange(0, n, k) if np.ndim(k) == 0 else np.asarray(k, dtype=int)
    finite = np.isfinite(values)
    sums = np.add.reduceat(np.where(finite, values, 0.0), starts)
    counts = np.add.reduceat(finite.astype(float), starts)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1.0), np.nan), counts


def quadrature_times(time_s: np.ndarray, k: int | np.ndarray) -> np.ndarray:
    """(2 m,) two simulation times per bin (of ``k`` samples, or starting at the indices ``k``, see
    :func:`bin_means`): the bin's mean time -+ the sd of its sample times. The mean of a signal at these two
    points equals its mean over the bin's samples for any cubic in time (same mean and variance of the nodes),
    so binned data are compared with binned predictions without the curvature bias of simulating at the bin's
    mean input. A one-sample bin gets -+ a quarter interval."""
    time_s = np.asarray(time_s, dtype=float)
    centre, counts = bin_means(time_s, k)
    square, _ = bin_means(time_s**2, k)
    spread = np.sqrt(np.maximum(square - centre**2, 0.0))
    single = counts <= 1
    spread[single] = 0.25 * float(np.min(np.diff(time_s))) if time_s.size > 1 else 0.0
    return np.stack([centre - spread, centre + spread], axis=1).ravel()


def with_path_samples(time_s: np.ndarray, nodes: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The simulation's times: the bins' ``nodes`` (p m,) plus the samples where the driving inputs' path turns,
    and where each node sits among them: ``(times (L,), node_index (p m,))``.

    The added samples are the run's first (a simulation starting at the first node would begin relaxed at a
    later input than the run did) and every sample within :data:`SNAP_SAMPLES` (plus one) of each segment
    start in ``starts`` (a path from the last node before a strain reversal to the first after it cuts the corner and
    never reaches the extreme; a run binned like an earlier repeat turns within that window of the start, not
    at it). The friction state remembers both: in the bundled PC data at the generating values, leaving them
    out misfits the blocking test by up to 0.19 N and the load cycle after its reversal by up to 0.07 N (bin sd
    0.1 N); with only the two samples at the start and repeats snapped to each other's starts, noise in the
    strain alone moved PR's fitted friction limit by 2.5-4.1 of its conditional sd (virtual-rig seeds 11 and
    12), against 0.1-1.6 with every sample simulated. Their predictions are simulated but not compared with
    data. A sample within a millionth of an interval of a node is not added again."""
    time_s, nodes = np.asarray(time_s, dtype=float), np.asarray(nodes, dtype=float)
    # a turn at start s runs from sample s to s + 1 (segment_starts marks the sample after which the input bends)
    window = range(-SNAP_SAMPLES - 1, SNAP_SAMPLES + 2)
    path = {0} | {int(s + d) for s in np.asarray(starts) if s > 0 for d in window if 0 <= s + d < time_s.size}
    extra = time_s[sorted(path)]
    tolerance = 1e-6 * (float(np.min(np.diff(time_s))) if time_s.size > 1 else 1.0)
    near = np.min(np.abs(extra[:, None] - nodes[None, :]), axis=1) <= tolerance
    times = np.unique(np.concatenate([nodes, extra[~near]]))
    return times, np.searchsorted(times, nodes)


#: A change of slope of a denoised input larger than this fraction of its range per sample marks a segment
#: boundary (the fitted inputs are exactly piecewise linear, so inside a segment the change is round-off).
SLOPE_CHANGE_TOLERANCE = 1e-6


def segment_starts(inputs: list[np.ndarray]) -> np.ndarray:
    """Indices where a run's segments start (first 0): the samples after which any of the denoised driving
    ``inputs`` (each (n,)) changes slope or jumps (its second difference exceeds
    :data:`SLOPE_CHANGE_TOLERANCE` of its range)."""
    n = inputs[0].shape[0]
    cuts = {0}
    for x in inputs:
        x = np.asarray(x, dtype=float)
        span = np.nanmax(x) - np.nanmin(x) if np.any(np.isfinite(x)) else 0.0
        if not span > 0.0 or n < 3:
            continue
        d2 = np.abs(np.diff(x, 2))
        cuts.update((np.flatnonzero(d2 > SLOPE_CHANGE_TOLERANCE * span) + 1).tolist())
    return np.array(sorted(cuts))


def merge_adjacent(starts: np.ndarray) -> np.ndarray:
    """Segment ``starts`` (increasing, first 0) with each start one sample after the previous kept one dropped
    (a kink the piecewise-linear fit spread over two samples is one boundary)."""
    kept = [int(starts[0])]
    for a in starts[1:]:
        if a - kept[-1] > 1:
            kept.append(int(a))
    return np.array(kept)


def segment_bins(starts: np.ndarray, n: int, per_segment: int) -> np.ndarray:
    """Start indices of the bins: each segment (``starts``, (s,), of ``n`` samples) cut into ``per_segment``
    bins of nearly equal sample count (fewer when the segment is shorter); starts are merged first
    (:func:`merge_adjacent`)."""
    edges = merge_adjacent(starts).tolist() + [n]
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        m = min(per_segment, b - a)
        out.extend(np.unique(a + np.floor(np.linspace(0.0, b - a, m + 1)[:-1]).astype(int)).tolist())
    return np.array(out)


#: Spread of the repeated nodes of a short last bin, in units of the shortest sample interval (see
#: :func:`sample_times`): small enough that a kink between them is invisible, large enough for a time step.
REPEAT_SPREAD = 1e-3


def sample_times(time_s: np.ndarray, k: int) -> np.ndarray:
    """(k m,) ``k`` simulation times per bin of ``k`` samples: a full bin's own sample times, so the mean of the
    simulated signal is the bin mean of a per-sample simulation whatever its shape in the bin (kinks included).

    A shorter last bin of ``c`` samples, when ``c`` divides ``k``, gets each sample ``k / c`` times, spread
    symmetrically by :data:`REPEAT_SPREAD` of the sample interval (repeats would put zero time steps into the
    time-stepping simulations); otherwise ``k`` nodes placed symmetrically with the bin's mean time and sd (those
    of :func:`quadrature_times`: exact for cubics)."""
    time_s = np.asarray(time_s, dtype=float)
    full = (time_s.size // k) * k
    c = time_s.size - full
    if c == 0:
        return time_s
    if k % c == 0 and time_s.size > 1:
        step = REPEAT_SPREAD * float(np.min(np.diff(time_s)))
        offsets = step * np.linspace(-1.0, 1.0, k // c) if k // c > 1 else np.zeros(1)
        tail = (time_s[full:, None] + offsets[None, :]).ravel()
    else:
        low, high = quadrature_times(time_s, k)[-2:]
        z = np.linspace(-1.0, 1.0, k)
        z = z / np.sqrt(np.mean(z**2)) if k > 1 else z
        tail = 0.5 * (low + high) + 0.5 * (high - low) * z
    return np.concatenate([time_s[:full], tail])


#: Segmentations of two runs whose segment starts differ by at most this many samples are taken to be the same
#: commanded protocol: the later run is binned like the earlier one (so repeats can share a simulation,
#: :func:`_share_repeats`; the denoising places a reversal within a few samples of where it was). Each run's
#: own turn then lies within this many samples of a start, and :func:`with_path_samples` simulates every
#: sample of that window. A count of samples, not a time: at a higher sampling rate the denoised reversals of
#: repeats lie more samples apart, fewer repeats are binned alike and share a simulation (more cost, the same
#: accuracy); measured at 20 Hz only.
SNAP_SAMPLES = 12


def _snap(segments: np.ndarray, known: list) -> np.ndarray:
    """``segments``, or an earlier run's from ``known`` (updated) when every start is within
    :data:`SNAP_SAMPLES` samples of it."""
    for other in known:
        if other.shape == segments.shape and np.max(np.abs(other - segments)) <= SNAP_SAMPLES:
            return other
    known.append(segments)
    return segments


def _interp_columns(time_s: np.ndarray, sample_time_s: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Each column of ``columns`` (n, q), sampled at ``sample_time_s`` (n,), at ``time_s`` (L,): (L, q). A
    noise-free input has no error columns (q = 0)."""
    if columns.shape[1] == 0:
        return np.zeros((len(time_s), 0))
    return np.stack([np.interp(time_s, sample_time_s, c) for c in columns.T], axis=-1)


def _reduce_run(
    run,
    k: int | None,
    denoise: bool,
    every_sample: bool = False,
    per_segment: int | None = None,
    known_segments: list | None = None,
    input_error: bool = False,
) -> dict:
    """One run binned by ``k`` samples, or (``per_segment``) into that many bins per segment of its denoised
    driving inputs (:func:`segment_bins`; segmentations of earlier runs of the protocol in ``known_segments``
    reused, see :data:`SNAP_SAMPLES`): simulation times and inputs (two per bin, :func:`quadrature_times`, or
    with ``every_sample`` ``k`` per bin, :func:`sample_times`; plus the samples where the inputs' path turns,
    :func:`with_path_samples`, and ``bin_nodes`` locating the bins' points; driving inputs denoised), observed
    bin means, counts, and the raw noise sd of each driving input (for :func:`_share_repeats`); with
    ``input_error``, the fitted inputs' error basis at the simulation's times (``error_basis``: name -> (L, q))."""
    signal, _ = OBSERVED[run.test]
    driving = DRIVING_INPUTS[run.test] if denoise else ()
    if run.test == "step" and run.supply_pa is None:
        raise ValueError(f"step run {run.key} has no supply pressure; the step likelihood needs supply_kpa")
    out, input_sd, fitted, basis = {}, {}, {}, {}
    for name in ("strain", "pressure_pa", "supply_pa"):
        raw = getattr(run, name)
        if raw is not None and name in driving:
            input_sd[name] = noise_sd(raw)
            denoised, segments = piecewise_linear_segments(run.time_s, raw, input_sd[name])
            if input_error and name in ERROR_INPUTS:
                basis[name] = fit_error_basis(run.time_s, raw, segments, input_sd[name])
            raw = denoised
        fitted[name] = raw
    n = run.time_s.shape[0]
    # Where the path turns: segment starts in per-segment binning (snapped, so repeats share one grid); with
    # fixed-count bins, which may straddle a turn anyway, only the run's first sample.
    starts = np.array([0])
    if per_segment is not None:
        smooth = [
            fitted[name] if name in driving else piecewise_linear_segments(run.time_s, fitted[name])[0]
            for name in DRIVING_INPUTS[run.test]
            if fitted[name] is not None
        ]
        known = [] if known_segments is None else known_segments
        starts = _snap(merge_adjacent(segment_starts(smooth)), known)
        k = segment_bins(starts, n, per_segment)
        out["segment_start"] = np.isin(k, merge_adjacent(starts))
    one_per_bin = np.ndim(k) == 0 and k == 1
    centre, _ = bin_means(run.time_s, k)
    if one_per_bin:
        sim_time, out["bin_nodes"] = run.time_s, np.arange(n)
    else:
        nodes = sample_times(run.time_s, k) if every_sample else quadrature_times(run.time_s, k)
        sim_time, out["bin_nodes"] = with_path_samples(run.time_s, nodes, starts)
    for name, values in fitted.items():
        out[name] = None if values is None else (values if one_per_bin else np.interp(sim_time, run.time_s, values))
    out["time_s"] = sim_time
    out["bin_time_s"] = centre
    out["observed"], out["counts"] = bin_means(getattr(run, signal), k)
    has_load = run.load_n is not None and np.any(np.isfinite(run.load_n))
    out["load_n"] = float(np.nanmedian(run.load_n)) if has_load else None
    out["added_compliance"] = run.added_compliance
    out["input_sd"] = input_sd
    out["error_basis"] = {
        name: b if one_per_bin else _interp_columns(sim_time, run.time_s, b) for name, b in basis.items()
    }
    return out


def mean_error_factor(columns: list[np.ndarray], points: int) -> np.ndarray:
    """(q, points) columns of the error of the mean of n runs' fitted input, each run's error ``B_i a_i``
    independent with ``columns[i]`` = ``B_i`` (points, q_i) (zero columns allowed): the exact low-rank factor
    of ``sum_i B_i B_i^T / n^2`` (eigenvalues below :data:`_ERROR_RANK_TOLERANCE` of the largest dropped)."""
    stacked = np.concatenate([np.zeros((points, 0)), *columns], axis=1) / max(len(columns), 1)
    if stacked.shape[1] == 0:
        return np.zeros((0, points))
    left, values, _ = np.linalg.svd(stacked, full_matrices=False)
    keep = values > np.sqrt(_ERROR_RANK_TOLERANCE) * max(values.max(), 1e-300)
    return (left[:, keep] * values[keep]).T


def _shared_input_error(bases: list[dict], name: str, points: int) -> np.ndarray:
    """(q, points) columns of the error of the mean of the runs' fitted input ``name`` (``bases`` hold each
    run's ``B_i`` (points, q_i) by input name; see :func:`mean_error_factor`)."""
    return mean_error_factor([b.get(name, np.zeros((points, 0))) for b in bases], points)


def _group_input_error(members: list, shared: np.ndarray, n_sets: int) -> dict:
    """Per :data:`ERROR_INPUTS` name, the (u, q, p m) error columns of each simulated input row of a group
    (:attr:`RunGroup.strain_error`, :attr:`RunGroup.pressure_error`): each column perturbs one input, rows with
    fewer columns are padded with zeros. ``None`` for both when the runs carry no error basis (q = 0)."""
    points = members[0][1]["time_s"].shape[0]
    per_set = []
    for j in range(n_sets):
        bases = [members[i][1]["error_basis"] for i in np.flatnonzero(shared == j)]
        per_set.append([(name, _shared_input_error(bases, name, points)) for name in ERROR_INPUTS])
    q = max(sum(block.shape[0] for _, block in blocks) for blocks in per_set)
    if q == 0:
        return {name: None for name in ERROR_INPUTS}
    out = {name: np.zeros((n_sets, q, points)) for name in ERROR_INPUTS}
    for j, blocks in enumerate(per_set):
        row = 0
        for name, block in blocks:
            out[name][j, row : row + block.shape[0]] = block
            row += block.shape[0]
    return out


def _share_repeats(members: list) -> tuple[np.ndarray, np.ndarray]:
    """Which runs of a group can share one simulation: same specimen, time grid and load, and driving inputs
    equal to within one raw noise sd everywhere (repeats of one commanded protocol, denoised). Returns
    ``(simulated (u,), shared (r,))``: the first run of each set and, per run, the index of its set."""
    simulated: list[int] = []
    shared = np.empty(len(members), dtype=int)
    for i, (run, red) in enumerate(members):
        for j, first in enumerate(simulated):
            other_run, other = members[first]
            same = bool(red["input_sd"]) and (
                run.specimen == other_run.specimen
                and red["load_n"] == other["load_n"]
                and red["added_compliance"] == other["added_compliance"]
                and np.allclose(red["time_s"], other["time_s"], rtol=0.0, atol=1e-9)
                and all(
                    name in other["input_sd"]
                    and np.nanmax(np.abs(red[name] - other[name])) <= min(sd, other["input_sd"][name])
                    for name, sd in red["input_sd"].items()
                )
            )
            if same:
                shared[i] = j
                break
        else:
            shared[i] = len(simulated)
            simulated.append(i)
    return np.array(simulated), shared


def prepare(
    dataset: Dataset,
    bin_sizes=None,
    *,
    bins_per_segment=DEFAULT_BINS_PER_SEGMENT,
    stroke_load_n: float = 5.5,
    denoise_inputs: bool = True,
    share_repeats: bool = True,
    every_sample: frozenset = frozenset(),
    input_errors: frozenset = INPUT_ERROR_TESTS,
) -> Observations:
    """Reduce ``dataset`` for the likelihood: denoise the driving inputs (``denoise_inputs``, see
    :data:`DRIVING_INPUTS`), bin every run, stack runs of a test that have the same number of bins, and let
    repeats of one protocol share a simulation from their averaged denoised inputs (``share_repeats``; only
    with ``denoise_inputs``). ``stroke_load_n`` [N] is used where a stroke run records no load.

    Binning: by default each segment of a run's inputs is cut into ``bins_per_segment[test]`` bins (see the
    module docstring; tests not listed are not binned). ``bin_sizes`` (test -> samples per bin, missing tests
    from :data:`DEFAULT_BIN_SIZES`) bins by a fixed count instead. Tests in ``every_sample`` (fixed-count
    binning only) are simulated at every sample and the predictions averaged per bin (:func:`sample_times`)
    instead of at two quadrature nodes per bin. Tests in ``input_errors`` carry their fitted inputs' error
    into the likelihood (see the module docstring; only with ``denoise_inputs``)."""
    if bin_sizes is not None:
        bin_sizes = MappingProxyType({**DEFAULT_BIN_SIZES, **dict(bin_sizes)})
        per_segment = MappingProxyType({})
    else:
        per_segment = MappingProxyType(dict(bins_per_segment))
        bin_sizes = MappingProxyType({t: 1 for t in OBSERVED if t not in per_segment})
        if every_sample & set(per_segment):
            raise ValueError("every_sample needs fixed-count bins: pass bin_sizes for those tests")
    specimens = tuple(dataset.specimens)
    buckets: dict[tuple[str, int], list] = {}
    segmentations: dict[tuple, list] = {}
    for run in dataset.runs:
        known = segmentations.setdefault((run.test, run.specimen, run.time_s.shape[0]), [])
        reduced = _reduce_run(
            run,
            bin_sizes.get(run.test),
            denoise_inputs,
            run.test in every_sample,
            per_segment.get(run.test),
            known,
            input_error=denoise_inputs and run.test in input_errors,
        )
        if reduced["load_n"] is None:
            if run.test == "step":
                raise ValueError(f"step run {run.key} records no load; the step likelihood needs load_n")
            reduced["load_n"] = stroke_load_n
        shape = (reduced["time_s"].shape[0], reduced["observed"].shape[0])
        buckets.setdefault((run.test, *shape), []).append((run, reduced))
    groups = []
    for (test, *_), members in sorted(buckets.items()):
        if share_repeats and denoise_inputs:
            simulated, shared = _share_repeats(members)
        else:
            simulated, shared = np.arange(len(members)), np.arange(len(members))

        def inputs(name, members=members, simulated=simulated, shared=shared):
            """(u, m): per simulated set, the mean of its members' (denoised) input."""
            rows = np.stack([red[name] for _, red in members])
            return np.stack([rows[shared == j].mean(axis=0) for j in range(len(simulated))])

        errors = {name: None for name in ERROR_INPUTS}
        if denoise_inputs and test in input_errors:
            errors = _group_input_error(members, shared, len(simulated))
        groups.append(
            RunGroup(
                test=test,
                keys=tuple(run.key for run, _ in members),
                specimen_index=np.array([specimens.index(members[i][0].specimen) for i in simulated]),
                time_s=np.stack([members[i][1]["time_s"] for i in simulated]),
                bin_time_s=np.stack([members[i][1]["bin_time_s"] for i in simulated]),
                strain=inputs("strain"),
                pressure_pa=inputs("pressure_pa"),
                supply_pa=inputs("supply_pa") if test == "step" else None,
                load_n=np.array([members[i][1]["load_n"] for i in simulated]),
                observed=np.stack([red["observed"] for _, red in members]),
                counts=np.stack([red["counts"] for _, red in members]),
                shared=shared,
                strain_error=errors["strain"],
                pressure_error=errors["pressure_pa"],
                bin_nodes=np.stack([members[i][1]["bin_nodes"] for i in simulated]),
                added_compliance_m_per_n=np.array([members[i][1]["added_compliance"] for i in simulated]),
                segment_start=np.stack([red["segment_start"] for _, red in members])
                if all("segment_start" in red for _, red in members)
                else None,
            )
        )
    return Observations(specimens, tuple(groups), bin_sizes, dataset.geometry, per_segment)


__all__ = [
    "DEFAULT_BINS_PER_SEGMENT",
    "DEFAULT_BIN_SIZES",
    "DRIVING_INPUTS",
    "ERROR_INPUTS",
    "INPUT_ERROR_TESTS",
    "NOISE_PARAMETERS",
    "OBSERVED",
    "Observations",
    "REPEAT_SPREAD",
    "RunGroup",
    "SLOPE_CHANGE_TOLERANCE",
    "SNAP_SAMPLES",
    "SPECIMEN_OFFSET",
    "SPECIMEN_SCALED",
    "SPECIMEN_VARYING",
    "bin_means",
    "mean_error_factor",
    "merge_adjacent",
    "prepare",
    "quadrature_times",
    "sample_times",
    "segment_bins",
    "segment_starts",
    "with_path_samples",
]
