"""The places tests read from, computed once: the repository root and the tests' data folder.

A test imports these (``from tests.paths import ROOT``) rather than counting parents of its own
``__file__``, so that it reads the same files wherever it lies in the tree.
"""

from __future__ import annotations

from pathlib import Path

#: the repository root (pyproject.toml, configs/, docs/, the packages)
ROOT = Path(__file__).resolve().parent.parent
#: the tests' own data files (tests/data/)
DATA_DIR = ROOT / "tests" / "data"
