"""Stewart-platform geometry, inverse/forward kinematics and workspace clamping."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimation.frames import matrix_from_euler_zyx
from landing_env.errors import ConfigError
from landing_env.stewart.kinematics import (
    ForwardKinematicsError,
    StewartGeometry,
    StewartKinematics,
    angular_velocity_from_euler_rates,
    rotation_matrix_zyx,
)

#: Required single-axis workspace: x, y, z (m), roll, pitch, yaw (rad).
REQUIRED = np.array([0.08, 0.08, 0.12, math.radians(12), math.radians(12), math.radians(10)])
#: A box that is partly outside the workspace, for random poses.
WIDE = np.array([0.12, 0.12, 0.18, 0.3, 0.3, 0.25])


@pytest.fixture(scope="module")
def kin() -> StewartKinematics:
    return StewartKinematics(StewartGeometry())


def random_poses(n: int, seed: int, scale: np.ndarray = WIDE) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 6)) * scale


def test_default_workspace_covers_each_axis_separately(kin: StewartKinematics) -> None:
    for axis in range(6):
        for fraction in np.linspace(-1.0, 1.0, 41):
            pose = np.zeros(6)
            pose[axis] = fraction * REQUIRED[axis]
            assert kin.is_reachable(pose), (axis, fraction)
    # and not absurdly more: a 0.3 m heave is out of reach
    assert not kin.is_reachable(np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0]))


def test_anchors_layout(kin: StewartKinematics) -> None:
    geometry = kin.geometry
    np.testing.assert_allclose(np.linalg.norm(kin.base_anchors[:, :2], axis=1), 0.5)
    np.testing.assert_allclose(np.linalg.norm(kin.top_anchors_p[:, :2], axis=1), 0.36)
    np.testing.assert_allclose(kin.top_anchors_p[:, 2], -geometry.top_anchor_depth)
    # pairs: two base joints 2 * 12 deg apart
    angle = np.arctan2(kin.base_anchors[:, 1], kin.base_anchors[:, 0])
    assert math.isclose(angle[1] - angle[0], math.radians(2 * geometry.base_half_angle_deg))
    # at home every leg has the same length, between the stroke limits
    assert np.ptp(kin.home_leg_lengths) < 1e-12
    assert geometry.min_leg_length < kin.home_leg_lengths[0] < geometry.max_leg_length


def test_rotation_matches_frames_helper() -> None:
    rng = np.random.default_rng(3)
    angles = rng.uniform(-1.5, 1.5, (20, 3))
    batch = rotation_matrix_zyx(angles[:, 0], angles[:, 1], angles[:, 2])
    for (roll, pitch, yaw), rotation in zip(angles, batch, strict=True):
        expected = matrix_from_euler_zyx(roll, pitch, yaw)
        np.testing.assert_allclose(rotation, expected, atol=1e-14)
        np.testing.assert_allclose(rotation_matrix_zyx(roll, pitch, yaw), expected, atol=1e-14)


def test_inverse_kinematics_batch_equals_single_and_leg_geometry(kin: StewartKinematics) -> None:
    poses = random_poses(50, 1)
    batch = kin.inverse_kinematics(poses)
    assert batch.shape == (50, 6)
    for pose, lengths in zip(poses, batch, strict=True):
        np.testing.assert_allclose(kin.inverse_kinematics(pose), lengths, atol=1e-14)
        # the top anchors are the plate's anchors moved by the pose, above the home frame
        rotation = matrix_from_euler_zyx(*pose[3:])
        home = np.array([0.0, 0.0, kin.geometry.home_height])
        expected_top = home + pose[:3] + kin.top_anchors_p @ rotation.T
        np.testing.assert_allclose(kin.top_anchors_base(pose), expected_top, atol=1e-14)
        legs = kin.leg_vectors(pose)
        np.testing.assert_allclose(np.linalg.norm(legs, axis=1), lengths, atol=1e-14)


def test_forward_kinematics_round_trip(kin: StewartKinematics) -> None:
    poses = random_poses(600, 2, REQUIRED)
    poses = poses[kin.is_reachable(poses)][:150]
    assert len(poses) == 150
    for pose in poses:
        recovered = kin.forward_kinematics(kin.inverse_kinematics(pose))
        np.testing.assert_allclose(recovered, pose, atol=1e-9, rtol=0.0)


def test_forward_kinematics_from_a_nearby_guess(kin: StewartKinematics) -> None:
    pose = np.array([0.05, -0.03, 0.1, 0.15, -0.1, 0.12])
    guess = pose + 0.01
    recovered = kin.forward_kinematics(kin.inverse_kinematics(pose), initial_guess=guess)
    np.testing.assert_allclose(recovered, pose, atol=1e-9)


def test_forward_kinematics_rejects_impossible_lengths(kin: StewartKinematics) -> None:
    # legs 0 and 1 start 0.21 m apart and end on top joints ~0.54 m apart: 0.01 m and 3 m
    # cannot both hold
    lengths = np.array([0.01, 3.0, 0.6, 0.6, 0.6, 0.6])
    with pytest.raises(ForwardKinematicsError, match="residual"):
        kin.forward_kinematics(lengths)


def test_jacobian_matches_finite_differences(kin: StewartKinematics) -> None:
    pose = np.array([0.02, -0.01, 0.05, 0.1, -0.07, 0.2])
    step = 1e-6
    numeric = np.empty((6, 6))
    for k in range(6):
        delta = np.zeros(6)
        delta[k] = step
        numeric[:, k] = (
            kin.inverse_kinematics(pose + delta) - kin.inverse_kinematics(pose - delta)
        ) / (2 * step)
    np.testing.assert_allclose(kin.jacobian(pose), numeric, atol=1e-8)


def test_surely_reachable_is_sufficient_and_usually_decides(kin: StewartKinematics) -> None:
    poses = random_poses(3000, 8, WIDE * 0.6)
    quaternions = Rotation.from_matrix(rotation_matrix_zyx(*poses[:, 3:].T)).as_quat()
    sure = np.array(
        [
            kin.surely_reachable(float(np.linalg.norm(pose[:3])), float(np.linalg.norm(q[:3])))
            for pose, q in zip(poses, quaternions, strict=True)
        ]
    )
    reachable = kin.is_reachable(poses)
    assert np.all(reachable[sure])  # never admits an unreachable pose
    assert sure.mean() > 0.2 and not reachable.all()  # ...yet decides many, near the edge too
    assert kin.surely_reachable(0.0, 0.0)
    # with a joint-angle limit it never decides
    limited = StewartKinematics(StewartGeometry(max_base_joint_angle_deg=80.0))
    assert not limited.surely_reachable(0.0, 0.0)


def test_reachable_commands_pass_unchanged(kin: StewartKinematics) -> None:
    poses = random_poses(300, 4)
    reachable = kin.is_reachable(poses)
    assert 0.1 < reachable.mean() < 0.9  # the sample really straddles the boundary
    for pose in poses[reachable][:60]:
        result = kin.clamp_to_workspace(pose)
        assert not result.clamped
        assert result.violated_legs == ()
        np.testing.assert_array_equal(result.pose, pose)
        np.testing.assert_allclose(result.leg_lengths, kin.inverse_kinematics(pose), atol=1e-14)


@settings(max_examples=150, deadline=None)
@given(
    direction=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
    magnitude=st.floats(0.0, 3.0),
)
def test_clamped_poses_are_on_the_boundary_and_within_stroke(
    direction: list[float], magnitude: float
) -> None:
    kin = StewartKinematics(StewartGeometry())
    geometry = kin.geometry
    command = np.asarray(direction) * WIDE * magnitude
    result = kin.clamp_to_workspace(command)
    assert kin.is_reachable(result.pose)
    assert np.all(result.leg_lengths >= geometry.min_leg_length)
    assert np.all(result.leg_lengths <= geometry.max_leg_length)
    np.testing.assert_allclose(result.leg_lengths, kin.inverse_kinematics(result.pose))
    if kin.is_reachable(command):
        assert not result.clamped
        np.testing.assert_array_equal(result.pose, command)
        return
    assert result.clamped
    violated = np.flatnonzero(
        (kin.inverse_kinematics(command) < geometry.min_leg_length)
        | (kin.inverse_kinematics(command) > geometry.max_leg_length)
    )
    assert result.violated_legs == tuple(violated)
    # on the straight line from home, short of the command and just inside the boundary
    s = float(np.dot(result.pose, command) / np.dot(command, command))
    assert 0.0 <= s < 1.0
    np.testing.assert_allclose(result.pose, s * command, atol=1e-12)
    assert not kin.is_reachable((s + 1e-5) * command)


def test_joint_angle_limits() -> None:
    free = StewartKinematics(StewartGeometry())
    base_home, top_home = free.joint_angles(np.zeros(6))
    # the home angles are equal for all legs; a limit just above them accepts home
    limit = float(base_home[0]) + math.radians(3)
    limited = StewartKinematics(StewartGeometry(max_base_joint_angle_deg=math.degrees(limit)))
    assert limited.is_reachable(np.zeros(6))
    tilted = np.array([0.07, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert free.is_reachable(tilted)
    base_tilted, _ = free.joint_angles(tilted)
    assert base_tilted.max() > limit
    assert not limited.is_reachable(tilted)
    result = limited.clamp_to_workspace(tilted)
    assert result.clamped and limited.is_reachable(result.pose)
    with pytest.raises(ConfigError, match="max_top_joint_angle_deg"):
        StewartGeometry(max_top_joint_angle_deg=math.degrees(float(top_home[0])) - 0.5)


def test_angular_velocity_from_euler_rates() -> None:
    attitude = np.array([0.2, -0.3, 0.7])
    rates = np.array([0.5, -0.2, 0.9])
    h = 1e-6
    r_plus = matrix_from_euler_zyx(*(attitude + h * rates))
    r_minus = matrix_from_euler_zyx(*(attitude - h * rates))
    skew = (r_plus - r_minus) / (2 * h) @ matrix_from_euler_zyx(*attitude).T
    numeric = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
    np.testing.assert_allclose(
        angular_velocity_from_euler_rates(attitude, rates), numeric, atol=1e-8
    )


def test_stroke_usage(kin: StewartKinematics) -> None:
    geometry = kin.geometry
    usage = kin.stroke_usage(np.array([geometry.min_leg_length, geometry.max_leg_length]))
    np.testing.assert_allclose(usage, [0.0, 1.0])


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"base_radius": -1.0}, "base_radius"),
        ({"min_leg_length": 0.6, "max_leg_length": 0.5}, "max_leg_length"),
        ({"home_height": 0.3}, "home_height"),
        ({"base_half_angle_deg": 70.0}, "base_half_angle_deg"),
        ({"max_base_joint_angle_deg": 10.0}, "max_base_joint_angle_deg"),
    ],
)
def test_geometry_validation_names_the_field(kwargs: dict, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        StewartGeometry(**kwargs)
    assert info.value.key == key
