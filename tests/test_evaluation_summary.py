"""One summary for every policy evaluation: success with its Wilson interval, the table from
its columns, and the Markdown, JSON and CSV files, the same for landing and approach."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from agents.evaluation import approach
from agents.evaluation import landing_summary as landing
from agents.evaluation.approach import ApproachEpisode
from agents.evaluation.landing import EpisodeResult
from agents.evaluation.runner import SeedFailure
from agents.evaluation.summary import (
    Column,
    finite_mean,
    finite_p95,
    markdown_table,
    success_fields,
    write_summary_files,
)


def _landings() -> list[EpisodeResult]:
    return [
        EpisodeResult("land-now", "bench-ss4", 0, "success", True, 0.2, 1.0, 0.01, 1.0, 5.0),
        EpisodeResult("land-now", "bench-ss4", 1, "hard_landing", False, 0.6, 6.0, 0.03),
        EpisodeResult("land-now", "bench-ss4", 2, "crash", False),
    ]


def _approaches() -> list[ApproachEpisode]:
    return [
        ApproachEpisode(
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


def test_landing_and_approach_share_the_success_cell_and_the_summary_fields() -> None:
    land = landing.summarise(_landings())
    appr = approach.summarise(_approaches())
    for summary, table, header in (
        (land, landing.markdown_table([land]), landing.TABLE_HEADER),
        (appr, approach.markdown_table([appr]), approach.TABLE_HEADER),
    ):
        row = table.splitlines()[2].split(" | ")
        cell = row[header.index("success (95% CI)")]
        assert cell.startswith(f"{100 * summary.success_rate:.1f}% (")
    assert land.normal_speed_mean == pytest.approx(0.4)
    assert appr.offset_mean_m == pytest.approx(0.1)  # the timeout has no offset


def test_the_summary_files_hold_the_table_the_settings_and_every_episode(
    tmp_path: Path,
) -> None:
    results = {"beacon-range": _approaches()}
    summaries = [approach.summarise(results["beacon-range"])]
    failures = {"beacon-range": [SeedFailure(9, "RayActorError: worker died")]}
    files = write_summary_files(
        tmp_path, "approach_x", heading="Approach: x", title="two episodes",
        table=approach.markdown_table(summaries), summaries=summaries, results=results,
        failures=failures, settings={"scenario": "x", "first_seed": 7}, command="deck-landing",
        notes="a note", csv_exclude=("trajectory",),
    )  # fmt: skip
    assert [p.name for p in files] == [
        "approach_x.md", "approach_x.json", "approach_x_episodes.csv"
    ]  # fmt: skip
    text = files[0].read_text()
    assert text.startswith("# Approach: x\n\ntwo episodes\n\nCommand: `deck-landing`\n\n| policy")
    assert "a note" in text and "- beacon-range, seed 9: RayActorError: worker died" in text
    data = json.loads(files[1].read_text())
    assert data["scenario"] == "x" and data["summaries"][0]["successes"] == 1
    with files[2].open() as handle:
        rows = list(csv.DictReader(handle))
    assert [r["seed"] for r in rows] == ["7", "8"] and "trajectory" not in rows[0]


def test_landing_and_approach_keep_no_table_code_of_their_own() -> None:
    import ast

    root = Path(__file__).resolve().parent.parent / "agents" / "evaluation"
    for name in ("landing.py", "approach.py"):
        tree = ast.parse((root / name).read_text())
        imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        assert "agents.evaluation.summary" in imported, name
        # no file writing of its own: csv and json are the summary module's
        modules = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert not {"csv", "json"} & modules, name
