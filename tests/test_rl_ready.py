"""``DeckLanding-v2`` takes the standard RL wrappers with their default arguments, and its
observation carries what a learner needs to fly: its own velocity and attitude."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import landing_env  # noqa: F401

FAST = {"overrides": {"camera.mode": "project"}}


def test_every_observation_key_is_a_float_box_so_vecnormalize_takes_the_defaults() -> None:
    env = gym.make("DeckLanding-v2", **FAST)
    try:
        for key, space in env.observation_space.spaces.items():
            assert isinstance(space, spaces.Box), key
            assert space.dtype == np.float32, key
        sb3_check_env(env.unwrapped, warn=True)
    finally:
        env.close()
    vec = make_vec_env("landing_env:DeckLanding-v2", n_envs=1, seed=2, env_kwargs=FAST)
    normalised = VecNormalize(vec)  # default arguments: every key normalised
    try:
        observation = normalised.reset()
        for _ in range(5):
            observation, reward, _, _ = normalised.step(
                np.zeros((1, *normalised.action_space.shape), dtype=np.float32)
            )
        assert set(observation) == set(vec.observation_space.spaces)
        for key, value in observation.items():
            assert np.all(np.isfinite(value)), key
            assert np.all(np.abs(value) <= normalised.clip_obs), key
        assert np.isfinite(reward).all()
    finally:
        normalised.close()


def test_the_flags_are_zero_or_one() -> None:
    env = gym.make("DeckLanding-v2", **FAST)
    try:
        observation, _ = env.reset(seed=4)
        for _ in range(10):
            for key in ("deck_pose_valid", "deck_pose_predicted", "tof_valid", "range_down_valid"):
                assert set(np.unique(observation[key])) <= {0.0, 1.0}, key
            observation, *_ = env.step(env.action_space.sample())
    finally:
        env.close()


def test_the_velocity_is_the_drones_in_its_heading_frame_and_the_attitude_its_roll_pitch() -> None:
    env = gym.make("DeckLanding-v2", **FAST)
    try:
        observation, info = env.reset(seed=7)
        # fly forward and up for a second: the heading-frame velocity follows the set-point
        for _ in range(20):
            observation, _, terminated, truncated, info = env.step(
                np.array([0.6, 0.0, 0.3, 0.0, -1.0], dtype=np.float32)
            )
            assert not (terminated or truncated)
        roll, pitch, yaw = info["drone"]["euler_w"]
        v_w = info["drone"]["velocity_w"]
        c, s = math.cos(yaw), math.sin(yaw)
        expected = [c * v_w[0] + s * v_w[1], -s * v_w[0] + c * v_w[1], v_w[2]]
        np.testing.assert_allclose(observation["velocity"], expected, atol=1e-5)
        np.testing.assert_allclose(observation["attitude"], [roll, pitch], atol=1e-5)
        assert observation["velocity"][0] > 0.5 * 0.6 * 1.5  # forward, towards 0.9 m/s
        assert observation["velocity"][2] > 0.1  # climbing
        assert abs(observation["velocity"][1]) < 0.2
    finally:
        env.close()


def test_a_time_out_is_a_truncation_with_no_terminal_penalty() -> None:
    env = gym.make(
        "DeckLanding-v2", overrides={"camera.mode": "project", "simulation.max_episode_s": 1.0}
    )
    try:
        env.reset(seed=1)
        truncated = terminated = False
        while not (terminated or truncated):
            _, reward, terminated, truncated, info = env.step(
                np.zeros(env.action_space.shape, dtype=np.float32)
            )
        assert truncated and not terminated
        assert info["outcome"] == "timeout"
        assert info["reward_crash"] == 0.0 and info["reward_success"] == 0.0
        assert math.isclose(
            reward, info["reward_shaping"] + info["reward_time"], rel_tol=0, abs_tol=1e-9
        )
    finally:
        env.close()


def test_a_dummy_vec_env_of_the_scenario_id_normalises_with_default_arguments() -> None:
    vec = DummyVecEnv([lambda: gym.make("DeckLanding-BenchSS4-v2", **FAST)])
    normalised = VecNormalize(vec)
    try:
        normalised.seed(3)
        normalised.reset()
        _, _, done, _ = normalised.step(
            np.zeros((1, *normalised.action_space.shape), dtype=np.float32)
        )
        assert done.shape == (1,)
    finally:
        normalised.close()
