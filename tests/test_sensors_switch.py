"""One switch, ``sensors: ideal | realistic``, for every env and command."""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
import pytest

import landing_env  # noqa: F401
from agents.cli import build_parser
from landing_env.config import SENSORS_ENV, load_config
from landing_env.errors import ConfigError


def test_realistic_bundles_camera_profile_distortion_tof_noise_and_their_calibrations() -> None:
    config = load_config("default", overrides={"sensors": "realistic"})
    assert config.sensors == "realistic"
    assert config.camera.profile == "ov9281" and config.camera.k1 == -0.05
    assert config.tof.noise == "vl53l1x"
    assert config.estimation.intrinsics_file.endswith("realistic/intrinsics.json")
    assert config.estimation.tof_calibration_file.endswith("realistic/tof_camera.json")


def test_ideal_undoes_a_realistic_scenario_and_explicit_overrides_win() -> None:
    ideal = load_config("realistic", overrides={"sensors": "ideal"})
    assert ideal.camera.profile == "ideal" and ideal.camera.k1 == 0.0
    assert ideal.tof.noise == "none" and ideal.estimation.intrinsics_file == ""
    mixed = load_config("realistic", overrides={"camera.profile": "imx219"})
    assert mixed.sensors == "realistic" and mixed.camera.profile == "imx219"
    assert mixed.tof.noise == "vl53l1x"


def test_the_environment_variable_is_the_default_and_a_scenario_key_beats_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(SENSORS_ENV, "realistic")
    assert load_config("default").camera.profile == "ov9281"
    assert load_config("default", overrides={"sensors": "ideal"}).camera.profile == "ideal"
    monkeypatch.setenv(SENSORS_ENV, "perfect")
    with pytest.raises(ConfigError, match="sensors"):
        load_config("default")


def test_an_unknown_sensor_set_is_refused_by_name() -> None:
    with pytest.raises(ConfigError, match="sensors"):
        load_config("default", overrides={"sensors": "great"})


@pytest.mark.parametrize("env_id", ["DeckLanding-v2", "DeckLandingTiming-v0"])
def test_every_env_honours_the_switch(env_id: str) -> None:
    env = gym.make(env_id, overrides={"sensors": "realistic", "camera.mode": "render"})
    try:
        env.reset(seed=0)
        world = env.unwrapped.world
        assert world.camera.formation is not None
        assert world.camera.formation.profile.name == "ov9281"
        assert world.config.tof.noise == "vl53l1x"
        # hover (DeckLanding-v2) or wait (the timing task's 0)
        hold = np.zeros(env.action_space.shape, np.float32) if env.action_space.shape else 0
        env.step(hold)
    finally:
        env.close()


def _leaf_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [parser]
    return [leaf for child in subs[0].choices.values() for leaf in _leaf_parsers(child)]


def _acting_leaves(parser: argparse.ArgumentParser, acts: bool = True) -> list:
    """The leaf parsers where ``--sensors`` acts: neither they nor a parent set
    ``sensors_act=False``."""
    acts = acts and parser.get_default("sensors_act") is not False
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [parser] if acts else []
    return [leaf for child in subs[0].choices.values() for leaf in _acting_leaves(child, acts)]


def test_every_command_that_builds_a_config_takes_sensors_and_no_other_offers_it() -> None:
    parser = build_parser()
    leaves = _leaf_parsers(parser)
    acting = _acting_leaves(parser)
    assert 5 <= len(acting) < len(leaves)
    assert len(acting) >= 5
    for leaf in leaves:
        offered = "--sensors" in leaf._option_string_actions
        assert offered == (leaf in acting), leaf.prog


def test_the_cli_switch_reaches_the_run_and_is_undone_after(monkeypatch) -> None:
    import os

    import agents.cli as cli

    seen = {}

    def fake(args):
        seen["profile"] = load_config("default").camera.profile
        return 0

    monkeypatch.delenv(SENSORS_ENV, raising=False)
    parser = build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            action.choices["demo"].set_defaults(func=fake)
    assert cli.main(["demo", "--sensors", "realistic"]) == 0
    assert seen["profile"] == "ov9281"
    assert SENSORS_ENV not in os.environ
