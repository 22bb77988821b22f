"""Sphinx configuration of the deck-landing documentation (MyST Markdown, furo theme).

Build: ``make docs`` (warnings are errors).  The task environments' pages and the
configuration reference come from the directives of ``docs/_ext/``; the tables of ids,
policies and results are committed Markdown written by ``python -m agents.cli.pages --write``.
"""

from __future__ import annotations

import sys
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as installed_version
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))
# document this checkout only: an editable install of another checkout (its import finder)
# would otherwise supply the modules this one lacks
sys.meta_path[:] = [
    f for f in sys.meta_path if not str(getattr(f, "__module__", "")).startswith("__editable__")
]
sys.path.insert(0, str(DOCS / "_ext"))

project = "deck-landing"
author = "deck-landing contributors"
copyright = "2026, deck-landing contributors"
try:  # the installed package's (pyproject.toml's, once installed: make docs installs it)
    release = installed_version(project)
except PackageNotFoundError:
    raise RuntimeError(
        "the docs read the version from the installed package: pip install -e '.[docs]'"
    ) from None
version = ".".join(release.split(".")[:2])

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",
    "deck_docs",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "README.md"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = "deck-landing"
html_static_path: list[str] = []
templates_path = ["_templates"]

autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
# the heavy optional dependencies are installed with the package; nothing is mocked
autodoc_inherit_docstrings = False
# a name re-exported by a package (estimation.fusion.FusionConfig) or an attribute name that
# two classes share resolves to more than one target; Sphinx then links the first
suppress_warnings = ["ref.python"]
