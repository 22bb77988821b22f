"""``deck-landing tune timing`` on Ray Tune, on a tiny budget."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from agents.training.tune import TuneSettings, load_tune_settings, tune_timing
from landing_env.errors import ConfigError
from tests.paths import ROOT


def test_the_shipped_search_yaml_loads() -> None:
    settings = load_tune_settings(ROOT / "configs" / "train" / "tune_timing.yaml")
    assert set(settings.space) == {"gamma", "learning_rate", "exploration_fraction"}


def test_a_bad_search_space_names_the_key() -> None:
    with pytest.raises(ConfigError, match=r"space\.gamma"):
        TuneSettings(space={"gamma": {"normal": [0.9, 0.1]}})
    with pytest.raises(ConfigError, match="samples"):
        TuneSettings(samples=0, space={"gamma": {"choice": [0.99]}})


@pytest.mark.slow
def test_a_tiny_search_runs_its_trials_and_keeps_the_best(tmp_path: Path) -> None:
    base = yaml.safe_load((ROOT / "configs" / "train" / "timing_dqn.yaml").read_text())
    zoo = base["DeckLandingTiming-BenchSS4-v6"]
    zoo.update(learning_starts=8, batch_size=8, buffer_size=1000, train_freq=4, gradient_steps=1)
    zoo["policy_kwargs"] = "dict(net_arch=[16])"
    base_path = tmp_path / "base.yaml"
    base_path.write_text(yaml.safe_dump(base))
    settings = TuneSettings(
        base=str(base_path),
        samples=2,
        timesteps=32,
        eval_episodes=2,
        max_concurrent=2,
        out_dir=str(tmp_path / "tune"),
        space={"gamma": {"choice": [0.99, 0.998]}, "learning_rate": {"loguniform": [1e-4, 1e-3]}},
        # a quick variant of the task: short history, low hold, short settle
        env_kwargs={
            "overrides": {"touchdown.settle_time_s": 0.1, "timing.history_s": 0.25,
                          "timing.rate_window_s": 0.2, "timing.hold_height_m": 0.45,
                          "timing.wait_limit_s": 2.0},
        },
    )  # fmt: skip
    result = tune_timing(settings)
    assert len(result.trials) == 2
    assert all(0.0 <= t["success_rate"] <= 1.0 for t in result.trials), result.trials
    assert result.best["success_rate"] == max(t["success_rate"] for t in result.trials)
    assert {t["config"]["gamma"] for t in result.trials} <= {0.99, 0.998}
    assert (tmp_path / "tune" / "best.yaml").is_file()
    assert (tmp_path / "tune" / "trials.json").is_file()
