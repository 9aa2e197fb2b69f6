"""The discovery loop: fit the base model, diagnose residual structure, screen candidate effects, accept the
best one only if it passes every gate, repeat.

**Screening** (every iteration, whether or not the diagnosis flags structure): the candidates not yet in the
model are ranked by the decrease of squared residuals one Gauss-Newton step promises from near their off
values (a score statistic); the top :attr:`Gates.screen` are refitted (all parameters free, the new effect
started near off) in one vmapped solve, plus every candidate the registry lists for a signature that is
significant after Holm (whatever its screen promised; :func:`refit_candidates`) and the flexible session
baseline until it is in the model. The report lists each significant signature with the candidates tried for
it and the gates each failed (``signatures``, one entry per round).

**Gates** (:class:`Gates`), all must pass:
1. predictive gain on held-out runs: ``delta elpd >= min_delta_elpd`` and ``delta elpd / se >= min_elpd_z``,
   with ``se`` from the per-block differences (a block is ten consecutive bins of one run);
2. parsimony: ``delta BIC <= max_delta_bic``, the log-likelihood scaled by ``n_eff / n`` and the penalty using
   ``n_eff = n (1 - rho1) / (1 + rho1)`` from the lag-1 autocorrelation of the residuals;
3. the effect explains its own signature: ``T_after / T_before <= max_signature_ratio`` (checked only where the
   signature was visible, ``T_before >= min_signature``: the base often absorbs part of an effect, and a ratio
   of two noise-level numbers says nothing);
4. it is real: the joint Laplace 94 % region of its strength parameters excludes their off values (a Wald
   test, :func:`strength_wald`; for one parameter, the value is more than ``strength_z`` sd from off);
5. it generalizes: held-out RMSE (standardized) ``<= max_heldout_ratio`` times the value before.
6. it is identified (:func:`identified`): no parameter of it has a Laplace correlation above
   ``max_correlation`` with a parameter already in the model, unless its held-out gain is strong on its own,
   ``delta elpd / se >= ridge_elpd_z``. Along such a ridge the Laplace approximation behind gate 4 is poor and a
   small gain can be a retuned base: on the benchmark's data, candidates that pass every other gate at
   correlations above 0.95 (mostly series compliance at 0.98-0.99 with the tensile stiffness, on data without
   that effect) gain only 1.1-2.2 standard errors. Held-out elpd does not rely on the Laplace approximation, so a
   large, well-measured gain still counts (bundled muscles: PC's mount and TPC's and FC's hysteresis, ``z``
   3.8-5.2 at correlations 0.975-0.98).
The evidence also records how much of the structure the diagnosis flagged the candidate removes (``flagged``,
``flagged_before``, ``flagged_after``: sums of ``T^2`` over the Holm-significant signatures); reported, not gated.

**Named only on its own evidence** (:func:`own_evidence`): an accepted physics effect is named only when its
own residual signature was significant after Holm before it was added and fell by at least half with it; one
that passed the gates without that is kept in the model and reported under ``described`` (a description of the
misfit, as the session baseline is), never named. On data from another physics with nothing hidden, a series
Kelvin-Voigt unit passed every gate on predictive gain alone while its signature rose (1.3 to 1.8, never
significant).

**Named only where the model with them fits** (``withheld``): when structure is still left after the loop stops
(some signature significant after Holm, whether no library candidate passed or the budget of ``max_effects`` was
spent), effects that had their own evidence are not named either, nor is a confusable pair called ambiguous; they
are reported as ``withheld`` and among ``described``, and the verdict is ``unexplained``. Structure outside the
library means a base that misses the data, and an effect accepted on the way may stand for part of that miss: on a
Sarosi-type surface with nothing hidden, the base missed the step by ``T`` 846 and a load damper passed every gate,
its own signature included, yet the model with it still missed by ``T`` 285 (docs/validation.md, *Discovery
benchmark*). On the project's own physics no correct detection of the tuning rounds left structure behind.

**Verdicts:** ``unconverged`` when the base model's least squares neither met its tolerance nor stopped improving
(:func:`fit_base`): nothing is screened or named, since a candidate would be judged against an unfinished fit;
otherwise the physics effects named (``named``); ``ambiguous`` when a rival of a known confusable pair
(:data:`~peano_bayes.effects.CONFUSABLE`) passed every gate with an elpd within two standard errors of the winner
(the rivals and the experiment that separates them are reported; a passing candidate outside such a pair is screened
again once the winner is in the model and, if it too came within two standard errors, is reported in the step's
``close_calls``, so the engineer sees the tie without the verdict changing); ``unexplained`` when structure is left
and no candidate passes (whatever was accepted on the way: see above), or when the flexible session baseline or a
physics effect without its own evidence was needed and nothing was named; ``none`` otherwise. A drift is claimed
(``drift_shown``) only when the residuals the session baseline absorbed trend in time within test conditions
(:func:`~.trend.within_condition_trend`, the baseline step's ``time_check``); otherwise the report says the misfit
is ordered with the conditions.
Noise-side effects that pass are added and reported as the noise model, never as physics.

**Which passing candidate is accepted:** the one with the largest held-out gain among the physics effects, the
session baseline and the load cell's offset and gain; heteroscedastic noise (:data:`~.effects.WIDENING_NOISE`)
only when nothing else passes, since widening the noise where residuals are large mimics any misfit. The
sensor terms compete on gain rather than yield to physics because on load-cell drift a sensor offset gains the
most held-out elpd in the first round (83-139 on the benchmark's drift runs) while a Maxwell branch also passes
(gain 42-64): ranked below physics, the offset would leave a spurious Maxwell branch named.

**The flexible session baseline** (``session_baseline``, a cubic in time over the session, added to the
force) is refitted every round until it is in the model and competes with the physics effects on held-out
gain: without it, a physics effect judged against a drifting baseline absorbs the drift (on load-cell drift,
a Maxwell branch's relaxation, with its loading split grown, not reduced, passes every gate in about half the
runs). Given priority over physics instead, it would also pass on hidden physics effects whose misfit follows
the order of the tests in the session, and absorb part of them. It names nothing: a model that
needed it reports its structure as ``unexplained`` unless a physics effect is also named, and it does not count
against ``max_effects``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace

import numpy as np
from scipy import stats

from ..effects import CONFUSABLE, LIBRARY, WIDENING_NOISE, check_effects, flexible_terms
from ..inference.fit import lag1_effective_size, noise_excess
from ..physics import PARAMETERS
from .data import SplitData
from .diagnose import MATCHED, SQUARED, Diagnosis, diagnose, signature_statistic
from .fitting import BATCH, Evaluation, ModelFit, evaluate, fit_models, gauss_newton_gain, matched_directions
from .model import DEFAULT_BASE, NAMES, model_spec
from .trend import joined_covariates, within_condition_trend

VERDICTS = ("named", "none", "ambiguous", "unexplained", "unconverged")
#: Candidates ranked by their signature rather than by Gauss-Newton gain (a noise model lowers the residuals
#: by widening the noise, which the gain does not penalize): refitted when their signature is significant.
SCREENED_BY_SIGNATURE = frozenset({"heteroscedastic_noise"})


@dataclass(frozen=True)
class Gates:
    """Acceptance thresholds (see the module docstring). They are fixed before a validation benchmark's final run
    and never set on its seeds.

    ``min_elpd_z`` is 0.5 rather than the 2 usual for K-fold elpd: one held-out repeat has a larger ``se``, and
    at 1.0 threshold pressure and cyclic softening, whose gain sits in a few held-out blocks, fail this gate
    alone, while false positives on no-effect data are rejected by the other gates at any ``z >= 0``.

    The strength gate is a joint test, not a marginal one (some strength parameter ``strength_z`` sd from off):
    nonlinear damping has three correlated strength parameters, none alone 1.88 sd from zero on data where it
    gains about 130 in held-out elpd, and is real only jointly.

    ``ridge_elpd_z`` lets a large, well-measured gain through the correlation gate (point 6): on the bundled
    muscles PC's mount and TPC's and FC's hysteresis gain 3.8-5.2 standard errors at correlations above
    ``max_correlation``, the correlated false positives on no-effect data 1.1-2.2.
    ``experiments/discrepancy_rescore.py`` recomputes this gate from a benchmark's logged evidence."""

    min_delta_elpd: float = 4.0
    min_elpd_z: float = 0.5
    max_delta_bic: float = -10.0
    max_signature_ratio: float = 0.5
    min_signature: float = 3.0
    strength_z: float = 1.88
    max_heldout_ratio: float = 0.98
    alpha: float = 0.01
    max_effects: int = 3
    screen: int = 4
    base_starts: int = 4
    max_correlation: float = 0.95
    ridge_elpd_z: float = 3.0


def identified(correlation: float, delta_elpd: float, elpd_se: float, gates: Gates = Gates()) -> bool:
    """Gate 6: the candidate's largest Laplace correlation with a parameter already in the model is at most
    ``gates.max_correlation``, or its held-out gain is at least ``gates.ridge_elpd_z`` standard errors."""
    strong = elpd_se > 0 and np.isfinite(elpd_se) and delta_elpd / elpd_se >= gates.ridge_elpd_z
    return bool(correlation <= gates.max_correlation or strong)


def _blocks(cov_block: np.ndarray, values: np.ndarray) -> np.ndarray:
    index = np.unique(cov_block, return_inverse=True)[1]
    return np.bincount(index, weights=values)


def within_two_se(best: np.ndarray, other: np.ndarray, blocks: np.ndarray) -> bool:
    """Whether ``best``'s held-out log-likelihood (per point, shape (n,)) beats ``other``'s by less than two
    standard errors, the errors from the per-block sums of the difference (``blocks``: each point's block)."""
    d = _blocks(blocks, best - other)
    se = float(np.sqrt(d.size) * np.std(d, ddof=1)) if d.size > 1 else float("inf")
    return bool(d.sum() <= 2.0 * se)


def _rmse(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")


def noise_floor(data) -> np.ndarray:
    """(n,) sd of each flat bin mean of ``data`` (a :class:`~peano_bayes.discovery.model.DiscoveryData`) from the
    sensor noise alone, in residual order: ``data.sd``, the model-free noise sd of its test's signal per raw
    sample (estimated from second differences before any model is fitted) over sqrt(samples in the bin)."""
    pairs = zip(data.groups, data.sd, strict=True)
    return np.concatenate([np.broadcast_to(np.asarray(sd, dtype=float), g.observed.shape).ravel() for g, sd in pairs])


def gap_table(fit_eval: Evaluation, held_eval: Evaluation, split: SplitData) -> dict:
    """Per test and split: RMSE and max |error| [signal unit], the standardized RMSE (1 = the fitted noise
    level), and against the model-free noise floor (:func:`~peano_bayes.inference.fit.noise_excess`): its RMSE,
    the excess RMSE and whether the residuals are consistent with noise."""
    out = {}
    parts = (
        ("fit", fit_eval, split.fit_covariates, split.fit),
        ("held_out", held_eval, split.held_out_covariates, split.held_out),
    )
    for part, ev, cov, data in parts:
        floor = noise_floor(data)
        for test in np.unique(cov.test):
            rows = cov.test == test
            err = ev.error[rows]
            out.setdefault(str(test), {})[part] = {
                "rmse": _rmse(err),
                "max_error": float(np.nanmax(np.abs(err))),
                "standardized_rmse": _rmse(ev.r[rows]),
                **noise_excess(err, floor[rows]),
            }
    return out


@dataclass
class _Candidate:
    name: str
    fit: ModelFit
    fit_eval: Evaluation
    held_eval: Evaluation
    evidence: dict
    passed: bool


def _standardized_distance(fit: ModelFit, names, off: dict) -> dict:
    """``(value - off) / sd`` of each parameter in ``names`` that has a Laplace sd > 0.

    An off value at the parameter's upper bound (a rigid series spring, ``series_viscoelastic``'s at
    ``RIGID_KELVIN_N_PER_M``; an open inlet, ``flow_restriction``'s at the widest orifice) is the end of a
    scale whose natural null is its reciprocal, the compliance or resistance ``1/x``. There the distance is
    measured on ``1/x`` against ``1/off``: ``(1/x - 1/off) / (sd / x^2)`` by the delta method, which is
    ``(x - off) / sd * x / off`` with the sign ``x - off`` has (so the Wald test's correlations keep theirs)
    and equals the plain distance near ``off``. Measured on ``x``, any finite stiffness lay millions of sd
    from 1e12 N/m: on the bundled TP data a fitted 2.83e5 +- 3.27e5 N/m passed the strength gate at 3e6 sd,
    though its compliance is 0.87 sd from off."""
    out = {}
    for p in names:
        sd = fit.sd.get(p, 0.0)
        if sd > 0.0:
            x, zero = fit.params[p], off[p]
            at_upper_bound = p in PARAMETERS and zero == PARAMETERS[p].bounds[1]
            out[p] = (x - zero) / sd * (x / zero if at_upper_bound else 1.0)
    return out


def strength_wald(fit: ModelFit, strength: tuple, off: dict, z: float) -> tuple[float, float]:
    """Joint test that the strength parameters of an effect are away from ``off``: the Wald statistic
    ``W = d' C^+ d`` of ``d = (value - off) / sd`` with ``C`` their Laplace correlation (pseudo-inverse: a
    direction the data do not constrain adds nothing), and its threshold, the chi-square quantile at the level
    ``2 Phi(z) - 1`` of the two-sided ``z`` with one degree of freedom per strength parameter tested (those
    with a Laplace sd > 0; for one parameter, ``W >= z^2`` is ``|value - off| >= z sd``)."""
    distance = _standardized_distance(fit, strength, off)
    names = list(distance)
    if not names:
        return 0.0, float("inf")
    d = np.array([distance[p] for p in names])
    index = [fit.spec.free_names.index(p) for p in names]
    corr = fit.correlation[np.ix_(index, index)]
    wald = float(d @ np.linalg.pinv(corr, rcond=1e-8, hermitian=True) @ d)
    level = 2.0 * stats.norm.cdf(z) - 1.0
    return wald, float(stats.chi2.ppf(level, len(names)))


def own_evidence(evidence: dict, gates: Gates = Gates()) -> bool:
    """Whether an accepted effect may be **named**: its own residual signature was significant after Holm before
    it was added (``signature_p_holm < gates.alpha``) and fell by at least ``1 - gates.max_signature_ratio``
    (half) with it. An effect that passes the gates without that improved the prediction for some other reason
    (it bent to fit a misfit it does not cause) and is reported as a description of the misfit, never named."""
    p = evidence.get("signature_p_holm", 1.0)
    ratio = evidence.get("signature_ratio", float("inf"))
    return bool(p < gates.alpha and ratio <= gates.max_signature_ratio)


def _statistic(r: np.ndarray, diag: Diagnosis, name: str) -> float:
    return signature_statistic(r, diag.weights[name], name in SQUARED, name in diag.one_sided)


def matched_weights(current: ModelFit, split, names=MATCHED) -> dict[str, np.ndarray]:
    """Weights (name -> (n,) over the fitted bins) of the signatures ``names`` (default :data:`~.diagnose.MATCHED`)
    read along their effect's own direction, for a diagnosis of ``current``: for the physics effect each belongs
    to, :func:`~.fitting.matched_directions` from ``current`` to the effect switched on at its screening start
    (:func:`effect_start`), on the tests the registry lists for it (``Effect.shows_in``) and zero
    elsewhere; zero where the effect is already in the model (nothing to screen) or its direction is not finite."""
    n = split.n_fit_bins
    owners = {name: next(e for e in LIBRARY.values() if e.signature == name and e.kind == "physics") for name in names}
    screened = [name for name in names if owners[name].name not in current.spec.active]
    starts = [effect_start(current, owners[name].name) for name in screened]
    rows = dict(zip(screened, matched_directions(current, starts, split), strict=True)) if screened else {}
    out = {}
    for name in names:
        w = rows.get(name, np.zeros(n))
        where = np.isin(split.fit_covariates.test, owners[name].shows_in) & np.isfinite(w)
        out[name] = np.where(where, w, 0.0)
    return out


def _score(
    name, fit, split, before: ModelFit, before_fit: Evaluation, before_held: Evaluation, gates, diag
) -> _Candidate:
    effect = LIBRARY[name]
    fit_eval, held_eval = evaluate(fit, split)
    diff = held_eval.loglik - before_held.loglik
    block_diff = _blocks(split.held_out_covariates.block, diff)
    delta_elpd = float(diff.sum())
    se = float(np.sqrt(block_diff.size) * np.std(block_diff, ddof=1)) if block_diff.size > 1 else float("inf")
    n = fit_eval.r.size
    n_eff = lag1_effective_size(fit_eval.r)
    delta_loglik = float(fit_eval.loglik.sum() - before_fit.loglik.sum())
    delta_k = fit.n_free - before.n_free
    delta_bic = -2.0 * (n_eff / n) * delta_loglik + delta_k * np.log(n_eff)
    # read after the refit along the directions the diagnosis read before it
    t_before = diag.statistic[effect.signature]
    t_after = _statistic(fit_eval.r, diag, effect.signature)
    flagged = [k for k in diag.p_holm if diag.p_holm[k] < gates.alpha]
    flagged_before = float(sum(diag.statistic[k] ** 2 for k in flagged))
    flagged_after = float(sum(_statistic(fit_eval.r, diag, k) ** 2 for k in flagged))
    off = effect.off
    distance = _standardized_distance(fit, effect.strength, off)
    z_strength = {p: abs(distance.get(p, 0.0)) for p in effect.strength}
    wald, wald_threshold = strength_wald(fit, effect.strength, off, gates.strength_z)
    heldout_ratio = _rmse(held_eval.r) / _rmse(before_held.r)
    free = fit.spec.free_names
    new = [free.index(p) for p in effect.params if p in free]
    old = [i for i, p in enumerate(free) if p not in effect.params]
    correlation = float(np.max(np.abs(fit.correlation[np.ix_(new, old)]))) if new and old else 0.0
    evidence = {
        "delta_elpd": delta_elpd,
        "elpd_se": se,
        "delta_bic": float(delta_bic),
        "n_eff": float(n_eff),
        "signature": effect.signature,
        "signature_before": float(t_before),
        "signature_after": float(t_after),
        "signature_ratio": float(t_after / t_before) if t_before > 0 else float("inf"),
        "signature_p_holm": float(diag.p_holm[effect.signature]),
        "strength_z": {k: float(v) for k, v in z_strength.items()},
        "strength_wald": wald,
        "strength_wald_threshold": wald_threshold,
        "heldout_rmse_ratio": float(heldout_ratio),
        "flagged": flagged,
        "flagged_before": flagged_before,
        "flagged_after": flagged_after,
        "max_correlation_with_base": correlation,
        "solver_ok": fit_eval.solver_ok and held_eval.solver_ok,
    }
    checks = {
        "predictive_gain": delta_elpd >= gates.min_delta_elpd and delta_elpd >= gates.min_elpd_z * se,
        "parsimony": delta_bic <= gates.max_delta_bic,
        "own_signature": t_before < gates.min_signature or evidence["signature_ratio"] <= gates.max_signature_ratio,
        "strength_excludes_off": wald >= wald_threshold,
        "generalizes": heldout_ratio <= gates.max_heldout_ratio,
        "identified": identified(correlation, delta_elpd, se, gates),
        "solver_ok": evidence["solver_ok"],
    }
    checks = {k: bool(v) for k, v in checks.items()}
    evidence["gates"] = checks
    evidence["own_evidence"] = own_evidence(evidence, gates)
    return _Candidate(name, fit, fit_eval, held_eval, evidence, all(checks.values()))


def effect_start(current: ModelFit, name: str) -> np.ndarray:
    """The superset point (d,) the screen starts effect ``name`` from: ``current``'s, with the effect's own
    parameters at its registered start values."""
    x = current.x.copy()
    for p, v in LIBRARY[name].start.items():
        x[NAMES.index(p)] = v
    return x


#: Continuations of a base fit's start that stopped at the step limit (each up to ``fitting.MAX_STEPS`` steps).
BASE_CONTINUATIONS = 8
#: A continuation counts as an improvement only when it lowers the cost (a negative log-likelihood) by more than
#: this: a fortieth of the smallest held-out gain a candidate may pass with (``Gates.min_delta_elpd``). On the
#: bundled muscles the base's best start ends within 0.1 of its final cost after one or two rounds and then
#: creeps along a flat valley by 0.01 a round without meeting the solver's step tolerance.
BASE_MIN_GAIN = 0.1


def fit_base(base, fit_data, *, starts: int = Gates.base_starts, seed: int = 0, centre=None, start=None) -> ModelFit:
    """Least-squares fit of the model with effects ``base`` to ``fit_data`` (a :class:`SplitData`'s ``fit``).

    With ``start`` (name -> value [SI]: the inference least squares' optimum on the same data, names outside
    the discovery model ignored), one vmapped batch (:data:`~.fitting.BATCH`) from that point and points
    scattered about it by a factor e^N(0, 0.3) in each free parameter: the inference fit has already searched
    the prior, so discovery only polishes its optimum on its own objective. Otherwise multi-start: the
    library's nominal values plus ``starts - 1`` starts scattered by a factor e^N(0, 0.3) in each free parameter
    (seeded by ``seed``), and with ``centre`` (name -> value [SI], e.g. a material prior's medians) as many
    again around it. A start stopped at the step limit continues (up to :data:`BASE_CONTINUATIONS` times)
    while it improves by more than :data:`BASE_MIN_GAIN`, and is marked ``stationary`` where it stops for gaining
    less; the lowest-cost fit wins. Raises RuntimeError if every start fails.
    """
    spec = model_spec(base)
    rng = np.random.default_rng(seed)
    scatter = lambda x: x * np.where(spec.mask, np.exp(rng.normal(0.0, 0.3, spec.mask.size)), 1.0)  # noqa: E731
    if start is not None:
        near = model_spec(base, {k: v for k, v in start.items() if k in NAMES}).pinned
        x0 = [near] + [scatter(near) for _ in range(BATCH - 1)]
    else:
        x0 = [spec.pinned] + [scatter(spec.pinned) for _ in range(starts - 1)]
        if centre is not None:  # as many starts again, around the centre (the nominal ones above are unchanged)
            near = model_spec(base, {k: v for k, v in centre.items() if k in NAMES}).pinned
            x0 += [near] + [scatter(near) for _ in range(starts - 1)]
    x0 = [np.where(spec.mask, s, spec.pinned) for s in x0]
    i = NAMES.index("length_fraction")
    for s in x0:
        s[i] = min(s[i], 0.95)
    fits = [f for f in fit_models([spec] * len(x0), x0, fit_data) if f is not None]
    if not fits:
        raise RuntimeError(f"every fit of the base model {base} failed (non-finite or the physics solver missed)")
    # A start that stopped at the step limit goes on from where it stopped (the same compiled solve, up to BATCH
    # at a time), while it still improves: a base far from the library's values needs several hundred steps.
    going = sorted(range(len(fits)), key=lambda i: fits[i].cost)
    for _ in range(BASE_CONTINUATIONS):
        going = [i for i in going if not fits[i].converged][:BATCH]
        if not going:
            break
        more = fit_models([fits[i].spec for i in going], [fits[i].x for i in going], fit_data)
        improved = []
        for i, new in zip(going, more, strict=True):
            if new is None or new.cost >= fits[i].cost:
                fits[i] = replace(fits[i], stationary=True)
            elif new.cost < fits[i].cost - BASE_MIN_GAIN:
                fits[i] = new
                improved.append(i)
            else:  # still creeping, by less than BASE_MIN_GAIN: keep the lower point, stop there
                fits[i] = replace(new, stationary=True)
        going = improved
    return min(fits, key=lambda f: f.cost)


def preference_order(passing: list) -> list:
    """Candidates that passed every gate (objects with ``name`` and ``evidence["delta_elpd"]``), best first:
    by held-out gain among everything but widening noise models (:data:`~.effects.WIDENING_NOISE`), which can
    mimic any misfit by widening the noise where residuals are large and so come in only when nothing else
    passed. Physics effects with their own signature's evidence (``evidence["own_evidence"]``), the session
    baseline and the load cell's offset and gain compete on gain; a physics effect without that evidence, which
    would only describe the misfit, comes after them: it is accepted only when none of them passed. Why: a load
    damping with its own signature at T 24 (Holm p 0.001) lost by 1.9 in held-out elpd to a Maxwell branch
    whose signature was not significant (p 0.27), and the verdict was ``unexplained`` (tuning seed 20009)."""

    def tier(c) -> int:
        return int(LIBRARY[c.name].kind == "physics" and not c.evidence.get("own_evidence", False))

    preferred = [c for c in passing if c.name not in WIDENING_NOISE]
    return sorted(preferred or passing, key=lambda c: (tier(c), -c.evidence["delta_elpd"]))


def withhold_where_structure_is_left(steps: list[dict], structure_left: bool) -> list[dict]:
    """The accepted ``steps`` with each marked ``withheld`` (and no longer ``named``) when it had its own evidence
    but ``structure_left`` after the last step: an effect is named only where the model with it fits, since
    structure no library effect removes means a misfit outside the library, part of which an effect accepted on
    the way may stand for."""
    return [
        s | {"withheld": bool(s["named"] and structure_left), "named": bool(s["named"] and not structure_left)}
        for s in steps
    ]


def conclude(steps: list[dict], structure_left: bool, settled: bool = True) -> tuple[list[dict], dict]:
    """The verdict of a finished search: its accepted ``steps`` (marked by :func:`withhold_where_structure_is_left`)
    and the report's ``verdict``, ``named``, ``described``, ``withheld``, ``drift_shown`` and ``ambiguous``, from
    the steps, whether the last diagnosis left structure and whether the base fit ``settled``. A withheld winner
    of a confusable pair is not ``ambiguous`` either: nothing is named while structure is left."""
    steps = withhold_where_structure_is_left(steps, structure_left)
    named = [s["effect"] for s in steps if s["named"]]
    # a flexible term, or a physics effect that passed the gates without its own signature's evidence (or withheld)
    described = [s["effect"] for s in steps if s["kind"] == "flexible" or (s["kind"] == "physics" and not s["named"])]
    ambiguous = [
        {"effects": [s["effect"], *s["rivals"]], "experiment": s["experiment"]}
        for s in steps
        if s["rivals"] and s["named"]
    ]
    if not settled:
        verdict = "unconverged"
    elif ambiguous:
        verdict = "ambiguous"
    elif named:
        verdict = "named"
    elif described or structure_left:
        verdict = "unexplained"
    else:
        verdict = "none"
    return steps, {
        "verdict": verdict,
        "named": named,
        "described": described,
        "withheld": [s["effect"] for s in steps if s["withheld"]],
        # drift is claimed only where the repeats of a condition show the trend in time (not only its order)
        "drift_shown": any(s["time_check"]["shows_in_time"] for s in steps if s["kind"] == "flexible"),
        "ambiguous": ambiguous,
    }


def refit_candidates(inactive, gain: dict, p_holm: dict, gates: Gates) -> tuple[list, dict]:
    """Which inactive effects one round refits, and why.

    Returns ``(ranked, by_signature)``: ``ranked`` the effects to refit, in order: the ``gates.screen`` best by
    the Gauss-Newton ``gain`` (effect -> promised decrease of squared residuals), then every effect the registry
    lists for a residual signature that is significant after Holm (``p_holm`` signature -> p, below
    ``gates.alpha``; this includes the effects screened by signature alone, :data:`SCREENED_BY_SIGNATURE`), then
    the flexible terms; ``by_signature`` each significant signature -> its inactive candidates. A one-step
    screen from an effect's off value can promise nothing where the gradient vanishes there (a friction loop
    from zero friction), so a significant signature always reaches its candidates, whatever they promised.
    """
    significant = [k for k in p_holm if p_holm[k] < gates.alpha]
    by_signature = {k: [e for e in inactive if LIBRARY[e].signature == k] for k in significant}
    ranked = sorted(gain, key=lambda e: -gain[e])[: gates.screen]
    for k in significant:
        ranked += [e for e in by_signature[k] if e not in ranked and e not in flexible_terms()]
    ranked += [e for e in inactive if e in flexible_terms()]
    return ranked, by_signature


def signature_outcomes(by_signature: dict, p_holm: dict, candidates: list) -> dict:
    """Per significant signature of one round: its Holm p-value and, for each library candidate of it, the
    gates it failed (``[]``: it passed every gate; ``None``: its fit failed)."""
    scored = {c.name: [g for g, ok in c.evidence["gates"].items() if not ok] for c in candidates}
    return {
        k: {"p_holm": float(p_holm[k]), "candidates": {e: scored.get(e) for e in effects}}
        for k, effects in by_signature.items()
    }


def _diagnose(current: ModelFit, cur_fit: Evaluation, split, gates: Gates, seed: int) -> Diagnosis:
    matched = matched_weights(current, split)
    return diagnose(cur_fit.r, split.fit_covariates, cur_fit.predicted, alpha=gates.alpha, seed=seed, matched=matched)


def _diagnosis_dict(d: Diagnosis) -> dict:
    return {
        "structure_left": bool(d.structure_left),
        "omnibus_p": d.omnibus_p,
        "signatures": {k: {"T": d.statistic[k], "p": d.p_value[k], "p_holm": d.p_holm[k]} for k in d.statistic},
    }


@dataclass(frozen=True, eq=False)
class Discovery:
    """What :func:`discover` returns: the JSON-ready ``report``, the ``split`` data, and the base and final
    models' :class:`~peano_bayes.discovery.fitting.Evaluation` on the fitted runs (``before``, ``after``) and on
    the held-out runs (``held_before``, ``held_after``)."""

    report: dict
    split: SplitData
    before: Evaluation
    after: Evaluation
    held_before: Evaluation
    held_after: Evaluation


def discover(
    split: SplitData,
    *,
    base=DEFAULT_BASE,
    gates: Gates = Gates(),
    seed: int = 0,
    progress=None,
    centre=None,
    start=None,
) -> Discovery:
    """Run the discovery loop on ``split`` (see :func:`~peano_bayes.discovery.data.discovery_data`); ``centre``
    (name -> value [SI], e.g. the material prior's medians) centres the base fit's starts, ``start`` (name ->
    value [SI], the inference least squares' optimum) replaces them (:func:`fit_base`).

    The report (:attr:`Discovery.report`) is a JSON-ready dict: ``verdict`` (one of :data:`VERDICTS`),
    ``named`` physics effects, ``noise_model`` noise-side effects, ``described`` flexible terms and physics
    effects the data needed without naming them, ``withheld`` those of them that had their own evidence but were
    not named for the structure left (:func:`conclude`), ``ambiguous`` rival sets with the experiment that
    separates them,
    ``steps`` (per accepted effect: evidence, gates, parameters with Laplace sd, RMSE before and after, the
    ``rivals`` of a confusable pair and other ``close_calls`` within two standard errors),
    ``screened`` (every candidate's evidence per iteration), ``signatures`` (per iteration, each significant
    signature with its candidates and the gates each failed, :func:`signature_outcomes`), ``gap`` (base vs
    final, fit and held-out), ``diagnoses`` and timings.
    """
    say = progress or (lambda line: None)
    started = time.perf_counter()
    base = check_effects(base)
    current = fit_base(base, split.fit, starts=gates.base_starts, seed=seed, centre=centre, start=start)
    base_fit = current
    cur_fit, cur_held = evaluate(current, split)
    first_fit, first_held = cur_fit, cur_held
    say(
        f"base model {'+'.join(base)} fitted: standardized RMSE fit {_rmse(cur_fit.r):.2f}, "
        f"held-out {_rmse(cur_held.r):.2f}"
    )
    steps, screened, diagnoses, signatures = [], [], [], []
    diag = _diagnose(current, cur_fit, split, gates, seed)
    diagnoses.append(_diagnosis_dict(diag))
    stopped = "max_effects"
    settled = base_fit.converged or base_fit.stationary
    if not settled:  # a candidate judged against an unfinished base may stand for the base's own misfit
        stopped = "base_unconverged"
        say("the base model's least squares did not converge: nothing is screened or named")
    while settled and sum(s["kind"] != "flexible" for s in steps) < gates.max_effects:
        # Screen whether or not the diagnosis flags structure: the gates, not the diagnosis, decide.
        inactive = [e for e in LIBRARY if e not in current.spec.active]
        present = dict(zip(NAMES, current.x, strict=True))
        specs = {e: model_spec(current.spec.active + (e,), present) for e in inactive}
        starts = {e: effect_start(current, e) for e in inactive}
        cost = cur_fit.cost
        gain = {
            e: gauss_newton_gain(specs[e], starts[e], split.fit, cost)
            for e in inactive
            if e not in SCREENED_BY_SIGNATURE and e not in flexible_terms()
        }
        ranked, by_signature = refit_candidates(inactive, gain, diag.p_holm, gates)
        say(
            f"step {len(steps) + 1}: {'structure left' if diag.structure_left else 'no significant structure'}; "
            f"refitting {', '.join(ranked)}"
        )
        fits = fit_models([specs[e] for e in ranked], [starts[e] for e in ranked], split.fit)
        candidates = [
            _score(e, f, split, current, cur_fit, cur_held, gates, diag)
            for e, f in zip(ranked, fits, strict=True)
            if f is not None
        ]
        screened.append({c.name: c.evidence | {"passed": c.passed} for c in candidates})
        signatures.append(signature_outcomes(by_signature, diag.p_holm, candidates))
        passing = [c for c in candidates if c.passed]
        if not passing:
            stopped = "no_candidate_passes" if diag.structure_left else "no_structure"
            break
        pool = preference_order(passing)
        best = pool[0]
        # Ties of a known confusable pair make the verdict ambiguous; other ties are reported as close calls
        # only, and the loser is screened again once the winner is in the model.
        ties = [
            c.name
            for c in pool[1:]
            if within_two_se(best.held_eval.loglik, c.held_eval.loglik, split.held_out_covariates.block)
        ]
        rivals = [r for r in ties if frozenset({best.name, r}) in CONFUSABLE]
        kind = LIBRARY[best.name].kind
        step = {
            "effect": best.name,
            "kind": kind,
            "named": kind == "physics" and best.evidence["own_evidence"],
            "meaning": LIBRARY[best.name].meaning,
            "rivals": rivals,
            "close_calls": [r for r in ties if r not in rivals],
            "experiment": {r: CONFUSABLE[frozenset({best.name, r})] for r in rivals},
            "evidence": best.evidence,
            "parameters": {
                p: {"value": best.fit.params[p], "sd": best.fit.sd.get(p)} for p in LIBRARY[best.name].params
            },
            "time_check": (
                within_condition_trend(
                    np.concatenate([cur_fit.r, cur_held.r]),
                    joined_covariates(split.fit_covariates, split.held_out_covariates),
                    gates.alpha,
                )
                if best.name in flexible_terms()
                else None
            ),
            "gap_before": gap_table(cur_fit, cur_held, split),
            "gap_after": gap_table(best.fit_eval, best.held_eval, split),
        }
        steps.append(step)
        say(
            f"step {len(steps)}: accepted {best.name} (delta elpd {best.evidence['delta_elpd']:.1f})"
            + (f"; rivals within 2 se: {', '.join(rivals)}" if rivals else "")
        )
        current, cur_fit, cur_held = best.fit, best.fit_eval, best.held_eval
        diag = _diagnose(current, cur_fit, split, gates, seed)
        diagnoses.append(_diagnosis_dict(diag))
    steps, outcome = conclude(steps, diag.structure_left, settled)
    report = {
        **outcome,
        "noise_model": [s["effect"] for s in steps if s["kind"] == "noise"],
        "structure_left": bool(diag.structure_left),
        "stopped": stopped,
        "base": list(base),
        "final_model": list(current.spec.active),
        "specimen": split.specimen,
        "noise_sd": split.noise_sd,
        "steps": steps,
        "screened": screened,
        "signatures": signatures,
        "diagnoses": diagnoses,
        "gap": {"before": gap_table(first_fit, first_held, split), "after": gap_table(cur_fit, cur_held, split)},
        "base_parameters": {p: base_fit.params[p] for p in base_fit.spec.free_names},
        "base_start": "multistart" if start is None else "inference_least_squares",
        "base_converged": base_fit.converged,
        "base_stationary": base_fit.stationary,
        "final_parameters": {p: {"value": current.params[p], "sd": current.sd.get(p)} for p in current.spec.free_names},
        "gates": asdict(gates),
        "seconds": time.perf_counter() - started,
    }
    return Discovery(report, split, first_fit, cur_fit, first_held, cur_held)


__all__ = [
    "Discovery",
    "Gates",
    "VERDICTS",
    "discover",
    "effect_start",
    "fit_base",
    "gap_table",
    "identified",
    "matched_weights",
    "preference_order",
    "refit_candidates",
    "signature_outcomes",
    "within_condition_trend",
    "within_two_se",
    "withhold_where_structure_is_left",
    "conclude",
]
