"""``align-predictive``: align-descend's approach to the hold band, ``land`` by predictive's
stopping rule on the observed chances (the lander's imitation teacher)."""

from __future__ import annotations

import gymnasium as gym
import pytest

import landing_env  # noqa: F401
from agents.policies.registry import make_env_and_policy, make_policy
from landing_env.anticipation.onboard_tilt_prediction import commit_by_prediction
from landing_env.errors import ConfigError


def test_it_lands_the_bench_by_committing_only_when_the_stopping_rule_holds() -> None:
    env, policy = make_env_and_policy("align-predictive", "bench-ss4", sensing="realistic")
    landed = 0
    try:
        for seed in (3_000_000, 3_000_001, 3_000_002):
            observation, _ = env.reset(seed=seed)
            policy.reset()
            commits = 0
            while True:
                action = policy.act(observation)
                assert env.action_space.contains(action)
                # land is the rule's verdict on what the policy saw, nothing else
                rule = commit_by_prediction(observation["prediction"])
                assert action[-1] == (1.0 if rule else -1.0)
                commits += int(rule and bool(observation["in_band"][0]))
                observation, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    break
            landed += info["outcome"] == "success"
            # it landed on its own commit, not the band's forced one
            assert commits >= 1 and not info["forced_commit"]
    finally:
        env.close()
    assert landed == 3


def test_it_holds_at_the_band_height_until_the_rule_commits() -> None:
    env, policy = make_env_and_policy("align-predictive", "bench-ss4", sensing="ideal")
    try:
        observation, _ = env.reset(seed=5)
        policy.reset()
        while True:
            action = policy.act(observation)
            action[-1] = -1.0  # never commit: the hold must last
            observation, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        # it reached the band and held there, without a descent of its own, until the
        # band's forced commit took it down
        assert info["forced_commit"]
        assert info["band_s"] >= env.unwrapped.timing.wait_limit_s - 1e-9
    finally:
        env.close()


def test_it_is_refused_where_there_is_no_land_action_or_no_prediction_naming_the_key() -> None:
    env = gym.make("DeckLanding-BenchSS4-v2", overrides={"action.land_trigger": False})
    try:
        with pytest.raises(ConfigError, match=r"action\.land_trigger"):
            make_policy("align-predictive", env)
    finally:
        env.close()
    env = gym.make("DeckLanding-ShipSS4-v6")
    try:
        with pytest.raises(ConfigError, match=r"timing\.observation"):
            make_policy("align-predictive", env)
    finally:
        env.close()
