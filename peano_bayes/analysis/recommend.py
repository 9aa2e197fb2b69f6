"""Design recommendation: which material and geometry meet a requirement, and how probably.

A requirement (``[requirement]`` of a spec TOML) asks for at least ``force_n`` [N] at contraction strain
``contraction`` [-] with the pressure at most ``max_pressure_kpa``, and optionally bounds the muscle's width
(``max_width_mm``: the tube length, across the load), its length (``max_length_mm``: the flat length n w), its
inflated thickness (``max_thickness_mm``) and its hysteresis loss (``max_hysteresis`` [-]). Candidates
(``[candidates]``) are every combination of material (a result directory each) x ``n_tubes`` x
``tube_width_mm`` x ``tube_length_mm``. Each is scored by the posterior probability of meeting every
requirement at once, over joint posterior draws of its material, for a **new specimen** of it:

- force: the **operating force**, what the muscle delivers while contracting against its load. At the maximum
  pressure the muscle is stretched :data:`OPERATING_STRETCH` past the required contraction and contracts back
  to it at :data:`OPERATING_RATE_PER_S` (:func:`operating_forces`), so friction and the viscoelastic elements
  act against the motion, as on the lower branch of a load cycle. The material's parameters are carried to the
  candidate geometry by :func:`~peano_bayes.physics.scale_parameters`; a new specimen's wall stiffnesses get
  a factor ``exp(specimen_log_sd z)``, ``z ~ N(0, 1)``, drawn with each posterior draw (the between-specimen
  spread of the fit). Design conditions, not rig conditions: the rig's mount compliance is replaced by the
  design's (default 0, a stiff mount; ``mount_compliance_m_per_n``).
- hysteresis loss: the material's posterior predictive Table 3 hysteresis (``metrics.json``; paired with the
  force by draw). Hysteresis is a ratio of energies and is taken as independent of geometry (an assumption);
- response time (``max_response_time_s``): the time to the required contraction at the material's posterior
  predictive Table 3 step speed, ``contraction x l0 / speed`` with the l0 of the paper's protocol: the tubes
  contract together, so the strain rate, not the end speed, is taken as independent of the tube count (an
  assumption), under the paper's step load. When the fit had no step test the inlet and damping come from
  their prior, so this requirement is scored on prior knowledge, and the report says so;
- width, length: geometry alone; thickness: :func:`thickness_m`, the fully inflated tube plus its walls.

A candidate beyond a limit of its material is infeasible: its probability is 0 and ``infeasible`` says why.
The limits (:func:`material_limits`) are the highest pressure the material was tested at, where the posterior
would start to extrapolate (``bundled/data/design_limits.toml`` for the paper's materials, the test pressure of
the fitted data for any other), and a burst pressure, where the paper reports one or the spec states one
(``[limits.CODE] burst_kpa``). Candidates are ranked by probability, then by the force margin; each carries
every requirement's probability and median margin, the force margin's 94 % interval, its *binding* requirement
(the one least likely to hold), the probability's Monte Carlo standard error over the ``draws`` it rests on, and
the probability that the force holds with the practical margin (:data:`~peano_bayes.analysis.ranking.
PRACTICAL_MARGIN`) to spare. The top candidate is *recommended* only where its probability exceeds the next
feasible candidate's by more than two standard errors of the difference; otherwise the two are tied.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..defaults import MAX_MOUNT_COMPLIANCE_M_PER_N
from ..errors import PeanoBayesInputError
from ..inference.posterior import SPECIMEN_SD
from ..inference.reduce import SPECIMEN_SCALED
from ..physics import Geometry, LoadCycle, scale_parameters, simulate_load_cycle
from .limits import design_limits, limit_violations, material_limits, thickness_m, violations, wall_thickness_m
from .ranking import PRACTICAL_MARGIN, SE_CLEARANCE, mc_se
from .spec import Requirement, Spec, load_spec

#: Strain [-] the muscle is stretched past the required contraction before contracting back to it, so that
#: friction and the viscoelastic elements are in their contracting state when the force is read.
OPERATING_STRETCH = 0.05
#: Strain rate [1/s] of that motion: quasi-static, about the rig's load-cycle rate (0.005-0.01 /s).
OPERATING_RATE_PER_S = 0.01
#: Samples of the simulated motion (stretch then contract).
_OPERATING_SAMPLES = 101
#: Probability mass of the reported intervals.
HDI_PROB = 0.94
#: The fitted tests whose force misfit the operating force carries (both read the muscle's force at pressure).
FORCE_TESTS = ("load_cycle", "blocking")



def _geometry_checks(req: Requirement, g: Geometry, code: str) -> dict[str, float]:
    """Requirement -> margin (fraction of the bound left; negative = violated) of the geometric requirements."""
    margins = {}
    for name, bound, value in (
        ("width", req.max_width_m, g.tube_length_m),
        ("length", req.max_length_m, g.flat_length_m),
        ("thickness", req.max_thickness_m, thickness_m(g, code)),
    ):
        if bound is not None:
            margins[name] = 1.0 - value / bound
    return margins


def operating_strain(contraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Time [s] and imposed strain [-] (n,) of the operating motion: from ``contraction`` stretched by
    :data:`OPERATING_STRETCH`, then contracting back to it, at :data:`OPERATING_RATE_PER_S`."""
    leg_s = OPERATING_STRETCH / OPERATING_RATE_PER_S
    time_s = np.linspace(0.0, 2.0 * leg_s, _OPERATING_SAMPLES)
    strain = np.interp(time_s, [0.0, leg_s, 2.0 * leg_s], [contraction, contraction - OPERATING_STRETCH, contraction])
    return time_s, strain


@functools.partial(jax.jit, static_argnames="config")
def _operating_forces(stacked, time_s, strain, pressure_pa, geometry, config):
    protocol = LoadCycle(time_s, strain, jnp.full_like(time_s, pressure_pa))
    return jax.vmap(lambda p: simulate_load_cycle(p, protocol, config=config, geometry=geometry).force_n[-1])(stacked)


def operating_forces(stacked: dict, config, geometry: Geometry, pressure_pa: float, contraction: float) -> np.ndarray:
    """(n,) force [N] a muscle of ``geometry`` delivers at ``contraction`` and ``pressure_pa`` while contracting
    against its load (:func:`operating_strain`); ``stacked``: parameter name -> (n,) draws [SI] for that
    geometry."""
    time_s, strain = operating_strain(contraction)
    return np.asarray(
        _operating_forces(stacked, jnp.asarray(time_s), jnp.asarray(strain), pressure_pa, geometry, config)
    )


def new_specimen_draws(idata, param_sets: list[dict], *, seed: int = 0) -> dict:
    """Stacked parameter draws (name -> (n,)) of a new specimen of the material from ``param_sets`` of
    :func:`~peano_bayes.inference.results.parameter_draws`. A result of the specimen hierarchy already gives
    new-specimen draws (its ``new_specimen__<name>`` variables): they are stacked unchanged. For a result
    that holds only the spread ``specimen_log_sd`` (a common stiffness factor per specimen), each set's wall
    stiffnesses (:data:`~peano_bayes.inference.reduce.SPECIMEN_SCALED`) are multiplied by
    ``exp(specimen_log_sd z)``, ``z ~ N(0, 1)``, the spread taken at the same posterior draw. A fit of one
    specimen has no spread: the draws are unchanged."""
    from ..inference.results import NEW_SPECIMEN_PREFIX, draw_indices

    stacked = {k: np.asarray([p[k] for p in param_sets], float) for k in param_sets[0]}
    post = idata.posterior
    if SPECIMEN_SD not in post or any(str(k).startswith(NEW_SPECIMEN_PREFIX) for k in post.data_vars):
        return stacked
    sd = post[SPECIMEN_SD].stack(sample=("chain", "draw")).values
    sd = sd[draw_indices(sd.size, len(param_sets))]
    factor = np.exp(sd * np.random.default_rng([seed, 11]).standard_normal(sd.size))
    return {k: v * factor if k in SPECIMEN_SCALED else v for k, v in stacked.items()}


def _design_conditions(stacked: dict, config, mount_compliance_m_per_n: float) -> tuple[dict, list[str]]:
    """The draws with the rig's artefacts replaced by the design's conditions, and what was replaced."""
    removed = []
    if config.mount:
        rig = stacked["mount_compliance_m_per_n"]
        stacked = {**stacked, "mount_compliance_m_per_n": np.full_like(rig, mount_compliance_m_per_n)}
        removed.append(
            f"the rig's mount compliance (median {float(np.median(rig)):.3g} m/N) replaced by the design's "
            f"{mount_compliance_m_per_n:g} m/N"
        )
    return stacked, removed


def _interval(values: np.ndarray) -> list[float]:
    finite = values[np.isfinite(values)]
    if finite.size < 2:
        return [float("nan"), float("nan")]
    import arviz as az

    return [float(x) for x in az.hdi(finite, hdi_prob=HDI_PROB)]


def evaluate_candidates(
    spec: Spec,
    materials: dict,
    *,
    mount_compliance_m_per_n: float = 0.0,
    seed: int = 0,
    discrepancy: dict | None = None,
    log=print,
) -> tuple[list[dict], list[str], dict]:
    """Every candidate of ``spec`` over ``materials`` (code -> ``(idata, metrics or None)``), best first, the
    rig artefacts removed from the predictions (see the module docstring) and each material's pressure limits
    (:meth:`~peano_bayes.analysis.spec.Spec.limits`).

    Each candidate: ``material``, ``n_tubes``, ``tube_width_mm``, ``tube_length_mm``, ``probability`` of
    meeting every requirement (0 if infeasible), ``p_each`` (requirement -> probability it holds), ``margin``
    (requirement -> median fraction of the bound to spare; negative means violated), ``force_margin_interval``
    (94 % interval of the force margin), ``binding``, ``force_median_n``, ``force_interval_n`` (94 %),
    ``force_discrepancy_sd_n`` and ``infeasible`` (the limits it breaks, empty if none).

    ``discrepancy``: code -> test -> sd of the fit's misfit beyond the noise [N or strain]
    (:func:`~peano_bayes.analysis.metrics.misfit_discrepancy`). Where a material's load cycles or blocking test
    misfit, the larger force misfit is added to its operating-force draws as a normal value per draw, as the
    metrics add it: in proportion to the force (its size at the result's own geometry scaled by the candidate's
    median force over the result geometry's, at the same pressure and contraction), growing in proportion to
    pressure above the tested one."""
    from ..inference.results import parameter_draws, result_config

    req = spec.requirement
    out, removed, limits = [], [], {}
    for code, (idata, metrics) in materials.items():
        config = result_config(idata)
        paired = {}  # requirement -> (n,) metric draws, paired with the force draws by index
        n_draws = spec.n_draws
        for name, needed, metric in (
            ("hysteresis", req.max_hysteresis, "hysteresis_loss"),
            ("response_time", req.max_response_time_s, "speed"),
        ):
            if needed is None:
                continue
            if metrics is None:
                raise PeanoBayesInputError(
                    f"material {code}: {name} needs its metrics.json; run 'peano-bayes metrics' first"
                )
            paired[name] = np.asarray(metrics["draw_values"][metric], float)
            n_draws = len(paired[name])  # the same evenly spaced posterior draws, so they pair by index
        total = idata.posterior.sizes["chain"] * idata.posterior.sizes["draw"]
        param_sets, _ = parameter_draws(idata, min(n_draws, total))
        stacked, artefacts = _design_conditions(
            new_specimen_draws(idata, param_sets, seed=seed), config, mount_compliance_m_per_n
        )
        removed += [f"{code}: {a}" for a in artefacts]
        reference = _result_geometry(idata)
        limits[code] = spec.limits(code, idata)
        infeasible = violations(code, req.max_pressure_pa, limits[code])
        misfit_n = max((s for t, s in (discrepancy or {}).get(code, {}).items() if t in FORCE_TESTS), default=0.0)
        if misfit_n > 0:
            at_reference = operating_forces(
                {k: jnp.asarray(v) for k, v in stacked.items()}, config, reference, req.max_pressure_pa, req.contraction
            )
            tested_pa = None if limits[code] is None else 1e3 * limits[code]["max_tested_kpa"]
            growth = 1.0 if tested_pa is None else max(1.0, req.max_pressure_pa / tested_pa)
            z = np.random.default_rng([seed, 13]).standard_normal(len(param_sets))
        log(f"{code}: {len(param_sets)} posterior draws (new specimens) over the candidate geometries")
        for n, w, length in itertools.product(spec.n_tubes, spec.tube_width_m, spec.tube_length_m):
            target = Geometry(n_tubes=n, tube_width_m=w, tube_length_m=length)
            scaled = {k: jnp.asarray(v) for k, v in scale_parameters(stacked, reference, target).items()}
            force = operating_forces(scaled, config, target, req.max_pressure_pa, req.contraction)
            sd_n = None
            if misfit_n > 0:
                sd_n = misfit_n * growth * abs(np.nanmedian(force) / np.nanmedian(at_reference))
                force = force + sd_n * z
            holds = {"force": np.isfinite(force) & (force >= req.force_n)}
            margin = {"force": float(np.median(force) / req.force_n - 1.0)}
            if "hysteresis" in paired:
                h = paired["hysteresis"][: len(force)]
                holds["hysteresis"] = np.isfinite(h) & (h <= req.max_hysteresis)
                margin["hysteresis"] = float(1.0 - np.nanmedian(h) / req.max_hysteresis)
            if "response_time" in paired:
                t = req.contraction * float(reference.flat_length_m) / paired["response_time"][: len(force)]
                holds["response_time"] = np.isfinite(t) & (t <= req.max_response_time_s)
                margin["response_time"] = float(1.0 - np.nanmedian(t) / req.max_response_time_s)
            for name, m in _geometry_checks(req, target, code).items():
                holds[name] = np.full(force.shape, m >= 0.0)
                margin[name] = m
            p_each = {name: float(np.mean(h)) for name, h in holds.items()}
            joint = 0.0 if infeasible else float(np.mean(np.all(np.stack(list(holds.values())), axis=0)))
            with_margin = np.isfinite(force) & (force >= (1.0 + PRACTICAL_MARGIN) * req.force_n)
            binding = min(p_each, key=lambda k: (p_each[k], margin[k]))
            out.append(
                dict(
                    material=code,
                    n_tubes=n,
                    tube_width_mm=1e3 * w,
                    tube_length_mm=1e3 * length,
                    probability=joint,
                    probability_se=mc_se(joint, len(force)),
                    draws=len(force),
                    p_force_with_margin=0.0 if infeasible else float(np.mean(with_margin)),
                    p_each=p_each,
                    margin=margin,
                    force_margin_interval=[x / req.force_n - 1.0 for x in _interval(force)],
                    binding=binding,
                    force_median_n=float(np.median(force)),
                    force_interval_n=_interval(force),
                    force_discrepancy_sd_n=None if sd_n is None else float(sd_n),
                    infeasible=infeasible,
                )
            )
    out.sort(key=lambda c: (bool(c["infeasible"]), -c["probability"], -c["margin"]["force"]))
    return out, removed, limits


def _result_geometry(idata) -> Geometry:
    """The geometry a result's data came from (its ``geometry`` attribute), else the paper's."""
    raw = idata.posterior.attrs.get("geometry")
    if not raw:
        return Geometry()
    g = json.loads(raw)
    return Geometry(n_tubes=int(g["n_tubes"]), tube_width_m=g["tube_width_m"], tube_length_m=g["tube_length_m"])


def recommended(candidates: list[dict]) -> dict:
    """Whether the top of ``candidates`` (best first) is recommended: ``{"verdict": "recommended" | "tied" |
    "none", "candidates": [indices]}``. *Recommended* when it is feasible and its probability exceeds every other
    feasible candidate's by more than :data:`~peano_bayes.analysis.ranking.SE_CLEARANCE` standard errors of the
    difference (taken as independent: conservative for two geometries of one material, whose draws are shared);
    *tied* naming the candidates within that of it; *none* when no feasible candidate meets the requirement in
    any draw."""
    feasible = [i for i, c in enumerate(candidates) if not c["infeasible"]]
    if not feasible or candidates[feasible[0]]["probability"] == 0.0:
        return {"verdict": "none", "candidates": []}
    top = candidates[feasible[0]]
    tied = [
        i
        for i in feasible[1:]
        if top["probability"] - candidates[i]["probability"]
        <= SE_CLEARANCE * math.hypot(top["probability_se"], candidates[i]["probability_se"])
    ]
    return {"verdict": "tied" if tied else "recommended", "candidates": [feasible[0], *tied]}


def explain(candidate: dict, requirement: Requirement) -> str:
    """One sentence on why a candidate ranks where it does."""
    c = candidate
    design = f"{c['material']} with {c['n_tubes']} tubes of {c['tube_width_mm']:g} x {c['tube_length_mm']:g} mm"
    low, high = c["force_interval_n"]
    force = (
        f"an operating force of {c['force_median_n']:.1f} N (94 % interval {low:.1f} to {high:.1f} N, a new "
        f"specimen contracting against the load) at {100 * requirement.contraction:g} % contraction and "
        f"{requirement.max_pressure_pa / 1e3:g} kPa against the {requirement.force_n:g} N asked"
    )
    if c["infeasible"]:
        return f"{design} is infeasible: {'; '.join(c['infeasible'])}; it would give {force}."
    binding = c["binding"]
    text = (
        f"{design} meets every requirement with probability {c['probability']:.2f} ± {c['probability_se']:.2f} "
        f"(Monte Carlo standard error over {c['draws']} draws), with {force}; "
        f"the binding requirement is {binding} (P = {c['p_each'][binding]:.2f}, median margin "
        f"{100 * c['margin'][binding]:+.0f} %)."
    )
    if c["probability"] < 0.5:
        text += (
            f" No candidate of the grid is likely to meet the requirement: relax {binding} or widen the grid"
            " (other materials, geometries or a higher pressure where a material allows it)."
        )
    return text


def recommend(
    spec_path: str | Path,
    results_dir: str | Path | None = None,
    *,
    mount_compliance_m_per_n: float = 0.0,
    seed: int = 0,
    log=print,
) -> dict:
    """Load a spec and the material results it names, score every candidate; returns ``requirement``,
    ``candidates`` (best first, see :func:`evaluate_candidates`), ``explanation`` of the top one, ``removed``
    (the rig artefacts left out of the design's predictions) and ``notes``. ``mount_compliance_m_per_n``
    [m/N]: the design's mount (default 0: stiff). ``seed``: of the new-specimen factors."""
    compliance = mount_compliance_m_per_n
    if not (math.isfinite(compliance) and 0.0 <= compliance <= MAX_MOUNT_COMPLIANCE_M_PER_N):
        raise PeanoBayesInputError(
            "mount compliance (--mount-compliance): expected a number of m/N from 0 to "
            f"{MAX_MOUNT_COMPLIANCE_M_PER_N:g} (100 mm/N), "
            f"got {mount_compliance_m_per_n!r}"
        )
    from ..inference.results import load_result
    from .metrics import read_metrics, result_discrepancy

    spec = load_spec(spec_path)
    root = Path(results_dir) if results_dir is not None else spec.results_dir
    codes = spec.materials or tuple(sorted(p.parent.name for p in root.glob("*/posterior.nc")))
    if not codes:
        where = "no such folder" if not root.is_dir() else "no material results (*/posterior.nc) in it"
        origin = "the spec's [results] dir" if results_dir is None else "the results folder"
        raise PeanoBayesInputError(
            f"{root} ({origin}): {where}; expected a folder that 'peano-bayes run' (or fit) wrote"
        )
    materials, misfits = {}, {}
    for code in codes:
        directory = root / code
        if not (directory / "posterior.nc").exists():
            named = "" if not spec.materials else f" (named in {spec_path} [candidates] materials)"
            raise PeanoBayesInputError(
                f"{directory}: no posterior.nc for material {code!r}{named}; expected a result folder per material "
                f"under {root}"
            )
        metrics = read_metrics(directory) if (directory / "metrics.json").exists() else None
        materials[code] = (load_result(directory), metrics)
        misfits[code] = result_discrepancy(directory)
    candidates, removed, limits = evaluate_candidates(
        spec, materials, mount_compliance_m_per_n=mount_compliance_m_per_n, seed=seed, discrepancy=misfits, log=log
    )
    notes = []
    if spec.requirement.max_response_time_s is not None:
        prior_based = [c for c, (_, m) in materials.items() if m and m["summary"]["speed"]["from_prior"]]
        if prior_based:
            notes.append(
                f"response time of {', '.join(prior_based)} rests on the prior of the inlet and damping "
                "parameters: their fits had no step test"
            )
    for code, tests in misfits.items():
        if tests:
            carried = [t for t in tests if t in FORCE_TESTS]
            notes.append(
                f"the model misfits {code}'s {', '.join(tests)} test{'s' if len(tests) > 1 else ''} beyond the "
                "sensor noise (residuals with structure): "
                + (
                    f"its operating forces carry the {' / '.join(carried)} force misfit as a model discrepancy "
                    "(force_discrepancy_sd_n), so its probabilities are wider than the closest model's"
                    if carried
                    else "its predictions are the closest model's and do not include that misfit"
                )
            )
    unconverged = [c for c, (idata, _) in materials.items() if not idata.posterior.attrs.get("converged", 1)]
    if unconverged:
        notes.append(f"the chains of {', '.join(unconverged)} did not converge: their probabilities are provisional")
    return {
        "spec": str(spec.source),
        "requirement": spec.requirement.__dict__,
        "limits": limits,
        "margin": PRACTICAL_MARGIN,
        "draws": {c["material"]: c["draws"] for c in candidates},
        "recommended": recommended(candidates),
        "candidates": candidates,
        "explanation": explain(candidates[0], spec.requirement),
        "removed": removed,
        "notes": notes,
    }


def recommendation_markdown(report: dict, top: int = 10) -> str:
    """The ``top`` candidates as a markdown table, then the one-sentence explanation of the first, what was
    removed from the rig's conditions and the notes."""
    margin = report["margin"]
    lines = [
        f"| rank | material | tubes | w [mm] | l [mm] | P(meets all) | P(force +{100 * margin:g} %) | operating "
        "force [N] (94 %) | force margin (94 %) | binding |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, c in enumerate(report["candidates"][:top], 1):
        low, high = c["force_interval_n"]
        m_low, m_high = c["force_margin_interval"]
        p_binding = c["p_each"][c["binding"]]
        binding = f"{c['binding']} ({p_binding:.2f} ± {mc_se(p_binding, c['draws']):.2f})"
        binding = "infeasible" if c["infeasible"] else binding
        lines.append(
            f"| {i} | {c['material']} | {c['n_tubes']} | {c['tube_width_mm']:g} | {c['tube_length_mm']:g} | "
            f"{c['probability']:.2f} ± {c['probability_se']:.2f} | "
            f"{c['p_force_with_margin']:.2f} ± {mc_se(c['p_force_with_margin'], c['draws']):.2f} | "
            f"{c['force_median_n']:.1f} ({low:.1f} to {high:.1f}) | "
            f"{100 * c['margin']['force']:+.0f} % ({100 * m_low:+.0f} to {100 * m_high:+.0f} %) | {binding} |"
        )
    refused = {c["material"]: c["infeasible"] for c in report["candidates"] if c["infeasible"]}
    verdict = report["recommended"]
    tied = verdict["candidates"][1:]
    lead = []
    if verdict["verdict"] == "tied":
        named = ", ".join(str(i + 1) for i in tied[:8]) + (f" and {len(tied) - 8} more" if len(tied) > 8 else "")
        lead = [
            f"**No single recommendation**: candidate{'s' if len(tied) > 1 else ''} {named} "
            f"{'are' if len(tied) > 1 else 'is'} within {SE_CLEARANCE:g} Monte Carlo standard errors of the first: "
            "more draws or the other requirements decide between them.",
            "",
        ]
    extra = [f"Infeasible: {code}: {'; '.join(reasons)}." for code, reasons in refused.items()]
    extra += [f"Design conditions: {r}." for r in report.get("removed", [])]
    extra += [f"Note: {n}." for n in report.get("notes", [])]
    head = [f"*P(force +{100 * margin:g} %)*: the probability the operating force clears the requirement by the "
            f"practical margin of {100 * margin:g} %; ± the Monte Carlo standard error.", ""]  # fmt: skip
    return "\n".join(head + lines + ["", *lead, report["explanation"], *([""] + extra if extra else [])])


__all__ = [
    "OPERATING_RATE_PER_S",
    "OPERATING_STRETCH",
    "Requirement",
    "Spec",
    "design_limits",
    "evaluate_candidates",
    "explain",
    "limit_violations",
    "load_spec",
    "material_limits",
    "recommended",
    "new_specimen_draws",
    "operating_forces",
    "operating_strain",
    "recommend",
    "recommendation_markdown",
    "thickness_m",
    "wall_thickness_m",
]
