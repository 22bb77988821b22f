"""The SB3 lander: trained through ``deck-landing train landing``, its card checked on load, and
its observation stacked at inference exactly as ``VecFrameStack`` stacks it in training."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

import landing_env  # noqa: F401
from agents.policies.lander import TrainedLanderPolicy, build_lander, normalization_path
from agents.training.learning_curve import read_learning_curve
from agents.training.trainer import load_train_config, train
from landing_env.errors import ConfigError

SHORT = {
    "sensors": "realistic",
    "estimation.observed": "tight",
    "simulation.max_episode_s": 2.0,
}


def _yaml(tmp_path: Path, algo: str = "sac", **zoo: object) -> Path:
    section = {
        "n_envs": 1,
        "n_timesteps": 160,
        "policy": "MultiInputPolicy",
        "frame_stack": 3,
        "learning_starts": 60,
        "batch_size": 32,
        "train_freq": 4,
        "gradient_steps": 1,
        "policy_kwargs": "dict(net_arch=[16, 16], log_std_init=-3)",
        "env_kwargs": {"overrides": SHORT},
        **zoo,
    }
    data = {
        "DeckLanding-BenchSS4-v2": section,
        "deck_landing": {
            "algo": algo,
            "vec_env": "dummy",
            "eval": {"freq": 80, "episodes": 1},
            "out_dir": str(tmp_path / "run"),
        },
    }
    path = tmp_path / "lander.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp_path = tmp_path_factory.mktemp("lander")
    result = train(load_train_config(_yaml(tmp_path)), progress_bar=False)
    assert result.timesteps >= 160
    return result.model_path


def test_a_trained_lander_carries_a_card_of_its_id_observation_and_sensing(trained: Path) -> None:
    policy = TrainedLanderPolicy(trained)
    assert policy.card.env_id == "DeckLanding-BenchSS4-v2"
    assert policy.card.algo == "sac"
    assert policy.card.estimator == "tight"
    assert policy.card.sensing == ["realistic"]
    assert policy.frame_stack == 3
    assert set(policy.card.observation["keys"]) >= {"deck_pose", "velocity", "attitude"}


def test_training_draws_its_learning_curve_from_its_held_out_evaluations(trained: Path) -> None:
    run = trained.parent
    summary = yaml.safe_load((run / "train_summary.yaml").read_text())
    curve = read_learning_curve(run)
    assert [int(t) for t in curve.timesteps] == [t for t, _ in summary["evaluations"]] == [80, 160]
    assert list(curve.success_rate) == [s for _, s in summary["evaluations"]]
    assert (run / "learning_curve.png").stat().st_size > 10_000
    rows = (run / "learning_curve.csv").read_text().splitlines()
    assert rows[0].startswith("timesteps,success_rate") and len(rows) == 3
    with pytest.raises(ConfigError, match=r"evaluations\.npz not found"):
        read_learning_curve(run / "checkpoints")


def test_the_lander_refuses_another_estimator_naming_it(trained: Path) -> None:
    env = gym.make("DeckLanding-BenchSS4-v2", overrides={**SHORT, "estimation.observed": "ihrcf"})
    try:
        with pytest.raises(ConfigError, match="estimator"):
            build_lander(env, str(trained), ())
        build_lander(env, str(trained), ("estimator",))  # allowed on purpose
    finally:
        env.close()


def test_the_stacked_observation_at_inference_is_vecframestacks(trained: Path) -> None:
    policy = build_lander(gym.make("DeckLanding-BenchSS4-v2", overrides=SHORT), str(trained), ())
    vec = VecFrameStack(
        DummyVecEnv([lambda: gym.make("DeckLanding-BenchSS4-v2", overrides=SHORT)]), 3
    )
    env = gym.make("DeckLanding-BenchSS4-v2", overrides=SHORT)
    try:
        vec.seed(5)
        stacked = vec.reset()
        observation, _ = env.reset(seed=5)
        policy.reset()
        for _ in range(25):
            mine = policy.stacked(observation)
            for key, value in mine.items():
                np.testing.assert_array_equal(value, stacked[key][0], err_msg=key)
            action = np.asarray(policy.model.predict(mine, deterministic=True)[0])
            stacked, _, done, _ = vec.step(action[None])
            observation, _, terminated, truncated, _ = env.step(action)
            assert bool(done[0]) == (terminated or truncated)
            if done[0]:
                break
    finally:
        vec.close()
        env.close()


def test_a_lander_yaml_with_a_timing_algorithm_or_a_bad_stack_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"deck_landing.algo.*sac, tqc, ppo"):
        load_train_config(_yaml(tmp_path, algo="dqn"))
    with pytest.raises(ConfigError, match="frame_stack"):
        load_train_config(_yaml(tmp_path, frame_stack=0))


def test_the_shipped_recipe_trains_the_scenario_id_with_realistic_tight_sensing() -> None:
    config = load_train_config("configs/train/lander_ppo.yaml")
    assert config.env_id == "DeckLanding-BenchSS4-v2"
    assert config.task == "DeckLanding-v2"
    assert config.settings.env_kwargs["overrides"] == {
        "sensors": "realistic",
        "estimation.observed": "tight",
    }


@pytest.mark.parametrize(
    ("recipe", "env_id", "actions"),
    [
        ("lander_velocity_ppo", "DeckLanding-BenchSS4-v2", 4),
        ("lander_ship_ppo", "DeckLanding-ShipSS4-v6", 5),
    ],
)
def test_the_research_recipes_train_ppo_alone_with_the_privileged_critic(
    recipe: str, env_id: str, actions: int
) -> None:
    from agents.training.trainer import make_envs

    config = load_train_config(f"configs/train/{recipe}.yaml")
    assert config.env_id == env_id
    assert config.settings.imitation is None
    config.settings.vec_env = "dummy"  # the environments in this process
    train_env, eval_env = make_envs(config)
    try:
        assert train_env.action_space.shape == (actions,)
        assert eval_env.action_space.shape == (actions,)
        assert "privileged" in train_env.observation_space.spaces
    finally:
        train_env.close()
        eval_env.close()


def test_rl_zoos_env_wrapper_wraps_the_training_environments_not_the_evaluation(
    tmp_path: Path,
) -> None:
    from agents.training.trainer import make_envs

    wrapper = {"gymnasium.wrappers.RecordEpisodeStatistics": {"buffer_length": 7}}
    config = load_train_config(_yaml(tmp_path, env_wrapper=[wrapper]))
    train_env, eval_env = make_envs(config)
    try:
        trained_env = train_env.venv.envs[0]
        assert isinstance(trained_env, gym.wrappers.RecordEpisodeStatistics)
        assert trained_env.return_queue.maxlen == 7
        assert not isinstance(eval_env.venv.envs[0], gym.wrappers.RecordEpisodeStatistics)
    finally:
        train_env.close()
        eval_env.close()


def test_an_env_wrapper_that_does_not_import_is_refused_naming_the_key(tmp_path: Path) -> None:
    from agents.training.trainer import make_envs

    config = load_train_config(_yaml(tmp_path, env_wrapper="agents.no_such_module.Wrapper"))
    with pytest.raises(ConfigError, match="env_wrapper"):
        make_envs(config)


def test_a_model_reads_its_own_normalisation_and_a_checkpoint_sb3s() -> None:
    run = Path("results/run")
    assert normalization_path(run / "best_model.zip") == run / "best_model_vecnormalize.pkl"
    assert (
        normalization_path(run / "checkpoints/lander_ppo_200000_steps.zip")
        == run / "checkpoints/lander_ppo_vecnormalize_200000_steps.pkl"
    )


def test_the_shipped_lander_flies_the_bench_to_touchdowns_on_its_own_land_trigger() -> None:
    from agents.policies.registry import make_env_and_policy

    env, policy = make_env_and_policy("lander", "bench-ss4")
    assert policy.card.env_id == "DeckLanding-BenchSS4-v2"
    assert "privileged" not in env.observation_space.spaces  # the actor flies without it
    landed = 0
    try:
        for seed in (4_000_000, 4_000_001, 4_000_002):
            observation, _ = env.reset(seed=seed)
            policy.reset()
            while True:
                action = policy.act(observation)
                assert env.action_space.contains(action)
                observation, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    break
            landed += info["outcome"] == "success" and not info["forced_commit"]
    finally:
        env.close()
    assert landed == 3
