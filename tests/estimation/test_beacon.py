"""The beacon estimator: bearing from the tag centre, position from one range (fast, no flight)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.beacon import (
    BEARING_MISSES_PLANE,
    BEYOND_BEACON_RANGE,
    IR_LOCK_MAX_RANGE_M,
    BeaconConfig,
    BeaconEstimator,
    beacon_position,
    bearing_from_pixel,
    tag_centre_pixel,
)
from estimation.camera_model import CameraIntrinsics
from estimation.estimator import NO_DETECTION, RANGE_INVALID
from estimation.geometry import Undistorter
from estimation.types import CameraFrame, RangeReading, TagDetection

TAG_ID = 3


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _square(centre_px: tuple[float, float], half_px: float) -> np.ndarray:
    u, v = centre_px
    return np.array(
        [
            [u - half_px, v + half_px],
            [u + half_px, v + half_px],
            [u + half_px, v - half_px],
            [u - half_px, v - half_px],
        ]
    )


def _frame(corners_px: np.ndarray, tag_id: int = TAG_ID) -> CameraFrame:
    return CameraFrame(timestamp=1.5, detections=(TagDetection(tag_id, corners_px),))


def _range(range_m: float, valid: bool = True) -> RangeReading:
    return RangeReading(timestamp=1.5, ranges=np.array([range_m]), valid=np.array([valid]))


def _invalid_beacon(estimate: object) -> bool:
    """An invalid estimate that still names its method and the frame's time."""
    return not estimate.valid and estimate.method == "beacon" and estimate.timestamp == 1.5


def _estimator(range_m: float, valid: bool = True, **config: float) -> BeaconEstimator:
    return BeaconEstimator(
        CameraIntrinsics(), TAG_ID, lambda: _range(range_m, valid), BeaconConfig(**config)
    )


def test_tag_centre_is_the_diagonals_intersection_not_the_corner_mean() -> None:
    # a trapezoid (perspective of a square): diagonals meet off the corners' mean
    corners = np.array([[0.0, 0.0], [4.0, 0.0], [3.0, 2.0], [1.0, 2.0]])
    centre = tag_centre_pixel(corners)
    # diagonals (0,0)-(3,2) and (4,0)-(1,2) meet at (2, 4/3)
    np.testing.assert_allclose(centre, [2.0, 4.0 / 3.0], atol=1e-12)
    assert not np.allclose(centre, corners.mean(axis=0))


@settings(max_examples=50, deadline=None)
@given(
    u=st.floats(-500.0, 500.0),
    v=st.floats(-500.0, 500.0),
    half=st.floats(1.0, 100.0),
)
def test_tag_centre_of_a_square_is_its_centre(u: float, v: float, half: float) -> None:
    np.testing.assert_allclose(tag_centre_pixel(_square((u, v), half)), [u, v], atol=1e-9)


def test_bearing_of_the_principal_point_is_the_optical_axis_and_is_unit() -> None:
    k = CameraIntrinsics()
    undistort = Undistorter(k)
    np.testing.assert_allclose(
        bearing_from_pixel(np.array([k.cx, k.cy]), undistort, k.matrix), [0.0, 0.0, 1.0], atol=1e-12
    )
    pixel = np.array([k.cx + k.fx * 0.3, k.cy - k.fy * 0.2])
    bearing = bearing_from_pixel(pixel, undistort, k.matrix)
    expected = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    np.testing.assert_allclose(bearing, expected, atol=1e-9)


def test_position_on_the_perpendicular_plane_has_the_range_plus_offset_as_depth() -> None:
    bearing = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    np.testing.assert_allclose(beacon_position(bearing, 2.0), [0.6, -0.4, 2.0], atol=1e-12)
    np.testing.assert_allclose(
        beacon_position(bearing, 2.0, None, 0.5), [0.75, -0.5, 2.5], atol=1e-12
    )


@pytest.mark.parametrize(
    ("range_m", "offset_m"),
    [(0.0, 0.0), (-1.0, 0.0), (0.3, -0.3), (float("nan"), 0.0), (float("inf"), 0.0)],
)
def test_no_position_for_a_non_positive_or_non_finite_distance(
    range_m: float, offset_m: float
) -> None:
    assert beacon_position(np.array([0.0, 0.0, 1.0]), range_m, None, offset_m) is None
    assert beacon_position(np.array([0.0, 0.0, 1.0]), range_m, np.eye(3), offset_m) is None


def test_no_position_for_a_bearing_parallel_to_or_behind_the_plane() -> None:
    assert beacon_position(np.array([1.0, 0.0, 0.0]), 2.0) is None
    assert beacon_position(np.array([0.0, 0.6, -0.8]), 2.0) is None
    # just in front: a position, far away
    position = beacon_position(np.array([1.0, 0.0, 1e-6]), 1.0)
    assert position is not None and position[2] == pytest.approx(1.0)


def test_level_camera_with_attitude_gives_the_perpendicular_plane_result() -> None:
    bearing = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    np.testing.assert_allclose(
        beacon_position(bearing, 2.0, np.eye(3), 0.5),
        beacon_position(bearing, 2.0, None, 0.5),
        atol=1e-12,
    )


def test_tilted_camera_puts_the_beacon_on_the_horizontal_plane_at_range_times_cosine() -> None:
    tilt_rad = 0.3
    r_level_c = _rot_x(tilt_rad)  # C to level: gravity in C is r.T @ z
    down_c = r_level_c.T @ np.array([0.0, 0.0, 1.0])
    bearing = np.array([0.1, 0.2, 1.0]) / np.linalg.norm([0.1, 0.2, 1.0])
    position = beacon_position(bearing, 2.0, r_level_c, 0.5)
    assert position is not None
    # height below the camera: (range + offset) * cos(tilt); the point lies on the bearing
    assert float(position @ down_c) == pytest.approx(2.5 * np.cos(tilt_rad), rel=1e-12)
    np.testing.assert_allclose(np.cross(position, bearing), 0.0, atol=1e-12)
    assert float(position @ bearing) > 0.0


def test_no_position_when_the_axis_or_the_bearing_points_at_or_above_the_horizon() -> None:
    bearing = np.array([0.0, 0.0, 1.0])
    assert beacon_position(bearing, 2.0, _rot_x(np.pi / 2)) is None  # axis horizontal
    assert beacon_position(bearing, 2.0, _rot_x(2.0)) is None  # axis upwards
    # axis down, bearing horizontal in the level frame
    r_level_c = _rot_x(0.5)
    down_c = r_level_c.T @ np.array([0.0, 0.0, 1.0])
    horizontal = np.cross(down_c, [1.0, 0.0, 0.0])
    horizontal /= np.linalg.norm(horizontal)
    assert beacon_position(horizontal, 2.0, r_level_c) is None


def test_config_defaults_are_the_paper_beacon_range_and_a_small_area() -> None:
    config = BeaconConfig()
    assert config.max_range_m == IR_LOCK_MAX_RANGE_M == 40.0
    assert config.min_corner_area_px == 4.0
    assert config.range_offset_m == 0.0


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("min_corner_area_px", -1.0),
        ("max_range_m", 0.0),
        ("range_offset_m", 1.5),
        ("range_offset_m", -1.5),
    ],
)
def test_config_rejects_values_outside_the_limits_naming_the_field(
    field: str, value: float
) -> None:
    with pytest.raises(ValueError, match=field):
        BeaconConfig(**{field: value})


def test_estimate_of_a_centred_tag_is_straight_ahead_at_the_range_and_level() -> None:
    k = CameraIntrinsics()
    estimate = _estimator(2.0, range_offset_m=0.25).estimate(
        _frame(_square((k.cx, k.cy), 20.0)), _range(9.0)
    )
    assert estimate.valid and estimate.method == "beacon" and estimate.timestamp == 1.5
    np.testing.assert_allclose(estimate.translation, [0.0, 0.0, 2.25], atol=1e-9)
    np.testing.assert_allclose(estimate.rotation, np.eye(3))
    assert estimate.extras["orientation_known"] is False
    np.testing.assert_allclose(estimate.extras["centre_px"], [k.cx, k.cy], atol=1e-9)


def test_estimate_of_an_off_centre_tag_follows_its_bearing() -> None:
    k = CameraIntrinsics()
    centre = (k.cx + 0.25 * k.fx, k.cy - 0.1 * k.fy)
    estimate = _estimator(4.0).estimate(_frame(_square(centre, 15.0)), _range(1.0))
    np.testing.assert_allclose(estimate.translation, [1.0, -0.4, 4.0], atol=1e-6)


def test_estimate_is_invalid_without_the_tag() -> None:
    k = CameraIntrinsics()
    estimate = _estimator(2.0).estimate(
        _frame(_square((k.cx, k.cy), 20.0), tag_id=TAG_ID + 1), _range(2.0)
    )
    assert _invalid_beacon(estimate) and estimate.reason == NO_DETECTION


def test_estimate_is_invalid_for_a_tag_smaller_than_the_minimum_area() -> None:
    k = CameraIntrinsics()
    frame = _frame(_square((k.cx, k.cy), 1.5))  # 9 px^2
    assert _estimator(2.0).estimate(frame, _range(2.0)).valid
    estimate = _estimator(2.0, min_corner_area_px=10.0).estimate(frame, _range(2.0))
    assert _invalid_beacon(estimate) and estimate.reason == "degenerate_corners"


def test_estimate_is_invalid_when_the_range_source_is_invalid() -> None:
    k = CameraIntrinsics()
    estimate = _estimator(2.0, valid=False).estimate(
        _frame(_square((k.cx, k.cy), 20.0)), _range(2.0)
    )
    assert _invalid_beacon(estimate) and estimate.reason == RANGE_INVALID


def test_estimate_is_invalid_when_the_range_gives_no_plane() -> None:
    k = CameraIntrinsics()
    estimate = _estimator(0.2, range_offset_m=-0.5).estimate(
        _frame(_square((k.cx, k.cy), 20.0)), _range(2.0)
    )
    assert _invalid_beacon(estimate) and estimate.reason == BEARING_MISSES_PLANE


def test_estimate_is_invalid_beyond_the_beacon_range_and_valid_at_it() -> None:
    k = CameraIntrinsics()
    frame = _frame(_square((k.cx, k.cy), 20.0))
    assert _estimator(5.0, max_range_m=5.0).estimate(frame, _range(5.0)).valid
    estimate = _estimator(5.0, max_range_m=4.99).estimate(frame, _range(5.0))
    assert _invalid_beacon(estimate) and estimate.reason == BEYOND_BEACON_RANGE
    # the range is the distance to the beacon, not its depth
    off_axis = _frame(_square((k.cx + k.fx, k.cy), 20.0))  # 45 degrees: distance = depth * sqrt 2
    estimate = _estimator(3.0, max_range_m=4.0).estimate(off_axis, _range(3.0))
    assert _invalid_beacon(estimate) and estimate.reason == BEYOND_BEACON_RANGE


def test_tag_centre_of_unsigned_integer_corners_is_exact() -> None:
    corners = _square((100.0, 200.0), 10.0).astype(np.uint16)
    np.testing.assert_allclose(tag_centre_pixel(corners), [100.0, 200.0], atol=1e-9)


def test_bearing_uses_cx_for_u_and_cy_for_v() -> None:
    k = CameraIntrinsics(cx=250.0, cy=262.0)
    bearing = bearing_from_pixel(np.array([250.0, 262.0]), Undistorter(k), k.matrix)
    np.testing.assert_allclose(bearing, [0.0, 0.0, 1.0], atol=1e-12)


def test_position_takes_a_column_bearing() -> None:
    bearing = np.array([[0.3], [-0.2], [1.0]])
    np.testing.assert_allclose(beacon_position(bearing, 2.0), [0.6, -0.4, 2.0], atol=1e-12)


def test_no_position_at_the_one_nanoradian_margin_of_the_horizon() -> None:
    # the bearing's component along the axis (or along gravity) must exceed 1e-9
    assert beacon_position(np.array([1.0, 0.0, 1e-9]), 2.0) is None
    assert beacon_position(np.array([1.0, 0.0, 1e-9]), 2.0, np.eye(3)) is None
    # the optical axis tilted so that its cosine to gravity is exactly 1e-9
    r_level_c = np.array([[1.0, 0.0, 0.0], [0.0, 1e-9, -1.0], [0.0, 1.0, 1e-9]])
    assert beacon_position(np.array([0.0, 1.0, 0.0]), 2.0, r_level_c) is None
    r_level_c[2, 2] = 0.75e-9
    assert beacon_position(np.array([0.0, 1.0, 0.0]), 2.0, r_level_c) is None


def test_estimate_reads_the_first_sensor_of_a_four_sensor_range_reading() -> None:
    k = CameraIntrinsics()
    frame = _frame(_square((k.cx, k.cy), 20.0))
    for shape in [(4,), (1, 4)]:
        reading = RangeReading(
            1.5,
            np.array([2.0, 9.0, 9.0, 9.0]).reshape(shape),
            np.array([True, False, False, False]).reshape(shape),
        )
        estimator = BeaconEstimator(CameraIntrinsics(), TAG_ID, lambda r=reading: r)
        estimate = estimator.estimate(frame, reading)
        assert estimate.valid, shape
        np.testing.assert_allclose(estimate.translation, [0.0, 0.0, 2.0], atol=1e-9)
    reading = RangeReading(1.5, np.array([2.0, 9.0]), np.array([False, True]))
    estimate = BeaconEstimator(CameraIntrinsics(), TAG_ID, lambda: reading).estimate(frame, reading)
    assert _invalid_beacon(estimate) and estimate.reason == RANGE_INVALID
