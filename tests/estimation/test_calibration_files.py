"""A calibration file of another kind or version is refused, naming the file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimation.camera_model import CameraIntrinsics
from estimation.frames import tof_positions_in_camera_frame
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_calibration import TofCameraCalibration


@pytest.mark.parametrize(
    ("cls", "kind"),
    [
        (TofCameraCalibration, "not a ToF–camera calibration file"),
        (IntrinsicsCalibrationResult, "not a camera-intrinsics file"),
    ],
)
def test_a_file_of_another_format_is_refused_naming_it(
    cls: type, kind: str, tmp_path: Path
) -> None:
    path = tmp_path / "other.json"
    path.write_text(json.dumps({"format": "deck-landing/something-else", "format_version": 1}))
    with pytest.raises(ValueError, match=rf"other\.json: {kind}"):
        cls.load(path)


def test_a_tof_calibration_of_an_unknown_version_is_refused_and_a_known_one_read(
    tmp_path: Path,
) -> None:
    path = tmp_path / "tof.json"
    k = CameraIntrinsics()
    calibration = TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), 0.04, 4.0)
    calibration.save(path)
    assert TofCameraCalibration.load(path).n_sensors == calibration.n_sensors
    doc = json.loads(path.read_text())
    path.write_text(json.dumps({**doc, "format_version": 9}))
    refused = r"tof\.json: unsupported format_version 9; readable: \(1, 2\)"
    with pytest.raises(ValueError, match=refused):
        TofCameraCalibration.load(path)


def test_a_tof_calibration_of_the_first_files_naming_its_version_as_version_is_read(
    tmp_path: Path,
) -> None:
    path = tmp_path / "tof.json"
    calibration = TofCameraCalibration.exact(
        CameraIntrinsics(), tof_positions_in_camera_frame(), 0.04, 4.0
    )
    calibration.save(path)
    doc = json.loads(path.read_text())
    doc["version"] = doc.pop("format_version")
    path.write_text(json.dumps(doc))
    assert TofCameraCalibration.load(path).n_sensors == calibration.n_sensors
    doc["version"] = 9
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"tof\.json: unsupported format_version 9"):
        TofCameraCalibration.load(path)


def _intrinsics_result(**changes: object) -> IntrinsicsCalibrationResult:
    fields: dict = {
        "K": np.array([[500.0, 0.0, 319.5], [0.0, 498.0, 241.25], [0.0, 0.0, 1.0]]),
        "dist": np.array([-0.2, 0.05, 0.001, -0.002, 0.01]),
        "rms_reprojection_error": 0.17,
        "per_view_errors": np.array([0.1, 0.2, 0.15]),
        "image_size": (640, 480),
        **changes,
    }
    return IntrinsicsCalibrationResult(**fields)


def test_an_intrinsics_file_saved_loads_back_with_every_field(tmp_path: Path) -> None:
    path = tmp_path / "intrinsics.json"
    metadata = {"source": "photos", "photos_used": ["a.png", "b.png", "c.png"]}
    result = _intrinsics_result(metadata=metadata)
    result.save(path)
    doc = json.loads(path.read_text())
    assert doc == {
        "format": "deck-landing/camera-intrinsics",
        "format_version": 2,
        "camera_model": "pinhole-radtan",
        "image_size": [640, 480],
        "camera_matrix": result.K.tolist(),
        "dist": result.dist.tolist(),
        "rms_reprojection_error_px": 0.17,
        "per_view_errors_px": [0.1, 0.2, 0.15],
        "metadata": metadata,
    }
    loaded = IntrinsicsCalibrationResult.load(path)
    np.testing.assert_array_equal(loaded.K, result.K)
    np.testing.assert_array_equal(loaded.dist, result.dist)
    np.testing.assert_array_equal(loaded.per_view_errors, result.per_view_errors)
    assert loaded.rms_reprojection_error == 0.17
    assert loaded.image_size == (640, 480) and isinstance(loaded.image_size[0], int)
    assert loaded.metadata == metadata and loaded.tag_corners is None
    assert loaded.camera_model == "pinhole-radtan"


def test_a_version_1_intrinsics_file_reads_as_pinhole_radtan_without_metadata(
    tmp_path: Path,
) -> None:
    path = tmp_path / "v1.json"
    _intrinsics_result().save(path)
    doc = json.loads(path.read_text())
    old = {k: v for k, v in doc.items() if k not in ("format_version", "camera_model", "metadata")}
    path.write_text(json.dumps({**old, "version": 1}))
    loaded = IntrinsicsCalibrationResult.load(path)
    assert loaded.camera_model == "pinhole-radtan" and loaded.metadata == {}
    np.testing.assert_array_equal(loaded.K, _intrinsics_result().K)
    path.write_text(json.dumps({**doc, "camera_model": "fisheye"}))
    with pytest.raises(ValueError) as refused:
        IntrinsicsCalibrationResult.load(path)
    assert str(refused.value) == f"{path}: camera_model 'fisheye' is unknown; known: pinhole-radtan"


def test_an_intrinsics_result_is_the_camera_model_of_its_matrix_and_first_five_coefficients() -> (
    None
):
    camera = _intrinsics_result().to_intrinsics()
    assert camera == CameraIntrinsics(
        width=640, height=480, fx=500.0, fy=498.0, cx=319.5, cy=241.25,
        dist=(-0.2, 0.05, 0.001, -0.002, 0.01),
    )  # fmt: skip
    # four coefficients (no k3) end in a zero k3; OpenCV's rational model's eight keep five
    four = _intrinsics_result(dist=np.array([-0.2, 0.05, 0.001, -0.002]))
    assert four.to_intrinsics().dist == (-0.2, 0.05, 0.001, -0.002, 0.0)
    eight = _intrinsics_result(dist=np.arange(1.0, 9.0))
    assert eight.to_intrinsics().dist == (1.0, 2.0, 3.0, 4.0, 5.0)


def test_an_intrinsics_result_refuses_another_camera_naming_every_mismatch() -> None:
    result = _intrinsics_result()
    result.require_camera((640, 480))
    result.require_camera((640.0, 480.0))
    with pytest.raises(ValueError) as size:
        result.require_camera((512, 512))
    assert str(size.value) == (
        "the calibration is for another camera: image size 640x480, but the images are 512x512"
    )
    with pytest.raises(ValueError) as both:
        result.require_camera((480, 640), "fisheye", source="k.json", images="the frames")
    assert str(both.value) == (
        "k.json is for another camera: camera model 'pinhole-radtan', not 'fisheye'; "
        "image size 640x480, but the frames are 480x640"
    )


def test_a_tof_calibration_saved_loads_back_with_its_settings_and_samples(tmp_path: Path) -> None:
    path = tmp_path / "tof.json"
    samples = [np.array([[1.0, 10.0, 20.0], [2.0, 30.0, 40.0], [4.0, 35.0, 45.0]])] * 4
    cal = TofCameraCalibration(
        samples, method="hyperbola", out_of_range="nan", metadata={"rig": "bench"},
        image_size=(640, 480),
    )  # fmt: skip
    cal.save(path)
    doc = json.loads(path.read_text())
    assert doc == {
        "format": "deck-landing/tof-camera-calibration",
        "format_version": 2,
        "image_size": [640, 480],
        "method": "hyperbola",
        "out_of_range": "nan",
        "metadata": {"rig": "bench"},
        "sensors": [{"range_m": [1.0, 2.0, 4.0], "u_px": [10.0, 30.0, 35.0],
                     "v_px": [20.0, 40.0, 45.0]}] * 4,
    }  # fmt: skip
    loaded = TofCameraCalibration.load(path)
    assert (loaded.method, loaded.out_of_range) == ("hyperbola", "nan")
    assert loaded.metadata == {"rig": "bench"} and loaded.image_size == (640, 480)
    for a, b in zip(loaded.samples, cal.samples, strict=True):
        np.testing.assert_array_equal(a, b)
    del doc["metadata"], doc["image_size"]
    path.write_text(json.dumps(doc))
    bare = TofCameraCalibration.load(path)
    assert bare.metadata == {} and bare.image_size is None


def test_an_exact_tof_calibration_saved_loads_back_exact(tmp_path: Path) -> None:
    path = tmp_path / "tof.json"
    k = CameraIntrinsics(width=320, height=240, fx=300.0, fy=290.0, cx=160.0, cy=120.0)
    positions = tof_positions_in_camera_frame()
    TofCameraCalibration.exact(k, positions, 0.3, 4.0).save(path)
    doc = json.loads(path.read_text())
    assert doc["exact_model"] == {"intrinsics": k.as_dict(), "tof_positions_c": positions.tolist()}
    loaded = TofCameraCalibration.load(path)
    assert loaded.method == "exact" and loaded.image_size == (320, 240)
    ranges = np.array([0.1, 1.0, 2.0, 9.0])  # outside the samples too: the analytic map
    out = loaded.lookup(ranges)
    np.testing.assert_allclose(out.pixels[:, 0], 300.0 * positions[:, 0] / ranges + 160.0)
    np.testing.assert_allclose(out.pixels[:, 1], 290.0 * positions[:, 1] / ranges + 120.0)
    doc["exact_model"]["intrinsics"].pop("fx")
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as refused:
        TofCameraCalibration.load(path)
    assert str(refused.value) == f"{path}: exact_model.intrinsics: missing key 'fx'"


@pytest.mark.parametrize(
    "image_size",
    [[640], [640, 480, 3], [0, 480], [640, -1], [640.0, 480], "640x480", {"w": 640}, 640],
)
def test_a_tof_calibrations_image_size_must_be_two_positive_pixel_counts(
    image_size: object, tmp_path: Path
) -> None:
    path = tmp_path / "tof.json"
    samples = [np.array([[1.0, 10.0, 20.0], [2.0, 30.0, 40.0]])] * 4
    TofCameraCalibration(samples).save(path)
    doc = json.loads(path.read_text())
    assert doc["image_size"] is None
    path.write_text(json.dumps({**doc, "image_size": image_size}))
    with pytest.raises(ValueError) as refused:
        TofCameraCalibration.load(path)
    assert str(refused.value) == (
        f"{path}: image_size {image_size!r} must be [width, height] in pixels"
    )


def test_image_sizes_given_as_floats_are_kept_and_named_as_whole_pixels(tmp_path: Path) -> None:
    path = tmp_path / "tof.json"
    samples = [np.array([[1.0, 10.0, 20.0], [2.0, 30.0, 40.0]])] * 4
    TofCameraCalibration(samples, image_size=(640.0, 480.0)).save(path)
    assert TofCameraCalibration.load(path).image_size == (640, 480)
    TofCameraCalibration(samples, image_size=(1, 1)).save(path)
    assert TofCameraCalibration.load(path).image_size == (1, 1)
    tof = TofCameraCalibration(samples, image_size=(640, 480))
    with pytest.raises(ValueError, match=r"but the images are 320x240$"):
        tof.require_camera((320.0, 240.0))
    with pytest.raises(ValueError, match=r"but the images are 320x240$"):
        _intrinsics_result().require_camera((320.0, 240.0))


def test_an_intrinsics_file_written_with_whole_numbers_loads_as_floats_and_pixels(
    tmp_path: Path,
) -> None:
    path = tmp_path / "intrinsics.json"
    doc = {
        "format": "deck-landing/camera-intrinsics",
        "format_version": 2,
        "image_size": [640.0, 480.0],
        "camera_matrix": [[500, 0, 320], [0, 500, 240], [0, 0, 1]],
        "dist": [0, 0, 0, 0, 0],
        "rms_reprojection_error_px": 1,
        "per_view_errors_px": [1, 1, 1],
    }
    path.write_text(json.dumps(doc))
    loaded = IntrinsicsCalibrationResult.load(path)
    for array in (loaded.K, loaded.dist, loaded.per_view_errors):
        assert array.dtype == np.float64
    assert isinstance(loaded.rms_reprojection_error, float)
    assert loaded.image_size == (640, 480) and all(type(v) is int for v in loaded.image_size)
