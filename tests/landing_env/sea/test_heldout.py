"""The held-out seas: they load, they run, they are what they say, and nothing fits to them."""

from __future__ import annotations

import json
import zipfile

import gymnasium as gym
import numpy as np
import pytest

import landing_env  # noqa: F401  (registers the environments)
from landing_env.anticipation.hms_forecast import ONLINE, deck_forecast_for, held_out_sea
from landing_env.config import CONFIG_DIR, load_config
from landing_env.errors import ConfigError
from landing_env.sea import heldout
from landing_env.sea.heldout import HELD_OUT_SEAS
from landing_env.sea.hms import HelideckMonitorConfig
from landing_env.waves.generator import GeneratedSea
from tests.paths import ROOT


def test_the_held_out_names_are_the_shipped_held_out_configs() -> None:
    assert set(HELD_OUT_SEAS) == {"ship-unseen-4", "ship-unseen-5", "bench-unseen"}
    assert "never used for fitting, training or tuning" in " ".join(heldout.__doc__.lower().split())
    for name in HELD_OUT_SEAS:
        header = (CONFIG_DIR / f"{name}.yaml").read_text().split("\n\n")[0]
        assert "NEVER used for fitting, training or tuning" in header, name


@pytest.mark.parametrize("name", sorted(HELD_OUT_SEAS))
def test_a_held_out_config_is_an_unseen_sea(name: str) -> None:
    config = load_config(name)
    sea = config.motion.ship if config.motion.kind == "ship" else config.motion.sea_state
    generator = sea.generator
    assert generator.spectrum in ("torsethaugen", "ochi_hubble")
    assert generator.speed_m_s > 0.0 and generator.ramped
    assert generator.swell_direction_deg is not None
    assert config.seed == 1_000_000
    assert (config.deck_mount == "ship") == name.startswith("ship")


def test_no_training_config_and_no_fit_names_a_held_out_sea() -> None:
    names = tuple(HELD_OUT_SEAS)
    train = sorted((CONFIG_DIR / "train").glob("*.yaml"))
    assert train
    for path in train:
        text = path.read_text()
        assert not any(name in text for name in names), path.name
    predictors = sorted((ROOT / "landing_env" / "assets" / "predictors").glob("*.npz"))
    assert predictors
    for path in predictors:
        with np.load(path, allow_pickle=False) as data:
            fitted = json.loads(str(data["metadata"]))["scenarios"]
        assert not set(fitted) & set(names), path.name
    for path in sorted((ROOT / "agents" / "models").glob("*.zip")):
        with zipfile.ZipFile(path) as archive:
            cards = [n for n in archive.namelist() if n.endswith(".json")]
            text = " ".join(archive.read(n).decode() for n in cards)
        assert not any(name in text for name in names), path.name


@pytest.mark.parametrize("name", sorted(n for n in HELD_OUT_SEAS if n.startswith("ship")))
def test_a_held_out_ship_sea_identifies_its_helideck_forecast_online_never_fitted_on_it(
    name: str,
) -> None:
    config = load_config(name)
    assert config.deck_forecast == ONLINE
    assert deck_forecast_for(config, HelideckMonitorConfig()) is None
    assert held_out_sea(config.motion) == name
    # without the family, the forecast would be fitted on the held-out sea: refused
    config.deck_forecast = ""
    with pytest.raises(ConfigError, match=f"held-out {name!r}") as error:
        deck_forecast_for(config, HelideckMonitorConfig())
    assert error.value.key == "deck_forecast"
    config.deck_forecast = "ship-everything"
    with pytest.raises(ConfigError, match=r"online.*ship-broad") as error:
        deck_forecast_for(config, HelideckMonitorConfig())
    assert error.value.key == "deck_forecast"


def test_a_scenarios_own_sea_is_no_held_out_sea() -> None:
    assert held_out_sea(load_config("ship-ss5").motion) == ""


@pytest.mark.parametrize("name", sorted(HELD_OUT_SEAS))
def test_a_deck_landing_env_runs_a_held_out_sea(name: str) -> None:
    env = gym.make("DeckLanding-v2", config=name)
    try:
        flat = lambda o: gym.spaces.flatten(env.observation_space, o)  # noqa: E731
        first = flat(env.reset(seed=1_000_000)[0])
        world = env.unwrapped.world
        assert isinstance(world.stewart.motion.waves, GeneratedSea)
        deck = [world.deck_state().position_w.copy()]
        for _ in range(5):
            observation, reward, *_ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
            assert np.all(np.isfinite(flat(observation))) and np.isfinite(reward)
            deck.append(world.deck_state().position_w.copy())
        assert np.ptp(np.array(deck), axis=0).max() > 0.0
        np.testing.assert_array_equal(first, flat(env.reset(seed=1_000_000)[0]))
    finally:
        env.close()
