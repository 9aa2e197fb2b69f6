"""Command line: ``peano-bayes <command>``. Thin over the Python API; see ``peano-bayes --help``.

Every subcommand registers itself in ``COMMANDS``. Bad input (any :class:`PeanoBayesInputError`) becomes a
one-line message on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable

from .errors import PeanoBayesError, PeanoBayesInputError

#: name -> (help, run(args) -> dict | None); ``run.arguments(parser)``, if set, adds the options.
COMMANDS: dict[str, tuple[str, Callable]] = {}


def command(name: str, help: str):
    """Register ``run(args)`` as subcommand ``name``; set ``run.arguments = fn(parser)`` to add its options."""

    def decorate(run):
        COMMANDS[name] = (help, run)
        return run

    return decorate


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="peano-bayes",
        description="Bayesian material-property inference workbench for Peano fluidic muscles.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (help_text, run) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout as the last line")
        getattr(run, "arguments", lambda parser: None)(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    from . import (
        commands,  # noqa: F401  (registers the subcommands)
        enable_compilation_cache,
    )

    try:
        enable_compilation_cache()
    except OSError:  # an unwritable home: compile every time
        pass

    parser = _build_parser()
    args = parser.parse_args(argv)
    _, run = COMMANDS[args.command]
    try:
        result = run(args)
    except PeanoBayesInputError as err:
        print(f"peano-bayes {args.command}: error: {err}", file=sys.stderr)
        return 2
    except PeanoBayesError as err:  # not the user's input: a failure of the computation
        print(f"peano-bayes {args.command}: failed: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"peano-bayes {args.command}: interrupted", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps(result if result is not None else {}, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
