"""Two policies on the same seeds (agents/evaluation/paired.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agents.evaluation.episode_files import load_outcomes
from agents.evaluation.paired import PairedComparison, compare, main, markdown_table
from landing_env.errors import ConfigError


def _write_run(directory: Path, scenario: str, policy: str, outcomes: dict[int, bool]) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"landing_{scenario}_{policy}.jsonl"
    lines = [
        json.dumps({"policy": policy, "scenario": scenario, "seed": seed, "success": ok})
        for seed, ok in outcomes.items()
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def _sample(n: int, failures: set[int]) -> dict[int, bool]:
    return {1000 + i: i not in failures for i in range(n)}


def test_the_discordant_seeds_are_counted_and_tested_exactly(tmp_path):
    # the reference fails seed 7 only; the policy fails 1-4 (seed 7 it lands)
    _write_run(tmp_path, "ship-ss4", "quiescent", _sample(200, {7}))
    _write_run(tmp_path, "ship-ss4", "timing-dqn-lookahead", _sample(200, {1, 2, 3, 4}))

    (c,) = compare(load_outcomes([tmp_path]), "quiescent")

    assert (c.policy, c.reference, c.seeds) == ("timing-dqn-lookahead", "quiescent", 200)
    assert (c.both, c.only_policy, c.only_reference, c.neither) == (195, 1, 4, 0)
    assert c.difference_points == pytest.approx(-1.5)
    # exact two-sided binomial of 1 in 5 at 1/2: 2 * (1 + 5) / 32
    assert c.p_value == pytest.approx(0.375)
    # Agresti and Min's Wald+2: (1 - 4) / 202 +- 1.96 * sqrt(1 + 4 + 1 - 9 / 202) / 202
    assert c.interval_points() == pytest.approx((-3.853, 0.883), abs=1e-3)


def test_a_lopsided_difference_is_significant_and_its_interval_excludes_zero():
    c = PairedComparison("bench-ss5", "a", "b", 200, 100, 40, 5, 55)

    assert c.difference_points == pytest.approx(17.5)
    assert c.p_value < 1e-6
    low, high = c.interval_points()
    assert 0.0 < low < 17.5 < high


def test_policies_that_agree_on_every_seed_differ_by_nothing_with_p_one():
    c = PairedComparison("ship-ss3", "a", "b", 100, 98, 0, 0, 2)

    assert c.difference_points == 0.0
    assert c.p_value == 1.0
    low, high = c.interval_points()
    assert low < 0.0 < high


def test_only_the_seeds_both_ran_are_paired(tmp_path):
    _write_run(tmp_path, "ship-ss5", "quiescent", _sample(300, {0, 250}))
    _write_run(tmp_path, "ship-ss5", "land-now", _sample(100, {0, 5}))

    (c,) = compare(load_outcomes([tmp_path]), "quiescent")

    assert c.seeds == 100
    assert (c.both, c.only_policy, c.only_reference, c.neither) == (98, 0, 1, 1)


def test_each_scenario_is_paired_on_its_own_and_policies_can_be_chosen(tmp_path):
    for scenario in ("ship-ss4", "ship-ss5"):
        _write_run(tmp_path, scenario, "quiescent", _sample(10, {0}))
        _write_run(tmp_path, scenario, "land-now", _sample(10, {1}))
        _write_run(tmp_path, scenario, "oracle", _sample(10, set()))

    chosen = compare(load_outcomes([tmp_path]), "quiescent", ["oracle"])

    assert [(c.scenario, c.policy) for c in chosen] == [
        ("ship-ss4", "oracle"),
        ("ship-ss5", "oracle"),
    ]
    assert all((c.only_policy, c.only_reference) == (1, 0) for c in chosen)
    assert len(compare(load_outcomes([tmp_path]), "quiescent")) == 4


def test_bad_comparisons_get_errors_that_name_what_is_wrong(tmp_path):
    _write_run(tmp_path / "a", "ship-ss4", "quiescent", {1: True})
    _write_run(tmp_path / "a", "ship-ss4", "land-now", {2: True})
    runs = load_outcomes([tmp_path / "a"])

    with pytest.raises(ConfigError, match=r"reference.*'oracle'.*quiescent"):
        compare(runs, "oracle")
    with pytest.raises(ConfigError, match=r"policy.*timing-dqn"):
        compare(runs, "quiescent", ["timing-dqn"])
    with pytest.raises(ConfigError, match="share no seed"):
        compare(runs, "quiescent")
    _write_run(tmp_path / "b", "ship-ss6", "land-now", {1: True})
    _write_run(tmp_path / "b", "ship-ss4", "quiescent", {1: True})
    with pytest.raises(ConfigError, match="nothing to compare"):
        compare(load_outcomes([tmp_path / "b"]), "quiescent")


def test_the_command_prints_the_table(tmp_path, capsys):
    _write_run(tmp_path, "ship-ss4", "quiescent", _sample(20, {3}))
    _write_run(tmp_path, "ship-ss4", "land-now", _sample(20, {3, 4, 5}))

    assert main([str(tmp_path), "--reference", "quiescent"]) == 0

    out = capsys.readouterr().out
    assert out.strip() == markdown_table(compare(load_outcomes([tmp_path]), "quiescent"))
    assert "| ship-ss4 | land-now | quiescent | 20 | 17 | 0 | 2 | 1 | -10.0 (" in out
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--reference", "oracle"])
