"""The lander's imitation stage: DAgger from ``align-predictive`` into the SB3 policy, the
``land`` entry's classes balanced, the critic fitted without moving the actor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th
import yaml

from agents.policies.lander import TrainedLanderPolicy, normalization_path
from agents.training.imitation import ImitationSettings, _land_weights, fit_actor, fit_critic
from agents.training.trainer import load_train_config, train
from landing_env.errors import ConfigError
from tests.paths import ROOT

RECIPE = ROOT / "configs" / "train" / "lander_ppo.yaml"


def _short_recipe(tmp_path: Path, **imitation: object) -> Path:
    data = yaml.safe_load(RECIPE.read_text())
    section = data["DeckLanding-BenchSS4-v2"]
    section.update(n_envs=1, n_timesteps=0)
    section["policy_kwargs"] = "dict(net_arch=dict(pi=[32, 32], vf=[32, 32]), log_std_init=-1.6)"
    data["deck_landing"].update(
        vec_env="dummy", out_dir=str(tmp_path / "run"), eval={"episodes": 1, "seed": 900_000}
    )
    data["deck_landing"]["imitation"] = {"iterations": 2, "episodes": 2, "epochs": 4, **imitation}
    path = tmp_path / "lander.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_the_shipped_recipe_imitates_align_predictive_before_ppo() -> None:
    config = load_train_config(RECIPE)
    assert config.settings.imitation is not None
    assert config.settings.imitation["teacher"] == "align-predictive"


def test_bad_imitation_settings_name_their_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"deck_landing\.imitation\.teacher"):
        load_train_config(_short_recipe(tmp_path, teacher="align-descend"))
    with pytest.raises(ConfigError, match="iterations"):
        load_train_config(_short_recipe(tmp_path, iterations=0))
    with pytest.raises(ConfigError, match=r"deck_landing\.imitation"):
        load_train_config(_short_recipe(tmp_path, epoch=3))


def test_a_commit_step_weighs_commit_weight_hold_steps_at_the_land_weights_mean() -> None:
    labels = np.full((100, 5), -1.0, np.float32)
    labels[:4, -1] = 1.0
    weights = _land_weights(labels, land_weight=2.0, commit_weight=10.0)
    assert weights[0] == pytest.approx(10.0 * weights[-1])
    assert weights.mean() == pytest.approx(2.0)


class _Model:
    """The policy of the shipped recipe's architecture over a small Dict observation."""

    def __init__(self) -> None:
        import gymnasium as gym
        from stable_baselines3 import PPO

        from landing_env.privileged import register_policy_aliases

        register_policy_aliases()
        space = gym.spaces.Dict(
            {
                "a": gym.spaces.Box(-5.0, 5.0, (3,), np.float32),
                "privileged": gym.spaces.Box(-5.0, 5.0, (2,), np.float32),
            }
        )

        class _Env(gym.Env):  # type: ignore[type-arg]
            observation_space = space
            action_space = gym.spaces.Box(-1.0, 1.0, (5,), np.float32)

        self.model = PPO(
            "PrivilegedCriticPolicy",
            _Env(),
            policy_kwargs={"net_arch": {"pi": [32, 32], "vf": [32, 32]}},
            device="cpu",
            seed=0,
        )


def _data(n: int = 512) -> tuple[dict[str, np.ndarray], np.ndarray]:
    rng = np.random.default_rng(0)
    observations = {
        "a": rng.normal(size=(n, 3)).astype(np.float32),
        "privileged": rng.normal(size=(n, 2)).astype(np.float32),
    }
    labels = np.zeros((n, 5), np.float32)
    labels[:, :4] = np.tanh(observations["a"][:, [0, 1, 2, 0]])
    # a rare commit, decided by the actor's own input
    labels[:, 4] = np.where(observations["a"][:, 0] + observations["a"][:, 1] > 2.0, 1.0, -1.0)
    return observations, labels


def test_the_fitted_actor_commits_where_the_teacher_commits_though_commits_are_rare() -> None:
    model = _Model().model
    observations, labels = _data()
    assert (labels[:, 4] > 0).mean() < 0.1
    settings = ImitationSettings(epochs=150, learning_rate=3e-3, decay=1.0)
    fit_actor(model, observations, labels, settings, seed=0)
    with th.no_grad():
        mean = model.policy.get_distribution(
            {k: th.as_tensor(v) for k, v in observations.items()}
        ).distribution.mean.numpy()
    commit = labels[:, 4] > 0
    # the environment obeys land above 0.5
    assert ((mean[:, 4] > 0.5) == commit).mean() > 0.95
    assert (mean[commit, 4] > 0.5).mean() > 0.8
    assert np.abs(mean[:, :4] - labels[:, :4]).mean() < 0.1


def test_fitting_the_critic_leaves_the_actor_as_imitation_left_it() -> None:
    model = _Model().model
    observations, _ = _data()
    tensors = {k: th.as_tensor(v) for k, v in observations.items()}
    with th.no_grad():
        before = model.policy.get_distribution(tensors).distribution.mean.clone()
        values_before = model.policy.predict_values(tensors).clone()
    returns = observations["privileged"][:, 0] * 3.0
    fit_critic(
        model, observations, returns, ImitationSettings(value_epochs=60, learning_rate=3e-3), seed=0
    )
    with th.no_grad():
        after = model.policy.get_distribution(tensors).distribution.mean
        values = model.policy.predict_values(tensors).flatten().numpy()
    assert th.equal(before, after)
    # the critic learnt the returns, which it reads through the privileged key
    start = np.mean((values_before.flatten().numpy() - returns) ** 2)
    assert np.mean((values - returns) ** 2) < 0.2 * start


def test_a_short_imitation_run_saves_a_student_with_its_card_and_statistics(
    tmp_path: Path,
) -> None:
    result = train(load_train_config(_short_recipe(tmp_path)), progress_bar=False)
    run = tmp_path / "run"
    student = run / "imitation_model.zip"
    assert student.is_file() and normalization_path(student).is_file()
    records = yaml.safe_load((run / "imitation.yaml").read_text())
    assert [r["flown_by"] for r in records] == ["teacher", "student"]
    # the teacher lands its episodes and commits on a few of their steps
    assert records[0]["success"] == 1.0
    assert 0.0 < records[0]["commit_share"] < 0.1
    assert records[1]["steps"] > records[0]["steps"]
    # no PPO step was asked for: the final model is the student, and so is the best one
    assert result.timesteps == 0
    assert result.best_model_path is not None
    assert normalization_path(result.best_model_path).is_file()
    assert TrainedLanderPolicy(result.best_model_path).card.env_id == "DeckLanding-BenchSS4-v2"
    policy = TrainedLanderPolicy(student)
    assert policy.card.observation.get("task") == "DeckLanding"
