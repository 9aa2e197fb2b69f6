"""The command registry and what every subcommand shares: :data:`COMMANDS` (name -> :class:`Command`, filled by
:func:`command` as the subcommand modules are imported, in ``--help`` order) and the checks of common options."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ... import bundled
from ...defaults import (
    MAX_PRESSURE_KPA,
)
from ...errors import PeanoBayesInputError


@dataclass(frozen=True)
class Command:
    """One subcommand: its one-line ``help`` and ``run(args) -> dict | None``; ``run.arguments(parser)``, if
    set, adds its options."""

    help: str
    run: Callable

    def arguments(self, parser) -> None:
        getattr(self.run, "arguments", lambda parser: None)(parser)


#: name -> :class:`Command`, in the order ``--help`` lists them.
COMMANDS: dict[str, Command] = {}


def command(name: str, help: str):
    """Register ``run(args)`` as subcommand ``name``; set ``run.arguments = fn(parser)`` to add its options."""

    def decorate(run):
        COMMANDS[name] = Command(help, run)
        return run

    return decorate


def _writable_folder(path, option: str) -> Path:
    """``path`` as a folder a command may write into (existing, or creatable where its nearest existing parent is
    a writable folder); otherwise :class:`PeanoBayesInputError` naming ``option``, before any work is done."""
    if not str(path).strip():
        raise PeanoBayesInputError(f"{option}: an empty path; expected a folder (existing or new)")
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise PeanoBayesInputError(f"{option} {path}: a file; expected a folder (existing or new)")
    parent = path
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not _can_create_in(parent):
        raise PeanoBayesInputError(f"{option} {path}: {parent} is not a folder this user can write into")
    return path


def _can_create_in(folder: Path) -> bool:
    """Whether a file can be created in ``folder``, by creating (and at once removing) one: ``os.access`` answers
    from permission bits, which say yes to root everywhere, also under ``/proc`` or on a read-only mount."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def _seed(text: str) -> int:
    """A ``--seed`` value: a whole number >= 0 (NumPy's generators refuse negative seeds)."""

    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value


_DATA_HELP = (
    "the dataset: a CSV with its TOML sidecar (or its stem), or a bundled material code "
    f"({' '.join(bundled.MATERIALS)})"
)


_PRESSURE_HELP = (
    "simulate the metrics at this pressure [kPa] instead of each material's own test pressure (written to "
    "metrics_at_<KPA>kPa.json)"
)


def _pressure_kpa(value: float | None, option: str = "--pressure-kpa") -> float | None:
    if value is not None and not (math.isfinite(value) and 0 < value <= MAX_PRESSURE_KPA):
        raise PeanoBayesInputError(
            f"{option} must be a pressure in kPa above 0 and at most {MAX_PRESSURE_KPA:g} (the model's range), "
            f"got {value:g}"
        )
    return value


__all__ = ["COMMANDS", "Command", "command"]
