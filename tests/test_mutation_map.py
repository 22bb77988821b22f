"""The mutation-testing map (tools/mutation.yaml): each mutated module with the test files that
import it, so that `make mutation` runs each mutant against those tests alone."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tests.paths import ROOT


def mutation_tool():
    spec = importlib.util.spec_from_file_location("mutation_tool", ROOT / "tools" / "mutation.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_map_names_for_each_module_the_test_files_that_import_it() -> None:
    tool = mutation_tool()
    mapping = tool.load_map()
    assert mapping["tests"] == tool.derive_tests(mapping["paths"]), (
        "tools/mutation.yaml is out of date: run python tools/mutation.py map"
    )
    assert "tests/agents/io/test_mavlink_autopilot.py" in mapping["tests"]["agents/io/timesync.py"]


def test_a_test_file_imports_a_module_by_either_form_of_import(tmp_path: Path) -> None:
    tool = mutation_tool()
    test_file = tmp_path / "test_x.py"
    test_file.write_text(
        "import agents.io.bag\nfrom agents.io import timesync\nfrom agents.io.mavlink import X\n"
    )
    names = tool.imported_modules(test_file)
    assert {"agents.io.bag", "agents.io.timesync", "agents.io.mavlink"} <= names


def test_a_module_not_in_the_map_is_refused_naming_it() -> None:
    tool = mutation_tool()
    with pytest.raises(SystemExit, match=r"agents/io/nowhere\.py"):
        tool.chosen(["agents/io/nowhere.py"], {"agents/io/timesync.py": []})


def test_a_run_on_chosen_tests_takes_only_the_modules_own_test_files_or_their_tests() -> None:
    tool = mutation_tool()
    mapped = ["tests/a/test_x.py", "tests/a/test_y.py"]
    assert tool.chosen_tests("m.py", None, mapped) == mapped
    picked = ["tests/a/test_y.py", "tests/a/test_x.py::test_one"]
    assert tool.chosen_tests("m.py", picked, mapped) == picked
    with pytest.raises(SystemExit, match=r"^--tests: tests/b/test_z\.py not among .* of m\.py"):
        tool.chosen_tests("m.py", ["tests/a/test_x.py", "tests/b/test_z.py"], mapped)


def test_a_name_taken_from_a_package_counts_as_importing_the_module_that_defines_it(
    tmp_path: Path,
) -> None:
    tool = mutation_tool()
    test_file = tmp_path / "test_x.py"
    test_file.write_text("from estimation.fusion import DeckFusion, FusionConfig\n")
    names = tool.imported_modules(test_file)
    assert {"estimation.fusion.filter", "estimation.fusion.config"} <= names
    assert "estimation.fusion.model" not in names


def test_a_module_no_test_imports_takes_the_tests_of_the_modules_that_import_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    tool = mutation_tool()
    # a module a test imports keeps its own test files alone
    derived = tool.derive_tests(["agents/io/recording_source.py"])
    assert "tests/agents/cli/test_bridge.py" in derived["agents/io/recording_source.py"]
    # a tree of its own: a module that a test may import directly some day stays no example
    for path, text in {
        "agents/io/work.py": "X = 1\n",
        "agents/io/source.py": "from agents.io.work import X\n",
        "agents/io/other.py": "Y = 2\n",
        "tests/agents/io/test_source.py": "from agents.io.source import X\n",
        "tests/agents/io/test_other.py": "from agents.io import other\n",
    }.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(text)
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    monkeypatch.setattr(tool, "SOURCES", ("agents",))
    derived = tool.derive_tests(["agents/io/*.py"])
    assert derived == {
        "agents/io/other.py": ["tests/agents/io/test_other.py"],
        "agents/io/source.py": ["tests/agents/io/test_source.py"],
        "agents/io/work.py": ["tests/agents/io/test_source.py"],  # its importer's
    }
