"""The success figure across runs (agents/evaluation/success_plot.py)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import pytest

from agents.evaluation.success_plot import load_cells, main, parse_targets, plot_success
from landing_env.errors import ConfigError


def _write_run(directory: Path, scenario: str, policy: str, outcomes: list[bool]) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"landing_{scenario}_{policy}.jsonl"
    lines = [
        json.dumps({"policy": policy, "scenario": scenario, "seed": 1000 + i, "success": ok})
        for i, ok in enumerate(outcomes)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_episodes_are_counted_per_scenario_and_policy_across_directories_and_files(tmp_path):
    _write_run(tmp_path / "a", "ship-ss4", "timing-dqn-lookahead", [True] * 9 + [False])
    _write_run(tmp_path / "a", "ship-ss4", "quiescent", [True] * 8 + [False] * 2)
    single = _write_run(tmp_path / "b", "ship-ss5", "deck-oracle", [True, False, True, True])

    cells = {(c.scenario, c.policy): c for c in load_cells([tmp_path / "a", single])}

    assert set(cells) == {
        ("ship-ss4", "timing-dqn-lookahead"),
        ("ship-ss4", "quiescent"),
        ("ship-ss5", "deck-oracle"),
    }
    assert (
        cells["ship-ss4", "timing-dqn-lookahead"].successes,
        cells["ship-ss4", "timing-dqn-lookahead"].episodes,
    ) == (9, 10)
    assert cells["ship-ss5", "deck-oracle"].rate == pytest.approx(0.75)
    low, high = cells["ship-ss4", "quiescent"].interval
    assert low < 0.8 < high


def test_a_seed_written_twice_by_a_resumed_run_counts_once(tmp_path):
    path = _write_run(tmp_path, "ship-ss6", "land-now", [True, False])
    first = path.read_text().splitlines()[0]
    path.write_text(path.read_text() + first + "\n")

    (cell,) = load_cells([path])

    assert (cell.successes, cell.episodes) == (1, 2)


def test_the_same_policy_and_scenario_in_two_runs_is_refused_naming_both_files(tmp_path):
    one = _write_run(tmp_path / "one", "ship-ss4", "quiescent", [True])
    two = _write_run(tmp_path / "two", "ship-ss4", "quiescent", [False])

    with pytest.raises(ConfigError, match="quiescent") as caught:
        load_cells([one, two])

    assert str(one) in str(caught.value) and str(two) in str(caught.value)


def test_bad_runs_and_targets_get_errors_that_name_them(tmp_path):
    with pytest.raises(ConfigError, match="neither a run directory"):
        load_cells([tmp_path / "missing"])
    with pytest.raises(ConfigError, match="no landing_"):
        load_cells([tmp_path])
    broken = tmp_path / "landing_x_y.jsonl"
    broken.write_text('{"policy": "y"}\n')
    with pytest.raises(ConfigError, match=r"landing_x_y.jsonl:1"):
        load_cells([broken])
    broken.write_text('{"policy": "y", "scenario": "x", "seed": 1, "success": null}\n')
    with pytest.raises(ConfigError, match="success is None"):
        load_cells([broken])
    empty = tmp_path / "landing_none.jsonl"
    empty.write_text("\n")
    with pytest.raises(ConfigError, match="no episodes"):
        load_cells([empty])
    for item in ("ship-ss4", "ship-ss4=-1", "=2", "ship-ss4=two", "ship-ss4=nan", "ship-ss4=inf"):
        with pytest.raises(ConfigError, match="SCENARIO=POINTS"):
            parse_targets([item])
    assert parse_targets(["ship-ss4=2", "ship-ss5=4"]) == {"ship-ss4": 2.0, "ship-ss5": 4.0}


def test_a_target_needs_a_run_of_its_scenario_and_a_bound_on_it(tmp_path):
    cells = load_cells([_write_run(tmp_path, "ship-ss4", "quiescent", [True, True])])

    with pytest.raises(ConfigError, match="no runs of"):
        plot_success(cells, tmp_path / "f.png", targets={"ship-ss9": 2})
    with pytest.raises(ConfigError, match="no oracle run"):
        plot_success(cells, tmp_path / "f.png", targets={"ship-ss4": 2})


def test_the_command_draws_policies_bounds_and_targets_into_an_image(tmp_path, capsys):
    run = tmp_path / "run"
    for scenario, rates in (("ship-ss4", (19, 20, 20)), ("ship-ss5", (17, 15, 18))):
        for policy, k in zip(
            ("timing-dqn-lookahead", "quiescent", "deck-oracle"), rates, strict=True
        ):
            _write_run(run, scenario, policy, [True] * k + [False] * (20 - k))
    out = tmp_path / "img" / "success.png"

    assert (
        main(
            [str(run), "--out", str(out), "--title", "test", "--target", "ship-ss4=2", "ship-ss5=4"]
        )
        == 0
    )

    image = mpimg.imread(out)
    assert image.ndim == 3 and image.shape[0] > 300 and image.shape[1] > 500
    assert image[..., :3].std() > 0.05  # something was drawn, not a blank canvas
    lines = capsys.readouterr().out.splitlines()
    assert any("ship-ss5" in line and "deck-oracle: 18/20 90.0 %" in line for line in lines)
    assert lines[-1] == f"wrote {out}"
