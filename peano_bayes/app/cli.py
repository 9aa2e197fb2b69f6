"""Command line: ``peano-bayes <command>``. It parses, calls one documented function and prints.

Exit status: 0 success; 1 a computation failed (for example the virtual rig's solver); 2 bad input (a one-line
message naming what, where and what was expected, or a path given that cannot be read or written as asked;
no traceback, nothing half-written); 3 a fit or run finished but did not converge (its results are written
and marked unconverged); 130 interrupted (Ctrl-C).

``--json`` makes standard output carry only one JSON object (standard JSON: a value that is not finite is
``null``): the command's result, or, when it stops with status 1, 2 or 130, ``{"error": message,
"exit_status": N}``, also when the command line itself cannot be parsed (then its usage goes to standard
error); everything else (messages, progress) goes to standard error. An option the command does not know is
reported with that command's usage. ``--quiet`` keeps only warnings and
errors; ``--verbose`` adds tracebacks of failed computations. ``--help`` and ``--version`` do not import JAX.
The compiled programs are cached on disk (``$PEANO_BAYES_CACHE``, default ``~/.cache/peano_bayes/jax``), so a
second run skips most compilation.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import traceback
from pathlib import Path

from .. import __version__
from ..defaults import compilation_cache_dir
from ..errors import PeanoBayesError, PeanoBayesInputError
from .commands import COMMANDS

#: Exit status of each outcome (documented in the module docstring and ``--help``).
EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_UNCONVERGED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130

_EPILOG = (
    "exit status: 0 success, 1 a computation failed, 2 bad input, 3 finished but not converged, "
    "130 interrupted. 'peano-bayes COMMAND --help' shows a command's options."
)


#: The options every command takes (after its name).
COMMON_OPTIONS = ("--json", "-q", "--quiet", "-v", "--verbose")


class UsageError(Exception):
    """A command line that cannot be parsed: ``message`` and the ``parser`` (a command's, or the top level's)
    whose usage applies."""

    def __init__(self, parser: argparse.ArgumentParser, message: str):
        super().__init__(message)
        self.parser, self.message = parser, message


class _Parser(argparse.ArgumentParser):
    """argparse's parser, raising :class:`UsageError` where argparse would print and exit, so that the caller
    can answer under ``--json`` too; ``commands`` maps each command name to its parser."""

    commands: dict[str, argparse.ArgumentParser]

    def error(self, message):
        required = "the following arguments are required: "
        if message.startswith(required) and any(not n.startswith("-") for n in message[len(required) :].split(", ")):
            lists = [a.option_strings[-1] for a in self._actions if a.option_strings and a.nargs == "+"]
            if lists:  # a list option before the positional argument took it as one of its values
                message += (
                    f" (a list option such as {lists[0]} takes every word after it up to the next option: give "
                    "the positional arguments first)"
                )
        raise UsageError(self, message)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every registered command (imports no JAX). Its ``parse_args`` raises
    :class:`UsageError` on a command line it cannot parse."""
    parser = _Parser(
        prog="peano-bayes",
        description="Bayesian material-property inference workbench for Peano fluidic muscles.",
        epilog=_EPILOG,
    )
    parser.add_argument("--version", action="version", version=f"peano-bayes {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--json", action="store_true", help="print only one JSON object on stdout (the rest: stderr)")
    talk = common.add_mutually_exclusive_group()
    talk.add_argument("-q", "--quiet", action="store_true", help="print only warnings and errors")
    talk.add_argument("-v", "--verbose", action="store_true", help="also print tracebacks of failed computations")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    parser.commands = {}
    for name, command in COMMANDS.items():
        p = sub.add_parser(name, parents=[common], help=command.help, description=command.help, epilog=_EPILOG)
        command.arguments(p)
        parser.commands[name] = p
    return parser


def parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """``argv`` parsed; an option or argument the command does not take raises :class:`UsageError` with the
    command's own usage, and says where an option every command takes belongs (after the command's name)."""
    args, extra = parser.parse_known_args(argv)
    if extra:
        misplaced = [a for a in extra if a in COMMON_OPTIONS]
        where = (
            f" ({' '.join(misplaced)} goes after the command's name: peano-bayes {args.command} {misplaced[0]} ...)"
            if misplaced
            else ""
        )
        raise UsageError(parser.commands[args.command], f"unrecognized arguments: {' '.join(extra)}{where}")
    return args


def _use_compilation_cache() -> None:
    """Point JAX's persistent compilation cache at ``$PEANO_BAYES_CACHE`` (or ``~/.cache/peano_bayes/jax``)
    without importing JAX: JAX reads these variables when it is first imported, if it ever is."""
    directory = str(compilation_cache_dir())
    if "jax" in sys.modules:  # already imported (a caller's process): configure it directly
        from ..jax_config import enable_compilation_cache

        with contextlib.suppress(OSError):  # an unwritable home: compile every time
            enable_compilation_cache(directory)
        return
    with contextlib.suppress(OSError):
        Path(directory).mkdir(parents=True, exist_ok=True)
        os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", directory)
        os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1")


def strict_json(value):
    """``value`` with every non-finite float (NaN: a metric no draw defines) as ``None``, so ``--json`` prints
    standard JSON (``null``), which any reader accepts, rather than Python's ``NaN``."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    return value


def _json_number(value):
    """A number type JSON does not know (a NumPy scalar) as a float, or ``None`` where it is not finite."""
    return strict_json(float(value))


def main(argv: list[str] | None = None) -> int:
    """Run ``peano-bayes`` with ``argv`` (default: ``sys.argv[1:]``); return the exit status."""
    try:
        return _main(argv)
    except BrokenPipeError:  # the reader went away (``peano-bayes check TP --json | head``): stop without a traceback
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        with contextlib.suppress(OSError):
            print("peano-bayes: stopped: the pipe it wrote to was closed", file=sys.stderr)
        return EXIT_FAILED


def _main(argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    try:
        args = parse(parser, argv)
    except UsageError as err:
        err.parser.print_usage(sys.stderr)
        print(f"{err.parser.prog}: error: {err.message}", file=sys.stderr)
        if "--json" in argv:
            print(json.dumps({"error": f"error: {err.message}", "exit_status": EXIT_BAD_INPUT}))
        return EXIT_BAD_INPUT
    command = COMMANDS[args.command]
    if args.quiet and hasattr(args, "no_progress"):
        args.no_progress = True
    _use_compilation_cache()
    say = f"peano-bayes {args.command}"
    # Human output goes to stdout, or to stderr under --json (stdout then holds the JSON object alone), or
    # nowhere under --quiet; warnings and errors always go to stderr.
    human = open(os.devnull, "w") if args.quiet else (sys.stderr if args.json else sys.stdout)  # noqa: SIM115

    def stop(status: int, word: str, message: str) -> int:
        """Say why the command stopped (stderr) and, under ``--json``, as the one object on stdout too."""
        print(f"{say}: {word}{': ' if message else ''}{message}", file=sys.stderr)
        if args.json:
            print(json.dumps({"error": f"{word}: {message}" if message else word, "exit_status": status}))
        return status

    try:
        with contextlib.redirect_stdout(human):
            result = command.run(args)
    except PeanoBayesInputError as err:
        return stop(EXIT_BAD_INPUT, "error", str(err))
    except BrokenPipeError:
        raise
    except OSError as err:  # a file or folder cannot be read or written as asked (a path the user gave)
        if args.verbose:
            traceback.print_exc()
        if err.filename is None:  # not a path (a lost connection, too many open files): the work failed
            return stop(EXIT_FAILED, "failed", str(err))
        expected = "a folder or a new path" if isinstance(err, (FileExistsError, NotADirectoryError)) else "a path"
        return stop(
            EXIT_BAD_INPUT, "error", f"{err.filename}: {err.strerror or err}; expected {expected} it can read or write"
        )
    except PeanoBayesError as err:  # not the user's input: a failure of the computation
        if args.verbose:
            traceback.print_exc()
        return stop(EXIT_FAILED, "failed", str(err))
    except KeyboardInterrupt as err:  # a sampler's own stop says where it saved its state
        return stop(EXIT_INTERRUPTED, "interrupted", str(err))
    finally:
        if human not in (sys.stdout, sys.stderr):
            human.close()
    result = {} if result is None else result
    if args.json:
        print(json.dumps(strict_json(result), default=_json_number, allow_nan=False))
    if result.get("converged") is False:
        print(f"{say}: WARNING: not converged (exit status {EXIT_UNCONVERGED})", file=sys.stderr)
        return EXIT_UNCONVERGED
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
