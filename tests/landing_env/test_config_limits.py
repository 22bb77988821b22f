"""Every numeric config value is checked for finiteness and a physical range, naming its key."""

from __future__ import annotations

import math

import pytest

from landing_env.config import DeckLandingConfig, available_configs, load_config
from landing_env.config_limits import LIMITS, numeric_leaves
from landing_env.errors import ConfigError

LEAVES = numeric_leaves(DeckLandingConfig)


def _shaped_like(default: object, number: float) -> object:
    """``number`` in the shape of a default value (a number or a tuple of them)."""
    if isinstance(default, tuple):
        return tuple(_shaped_like(item, number) for item in default)
    return int(number) if isinstance(default, int) and math.isfinite(number) else number


def _names(error: ConfigError, key: str) -> bool:
    """The error's key is ``key`` (or an element of it), or its message names it."""
    return error.key.split("[", 1)[0] == key or key in str(error)


@pytest.mark.parametrize(("key", "default"), LEAVES, ids=[k for k, _ in LEAVES])
def test_every_numeric_key_refuses_nan_inf_and_absurd_values(key: str, default: object) -> None:
    allow_inf = LIMITS.get(key) is not None and LIMITS[key].allow_inf
    for number in (math.nan, math.inf, -math.inf, 1e9, -1e9):
        if number == math.inf and allow_inf:
            continue
        value = _shaped_like(default, number)
        with pytest.raises(ConfigError) as info:
            load_config("default", overrides={key: value})
        assert _names(info.value, key), (value, str(info.value))


def test_inf_is_accepted_where_it_means_something() -> None:
    config = load_config(
        "default",
        overrides={
            "estimation.ihrcf.max_plane_rms_m": math.inf,
            "estimation.fusion.atda_sigma": [0.003, 0.003, math.inf, 3.0, 3.0, 0.3],
        },
    )
    assert config.estimation.ihrcf.max_plane_rms_m == math.inf
    with pytest.raises(ConfigError, match=r"estimation\.fusion\.atda_sigma"):
        load_config("default", overrides={"estimation.fusion.atda_sigma": [math.nan] * 6})


@pytest.mark.parametrize("name", available_configs())
def test_every_shipped_config_is_within_the_limits(name: str) -> None:
    assert isinstance(load_config(name), DeckLandingConfig)


def test_the_limits_table_names_only_existing_keys() -> None:
    keys = {key for key, _ in LEAVES}
    keys |= {"camera.cx", "camera.cy", "seed", "motion.sinusoids.phases_deg"}  # None defaults
    assert set(LIMITS) <= keys, set(LIMITS) - keys


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        ({"reward.time_cost": math.nan}, "reward.time_cost"),
        ({"reward.success_bonus": -1.0}, "reward.success_bonus"),
        ({"simulation.physics_hz": 1_000_000}, "simulation.physics_hz"),
        ({"simulation.max_episode_s": math.inf}, "simulation.max_episode_s"),
        ({"start.height_m": [math.inf, math.inf]}, "start.height_m"),
        ({"rangefinder.resolution": math.inf}, "rangefinder.resolution"),
        ({"deck.thickness": math.nan}, "deck.thickness"),
        ({"stewart.top_radius": math.inf}, "stewart.top_radius"),
        ({"imu.gyro_noise_density": math.inf}, "imu.gyro_noise_density"),
        ({"tof.sigma_0": math.nan}, "tof.sigma_0"),
        ({"motion.sea_state.roll_period_s": math.inf}, "motion.sea_state.roll_period_s"),
        ({"stewart_base_position": [0.0, math.nan, 0.04]}, "stewart_base_position"),
    ],
)
def test_values_that_crashed_runs_are_refused_at_load(overrides: dict, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_config("default", overrides=overrides)
    assert info.value.key.split("[", 1)[0] == key


def test_cross_field_errors_name_both_keys() -> None:
    with pytest.raises(ConfigError) as info:
        load_config("default", overrides={"simulation.env_hz": 7})
    assert "physics_hz" in str(info.value) and "env_hz" in str(info.value)
    for section in ("tof", "rangefinder"):
        with pytest.raises(ConfigError) as info:
            load_config("default", overrides={f"{section}.min_range": 50.0})
        assert "min_range" in str(info.value) and "max_range" in str(info.value)
    with pytest.raises(ConfigError) as info:
        load_config("default", overrides={"estimation.vision_link.latency_s": 0.0})
    assert "latency_jitter_s" in str(info.value) and "latency_s =" in str(info.value)
    # a bound computed from another key names that key (here half the ship's length)
    with pytest.raises(ConfigError) as info:
        load_config("default", overrides={"motion.ship.length_m": 15.0})
    assert "helideck_position_m" in str(info.value) and "length_m = 15.0" in str(info.value)


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("deck.quiet_zone_cells", 10.0),
        ("stewart.base_radius", 5.0),
        ("stewart.top_anchor_depth", 0.4),
        ("stewart.min_leg_length", 4.7),
        ("motion.ship.length_m", 15.0),
        ("motion.ship.beam_m", 1.0),
        ("deck.pad_radius", 10.0),
    ],
)
def test_a_value_refused_by_a_cross_field_check_is_named(key: str, value: float) -> None:
    with pytest.raises(ConfigError) as info:
        load_config("default", overrides={key: value})
    assert key.rsplit(".", 1)[-1] in str(info.value)


def test_a_missing_vehicle_file_is_a_config_error() -> None:
    with pytest.raises(ConfigError) as info:
        load_config("default", vehicle="/nonexistent.yaml")
    assert info.value.key == "vehicle" and "/nonexistent.yaml" in str(info.value)


@pytest.mark.parametrize(("key", "value"), [("camera.k1", -0.05), ("camera.fx", 300.0)])
def test_a_changed_camera_without_its_calibration_is_refused(key: str, value: float) -> None:
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the environments)

    with pytest.raises(ConfigError) as info:
        gym.make("DeckLanding-v2", overrides={key: value, "estimation.observed": "ihrcf"})
    message = str(info.value)
    assert info.value.key == "estimation.intrinsics_file"  # the prefix is added once
    assert key in message and "matching calibration" in message
    assert "deck-landing calibrate" in message
    # with the exact camera model no calibration file is needed
    env = gym.make(
        "DeckLanding-v2",
        overrides={
            key: value,
            "estimation.observed": "ihrcf",
            "estimation.intrinsics": "exact",
            "estimation.tof_calibration": "exact",
        },
    )
    env.close()


def test_every_config_tree_built_by_the_loader_refuses_non_finite_numbers() -> None:
    from landing_env.config_loading import build_dataclass
    from landing_env.timing_config import TimingConfig

    with pytest.raises(ConfigError) as info:
        build_dataclass(TimingConfig, {"wait_limit_s": math.inf}, "timing")
    assert info.value.key == "timing.wait_limit_s"
    assert build_dataclass(TimingConfig, {"wait_limit_s": 20.0}, "timing").wait_limit_s == 20.0
