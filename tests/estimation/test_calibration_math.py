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
    calibrate_from_images,
    chessboard_object_points,
    find_chessboard,
    image_files,
)
from estimation.tof_calibration import (
    OUT_OF_RANGE_POLICIES,
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


def test_the_boards_object_points_run_along_each_row_then_down_the_rows() -> None:
    grid = chessboard_object_points((3, 2), 0.5)
    expected = [[0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [0, 0.5, 0], [0.5, 0.5, 0], [1.0, 0.5, 0]]
    np.testing.assert_array_equal(grid, expected)


#: the camera of :func:`_views`: 640x480, focal length 458 px
VIEWS_CAMERA = CameraIntrinsics(
    width=640, height=480, fx=458.5, fy=457.9, cx=319.5, cy=239.5,
    dist=(-0.12, 0.05, 0.0005, -0.0003, 0.0),
)  # fmt: skip


def _views(n: int, pattern: tuple[int, int] = (7, 10)) -> list[np.ndarray]:
    """``n`` noisy views of the board of ``pattern`` by :data:`VIEWS_CAMERA`."""
    truth = VIEWS_CAMERA
    board = chessboard_object_points(pattern, 0.03)
    board_centred = board - board.mean(axis=0)
    rng = np.random.default_rng(9)
    return [
        truth.project(board_centred @ rotation.T + translation)
        + rng.normal(0.0, 0.1, size=(len(board), 2))
        for rotation, translation in _board_poses(rng, n)
    ]


def test_a_calibration_needs_three_views_each_of_the_whole_pattern() -> None:
    views = _views(4)
    three = calibrate(views[:3], (640, 480), 0.03)
    assert three.per_view_errors.shape == (3,) and three.image_size == (640, 480)
    assert abs(three.K[0, 0] - VIEWS_CAMERA.fx) < 0.02 * VIEWS_CAMERA.fx
    with pytest.raises(ValueError) as two:
        calibrate(views[:2], (640, 480), 0.03)
    assert str(two.value) == "need at least 3 views, got 2"
    views[1] = views[1][:-1]
    with pytest.raises(ValueError) as short:
        calibrate(views, (640, 480), 0.03)
    assert str(short.value) == "view 1 has 69 corners; pattern (7, 10) has 70"


def test_the_calibrations_flags_reach_opencv() -> None:
    views = _views(6)
    free = calibrate(views, (640, 480), 0.03)
    assert free.dist.shape == (5,) and np.all(free.dist[2:] != 0.0)
    held = calibrate(views, (640, 480), 0.03, flags=cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3)
    assert held.dist.shape == (5,) and np.all(held.dist[2:] == 0.0) and held.dist[0] != 0.0
    assert held.image_size == (640, 480) and held.metadata == {} and held.tag_corners is None


def test_a_colour_image_gives_the_grey_ones_corners_and_a_float_image_is_refused() -> None:
    pattern = (4, 3)
    grey = _board_texture(pattern)
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    corners = find_chessboard(grey, pattern)
    assert corners is not None and corners.shape == (12, 2) and corners.dtype == np.float64
    np.testing.assert_array_equal(find_chessboard(rgb, pattern), corners)
    with pytest.raises(ValueError) as refused:
        find_chessboard(grey.astype(float), pattern)
    assert str(refused.value) == "image must be 8-bit"


def _board_texture(pattern: tuple[int, int], square_px: int = 20) -> np.ndarray:
    """A chessboard of ``pattern`` inner corners, fronto-parallel, with a one-square margin."""
    cols, rows = pattern[0] + 1, pattern[1] + 1
    board = np.full(((rows + 2) * square_px, (cols + 2) * square_px), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y0, x0 = (r + 1) * square_px, (c + 1) * square_px
                board[y0 : y0 + square_px, x0 : x0 + square_px] = 0
    return board


def _board_photo(pattern: tuple[int, int], tilt_deg: tuple[float, float]) -> np.ndarray:
    """The board, tilted by ``tilt_deg`` about x and y, 0.4 m in front of a 320x240 pinhole."""
    texture = _board_texture(pattern)
    square_m, square_px = 0.02, 20
    k = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    rotation = Rotation.from_euler("xy", tilt_deg, degrees=True).as_matrix()
    # texture pixel -> board point (metres, the board's centre at its origin)
    centre_px = (np.array(texture.shape[::-1]) - 1) / 2.0
    to_board = np.array(
        [
            [square_m / square_px, 0.0, -centre_px[0] * square_m / square_px],
            [0.0, square_m / square_px, -centre_px[1] * square_m / square_px],
            [0.0, 0.0, 1.0],
        ]
    )
    h = k @ np.column_stack([rotation[:, 0], rotation[:, 1], [0.0, 0.0, 0.4]]) @ to_board
    photo = cv2.warpPerspective(
        texture, h, (320, 240), flags=cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT,
        borderValue=255,
    )  # fmt: skip
    return cv2.GaussianBlur(photo, (3, 3), 0.6)


def test_photos_calibrate_and_the_result_records_the_board_and_every_photos_fate(
    tmp_path: Path,
) -> None:
    pattern = (4, 3)
    # the first photo unreadable, the size taken from the next; a rejection between the boards
    (tmp_path / "a_corrupt.png").write_bytes(b"not a png")
    cv2.imwrite(str(tmp_path / "b_view0.png"), _board_photo(pattern, (0.0, 0.0)))
    cv2.imwrite(str(tmp_path / "c_small.png"), _board_photo(pattern, (0.0, 0.0))[:200])
    cv2.imwrite(str(tmp_path / "d_blank.png"), np.full((240, 320), 200, np.uint8))
    cv2.imwrite(str(tmp_path / "e_view1.png"), _board_photo(pattern, (25.0, 0.0)))
    cv2.imwrite(str(tmp_path / "f_view2.png"), _board_photo(pattern, (-20.0, 20.0)))
    paths = image_files(tmp_path)
    run = calibrate_from_images(paths, pattern, 0.02)
    used = ["b_view0.png", "e_view1.png", "f_view2.png"]
    rejected = [
        ("a_corrupt.png", "cannot be read as an image"),
        ("c_small.png", "size 320x200 differs from 320x240"),
        ("d_blank.png", "no 4x3 chessboard found"),
    ]
    assert run.used == tuple(used) and run.rejected == tuple(rejected)
    assert run.result.image_size == (320, 240) and len(run.result.per_view_errors) == 3
    assert run.result.metadata == {
        "source": "photos",
        "pattern": [4, 3],
        "square_size_m": 0.02,
        "photos_used": used,
        "photos_rejected": [{"photo": n, "reason": r} for n, r in rejected],
    }
    assert np.all(run.result.dist[2:] != 0.0)
    flags = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3
    held = calibrate_from_images(paths, pattern, 0.02, flags)
    assert np.all(held.result.dist[2:] == 0.0)
    with pytest.raises(ValueError) as too_few:
        calibrate_from_images(paths[:5], pattern, 0.02)
    assert str(too_few.value) == (
        "need at least 3 usable photos, got 2 (a_corrupt.png: cannot be read as an image; "
        "c_small.png: size 320x200 differs from 320x240; d_blank.png: no 4x3 chessboard found)"
    )


@pytest.mark.parametrize("square_m", [0.0, -0.02, math.nan, math.inf])
def test_a_square_size_not_a_positive_number_of_metres_is_refused(square_m: float) -> None:
    with pytest.raises(ValueError) as refused:
        calibrate_from_images([], (4, 3), square_m)
    assert str(refused.value) == (
        f"square size must be a positive number of metres, got {square_m}"
    )


@pytest.mark.parametrize("pattern", [(1, 5), (5, 1), (4,), (4, 3, 2)])
def test_a_pattern_not_two_counts_of_at_least_two_corners_is_refused(pattern: tuple) -> None:
    with pytest.raises(ValueError) as refused:
        calibrate_from_images([], pattern, 0.02)
    assert str(refused.value) == (
        f"pattern must be COLSxROWS inner corners, each >= 2, got {pattern}"
    )


def test_no_photos_at_all_are_refused_as_no_image_files(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("not an image")
    assert image_files(tmp_path) == []
    # a 2x2 board is a board: the photos are what is missing
    with pytest.raises(ValueError) as refused:
        calibrate_from_images(image_files(tmp_path), (2, 2), 0.02)
    assert str(refused.value) == "need at least 3 usable photos, got 0 (no image files)"


def test_a_folders_image_files_are_its_images_of_any_case_sorted_by_name(tmp_path: Path) -> None:
    for name in ("b.PNG", "a.jpeg", "c.tiff", "d.txt", "e.png.bak", "f.Jpg"):
        (tmp_path / name).write_bytes(b"")
    assert [p.name for p in image_files(tmp_path)] == ["a.jpeg", "b.PNG", "c.tiff", "f.Jpg"]
    with pytest.raises(ValueError) as refused:
        image_files(tmp_path / "d.txt")
    assert str(refused.value) == f"{tmp_path / 'd.txt'}: not a folder"


@pytest.mark.parametrize(
    "image",
    [np.zeros((4, 4), np.uint8), np.zeros((4, 4, 4), np.uint8), np.zeros((4, 4, 3), np.uint16)],
)
def test_only_an_8_bit_three_channel_image_converts_to_ycbcr(image: np.ndarray) -> None:
    with pytest.raises(ValueError) as refused:
        ycbcr_studio(image)
    assert str(refused.value) == "image_rgb must be an HxWx3 uint8 RGB image"


def test_samples_keep_finite_positive_ranges_sorted_and_average_a_repeated_range() -> None:
    samples = np.array(
        [
            [2.0, 30.0, 40.0],
            [1.0, 10.0, 20.0],
            [2.0, 34.0, 50.0],
            [0.0, 1.0, 1.0],
            [-1.0, 1.0, 1.0],
            [3.0, np.nan, 1.0],
            [np.inf, 1.0, 1.0],
            [2.0, 38.0, 60.0],
        ]
    )
    cal = TofCameraCalibration([samples, samples[[1, 0]]])
    np.testing.assert_array_equal(cal.samples[0], [[1.0, 10.0, 20.0], [2.0, 34.0, 50.0]])
    np.testing.assert_array_equal(cal.samples[1], [[1.0, 10.0, 20.0], [2.0, 30.0, 40.0]])
    np.testing.assert_array_equal(cal.range_span, [[1.0, 2.0], [1.0, 2.0]])
    assert cal.n_sensors == 2
    with pytest.raises(ValueError) as refused:
        TofCameraCalibration([samples, samples[[0, 2, 3]]])
    assert str(refused.value) == "sensor 1 has 1 usable samples; at least 2 are needed"


def test_a_calibration_keeps_its_settings_and_a_copy_of_its_metadata_under_another_method() -> None:
    metadata = {"rig": "bench"}
    samples = [np.array([[1.0, 10.0, 20.0], [2.0, 30.0, 40.0], [4.0, 35.0, 45.0]])] * 4
    cal = TofCameraCalibration(
        samples, out_of_range="nan", metadata=metadata, image_size=(640.0, 480.0)
    )
    metadata["rig"] = "changed"
    assert cal.metadata == {"rig": "bench"} and cal.image_size == (640, 480)
    assert cal.method == "pchip" and cal.out_of_range == "nan"
    hyperbola = cal.with_method("hyperbola")
    assert hyperbola.method == "hyperbola" and hyperbola.out_of_range == "nan"
    assert hyperbola.metadata == {"rig": "bench"} and hyperbola.image_size == (640, 480)
    assert cal.with_method("pchip", out_of_range="hyperbola").out_of_range == "hyperbola"
    assert TofCameraCalibration(samples).metadata == {}
    assert TofCameraCalibration(samples).image_size is None
    with pytest.raises(ValueError) as refused:
        cal.with_method("exact")
    assert str(refused.value) == (
        "method 'exact' needs a calibration built by TofCameraCalibration.exact"
    )


def test_an_exact_calibration_samples_its_span_and_knows_its_camera() -> None:
    k = CameraIntrinsics(width=640, height=480)
    cal = TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), 0.3, 4.0)
    assert [len(s) for s in cal.samples] == [120] * 4
    np.testing.assert_array_equal(cal.range_span, [[0.3, 4.0]] * 4)
    assert cal.metadata == {"source": "exact", "r_min": 0.3, "r_max": 4.0}
    assert cal.image_size == (640, 480) and cal.method == "exact"
    assert cal.with_method("pchip").with_method("exact").image_size == (640, 480)
    # a range the sensor cannot give has no pixel; the analytic map extrapolates nothing
    out = cal.lookup(np.array([np.nan, -1.0, 0.0, 9.0]))
    np.testing.assert_array_equal(out.valid, [False, False, False, True])
    assert np.all(np.isnan(out.pixels[:3])) and not out.out_of_range.any()
    assert out.out_of_range.dtype == bool
    for r_min, r_max in [(0.0, 1.0), (2.0, 1.0), (1.0, 1.0)]:
        with pytest.raises(ValueError) as refused:
            TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), r_min, r_max)
        assert str(refused.value) == f"need 0 < r_min < r_max, got {r_min}, {r_max}"


def test_measurements_must_be_ranges_n_by_k_and_pixels_n_by_k_by_2() -> None:
    ranges = np.ones((5, 4))
    for pixels in (np.ones((5, 4)), np.ones((5, 3, 2)), np.ones((4, 4, 2))):
        with pytest.raises(ValueError) as refused:
            TofCameraCalibration.from_measurements(ranges, pixels)
        assert str(refused.value) == "ranges must be (n, k) and pixels (n, k, 2)"
    with pytest.raises(ValueError, match="ranges must be"):
        TofCameraCalibration.from_measurements(np.ones(5), np.ones((5, 2)))


def test_a_tof_calibration_refuses_images_of_another_size_naming_both() -> None:
    samples = [np.array([[1.0, 10.0, 20.0], [2.0, 30.0, 40.0]])] * 4
    TofCameraCalibration(samples).require_camera((1, 1))  # a file that does not say passes
    cal = TofCameraCalibration(samples, image_size=(640, 480))
    cal.require_camera((640.0, 480.0))
    with pytest.raises(ValueError) as refused:
        cal.require_camera((480, 640), source="tof.json", images="the frames")
    assert str(refused.value) == (
        "tof.json is for another camera: image size 640x480, but the frames are 480x640"
    )
    with pytest.raises(ValueError) as default:
        cal.require_camera((320, 240))
    assert str(default.value) == (
        "the ToF-camera calibration is for another camera: image size 640x480, "
        "but the images are 320x240"
    )


def test_a_hyperbola_fit_evaluates_a_over_the_range_plus_c() -> None:
    r = np.array([0.5, 1.0, 2.0, 4.0])
    fit = fit_hyperbola(r, 30.0 / r + 250.0)
    np.testing.assert_allclose(fit(np.array([0.25, 3])), [370.0, 260.0], rtol=1e-12)
    assert fit(2) == pytest.approx(265.0, rel=1e-12)


def test_ycbcr_planes_are_opencvs_full_range_values_rescaled_to_the_studio_range() -> None:
    greys = np.repeat(np.arange(256, dtype=np.uint8)[None, :, None], 3, axis=2)
    y, cb, cr = ycbcr_studio(greys)
    assert y.dtype == cb.dtype == cr.dtype == np.float32
    # a grey has no chroma; its luma runs from 16 (black) to 235 (white) in 219 equal steps
    np.testing.assert_allclose(y[0], 16.0 + np.arange(256) * 219.0 / 255.0, rtol=1e-6)
    assert np.all(cb == 128.0) and np.all(cr == 128.0)
    image = np.random.default_rng(3).integers(0, 256, size=(16, 16, 3), dtype=np.uint8)
    full = cv2.cvtColor(image, cv2.COLOR_RGB2YCrCb).astype(float)
    y, cb, cr = ycbcr_studio(image)
    np.testing.assert_allclose(y, 16.0 + full[..., 0] * 219.0 / 255.0, rtol=1e-6)
    np.testing.assert_allclose(cb, 128.0 + (full[..., 2] - 128.0) * 224.0 / 255.0, rtol=1e-6)
    np.testing.assert_allclose(cr, 128.0 + (full[..., 1] - 128.0) * 224.0 / 255.0, rtol=1e-6)


def test_an_unknown_pad_colour_or_look_up_is_refused_naming_the_key_and_the_choices() -> None:
    with pytest.raises(ConfigError) as colour:
        segment_pad(np.zeros((4, 4, 3), dtype=np.uint8), "purple")
    assert str(colour.value) == (
        "colour: 'purple' is not allowed; choose one of 'blue', 'green', 'yellow', 'red'"
    )
    samples = [np.array([[1.0, 10.0, 20.0], [2.0, 30.0, 40.0]])]
    with pytest.raises(ConfigError) as method:
        TofCameraCalibration(samples, method="linear")
    assert str(method.value) == (
        "method: 'linear' is not allowed; choose one of 'pchip', 'hyperbola', 'exact'"
    )
    with pytest.raises(ConfigError) as policy:
        TofCameraCalibration(samples, out_of_range="clip")
    assert str(policy.value) == (
        "out_of_range: 'clip' is not allowed; choose one of 'hyperbola', 'nan'"
    )


#: two sensors' samples off any hyperbola: PCHIP and the fit tell apart
BENT_SAMPLES = [
    np.array([[0.5, 100.0, 50.0], [1.0, 60.0, 45.0], [2.0, 55.0, 20.0], [3.0, 10.0, 18.0]]),
    np.array([[0.4, 200.0, 70.0], [1.5, 120.0, 66.0], [2.5, 110.0, 30.0]]),
]


def test_pchip_passes_through_its_samples_up_to_each_end_of_the_span() -> None:
    cal = TofCameraCalibration(BENT_SAMPLES)
    for k in range(3):
        out = cal.lookup(np.array([BENT_SAMPLES[0][k, 0], BENT_SAMPLES[1][k, 0]]))
        np.testing.assert_allclose(out.pixels, [BENT_SAMPLES[0][k, 1:], BENT_SAMPLES[1][k, 1:]])
        assert out.valid.all() and not out.out_of_range.any()
    ends = cal.lookup(np.array([3.0, 2.5]))
    np.testing.assert_allclose(ends.pixels, [[10.0, 18.0], [110.0, 30.0]])
    assert not ends.out_of_range.any()


def test_a_hyperbola_calibration_looks_up_its_fit_in_and_out_of_its_span_under_either_policy() -> (
    None
):
    ranges = np.array([1.2, 5.0])
    for policy in OUT_OF_RANGE_POLICIES:
        cal = TofCameraCalibration(BENT_SAMPLES, method="hyperbola", out_of_range=policy)
        out = cal.lookup(ranges)
        expected = [[cal.hyperbola_u[i](r), cal.hyperbola_v[i](r)] for i, r in enumerate(ranges)]
        np.testing.assert_allclose(out.pixels, expected, rtol=1e-12)
        assert out.valid.all()
        np.testing.assert_array_equal(out.out_of_range, [False, True])
    pchip = TofCameraCalibration(BENT_SAMPLES).lookup(ranges)
    assert np.all(np.abs(pchip.pixels[0] - out.pixels[0]) > 1.0)


def test_ranges_the_sensors_cannot_give_are_not_flagged_out_of_range() -> None:
    cal = TofCameraCalibration(BENT_SAMPLES + BENT_SAMPLES)
    out = cal.lookup(np.array([np.nan, -1.0, 0.0, np.inf]))
    assert not out.valid.any() and not out.out_of_range.any()
    # a reading for each sensor or nothing: another count has no pixels
    wrong = cal.lookup(np.array([1.0, 1.0]))
    assert wrong.pixels.shape == (4, 2) and np.all(np.isnan(wrong.pixels))
    assert wrong.valid.dtype == bool and wrong.out_of_range.dtype == bool
    assert not wrong.valid.any() and not wrong.out_of_range.any()


def test_an_exact_look_up_at_a_range_too_short_to_project_is_not_valid() -> None:
    out = _exact().lookup(np.array([1e-10, 1.0, 1.0, 1.0]))
    np.testing.assert_array_equal(out.valid, [False, True, True, True])
    assert np.all(np.isnan(out.pixels[0]))


def test_a_board_in_uneven_light_is_found() -> None:
    pattern = (4, 3)
    photo = _board_photo(pattern, (-20.0, 20.0)).astype(float)
    # the light falls to 30 % around a spot on the board's upper left
    yy, xx = np.mgrid[0 : photo.shape[0], 0 : photo.shape[1]]
    gain = 0.3 + 0.7 * np.clip(np.hypot(xx - 100.0, yy - 80.0) / 150.0, 0.0, 1.0)
    shaded = (photo * gain).astype(np.uint8)
    corners = find_chessboard(shaded, pattern)
    assert corners is not None
    np.testing.assert_allclose(corners, find_chessboard(photo.astype(np.uint8), pattern), atol=0.2)


def test_board_corners_are_refined_to_convergence_in_an_eleven_pixel_window() -> None:
    pattern = (4, 3)
    for tilt in [(-20.0, 20.0), (30.0, 30.0)]:
        photo = _board_photo(pattern, tilt)
        found, rough = cv2.findChessboardCorners(photo, pattern)
        assert found
        converged = cv2.cornerSubPix(
            photo, rough, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS, 0, 1e-9)
        ).reshape(-1, 2)
        # measured: within 3e-5 px; a 13-pixel window, or steps stopped under 1 px, 2e-3 px off
        np.testing.assert_allclose(find_chessboard(photo, pattern), converged, atol=5e-4)


def test_a_colour_photo_is_read_by_its_luminance(tmp_path: Path) -> None:
    pattern = (4, 3)
    tilts = [(0.0, 0.0), (25.0, 0.0), (-20.0, 20.0)]
    for i, tilt in enumerate(tilts):
        white = _board_photo(pattern, tilt).astype(float) / 255.0
        # the board printed red on dark blue: the two have the same grey if red and blue
        # are taken for each other (luminance weights red 0.299, blue 0.114)
        bgr = np.zeros((*white.shape, 3))
        bgr[..., 2] = 255.0 * white
        bgr[..., 0] = 97.0 * (1.0 - white)
        cv2.imwrite(str(tmp_path / f"view{i}.png"), bgr.astype(np.uint8))
    run = calibrate_from_images(image_files(tmp_path), pattern, 0.02)
    assert run.used == ("view0.png", "view1.png", "view2.png") and not run.rejected


def test_the_ranges_may_come_in_any_shape_holding_one_per_sensor() -> None:
    cal = TofCameraCalibration(BENT_SAMPLES + BENT_SAMPLES)
    ranges = np.array([0.7, 1.1, 2.6, 0.45])
    flat = cal.lookup(ranges)
    for shaped in (ranges.reshape(4, 1), ranges.reshape(2, 2), ranges.tolist()):
        out = cal.lookup(shaped)
        np.testing.assert_array_equal(out.pixels, flat.pixels)
        np.testing.assert_array_equal(out.out_of_range, flat.out_of_range)
