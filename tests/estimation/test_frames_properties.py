"""Properties of the frame conventions (:mod:`estimation.frames`) and the quaternions the io
layer writes (MAVLink's ``(w, x, y, z)``, ROS's ``(x, y, z, w)``), for any rotation and offset:
round trips, composition, and lengths kept."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from agents.io.landing_target import quaternion_wxyz
from agents.io.messages import pose, quaternion_xyzw, rotation_of, transform
from estimation.frames import (
    R_BC,
    R_PD,
    deck_pose_in_camera,
    euler_zyx_from_matrix,
    euler_zyx_from_rows,
    matrix_from_euler_zyx,
    matrix_from_rotvec,
)


def make_transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = rotation, translation
    return transform


PROPERTY = settings(max_examples=150, deadline=None)

components = st.floats(-1.0, 1.0, allow_nan=False)
metres = st.floats(-50.0, 50.0, allow_nan=False)


@st.composite
def rotations(draw: st.DrawFn) -> np.ndarray:
    """Any rotation: a random unit quaternion (gimbal lock and half turns included)."""
    q = np.array([draw(components) for _ in range(4)])
    assume(np.linalg.norm(q) > 0.1)
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


vectors = st.tuples(metres, metres, metres).map(np.array)


class Quat:
    """A ``geometry_msgs/Quaternion`` stand-in."""

    def __init__(self, xyzw: np.ndarray) -> None:
        self.x, self.y, self.z, self.w = (float(v) for v in xyzw)


@PROPERTY
@given(rotation=rotations())
def test_euler_angles_of_any_rotation_rebuild_it(rotation: np.ndarray) -> None:
    roll, pitch, yaw = euler_zyx_from_matrix(rotation)
    assert -np.pi <= roll <= np.pi and -np.pi / 2 <= pitch <= np.pi / 2 and -np.pi <= yaw <= np.pi
    # within 1e-5 at gimbal lock (pitch +-90 deg), where roll is taken as 0
    np.testing.assert_allclose(matrix_from_euler_zyx(roll, pitch, yaw), rotation, atol=1e-5)


@PROPERTY
@given(
    angles=st.tuples(
        *[st.floats(-1e3, 1e3) | st.sampled_from([0.0, -0.0, np.pi, -np.pi / 2, 1e-300])] * 3
    )
)
def test_the_written_out_zyx_matrix_is_scipy_s_bit_for_bit(
    angles: tuple[float, float, float],
) -> None:
    roll, pitch, yaw = angles
    expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    assert matrix_from_euler_zyx(roll, pitch, yaw).tobytes() == expected.tobytes()


@PROPERTY
@given(rotvec=st.tuples(*[st.floats(-20.0, 20.0) | st.sampled_from([0.0, -0.0, 1e-4, 1e-300])] * 3))
def test_the_written_out_rotation_vector_matrix_is_scipy_s_bit_for_bit(
    rotvec: tuple[float, float, float],
) -> None:
    expected = Rotation.from_rotvec(rotvec).as_matrix()
    assert matrix_from_rotvec(np.array(rotvec)).tobytes() == expected.tobytes()


def _euler_of_indexed_entries(r: np.ndarray) -> np.ndarray:
    """The closed form as it read each entry of the array (``float(r[i, j])``)."""
    sin_pitch = -float(r[2, 0])
    if abs(sin_pitch) >= 1.0 - 1e-12:
        pitch = math.copysign(math.pi / 2.0, sin_pitch)
        return np.array([0.0, pitch, math.atan2(-float(r[0, 1]), float(r[1, 1]))])
    return np.array(
        [
            math.atan2(float(r[2, 1]), float(r[2, 2])),
            math.asin(sin_pitch),
            math.atan2(float(r[1, 0]), float(r[0, 0])),
        ]
    )


@PROPERTY
@given(
    st.one_of(
        rotations(),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=9, max_size=9).map(
            lambda v: np.array(v).reshape(3, 3)
        ),
        st.sampled_from(
            [
                matrix_from_euler_zyx(0.3, np.pi / 2, -0.2),
                matrix_from_euler_zyx(-0.1, -np.pi / 2, 1.0),
            ]
        ),
    )
)
def test_euler_angles_from_a_matrix_s_rows_are_the_matrix_s_bit_for_bit(
    rotation: np.ndarray,
) -> None:
    rows = euler_zyx_from_rows(tuple(rotation.ravel().tolist()))
    expected = _euler_of_indexed_entries(rotation)
    assert np.array(rows).tobytes() == expected.tobytes()
    assert euler_zyx_from_matrix(rotation).tobytes() == expected.tobytes()
    assert euler_zyx_from_matrix(rotation.astype(np.float32)).tobytes() == (
        _euler_of_indexed_entries(rotation.astype(np.float32)).tobytes()
    )


def test_non_finite_angles_give_scipy_s_matrix() -> None:
    for angles in ((np.nan, 0.0, 0.0), (0.0, np.inf, 0.0), (0.0, 0.0, -np.inf)):
        expected = Rotation.from_euler("ZYX", angles[::-1]).as_matrix()
        np.testing.assert_array_equal(matrix_from_euler_zyx(*angles), expected)
    for rotvec in ((np.nan, 0.0, 0.0), (0.0, np.inf, 1.0)):
        expected = Rotation.from_rotvec(rotvec).as_matrix()
        np.testing.assert_array_equal(matrix_from_rotvec(np.array(rotvec)), expected)


@PROPERTY
@given(angles=st.tuples(*[st.floats(-3.1, 3.1)] * 3))
def test_zyx_euler_is_yaw_then_pitch_then_roll(angles: tuple[float, float, float]) -> None:
    roll, pitch, yaw = angles
    rotation = matrix_from_euler_zyx(roll, pitch, yaw)
    about = {
        axis: Rotation.from_euler(axis, a).as_matrix()
        for axis, a in zip("xyz", angles, strict=True)
    }
    np.testing.assert_allclose(rotation, about["z"] @ about["y"] @ about["x"], atol=1e-12)
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) > 0.0


@PROPERTY
@given(
    r_wb=rotations(),
    r_wp=rotations(),
    t_wb=vectors,
    t_wp=vectors,
    t_bc=st.tuples(*[st.floats(-0.5, 0.5)] * 3).map(np.array),
    offset=st.tuples(*[st.floats(-2.0, 2.0)] * 3).map(np.array),
)
def test_the_deck_pose_in_the_camera_is_the_composed_transforms(
    r_wb: np.ndarray,
    r_wp: np.ndarray,
    t_wb: np.ndarray,
    t_wp: np.ndarray,
    t_bc: np.ndarray,
    offset: np.ndarray,
) -> None:
    r_cd, t_cd = deck_pose_in_camera(t_wb, r_wb, t_wp, r_wp, t_bc, offset)
    # T_CD = (T_WB T_BC)^-1 T_WP T_PD, the tag T_PD at the offset on the plate
    t_wc = make_transform(r_wb, t_wb) @ make_transform(R_BC, t_bc)
    t_wd = make_transform(r_wp, t_wp) @ make_transform(R_PD, offset)
    expected = np.linalg.inv(t_wc) @ t_wd
    np.testing.assert_allclose(r_cd, expected[:3, :3], atol=1e-9)
    np.testing.assert_allclose(t_cd, expected[:3, 3], atol=1e-9)
    # the tag is as far from the camera in C as in the world
    camera_w = t_wb + r_wb @ t_bc
    tag_w = t_wp + r_wp @ offset
    assert abs(np.linalg.norm(t_cd) - np.linalg.norm(tag_w - camera_w)) < 1e-9


@PROPERTY
@given(rotation=rotations())
def test_mavlinks_quaternion_is_unit_scalar_first_non_negative_and_the_rotation(
    rotation: np.ndarray,
) -> None:
    w, x, y, z = quaternion_wxyz(rotation)
    assert abs(np.linalg.norm([w, x, y, z]) - 1.0) < 1e-12 and w >= 0.0
    np.testing.assert_allclose(Rotation.from_quat([x, y, z, w]).as_matrix(), rotation, atol=1e-9)


@PROPERTY
@given(rotation=rotations())
def test_a_ros_quaternion_round_trips_the_rotation(rotation: np.ndarray) -> None:
    q = quaternion_xyzw(rotation)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    np.testing.assert_allclose(rotation_of(Quat(q)), rotation, atol=1e-9)


@PROPERTY
@given(rotation=rotations(), translation=vectors)
def test_a_ros_pose_or_transform_holds_the_rotation_and_translation_it_was_made_of(
    rotation: np.ndarray, translation: np.ndarray
) -> None:
    made = pose(rotation, translation)
    p, q = made.position, made.orientation
    assert [p.x, p.y, p.z] == translation.tolist()
    np.testing.assert_allclose(rotation_of(q), rotation, atol=1e-9)
    assert [q.x, q.y, q.z, q.w] == quaternion_xyzw(rotation).tolist()
    stamped = transform(1.5, "world", "body", rotation, translation)
    t, q = stamped.transform.translation, stamped.transform.rotation
    assert (stamped.header.frame_id, stamped.child_frame_id) == ("world", "body")
    assert [t.x, t.y, t.z] == translation.tolist()
    assert [q.x, q.y, q.z, q.w] == quaternion_xyzw(rotation).tolist()


@PROPERTY
@given(direction=st.tuples(*[st.floats(-1.0, 1.0)] * 3).map(np.array))
def test_a_rotation_vector_of_exactly_1_mrad_is_scipy_s_series_bit_for_bit(
    direction: np.ndarray,
) -> None:
    assume(np.linalg.norm(direction) > 0.1)
    rotvec = direction / np.linalg.norm(direction) * 1e-3
    x, y, z = rotvec.tolist()
    assume(math.sqrt(x * x + y * y + z * z) == 1e-3)
    expected = Rotation.from_rotvec(rotvec).as_matrix()
    assert matrix_from_rotvec(rotvec).tobytes() == expected.tobytes()


def test_a_rotation_vector_as_a_row_or_a_column_is_the_same_rotation() -> None:
    rotvec = np.array([0.3, -0.2, 0.9])
    expected = matrix_from_rotvec(rotvec)
    for shaped in (rotvec.reshape(1, 3), rotvec.reshape(3, 1), rotvec.tolist()):
        assert matrix_from_rotvec(shaped).tobytes() == expected.tobytes()


def test_a_quarter_turn_about_each_axis_has_the_known_quaternion_components() -> None:
    half = math.sqrt(0.5)
    for axis, angles in enumerate(((np.pi / 2, 0, 0), (0, np.pi / 2, 0), (0, 0, np.pi / 2))):
        rotation = matrix_from_euler_zyx(*angles)
        vector = [0.0, 0.0, 0.0]
        vector[axis] = half
        np.testing.assert_allclose(quaternion_xyzw(rotation), [*vector, half], atol=1e-15)
        np.testing.assert_allclose(quaternion_wxyz(rotation), [half, *vector], atol=1e-15)
    # a half turn about z: MAVLink's scalar kept non-negative, the axis +z or -z
    w, x, y, z = quaternion_wxyz(matrix_from_euler_zyx(0.0, 0.0, np.pi))
    assert w >= 0.0 and abs(w) < 1e-15 and (x, y) == (0.0, 0.0) and abs(abs(z) - 1.0) < 1e-15


# sines of +-0, of a subnormal product and of either sign, cosines of either sign
SIGN_CLASSES = (0.0, -0.0, 1e-300, -1e-300, 0.5, -0.5, 7.0, -7.0)


def test_the_zyx_matrix_is_scipy_s_bit_for_bit_for_every_sign_of_zero_and_half_angle() -> None:
    for roll in SIGN_CLASSES:
        for pitch in SIGN_CLASSES:
            for yaw in SIGN_CLASSES:
                expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
                assert matrix_from_euler_zyx(roll, pitch, yaw).tobytes() == expected.tobytes(), (
                    roll,
                    pitch,
                    yaw,
                )


# rotation vectors under 1 mrad where the series' last term, a**4 / 3840, decides the last bit
# of the scale (found by searching random vectors of 0.5 to 1 mrad)
LAST_BIT = (
    (-0.00046896648658768754, 0.0005480245089507467, -0.000677612138592011),
    (-0.00043270253543833075, 9.436413401531098e-05, 0.0006077545688490091),
    (-0.0003097890255945509, 0.0007893963297708753, 0.0003803217993245758),
)


def test_below_1_mrad_the_rotation_vectors_series_has_scipy_s_terms_to_the_last_bit() -> None:
    for rotvec in LAST_BIT:
        expected = Rotation.from_rotvec(rotvec).as_matrix()
        assert matrix_from_rotvec(np.array(rotvec)).tobytes() == expected.tobytes(), rotvec
