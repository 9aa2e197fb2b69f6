"""``summary.json``, the record of one fit, written and read through one typed schema (:class:`Summary`).

:func:`~peano_bayes.app.pipeline.infer` builds a :class:`Summary` and writes it with :func:`write_summary`;
everything that reads a result (the main job's index, ``metrics``, the batch runner) reads it with
:func:`read_summary`, which refuses a file that is not a summary and names what is missing. A :class:`Summary` is
also a read-only mapping, so ``summary["steps"]`` and ``summary.steps`` are the same value.

Units: SI throughout (``units`` gives each parameter's); times in seconds (``timings_s``).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from ..atomic import write_text
from ..errors import PeanoBayesInputError


@dataclass(frozen=True, eq=False)
class Summary(Mapping):
    """One fit's record (the fields of ``summary.json``).

    **What was fitted:** ``material`` code; ``label`` the result folder's name; ``dataset`` the data file;
    ``prior`` the prior's label; ``tests`` fitted; ``model`` the sampled model and how it was chosen
    (:meth:`~peano_bayes.discovery.choice.ModelChoice.as_dict`); ``seed``.
    **Sampling:** ``n_walkers`` per ensemble; ``n_ensembles``; ``warmup`` steps; ``warmup_stable``;
    ``warmup_changes`` the proposal's change at each warm-up bound; ``checks`` every convergence check (steps,
    tau_max); ``steps`` in all; ``resumed_from_step``; ``acceptance``; ``sampler_coordinates``; ``convergence``
    (:meth:`~peano_bayes.inference.diagnostics.Convergence.as_dict`, with ``converged``); ``min_ess_per_s``.
    **Posterior:** ``parameters`` name -> mean, sd, 94 % HDI [SI]; ``hierarchy`` the specimens and varying
    parameters; ``new_specimen`` the predictive of a specimen not yet made; ``contraction`` posterior sd over
    prior sd's complement; ``prior_z`` where each posterior median sits in its prior, in prior sd
    (:func:`~peano_bayes.inference.results.prior_positions`); ``prior_conflicts`` the parameters whose median lies
    beyond :data:`~peano_bayes.inference.results.PRIOR_CONFLICT_SD` of them in a tail, where prior and data
    disagree; ``ridges`` strongly correlated combinations; ``units``; ``fixed`` held values.
    **Fit:** ``fit_quality_least_squares`` and ``fit_quality_posterior_mean`` per test (RMSE, R^2, excess over
    the noise floor); ``residual_correlation`` per test; ``least_squares`` (``fit.json``'s outcome);
    ``posterior_mode`` (log posterior, steps, status codes of :class:`~peano_bayes.inference.status.ModeStatus`);
    ``timings_s`` per stage.
    """

    material: str
    label: str
    dataset: str
    prior: str
    tests: list
    model: dict
    seed: int
    n_walkers: int
    steps: int
    convergence: dict
    parameters: dict
    units: dict
    warmup: int = 0
    warmup_stable: bool = True
    warmup_changes: list = field(default_factory=list)
    checks: list = field(default_factory=list)
    n_ensembles: int = 1
    resumed_from_step: int = 0
    acceptance: float = float("nan")
    sampler_coordinates: dict = field(default_factory=dict)
    min_ess_per_s: float = float("nan")
    hierarchy: dict = field(default_factory=dict)
    new_specimen: dict = field(default_factory=dict)
    contraction: dict = field(default_factory=dict)
    prior_z: dict = field(default_factory=dict)
    prior_conflicts: list = field(default_factory=list)
    ridges: list = field(default_factory=list)
    fixed: dict = field(default_factory=dict)
    fit_quality_least_squares: dict = field(default_factory=dict)
    fit_quality_posterior_mean: dict = field(default_factory=dict)
    residual_correlation: dict = field(default_factory=dict)
    least_squares: dict = field(default_factory=dict)
    posterior_mode: dict | None = None
    timings_s: dict = field(default_factory=dict)

    # -- a read-only mapping of the fields, for readers that take a summary as a dict --
    def __getitem__(self, key: str):
        if key not in _FIELDS:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(_FIELDS)

    def __len__(self) -> int:
        return len(_FIELDS)

    @property
    def converged(self) -> bool:
        return bool(self.convergence.get("converged", False))

    def to_json(self) -> dict:
        """The JSON-ready dict written to ``summary.json``."""
        return {name: getattr(self, name) for name in _FIELDS}

    @classmethod
    def from_json(cls, data, source: str = "summary.json") -> Summary:
        """The :class:`Summary` of a parsed ``summary.json``; raises :class:`PeanoBayesInputError` naming
        ``source`` and what is missing or of the wrong type. Keys this version does not know are ignored (a file
        written by a newer version); optional fields missing from an older file take their defaults."""
        if not isinstance(data, dict):
            raise PeanoBayesInputError(f"{source}: expected a JSON object (a fit's summary), got {type(data).__name__}")
        missing = [f.name for f in _REQUIRED if f.name not in data]
        if missing:
            raise PeanoBayesInputError(
                f"{source}: not a fit's summary: missing {', '.join(missing)} (expected the summary.json that "
                "'peano-bayes fit' writes)"
            )
        for name, kind in _TYPES.items():
            value = data.get(name)
            if value is not None and not isinstance(value, kind):
                raise PeanoBayesInputError(f"{source}: {name!r} is {type(value).__name__}, expected {kind.__name__}")
        return cls(**{name: data[name] for name in _FIELDS if name in data})


_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(Summary))
_REQUIRED = tuple(f for f in dataclasses.fields(Summary) if f.default is dataclasses.MISSING and
                  f.default_factory is dataclasses.MISSING)  # fmt: skip
#: Types checked on reading (JSON gives int for a whole float; numbers are not checked beyond that).
_TYPES = {"material": str, "label": str, "tests": list, "model": dict, "steps": int, "convergence": dict,
          "parameters": dict, "units": dict}  # fmt: skip


def read_summary(path: str | Path) -> Summary:
    """The :class:`Summary` in ``path`` (a ``summary.json`` or the result folder holding one)."""
    path = Path(path)
    file = path / "summary.json" if path.is_dir() else path
    try:
        data = json.loads(file.read_text())
    except FileNotFoundError:
        raise PeanoBayesInputError(
            f"{file}: no such file (a result folder holds the summary.json of its fit)"
        ) from None
    except json.JSONDecodeError as err:
        raise PeanoBayesInputError(f"{file}: not valid JSON ({err})") from None
    return Summary.from_json(data, str(file))


def write_summary(path: str | Path, summary: Summary) -> None:
    """Write ``summary`` to ``path`` atomically (non-finite numbers as JSON's NaN/Infinity, as Python writes them)."""
    write_text(Path(path), json.dumps(summary.to_json(), indent=1, default=float))


__all__ = ["Summary", "read_summary", "write_summary"]
