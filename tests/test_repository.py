"""Every file of the repository that names another file of the repository names one that exists.

A user who clones the repository (or unpacks its source distribution) has the tracked files and nothing else, so
a docstring, comment, README or result that points at a removed experiment folder or at a project-internal note
sends them nowhere. This reads every tracked text file (``git ls-files``; without git, every file under the root
but ``.git``, ``.venv`` and caches; pattern files such as ``.gitignore`` aside) and checks three kinds of
reference:

- **repository paths**: tokens that start at a top-level folder (``experiments``, ``docs``, ``peano_bayes``,
  ``priors``, ``tests``, ``notebooks``) followed by ``/``, taken from the repository root. Placeholders
  (``<CODE>``, ``{code}``, ``[.gz]``) and wildcards are globbed: the reference holds if some file matches. A path
  written as ``<commit>:<path>`` names a file of that commit (how a removed result is cited); it is checked
  with ``git cat-file`` where git knows the commit and skipped where it does not (a shallow clone);
- **markdown links** ``[text](target)`` in markdown files and notebooks: a relative target is taken from the
  linking file's folder (URLs and in-page anchors are not files);
- **notes users do not have**: the design and physics notes the project was built from, which are not part of
  the repository, cited by name (:data:`ABSENT_NOTES`).

A captured program output (``*.log``) is a record of one run, kept verbatim: the output folders it names (a fit's
result folder, gitignored for its size) are what that run wrote, not files the repository promises, so its
repository paths are not checked (absent notes still are).

The failure lists every ``file:line: reference``.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Top-level folders whose paths are checked.
TOP_LEVEL = ("experiments", "docs", "peano_bayes", "priors", "tests", "notebooks")

#: Project-internal notes that are not in the repository: any mention of one is a dangling reference. The
#: patterns are written so that this file does not match them.
ABSENT_NOTES = re.compile(r"\b(?:DESIGN|PHYSICS|DISCREPANCY|ANCHORS_AND_APIS)\.md\b|\.\./shared\b")

#: A repository path: a top-level folder, ``/`` and path characters (placeholders and wildcards included),
#: optionally qualified by a commit (``<hex>:``). Not preceded by a path character, so the tail of an absolute
#: path or URL (``/home/x/peano_bayes/...``, ``github.com/o/peano_bayes``) is not taken for one.
PATH = re.compile(
    r"(?<![\w./\-])(?:(?P<commit>[0-9a-f]{7,40}):)?"
    r"(?P<path>(?:" + "|".join(TOP_LEVEL) + r")/[\w.\-/<>{}*?\[\]]*)"
)

#: A markdown link's target: ``](target)`` up to whitespace or the closing parenthesis.
LINK = re.compile(r"\]\((?P<target><[^>]*>|[^)\s]+)")

#: Where a placeholder or wildcard starts: the path is globbed from there.
PLACEHOLDER = re.compile(r"<[^>/]*>|\{[^}/]*\}|\[[^\]/]*\]|\*|\?")

#: Files whose markdown links are checked (elsewhere ``](`` is code, or a link of a generated report relative to
#: its output folder).
MARKDOWN = {".md", ".ipynb"}

#: Files of patterns, not references (``.gitignore``'s ``experiments/*/claims/`` names what may appear).
PATTERN_FILES = {".gitignore", ".gitattributes", ".dockerignore"}

#: Captured program output: a verbatim record of a run, whose repository paths are the run's own outputs.
CAPTURED_OUTPUT = {".log"}

SKIPPED_DIRS = {".git", ".venv", "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis", "node_modules"}


def _git(*args: str) -> subprocess.CompletedProcess | None:
    if shutil.which("git") is None:
        return None
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=False)


def tracked_files() -> list[Path]:
    """The repository's files: tracked by git if git knows the folder, else every file under the root."""
    listed = _git("ls-files", "-z")
    if listed is not None and listed.returncode == 0:
        return [ROOT / name for name in listed.stdout.split("\0") if name and (ROOT / name).is_file()]
    files = []
    for folder, dirs, names in os.walk(ROOT):
        dirs[:] = [d for d in dirs if d not in SKIPPED_DIRS and not d.endswith(".egg-info")]
        files += [Path(folder) / n for n in names]
    return files


def _text(path: Path) -> str | None:
    """The file's text, or None for a binary file (NUL bytes or not UTF-8)."""
    data = path.read_bytes()
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def _exists(target: Path) -> bool:
    """Whether ``target`` exists; placeholders and wildcards match any name part (glob ``*``)."""
    text = str(target)
    if not PLACEHOLDER.search(text):
        return target.exists()
    pattern = "*".join(glob.escape(part) for part in PLACEHOLDER.split(text))
    return bool(glob.glob(pattern))


def _clean(path: str) -> str:
    """A path token without the prose punctuation that ends it (``path.``, ``path,``, ``path)``, ``path...``)."""
    path = path.rstrip(".,;:!'\"`)")
    while path.endswith("]") and path.count("[") < path.count("]"):  # ``[--out experiments/sbc]``, ``[a/b](...)``
        path = path[:-1].rstrip(".,;:!'\"`)")
    return path


_KNOWN_COMMITS: dict[str, bool] = {}


def _in_commit(commit: str, path: str) -> bool | None:
    """Whether ``commit`` holds ``path`` (None where git or the commit is not available)."""
    if commit not in _KNOWN_COMMITS:
        known = _git("cat-file", "-e", f"{commit}^{{commit}}")
        _KNOWN_COMMITS[commit] = known is not None and known.returncode == 0
    if not _KNOWN_COMMITS[commit]:
        return None
    path = path.rstrip("/")
    if PLACEHOLDER.search(path):
        path = path[: PLACEHOLDER.search(path).start()].rsplit("/", 1)[0]
    return _git("cat-file", "-e", f"{commit}:{path}").returncode == 0


def dangling_references(path: Path, text: str) -> list[str]:
    """``file:line: reference`` for every reference of ``text`` (the contents of ``path``) that does not exist."""
    rel = path.relative_to(ROOT).as_posix()
    bad = []
    for number, line in enumerate(text.splitlines(), 1):
        for match in ABSENT_NOTES.finditer(line):
            bad.append(f"{rel}:{number}: {match.group(0)} (not part of the repository)")
        for match in PATH.finditer(line) if path.suffix not in CAPTURED_OUTPUT else ():
            token = _clean(match.group("path"))
            if match.group("commit"):
                if _in_commit(match.group("commit"), token) is False:
                    bad.append(f"{rel}:{number}: {match.group('commit')}:{token} (not in that commit)")
            elif not _exists(ROOT / token):
                bad.append(f"{rel}:{number}: {token}")
        for match in LINK.finditer(line) if path.suffix in MARKDOWN else ():
            target = match.group("target").strip("<>")
            if re.match(r"[a-z][a-z0-9+.\-]*:", target, re.IGNORECASE) or target.startswith(("#", "/")):
                continue  # a URL, mailto:, an anchor in the same page or an absolute path
            target = target.split("#", 1)[0]
            if target and not _exists(path.parent / target):
                bad.append(f"{rel}:{number}: ]({match.group('target')})")
    return bad


def test_every_referenced_repository_file_exists():
    this = Path(__file__).resolve()
    bad = []
    for path in tracked_files():
        if path.resolve() == this or path.name in PATTERN_FILES:
            continue
        text = _text(path)
        if text is not None:
            bad += dangling_references(path, text)
    assert not bad, f"{len(bad)} references to files not in the repository:\n" + "\n".join(bad)


def test_the_check_finds_a_dangling_reference(tmp_path):
    """The checker itself: a missing path, a broken relative link and an absent note are reported; existing
    paths, globbed placeholders and URLs are not."""
    fake = ROOT / "tests" / "fake_note.md"  # never written: the text is checked as if it were this file
    text = "\n".join(
        [
            "see `experiments/no_such_study/RESULT.md` and [the format](../docs/data-format.md)",
            "and [nothing](./no_such_file.md), DESIGN" + ".md section 5",
            "fine: peano_bayes/rig/, peano_bayes/bundled/data/<CODE>.csv, tests/*.py, https://x.org/a/b.md",
            "[a link](https://example.org/docs/x.md) and [an anchor](#top)",
        ]
    )
    bad = dangling_references(fake, text)
    captured = dangling_references(ROOT / "tests" / "fake_run.log", text)
    assert captured == ["tests/fake_run.log:2: DESIGN" + ".md (not part of the repository)"], captured
    assert bad == [
        "tests/fake_note.md:1: experiments/no_such_study/RESULT.md",
        "tests/fake_note.md:2: DESIGN" + ".md (not part of the repository)",
        "tests/fake_note.md:2: ](./no_such_file.md)",
    ], bad
