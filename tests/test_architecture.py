"""The package's rooms import only from rooms listed before them in docs/architecture.md.

docs/architecture.md draws ``peano_bayes/`` as a tree of rooms (``physics/``, ``effects.py``, ``data/``, ...,
``app/``) and promises that a room imports only from rooms listed before it. This reads that order from the
document itself and every import of every module (``ast``: module-level and function-level imports alike,
relative ones resolved), and fails on an import of a room listed later, so that the picture a newcomer reads
stays the code's. Top-level infrastructure outside the tree (``errors.py``, ``defaults.py``, ...) may be
imported by any room and is not checked; the package's ``__init__.py`` re-exports and is not a room.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "peano_bayes"


def documented_rooms() -> list[str]:
    """The rooms of the tree in docs/architecture.md, top (imported by all below) to bottom."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    tree = text.split("```", 2)[1]
    assert tree.lstrip().startswith("peano_bayes/"), "the first code block is the package's tree"
    return [m.group(1) for m in re.finditer(r"^  (\w+)(?:/|\.py) ", tree, flags=re.MULTILINE)]


def imported_modules(path: Path, text: str | None = None) -> set[str]:
    """Every ``peano_bayes...`` module that the module at ``path`` (its source: ``text``, else the file's)
    imports, as a dotted name."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    package = parts[:-1]  # a module's package; for an __init__.py, the package itself
    found = set()
    text = path.read_text() if text is None else text
    for node in ast.walk(ast.parse(text, filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                base = (node.module or "").split(".")
            else:
                base = package[: len(package) - (node.level - 1)] + (node.module.split(".") if node.module else [])
            found.add(".".join(base))
            if node.module is None:  # from . import x: x is a module of the package
                found.update(".".join([*base, alias.name]) for alias in node.names)
    return {name for name in found if name.split(".")[0] == "peano_bayes"}


def room_of(dotted: str) -> str | None:
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 else None


def test_the_documented_rooms_are_the_packages_folders_and_registry():
    rooms = documented_rooms()
    assert rooms[0] == "physics" and rooms[-1] == "app" and len(set(rooms)) == len(rooms)
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert folders <= set(rooms), f"folders missing from docs/architecture.md's tree: {sorted(folders - set(rooms))}"
    assert all((PACKAGE / r).is_dir() or (PACKAGE / f"{r}.py").is_file() for r in rooms)


def test_every_room_imports_only_rooms_listed_before_it():
    rank = {room: i for i, room in enumerate(documented_rooms())}
    against = []
    for path in sorted(PACKAGE.rglob("*.py")):
        source = room_of(".".join(path.relative_to(ROOT).with_suffix("").parts))
        if source not in rank:  # infrastructure and the package's own __init__
            continue
        for target in sorted(imported_modules(path)):
            room = room_of(target)
            if room in rank and rank[room] > rank[source]:
                against.append(f"{path.relative_to(ROOT)} ({source}) imports {target} ({room})")
    assert not against, "imports of rooms listed later in docs/architecture.md:\n" + "\n".join(against)


def test_the_import_reader_resolves_relative_imports():
    """The reader itself: on a real module, and on a source written for it (relative imports at each level,
    ``from . import``, a function-level import, one that leaves the package)."""
    names = imported_modules(PACKAGE / "discovery" / "report.py")
    assert "peano_bayes.report" in names and "peano_bayes.report.figures" in names
    text = (
        "from ..physics import simulate\nfrom . import model\n"
        "def f():\n    from ...x import y\n    import peano_bayes.app\n"
    )
    assert imported_modules(PACKAGE / "discovery" / "probe.py", text) == {
        "peano_bayes.physics",
        "peano_bayes.discovery",
        "peano_bayes.discovery.model",
        "peano_bayes.app",
    }
