"""The package's errors, in one place.

:class:`PeanoBayesInputError` is input a user can correct (a file, a specification, an argument): the command line
turns it into a one-line message and exit status 2. :class:`PeanoBayesError` is the root of every error the package
raises on purpose; one that is not an input error (such as the virtual rig's solver failing for some parameters)
becomes a one-line message and exit status 1.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def did_you_mean(word: str, choices: Iterable[str], *, brackets: bool = False, cutoff: float = 0.6) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices`` (``[x]`` with ``brackets``), or ``""``."""
    near = difflib.get_close_matches(word, list(choices), n=1, cutoff=cutoff)
    if not near:
        return ""
    return f" (did you mean [{near[0]}]?)" if brackets else f" (did you mean {near[0]!r}?)"


class PeanoBayesError(Exception):
    """Root of the errors peano_bayes raises on purpose."""


class PeanoBayesInputError(PeanoBayesError, ValueError):
    """Bad input: a file, a specification or an argument that cannot be used as given.

    The message names what was wrong, where, the value seen and what was expected.
    """


class DataFormatError(PeanoBayesInputError):
    """A rig dataset (CSV + TOML sidecar) does not follow the documented format.

    Attributes ``file``, ``row`` (1-based line number in the file, header = 1), ``column``, ``value`` and
    ``expected`` locate the problem; any of them may be ``None`` when it does not apply.
    """

    def __init__(self, message: str, *, file=None, row=None, column=None, value=None, expected=None):
        self.file, self.row, self.column, self.value, self.expected = file, row, column, value, expected
        where = ", ".join(
            part
            for part in (
                f"{file}" if file is not None else None,
                f"row {row}" if row is not None else None,
                f"column '{column}'" if column is not None else None,
            )
            if part
        )
        detail = message
        if value is not None:
            detail += f": got {value!r}"
        if expected is not None:
            detail += f"; expected {expected}"
        super().__init__(f"{where}: {detail}" if where else detail)
