"""Data shipped inside the package: the eight synthetic rig datasets, the priors, and the paper's numbers.

Read through :mod:`importlib.resources`, so an installed wheel finds them as a source checkout does:

- ``data/<CODE>.csv`` + ``data/<CODE>.toml``: the bundled rig datasets of the paper's eight materials
  (synthetic, made by the virtual rig; their generating values are in ``data/true_parameters.toml``);
- ``data/published_metrics.csv``, ``data/published_orderings.csv``: the numbers and orderings Veale, Xie and
  Anderson (2016) report, each row with where it stands in the paper;
- ``priors/*.toml``: the prior files (``default.toml`` is the root every other file extends).

The folder must be on a file system (an ordinary ``pip install``), not inside a zip archive.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from ..errors import PeanoBayesInputError

#: The material codes of the bundled datasets, in the paper's Table 4 order.
MATERIALS = ("TP", "P", "PR", "TPC", "PC", "PCS", "TFC", "FC")


def _root() -> Path:
    root = resources.files(__name__)
    if not isinstance(root, Path):  # a zipped install: the readers need real files
        raise RuntimeError(f"peano_bayes's bundled data is not on a file system ({root!r}); install it unzipped")
    return root


#: Folder of the bundled datasets and the paper's numbers.
DATA_DIR: Path = _root() / "data"
#: Folder of the bundled prior files.
PRIORS_DIR: Path = _root() / "priors"


def dataset_path(code: str) -> Path:
    """The CSV of the bundled dataset of material ``code`` (one of :data:`MATERIALS`)."""
    if code not in MATERIALS:
        raise PeanoBayesInputError(f"no bundled dataset {code!r}; expected one of {' '.join(MATERIALS)}")
    return DATA_DIR / f"{code}.csv"


def resolve_dataset(name: str | Path) -> Path:
    """``name`` as given if it names an existing file (or CSV stem), else the bundled dataset of that material
    code; so the command line takes ``TP`` as well as ``path/to/TP.csv``."""
    path = Path(name)
    code = str(name).upper()  # material codes are case-blind, as ``prior new --like`` and ``run --materials``
    if code in MATERIALS and not (path.is_file() or path.with_name(path.name + ".csv").is_file()):
        return dataset_path(code)
    bare_word = len(path.parts) == 1 and not path.suffix
    if code not in MATERIALS and bare_word and not (path.exists() or path.with_name(path.name + ".csv").exists()):
        raise PeanoBayesInputError(
            f"{name}: neither a bundled material code nor a dataset file ({name}.csv not found); expected "
            f"one of {' '.join(MATERIALS)} or the path of a rig CSV with its TOML sidecar"
        )
    return path
