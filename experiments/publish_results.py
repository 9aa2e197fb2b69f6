"""Publish a finished main job into ``docs/results/``: its ``index.md`` and ``ranking.md`` and every file they
link, nothing else, so the published page is one run's and every link resolves.

The posteriors (``posterior.nc``, about 70 MB per material) and the PDFs stay behind; PNG figures are re-encoded
with a 256-colour palette (about a third of the size, the plots are line art). The new tree is built beside the
old one and swapped in at the end, so an interrupted publish leaves the old page whole. A link to a missing file
is an error (exit 1) and nothing is replaced.

    python experiments/publish_results.py RESULTS [--out docs/results]
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
from pathlib import Path

from PIL import Image

#: A markdown link's target: ``](target)`` up to the closing parenthesis (no spaces in our targets).
LINK = re.compile(r"\]\(([^)\s]+)\)")
PAGES = ("index.md", "ranking.md")


def linked_files(results: Path) -> tuple[list[Path], list[str]]:
    """Files the pages link (relative to ``results``), and the links whose file is missing."""
    found, missing = [], []
    for page in PAGES:
        text = (results / page).read_text(encoding="utf-8")
        for target in LINK.findall(text):
            if "://" in target or target.startswith("#"):
                continue
            path = Path(target.split("#")[0])
            if (results / path).is_file():
                found.append(path)
            else:
                missing.append(f"{page}: {target}")
    return sorted(set(found)), missing


def copy(source: Path, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    if source.suffix.lower() == ".png":
        with Image.open(source) as image:
            image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(target, optimize=True)
    else:
        shutil.copyfile(source, target)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", type=Path, help="a finished `peano-bayes run` output folder")
    parser.add_argument("--out", type=Path, default=Path("docs/results"), help="default: docs/results")
    args = parser.parse_args()
    files, missing = linked_files(args.results)
    if missing:
        print("links to missing files, nothing published:\n  " + "\n  ".join(missing), file=sys.stderr)
        return 1
    staging = args.out.with_name(args.out.name + ".new")
    shutil.rmtree(staging, ignore_errors=True)
    for page in PAGES:
        copy(args.results / page, staging / page)
    for path in files:
        copy(args.results / path, staging / path)
    old = args.out.with_name(args.out.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if args.out.exists():
        args.out.rename(old)
    staging.rename(args.out)
    shutil.rmtree(old, ignore_errors=True)
    size = sum(p.stat().st_size for p in args.out.rglob("*") if p.is_file())
    print(f"published {len(files)} linked files and {len(PAGES)} pages into {args.out} ({size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
