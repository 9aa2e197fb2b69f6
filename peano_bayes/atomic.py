"""Atomic file writes: the new content goes to a temporary file beside the target, which then replaces the target
with :func:`os.replace`, so a reader (or an interrupted run) sees the old file or the new one, never half of one.

:func:`replacing` is the general form (a writer that wants a path, e.g. ``savefig`` or ``to_netcdf``, writes the
temporary file itself); :func:`write_text` and :func:`write_bytes` are the common cases. The temporary file is
``.<name>.<random>.tmp`` in the target's directory (the same file system, so the replace is atomic); it is
removed if anything fails before the replace. A replaced file keeps the target's permission bits; a new one gets
the process's default (``0o666`` less the umask).
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a new, empty temporary file beside ``path``; when the block ends without an exception it replaces
    ``path``, otherwise it is removed and the exception propagates (``path`` is untouched)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    try:
        yield tmp
        if path.exists():
            os.chmod(tmp, stat.S_IMODE(path.stat().st_mode))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_into(tmp: Path, data: bytes) -> None:
    """Write ``data`` to the temporary file ``tmp`` (from :func:`replacing`) and flush it to disk."""
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Replace ``path`` atomically by ``data``."""
    with replacing(path) as tmp:
        write_into(tmp, data)


def write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Replace ``path`` atomically by ``text`` (encoded as ``encoding``, line endings as they are in ``text``)."""
    write_bytes(path, text.encode(encoding))


__all__ = ["replacing", "write_bytes", "write_into", "write_text"]
