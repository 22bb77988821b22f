"""``DeckLanding-v2``: the land action obeyed only in the hold band, the forced commit, the
observation's memory of the last estimate, the reward's touchdown terms, the privileged critic,
and the PPO recipe trained by ``deck-landing train landing`` and by rl-zoo3 unmodified."""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
import yaml

import landing_env  # noqa: F401
from agents.policies.align_descend import AlignDescendPolicy
from agents.policies.lander import build_lander, normalization_path
from agents.training.trainer import load_train_config, normalize_kwargs, train
from landing_env.config import RewardConfig
from landing_env.envs.actions import action_from_setpoint
from landing_env.envs.rewards import touchdown_terms
from landing_env.errors import ConfigError
from landing_env.touchdown import Outcome, TouchdownMetrics
from tests.paths import ROOT

RECIPE = ROOT / "configs" / "train" / "lander_ppo.yaml"
#: no wave-off: a commit in the band always descends to touchdown
NO_WAVE_OFF = {"timing.wave_off_tilt_deg": 0.0}
#: over the hold height, centred, level
AT_HOLD = {"height_m": 0.73, "offset_m": (0.0, 0.0), "yaw": 0.0}


def _hold(env: gym.Env) -> np.ndarray:
    """The timing task's hold as an action (``land`` at -1 where the action has it)."""
    base = env.unwrapped
    return action_from_setpoint(base._hold_setpoint(), base.config.action)


def _land(action: np.ndarray) -> np.ndarray:
    landing = action.copy()
    landing[-1] = 1.0
    return landing


def _into_band(env: gym.Env, limit: int = 100) -> dict:
    for _ in range(limit):
        _, _, terminated, truncated, info = env.step(_hold(env))
        assert not (terminated or truncated)
        if info["in_band"]:
            return info
    raise AssertionError("the hold never reached the band")


def test_a_land_outside_the_band_is_not_obeyed_and_inside_it_runs_the_descent() -> None:
    env = gym.make("DeckLanding-BenchSS4-v2", overrides=NO_WAVE_OFF)
    try:
        env.reset(seed=3, options={**AT_HOLD, "height_m": 2.5})
        height = env.unwrapped.world.drone_state().position_w[2]
        _, _, terminated, _, info = env.step(_land(_hold(env)))
        assert info["land_refused"] and not info["committed"] and not terminated
        # the set-point was flown for one period, no descent
        assert abs(env.unwrapped.world.drone_state().position_w[2] - height) < 0.1
        assert info["time_s"] == pytest.approx(0.05, abs=1e-6)

        env.reset(seed=3, options=AT_HOLD)
        _into_band(env)
        _, reward, terminated, _, info = env.step(_land(_hold(env)))
        assert terminated and info["committed"] and not info["land_refused"]
        assert "touchdown" in info and info["outcome"] in ("success", "hard_landing")
        # the timed descent (1.3 s to contact) ran inside the one step
        assert 0.8 < info["descent_s"] < 3.0
        assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")))
    finally:
        env.close()


def test_holding_in_the_band_is_forced_down_after_the_wait_limit() -> None:
    env = gym.make("DeckLanding-BenchSS4-v2", overrides={**NO_WAVE_OFF, "timing.wait_limit_s": 1.0})
    try:
        env.reset(seed=4, options=AT_HOLD)
        in_band = 0
        for _ in range(100):
            _, _, terminated, truncated, info = env.step(_hold(env))
            in_band += int(info["in_band"] or info["forced_commit"])
            if terminated or truncated:
                break
        assert terminated and info["forced_commit"] and "touchdown" in info
        assert info["band_s"] >= 1.0 and in_band >= 20  # 1 s in the band at 20 Hz
    finally:
        env.close()


def test_without_the_land_trigger_the_hold_is_never_forced_down() -> None:
    env = gym.make(
        "DeckLanding-BenchSS4-v2",
        overrides={**NO_WAVE_OFF, "timing.wait_limit_s": 1.0, "action.land_trigger": False},
    )
    try:
        assert env.action_space.shape == (4,)
        env.reset(seed=4, options=AT_HOLD)
        for _ in range(40):
            _, _, terminated, _, info = env.step(_hold(env))
            assert not terminated and not info["committed"]
        assert info["band_s"] >= 1.0
    finally:
        env.close()


def test_a_lost_tag_leaves_the_last_estimate_observed_with_its_age() -> None:
    env = gym.make("DeckLanding-BenchSS4-v2")
    try:
        observation, _ = env.reset(seed=5, options=AT_HOLD)
        base = env.unwrapped
        assert observation["deck_seen"][0] == 1.0 and observation["deck_age"][0] == 0.0
        assert observation["deck_position"][2] == pytest.approx(-0.7, abs=0.1)
        lost = {**base._base_observation, "deck_pose_valid": np.zeros(1, np.float32)}
        base._base_observation = lost
        for _ in range(3):
            base._record()
        again = base._lander_observation()
        np.testing.assert_array_equal(again["deck_position"], observation["deck_position"])
        assert again["deck_age"][0] == pytest.approx(0.15, abs=1e-6)
        assert env.observation_space.contains(again)
    finally:
        env.close()


def test_a_one_metre_per_second_touchdown_is_clearly_worse_than_a_soft_one() -> None:
    reward = RewardConfig()

    def net(speed: float, outcome: Outcome) -> float:
        metrics = TouchdownMetrics(relative_normal_speed=speed, deck_tilt_deg=2.0)
        metrics.lateral_offset_m = 0.02
        terms = touchdown_terms(outcome, metrics, reward, touchdown_bonus=True, speed_squared=True)
        return sum(terms.values())

    soft, hard = net(0.3, Outcome.SUCCESS), net(1.0, Outcome.HARD_LANDING)
    assert soft > 10.0 and hard < -5.0
    # and the hard one is not better than giving up to a crash by much
    assert hard < -reward.crash_penalty + 2.0


def test_align_descend_flies_its_own_descent_on_v2() -> None:
    env = gym.make("DeckLanding-BenchSS4-v2")
    try:
        observation, _ = env.reset(seed=0)
        base = env.unwrapped
        action = AlignDescendPolicy(base.config.action, dt=base.env_dt).act(observation)
        assert action.shape == env.action_space.shape and action[-1] == -1.0
    finally:
        env.close()


def test_the_actor_never_sees_the_privileged_key_and_the_critic_does() -> None:
    from stable_baselines3 import PPO

    from landing_env.privileged import register_policy_aliases

    register_policy_aliases()
    env = gym.make("DeckLanding-BenchSS4-v2", privileged=True)
    plain = gym.make("DeckLanding-BenchSS4-v2")
    try:
        model = PPO(
            "PrivilegedCriticPolicy",
            env,
            n_steps=32,
            batch_size=32,
            policy_kwargs={"net_arch": [16, 16]},
            device="cpu",
        )
        policy = model.policy
        assert "privileged" not in policy.pi_features_extractor.extractors
        assert "privileged" in policy.vf_features_extractor.extractors
        observation, _ = env.reset(seed=0)
        batch = {k: th.as_tensor(v[None]) for k, v in observation.items()}
        shifted = {**batch, "privileged": batch["privileged"] + 3.0}
        with th.no_grad():
            mean = policy.get_distribution(batch).distribution.mean
            assert th.equal(mean, policy.get_distribution(shifted).distribution.mean)
            assert not th.equal(policy.predict_values(batch), policy.predict_values(shifted))
            # the actor runs on the env built without the key
            seen, _ = plain.reset(seed=0)
            without = {k: th.as_tensor(v[None]) for k, v in seen.items()}
            assert "privileged" not in without
            assert policy.get_distribution(without).distribution.mean.shape == mean.shape
    finally:
        env.close()
        plain.close()


def _short_recipe(tmp_path: Path, timesteps: int = 256) -> Path:
    """The PPO recipe cut to ``timesteps`` steps, evaluated and saved halfway and at the end."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    data = yaml.safe_load(RECIPE.read_text())
    zoo = data["DeckLanding-BenchSS4-v2"]
    zoo.update(
        {"n_envs": 1, "n_timesteps": timesteps, "n_steps": 64, "batch_size": 32, "n_epochs": 1}
    )
    zoo["env_kwargs"]["overrides"]["simulation.max_episode_s"] = 3.0
    # PPO alone: the imitation stage before it has its own tests (test_imitation.py)
    data["deck_landing"].pop("imitation", None)
    data["deck_landing"].update(
        {
            "vec_env": "dummy",
            "eval": {"freq": timesteps // 2, "episodes": 1},
            "checkpoint_freq": timesteps // 2,
            "out_dir": str(tmp_path),
        }
    )
    path = tmp_path / "lander_ppo.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_the_ppo_recipe_trains_with_vecnormalize_and_the_privileged_critic(tmp_path: Path) -> None:
    recipe = yaml.safe_load(RECIPE.read_text())["DeckLanding-BenchSS4-v2"]
    episode_steps = 40 * 20
    assert 1.0 / (1.0 - recipe["gamma"]) >= episode_steps
    assert recipe["n_envs"] == 2
    # every key normalised but the prediction, which the stopping rule's feature reads raw
    normalised = normalize_kwargs(recipe)["norm_obs_keys"]
    env = gym.make("DeckLanding-BenchSS4-v2", privileged=True)
    keys = set(env.observation_space.spaces)
    env.close()
    assert sorted(normalised) == sorted(keys - {"prediction"})
    config = load_train_config(_short_recipe(tmp_path))
    result = train(config, progress_bar=False)
    assert result.timesteps >= 256 and result.evaluations
    assert (tmp_path / "vecnormalize.pkl").is_file()
    assert list(tmp_path.glob("tb/*/progress.csv"))
    from stable_baselines3 import PPO

    model = PPO.load(result.model_path, device="cpu")
    assert type(model.policy).__name__ == "PrivilegedCriticPolicy"
    assert model.policy.pi_features_extractor.stopping_rule_key == "prediction"
    # lander-model flies it on the task built without the privileged key, normalised
    overrides = data_overrides(RECIPE)
    env = gym.make("DeckLanding-BenchSS4-v2", overrides=overrides)
    try:
        policy = build_lander(env, str(result.model_path), ())
        assert policy.normalize is not None
        observation, _ = env.reset(seed=1)
        assert "privileged" not in observation
        action = policy.act(observation)
        assert action.shape == env.action_space.shape and env.action_space.contains(action)
        # the best model flies with the statistics of its own evaluation, not the run's end
        assert result.best_model_path is not None
        best_statistics = tmp_path / "best_model_vecnormalize.pkl"
        assert best_statistics.is_file()
        best = build_lander(env, str(result.best_model_path), ())
        with best_statistics.open("rb") as stream:
            saved = pickle.load(stream)
        assert best.normalize is not None
        counted = saved.obs_rms["deck_position"].count
        assert best.normalize.obs_rms["deck_position"].count == counted
        assert counted <= policy.normalize.obs_rms["deck_position"].count
        # and each checkpoint with the statistics of its own step
        checkpoints = sorted((tmp_path / "checkpoints").glob("*_steps.zip"))
        assert checkpoints
        assert all(normalization_path(checkpoint).is_file() for checkpoint in checkpoints)
    finally:
        env.close()
    # a model of the land action refuses the pure velocity task, whose actions have 4 entries
    velocity = gym.make(
        "DeckLanding-BenchSS4-v2", overrides={**overrides, "action.land_trigger": False}
    )
    try:
        # the observation's previous action is named, one entry, not the whole space
        with pytest.raises(ConfigError) as refused:
            build_lander(velocity, str(result.model_path), ())
        message = str(refused.value)
        assert message.startswith("observation.keys.previous_action: ")
        assert "{'shape': [5]" in message and "against {'shape': [4]" in message
        assert "attitude" not in message
        with pytest.raises(ConfigError, match="acts with 5 entries, the environment takes 4"):
            build_lander(velocity, str(result.model_path), ("observation",))
    finally:
        velocity.close()


def data_overrides(path: Path) -> dict:
    """The recipe's environment overrides (its sensing and estimator)."""
    return yaml.safe_load(path.read_text())["DeckLanding-BenchSS4-v2"]["env_kwargs"]["overrides"]


def test_rl_zoo3_trains_the_ppo_recipe_unmodified(tmp_path: Path) -> None:
    env_id = "DeckLanding-BenchSS4-v2"
    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", env_id,
        "--gym-packages", "landing_env", "--conf-file", str(RECIPE), "-f", str(tmp_path),
        "-n", "256", "--seed", "1", "--eval-freq", "-1", "--vec-env", "dummy",
        "--hyperparams", "n_envs:1", "n_steps:128", "batch_size:64", "n_epochs:1",
    ]  # fmt: skip
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    saved = list(tmp_path.glob(f"ppo/{env_id}_*/{env_id}.zip"))
    assert saved, done.stdout[-2000:]
    assert list(tmp_path.glob(f"ppo/{env_id}_*/{env_id}/vecnormalize.pkl"))
    from stable_baselines3 import PPO

    model = PPO.load(saved[0], device="cpu")
    assert type(model.policy).__name__ == "PrivilegedCriticPolicy"
    assert model.policy.pi_features_extractor.stopping_rule_key == "prediction"
    assert model.num_timesteps >= 256


def test_a_run_started_from_a_model_goes_on_from_its_normalisation(tmp_path: Path) -> None:
    # one rollout each: the statistics' count is what is compared
    first = train(load_train_config(_short_recipe(tmp_path / "first", 64)), progress_bar=False)
    recipe = yaml.safe_load(_short_recipe(tmp_path / "second", 64).read_text())
    recipe["deck_landing"]["init_model"] = str(first.model_path)
    (tmp_path / "second" / "lander_ppo.yaml").write_text(yaml.safe_dump(recipe))
    second = train(load_train_config(tmp_path / "second" / "lander_ppo.yaml"), progress_bar=False)
    counts = []
    for run in (first, second):
        with (run.model_path.parent / "vecnormalize.pkl").open("rb") as stream:
            counts.append(pickle.load(stream).obs_rms["deck_position"].count)
    # the second run's statistics include the first run's samples
    assert counts[1] == pytest.approx(counts[0] + second.timesteps, abs=1.0)


def test_ctrl_c_ends_a_run_with_its_model_statistics_and_card_saved(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from stable_baselines3 import PPO

    def interrupted(self: PPO, *args: object, **kwargs: object) -> PPO:
        raise KeyboardInterrupt

    monkeypatch.setattr(PPO, "learn", interrupted)
    result = train(load_train_config(_short_recipe(tmp_path)), progress_bar=False)
    assert result.stopped_because == "interrupted"
    assert result.model_path.is_file() and (tmp_path / "vecnormalize.pkl").is_file()
    from agents.common.cards import read_metadata

    assert read_metadata(result.model_path) is not None
