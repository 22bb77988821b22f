"""Every ```python block of the README and the getting-started page runs, warning-free.

Deprecation warnings are errors, and so is any warning Gymnasium gives (an out-of-date id,
a checker's complaint), so a snippet that shows a superseded id fails here.  Bash blocks are
not run.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest

from tests.paths import ROOT

DOCUMENTS = ("README.md", "docs/getting-started.md")
_PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)


def python_blocks(path: Path) -> list[str]:
    """The code of every fenced ```python block of a Markdown file."""
    return _PYTHON_BLOCK.findall(path.read_text(encoding="utf-8"))


SNIPPETS = [
    pytest.param(code, id=f"{name}[{i}]")
    for name in DOCUMENTS
    for i, code in enumerate(python_blocks(ROOT / name))
]


def test_each_document_has_python_snippets() -> None:
    for name in DOCUMENTS:
        assert python_blocks(ROOT / name), f"{name} has no ```python block"


def test_a_block_is_found_between_its_fences() -> None:
    text = "x\n```python\nprint(1)\n```\n```bash\nls\n```\n```python\na = 2\n```\n"
    path = ROOT / "results" / "snippet_probe.md"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text, encoding="utf-8")
    try:
        assert python_blocks(path) == ["print(1)\n", "a = 2\n"]
    finally:
        path.unlink()


def _is_gymnasium_warning(warning: warnings.WarningMessage) -> bool:
    return "gymnasium" in str(warning.filename) or "WARN:" in str(warning.message)


@pytest.mark.parametrize("code", SNIPPETS)
def test_the_snippet_runs_without_a_deprecation_or_gymnasium_warning(code: str) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.simplefilter("error", DeprecationWarning)
        exec(compile(code, "<snippet>", "exec"), {"__name__": "__snippet__"})
    bad = [
        w for w in caught if issubclass(w.category, DeprecationWarning) or _is_gymnasium_warning(w)
    ]
    assert not bad, [f"{w.category.__name__}: {w.message}" for w in bad]
