"""``lens: standard | wide``: the camera's lens, with the calibrations made for it, and the ship
scenarios' view gate that follows the lens."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import landing_env  # noqa: F401
from estimation.camera_model import CameraIntrinsics
from landing_env.config import CONFIG_DIR, load_config
from landing_env.errors import ConfigError
from landing_env.estimators import load_intrinsics
from landing_env.scenarios import SCENARIO_IDS


def test_the_wide_lens_sees_80_degrees_across_where_the_standard_sees_58() -> None:
    standard = load_config("default").camera.intrinsics
    wide = load_config("default", overrides={"lens": "wide"}).camera.intrinsics
    across = {
        name: math.degrees(2 * math.atan(camera.half_view_tan()))
        for name, camera in (("standard", standard), ("wide", wide))
    }
    assert across["standard"] == pytest.approx(58.2, abs=0.3)
    assert across["wide"] == pytest.approx(79.9, abs=0.3)


@pytest.mark.parametrize("sensors", ["ideal", "realistic"])
def test_each_sensing_profile_gets_the_calibration_made_for_the_wide_lens(sensors: str) -> None:
    config = load_config("default", overrides={"lens": "wide", "sensors": sensors})
    folder = "wide" if sensors == "ideal" else "wide-realistic"
    assert config.estimation.intrinsics_file == f"configs/calibration/{folder}/intrinsics.json"
    assert config.estimation.tof_calibration_file.endswith(f"{folder}/tof_camera.json")
    # the file was made for this very camera (the environment checks it) and found fx
    calibrated = load_intrinsics(config)
    assert calibrated.fx == pytest.approx(config.camera.fx, abs=1.0)
    assert calibrated.dist[0] == pytest.approx(config.camera.k1, abs=0.005)
    # the realistic profile's distortion and noise still apply through the wide lens
    assert config.camera.profile == ("ov9281" if sensors == "realistic" else "ideal")


def test_the_standard_lens_keeps_the_sensing_profiles_own_calibrations() -> None:
    config = load_config("default", overrides={"sensors": "realistic", "lens": "standard"})
    assert config.camera.fx == 458.5
    assert config.estimation.intrinsics_file.endswith("realistic/intrinsics.json")


def test_an_explicit_override_beats_the_lens_and_an_unknown_lens_is_refused_by_name() -> None:
    config = load_config("default", overrides={"lens": "wide", "camera.fx": 300.0})
    assert config.camera.fx == 300.0
    with pytest.raises(ConfigError, match="lens"):
        load_config("default", overrides={"lens": "fisheye"})


def test_the_wide_calibration_files_were_made_for_the_lens_the_preset_names() -> None:
    for folder in ("wide", "wide-realistic"):
        summary = json.loads((CONFIG_DIR / "calibration" / folder / "summary.json").read_text())
        k = np.array(summary["intrinsics"]["K"])
        assert k[0, 0] == pytest.approx(305.1, abs=1.0)
        assert k[1, 1] == pytest.approx(304.67, abs=1.0)
        assert summary["intrinsics"]["rms_reprojection_error_px"] < 0.2


def test_the_half_view_widens_with_barrel_distortion_and_narrows_off_centre() -> None:
    pinhole = CameraIntrinsics(fx=305.1, fy=304.67)
    barrel = CameraIntrinsics(fx=305.1, fy=304.67, dist=(-0.05, 0.0, 0.0, 0.0, 0.0))
    off_centre = CameraIntrinsics(fx=305.1, fy=304.67, cx=225.5)
    assert barrel.half_view_tan() > pinhole.half_view_tan()
    assert off_centre.half_view_tan() == pytest.approx(225.5 / 305.1)
    # a point just inside the half view projects inside the image, one beyond it outside
    for camera in (pinhole, barrel):
        t = camera.half_view_tan()
        inside = camera.project(np.array([[0.0, t * 0.99, 1.0]]))[0]
        outside = camera.project(np.array([[0.0, t * 1.02, 1.0]]))[0]
        assert 0.0 <= inside[1] <= camera.height - 1
        assert outside[1] > camera.height - 1


def test_the_ship_ids_see_through_the_scenarios_lens_and_gate_on_its_view() -> None:
    # the standard lens with the fixed gate of the ids before v4, and the scenario's own
    standard = {"lens": "standard", "timing.guidance.view_from_camera": False}
    for overrides, lens, half_tan in ((standard, "standard", 0.558), ({}, "wide", None)):
        env = gym.make(
            "DeckLandingTiming-ShipSS5-v8", overrides={"sensors": "realistic", **overrides}
        )
        try:
            unwrapped = env.unwrapped
            assert unwrapped.config.lens == lens
            gate = unwrapped.guidance.gains.view_half_tan
            if half_tan is None:
                # the calibrated camera's own half view, not a number for another lens
                assert gate == pytest.approx(load_intrinsics(unwrapped.config).half_view_tan())
                assert gate > 0.8
            else:
                assert gate == half_tan
        finally:
            env.close()
    # the ship ids fly their scenario's own lens
    assert "lens" not in SCENARIO_IDS["DeckLanding-ShipSS5-v6"].overrides
    assert load_config("ship-ss6").lens == "wide"
    # at sea state 4 the standard lens's finer pixels win (README "A wider lens for the ship")
    assert load_config("ship-ss4").lens == load_config("ship-ss3").lens == "standard"


def test_a_wide_lens_ship_episode_runs_to_an_outcome_with_every_observation_in_its_space() -> None:
    env = gym.make("DeckLandingTiming-ShipSS5-v8", overrides={"sensors": "realistic"})
    try:
        observation, _ = env.reset(seed=3)
        assert env.observation_space.contains(observation)
        for _ in range(5):
            observation, _, terminated, truncated, _ = env.step(0)
            assert env.observation_space.contains(observation)
            assert not (terminated or truncated)
        observation, _, terminated, truncated, info = env.step(1)
        assert env.observation_space.contains(observation)
        assert terminated or truncated
        assert info["outcome"] in ("success", "hard_landing", "crash", "timeout")
    finally:
        env.close()


def test_a_model_card_names_a_lens_other_than_the_standard_one_in_its_sensing() -> None:
    from agents.common.cards import sensing_profile

    assert sensing_profile(load_config("bench-ss5", {"sensors": "realistic"})) == "realistic"
    ship = load_config("ship-ss5", {"sensors": "realistic"})
    assert sensing_profile(ship) == "realistic,lens=wide"
    assert sensing_profile(load_config("ship-ss5", {"tof.noise": "vl53l1x"})) == (
        "tof.noise=vl53l1x,lens=wide"
    )
    # a profile named by the caller keeps the lens it is flown with
    assert sensing_profile(ship, "realistic-2x") == "realistic-2x,lens=wide"
    assert sensing_profile(load_config("ship-ss4"), "realistic-2x") == "realistic-2x"


@settings(max_examples=60, deadline=None)
@given(
    fx=st.floats(150.0, 900.0),
    aspect=st.floats(0.95, 1.05),
    cx=st.floats(200.0, 310.0),
    cy=st.floats(200.0, 310.0),
    k1=st.floats(-0.06, 0.06),
)
def test_any_camera_keeps_a_point_within_its_half_view_inside_the_image(
    fx: float, aspect: float, cx: float, cy: float, k1: float
) -> None:
    camera = CameraIntrinsics(fx=fx, fy=fx * aspect, cx=cx, cy=cy, dist=(k1, 0.0, 0.0, 0.0, 0.0))
    t = camera.half_view_tan()
    assert math.isfinite(t) and t > 0.0
    # the four directions along the image axes, just inside the half view
    rays = np.array([[t, 0.0, 1.0], [-t, 0.0, 1.0], [0.0, t, 1.0], [0.0, -t, 1.0]]) * [
        0.98,
        0.98,
        1.0,
    ]
    pixels = camera.project(rays)
    assert np.all(pixels >= -0.5) and np.all(pixels[:, 0] <= camera.width - 0.5)
    assert np.all(pixels[:, 1] <= camera.height - 0.5)


def test_a_view_gate_from_a_camera_its_calibration_does_not_fit_is_refused_naming_the_file() -> (
    None
):
    from landing_env.envs.timing import DeckLandingTimingEnv

    with pytest.raises(ConfigError, match=r"estimation\.intrinsics_file"):
        DeckLandingTimingEnv(
            "ship-ss5",
            overrides={
                "camera.fx": 300.0,
                "estimation.observed": "truth",
                "timing.hold_height_m": 2.0,
                "timing.guidance.view_from_camera": True,
            },
        )
