"""Training the timing policy: the YAML, a short SB3 run, the shipped policy against land-now."""

from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.evaluation.landing import evaluate_policy
from agents.policies.timing import SHIPPED_TIMING_MODEL, TrainedTimingPolicy
from agents.training.trainer import (
    SCENARIO_ENV_ID,
    ZOO_META_KEYS,
    algorithm_kwargs,
    load_train_config,
    parse_policy_kwargs,
    train,
)
from landing_env.errors import ConfigError
from landing_env.scenarios import TIMING_TASK
from tests.paths import ROOT

#: the range-scheduled descent the shipped timing_dqn.zip was trained on
RANGE_DESCENT = {"timing.guidance.descent_profile": "range"}
CONFIG = ROOT / "configs" / "train" / "timing_ppo.yaml"


@pytest.mark.parametrize("name", ["ppo", "dqn"])
def test_the_yamls_are_rl_zoo_style_and_complete(name: str) -> None:
    from stable_baselines3 import DQN, PPO

    algo = name.split("_")[0]
    path = CONFIG.with_name(f"timing_{name}.yaml")
    data = yaml.safe_load(path.read_text())
    zoo = dict(data[SCENARIO_ENV_ID])
    zoo.pop("env_kwargs", None)  # rl-zoo3's (and our) keywords of gym.make
    # every key of the zoo section is a zoo meta key or a keyword argument of the algorithm
    algo_args = set(inspect.signature({"ppo": PPO, "dqn": DQN}[algo].__init__).parameters)
    assert set(zoo) <= set(ZOO_META_KEYS) | algo_args
    assert isinstance(zoo["policy_kwargs"], str) and zoo["policy_kwargs"].startswith("dict(")
    config = load_train_config(path)
    assert config.settings.algo == algo and config.n_envs == 2
    assert config.env_id == SCENARIO_ENV_ID  # the scenario is in the id, not in env_kwargs
    assert "config" not in config.settings.env_kwargs
    kwargs = algorithm_kwargs(config.hyperparams)
    assert "n_envs" not in kwargs and "n_timesteps" not in kwargs
    # PPO: separate actor and critic networks; DQN: one Q-network
    net_arch = kwargs["policy_kwargs"]["net_arch"]
    assert isinstance(net_arch, dict if algo == "ppo" else list)


def test_zoo_policy_kwargs_strings_are_parsed_without_eval() -> None:
    from torch import nn

    parsed = parse_policy_kwargs(
        "dict(net_arch=[32, dict(pi=[16], vf=[8])], activation_fn=nn.ReLU)"
    )
    assert parsed == {"net_arch": [32, {"pi": [16], "vf": [8]}], "activation_fn": nn.ReLU}
    with pytest.raises(ConfigError, match="policy_kwargs"):
        parse_policy_kwargs("__import__('os').system('true')")
    assert algorithm_kwargs({"learning_rate": "lin_0.001"})["learning_rate"](0.5) == 0.0005


def test_bad_settings_name_the_key(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({TIMING_TASK: {"n_envs": 1}, "deck_landing": {"algo": "sac"}}))
    with pytest.raises(ConfigError, match=r"deck_landing\.algo"):
        load_train_config(path)
    path.write_text(yaml.safe_dump({"CartPole-v1": {}}))
    with pytest.raises(ConfigError, match=SCENARIO_ENV_ID):
        load_train_config(path)


def test_a_short_training_run_updates_and_saves_a_policy_that_loads_again(tmp_path: Path) -> None:
    import torch
    from stable_baselines3 import PPO

    config = load_train_config(CONFIG)
    settings = config.settings
    # a quick variant of the task: short history, low hold, short settle, a small network
    settings.env_kwargs["timing"] = {
        "history_s": 0.25,
        "rate_window_s": 0.2,
        "hold_height_m": 0.45,
        "wait_limit_s": 2.0,
    }
    settings.env_kwargs["overrides"] = {"touchdown.settle_time_s": 0.1}
    settings.eval.freq = 128
    settings.eval.episodes = 1
    settings.checkpoint_freq = 128
    # no worker processes to start (SubprocVecEnv: tests/landing_env/envs/test_deck_landing.py)
    settings.vec_env = "dummy"
    settings.target_success_rate = 1.1  # run every step: no early stop on a lucky evaluation
    config.hyperparams.update(n_steps=64, batch_size=32, n_epochs=4)
    config.hyperparams["policy_kwargs"] = "dict(net_arch=[32, 32])"
    result = train(config, out_dir=tmp_path, total_timesteps=256, progress_bar=False)
    assert result.timesteps >= 256
    assert result.model_path.is_file() and result.best_model_path is not None
    assert len(result.evaluations) == 2
    checkpoints = sorted((tmp_path / "checkpoints").glob("*.zip"), key=lambda p: p.stat().st_mtime)
    assert len(checkpoints) >= 2
    assert list((tmp_path / "tb").iterdir())  # TensorBoard logs
    assert (tmp_path / "train_summary.yaml").is_file()
    # the optimiser changed the policy between the first checkpoint and the end
    first = PPO.load(checkpoints[0], device="cpu").policy.state_dict()
    model = PPO.load(result.model_path, device="cpu")
    final = model.policy.state_dict()
    moved = max(float((final[k] - first[k]).abs().max()) for k in final)
    assert moved > 1e-4
    assert all(torch.isfinite(v).all() for v in final.values())
    # the saved policy acts as the loaded model does
    policy = TrainedTimingPolicy(result.model_path)
    rng = np.random.default_rng(0)
    for _ in range(5):
        observation = rng.normal(size=model.observation_space.shape).astype(np.float32)
        expected, _ = model.predict(observation, deterministic=True)
        assert policy.act(observation) == int(expected)


def test_the_shipped_policy_beats_land_now_on_held_out_seeds() -> None:
    episodes, first = 24, 2_000_000
    # both on the range-scheduled descent the shipped policy was trained on
    learned = evaluate_policy(
        "timing-model",
        "bench-ss4",
        episodes,
        first,
        model_path=str(SHIPPED_TIMING_MODEL),
        extra_overrides=RANGE_DESCENT,
    )
    now = evaluate_policy("land-now", "bench-ss4", episodes, first, extra_overrides=RANGE_DESCENT)
    learned_rate = np.mean([r.success for r in learned])
    now_rate = np.mean([r.success for r in now])
    assert learned_rate > now_rate
    # 21 of 24 here: the policy was trained on the bench deck with gamma 3.3 and rigid feet;
    # the bench sea is now gamma 1 (DNV-RP-C205), less regular, and the feet compliant
    assert learned_rate >= 0.85


#: (file, algorithm, the id its rl-zoo3 section names, budget cuts) of each shipped YAML
#: that rl-zoo3 trains; only the budget is cut (-n, --hyperparams) so that the test is short
ZOO_YAMLS = (
    (
        CONFIG,
        "ppo",
        SCENARIO_ENV_ID,
        ("n_envs:1", "n_steps:32", "batch_size:16", "n_epochs:1"),
    ),
)


@pytest.mark.parametrize(("config", "algo", "env_id", "cuts"), ZOO_YAMLS)
def test_rl_zoo3_trains_on_the_shipped_yaml_unmodified(
    tmp_path: Path, config: Path, algo: str, env_id: str, cuts: tuple[str, ...]
) -> None:
    import subprocess
    import sys

    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", algo,
        "--env", env_id, "--gym-packages", "landing_env",
        "--conf-file", str(config), "-f", str(tmp_path), "-n", "48", "--seed", "1",
        "--eval-freq", "-1", "--vec-env", "dummy", "--n-eval-envs", "1",
        "--hyperparams", *cuts,
    ]  # fmt: skip
    done = subprocess.run(
        command, cwd=config.parents[2], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    saved = list(tmp_path.glob(f"{algo}/{env_id}_*/{env_id}.zip"))
    assert saved, done.stdout[-2000:]
    import gymnasium as gym
    from stable_baselines3 import PPO, SAC

    model = {"ppo": PPO, "sac": SAC}[algo].load(saved[0], device="cpu")
    env = gym.make(env_id)
    try:
        if algo == "ppo":
            assert model.observation_space.shape == env.observation_space.shape
        else:  # the lander's Dict, each key stacked three steps deep (frame_stack: 3)
            spaces = env.observation_space.spaces
            for key, space in model.observation_space.spaces.items():
                assert space.shape[-1] == 3 * spaces[key].shape[-1], key
        assert model.num_timesteps >= 48
    finally:
        env.close()


def test_training_can_start_from_a_trained_model_whose_card_matches() -> None:
    import gymnasium as gym
    import torch
    from stable_baselines3 import DQN

    from agents.training.trainer import _start_from

    realistic = SHIPPED_TIMING_MODEL
    trained = DQN.load(realistic, device="cpu")
    for estimator, refused in (("ihrcf", False), ("tight", True)):
        env = gym.make(
            SCENARIO_ENV_ID,
            overrides={**RANGE_DESCENT, "estimation.observed": estimator},
        )
        try:
            model = DQN("MlpPolicy", env, policy_kwargs={"net_arch": [64, 64]}, device="cpu")
            if refused:
                with pytest.raises(ConfigError, match="estimator"):
                    _start_from(model, str(realistic), env)
                continue
            _start_from(model, str(realistic), env)
        finally:
            env.close()
        for name, value in trained.policy.state_dict().items():
            assert torch.equal(model.policy.state_dict()[name], value), name
    with pytest.raises(ConfigError, match="init_model"):
        _start_from(model, "no/such/model.zip", env)


def test_the_randomised_predictive_yaml_flies_the_policys_settings_over_each_own_predictor() -> (
    None
):
    """The third stage of ``timing-dqn-predictive`` writes the policy's timing settings out in
    its YAML: they must stay what the registry flies it with, and it draws both bench sea
    states, each reading its own predictor (``tilt_model: scenario``)."""
    from landing_env.config_loading import build_dataclass
    from landing_env.scenarios import BENCH_TIMING, PREDICTIVE_TIMING
    from landing_env.timing_config import TimingConfig

    config = load_train_config(CONFIG.with_name("timing_dqn_predictive_randomised.yaml"))
    written = build_dataclass(TimingConfig, config.settings.env_kwargs["timing"], "timing")
    flown = {**BENCH_TIMING, **PREDICTIVE_TIMING, "observation": "prediction"}
    assert written == build_dataclass(TimingConfig, flown, "timing")
    assert written.tilt_model == "scenario"
    assert set(config.settings.randomise["scenarios"]) == {"bench-ss4", "bench-ss5"}
    second_stage = "timing_dqn_predictive_finetune/timing_dqn_final.zip"
    assert config.settings.init_model.endswith(second_stage)


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"normalize": True}, "normalize"),
        ({"normalize": "dict(norm_obs_keys=['prediction', 'velocity'])"}, "normalize"),
        ({"frame_stack": 2}, "frame_stack"),
    ],
)
def test_a_recipe_that_would_feed_the_stopping_rule_feature_altered_input_is_refused(
    tmp_path: Path, change: dict, named: str
) -> None:
    recipe = yaml.safe_load((ROOT / "configs" / "train" / "lander_ppo.yaml").read_text())
    zoo = recipe["DeckLanding-BenchSS4-v2"]
    zoo["policy_kwargs"] = "dict(features_extractor_kwargs=dict(stopping_rule_key='prediction'))"
    zoo["normalize"] = "dict(norm_obs_keys=['velocity'])"
    path = tmp_path / "recipe.yaml"
    path.write_text(yaml.safe_dump(recipe))
    assert load_train_config(path).frame_stack == 1  # unnormalised, one frame: accepted
    zoo.update(change)
    path.write_text(yaml.safe_dump(recipe))
    with pytest.raises(ConfigError, match=rf"DeckLanding-BenchSS4-v2\.{named}.*'prediction'"):
        load_train_config(path)
