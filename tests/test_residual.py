"""The residual lander: a learnt correction of align-descend, trained through rl-zoo3's
``env_wrapper`` and flown with the same sum the training environment sent."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import landing_env  # noqa: F401
from agents.align_descend import build_align_descend
from agents.lander import TrainedLanderPolicy, build_lander
from agents.residual import ResidualLanderWrapper, residual_action, residual_settings
from agents.training import load_train_config, train, zoo_env_wrapper
from landing_env.errors import ConfigError

ID = "DeckLanding-BenchSS4-v1"
SHORT = {"sensors": "realistic", "estimation.observed": "tight", "simulation.max_episode_s": 3.0}
WRAPPER = {"agents.residual.ResidualLanderWrapper": {"base": "align-descend", "scale": 0.4}}


def test_a_zero_correction_flies_exactly_as_align_descend() -> None:
    wrapped = ResidualLanderWrapper(gym.make(ID, overrides=SHORT), scale=0.5)
    alone = gym.make(ID, overrides=SHORT)
    policy = build_align_descend(alone, None, ())
    try:
        for seed in (4, 5):
            observation, _ = wrapped.reset(seed=seed)
            mine, _ = alone.reset(seed=seed)
            policy.reset()
            while True:
                observation, reward, terminated, truncated, info = wrapped.step(np.zeros(4))
                action = policy(mine)
                mine, expected, done, cut, _ = alone.step(action)
                np.testing.assert_array_equal(info["base_action"], action)
                assert reward == expected
                for key, value in observation.items():
                    np.testing.assert_array_equal(value, mine[key], err_msg=key)
                assert (terminated, truncated) == (done, cut)
                if terminated or truncated:
                    break
    finally:
        wrapped.close()
        alone.close()


def test_the_correction_is_scaled_added_and_clipped() -> None:
    total = residual_action(np.array([0.9, -0.2, 0.0, -1.0]), np.array([1.0, 1.0, -0.5, -1.0]), 0.4)
    np.testing.assert_allclose(total, [1.0, 0.2, -0.2, -1.0], atol=1e-7)
    assert total.dtype == np.float32


@pytest.mark.parametrize(
    ("base", "scale", "key"),
    [
        ("predictive", 0.5, "residual.base"),
        ("align-descend", 0.0, "residual.scale"),
        ("align-descend", 2.5, "residual.scale"),
        ("align-descend", "half", "residual.scale"),
        ("align-descend", True, "residual.scale"),
    ],
)
def test_bad_residual_settings_are_refused_naming_the_key(
    base: str, scale: object, key: str
) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        residual_settings(base, scale)


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("agents.residual.NoSuchWrapper", "cannot import 'agents.residual.NoSuchWrapper'"),
        ("no_such_module.Wrapper", "cannot import"),
        ([42], "each entry must be"),
        ({"a.B": {}, "c.D": {}}, "each entry must be"),
    ],
)
def test_a_bad_env_wrapper_is_refused_naming_the_key(value: object, match: str) -> None:
    with pytest.raises(ConfigError, match=f"env_wrapper.*{match}"):
        zoo_env_wrapper(value)


def test_a_wrong_correction_is_refused_before_anything_moves() -> None:
    env = ResidualLanderWrapper(gym.make(ID, overrides=SHORT))
    try:
        with pytest.raises(RuntimeError, match="before reset"):
            env.step(np.zeros(4))
        env.reset(seed=1)
        for bad in (np.zeros(3), np.array([0.0, np.nan, 0.0, 0.0])):
            with pytest.raises(ValueError, match="correction of align-descend"):
                env.step(bad)
    finally:
        env.close()


@pytest.fixture(scope="module")
def residual_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp_path = tmp_path_factory.mktemp("residual")
    data = {
        ID: {
            "n_envs": 1,
            "n_timesteps": 120,
            "policy": "MultiInputPolicy",
            "env_wrapper": [WRAPPER],
            "frame_stack": 2,
            "learning_starts": 40,
            "batch_size": 16,
            "train_freq": 4,
            "gradient_steps": 1,
            "policy_kwargs": "dict(net_arch=[16, 16], log_std_init=-2)",
            "env_kwargs": {"overrides": SHORT},
        },
        "deck_landing": {
            "algo": "sac",
            "vec_env": "dummy",
            "eval": {"freq": 1000, "episodes": 1},
            "out_dir": str(tmp_path / "run"),
        },
    }
    path = tmp_path / "residual.yaml"
    path.write_text(yaml.safe_dump(data))
    return train(load_train_config(path), progress_bar=False).model_path


def test_a_residual_lander_records_its_base_and_flies_base_plus_correction(
    residual_model: Path,
) -> None:
    policy = TrainedLanderPolicy(residual_model)
    assert policy.residual == {"base": "align-descend", "scale": 0.4}
    assert policy.card.observation["residual"] == policy.residual
    env = gym.make(ID, overrides=SHORT)
    with pytest.raises(RuntimeError, match="check_env"):
        policy.act(env.reset(seed=2)[0])
    env.close()

    env = gym.make(ID, overrides=SHORT)
    policy = build_lander(env, str(residual_model), ())
    # the same model stacking on its own, and align-descend on its own: their sum is the action
    plain = TrainedLanderPolicy(residual_model)
    reference = build_align_descend(env, None, ())
    try:
        observation, _ = env.reset(seed=2)
        for each in (policy, plain, reference):
            each.reset()
        for _ in range(40):
            correction = plain.model.predict(plain.stacked(observation), deterministic=True)[0]
            expected = residual_action(reference(observation), correction, 0.4)
            action = policy.act(observation)
            np.testing.assert_array_equal(action, expected)
            observation, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    finally:
        env.close()


def test_a_new_residual_learner_starts_with_a_zero_correction_and_small_noise() -> None:
    from stable_baselines3 import SAC

    from agents.residual import start_at_zero_correction

    env = ResidualLanderWrapper(gym.make(ID, overrides=SHORT))
    try:
        observation, _ = env.reset(seed=3)
        model = SAC("MultiInputPolicy", env, policy_kwargs={"net_arch": [16]}, device="cpu")
        assert np.abs(model.predict(observation, deterministic=True)[0]).max() > 1e-3
        assert start_at_zero_correction(model, std=0.1)
        np.testing.assert_array_equal(model.predict(observation, deterministic=True)[0], 0.0)
        draws = np.array([model.predict(observation)[0] for _ in range(400)])
        assert 0.07 < draws.std() < 0.13  # tanh(N(0, 0.1)) is about 0.1 wide
        sde = SAC("MultiInputPolicy", env, use_sde=True, device="cpu")
        assert not start_at_zero_correction(sde)
    finally:
        env.close()
