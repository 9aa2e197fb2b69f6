"""The subcommands of ``peano-bayes``, each a thin wrapper over one documented function of the Python API.

Every subcommand registers itself in :data:`COMMANDS` with :func:`command`; its ``arguments(parser)`` adds its
options and must not import JAX (so ``--help`` stays instant): heavy imports happen inside ``run(args)``.
``run`` returns a JSON-ready dict (printed under ``--json``); a dict whose ``converged`` is ``False`` makes the
command exit with status 3.
"""

# Imported in the order ``--help`` lists the subcommands: each module registers its own in COMMANDS.
from . import data, fitting, results  # noqa: F401
from .registry import COMMANDS, Command, command

__all__ = ["COMMANDS", "Command", "command"]
