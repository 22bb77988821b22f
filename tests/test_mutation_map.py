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


def test_every_chosen_test_is_a_test_of_the_modules_mapped_files() -> None:
    tool = mutation_tool()
    mapping = tool.load_map()
    assert tool.check_chosen(mapping["chosen"], mapping["tests"]) == []
    # the fusion's model runs on its unit tests, not on the filter's Monte-Carlo ones
    model = mapping["chosen"]["estimation/fusion/model.py"]
    assert (
        "tests/estimation/fusion/test_filter_identification.py"
        in (mapping["tests"]["estimation/fusion/model.py"])
    )
    assert "tests/estimation/fusion/test_filter_identification.py" not in model


def test_a_bad_choice_of_tests_is_refused_naming_the_module_and_the_test(tmp_path: Path) -> None:
    tool = mutation_tool()
    test_file = "tests/estimation/test_limits.py"
    mapped = {"estimation/limits.py": [test_file]}
    assert tool.check_chosen({"estimation/limits.py": [test_file]}, mapped) == []
    name = sorted(tool.test_names(ROOT / test_file))[0]
    assert tool.check_chosen({"estimation/limits.py": [f"{test_file}::{name}"]}, mapped) == []
    assert tool.check_chosen({"estimation/nowhere.py": [test_file]}, mapped) == [
        "chosen: estimation/nowhere.py is not a mapped module"
    ]
    assert tool.check_chosen({"estimation/limits.py": []}, mapped) == [
        "chosen: estimation/limits.py chooses no test (leave it out to run all)"
    ]
    assert tool.check_chosen({"estimation/limits.py": ["tests/test_fuzz.py"]}, mapped) == [
        "chosen: estimation/limits.py: tests/test_fuzz.py is not among its mapped test files"
    ]
    assert tool.check_chosen({"estimation/limits.py": [f"{test_file}::test_gone"]}, mapped) == [
        f"chosen: estimation/limits.py: {test_file} has no test test_gone"
    ]


def test_a_run_takes_the_chosen_tests_unless_told_its_own_or_all(tmp_path: Path) -> None:
    tool = mutation_tool()
    mapped = ["tests/a/test_x.py", "tests/a/test_y.py"]
    kept = ["tests/a/test_x.py::test_one"]
    assert tool.chosen_tests("m.py", None, mapped, kept) == kept
    assert tool.chosen_tests("m.py", None, mapped, None) == mapped
    assert tool.chosen_tests("m.py", ["tests/a/test_y.py"], mapped, kept) == ["tests/a/test_y.py"]
    # a module's run folder goes under the folder asked for, with that selection
    run_dir = tool.prepare("estimation/limits.py", kept, tmp_path / "runs")
    assert run_dir == tmp_path / "runs" / "estimation.limits"
    text = (run_dir / "pyproject.toml").read_text()
    assert 'pytest_add_cli_args_test_selection = ["tests/a/test_x.py::test_one"]' in text
    assert 'only_mutate = ["estimation/limits.py"]' in text
    assert f"timeout_multiplier = {tool.TIMEOUT_MULTIPLIER}" in text
    assert (run_dir / "estimation").resolve() == ROOT / "estimation"


def test_a_module_without_a_function_is_not_run(capsys: pytest.CaptureFixture) -> None:
    tool = mutation_tool()
    assert not tool.has_functions(ROOT / "landing_env/sea/heldout.py")
    assert tool.has_functions(ROOT / "estimation/limits.py")
    assert tool.main(["run", "landing_env/sea/heldout.py"]) == 0
    assert "landing_env/sea/heldout.py: no function to mutate; not run" in capsys.readouterr().out


def test_map_keeps_the_hand_kept_choice(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    tool = mutation_tool()
    mapping = tool.load_map()
    monkeypatch.setattr(tool, "MAP_FILE", tmp_path / "mutation.yaml")
    tool.write_map(mapping["paths"], mapping["tests"], mapping["chosen"])
    assert tool.load_map() == mapping
    bad = {**mapping["chosen"], "estimation/limits.py": ["tests/test_fuzz.py"]}
    tool.write_map(mapping["paths"], mapping["tests"], bad)
    assert tool.main(["map"]) == 1
    assert tool.load_map()["chosen"] == bad  # refused: the file is left as it was


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
        tool.named_modules(["agents/io/nowhere.py"], {"agents/io/timesync.py": []})


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
