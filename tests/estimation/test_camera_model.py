"""The pinhole camera with OpenCV's distortion (estimation.camera_model): its file entry, its
projection, the undistortion that inverts it, and the field of view it sees."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.camera_model import CameraIntrinsics

BARREL = (-0.25, 0.06, 0.0015, -0.001, -0.004)
LENS = CameraIntrinsics(640, 480, 500.0, 505.0, 300.0, 250.0, BARREL)


def test_a_camera_written_as_data_reads_back_equal_with_its_distortion_a_list() -> None:
    data = LENS.as_dict()
    assert set(data) == {"width", "height", "fx", "fy", "cx", "cy", "dist"}
    assert data["dist"] == list(BARREL)
    assert CameraIntrinsics.from_dict(data) == LENS


def test_a_camera_without_distortion_or_with_fewer_terms_has_the_rest_zero() -> None:
    data = {"width": 64, "height": 48, "fx": 50, "fy": 51, "cx": 31.5, "cy": 23.5}
    assert CameraIntrinsics.from_dict(data).dist == (0.0,) * 5
    assert not CameraIntrinsics.from_dict(data).has_distortion
    assert CameraIntrinsics.from_dict({**data, "dist": []}).dist == (0.0,) * 5
    assert CameraIntrinsics.from_dict({**data, "dist": [-0.1]}).dist == (-0.1, 0.0, 0.0, 0.0, 0.0)
    three = CameraIntrinsics.from_dict({**data, "dist": [-0.1, 0.02, 0.001]})
    assert three.dist == (-0.1, 0.02, 0.001, 0.0, 0.0)
    five = CameraIntrinsics.from_dict({**data, "dist": list(BARREL)})
    assert five.dist == BARREL


def test_a_camera_entry_missing_a_key_or_holding_a_non_number_is_refused_naming_it() -> None:
    data = LENS.as_dict()
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        partial = {k: v for k, v in data.items() if k != key}
        with pytest.raises(ValueError) as error:
            CameraIntrinsics.from_dict(partial, where="rig.json: camera")
        assert str(error.value) == f"rig.json: camera: missing key {key!r}"
    with pytest.raises(ValueError, match=r"^rig\.json: camera: not a camera model \(.+\)$"):
        CameraIntrinsics.from_dict({**data, "fx": "wide"}, where="rig.json: camera")
    with pytest.raises(ValueError, match=r"^camera: not a camera model \(.+\)$"):
        CameraIntrinsics.from_dict({**data, "dist": None})


def test_six_distortion_terms_are_refused_and_five_read() -> None:
    data = LENS.as_dict()
    with pytest.raises(ValueError) as error:
        CameraIntrinsics.from_dict({**data, "dist": [0.0] * 6})
    assert str(error.value) == "camera.dist: 6 values; at most 5 (k1 k2 p1 p2 k3)"
    assert CameraIntrinsics.from_dict({**data, "dist": [0.0] * 5}).dist == (0.0,) * 5


@pytest.mark.parametrize("key", ["width", "height", "fx", "fy"])
def test_a_camera_without_a_pixel_or_a_positive_focal_length_is_refused(key: str) -> None:
    smallest = {"width": 1, "height": 1, "fx": 0.25, "fy": 0.25, "cx": 0.0, "cy": 0.0}
    assert CameraIntrinsics.from_dict(smallest).width == 1  # the smallest camera there is
    with pytest.raises(ValueError) as error:
        CameraIntrinsics.from_dict({**smallest, key: 0})
    assert str(error.value) == "camera: need width, height >= 1 px and fx, fy > 0"


def test_a_point_projects_through_the_pinhole_and_the_distortion_as_opencv_does() -> None:
    points_c = np.array([[0.3, -0.2, 2.0], [-1.0, 0.5, 3.0], [0.0, 0.0, 1.0]])
    expected, _ = cv2.projectPoints(
        points_c, np.zeros(3), np.zeros(3), LENS.matrix, LENS.dist_coeffs
    )
    np.testing.assert_allclose(LENS.project(points_c), expected.reshape(-1, 2), atol=1e-9)
    ideal = LENS.project(points_c, distort=False)
    np.testing.assert_allclose(ideal[0], [500.0 * 0.15 + 300.0, 505.0 * -0.1 + 250.0])
    # integer coordinates are points like any other
    np.testing.assert_allclose(
        LENS.project(np.array([[1, 2, 10]])), LENS.project([[1.0, 2.0, 10.0]])
    )


def test_a_point_on_or_behind_the_lens_plane_has_no_pixel() -> None:
    points_c = np.array([[0.1, 0.1, 1e-9], [0.1, 0.1, -2.0], [0.1, 0.1, 2.0]])
    for camera in (LENS, CameraIntrinsics()):
        pixels = camera.project(points_c)
        assert np.isnan(pixels[:2]).all() and np.isfinite(pixels[2]).all()
        assert np.isnan(camera.project(points_c[:2])).all()


@settings(max_examples=40, deadline=None)
@given(
    u=st.floats(40.0, 600.0),
    v=st.floats(40.0, 440.0),
)
def test_undistorting_a_distorted_pixel_gives_back_the_pinholes_pixel(u: float, v: float) -> None:
    ray = np.array([[(u - LENS.cx) / LENS.fx, (v - LENS.cy) / LENS.fy, 1.0]])
    distorted = LENS.project(ray)
    # OpenCV iterates a fixed five times: a hundredth of a pixel at the corners
    np.testing.assert_allclose(LENS.undistort_pixels(distorted), [[u, v]], atol=0.02)


def test_undistorting_without_distortion_is_a_copy_of_the_pixels() -> None:
    pinhole = CameraIntrinsics()
    pixels = np.array([[10.0, 20.0], [300.5, 7.25]])
    undistorted = pinhole.undistort_pixels(pixels)
    np.testing.assert_array_equal(undistorted, pixels)
    undistorted[0, 0] = -1.0
    assert pixels[0, 0] == 10.0
    np.testing.assert_array_equal(pinhole.undistort_pixels([3.0, 4.0]), [[3.0, 4.0]])
    # integer pixels are pixels like any other, with a lens or without
    assert pinhole.undistort_pixels([[3, 4]]).dtype == np.float64
    np.testing.assert_array_equal(
        LENS.undistort_pixels([[100, 200]]), LENS.undistort_pixels([[100.0, 200.0]])
    )


def test_the_half_view_of_a_pinhole_is_its_nearest_edge_over_the_focal_length() -> None:
    pinhole = CameraIntrinsics(640, 480, 500.0, 350.0, 300.0, 250.0)
    # left 300/500, right 339/500, top 250/350, bottom 229/350: the left edge is nearest
    assert pinhole.half_view_tan() == pytest.approx(300.0 / 500.0)
    tall = CameraIntrinsics(640, 480, 500.0, 600.0, 300.0, 250.0)
    assert tall.half_view_tan() == pytest.approx(229.0 / 600.0)  # the bottom edge


@pytest.mark.parametrize(
    ("cx", "cy", "expected"),
    [
        (250.0, 240.0, 250.0 / 500.0),  # the left edge
        (390.0, 240.0, 249.0 / 500.0),  # the right edge: the last pixel is 639
        (320.0, 200.0, 200.0 / 450.0),  # the top edge
        (320.0, 260.0, 219.0 / 450.0),  # the bottom edge: the last pixel is 479
    ],
)
def test_each_image_edge_bounds_the_half_view_when_it_is_the_nearest(
    cx: float, cy: float, expected: float
) -> None:
    assert CameraIntrinsics(640, 480, 500.0, 450.0, cx, cy).half_view_tan() == pytest.approx(
        expected, rel=1e-12
    )


def test_a_ray_within_the_half_view_lands_in_the_distorted_image_and_one_beyond_leaves_it() -> None:
    tan = LENS.half_view_tan()
    pinhole = CameraIntrinsics(640, 480, 500.0, 505.0, 300.0, 250.0)
    assert abs(tan - pinhole.half_view_tan()) > 0.01  # the barrel widens the view
    limits = np.array([LENS.width - 1.0, LENS.height - 1.0])

    def along_axes(scale: float) -> np.ndarray:
        rays = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]], dtype=float) * tan * scale
        rays[:, 2] = 1.0
        return LENS.project(rays)

    def in_image(pixels: np.ndarray) -> np.ndarray:
        return ((pixels >= -1e-6) & (pixels <= limits + 1e-6)).all(axis=1)

    assert in_image(along_axes(0.999)).all()
    assert not in_image(along_axes(1.001)).all()  # the nearest edge is passed
