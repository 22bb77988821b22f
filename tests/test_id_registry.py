"""The registered ids mean what Gymnasium says: current ids make without a warning, pass both
checkers, and every CLI scenario flies a registered id; the policy registry agrees with them."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import registry
from gymnasium.utils.env_checker import check_env as gym_check_env

import landing_env  # noqa: F401  (registers the ids)
from agents.policies.registry import (
    DEFAULT_POLICY,
    POLICIES,
    check_registry,
    env_settings,
    policy_spec,
)
from landing_env.envs.base import without_nan
from landing_env.errors import ConfigError
from landing_env.scenarios import SCENARIO_IDS, SCENARIOS, TASKS
from tests.paths import ROOT

CURRENT = [*TASKS, *(i for i, s in SCENARIO_IDS.items() if s.superseded_by is None)]


def test_there_are_at_most_twenty_current_ids_and_each_is_its_names_highest_version() -> None:
    assert len(CURRENT) <= 20
    ours = [spec for spec in registry.values() if spec.id in CURRENT]
    for spec in ours:
        versions = [
            s.version
            for s in registry.values()
            if s.namespace == spec.namespace and s.name == spec.name and s.version is not None
        ]
        assert spec.version == max(versions), spec.id


@pytest.mark.parametrize("env_id", CURRENT)
def test_making_a_current_id_warns_of_nothing(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id)
    env.close()


def test_an_id_no_longer_registered_is_refused_naming_the_current_version() -> None:
    with pytest.raises(gym.error.Error, match=r"v6"):
        gym.make("DeckLandingTiming-BenchSS4-v5")
    # the unversioned name is the current version
    env = gym.make("DeckLandingTiming-BenchSS4")
    assert env.spec is not None and env.spec.id == "DeckLandingTiming-BenchSS4-v6"
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("env_id", CURRENT)
def test_gymnasiums_and_sb3s_checkers_pass_on_every_current_id(env_id: str) -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id)
    try:
        with warnings.catch_warnings():
            # the checkers' advice on unbounded or unnormalised Box keys is not an error
            warnings.simplefilter("ignore", UserWarning)
            gym_check_env(env.unwrapped, skip_render_check=True)
            sb3_check_env(env.unwrapped, warn=False)
    finally:
        env.close()


def test_info_holds_no_nan_so_that_two_runs_of_a_seed_compare_equal() -> None:
    cleaned = without_nan(
        {"a": np.array([1.0, np.nan]), "b": float("nan"), "c": [np.float64("nan"), 2.0]}
    )
    np.testing.assert_array_equal(cleaned["a"], [1.0, 0.0])
    assert cleaned["b"] is None and cleaned["c"] == [None, 2.0]
    # integers and valid floats are left as they are
    assert without_nan({"n": 3, "x": 0.5}) == {"n": 3, "x": 0.5}


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_every_cli_scenario_flies_a_registered_id_for_its_default_policy(scenario: str) -> None:
    policy = DEFAULT_POLICY[scenario]
    env_id, _ = env_settings(policy, scenario)
    assert env_id in SCENARIO_IDS
    assert SCENARIO_IDS[env_id].task == policy_spec(policy).task
    # a registered scenario's id is built on its own config; a held-out sea on its own
    if not SCENARIOS[scenario].held_out:
        assert SCENARIO_IDS[env_id].config == SCENARIOS[scenario].config


def test_the_policy_registry_is_consistent_and_names_one_recommended_policy_per_setting() -> None:
    check_registry()
    kinds = {spec.kind for spec in POLICIES.values()}
    assert kinds == {"baseline", "heuristic", "trained", "bound"}
    for scenario in ("bench-ss4", "ship-ss3", "ship-ss4", "ship-ss5", "ship-ss6"):
        assert POLICIES[DEFAULT_POLICY[scenario]].status == "recommended", scenario


def test_a_policy_brings_its_estimator_and_settings_and_the_user_overrides_them() -> None:
    env_id, overrides = env_settings("predictive", "bench-ss4")
    assert env_id == "DeckLandingTiming-BenchSS4-v6"
    assert overrides["estimation.observed"] == "tight"
    assert overrides["timing.wave_off_rule"] == "value"
    _, mine = env_settings(
        "predictive", "bench-ss4", "ihrcf", extra_overrides={"timing.wait_limit_s": 30.0}
    )
    assert mine["estimation.observed"] == "ihrcf" and mine["timing.wait_limit_s"] == 30.0
    env_id, _ = env_settings("align-descend", "ship-ss5")
    assert env_id == "DeckLanding-ShipSS5-v6"


def test_unknown_policies_and_scenarios_are_refused_naming_the_choices() -> None:
    with pytest.raises(ConfigError, match=r"policy.*predictive"):
        policy_spec("timing-dqn-timed")
    with pytest.raises(ConfigError, match=r"scenario.*bench-ss4"):
        env_settings("quiescent", "bench-ss9")
    with pytest.raises(ConfigError, match=r"scenario.*DeckLanding"):
        env_settings("quiescent", "high-approach")


def test_the_readmes_which_to_use_table_is_the_registrys_recommendation() -> None:
    from agents.evaluation.results import recommended_figures

    readme = (ROOT / "README.md").read_text()
    rows = [line for line in readme.splitlines() if line.startswith("| ") and "% (" in line]
    figures = recommended_figures()
    assert len(rows) == len(figures)
    for figure, row in zip(figures, rows, strict=True):
        result = figure.result
        env_id, _ = env_settings(figure.policy, result.scenario)
        assert figure.label in row and f"`{figure.policy}`" in row and f"`{env_id}`" in row
        assert figure.row.cell() in row
        assert f"--seed {result.first_seed}" in row and f"--scenario {result.scenario}" in row


def test_a_section_keyword_is_laid_over_the_ids_settings_and_overrides_over_both() -> None:
    env = gym.make(
        "DeckLandingTiming-BenchSS4-v6",
        timing={"guidance": {"descent_profile": "range"}, "wait_limit_s": 20.0},
    )
    timing = env.unwrapped.timing
    # the section wins over the id's timed descent; the id's other settings stay
    assert timing.guidance.descent_profile == "range" and timing.wait_limit_s == 20.0
    assert timing.tilt_model == "scenario"
    env.close()
    env = gym.make(
        "DeckLandingTiming-BenchSS4-v6",
        timing={"wait_limit_s": 20.0},
        overrides={"timing.wait_limit_s": 12.0},
    )
    assert env.unwrapped.timing.wait_limit_s == 12.0
    env.close()


def _expand(pattern: str) -> list[str]:
    """``DeckLanding-{BenchSS3,4,5,PaperStewart}-v1`` as its ids (a bare number continues the
    name before it: ``BenchSS3,4`` is BenchSS3 and BenchSS4)."""
    import re

    match = re.search(r"\{([^}]*)\}", pattern)
    if match is None:
        return [pattern]
    names: list[str] = []
    for part in match.group(1).split(","):
        stem = re.sub(r"\d+$", "", names[-1]) if names and part.isdigit() else ""
        names.append(stem + part)
    return [pattern[: match.start()] + name + pattern[match.end() :] for name in names]


def test_the_changelogs_list_of_current_ids_is_the_registrys() -> None:
    import re

    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    entry = text.split("registered ids, each the highest version of its name**", 1)[1]
    entry = entry.split("\n- ", 1)[0].split(" The ", 1)[0]
    named = [i for p in re.findall(r"`(DeckLanding[^`]*-v\d+)`", entry) for i in _expand(p)]
    assert sorted(named) == sorted(CURRENT)
