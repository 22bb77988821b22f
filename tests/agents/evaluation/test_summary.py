"""One pipeline for every policy evaluation: one record, one summary (success with its Wilson
interval), one table from the columns each evaluation picks, and the Markdown, JSON and CSV
files, the same for landing and approach."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from agents.evaluation.approach import APPROACH_EVALUATION
from agents.evaluation.landing import LANDING_EVALUATION
from agents.evaluation.pipeline import Evaluated
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.runner import SeedFailure
from agents.evaluation.summary import (
    Column,
    columns,
    finite_mean,
    finite_p95,
    markdown_table,
    success_fields,
    summarise,
)
from tests.paths import ROOT


def _landings() -> list[EpisodeRecord]:
    return [
        EpisodeRecord("land-now", "bench-ss4", 0, "success", True, 0.2, 1.0, 0.01, 1.0, 5.0),
        EpisodeRecord("land-now", "bench-ss4", 1, "hard_landing", False, 0.6, 6.0, 0.03),
        EpisodeRecord("land-now", "bench-ss4", 2, "crash", False),
    ]


def _approaches() -> list[EpisodeRecord]:
    return [
        EpisodeRecord(
            "beacon-range", "high-approach", seed, outcome, outcome == "success",
            lateral_offset_m=offset, estimator="beacon", trajectory=[(0.0, 1.0, 2.0, 3.0)],
        )
        for seed, outcome, offset in ((7, "success", 0.1), (8, "timeout", math.nan))
    ]  # fmt: skip


def test_success_fields_give_the_rate_and_its_wilson_interval() -> None:
    fields = success_fields(_landings())
    assert (fields["episodes"], fields["successes"]) == (3, 1)
    assert fields["success_rate"] == pytest.approx(1 / 3)
    assert fields["success_ci_low"] < 1 / 3 < fields["success_ci_high"]
    with pytest.raises(ValueError, match="no episodes"):
        success_fields([])


def test_statistics_skip_the_episodes_where_a_metric_does_not_exist() -> None:
    assert finite_mean([1.0, math.nan, 3.0]) == pytest.approx(2.0)
    assert finite_p95([math.nan, 2.0]) == pytest.approx(2.0)
    assert math.isnan(finite_mean([math.nan])) and math.isnan(finite_p95([]))


def test_a_table_is_built_from_its_columns() -> None:
    columns = (Column("name", lambda s: s["name"]), Column("n", lambda s: str(s["n"])))
    table = markdown_table([{"name": "a", "n": 1}, {"name": "b", "n": 2}], columns)
    assert table.splitlines() == ["| name | n |", "|---|---|", "| a | 1 |", "| b | 2 |"]


def test_a_column_not_in_the_catalogue_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="'speed'"):
        columns("policy", "speed")


def test_landing_and_approach_pick_their_columns_of_one_summary() -> None:
    land = summarise(_landings())
    appr = summarise(_approaches())
    for summary, evaluation in ((land, LANDING_EVALUATION), (appr, APPROACH_EVALUATION)):
        header = [c.header for c in evaluation.columns]
        row = markdown_table([summary], evaluation.columns).splitlines()[2].split(" | ")
        cell = row[header.index("success (95% CI)")]
        assert cell.startswith(f"{100 * summary.success_rate:.1f}% (")
    assert land.normal_speed_mean == pytest.approx(0.4)
    assert land.failures == {"crash": 1}  # the hard landing failed no named check
    assert appr.lateral_offset_mean_m == pytest.approx(0.1)  # the timeout has no offset
    assert appr.estimator == "beacon"
    approach_header = [c.header for c in APPROACH_EVALUATION.columns]
    assert "relocations / searches" in approach_header and "oracle" not in approach_header


def test_the_summary_files_hold_the_table_the_settings_and_every_episode(
    tmp_path: Path,
) -> None:
    results = {"beacon-range": _approaches()}
    evaluated = Evaluated(
        APPROACH_EVALUATION, "x", [summarise(results["beacon-range"])], results,
        {"beacon-range": [SeedFailure(9, "RayActorError: worker died")]},
    )  # fmt: skip
    files = evaluated.write(
        tmp_path, "two episodes", {"scenario": "x", "first_seed": 7}, "deck-landing", "a note"
    )
    assert [p.name for p in files] == [
        "approach_x.md", "approach_x.json", "approach_x_episodes.csv", "approach_x.png"
    ]  # fmt: skip
    text = files[0].read_text()
    assert text.startswith("# Approach: x\n\ntwo episodes\n\nCommand: `deck-landing`\n\n| policy")
    assert "a note" in text and "- beacon-range, seed 9: RayActorError: worker died" in text
    data = json.loads(files[1].read_text())
    assert data["scenario"] == "x" and data["summaries"][0]["successes"] == 1
    # the approach's own figures, not the landing's
    assert "landing_error_p95_m" in data["summaries"][0]
    assert "oracle_success_rate" not in data["summaries"][0]
    with files[2].open() as handle:
        rows = list(csv.DictReader(handle))
    assert [r["seed"] for r in rows] == ["7", "8"] and rows[0]["estimator"] == "beacon"
    assert "trajectory" not in rows[0] and "wait_s" not in rows[0]


def test_the_landing_files_keep_the_landing_columns(tmp_path: Path) -> None:
    results = {"land-now": _landings()}
    evaluated = Evaluated(LANDING_EVALUATION, "bench-ss4", [summarise(_landings())], results)
    files = evaluated.write(tmp_path, "three episodes", {"scenario": "bench-ss4"})
    summary = json.loads(files[1].read_text())["summaries"][0]
    assert "failures" in summary and "estimator" not in summary
    with files[2].open() as handle:
        header = next(csv.reader(handle))
    assert header[-2:] == ["wait_s", "wave_offs"] and "landing_error_m" not in header


def test_one_episode_loop_runs_every_evaluation_and_the_demo() -> None:
    import ast

    root = ROOT / "agents"
    for path in (root / "evaluation" / "landing.py", root / "evaluation" / "approach.py",
                 root / "cli" / "demo.py"):  # fmt: skip
        tree = ast.parse(path.read_text())
        calls = {
            node.func.attr
            for node in ast.walk(tree)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
        }
        assert not {"reset", "step"} & calls, path.name
        imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        assert "agents.evaluation.pipeline" in imported, path.name
        # no file writing of its own: csv and json are the summary module's
        modules = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert not {"csv", "json", "gymnasium"} & modules, path.name
