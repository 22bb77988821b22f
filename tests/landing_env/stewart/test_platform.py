"""The Stewart platform in PyBullet: tracking, real contact with a resting box, legs, clamping."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from estimation.frames import matrix_from_euler_zyx
from landing_env.stewart.kinematics import StewartGeometry, angular_velocity_from_euler_rates
from landing_env.stewart.motion import (
    MotionConfig,
    MotionSource,
    StaticMotionConfig,
    make_motion_source,
)
from landing_env.stewart.platform import PlatformConfig, StewartPlatform

DT = 1.0 / 240.0
GRAVITY = 9.81
PLATE_THICKNESS = 0.03
BASE_POSITION = np.array([0.4, -0.3, 0.04])
BASE_YAW = 0.5
#: tracking tolerances of the brief
MAX_POSITION_ERROR_M = 1e-3
MAX_ANGLE_ERROR_RAD = math.radians(0.05)


@pytest.fixture
def client() -> Iterator[BulletClient]:
    c = BulletClient(connection_mode=pybullet.DIRECT)
    c.setGravity(0.0, 0.0, -GRAVITY)
    c.setTimeStep(DT)
    c.createMultiBody(0.0, c.createCollisionShape(pybullet.GEOM_PLANE))
    yield c
    c.disconnect()


def make_plate(c: BulletClient, mass: float = 10.0, maximal: bool = False) -> int:
    """A 1 m deck plate whose base frame is the centre of its top surface (the deck contract)."""
    shape = c.createCollisionShape(
        pybullet.GEOM_BOX,
        halfExtents=[0.5, 0.5, 0.5 * PLATE_THICKNESS],
        collisionFramePosition=[0.0, 0.0, -0.5 * PLATE_THICKNESS],
    )
    body = c.createMultiBody(
        baseMass=mass,
        baseCollisionShapeIndex=shape,
        basePosition=[0.0, 0.0, 1.0],
        useMaximalCoordinates=maximal,
    )
    c.changeDynamics(body, -1, lateralFriction=0.8)
    return body


def make_platform(
    c: BulletClient, motion: MotionSource, plate: int | None = None
) -> StewartPlatform:
    plate = make_plate(c) if plate is None else plate
    return StewartPlatform(c, StewartGeometry(), BASE_POSITION, plate, motion, base_yaw=BASE_YAW)


def run(
    c: BulletClient, platform: StewartPlatform, seconds: float, t0: float = 0.0
) -> tuple[np.ndarray, int]:
    """Step ``seconds`` of simulation; return per-step (measured - applied) pose errors."""
    errors = []
    clamped = 0
    steps = round(seconds / DT)
    for k in range(1, steps + 1):
        status = platform.step_to(t0 + k * DT)
        c.stepSimulation()
        clamped += status.clamped
        errors.append(platform.measured_pose() - status.applied_pose)
        if k % 8 == 0:
            platform.update_leg_visuals()
    return np.array(errors), clamped


def sinusoids(seed: int = 0) -> MotionSource:
    return make_motion_source(MotionConfig(), np.random.default_rng(seed))


def test_home_pose_and_reset(client: BulletClient) -> None:
    motion = sinusoids()
    platform = make_platform(client, motion)
    home_position, home_rotation = platform.home_pose_w()
    np.testing.assert_allclose(home_position, BASE_POSITION + np.array([0.0, 0.0, 0.55]))
    np.testing.assert_allclose(home_rotation, matrix_from_euler_zyx(0.0, 0.0, BASE_YAW))
    status = platform.reset(2.0)
    assert not status.clamped
    np.testing.assert_allclose(platform.measured_pose(), motion.pose(2.0), atol=1e-7)
    position, rotation = platform.top_plate_pose_w()
    expected_position, expected_rotation = platform.pose_to_world(motion.pose(2.0))
    np.testing.assert_allclose(position, expected_position, atol=1e-7)
    np.testing.assert_allclose(rotation, expected_rotation, atol=1e-7)
    # the plate starts with the motion's velocity, in the world frame
    linear, angular = platform.top_plate_velocity_w()
    rates = motion.velocity(2.0)
    np.testing.assert_allclose(linear, platform.rotation_wb @ rates[:3], atol=1e-9)
    expected_angular = platform.rotation_wb @ angular_velocity_from_euler_rates(
        motion.pose(2.0)[3:], rates[3:]
    )
    np.testing.assert_allclose(angular, expected_angular, atol=1e-9)


def test_unloaded_plate_tracks_exactly(client: BulletClient) -> None:
    platform = make_platform(client, sinusoids(1))
    platform.reset(0.0)
    errors, clamped = run(client, platform, 5.0)
    assert clamped == 0
    assert np.max(np.abs(errors[:, :3])) < 1e-6
    assert np.max(np.abs(errors[:, 3:])) < 1e-6


def test_plate_carries_a_resting_box_and_keeps_its_path(client: BulletClient) -> None:
    platform = make_platform(client, sinusoids(2))
    platform.reset(0.0)
    position, rotation = platform.top_plate_pose_w()
    half = 0.05
    box_shape = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[0.1, 0.1, half])
    start_p = np.array([0.1, -0.05, half])
    box = client.createMultiBody(
        baseMass=1.0,
        baseCollisionShapeIndex=box_shape,
        basePosition=(position + rotation @ start_p).tolist(),
        baseOrientation=Rotation.from_matrix(rotation).as_quat().tolist(),
    )
    client.changeDynamics(box, -1, lateralFriction=0.8)
    box_in_plate, box_in_world, plate_in_world = [], [], []
    errors = []
    for k in range(1, round(10.0 / DT) + 1):
        status = platform.step_to(k * DT)
        client.stepSimulation()
        errors.append(platform.measured_pose() - status.applied_pose)
        plate_position, plate_rotation = platform.top_plate_pose_w()
        box_position = np.array(client.getBasePositionAndOrientation(box)[0])
        box_in_plate.append(plate_rotation.T @ (box_position - plate_position))
        box_in_world.append(box_position)
        plate_in_world.append(plate_position)
    errors = np.array(errors)
    box_in_plate = np.array(box_in_plate)
    # the plate is not pushed off its path
    assert np.max(np.abs(errors[:, :3])) < MAX_POSITION_ERROR_M
    assert np.max(np.abs(errors[:, 3:])) < MAX_ANGLE_ERROR_RAD
    # the box stays on the plate: resting on its surface, hardly sliding
    np.testing.assert_allclose(box_in_plate[:, 2], half, atol=2e-3)
    assert np.max(np.linalg.norm(box_in_plate[:, :2] - start_p[:2], axis=1)) < 0.02
    # and it moves with the plate through the world
    box_motion = np.ptp(np.array(box_in_world), axis=0)
    plate_motion = np.ptp(np.array(plate_in_world), axis=0)
    assert plate_motion.max() > 0.05
    np.testing.assert_allclose(box_motion, plate_motion, atol=0.02)


def test_sea_state_tracking_of_a_maximal_coordinate_plate(client: BulletClient) -> None:
    plate = make_plate(client, mass=15.0, maximal=True)
    motion = make_motion_source(MotionConfig(kind="sea_state"), np.random.default_rng(4))
    platform = make_platform(client, motion, plate)
    platform.reset(0.0)
    errors, _ = run(client, platform, 10.0)
    assert np.max(np.abs(errors[:, :3])) < 1e-6
    assert np.max(np.abs(errors[:, 3:])) < 1e-6


def test_out_of_reach_command_is_clamped_and_reported(client: BulletClient) -> None:
    static = StaticMotionConfig(position_m=(0.0, 0.0, 0.3), attitude_deg=(0.0, 0.0, 0.0))
    motion = make_motion_source(MotionConfig(kind="static", static=static), np.random.default_rng())
    platform = make_platform(client, motion)
    status = platform.reset(0.0)
    assert status.clamped and status.violated_legs == (0, 1, 2, 3, 4, 5)
    np.testing.assert_allclose(status.commanded_pose[2], 0.3)
    assert 0.1 < status.applied_pose[2] < 0.3
    np.testing.assert_allclose(status.stroke_usage, 1.0, atol=1e-4)
    assert status.max_stroke_usage > 0.999
    errors, clamped = run(client, platform, 0.5)
    assert clamped == round(0.5 / DT)
    assert np.max(np.abs(errors)) < 1e-6
    np.testing.assert_allclose(platform.measured_pose(), status.applied_pose, atol=1e-6)


def test_legs_follow_the_plate_and_are_invisible_to_rays(client: BulletClient) -> None:
    platform = make_platform(client, sinusoids(3))
    platform.reset(0.0)
    run(client, platform, 1.0)
    platform.update_leg_visuals()
    base, top = platform.leg_anchor_points_w()
    legs = top - base
    np.testing.assert_allclose(
        np.linalg.norm(legs, axis=1), platform.last_status.leg_lengths, atol=1e-6
    )
    for i in range(6):
        unit = legs[i] / np.linalg.norm(legs[i])
        cyl_pos, cyl_q = client.getBasePositionAndOrientation(platform.cylinder_body_ids[i])
        rod_pos, _ = client.getBasePositionAndOrientation(platform.rod_body_ids[i])
        axis = np.array(client.getMatrixFromQuaternion(cyl_q)).reshape(3, 3)[:, 2]
        np.testing.assert_allclose(axis, unit, atol=1e-9)
        # cylinder starts at the base joint, rod ends at the top joint, and they overlap
        cylinder_start = np.array(cyl_pos) - 0.5 * platform._cylinder_length * unit
        rod_end = np.array(rod_pos) + 0.5 * platform._rod_length * unit
        np.testing.assert_allclose(cylinder_start, base[i], atol=1e-9)
        np.testing.assert_allclose(rod_end, top[i], atol=1e-6)
        assert platform._cylinder_length + platform._rod_length > np.linalg.norm(legs[i])
        # a ray straight through the middle of the leg hits nothing
        middle = 0.5 * (base[i] + top[i])
        across = np.cross(unit, [0.0, 0.0, 1.0])
        across /= np.linalg.norm(across)
        hit = client.rayTest((middle - 0.2 * across).tolist(), (middle + 0.2 * across).tolist())
        assert hit[0][0] == -1
        for body in (platform.cylinder_body_ids[i], platform.rod_body_ids[i]):
            assert client.getClosestPoints(body, platform.top_plate_body_id, 1.0) == ()


def test_leg_visual_lengths_cover_the_stroke() -> None:
    geometry = StewartGeometry()
    c = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        platform = StewartPlatform(c, geometry, np.zeros(3), make_plate(c), sinusoids())
        assert platform._cylinder_length <= geometry.min_leg_length
        assert platform._rod_length <= geometry.min_leg_length
        assert platform._cylinder_length + platform._rod_length >= geometry.max_leg_length
    finally:
        c.disconnect()


def test_base_plate_is_a_static_collision_body(client: BulletClient) -> None:
    platform = make_platform(client, sinusoids())
    platform.reset(0.0)
    # straight down just outside the top plate's footprint but over the base plate
    corner = BASE_POSITION + platform.rotation_wb @ np.array([0.56, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])
    hit = client.rayTest((corner + up).tolist(), (corner - 0.5 * up).tolist())[0]
    assert hit[0] == platform.base_body_id
    np.testing.assert_allclose(hit[3][2], BASE_POSITION[2], atol=1e-6)
    assert client.getDynamicsInfo(platform.base_body_id, -1)[0] == 0.0
    config = PlatformConfig()
    assert math.isclose(BASE_POSITION[2], config.base_plate_thickness)


def test_advance_on_the_world_clock_matches_step_to(client: BulletClient) -> None:
    """advance() on a cumulative clock (motion evaluated ahead in batches) commands the same
    poses, clamps and plate motion as step_to() on t0 + k dt (one evaluation per step)."""
    other = BulletClient(connection_mode=pybullet.DIRECT)
    other.setGravity(0.0, 0.0, -GRAVITY)
    other.setTimeStep(DT)
    try:
        platforms = []
        for c in (client, other):
            # sea state 4 with gamma 3.3, seed 5 leaves the workspace from t = 3.6 s: clamping
            # is exercised
            config = MotionConfig(kind="sea_state", sea_state={"gamma": 3.3})  # type: ignore[arg-type]
            motion = make_motion_source(config, np.random.default_rng(5))
            platform = make_platform(c, motion)
            platform.reset(3.0)
            platforms.append(platform)
        batched, single = platforms
        clock = 3.0
        clamped = 0
        for k in range(1, 241):
            was_clamped = batched.advance(clock + DT)
            clock += DT
            status = single.step_to(3.0 + k * DT)
            client.stepSimulation()
            other.stepSimulation()
            reference = batched.last_status
            assert reference is not None
            assert was_clamped == reference.clamped == status.clamped
            assert reference.violated_legs == status.violated_legs
            np.testing.assert_allclose(reference.t, status.t, atol=1e-12)
            np.testing.assert_allclose(reference.applied_pose, status.applied_pose, atol=1e-12)
            np.testing.assert_allclose(reference.leg_lengths, status.leg_lengths, atol=1e-12)
            clamped += was_clamped
        assert clamped > 0
        np.testing.assert_allclose(batched.measured_pose(), single.measured_pose(), atol=1e-9)
    finally:
        other.disconnect()
