"""Direct tests of behaviours that a mutation probe of the suite found untested or caught by luck:
the reward's shaping sign, IMU saturation, the flip crash, the touchdown tilt boundary, the
action scaling per axis, deck-motion seeding, the rigid fit's translation and the settle rule.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import landing_env  # noqa: F401  (registers the environments)
from estimation.frames import matrix_from_euler_zyx, tag_corners_in_tag_frame
from estimation.geometry import RigidFitter
from landing_env.config import TouchdownConfig, load_config
from landing_env.envs.base import IMU_HIGH
from landing_env.stewart.motion import make_motion_source, sample_poses
from landing_env.touchdown import Outcome, TouchdownMetrics, evaluate_touchdown

TRUTH = {"estimation.observed": "truth", "start.max_offset_m": 0.0}


def make(**overrides: object) -> gym.Env:
    return gym.make("DeckLanding-v2", overrides={**TRUTH, **overrides})


def step_n(env: gym.Env, action: list[float], n: int) -> tuple[list[float], dict]:
    """``n`` steps of the velocity set-point ``action`` (the land trigger, where the action
    has one, not pulled)."""
    full = np.full(env.action_space.shape, -1.0, dtype=np.float32)
    full[: len(action)] = action
    rewards, info = [], {}
    for _ in range(n):
        _, reward, terminated, truncated, info = env.step(full)
        rewards.append(reward)
        if terminated or truncated:
            break
    return rewards, info


def test_shaping_rewards_approaching_the_deck_and_charges_leaving_it() -> None:
    # without the time cost, the relative speed's potential and the action-rate term only the
    # distance's shaping is left in flight
    env = make(
        **{
            "reward.time_cost": 0.0,
            "reward.velocity_weight": 0.0,
            "reward.action_rate_weight": 0.0,
            "motion.kind": "static",
        }
    )
    try:
        env.reset(seed=0)
        down, _ = step_n(env, [0.0, 0.0, -0.5, 0.0], 10)
        env.reset(seed=0)
        up, _ = step_n(env, [0.0, 0.0, 0.5, 0.0], 10)
    finally:
        env.close()
    # the first step only starts the motion; from the second on the sign is the direction's
    assert all(r > 0.0 for r in down[2:]) and all(r < 0.0 for r in up[2:])
    # 0.5 m/s for 0.05 s at vertical weight 0.5: about 0.0125 a step
    assert np.mean(down[4:]) == pytest.approx(0.0125, rel=0.3)


def test_imu_saturation_is_clipped_in_the_observation_and_flagged_in_info() -> None:
    env = make(**{"imu.gyro_bias_sigma": 100.0})  # biases of order 100 rad/s: past 2000 deg/s
    try:
        observation, info = env.reset(seed=3)
        observation, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert info["imu_saturated"] is True
        assert np.isclose(np.abs(observation["imu"][3:]), IMU_HIGH[3:]).any()
        assert env.observation_space.contains(observation)
    finally:
        env.close()
    env = make()
    try:
        env.reset(seed=3)
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert info["imu_saturated"] is False
    finally:
        env.close()


def test_tilting_past_flip_tilt_deg_in_flight_is_a_crash() -> None:
    # a full-speed forward acceleration pitches the drone by far more than 5 degrees
    strict = make(**{"simulation.flip_tilt_deg": 5.0})
    try:
        strict.reset(seed=0)
        rewards, info = step_n(strict, [1.0, 0.0, 0.0, 0.0], 40)
        assert info["outcome"] == "crash" and len(rewards) < 40
        assert "touchdown" not in info and "crash_contact" not in info  # no contact
        assert np.hypot(*info["drone"]["position_w"][:2]) < 3.0  # nor the arena
    finally:
        strict.close()
    relaxed = make()
    try:
        relaxed.reset(seed=0)
        rewards, info = step_n(relaxed, [1.0, 0.0, 0.0, 0.0], len(rewards))
        assert info["outcome"] == "in_flight"
    finally:
        relaxed.close()


@pytest.mark.parametrize(("tilt", "ok"), [(5.0, True), (5.0 + 1e-9, False), (4.99, True)])
def test_deck_tilt_check_at_its_boundary(tilt: float, ok: bool) -> None:
    metrics = TouchdownMetrics(
        relative_normal_speed=0.2,
        deck_tilt_deg=tilt,
        relative_attitude_deg=1.0,
        lateral_offset_m=0.0,
        all_feet_touched=True,
        on_deck_after_settle=True,
    )
    outcome, result = evaluate_touchdown(metrics, TouchdownConfig(max_deck_tilt_deg=5.0))
    assert (outcome is Outcome.SUCCESS) is ok
    assert ("deck_tilt" in result.failed_checks) is (not ok)


def test_each_action_axis_is_scaled_by_its_own_limit() -> None:
    env = make(
        **{
            "action.max_horizontal_speed": 1.5,
            "action.max_vertical_speed": 0.7,
            "action.max_yaw_rate_deg": 30.0,
        }
    )
    try:
        scale = env.unwrapped._action_to_setpoint
        setpoint = scale(np.array([0.5, -1.0, 1.0, -0.5]))
        np.testing.assert_allclose(setpoint.velocity_h, [0.75, -1.5, 0.7])
        assert setpoint.yaw_rate == pytest.approx(math.radians(-15.0))
    finally:
        env.close()


@pytest.mark.parametrize("kind", ["sinusoids", "sea_state"])
def test_deck_motion_is_a_function_of_its_seed(kind: str) -> None:
    config = load_config("default", overrides={"motion.kind": kind}).motion
    times = np.linspace(0.0, 20.0, 41)
    first = sample_poses(make_motion_source(config, np.random.default_rng(5)), times)
    again = sample_poses(make_motion_source(config, np.random.default_rng(5)), times)
    other = sample_poses(make_motion_source(config, np.random.default_rng(6)), times)
    np.testing.assert_array_equal(first, again)
    assert np.abs(first - other).max() > 1e-3


def test_env_reset_seed_sets_the_deck_motion() -> None:
    def deck_heights(seed: int) -> np.ndarray:
        env = make(**{"simulation.drone_fixed": True})
        try:
            env.reset(seed=seed)
            return np.array(
                [step_n(env, [0, 0, 0, 0], 1)[1]["deck"]["position_w"][2] for _ in range(20)]
            )
        finally:
            env.close()

    np.testing.assert_array_equal(deck_heights(1), deck_heights(1))
    assert np.abs(deck_heights(1) - deck_heights(2)).max() > 1e-4


def test_rigid_fit_returns_the_model_to_measured_translation() -> None:
    model = tag_corners_in_tag_frame(0.3)
    rotation = matrix_from_euler_zyx(0.3, -0.2, 0.1)
    translation = np.array([0.12, -0.34, 1.9])
    fit = RigidFitter(model).fit((rotation @ model.T).T + translation)
    assert fit is not None
    np.testing.assert_allclose(fit.translation, translation, atol=1e-12)
    np.testing.assert_allclose(fit.rotation, rotation, atol=1e-12)


def _land(overrides: dict) -> dict:
    env = make(**{"motion.kind": "static", **overrides})
    try:
        env.reset(seed=0)
        _, info = step_n(env, [0.0, 0.0, -0.4, 0.0], 600)
    finally:
        env.close()
    return info


def test_a_drone_that_slides_off_during_the_settle_is_not_a_success(tmp_path) -> None:
    """The settle rule, in the environment: on a slippery deck (feet friction 0.2: a wet,
    oily deck below CAP 437's 0.65, which holds the drone at 20 degrees) tilted 20 degrees,
    thresholds relaxed so that only the settle can fail, the drone touches down, then slides
    off within the second after contact; on the level deck it stays."""
    import yaml

    from landing_env.physics.quadrotor_params import DEFAULT_PARAMS_PATH

    vehicle = yaml.safe_load(DEFAULT_PARAMS_PATH.read_text())
    vehicle["landing_gear"]["friction"] = 0.2
    vehicle["urdf"] = str(DEFAULT_PARAMS_PATH.parent / vehicle["urdf"])
    slippery = tmp_path / "slippery.yaml"
    slippery.write_text(yaml.safe_dump(vehicle))
    relaxed = {
        "touchdown.max_deck_tilt_deg": 60.0,
        "touchdown.max_relative_attitude_deg": 90.0,
        "vehicle": str(slippery),
    }
    tilted = _land({**relaxed, "motion.static.attitude_deg": [20.0, 0.0, 0.0]})
    assert tilted["outcome"] == "hard_landing"
    failed = tilted["touchdown"]["failed_checks"]
    # it left the deck during the settle (falling off the edge, its body may touch: tip-over);
    # every check of the touchdown itself passed
    assert "on_deck_after_settle" in failed
    assert not {"deck_tilt", "relative_normal_speed", "relative_attitude", "all_feet_on_deck"} & {
        c.split(" ")[0] for c in failed
    }
    assert tilted["touchdown"]["all_feet_touched"]
    level = _land(relaxed)
    assert level["outcome"] == "success"
    assert level["touchdown"]["on_deck_after_settle"]
