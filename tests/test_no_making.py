"""The project speaks of itself, not of its making: no issue numbers, development rounds or
targets of a task in the README, the docs (the experiments' records included), the configs
and the packages.  History goes to CHANGELOG.md, results are dated and name their commit."""

from __future__ import annotations

import re
from pathlib import Path

from tests.paths import ROOT

#: what is scanned: files, and folders (their text files)
SCANNED = ("README.md", "docs", "configs", "agents", "estimation", "landing_env")
SUFFIXES = {".md", ".py", ".yaml", ".yml", ".json", ".txt", ".rst", ".toml", ".cfg", ".csv"}
SKIPPED_DIRS = {"_build", "__pycache__"}
#: the making's traces: a task's number, a round of work, a task's target, a task's words
MAKING = re.compile(r"\bissue \d+|ISSUE_|\bsession \d+|\(target \d+|\bthe issue's\b", re.IGNORECASE)


def _files() -> list[Path]:
    files: list[Path] = []
    for name in SCANNED:
        path = ROOT / name
        if path.is_file():
            files.append(path)
            continue
        files += [
            f
            for f in sorted(path.rglob("*"))
            if f.is_file()
            and f.suffix in SUFFIXES
            and not SKIPPED_DIRS & set(f.relative_to(ROOT).parts)
        ]
    return files


def making_lines(files: list[Path], root: Path = ROOT) -> list[str]:
    """``file:line: text`` (relative to ``root``) of every line that speaks of the project's
    making."""
    found = []
    for path in files:
        text = path.read_text(encoding="utf-8", errors="replace")
        for number, line in enumerate(text.splitlines(), start=1):
            if MAKING.search(line):
                found.append(f"{path.relative_to(root)}:{number}: {line.strip()}")
    return found


def test_the_project_does_not_speak_of_its_making() -> None:
    files = _files()
    assert any(f.name == "README.md" for f in files) and len(files) > 100
    found = making_lines(files)
    assert not found, "the project's making shows:\n" + "\n".join(found)


def test_the_scan_names_the_file_and_line_of_each_trace(tmp_path: Path) -> None:
    page = tmp_path / "docs" / "page.md"
    page.parent.mkdir()
    page.write_text("fine\nAs in issue 12, (target 4)\nISSUE_NOISE = 1\nissues 34 upstream\n")
    assert making_lines([page], tmp_path) == [
        "docs/page.md:2: As in issue 12, (target 4)",
        "docs/page.md:3: ISSUE_NOISE = 1",
    ]
