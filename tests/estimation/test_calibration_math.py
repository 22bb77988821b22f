"""ToF–camera calibration and chessboard intrinsics maths."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator
from scipy.spatial.transform import Rotation

from estimation.camera_model import CameraIntrinsics
from estimation.frames import tof_positions_in_camera_frame
from estimation.intrinsics_calibration import (
    IntrinsicsCalibrationResult,
    calibrate,
    chessboard_object_points,
    find_chessboard,
)
from estimation.tof_calibration import (
    PAD_COLOURS,
    TofCameraCalibration,
    fit_hyperbola,
    segment_pad,
    ycbcr_studio,
)
from estimation.tof_rig import pad_centroid_in_image
from landing_env.errors import ConfigError


def pad_centroid(mask: np.ndarray) -> np.ndarray | None:
    """The rig's pad centroid of ``mask`` (any blob with area)."""
    return pad_centroid_in_image(mask, 1e-9)[0]


PAD_RGB = {"blue": (0, 0, 255), "green": (0, 255, 0), "yellow": (255, 255, 0), "red": (255, 0, 0)}


def _draw_disc(image: np.ndarray, centre: tuple[int, int], radius: int, rgb) -> None:
    """A filled disc with cv2 (integer centre: cv2's sub-pixel discs are not symmetric)."""
    cv2.circle(image, centre, radius, rgb, thickness=-1, lineType=cv2.LINE_8)


def test_ycbcr_conversion_uses_the_papers_studio_range_and_channel_order() -> None:
    pixels = np.array([[[255, 255, 255], [0, 0, 0], [0, 0, 255], [255, 0, 0]]], dtype=np.uint8)
    y, cb, cr = ycbcr_studio(pixels)
    np.testing.assert_allclose(y[0, :2], [235.0, 16.0], atol=0.5)
    np.testing.assert_allclose(cb[0, :2], [128.0, 128.0], atol=0.5)
    # Eq. 2: pure blue has Cb = 240 and pure red Cr = 240 (OpenCV's order is Y, Cr, Cb)
    assert cb[0, 2] == pytest.approx(240.0, abs=1.0)
    assert cr[0, 3] == pytest.approx(240.0, abs=1.0)


def test_pads_are_segmented_and_their_centroids_found() -> None:
    image = np.full((240, 320, 3), 128, dtype=np.uint8)  # grey deck
    image[100:140, 140:180] = 255  # a white patch (the tag's margin) must not be picked
    centres = {"blue": (60, 50), "green": (250, 60), "yellow": (240, 190), "red": (70, 180)}
    for colour, centre in centres.items():
        _draw_disc(image, centre, 18, PAD_RGB[colour])
    # a small speck of the same colour elsewhere: the largest blob wins
    image[5:8, 300:303] = PAD_RGB["blue"]
    for colour in PAD_COLOURS:
        mask = segment_pad(image, colour)
        # each mask holds one pad (plus the speck for blue), not the others (pure green lies
        # inside Table 1's yellow box, so this checks the yellow/green exclusion too)
        assert 900 < mask.sum() < 1100 + (9 if colour == "blue" else 0), colour
        centroid = pad_centroid(mask)
        assert centroid is not None
        np.testing.assert_allclose(centroid, centres[colour], atol=1e-9)


@pytest.mark.parametrize("centre", [(60.3, 50.6), (60.25, 50.75), (61.1, 49.9)])
@pytest.mark.parametrize("radius", [8.0, 12.3, 18.0])
def test_pad_centroids_are_sub_pixel(centre: tuple[float, float], radius: float) -> None:
    yy, xx = np.mgrid[0:120, 0:120]
    mask = (xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= radius**2
    centroid = pad_centroid(mask)
    assert centroid is not None
    # the hull through the boundary pixels' centres: measured ≤ 0.12 px for r ≥ 8 px
    np.testing.assert_allclose(centroid, centre, atol=0.15)


def test_a_notched_pad_is_closed_by_the_convex_hull() -> None:
    image = np.full((100, 100, 3), 128, dtype=np.uint8)
    _draw_disc(image, (50, 50), 20, PAD_RGB["red"])
    image[45:55, 30:50] = 128  # a notch from the left edge into the centre (e.g. a glare)
    centroid = pad_centroid(segment_pad(image, "red"))
    assert centroid is not None
    np.testing.assert_allclose(centroid, (50.0, 50.0), atol=0.3)


def test_empty_masks_and_bad_inputs() -> None:
    assert pad_centroid(np.zeros((50, 50), dtype=bool)) is None
    single = np.zeros((50, 50), dtype=bool)
    single[10, 20] = True
    assert pad_centroid(single) is None  # a one-pixel speck has no area: no pad
    with pytest.raises(ConfigError, match="colour"):
        segment_pad(np.zeros((4, 4, 3), dtype=np.uint8), "purple")
    with pytest.raises(ValueError, match="uint8"):
        segment_pad(np.zeros((4, 4, 3), dtype=float), "red")


def _exact(intrinsics: CameraIntrinsics | None = None) -> TofCameraCalibration:
    k = intrinsics or CameraIntrinsics()
    return TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), 0.3, 4.0, n_samples=120)


def test_exact_calibration_is_the_projection_of_the_touch_points() -> None:
    k = CameraIntrinsics()
    cal = _exact(k)
    sensors = tof_positions_in_camera_frame()
    ranges = np.array([0.5, 1.0, 2.0, 3.0])
    out = cal.lookup(ranges)
    assert np.all(out.valid) and not np.any(out.out_of_range)
    np.testing.assert_allclose(out.pixels[:, 0], k.fx * sensors[:, 0] / ranges + k.cx, atol=1e-9)
    np.testing.assert_allclose(out.pixels[:, 1], k.fy * sensors[:, 1] / ranges + k.cy, atol=1e-9)


@pytest.mark.parametrize("lens", [(0, 0, 0, 0, 0), (-0.25, 0.08, 0.001, -0.001, 0.0)])
def test_pchip_reproduces_the_exact_map_between_samples(lens) -> None:
    k = CameraIntrinsics(dist=lens)
    exact = _exact(k)
    pchip = exact.with_method("pchip")
    samples = exact.samples[0][:, 0]
    midpoints = 0.5 * (samples[1:] + samples[:-1])
    worst = 0.0
    for r in midpoints:
        reading = np.full(4, r)
        worst = max(
            worst,
            float(np.max(np.abs(pchip.lookup(reading).pixels - exact.lookup(reading).pixels))),
        )
    # 120 samples over 0.3-4 m: measured worst 0.022 px (pinhole), at the short-range end
    assert worst < 0.05
    # the look-up evaluates scipy's PCHIP pieces itself: it must be scipy's interpolant
    reference = PchipInterpolator(exact.samples[1][:, 0], exact.samples[1][:, 1:], axis=0)
    for r in np.linspace(0.3, 4.0, 37):
        np.testing.assert_allclose(pchip.lookup(np.full(4, r)).pixels[1], reference(r), atol=1e-9)


def test_hyperbola_fit_recovers_focal_times_offset_and_principal_point() -> None:
    k = CameraIntrinsics()
    cal = _exact(k)
    sensors = tof_positions_in_camera_frame()
    for i in range(4):
        assert cal.hyperbola_u[i].a == pytest.approx(k.fx * sensors[i, 0], rel=1e-10)
        assert cal.hyperbola_u[i].c == pytest.approx(k.cx, abs=1e-8)
        assert cal.hyperbola_v[i].a == pytest.approx(k.fy * sensors[i, 1], rel=1e-10)
        assert cal.hyperbola_v[i].c == pytest.approx(k.cy, abs=1e-8)
        assert cal.hyperbola_u[i].rms < 1e-9
    # with 0.2 px centroid noise the fit still lands close
    rng = np.random.default_rng(2)
    r = np.linspace(0.3, 4.0, 120)
    noisy = 32.4 / r + 255.5 + rng.normal(0.0, 0.2, size=r.size)
    fit = fit_hyperbola(r, noisy)
    assert fit.a == pytest.approx(32.4, abs=0.2) and fit.c == pytest.approx(255.5, abs=0.1)
    assert fit.rms == pytest.approx(0.2, rel=0.2)


def test_out_of_range_lookups_are_flagged_not_silent() -> None:
    pchip = _exact().with_method("pchip")
    ranges = np.array([0.1, 1.0, 5.0, 2.0])
    extrapolated = pchip.lookup(ranges)
    np.testing.assert_array_equal(extrapolated.out_of_range, [True, False, True, False])
    np.testing.assert_array_equal(extrapolated.extrapolated, [True, False, True, False])
    assert np.all(extrapolated.valid)
    # for a pinhole the hyperbola extrapolation is the exact map
    np.testing.assert_allclose(extrapolated.pixels, _exact().lookup(ranges).pixels, atol=1e-8)
    strict = pchip.with_method("pchip", out_of_range="nan").lookup(ranges)
    np.testing.assert_array_equal(strict.valid, [False, True, False, True])
    assert np.all(np.isnan(strict.pixels[[0, 2]])) and np.all(np.isfinite(strict.pixels[[1, 3]]))
    bad = pchip.lookup(np.array([np.nan, -1.0, 0.0, 1.0]))
    np.testing.assert_array_equal(bad.valid, [False, False, False, True])
    assert not pchip.lookup(np.ones(3)).valid.any()
    with pytest.raises(ConfigError, match="out_of_range"):
        pchip.with_method("pchip", out_of_range="clip")


def test_calibration_from_measurements_cleans_the_samples(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    ranges = np.repeat(np.linspace(0.3, 2.0, 30)[:, None], 4, axis=1)
    ranges = np.vstack([ranges, ranges[:5]])  # repeated altitudes are averaged
    sensors = tof_positions_in_camera_frame()
    pixels = 458.0 * sensors[None, :, :2] / ranges[:, :, None] + 255.5
    pixels = pixels + rng.normal(0.0, 0.1, size=pixels.shape)
    pixels[10, 2] = np.nan  # pad not found in one frame
    cal = TofCameraCalibration.from_measurements(ranges, pixels, metadata={"rig": "sim"})
    assert [len(s) for s in cal.samples] == [30, 30, 29, 30]
    assert np.all(np.diff(cal.samples[0][:, 0]) > 0.0)
    path = tmp_path / "tof.json"
    cal.save(path)
    loaded = TofCameraCalibration.load(path)
    assert loaded.metadata == {"rig": "sim"} and loaded.method == "pchip"
    probe = np.array([0.45, 0.8, 1.3, 1.9])
    np.testing.assert_allclose(loaded.lookup(probe).pixels, cal.lookup(probe).pixels, atol=1e-12)
    exact = _exact(CameraIntrinsics(dist=(-0.1, 0.0, 0.0, 0.0, 0.0)))
    exact.save(path)
    np.testing.assert_allclose(
        TofCameraCalibration.load(path).lookup(probe).pixels, exact.lookup(probe).pixels
    )
    with pytest.raises(ValueError, match="at least 2"):
        TofCameraCalibration([np.array([[1.0, 2.0, 3.0]])])


def _board_poses(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    poses = []
    for _ in range(n):
        tilt = Rotation.from_euler("xy", rng.uniform(-35.0, 35.0, size=2), degrees=True)
        yaw = Rotation.from_euler("z", rng.uniform(-math.pi, math.pi))
        translation = np.array(
            [rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(0.6, 1.2)]
        )
        poses.append(((tilt * yaw).as_matrix(), translation))
    return poses


def test_chessboard_calibration_recovers_the_intrinsics(tmp_path: Path) -> None:
    truth = CameraIntrinsics(
        fx=458.5, fy=457.855, cx=258.77, cy=252.31, dist=(-0.12, 0.05, 0.0005, -0.0003, 0.0)
    )
    pattern, square = (7, 10), 0.03
    board = chessboard_object_points(pattern, square)
    board_centred = board - board.mean(axis=0)
    rng = np.random.default_rng(9)
    views = []
    for rotation, translation in _board_poses(rng, 20):
        corners = truth.project(board_centred @ rotation.T + translation)
        assert np.all(np.isfinite(corners))
        views.append(corners + rng.normal(0.0, 0.1, size=corners.shape))
    result = calibrate(views, (truth.width, truth.height), square, pattern)
    k = result.K
    for estimated, true in (
        (k[0, 0], truth.fx),
        (k[1, 1], truth.fy),
        (k[0, 2], truth.cx),
        (k[1, 2], truth.cy),
    ):
        assert abs(estimated - true) < 0.005 * true
    # OpenCV's RMS is over 2-D errors: sqrt(2) x the per-coordinate noise
    assert result.rms_reprojection_error == pytest.approx(0.1 * math.sqrt(2.0), rel=0.2)
    assert result.per_view_errors.shape == (20,)
    intrinsics = result.to_intrinsics()
    assert intrinsics.fx == k[0, 0] and intrinsics.dist[0] == pytest.approx(-0.12, abs=0.02)
    path = tmp_path / "camera.json"
    result.save(path)
    loaded = IntrinsicsCalibrationResult.load(path)
    np.testing.assert_allclose(loaded.K, result.K)
    np.testing.assert_allclose(loaded.dist, result.dist)
    assert loaded.image_size == (truth.width, truth.height)


def test_find_chessboard_locates_the_inner_corners_in_opencv_pixels() -> None:
    pattern, square_px, margin = (7, 10), 20, 40
    cols, rows = pattern[0] + 1, pattern[1] + 1
    image = np.full((rows * square_px + 2 * margin, cols * square_px + 2 * margin), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y0, x0 = margin + r * square_px, margin + c * square_px
                image[y0 : y0 + square_px, x0 : x0 + square_px] = 0
    corners = find_chessboard(image, pattern)
    assert corners is not None and corners.shape == (70, 2)
    # an inner corner between pixel columns x-1 and x lies at x - 0.5 in OpenCV pixels
    xs = margin + square_px * np.arange(1, cols) - 0.5
    ys = margin + square_px * np.arange(1, rows) - 0.5
    expected = np.array([(x, y) for y in ys for x in xs])
    distances = np.linalg.norm(corners[:, None, :] - expected[None, :, :], axis=2)
    assert np.max(distances.min(axis=1)) < 0.1
    assert find_chessboard(np.full((200, 200), 255, np.uint8), pattern) is None
