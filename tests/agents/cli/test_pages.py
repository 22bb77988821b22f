"""The README's and the docs' generated tables are committed and current: a block that differs
from its sources (the registries, configs/results) fails here, naming the command that
rewrites it."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from agents.cli import pages
from landing_env.errors import ConfigError
from tests.paths import ROOT


def test_the_committed_pages_match_the_registries_and_the_results() -> None:
    stale = pages.stale_pages()
    assert not stale, f"{stale} are stale: run `{pages.WRITE_COMMAND}` (make pages)"


def _copy(tmp_path: Path) -> Path:
    for page in pages.PAGES:
        (tmp_path / page).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / page, tmp_path / page)
    return tmp_path


def test_an_edited_table_is_stale_and_writing_restores_it(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    page = root / "docs" / "results.md"
    text = page.read_text()
    page.write_text(text.replace("| `quiescent` |", "| `land-now` |", 1))
    assert pages.stale_pages(root) == ["docs/results.md"]
    assert pages.write_pages(root) == ["docs/results.md"]
    assert page.read_text() == text and pages.stale_pages(root) == []


def test_the_results_page_shows_every_scenarios_default_and_every_summary() -> None:
    from agents.evaluation.results import summaries
    from agents.policies.registry import DEFAULT_POLICY

    text = (ROOT / "docs" / "results.md").read_text()
    for scenario, policy in DEFAULT_POLICY.items():
        assert f"| `{scenario}` | `{policy}` |" in text
    for result in summaries().values():
        assert result.title in text and result.command in text


def test_a_page_without_its_block_is_refused_naming_the_markers() -> None:
    with pytest.raises(ConfigError, match="<!-- end generated: results -->"):
        pages.regenerated("# Results\n", "docs/results.md")
