"""Rig datasets: the format (:mod:`.format`), the immutable SI-unit :class:`Dataset`, load and save.

A dataset is ``NAME.csv`` (one row per sample) plus ``NAME.toml`` (material, geometry, conditions,
provenance); see ``docs/data-format.md``.
"""

from __future__ import annotations

from ..errors import DataFormatError as DataFormatError
from .dataset import Conditions as Conditions
from .dataset import Dataset as Dataset
from .dataset import Material as Material
from .dataset import Run as Run
from .io import dataset_paths as dataset_paths
from .io import load as load
from .io import save as save
