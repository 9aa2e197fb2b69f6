"""The inference model of a material chosen with discovery: its configured model plus what discovery named.

The effect registry (:mod:`peano_bayes.effects`) says which :class:`~peano_bayes.physics.ModelConfig` fields
contain each physics effect (``Effect.model``), so the same names serve both directions:
:func:`~peano_bayes.effects.effects_in` reads the effects a configuration contains,
:func:`~peano_bayes.effects.adopt` adds named effects to one. :func:`choose_model` runs discovery from the
material's configured model as the base, writes its report, and returns a :class:`ModelChoice`: the
configuration to sample and the record of why.

Discovery only adds: an effect of the configured model is never removed, because on one specimen's tests a
missing effect can hide behind another (``ABSORBS``, ``CONFUSABLE``) and discovery misses some generating
elements on the bundled files (docs/validation.md, *Discovery on the bundled muscles*). A named physics effect
with no element in the inference model (``cyclic_softening``) is recorded as named but not sampled; the
noise-side effects a report lists under ``noise_model`` are left out (the likelihood's noise model is fixed).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from ..effects import LIBRARY, adopt, effects_in, physics_effects, superset_config
from ..physics.model import ModelConfig


def config_dict(config: ModelConfig) -> dict:
    """The fields of ``config`` as a JSON-ready dict."""
    return {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}


@dataclass(frozen=True)
class ModelChoice:
    """The model a fit samples and how it was chosen.

    **Fields:** ``config`` the :class:`ModelConfig` sampled; ``configured`` the effects of the material's own
    model (its prior's ``[config]``); ``named`` the physics effects discovery named; ``adopted`` those of
    ``named`` that were added (the others were configured already); ``not_in_model`` named effects the
    inference model has no element for; ``verdict`` discovery's verdict (``None`` without discovery);
    ``unexplained`` whether discovery ended with structure it could not name (its verdict, a flexible term it
    needed, or significant residual structure left after the last effect); ``report`` the discovery
    report's folder (a fit's ``summary.json`` records it relative to the result folder: ``discovery``).
    """

    config: ModelConfig
    configured: tuple[str, ...]
    named: tuple[str, ...] = ()
    adopted: tuple[str, ...] = ()
    not_in_model: tuple[str, ...] = ()
    verdict: str | None = None
    unexplained: bool = False
    report: str | None = None

    @property
    def sampled(self) -> tuple[str, ...]:
        """The effects of the sampled model."""
        return effects_in(self.config)

    def as_dict(self) -> dict:
        return {
            "config": config_dict(self.config),
            "effects": list(self.sampled),
            "configured": list(self.configured),
            "discovery": None
            if self.verdict is None
            else {
                "verdict": self.verdict,
                "named": list(self.named),
                "adopted": list(self.adopted),
                "not_in_model": list(self.not_in_model),
                "unexplained": self.unexplained,
                "report": self.report,
            },
        }


def configured_model(config: ModelConfig) -> ModelChoice:
    """The record of a fit that samples its configured model (no discovery)."""
    return ModelChoice(config=config, configured=effects_in(config))


def choice_from_report(config: ModelConfig, report: dict, report_dir: str | Path | None) -> ModelChoice:
    """The :class:`ModelChoice` that adopts the physics effects a discovery ``report`` named into ``config``."""
    named = tuple(n for n in report.get("named", ()) if n in physics_effects())
    configured = effects_in(config)
    chosen = adopt(config, named)
    return ModelChoice(
        config=chosen,
        configured=configured,
        named=named,
        adopted=tuple(n for n in named if LIBRARY[n].model and n not in configured),
        not_in_model=tuple(n for n in named if not LIBRARY[n].model),
        verdict=str(report.get("verdict")),
        unexplained=report.get("verdict") == "unexplained"
        or bool(report.get("described"))
        or bool(report.get("structure_left")),
        report=None if report_dir is None else str(report_dir),
    )


def base_config(base) -> ModelConfig:
    """The inference model holding exactly the elements of the effects ``base`` (every other element off; the
    inlet law is in every model, :func:`~peano_bayes.effects.adopt`)."""
    return adopt(superset_config({}), base)


def base_least_squares(dataset, base, prior, *, specimen: str | None = None, tests=None, seed: int = 0):
    """The inference least squares of ``fit`` (the same starts and solver, :func:`~peano_bayes.inference.driver.
    least_squares`) of the model with effects ``base`` (:func:`base_config`) on the runs of ``specimen`` (default:
    the first) and ``tests`` (default: all) of ``dataset``, under ``prior`` (a whole
    :class:`~peano_bayes.inference.priors.Prior`; the model's part is used). Returns its
    :class:`~peano_bayes.inference.fit.FitResult`: ``params`` is where :func:`~.workflow.discover`'s base fit
    starts (``start``), so discovery screens candidates against the optimum ``fit`` would find, not against a
    search of its own that may stop at its step limit.

    Runs on a second, known mount put the mount into the model, as in ``fit``."""
    from ..inference.driver import least_squares, with_known_mounts
    from ..inference.posterior import DEFAULT_HELD, build_posterior
    from ..inference.reduce import prepare

    specimen = tuple(dataset.specimens)[0] if specimen is None else specimen
    runs = tuple(r for r in dataset.runs if r.specimen == specimen and (tests is None or r.test in tests))
    one = dataclasses.replace(dataset, runs=runs)
    config = with_known_mounts(one, base_config(base))
    model_prior = prior.for_config(config)
    posterior = build_posterior(prepare(one), model_prior, config=config, held=DEFAULT_HELD)
    return least_squares(posterior, model_prior, seed=seed)


def choose_model(
    dataset,
    config: ModelConfig,
    out_dir: str | Path,
    *,
    tests=None,
    seed: int = 0,
    log=print,
    centre=None,
    start=None,
):
    """Run discovery on ``dataset`` (its first specimen, ``tests``) from the effects of ``config`` as the base,
    its base fit started at ``centre`` (name -> value [SI]: the material prior's medians, which on the bundled
    muscles lie decades from the library's nominal values) as well as at the nominal values, or with ``start``
    (name -> value [SI], the inference least squares' optimum of ``config`` on the same data) from that point
    alone (:func:`~peano_bayes.discovery.workflow.fit_base`); write the report into ``out_dir`` and return the
    :class:`ModelChoice` that adds what it named."""
    from .data import discovery_data
    from .report import write_report
    from .workflow import discover

    split = discovery_data(dataset, tests=tests)
    result = discover(split, base=effects_in(config), seed=seed, progress=log, centre=centre, start=start)
    write_report(result, Path(out_dir))
    return choice_from_report(config, result.report, out_dir)


__all__ = [
    "ModelChoice",
    "base_config",
    "base_least_squares",
    "choice_from_report",
    "choose_model",
    "config_dict",
    "configured_model",
]
