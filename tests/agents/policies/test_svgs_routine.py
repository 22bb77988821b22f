"""The SVGS routine, the beacon-range baseline, the beacon estimator, the rangefinder and the
approach evaluation."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
from pybullet_utils.bullet_client import BulletClient

from agents.policies.beacon_range import BeaconRangeConfig, BeaconRangePolicy, PrecLandState
from agents.policies.svgs_routine import (
    AttitudeFilter,
    RoutineConfig,
    RoutineState,
    SvgsRoutinePolicy,
    lawnmower_square,
    levelled_offset,
)
from estimation.beacon import (
    BeaconEstimator,
    beacon_position,
    bearing_from_pixel,
    tag_centre_pixel,
)
from estimation.camera_model import CameraIntrinsics
from estimation.frames import R_BC, matrix_from_euler_zyx, tag_corners_in_tag_frame
from estimation.geometry import Undistorter
from estimation.types import CameraFrame, RangeReading, TagDetection
from landing_env.errors import ConfigError
from landing_env.sensors.rangefinder import Rangefinder, RangefinderConfig

HOVER_IMU = np.array([0.0, 0.0, 9.81, 0.0, 0.0, 0.0], dtype=np.float32)


def observation(
    pose: tuple[float, ...] | None, tof: float | None = None, range_down: float | None = None
) -> dict[str, np.ndarray]:
    """A DeckLanding-v2 observation with the given deck pose (None: invalid)."""
    valid = pose is not None
    return {
        "deck_pose": np.array(pose if valid else [0.0] * 6, dtype=np.float32),
        "deck_pose_valid": np.array([int(valid)], dtype=np.int8),
        "deck_pose_predicted": np.zeros(1, dtype=np.int8),
        "tof_range": np.full(4, tof or 0.0, dtype=np.float32),
        "tof_valid": np.full(4, int(tof is not None), dtype=np.int8),
        "imu": HOVER_IMU.copy(),
        "range_down": np.array([range_down or 0.0], dtype=np.float32),
        "range_down_valid": np.array([int(range_down is not None)], dtype=np.int8),
    }


# ------------------------------------------------------------------------------ search pattern
def test_lawnmower_square_covers_its_square_in_lanes() -> None:
    points = np.array(lawnmower_square((1.0, -2.0), 6.0, 2.0))
    assert points[:, 0].min() == pytest.approx(-2.0) and points[:, 0].max() == pytest.approx(4.0)
    assert points[:, 1].min() == pytest.approx(-5.0) and points[:, 1].max() == pytest.approx(1.0)
    lanes = np.unique(np.round(points[:, 0], 9))
    assert len(lanes) == 4 and np.allclose(np.diff(lanes), 2.0)
    # boustrophedon: consecutive lanes are swept in opposite directions
    assert points[1, 1] > points[0, 1] and points[3, 1] < points[2, 1]


def test_each_scan_square_is_wider_by_the_growth_about_the_same_centre() -> None:
    config = RoutineConfig(scan_first_side_m=4.0, scan_growth_m=3.0, scan_lane_spacing_m=1.5)
    policy = SvgsRoutinePolicy(config=config, timing_model=None)
    policy._scan_centre = (0.5, 0.5)
    squares = []
    for k in range(4):
        policy._scan_square = k
        policy._load_square()
        squares.append(np.array(policy._scan))
    assert [np.ptp(sq, axis=0)[0] for sq in squares] == pytest.approx([4.0, 7.0, 10.0, 13.0])
    assert all(np.allclose((sq.min(0) + sq.max(0)) / 2, 0.5) for sq in squares)


def test_routine_scans_outwards_until_the_landmark_is_found() -> None:
    policy = SvgsRoutinePolicy(config=RoutineConfig(lock_frames=2), timing_model=None)
    positions = []
    for _ in range(400):
        policy(observation(None, range_down=15.0))
        positions.append(policy.odometry.position.copy())
    assert policy.state is RoutineState.SCAN
    reach = np.abs(np.array(positions)[:, :2]).max(axis=0)
    assert reach.max() > 2.5  # it flies the pattern, not in place
    policy(observation((0.5, 0.5, 15.0, 0.0, 0.0, 0.0), range_down=15.0))
    assert policy.state is RoutineState.SCAN  # one frame is no lock yet
    policy(observation((0.5, 0.5, 15.0, 0.0, 0.0, 0.0), range_down=15.0))
    assert policy.state is RoutineState.ALIGN


# ------------------------------------------------------------------------------ relocation
def test_lost_sight_triggers_relocation_to_the_trusted_pose_xy_first_then_xyz() -> None:
    config = RoutineConfig(lost_sight_s=0.5, relocate_leg_s=4.0)
    policy = SvgsRoutinePolicy(config=config, dt=0.05, timing_model=None)
    seen = (0.0, 0.0, 10.0, 0.0, 0.0, 0.0)
    for _ in range(40):  # aligned over the landmark: align, then descend
        policy(observation(seen, range_down=10.0))
    assert policy.state is RoutineState.DESCEND
    trusted = policy.trusted_position.copy()
    # sight lost while the drone drifts: it flies on blind for a while (dead-reckoned)
    for _ in range(9):
        policy(observation(None, range_down=9.0))
    assert policy.state is RoutineState.DESCEND
    policy.odometry.position += np.array([3.0, -2.0, -1.0])  # pushed away by a gust
    for _ in range(3):
        action = policy(observation(None, range_down=9.0))
    assert policy.state is RoutineState.RELOCATE_XY
    assert policy.transitions[-1][1:] == ("relocate_xy", "sight lost")
    # back towards the trusted xy, holding the current height
    assert action[0] < -0.1 and action[1] > 0.1 and action[2] == pytest.approx(0.0)
    for _ in range(200):
        action = policy(observation(None, range_down=9.0))
        if policy.state is not RoutineState.RELOCATE_XY:
            break
    assert policy.state is RoutineState.RELOCATE_XYZ
    assert np.hypot(*(policy.odometry.position[:2] - trusted[:2])) < 0.5
    action = policy(observation(None, range_down=9.0))
    assert action[2] > 0.1  # then up to the trusted height
    for _ in range(200):
        policy(observation(None, range_down=9.0))
        if policy.state is not RoutineState.RELOCATE_XYZ:
            break
    assert policy.state is RoutineState.SCAN  # nothing there either: search again
    policy(observation(seen, range_down=10.0))
    policy(observation(seen, range_down=10.0))
    assert policy.state is RoutineState.ALIGN


def test_descent_pauses_when_misaligned() -> None:
    policy = SvgsRoutinePolicy(timing_model=None)
    for _ in range(40):
        policy(observation((0.0, 0.0, 10.0, 0.0, 0.0, 0.0)))
    assert policy.state is RoutineState.DESCEND
    action = policy(observation((3.0, 0.0, 10.0, 0.0, 0.0, 0.0)))  # 3 m to the right
    assert policy.state is RoutineState.ALIGN
    assert action[2] == pytest.approx(0.0) and action[1] < 0.0  # no descent; moves right


def test_routine_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="descent_min_speed"):
        RoutineConfig(descent_min_speed=2.0, descent_max_speed=1.0)
    with pytest.raises(ConfigError, match="scan_lane_spacing_m"):
        RoutineConfig(scan_lane_spacing_m=0.0)


@pytest.mark.parametrize(
    ("cls", "name", "refused", "accepted"),
    [
        (RoutineConfig, "scan_speed", 0.0, 1e-6),
        (RoutineConfig, "align_hold_s", -1e-6, 0.0),
        (RoutineConfig, "scan_squares", 51, 50),
        (RoutineConfig, "misaligned_factor", 0.999, 1.0),
        (RoutineConfig, "lock_frames", 0, 1),
        (BeaconRangeConfig, "acceptance_radius_m", 0.0, 1e-6),
        (BeaconRangeConfig, "search_timeout_s", -1e-6, 0.0),
        (BeaconRangeConfig, "max_searches", 101, 0),
        (BeaconRangeConfig, "attitude_gain", -0.2, 0.2),
    ],
)
def test_a_setting_outside_its_declared_limit_is_refused_naming_it(
    cls: type, name: str, refused: float, accepted: float
) -> None:
    with pytest.raises(ConfigError, match=rf"^{name}: {refused!r} is out of range"):
        cls(**{name: refused})
    assert getattr(cls(**{name: accepted}), name) == accepted


@pytest.mark.parametrize("cls", [RoutineConfig, BeaconRangeConfig])
def test_every_declared_limit_holds_at_its_bounds(cls: type) -> None:
    declared = [f for f in dataclasses.fields(cls) if "limit" in f.metadata]
    assert len(declared) >= 15
    for item in declared:
        limit = item.metadata["limit"]
        for bound, inclusive, step in (
            (limit.low, limit.low_inclusive, -1),
            (limit.high, limit.high_inclusive, 1),
        ):
            if bound is None:
                continue
            outside = bound if not inclusive else bound + step
            with pytest.raises(ConfigError, match=rf"^{item.name}: "):
                cls(**{item.name: outside})


# ------------------------------------------------------------------------------ attitude
def test_attitude_filter_levels_a_tilted_offset() -> None:
    tilt = math.radians(10.0)
    rotation = matrix_from_euler_zyx(tilt, 0.0, 0.0)  # rolled 10 degrees
    force_b = rotation.T @ np.array([0.0, 0.0, 9.81])
    attitude = AttitudeFilter(0.05, gain=0.6)
    for _ in range(400):
        attitude.update(np.concatenate([force_b, np.zeros(3)]))
    r_hb = attitude.level_from_body()
    assert np.allclose(r_hb, rotation, atol=1e-3)
    # a deck straight below (in W) seen by the rolled camera: levelled, it is straight below
    deck_b = rotation.T @ np.array([0.0, 0.0, -20.0])
    forward, left, height = levelled_offset(R_BC.T @ deck_b, r_hb)
    assert abs(forward) < 0.05 and abs(left) < 0.05 and height == pytest.approx(20.0, abs=0.01)


# ------------------------------------------------------------------------------ beacon
def test_tag_centre_pixel_is_the_projected_centre_under_perspective() -> None:
    camera = CameraIntrinsics()
    r_cd = matrix_from_euler_zyx(math.radians(25.0), math.radians(-15.0), 0.4)
    t_cd = np.array([0.6, -0.4, 3.0])
    corners = camera.project((r_cd @ tag_corners_in_tag_frame(0.5).T).T + t_cd)
    centre = camera.project(t_cd[None])[0]
    assert np.allclose(tag_centre_pixel(corners), centre, atol=1e-9)
    assert np.linalg.norm(corners.mean(axis=0) - centre) > 0.05  # the mean is not


@pytest.mark.parametrize("tilt_deg", [0.0, 8.0])
def test_beacon_position_recovers_a_synthetic_position(tilt_deg: float) -> None:
    camera = CameraIntrinsics(dist=(-0.05, 0.01, 0.0, 0.0, 0.0))
    undistort = Undistorter(camera)
    # the camera tilted by tilt_deg over level ground 12 m below; the beacon 3 m off
    r_level_c = matrix_from_euler_zyx(math.radians(tilt_deg), 0.0, 0.0)
    beacon_level = np.array([3.0, -2.0, 12.0])  # levelled frame, z down
    beacon_c = r_level_c.T @ beacon_level
    pixel = camera.project(beacon_c[None])[0]
    bearing = bearing_from_pixel(pixel, undistort, camera.matrix)
    assert np.allclose(bearing, beacon_c / np.linalg.norm(beacon_c), atol=1e-6)
    # the rangefinder along +z_C hits the ground at 12 / cos(tilt)
    axis_down = (r_level_c @ np.array([0.0, 0.0, 1.0]))[2]
    range_m = 12.0 / axis_down
    position = beacon_position(bearing, range_m, r_level_c)
    assert position is not None and np.allclose(position, beacon_c, atol=1e-6)
    if tilt_deg == 0.0:  # without the attitude: the plane normal to the optical axis
        assert np.allclose(beacon_position(bearing, range_m), beacon_c, atol=1e-6)
    assert beacon_position(bearing, math.nan) is None
    assert beacon_position(np.array([1.0, 0.0, -0.1]), 5.0) is None


def test_beacon_estimator_gives_position_only_from_a_detection_and_the_range() -> None:
    camera = CameraIntrinsics()
    t_cd = np.array([1.2, -0.7, 9.5])
    corners = camera.project(tag_corners_in_tag_frame(1.0) + t_cd)
    frame = CameraFrame(1.0, (TagDetection(3, corners),))
    reading = RangeReading(1.0, np.array([9.5]), np.array([True]))
    estimator = BeaconEstimator(camera, 3, lambda: reading)
    estimate = estimator.estimate(frame, RangeReading(1.0, np.full(4, np.nan), np.zeros(4, bool)))
    assert estimate.valid and estimate.method == "beacon"
    assert np.allclose(estimate.translation, t_cd, atol=1e-9)
    assert np.allclose(estimate.rotation, np.eye(3)) and not estimate.extras["orientation_known"]
    lost = RangeReading(1.0, np.array([np.nan]), np.array([False]))
    assert BeaconEstimator(camera, 3, lambda: lost).estimate(frame, reading).reason == (
        "range_invalid"
    )
    assert BeaconEstimator(camera, 4, lambda: reading).estimate(frame, reading).reason == (
        "no_detection"
    )


def test_beacon_range_searches_then_lands_in_place() -> None:
    policy = BeaconRangePolicy(dt=0.1)
    policy.config.search_timeout_s = 1.0
    policy.config.max_searches = 1
    for _ in range(30):
        policy(observation((0.05, 0.0, 10.0, 0.0, 0.0, 0.0), range_down=10.0))
    assert policy.state is PrecLandState.DESCEND_ABOVE_TARGET
    for _ in range(25):
        action = policy(observation(None, range_down=10.0))
    assert policy.state is PrecLandState.SEARCH and action[2] > 0.0  # climbs to search
    for _ in range(200):
        action = policy(observation(None, range_down=20.0))
        if policy.state is not PrecLandState.SEARCH:
            break
    assert policy.state is PrecLandState.FALLBACK and action[2] < 0.0


# ------------------------------------------------------------------------------ rangefinder
def test_rangefinder_is_nan_and_invalid_out_of_range() -> None:
    client = BulletClient(connection_mode=p.DIRECT)
    try:
        client.createMultiBody(0.0, client.createCollisionShape(p.GEOM_PLANE))
        config = RangefinderConfig(max_range=10.0, sigma_0=0.0, sigma_per_m=0.0, resolution=0.0)
        sensor = Rangefinder(client, config, np.random.default_rng(0))
        level = np.eye(3)
        near = sensor.measure(0.0, np.array([0.0, 0.0, 4.03]), level, exclude_body=-1)
        assert near.valid.tolist() == [True] and near.ranges[0] == pytest.approx(4.0)
        far = sensor.measure(0.0, np.array([0.0, 0.0, 12.0]), level, exclude_body=-1)
        assert far.valid.tolist() == [False] and np.isnan(far.ranges[0])
        noisy = Rangefinder(client, RangefinderConfig(), np.random.default_rng(1))
        values = [
            noisy.measure(0.0, np.array([0.0, 0.0, 20.03]), level, -1).ranges[0] for _ in range(200)
        ]
        assert np.mean(values) == pytest.approx(20.0, abs=0.01)
        assert 0.03 < np.std(values) < 0.06  # 2.5 cm + 0.1 %/m at 20 m
        assert np.allclose(np.round(np.array(values) / 0.01) * 0.01, values)
        off = Rangefinder(client, RangefinderConfig(enabled=False), np.random.default_rng(0))
        assert not off.measure(0.0, np.array([0.0, 0.0, 4.03]), level, -1).valid[0]
    finally:
        client.disconnect()
    with pytest.raises(ConfigError, match="min_range"):
        RangefinderConfig(min_range=50.0)


def test_env_observation_carries_the_downward_range() -> None:
    import gymnasium as gym

    import landing_env  # noqa: F401

    env = gym.make("DeckLanding-v2", overrides={"start.max_offset_m": 0.0})
    try:
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        assert obs["range_down_valid"][0] == 1
        height = info["drone"]["position_w"][2] - info["deck"]["position_w"][2] - 0.03
        assert obs["range_down"][0] == pytest.approx(height, abs=0.1)
    finally:
        env.close()


# ------------------------------------------------------------------------------ the approach
def test_seeded_high_approach_episodes_land(tmp_path: Path) -> None:
    """One seeded episode of each policy from 20 m, 5 m off, sea state 3 with gusts."""
    from agents.evaluation.approach import evaluate_approach
    from agents.policies.svgs_routine import RoutineState

    evaluation = evaluate_approach(
        ["svgs-routine", "beacon-range"],
        "high-approach",
        episodes=1,
        out_dir=tmp_path,
        first_seed=7,
        workers=1,
        progress=False,
    )
    routine = evaluation.results["svgs-routine"][0]
    assert routine.start_height_m == pytest.approx(20.0, abs=0.1)
    assert routine.start_offset_m == pytest.approx(5.0, abs=0.1)
    assert routine.outcome == "success", routine
    assert routine.lateral_offset_m < 0.3 and routine.final_state == RoutineState.LAND.value
    beacon = evaluation.results["beacon-range"][0]
    assert beacon.estimator == "beacon" and beacon.outcome in ("success", "hard_landing")
    assert all(path.is_file() for path in evaluation.files)
    table = (tmp_path / "approach_high-approach.md").read_text()
    assert "svgs-routine" in table and "beacon-range" in table


class _FakeTiming:
    """A stand-in for the trained timing model: commits at its third decision."""

    name = "timing-fake"

    def __init__(self) -> None:
        self.calls: list[np.ndarray] = []

    def act(self, flat: np.ndarray) -> int:
        self.calls.append(flat)
        return int(len(self.calls) >= 3)


def test_hold_lets_the_timing_model_choose_the_commit() -> None:
    model = _FakeTiming()
    policy = SvgsRoutinePolicy(dt=0.05, timing_model=model)  # type: ignore[arg-type]
    assert policy.timing_source == "timing-fake"
    hold = policy.config.timing.hold_height_m
    steps_in_hold = 0
    for _ in range(200):
        policy(observation((0.0, 0.0, hold, 0.0, 0.0, 0.0), tof=hold))
        if policy.state is RoutineState.HOLD:
            steps_in_hold += 1
        if policy.state is RoutineState.LAND:
            break
    assert policy.state is RoutineState.LAND and policy.reason == "committed by timing-fake"
    assert len(model.calls) == 3 and model.calls[0].shape == (policy.layout.size,)
    # a history's length at the hold height first, then a decision every steps_per_decision
    timing = policy.config.timing
    expected = round(timing.history_s / 0.05) + 2 * timing.steps_per_decision
    assert abs(steps_in_hold - expected) <= 1
    # the quiescent heuristic without a model
    assert SvgsRoutinePolicy(timing_model=None).timing_source == "quiescent"
