"""Per-episode randomisation of the timing task, and a tiny training on it."""

from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.training.sampler import (
    SENSING_PROFILES,
    RandomisedTimingEnv,
    RandomiseSettings,
    register_sensing_profile,
    sensing_signatures,
)
from agents.training.trainer import ZOO_META_KEYS, load_train_config, train
from landing_env.config_loading import build_dataclass
from landing_env.errors import ConfigError
from landing_env.scenarios import TIMING_TASK
from tests.paths import ROOT

RANDOMISED = ROOT / "configs/train/timing_randomised.yaml"
QUICK_TIMING = {"history_s": 0.25, "rate_window_s": 0.2, "hold_height_m": 0.45, "wait_limit_s": 2.0}
TWO_BY_TWO = {
    "scenarios": ["bench-ss4", "bench-ss5"],
    "sensing": ["ideal", "tof-vl53l1x"],
    "wind_speed_mps": [1.0, 3.0],
    "start_height_m": [0.45, 0.7],
    "overrides": {"touchdown.settle_time_s": 0.1},
}


@pytest.mark.parametrize(
    ("section", "key"),
    [
        ({"scenarios": ["bench-ss9"]}, r"randomise\.scenarios: 'bench-ss9'.*bench-ss4"),
        ({"sensing": ["perfect"]}, r"randomise\.sensing: 'perfect'.*tof-vl53l1x"),
        ({"estimator": "psychic"}, r"randomise\.estimator"),
        ({"wind_speed_mps": [3.0, 1.0]}, r"randomise\.wind_speed_mps"),
        ({"start_height_m": [0.5]}, r"randomise\.start_height_m"),
        ({"colour": "red"}, r"randomise\.colour"),
    ],
)
def test_bad_randomisation_settings_name_the_key(section: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        build_dataclass(RandomiseSettings, section, "randomise")


def test_each_episode_draws_a_variant_and_its_world_matches_it() -> None:
    env = RandomisedTimingEnv(TWO_BY_TWO, QUICK_TIMING)
    seen = set()
    try:
        for episode in range(8):
            observation, info = env.reset(seed=100 + episode)
            assert env.observation_space.contains(observation)
            variant = info["variant"]
            seen.add((variant["scenario"], variant["sensing"]))
            config = env.unwrapped.config
            assert config.tof.noise == (
                "vl53l1x" if variant["sensing"] == "tof-vl53l1x" else "none"
            )
            assert config.motion.sea_state.sea_state == int(variant["scenario"][-1])
            wind = np.asarray(config.wind.mean_velocity_w)
            assert config.wind.enabled
            assert np.linalg.norm(wind) == pytest.approx(variant["wind_speed_mps"])
            assert 1.0 <= variant["wind_speed_mps"] <= 3.0
            assert 0.45 <= variant["start_height_m"] <= 0.7
            _, _, terminated, _, info = env.step(1)
            assert terminated and info["variant"] == variant
    finally:
        env.close()
    assert len(seen) >= 3  # most of the four worlds in eight draws


def test_a_seeded_reset_gives_the_same_variant_and_episode() -> None:
    first = RandomisedTimingEnv(TWO_BY_TWO, QUICK_TIMING)
    second = RandomisedTimingEnv(TWO_BY_TWO, QUICK_TIMING)
    try:
        a = [first.reset(seed=7)]
        b = [second.reset(seed=7)]
        a.append(first.reset())
        b.append(second.reset())
        for (obs_a, info_a), (obs_b, info_b) in zip(a, b, strict=True):
            assert info_a["variant"] == info_b["variant"]
            np.testing.assert_array_equal(obs_a, obs_b)
        other = [second.reset(seed=8)[1]["variant"] for _ in range(1)]
        other += [second.reset()[1]["variant"] for _ in range(3)]
        again = [first.reset(seed=7)[1]["variant"]] + [
            first.reset()[1]["variant"] for _ in range(3)
        ]
        assert other != again  # distinct seeds (vector workers) draw distinct sequences
    finally:
        first.close()
        second.close()


def test_new_sensing_profiles_plug_in_by_name() -> None:
    register_sensing_profile("tof-noisy-test", {"tof.noise": "vl53l1x"})
    try:
        settings = build_dataclass(
            RandomiseSettings, {"sensing": ["ideal", "tof-noisy-test"]}, "randomise"
        )
        # as model cards name them
        assert sensing_signatures(settings) == ["ideal", "tof.noise=vl53l1x"]
    finally:
        SENSING_PROFILES.pop("tof-noisy-test")
    with pytest.raises(ConfigError, match="sensing"):
        register_sensing_profile("", {})


def _leaves(nested: dict, prefix: str = "") -> list[tuple[str, object]]:
    return [
        leaf
        for key, value in nested.items()
        for leaf in (
            _leaves(value, f"{prefix}{key}.")
            if isinstance(value, dict)
            else [(f"{prefix}{key}", value)]
        )
    ]


def test_every_sensing_profile_the_sampler_offers_is_a_preset_file_and_sets_its_values() -> None:
    from landing_env.config import CONFIG_DIR, SENSOR_SETS, load_config, sensor_preset

    files = {path.stem: path for path in (CONFIG_DIR / "sensors").glob("*.yaml")}
    assert set(SENSING_PROFILES) == set(files)
    for name, path in files.items():
        preset = sensor_preset(name) if name in SENSOR_SETS else yaml.safe_load(path.read_text())
        config = load_config("default", SENSING_PROFILES[name])
        assert config.sensors == preset.get("sensors", "ideal"), name
        for key, value in _leaves(preset):
            section, _, field = key.rpartition(".")
            have = config
            for part in section.split(".") if section else []:
                have = getattr(have, part)
            got = getattr(have, field)
            assert (list(got) if isinstance(got, tuple) else got) == value, (name, key)


def test_a_sensing_file_naming_no_bundle_is_refused_naming_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import landing_env.config as config_module

    (tmp_path / "sensors").mkdir()
    (tmp_path / "sensors" / "murky.yaml").write_text("sensors: foggy\ntof:\n  noise: vl53l1x\n")
    monkeypatch.setattr(config_module, "CONFIG_DIR", tmp_path)
    with pytest.raises(ConfigError, match=r"sensors: .*murky\.yaml: 'foggy'.*realistic"):
        config_module.sensing_profiles()


def test_twice_the_realistic_noise_doubles_every_noise_sigma() -> None:
    from landing_env.config import load_config
    from landing_env.sensors.corner_noise import sigma_px

    realistic = load_config("default", SENSING_PROFILES["realistic"])
    doubled = load_config("default", SENSING_PROFILES["realistic-2x"])
    assert doubled.sensors == realistic.sensors == "realistic"
    ranges = np.array([0.1, 0.7, 3.0])
    np.testing.assert_allclose(doubled.tof.sigma(ranges), 2.0 * realistic.tof.sigma(ranges))
    side, blur = np.array([20.0, 80.0, 300.0]), np.array([0.0, 1.0, 3.0])
    np.testing.assert_allclose(
        sigma_px(doubled.camera.pixel_noise_fit, side, blur),
        2.0 * sigma_px(realistic.camera.pixel_noise_fit, side, blur),
        rtol=1e-3,
    )


def test_the_randomised_yaml_is_rl_zoo_style_and_loads() -> None:
    from sb3_contrib import RecurrentPPO

    data = yaml.safe_load(RANDOMISED.read_text())
    algo_args = set(inspect.signature(RecurrentPPO.__init__).parameters)
    assert set(data[TIMING_TASK]) <= set(ZOO_META_KEYS) | algo_args
    config = load_train_config(RANDOMISED)
    assert config.settings.algo == "recurrentppo"
    assert config.settings.randomise is not None
    assert set(config.settings.randomise["sensing"]) == {"ideal", "tof-vl53l1x"}


def test_a_tiny_randomised_recurrent_training_saves_a_model_with_its_card(tmp_path: Path) -> None:
    from agents.common.cards import read_metadata
    from agents.policies.timing import TrainedTimingPolicy

    config = load_train_config(RANDOMISED)
    settings = config.settings
    settings.env_kwargs["timing"] = QUICK_TIMING
    settings.randomise = {**TWO_BY_TWO, "estimator": "ihrcf"}
    settings.vec_env = "dummy"
    settings.eval.freq = 128
    settings.eval.episodes = 2
    settings.checkpoint_freq = 10_000
    config.hyperparams.update(n_envs=1, n_steps=64, batch_size=32, n_epochs=1)
    config.hyperparams["policy_kwargs"] = "dict(net_arch=[16], lstm_hidden_size=16)"
    result = train(config, out_dir=tmp_path, total_timesteps=128, progress_bar=False)
    assert result.timesteps >= 128 and result.model_path.is_file()
    assert result.evaluations  # the randomised evaluation env ran
    card = read_metadata(result.model_path)
    assert card is not None and card.algo == "recurrentppo"
    assert card.sensing == ["ideal", "tof.noise=vl53l1x"] and card.estimator == "ihrcf"
    assert card.training_config["deck_landing"]["randomise"]["scenarios"] == TWO_BY_TWO["scenarios"]
    policy = TrainedTimingPolicy(result.model_path)
    assert policy.recurrent and policy.name == "timing-recurrentppo"
    observation = np.zeros(card.observation["size"], dtype=np.float32)
    assert policy.act(observation) in (0, 1) and policy._state is not None
    policy.reset()
    assert policy._state is None
