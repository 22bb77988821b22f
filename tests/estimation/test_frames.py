"""The frame conventions: camera mount, tag corners, Euler angles."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimation.frames import (
    R_BC,
    deck_pose_in_camera,
    euler_zyx_from_matrix,
    level_from_body,
    levelled_deck_pose,
    matrix_from_euler_zyx,
    tag_corners_in_tag_frame,
    tilt_deg,
    tof_positions_in_camera_frame,
)


def test_camera_mount_is_a_proper_rotation_looking_down() -> None:
    assert np.isclose(np.linalg.det(R_BC), 1.0)
    # the optical axis is the body's down axis, the image top the nose
    np.testing.assert_array_equal(R_BC[:, 2], [0.0, 0.0, -1.0])
    np.testing.assert_array_equal(R_BC[:, 1], [-1.0, 0.0, 0.0])


def test_level_drone_over_level_deck_sees_identity_and_depth() -> None:
    r_cd, t_cd = deck_pose_in_camera(
        np.array([0.0, 0.0, 2.03]), np.eye(3), np.zeros(3), np.eye(3), np.array([0, 0, -0.03])
    )
    np.testing.assert_allclose(r_cd, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(t_cd, [0.0, 0.0, 2.0], atol=1e-12)


def test_tof_layout_is_the_papers_square() -> None:
    positions = tof_positions_in_camera_frame()
    np.testing.assert_allclose(np.linalg.norm(positions, axis=1), 0.1)
    np.testing.assert_allclose(positions.sum(axis=0), 0.0, atol=1e-15)
    corners = tag_corners_in_tag_frame(0.3)
    np.testing.assert_allclose(np.abs(corners[:, :2]), 0.15)


@settings(max_examples=300, deadline=None)
@given(
    roll=st.floats(-3.1, 3.1),
    pitch=st.floats(-1.55, 1.55),
    yaw=st.floats(-3.1, 3.1),
)
def test_euler_closed_form_matches_scipy(roll: float, pitch: float, yaw: float) -> None:
    rotation = matrix_from_euler_zyx(roll, pitch, yaw)
    ours = euler_zyx_from_matrix(rotation)
    yaw_s, pitch_s, roll_s = Rotation.from_matrix(rotation).as_euler("ZYX")
    np.testing.assert_allclose(ours, [roll_s, pitch_s, yaw_s], atol=1e-9)
    np.testing.assert_allclose(matrix_from_euler_zyx(*ours), rotation, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    drone=st.tuples(*[st.floats(-0.26, 0.26)] * 2, st.floats(-3.1, 3.1)),
    deck=st.tuples(*[st.floats(-0.17, 0.17)] * 3),
    offset=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(0.3, 5.0)),
)
def test_levelled_deck_pose_is_what_a_level_camera_sees(
    drone: tuple[float, float, float],
    deck: tuple[float, float, float],
    offset: tuple[float, float, float],
) -> None:
    roll, pitch, yaw = drone
    r_wb = matrix_from_euler_zyx(roll, pitch, yaw)
    r_wp = matrix_from_euler_zyx(*deck)
    t_wb = np.array([offset[0], offset[1], offset[2]])
    # the camera at the body origin, so that tilting the drone only turns the camera
    tilted = deck_pose_in_camera(t_wb, r_wb, np.zeros(3), r_wp, np.zeros(3))
    level = deck_pose_in_camera(
        t_wb, matrix_from_euler_zyx(0, 0, yaw), np.zeros(3), r_wp, np.zeros(3)
    )

    def vector(pose: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        return np.concatenate([pose[1], euler_zyx_from_matrix(pose[0])])

    levelled = levelled_deck_pose(vector(tilted), level_from_body(r_wb))
    np.testing.assert_allclose(levelled, vector(level), atol=1e-9)
    # a level drone changes nothing
    np.testing.assert_allclose(
        levelled_deck_pose(vector(level), np.eye(3)), vector(level), atol=1e-12
    )


def test_camera_offsets_map_to_forward_and_left_of_a_level_drone() -> None:
    from estimation.frames import camera_to_heading_xy

    # the tag above the image centre (y_C < 0) lies ahead; to the image's right, to starboard
    np.testing.assert_allclose(camera_to_heading_xy(np.array([0.0, -0.2])), [0.2, 0.0])
    np.testing.assert_allclose(camera_to_heading_xy(np.array([0.3, 0.0])), [0.0, -0.3])
    stack = camera_to_heading_xy(np.array([[1.0, 2.0], [-1.0, 0.5]]))
    np.testing.assert_allclose(stack, [[-2.0, -1.0], [-0.5, 1.0]])
    # the same as rotating the full vector into the body frame
    v_c = np.array([0.4, -0.7, 2.0])
    np.testing.assert_allclose(camera_to_heading_xy(v_c[:2]), (R_BC @ v_c)[:2])


def test_tag_corners_go_round_from_bottom_left_at_half_the_size_in_the_tags_plane() -> None:
    corners = tag_corners_in_tag_frame(0.3)
    np.testing.assert_array_equal(
        corners,
        [[-0.15, 0.15, 0.0], [0.15, 0.15, 0.0], [0.15, -0.15, 0.0], [-0.15, -0.15, 0.0]],
    )


def test_the_tof_sensors_sit_round_the_camera_from_its_upper_left_at_their_arm() -> None:
    # sensor 1 up and left in the image (x_C < 0, y_C < 0), then right, down, left
    d = 0.1 / np.sqrt(2.0)
    np.testing.assert_allclose(
        tof_positions_in_camera_frame(),
        [[-d, -d, 0.0], [d, -d, 0.0], [d, d, 0.0], [-d, d, 0.0]],
        atol=1e-17,
    )
    along_x = tof_positions_in_camera_frame(0.2, 0.0)
    np.testing.assert_array_equal(along_x[:, 1:], 0.0)
    np.testing.assert_array_equal(along_x[:, 0], [-0.2, 0.2, 0.2, -0.2])


QUARTER = np.pi / 2


def test_a_quarter_turn_of_roll_pitch_or_yaw_is_the_textbook_matrix_and_reads_back() -> None:
    rx = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    ry = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
    rz = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    for angles, expected in (((QUARTER, 0, 0), rx), ((0, QUARTER, 0), ry), ((0, 0, QUARTER), rz)):
        rotation = matrix_from_euler_zyx(*angles)
        np.testing.assert_allclose(rotation, expected, atol=1e-15)
        if angles[1] == 0:
            np.testing.assert_allclose(euler_zyx_from_matrix(rotation), angles, atol=1e-15)
    # yaw is applied last: a yawed then pitched frame's x axis points along the yaw, tipped down
    r = matrix_from_euler_zyx(0.0, np.radians(30.0), QUARTER)
    np.testing.assert_allclose(r[:, 0], [0.0, np.cos(np.radians(30.0)), -0.5], atol=1e-15)


def test_at_gimbal_lock_the_roll_reads_0_and_the_yaw_takes_what_is_left() -> None:
    # pitch +90 degrees: only yaw - roll tells rotations apart; -90 degrees: yaw + roll
    for pitch, yaw in ((QUARTER, -0.2 - 0.3), (-QUARTER, -0.2 + 0.3)):
        rotation = matrix_from_euler_zyx(0.3, pitch, -0.2)
        roll_read, pitch_read, yaw_read = euler_zyx_from_matrix(rotation)
        assert roll_read == 0.0 and pitch_read == pitch
        assert abs(yaw_read - yaw) < 1e-9
        np.testing.assert_allclose(
            matrix_from_euler_zyx(roll_read, pitch_read, yaw_read), rotation, atol=1e-15
        )


def test_the_tilt_is_the_angle_of_the_z_axis_from_the_reference_whatever_the_yaw() -> None:
    assert tilt_deg(0.0, 0.0) == 0.0
    assert abs(tilt_deg(np.radians(3.0), 0.0) - 3.0) < 1e-12
    assert abs(tilt_deg(0.0, np.radians(-4.0)) - 4.0) < 1e-12
    assert abs(tilt_deg(np.pi, 0.0) - 180.0) < 1e-12
    np.testing.assert_allclose(
        tilt_deg(np.radians([3.0, 0.0, -30.0]), np.radians([4.0, 20.0, 40.0])),
        np.degrees(
            np.arccos(np.cos(np.radians([3.0, 0.0, -30.0])) * np.cos(np.radians([4.0, 20.0, 40.0])))
        ),
        atol=1e-12,
    )


@settings(max_examples=200, deadline=None)
@given(
    roll=st.floats(-3.1, 3.1),
    pitch=st.floats(-1.55, 1.55),
    yaw=st.floats(-3.1, 3.1),
)
def test_the_tilt_of_roll_and_pitch_is_their_frames_z_axis_from_the_reference_z(
    roll: float, pitch: float, yaw: float
) -> None:
    z_axis = matrix_from_euler_zyx(roll, pitch, yaw)[:, 2]
    expected = np.degrees(np.arccos(np.clip(z_axis[2], -1.0, 1.0)))
    assert abs(float(tilt_deg(roll, pitch)) - expected) < 1e-5
