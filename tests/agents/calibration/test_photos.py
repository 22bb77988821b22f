"""``deck-landing calibrate intrinsics`` on photo files: K recovered, bad photos rejected."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from agents.cli import main
from estimation.frames import matrix_from_euler_zyx
from estimation.intrinsics_calibration import (
    IntrinsicsCalibrationResult,
    calibrate_from_images,
    image_files,
)
from tests.paths import DATA_DIR

K_TRUE = np.array([[520.0, 0.0, 319.5], [0.0, 518.0, 241.0], [0.0, 0.0, 1.0]])
SIZE = (640, 480)
PATTERN = (9, 6)
SQUARE_M = 0.025
PX_PER_SQUARE = 40


def _board_texture() -> np.ndarray:
    """A 10x7-square board (9x6 inner corners) with a white margin of one square."""
    cols, rows = PATTERN[0] + 1, PATTERN[1] + 1
    s = PX_PER_SQUARE
    board = np.full(((rows + 2) * s, (cols + 2) * s), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                board[(r + 1) * s : (r + 2) * s, (c + 1) * s : (c + 2) * s] = 0
    return board


def _photo(roll: float, pitch: float, yaw: float, distance_m: float) -> np.ndarray:
    """The board seen by the pinhole K_TRUE (no distortion), its centre on the optical axis."""
    texture = _board_texture()
    metres_per_px = SQUARE_M / PX_PER_SQUARE
    # texture pixel (u, v) -> board point (x, y, 0) with the first inner corner at the origin
    offset = PX_PER_SQUARE * 2 - 0.5
    a = np.array(
        [[metres_per_px, 0, -offset * metres_per_px], [0, metres_per_px, -offset * metres_per_px]]
    )
    centre = np.array([(PATTERN[0] - 1) * SQUARE_M / 2, (PATTERN[1] - 1) * SQUARE_M / 2, 0.0])
    rotation = matrix_from_euler_zyx(roll, pitch, yaw)
    t = np.array([0.0, 0.0, distance_m]) - rotation @ centre
    h_board = K_TRUE @ np.column_stack([rotation[:, 0], rotation[:, 1], t])
    h = h_board @ np.vstack([a, [0, 0, 1]])
    image = cv2.warpPerspective(
        texture, h, SIZE, flags=cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT, borderValue=255
    )
    return cv2.GaussianBlur(image, (3, 3), 0.6)


POSES = [
    (0.0, 0.0, 0.0, 0.45),
    (0.35, 0.0, 0.1, 0.5),
    (-0.35, 0.1, -0.1, 0.5),
    (0.0, 0.4, 0.2, 0.5),
    (0.1, -0.4, 0.0, 0.55),
    (0.3, 0.3, 0.5, 0.5),
    (-0.3, -0.3, -0.4, 0.55),
    (0.2, -0.2, 1.2, 0.48),
]


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("photos")
    for i, pose in enumerate(POSES):
        cv2.imwrite(str(folder / f"view{i:02d}.png"), _photo(*pose))
    cv2.imwrite(str(folder / "blank.png"), np.full((SIZE[1], SIZE[0]), 200, np.uint8))
    cv2.imwrite(str(folder / "small.png"), np.full((240, 320), 200, np.uint8))
    (folder / "corrupt.jpg").write_bytes(b"\xff\xd8\xff\xe0 not a jpeg")
    (folder / "notes.txt").write_text("ignored: not an image")
    return folder


def test_photos_recover_the_camera_matrix_and_name_every_rejected_photo(photos: Path) -> None:
    run = calibrate_from_images(image_files(photos), PATTERN, SQUARE_M)
    k = run.result.K
    # the focal lengths to 0.5 %, the principal point (less well seen in 8 photos) to 2 px
    assert abs(k[0, 0] - 520.0) / 520.0 < 0.005 and abs(k[1, 1] - 518.0) / 518.0 < 0.005
    assert abs(k[0, 2] - 319.5) < 2.0 and abs(k[1, 2] - 241.0) < 2.0
    assert run.result.rms_reprojection_error < 0.2
    assert len(run.result.per_view_errors) == len(POSES) == len(run.used)
    rejected = dict(run.rejected)
    assert set(rejected) == {"blank.png", "small.png", "corrupt.jpg"}
    assert "cannot be read" in rejected["corrupt.jpg"]
    assert "320x240 differs from 640x480" in rejected["small.png"]
    assert "no 9x6 chessboard found" in rejected["blank.png"]


def test_the_command_writes_a_versioned_file_that_refuses_another_camera(
    photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "intrinsics.json"
    summary = tmp_path / "summary.json"
    code = main(
        [
            "calibrate",
            "intrinsics",
            "--images",
            str(photos),
            "--pattern",
            "9x6",
            "--square",
            str(SQUARE_M),
            "--out",
            str(out),
            "--summary",
            str(summary),
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "RMS reprojection error" in printed and "rejected blank.png" in printed
    doc = json.loads(out.read_text())
    assert doc["format_version"] == 2 and doc["camera_model"] == "pinhole-radtan"
    assert json.loads(summary.read_text())["rejected"]["corrupt.jpg"]
    result = IntrinsicsCalibrationResult.load(out)
    result.require_camera((640, 480))
    with pytest.raises(ValueError, match=r"image size 640x480, but the images are 512x512"):
        result.require_camera((512, 512))
    with pytest.raises(ValueError, match="camera model 'pinhole-radtan', not 'fisheye'"):
        result.require_camera((640, 480), camera_model="fisheye")


def test_an_unknown_model_or_version_in_a_file_is_refused(photos: Path, tmp_path: Path) -> None:
    run = calibrate_from_images(image_files(photos), PATTERN, SQUARE_M)
    path = tmp_path / "k.json"
    run.result.save(path)
    doc = json.loads(path.read_text())
    path.write_text(json.dumps({**doc, "camera_model": "fisheye"}))
    with pytest.raises(ValueError, match="camera_model 'fisheye' is unknown"):
        IntrinsicsCalibrationResult.load(path)
    path.write_text(json.dumps({**doc, "format_version": 7}))
    with pytest.raises(ValueError, match="unsupported format_version 7"):
        IntrinsicsCalibrationResult.load(path)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--pattern", "9by6", "--square", "0.02"], "expected COLSxROWS"),
        (["--pattern", "9x6", "--square", "-1"], "positive number of metres"),
    ],
)
def test_bad_arguments_are_refused_by_name(
    photos: Path, args: list[str], message: str, capsys: pytest.CaptureFixture
) -> None:
    with pytest.raises(SystemExit):
        main(["calibrate", "intrinsics", "--images", str(photos), *args])
    assert message in capsys.readouterr().err


def test_a_folder_without_enough_boards_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    cv2.imwrite(str(tmp_path / "blank.png"), np.zeros((48, 64), np.uint8))
    code = main(
        ["calibrate", "intrinsics", "--images", str(tmp_path), "--pattern", "9x6", "--square", "1"]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "need at least 3 usable photos" in err and "blank.png" in err


OPENCV_PHOTOS = DATA_DIR / "opencv_chessboard"
#: OpenCV's calibration sample on its 13 ``left??.jpg`` photos, 9x6, as widely quoted (README)
OPENCV_K = {"fx": 532.795, "fy": 532.919, "cx": 342.458, "cy": 233.901}
OPENCV_DIST = (-0.28109, 0.02726, 0.00122, -0.00013, 0.15851)


def test_opencvs_sample_photos_give_opencvs_published_calibration() -> None:
    run = calibrate_from_images(image_files(OPENCV_PHOTOS), (9, 6), 0.025)
    assert len(run.used) == 12 and not run.rejected
    k = run.result.K
    # twelve of the thirteen photos (left14 is missing): the focal lengths to 0.05 %, the
    # principal point to 1 px, and every pixel within half the image height of the centre on
    # a ray within 1 px of OpenCV's (principal point and distortion together)
    assert abs(k[0, 0] - OPENCV_K["fx"]) / OPENCV_K["fx"] < 5e-4
    assert abs(k[1, 1] - OPENCV_K["fy"]) / OPENCV_K["fy"] < 5e-4
    assert abs(k[0, 2] - OPENCV_K["cx"]) < 1.0 and abs(k[1, 2] - OPENCV_K["cy"]) < 1.0
    angles = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    ring = np.stack([320.0 + 240.0 * np.cos(angles), 240.0 + 240.0 * np.sin(angles)], axis=1)
    k_opencv = np.array(
        [[OPENCV_K["fx"], 0.0, OPENCV_K["cx"]], [0.0, OPENCV_K["fy"], OPENCV_K["cy"]], [0, 0, 1]]
    )
    ours = cv2.undistortPoints(ring[:, None, :], k, run.result.dist[:5])[:, 0]
    theirs = cv2.undistortPoints(ring[:, None, :], k_opencv, np.array(OPENCV_DIST))[:, 0]
    assert np.max(np.linalg.norm(ours - theirs, axis=1)) * OPENCV_K["fx"] < 1.0
    assert run.result.rms_reprojection_error < 0.3


def test_a_missing_images_folder_is_named_once(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    missing = tmp_path / "missing"
    code = main(
        [
            "calibrate",
            "intrinsics",
            "--images",
            str(missing),
            "--pattern",
            "9x6",
            "--square",
            "0.025",
        ]
    )
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err == f"deck-landing calibrate: error: --images {missing}: not a folder"
