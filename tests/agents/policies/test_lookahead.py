"""The onboard look-ahead as an observation: its features, the wrapper that decides every check
on them, the policy that plays a model trained on it in the bare task, and the model's card."""

from __future__ import annotations

import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import landing_env  # noqa: F401  (registers the ids)
from agents.common.cards import card_for_training, env_signature, write_metadata
from agents.policies.lookahead import (
    FAILED_SCORE,
    LOOKAHEAD_FEATURES,
    LookaheadSettings,
    LookaheadTimingPolicy,
    LookaheadTimingWrapper,
    check_features,
    find_lookahead,
)
from agents.policies.oracle import NO_TOUCHDOWN_MARGIN, TriedCommit
from agents.policies.timing import TrainedTimingPolicy
from agents.training.trainer import TrainConfig, TrainSettings
from landing_env.errors import ConfigError
from tests.paths import ROOT

SHIP_ID = "DeckLandingTiming-ShipSS4-v7"
#: v4 is the ship ids' history observation, which the look-ahead replaces: v5 adds only the forecast
pytestmark = pytest.mark.filterwarnings("ignore:.*is out of date")


@pytest.fixture(scope="module")
def wrapped(small_forecast):
    env = LookaheadTimingWrapper(
        gym.make(SHIP_ID), forecast=small_forecast, draws=2, check_every_s=0.3
    )
    yield env
    env.close()


# ------------------------------------------------------------------------------ features
def test_a_check_scores_each_draw_by_its_margin_and_a_failure_at_the_floor() -> None:
    tries = [
        TriedCommit(lands=True, success=True, margin=0.4),
        TriedCommit(lands=False, success=True, margin=0.05),  # lands without the slack
        TriedCommit(lands=False, success=False, margin=0.3),  # tipped over: a failure
        TriedCommit(lands=False, success=False, margin=NO_TOUCHDOWN_MARGIN),
    ]
    features = dict(zip(LOOKAHEAD_FEATURES, check_features(tries), strict=True))
    assert features["valid"] == 1.0
    assert features["chance"] == pytest.approx(0.25)
    assert features["success"] == pytest.approx(0.5)
    assert features["mean_score"] == pytest.approx((0.4 + 0.05 - 1.0 - 1.0) / 4)
    assert features["min_score"] == FAILED_SCORE
    nothing = dict(zip(LOOKAHEAD_FEATURES, check_features(None), strict=True))
    assert nothing == {
        "valid": 0.0,
        "chance": 0.0,
        "success": 0.0,
        "mean_score": FAILED_SCORE,
        "min_score": FAILED_SCORE,
    }


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.booleans(), st.booleans(), st.floats(allow_nan=True, allow_infinity=True)),
        min_size=1,
        max_size=16,
    )
)
def test_any_tried_commits_give_features_inside_the_observation_bounds(draws) -> None:
    features = check_features([TriedCommit(a and b, b, m) for a, b, m in draws])
    assert features.shape == (len(LOOKAHEAD_FEATURES),)
    assert np.all(np.isfinite(features)) and np.all(np.abs(features) <= 1.0)


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("draws", 0),
        ("draws", 65),
        ("draws", 2.5),
        ("check_every_s", 0.0),
        ("min_margin", 1.5),
        ("checks", 0),
        ("checks", True),
        ("airframe_in_trim", "yes"),
    ],
)
def test_a_bad_lookahead_setting_is_refused_naming_its_key(key: str, value: float) -> None:
    with pytest.raises(ConfigError) as error:
        LookaheadSettings(**{key: value})
    assert error.value.key == key


def test_a_lookahead_with_airframes_in_trim_signs_it_and_plays_that_onboard_model() -> None:
    plain = LookaheadSettings()
    in_trim = LookaheadSettings(airframe_in_trim=True)
    # the shipped look-ahead signs as before the option existed; the other says it twice
    assert "airframe_in_trim" not in plain.signature()
    assert "airframe_in_trim" not in plain.signature()["onboard"]
    assert in_trim.signature()["airframe_in_trim"] is True
    assert in_trim.signature()["onboard"]["airframe_in_trim"] is True
    assert in_trim.onboard().airframe_in_trim and not plain.onboard().airframe_in_trim
    # a card rebuilds the settings it was made with (the fields it holds)
    card = json.loads(json.dumps(in_trim.signature()))
    fields = {k: card[k] for k in LookaheadSettings.__dataclass_fields__ if k in card}
    assert LookaheadSettings(**fields) == in_trim


def test_a_check_interval_off_the_tasks_decisions_is_refused(small_forecast) -> None:
    env = gym.make(SHIP_ID)
    try:
        with pytest.raises(ConfigError) as error:
            LookaheadTimingWrapper(env, forecast=small_forecast, check_every_s=0.25)
        assert error.value.key == "lookahead.check_every_s"
        with pytest.raises(ConfigError) as error:
            LookaheadTimingWrapper(env, forecast=small_forecast, drawz=4)
        assert "drawz" in str(error.value)
    finally:
        env.close()


def test_lookahead_with_randomised_scenarios_is_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError) as error:
        TrainSettings(algo="dqn", lookahead={"draws": 2}, randomise={"scenarios": ["bench-ss4"]})
    assert error.value.key == "deck_landing.lookahead"


# ------------------------------------------------------------------------------ the wrapper
def test_a_wait_holds_one_check_and_a_commit_ends_the_descent(wrapped) -> None:
    observation, _ = wrapped.reset(seed=3)
    base = wrapped.unwrapped
    assert wrapped.observation_space.contains(observation)
    assert observation.shape == (LookaheadSettings(checks=2).size,)
    assert observation[0] == 1.0  # a look-ahead was made at the start
    assert np.all(observation[5:10] == check_features(None))  # no earlier check yet
    assert observation[-1] == 0.0  # nothing of the wait used
    first = observation[:5].copy()
    observation, reward, terminated, _, info = wrapped.step(0)
    assert not terminated and math.isfinite(reward)
    assert base._wait_s == pytest.approx(0.3)  # three of the task's 0.1 s decisions
    np.testing.assert_array_equal(observation[5:10], first)  # the last check moved back
    assert observation[-1] == pytest.approx(0.3 / base.timing.wait_limit_s)
    observation, reward, terminated, _, info = wrapped.step(1)
    assert terminated and info["committed"]
    assert wrapped.observation_space.contains(observation)
    assert observation[0] == 0.0  # nothing to look ahead at after the episode's end


def test_the_same_seed_gives_the_same_lookahead_and_episode(wrapped) -> None:
    runs = []
    for _ in range(2):
        observations = [wrapped.reset(seed=11)[0]]
        observations.append(wrapped.step(0)[0])
        _, reward, _, _, info = wrapped.step(1)
        runs.append((observations, reward, info["outcome"]))
    for a, b in zip(runs[0][0], runs[1][0], strict=True):
        np.testing.assert_array_equal(a, b)
    assert runs[0][1:] == runs[1][1:]


def test_the_lookahead_leaves_the_episode_as_it_found_it(small_forecast) -> None:
    plain = gym.make(SHIP_ID)
    wrapped = LookaheadTimingWrapper(
        gym.make(SHIP_ID), forecast=small_forecast, draws=1, check_every_s=0.1
    )
    try:
        plain.reset(seed=5)
        wrapped.reset(seed=5)
        for _ in range(3):
            expected = plain.step(0)
            wrapped.step(0)
            np.testing.assert_array_equal(wrapped.unwrapped._flat_observation(), expected[0])
        _, reward, _, _, info = plain.step(1)
        _, wrapped_reward, _, _, wrapped_info = wrapped.step(1)
        assert info["outcome"] == wrapped_info["outcome"]
        assert wrapped_reward == pytest.approx(reward)
    finally:
        plain.close()
        wrapped.close()


def test_random_decisions_stay_in_the_space_to_the_wait_limit(small_forecast) -> None:
    env = LookaheadTimingWrapper(
        gym.make(SHIP_ID, overrides={"timing.wait_limit_s": 1.2}),
        forecast=small_forecast,
        draws=1,
        check_every_s=0.4,
    )
    assert env.observation_space.shape == (11,)
    rng = np.random.default_rng(0)
    try:
        for seed in range(3):
            observation, _ = env.reset(seed=seed)
            steps = 0
            while True:
                assert env.observation_space.contains(observation)
                action = int(rng.random() < 0.2)
                observation, _, terminated, truncated, info = env.step(action)
                steps += 1
                if terminated or truncated:
                    break
            assert env.observation_space.contains(observation)
            assert steps <= 3  # 1.2 s of wait in 0.4 s checks forces the commit
            assert info["outcome"] != "in_flight"
    finally:
        env.close()


# ------------------------------------------------------------------------------ the model
def _model(tmp_path: Path, env: gym.Env) -> Path:
    from stable_baselines3 import DQN

    model = DQN("MlpPolicy", env, learning_starts=10, policy_kwargs={"net_arch": [8]}, seed=0)
    path = tmp_path / "lookahead.zip"
    model.save(path)
    config = TrainConfig(hyperparams={}, settings=TrainSettings(algo="dqn"))
    write_metadata(path, card_for_training(env, config))
    return path


def test_the_card_records_the_lookahead_and_the_bare_task_does_not(wrapped) -> None:
    signature = env_signature(wrapped)
    assert find_lookahead(wrapped) is wrapped
    assert signature["observation"]["size"] == wrapped.observation_space.shape[0]
    lookahead = signature["observation"]["lookahead"]
    assert lookahead["draws"] == 2 and lookahead["check_every_s"] == 0.3
    assert lookahead["features"] == list(LOOKAHEAD_FEATURES)
    assert "lookahead" not in env_signature(wrapped.unwrapped)["observation"]


def test_the_policy_plays_the_wrappers_checks_in_the_bare_task(wrapped, tmp_path) -> None:
    path = _model(tmp_path, wrapped)
    first, _ = wrapped.reset(seed=7)
    env = gym.make(SHIP_ID)
    try:
        policy = LookaheadTimingPolicy(path, env, forecast=wrapped.observer.planner.forecast)
        observation, _ = env.reset(seed=7)
        policy.reset()
        actions = [policy(observation)]
        np.testing.assert_array_equal(policy.checks[0][1], first)
        # between checks it waits without looking ahead
        for _ in range(2):
            if actions[-1] == 1:
                break
            observation, *_ = env.step(actions[-1])
            actions.append(policy(observation))
        assert len(policy.checks) == 1
        assert actions[1:] == [0] * (len(actions) - 1)
    finally:
        env.close()


def test_a_lookahead_model_is_refused_as_a_plain_timing_model_and_vice_versa(
    wrapped, tmp_path
) -> None:
    path = _model(tmp_path, wrapped)
    env = gym.make(SHIP_ID)
    try:
        with pytest.raises(ConfigError) as error:
            TrainedTimingPolicy(path).check_env(env)
        assert error.value.key == "policy" and "timing-dqn-lookahead" in str(error.value)
        (tmp_path / "plain").mkdir()
        plain = _model(tmp_path / "plain", env)
        with pytest.raises(ConfigError) as error:
            LookaheadTimingPolicy(plain, env, forecast=wrapped.observer.planner.forecast)
        assert error.value.key == "model"
    finally:
        env.close()


def test_a_card_of_other_lookahead_settings_is_refused_by_key(
    small_forecast, wrapped, tmp_path
) -> None:
    path = _model(tmp_path, wrapped)
    other = LookaheadTimingWrapper(
        gym.make(SHIP_ID), forecast=small_forecast, draws=2, check_every_s=0.3, min_margin=0.3
    )
    try:
        from agents.common.cards import check_compatible, read_metadata

        card = read_metadata(path)
        assert card.observation["lookahead"]["min_margin"] == 0.15  # the trained one
        with pytest.raises(ConfigError) as error:
            check_compatible(card, env_signature(other), path.name)
        assert error.value.key == "observation.lookahead"
    finally:
        other.close()


def test_a_lookahead_training_config_signs_its_card_with_the_lookahead_unwrapped_too() -> None:
    from agents.training.trainer import load_train_config
    from landing_env.config_loading import build_dataclass

    config = load_train_config(ROOT / "configs/train/timing_dqn_lookahead_offline.yaml")
    assert config.settings.lookahead is not None
    env = gym.make("DeckLandingTiming-ShipSS5-v7")
    try:
        given = build_dataclass(LookaheadSettings, config.settings.lookahead, "lookahead")
        card = card_for_training(env, config, lookahead=given)
    finally:
        env.close()
    lookahead = card.observation["lookahead"]
    settings = LookaheadSettings(**config.settings.lookahead)
    assert lookahead == settings.signature()
    assert card.observation["size"] == settings.size


def test_the_shipped_lookahead_model_decides_at_ship_ss5_with_realistic_sensing() -> None:
    from agents.policies.registry import make_env_and_policy

    env, policy = make_env_and_policy(
        "timing-dqn-lookahead", "ship-ss5", "tight", extra_overrides={"sensors": "realistic"}
    )
    try:
        assert isinstance(policy, LookaheadTimingPolicy)
        assert policy.settings == LookaheadSettings(
            draws=16, check_every_s=0.5, checks=2, airframe_in_trim=True
        )
        observation, _ = env.reset(seed=1_000_001)
        policy.reset()
        action = policy(observation)
        assert action in (0, 1) and len(policy.checks) == 1
        assert policy.checks[0][1][0] == 1.0  # a look-ahead was made
    finally:
        env.close()
