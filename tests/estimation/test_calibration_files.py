"""A calibration file of another kind or version is refused, naming the file."""

from __future__ import annotations

import json
from pathlib import Path

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
