"""Config loading: strict keys, typed values, clear messages."""

from __future__ import annotations

import pytest

from landing_env.config import available_configs, load_config
from landing_env.errors import ConfigError


def test_default_config_loads_and_has_papers_rates() -> None:
    config = load_config("default")
    assert config.simulation.physics_hz == 240
    assert config.simulation.env_hz == 20
    assert config.simulation.substeps == 12


@pytest.mark.parametrize("name", available_configs())
def test_every_shipped_config_loads(name: str) -> None:
    load_config(name)


def test_unknown_key_names_the_key_and_the_allowed_ones() -> None:
    with pytest.raises(ConfigError) as excinfo:
        load_config("default", camera={"moed": "render"})
    message = str(excinfo.value)
    assert "camera.moed" in message
    assert "mode" in message


def test_bad_choice_lists_the_allowed_values() -> None:
    with pytest.raises(ConfigError) as excinfo:
        load_config("default", overrides={"camera.mode": "raytrace"})
    message = str(excinfo.value)
    assert "camera.mode" in message
    assert "'render'" in message and "'project'" in message


def test_bad_type_is_named() -> None:
    with pytest.raises(ConfigError, match=r"simulation\.env_hz"):
        load_config("default", simulation={"env_hz": "fast"})


def test_physics_rate_must_be_a_multiple_of_the_env_rate() -> None:
    with pytest.raises(ConfigError, match=r"simulation\.physics_hz.*not a multiple"):
        load_config("default", simulation={"physics_hz": 240, "env_hz": 50})


def test_unknown_config_name_lists_the_shipped_ones() -> None:
    with pytest.raises(ConfigError, match="default"):
        load_config("no-such-scenario")


def test_overrides_apply_on_top_of_yaml() -> None:
    config = load_config("default", overrides={"tof.max_range": 3.0, "simulation.env_hz": 40})
    assert config.tof.max_range == 3.0
    assert config.simulation.env_hz == 40
    assert config.simulation.substeps == 6


def test_estimator_names_are_checked() -> None:
    with pytest.raises(ConfigError, match=r"estimation\.observed.*'truth'"):
        load_config("default", estimation={"observed": "magic"})
