"""``deck-landing calibrate tof --recording``: a rig's recording folder to the ToF–camera
calibration, the simulated rig through the same function, and bad input named."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from agents.cli import main
from agents.io.recording import RecordingError, write_folder
from agents.io.tof_rig import (
    calibrate_tof_recording,
    intrinsics_file,
    read_rig_recording,
    rig_file,
    write_rig_recording,
)
from estimation.camera_model import CameraIntrinsics
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_calibration import PAD_COLOURS, TofCameraCalibration
from estimation.tof_rig import (
    RIG_FILE,
    RigFrame,
    RigStage,
    StageWindow,
    TofRigDescription,
    TofRigError,
    calibrate_rig,
    pad_centroid_in_image,
    reading_rows,
)
from landing_env.calibration.tof_camera_sim import (
    TofRigConfig,
    calibrate_tof_camera_in_sim,
    record_tof_rig_in_sim,
)
from landing_env.config import load_config

# a small synthetic rig: 160x120 pinhole, sensors 5 cm off the optical axis
CAMERA = CameraIntrinsics(width=160, height=120, fx=100.0, fy=100.0, cx=79.5, cy=59.5)
MOUNTS_C = np.array(
    [[-0.05, -0.05, 0.0], [0.05, -0.05, 0.0], [0.05, 0.05, 0.0], [-0.05, 0.05, 0.0]]
)
RGB = {"blue": (0, 0, 255), "green": (0, 255, 0), "yellow": (255, 255, 0), "red": (255, 0, 0)}
RANGES_M = (0.4, 0.6, 0.9, 1.3)
READINGS = 4


def _pad_image(range_m: float, camera: CameraIntrinsics = CAMERA) -> np.ndarray:
    """Grey floor, a disc of each pad colour centred on its sensor's touch-point pixel."""
    image = np.full((camera.height, camera.width, 3), 128, np.uint8)
    points = np.column_stack([MOUNTS_C[:, :2], np.full(4, range_m)])
    radius = 0.02 * camera.fx / range_m
    for (u, v), colour in zip(camera.project(points), PAD_COLOURS, strict=True):
        # 4 fractional bits: the disc's centre to 1/16 px
        centre = (round(u * 16), round(v * 16))
        cv2.circle(image, centre, round(radius * 16), RGB[colour], -1, cv2.LINE_8, 4)
    return image


def _synthetic_rig(camera: CameraIntrinsics = CAMERA) -> tuple[list[RigStage], TofRigDescription]:
    stages, windows = [], []
    for k, r in enumerate(RANGES_M):
        t0 = float(k)
        stamps = np.array([t0 + 0.1 * (j + 1) for j in range(READINGS)])
        readings = np.full(READINGS, r)
        readings[0] = np.nan  # one reading without a return: the other three are averaged
        frame = RigFrame(t0, f"pads_{k}.png", _pad_image(r, camera))
        stages.append(RigStage((frame,), (stamps,) * 4, (readings,) * 4))
        windows.append(StageWindow(t0, t0 + 0.5, r))
    description = TofRigDescription(
        stages=tuple(windows),
        min_pad_area_px=4.0,
        camera=camera,
        tof_mount_offsets_c=tuple(tuple(row) for row in MOUNTS_C.tolist()),
        metadata={"source": "test"},
    )
    return stages, description


@pytest.fixture
def rig_folder(tmp_path: Path) -> Path:
    stages, description = _synthetic_rig()
    return write_rig_recording(tmp_path / "rig", stages, description)


def _calibrate(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str]:
    code = main(["calibrate", "tof", *args])
    return code, capsys.readouterr().err


def test_pads_drawn_at_the_touch_points_give_those_pixels_back(
    rig_folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "out"
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", str(out))
    assert code == 0, err
    cal = TofCameraCalibration.load(out / "tof_camera.json")
    assert cal.image_size == (CAMERA.width, CAMERA.height)
    assert cal.metadata["camera"] == CAMERA.as_dict()
    assert np.allclose(cal.metadata["tof_mount_offsets_c"], MOUNTS_C)
    exact = TofCameraCalibration.exact(CAMERA, MOUNTS_C, 0.3, 1.5)
    for i, samples in enumerate(cal.samples):
        # every stage kept, the range the mean of the three valid readings
        np.testing.assert_allclose(samples[:, 0], RANGES_M, rtol=1e-15)
        truth = np.array([exact.lookup(np.full(4, r)).pixels[i] for r in RANGES_M])
        # the centroid of the hull of a rasterised disc's border pixels: within a fifth of a
        # pixel of the disc's centre (measured: up to 0.13 px, the small near-stage discs)
        assert np.abs(samples[:, 1:] - truth).max() < 0.2
    summary = json.loads((out / "summary.json").read_text())
    assert [s["samples"] for s in summary["sensors"]] == [4, 4, 4, 4]


def test_the_simulated_rig_gives_the_same_calibration_through_its_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """In the simulator, and written as a recording folder then `calibrate tof --recording`:
    the same file, byte for byte (images are PNG, stamps and ranges exact decimal text).
    The sensors are noisy and miss returns, so the averaging goes through the CSV too."""
    config = load_config("default", overrides={"tof.noise": "vl53l1x"})
    rig = TofRigConfig(stages=8, readings_per_stage=5)
    in_sim = calibrate_tof_camera_in_sim(config, rig, np.random.default_rng(7))
    rig = record_tof_rig_in_sim(config, rig, np.random.default_rng(7))
    folder = write_rig_recording(tmp_path / "rig", rig.stages, rig.description)
    out = tmp_path / "out"
    code, err = _calibrate(capsys, "--recording", str(folder), "--out", str(out))
    assert code == 0, err
    in_sim.calibration.save(tmp_path / "in_sim.json")
    assert (out / "tof_camera.json").read_text() == (tmp_path / "in_sim.json").read_text()
    # the readings were noisy: averaging mattered
    readings = np.concatenate([s.readings_m[0] for s in rig.stages])
    assert np.nanstd(readings[:5]) > 0.0


def test_calibrate_command_records_the_rig_and_calibrates_from_the_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from agents.calibration.simulated import run_calibration

    run = run_calibration(out_dir=tmp_path, views=4, stages=4, progress=False)
    folder = run.files["tof_rig"]
    assert (folder / RIG_FILE).is_file() and (folder / "ranges.csv").is_file()
    code, err = _calibrate(capsys, "--recording", str(folder), "--out", str(tmp_path / "again"))
    assert code == 0, err
    again = (tmp_path / "again" / "tof_camera.json").read_text()
    assert again == run.files["tof_camera"].read_text()


def test_a_missing_folder_is_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    code, err = _calibrate(capsys, "--recording", str(tmp_path / "nowhere"), "--out", "x")
    assert code == 2
    assert "nowhere: not a folder" in err


def test_a_missing_rig_file_or_ranges_file_is_named(
    rig_folder: Path, capsys: pytest.CaptureFixture
) -> None:
    (rig_folder / "ranges.csv").unlink()
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2 and "no ranges.csv" in err
    (rig_folder / RIG_FILE).unlink()
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2 and f"no {RIG_FILE}" in err


def test_a_missing_csv_column_is_named(rig_folder: Path, capsys: pytest.CaptureFixture) -> None:
    lines = (rig_folder / "ranges.csv").read_text().splitlines()
    cut = [",".join(line.split(",")[:4]) for line in lines]
    (rig_folder / "ranges.csv").write_text("\n".join(cut) + "\n")
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2
    assert "ranges.csv: missing column(s) range_4_m" in err


def _intrinsics_file(path: Path, focal_px: float, size: tuple[int, int]) -> Path:
    """An intrinsics calibration file: focal length ``focal_px``, the principal point at the
    centre of an image of ``size`` (width, height), no distortion."""
    width, height = size
    IntrinsicsCalibrationResult(
        K=np.array([[focal_px, 0, (width - 1) / 2], [0, focal_px, (height - 1) / 2], [0, 0, 1]]),
        dist=np.zeros(5),
        rms_reprojection_error=0.1,
        per_view_errors=np.zeros(3),
        image_size=size,
    ).save(path)
    return path


def test_images_of_another_size_than_the_intrinsics_are_refused(
    rig_folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    intrinsics = _intrinsics_file(tmp_path / "intrinsics.json", 500.0, (640, 480))
    args = ("--recording", str(rig_folder), "--calibration", str(intrinsics), "--out", "x")
    code, err = _calibrate(capsys, *args)
    assert code == 2
    assert f"{intrinsics} is for another camera: image size 640x480" in err
    assert "pads_0.png" in err and "160x120" in err


def test_an_image_of_another_size_than_the_rig_files_camera_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    stages, description = _synthetic_rig()
    small = CameraIntrinsics(width=80, height=60, fx=50.0, fy=50.0, cx=39.5, cy=29.5)
    frame = RigFrame(3.0, "pads_3.png", _pad_image(RANGES_M[3], small))
    stages[3] = RigStage((frame,), stages[3].reading_t_s, stages[3].readings_m)
    folder = write_rig_recording(tmp_path / "rig", stages, description)
    code, err = _calibrate(capsys, "--recording", str(folder), "--out", "x")
    assert code == 2
    assert "pads_3.png: image is 80x60, the camera model is 160x120" in err


def test_too_few_stages_are_refused_naming_the_rig_file(
    rig_folder: Path, capsys: pytest.CaptureFixture
) -> None:
    doc = json.loads((rig_folder / RIG_FILE).read_text())
    doc["stages"] = doc["stages"][:1]
    (rig_folder / RIG_FILE).write_text(json.dumps(doc))
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2
    assert f"{RIG_FILE}: stages: 1 given; at least 2 are needed" in err


def test_a_stage_without_a_frame_is_named(rig_folder: Path, capsys: pytest.CaptureFixture) -> None:
    (rig_folder / "pads_2.png").unlink()  # its frame is skipped by the reader
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2
    assert "stages[2] (2.0 to 2.5 s): no frame of frames.csv in it" in err
    assert "image missing or unreadable" in err


def test_overlapping_or_malformed_windows_are_named(
    rig_folder: Path, capsys: pytest.CaptureFixture
) -> None:
    doc = json.loads((rig_folder / RIG_FILE).read_text())
    doc["stages"][1]["t_start_s"] = 0.2
    (rig_folder / RIG_FILE).write_text(json.dumps(doc))
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2 and "stages[1] starts at 0.2 s, not after stages[0] ends" in err
    doc["stages"][1] = {"t_start_s": 1.0}
    (rig_folder / RIG_FILE).write_text(json.dumps(doc))
    code, err = _calibrate(capsys, "--recording", str(rig_folder), "--out", "x")
    assert code == 2 and "stages[1]: need an object with t_start_s and t_end_s" in err


def test_too_few_usable_stages_name_the_sensor_and_why(tmp_path: Path) -> None:
    stages, description = _synthetic_rig()
    # the red pad painted over in all but one stage
    for k in range(1, len(stages)):
        image = stages[k].frames[0].image.copy()
        image[np.all(image == RGB["red"], axis=2)] = 128
        frame = RigFrame(stages[k].frames[0].t_s, "grey.png", image)
        stages[k] = RigStage((frame,), stages[k].reading_t_s, stages[k].readings_m)
    with pytest.raises(ValueError, match=r"sensor 4 \(red pad\): 1; at least 2") as error:
        calibrate_rig(stages, description)
    assert "'pad_not_found': [0, 0, 0, 3]" in str(error.value)


def test_sensors_with_too_few_returns_are_skipped_and_counted() -> None:
    stages, description = _synthetic_rig()
    k = 1
    half_missing = stages[k].readings_m[0].copy()
    half_missing[1] = np.nan  # two of four left: still kept (at least half)
    most_missing = half_missing.copy()
    most_missing[2] = np.nan  # one of four: skipped
    readings = (half_missing, most_missing, *stages[k].readings_m[2:])
    stages[k] = RigStage(stages[k].frames, stages[k].reading_t_s, readings)
    result = calibrate_rig(stages, description)
    assert result.skipped["range_invalid"] == [0, 1, 0, 0]
    assert result.ranges[k, 0] == pytest.approx(RANGES_M[k]) and np.isnan(result.ranges[k, 1])


def test_grey_images_are_refused_naming_the_file(tmp_path: Path) -> None:
    stages, description = _synthetic_rig()
    grey = cv2.cvtColor(stages[0].frames[0].image, cv2.COLOR_RGB2GRAY)
    stages[0] = RigStage(
        (RigFrame(0.0, "grey.png", grey),), stages[0].reading_t_s, stages[0].readings_m
    )
    with pytest.raises(ValueError, match=r"grey\.png: the pads are found by colour"):
        calibrate_rig(stages, description)


def test_the_calibration_file_is_versioned_and_version_1_still_reads(tmp_path: Path) -> None:
    stages, description = _synthetic_rig()
    cal = calibrate_rig(stages, description).calibration
    cal.save(tmp_path / "v2.json")
    doc = json.loads((tmp_path / "v2.json").read_text())
    assert doc["format_version"] == 2 and doc["image_size"] == [160, 120]
    old = {k: v for k, v in doc.items() if k not in ("format_version", "image_size")}
    (tmp_path / "v1.json").write_text(json.dumps({**old, "version": 1}))
    v1 = TofCameraCalibration.load(tmp_path / "v1.json")
    assert v1.image_size is None
    for a, b in zip(v1.samples, cal.samples, strict=True):
        np.testing.assert_array_equal(a, b)
    (tmp_path / "v3.json").write_text(json.dumps({**doc, "format_version": 3}))
    with pytest.raises(ValueError, match="unsupported format_version 3"):
        TofCameraCalibration.load(tmp_path / "v3.json")
    with pytest.raises(ValueError, match="image size 160x120, but the images are 640x480"):
        cal.require_camera((640, 480))


def test_estimate_refuses_a_tof_calibration_made_for_another_image_size(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    pytest.importorskip("mcap_ros2")
    stages, description = _synthetic_rig()
    calibration = tmp_path / "cal"
    calibration.mkdir()
    calibrate_rig(stages, description).calibration.save(calibration / "tof_camera.json")
    # a recording of 80x60 frames, with intrinsics that fit them
    small = CameraIntrinsics(width=80, height=60, fx=50.0, fy=50.0, cx=39.5, cy=29.5)
    IntrinsicsCalibrationResult(
        K=small.matrix,
        dist=np.zeros(5),
        rms_reprojection_error=0.1,
        per_view_errors=np.zeros(3),
        image_size=(80, 60),
    ).save(calibration / "intrinsics.json")
    frames = [RigFrame(0.0, "f0.png", _pad_image(0.5, small))]
    recording = write_rig_recording(
        tmp_path / "rec",
        [RigStage(tuple(frames), (np.array([0.0]),) * 4, (np.array([0.5]),) * 4)],
        description,
    )
    code = main(
        ["estimate", "--input", str(recording), "--estimator", "ihrcf",
         "--calibration", str(calibration), "--out", str(tmp_path / "o.csv")]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "tof_camera.json is for another camera: image size 160x120" in err
    assert "the images are 80x60" in err


def test_fuzzed_rig_files_give_a_named_error_or_load(rig_folder: Path) -> None:
    """Random values put in each field of a valid rig file: it loads, or a TofRigError
    names the file; nothing else is raised."""
    doc = json.loads((rig_folder / RIG_FILE).read_text())
    junk = [None, "x", -1, 0, 1e308, float("nan"), [], {}, [1, 2], [[1, 2, 3]] * 4, True]
    rng = np.random.default_rng(0)
    path = rig_folder / RIG_FILE
    fields = ["stages", "min_pad_area_px", "camera", "tof_mount_offsets_c", "tof_max_range_m",
              "metadata", "format_version", "stages.0", "stages.1.t_end_s",
              "camera.fx"]  # fmt: skip
    for _ in range(200):
        mutated = json.loads(json.dumps(doc))
        key = fields[rng.integers(len(fields))]
        value = junk[rng.integers(len(junk))]
        parts = key.split(".")
        target = mutated
        for part in parts[:-1]:
            target = target[int(part)] if isinstance(target, list) else target.setdefault(part, {})
        last = parts[-1]
        if isinstance(target, list):
            target[int(last)] = value
        else:
            target[last] = value
        path.write_text(json.dumps(mutated))
        try:
            TofRigDescription.load(path)
        except TofRigError as exc:
            assert str(path) in str(exc)


def test_a_rig_folders_frames_and_rows_go_to_the_stages_whose_window_holds_them_ends_included(
    tmp_path: Path,
) -> None:
    image = np.full((4, 6, 3), 90, np.uint8)
    stamps = [0.0, 1.0, 2.0, 2.5, 3.0, 4.0, 5.0]  # windows [1, 2] and [3, 4]
    frames = [(t, f"f{k}.png", image) for k, t in enumerate(stamps)]
    rows = [
        (t, [t, t + 0.1, t + 0.2, t + 0.3]) for t in sorted([0.5, *stamps, 6.0, 7.0]) if t != 2.5
    ]
    folder = write_folder(tmp_path / "rig", frames, rows)
    windows = (StageWindow(1.0, 2.0), StageWindow(3.0, 4.0))
    TofRigDescription(stages=windows).save(folder / RIG_FILE)
    stages, _, left_out = read_rig_recording(folder)
    assert [[(f.t_s, f.name) for f in s.frames] for s in stages] == [
        [(1.0, str(folder / "f1.png")), (2.0, str(folder / "f2.png"))],
        [(3.0, str(folder / "f4.png")), (4.0, str(folder / "f5.png"))],
    ]
    assert [[t.tolist() for t in s.reading_t_s] for s in stages] == [
        [[1.0, 2.0]] * 4, [[3.0, 4.0]] * 4,
    ]  # fmt: skip
    assert stages[1].readings_m[2].tolist() == [3.2, 4.2]
    assert left_out == {
        "frames.csv: frame outside every stage": 3,
        "ranges.csv: row outside every stage": 5,
    }
    # windows holding everything: nothing left out
    TofRigDescription(stages=(StageWindow(-1.0, 2.2), StageWindow(2.4, 8.0))).save(
        folder / RIG_FILE
    )
    assert read_rig_recording(folder)[2] == {}
    # a window with frames but no row, or no frame at all, is named exactly
    TofRigDescription(stages=(StageWindow(2.5, 2.6), StageWindow(3.0, 4.0))).save(folder / RIG_FILE)
    with pytest.raises(TofRigError) as refused:
        read_rig_recording(folder)
    assert (
        str(refused.value)
        == f"{folder / RIG_FILE}: stages[0] (2.5 to 2.6 s): no row of ranges.csv in it"
    )
    TofRigDescription(stages=(StageWindow(2.6, 2.7), StageWindow(3.0, 4.0))).save(folder / RIG_FILE)
    with pytest.raises(TofRigError) as refused:
        read_rig_recording(folder)
    assert str(refused.value).endswith("(2.6 to 2.7 s): no frame of frames.csv in it")


def test_a_missing_rig_file_or_intrinsics_file_is_named_exactly(tmp_path: Path) -> None:
    folder = write_folder(tmp_path / "rig", [], [])
    with pytest.raises(TofRigError) as refused:
        rig_file(folder)
    assert str(refused.value) == (
        f"{folder}: no {RIG_FILE} in the folder and no --stages-file FILE given "
        "(the rig's stage windows)"
    )
    mcap = tmp_path / "rig.mcap"
    with pytest.raises(TofRigError, match=f"rig.mcap: no {RIG_FILE} beside it and no"):
        rig_file(mcap)
    (tmp_path / "intrinsics.json").write_text("{}")
    assert intrinsics_file(tmp_path) == tmp_path / "intrinsics.json"
    with pytest.raises(RecordingError) as refused:
        intrinsics_file(folder)
    assert (
        str(refused.value) == f"--calibration {folder / 'intrinsics.json'}: no such intrinsics file"
    )


def test_the_intrinsics_given_are_the_camera_the_calibration_records_over_the_rig_files(
    rig_folder: Path, tmp_path: Path
) -> None:
    intrinsics = _intrinsics_file(tmp_path / "intrinsics.json", 110.0, (160, 120))
    result, _ = calibrate_tof_recording(rig_folder, intrinsics)
    assert (result.calibration.metadata["camera"]["fx"], CAMERA.fx) == (110.0, 100.0)


def test_a_stages_range_is_the_mean_of_its_finite_non_negative_readings_if_half_or_more() -> None:
    stages, description = _synthetic_rig()
    nan, inf = np.nan, np.inf
    five = {
        0: [0.0, 0.75, 0.75, 0.0, nan],  # a range of 0 m is a return: four of five, mean 0.375
        1: [-1.0, inf, 0.6, 0.6, 0.6],  # negative or infinite: no return
        2: [0.9, 0.9, nan, nan, nan],  # two of five: fewer than half, skipped
        3: [0.5, 0.7, 0.6, nan, nan],
    }
    stamps = np.arange(5.0) * 0.1 + 1.0
    stages[1] = RigStage(
        stages[1].frames, (stamps,) * 4, tuple(np.array(five[i]) for i in range(4))
    )
    # a stage of one reading per sensor keeps it (the third sensor has none there)
    one = [np.array([0.95]), np.array([0.95]), np.array([nan]), np.array([0.95])]
    stages[2] = RigStage(stages[2].frames, (np.array([2.0]),) * 4, tuple(one))
    result = calibrate_rig(stages, description)
    np.testing.assert_array_equal(result.ranges[1], [0.375, 0.6, nan, 0.6])
    np.testing.assert_array_equal(result.ranges[2], [0.95, 0.95, nan, 0.95])
    assert result.skipped["range_invalid"] == [0, 0, 2, 0]
    # a skipped stage's pixels are NaN, as its range is
    assert np.isnan(result.pixels[1, 2]).all() and np.isnan(result.pixels[2, 2]).all()


def test_a_stages_pad_centroid_is_the_mean_over_the_frames_that_show_the_pad() -> None:
    stages, description = _synthetic_rig()
    base = calibrate_rig(stages, description).pixels
    k = 1
    shown = stages[k].frames[0]
    no_red = shown.image.copy()
    no_red[np.all(no_red == RGB["red"], axis=2)] = 128
    moved = np.roll(shown.image, 2, axis=1)  # every pad 2 px to the right
    frames = (
        RigFrame(shown.t_s, "no_red.png", no_red),
        shown,
        RigFrame(shown.t_s + 0.2, "moved.png", moved),
    )
    stages[k] = RigStage(frames, stages[k].reading_t_s, stages[k].readings_m)
    # and the blue pad (the first sensor's) painted over in the next stage's only frame
    no_blue = stages[k + 1].frames[0].image.copy()
    no_blue[np.all(no_blue == RGB["blue"], axis=2)] = 128
    only = RigFrame(stages[k + 1].frames[0].t_s, "no_blue.png", no_blue)
    stages[k + 1] = RigStage((only,), stages[k + 1].reading_t_s, stages[k + 1].readings_m)
    result = calibrate_rig(stages, description)
    pixels = result.pixels
    # the red pad from two frames (1 px on average), the others from three (2/3 px)
    np.testing.assert_allclose(pixels[k, :3], base[k, :3] + [2.0 / 3.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(pixels[k, 3], base[k, 3] + [1.0, 0.0], atol=1e-9)
    assert np.isnan(pixels[k + 1, 0]).all() and np.isnan(result.ranges[k + 1, 0])
    np.testing.assert_array_equal(pixels[k + 1, 1:], base[k + 1, 1:])
    np.testing.assert_array_equal(pixels[[0, 3]], base[[0, 3]])
    assert result.skipped["pad_not_found"] == [1, 0, 0, 0]


def test_two_stages_calibrate_and_fewer_or_malformed_ones_are_refused_by_name() -> None:
    stages, description = _synthetic_rig()
    two = calibrate_rig(stages[:2], description)
    assert [len(s) for s in two.calibration.samples] == [2, 2, 2, 2]
    with pytest.raises(TofRigError) as refused:
        calibrate_rig(stages[:1], description)
    assert str(refused.value) == "1 stage(s); at least 2 are needed"
    empty = [stages[0], RigStage((), stages[1].reading_t_s, stages[1].readings_m)]
    with pytest.raises(TofRigError) as refused:
        calibrate_rig(empty, description)
    assert str(refused.value) == "stage 1: no camera frame"
    three = [
        stages[0],
        RigStage(stages[1].frames, stages[1].reading_t_s[:3], stages[1].readings_m[:3]),
    ]
    with pytest.raises(TofRigError) as refused:
        calibrate_rig(three, description)
    assert str(refused.value) == "stage 1: 3 sensors; need 4"
    # no camera model: every image the size of the first
    small = CameraIntrinsics(width=80, height=60, fx=50.0, fy=50.0, cx=39.5, cy=29.5)
    stages[3] = RigStage(
        (RigFrame(3.0, "pads_3.png", _pad_image(RANGES_M[3], small)),),
        stages[3].reading_t_s,
        stages[3].readings_m,
    )
    with pytest.raises(TofRigError) as refused:
        calibrate_rig(stages, TofRigDescription(stages=description.stages, min_pad_area_px=4.0))
    assert str(refused.value) == "pads_3.png: image is 80x60, the first was 160x120"


def test_sensors_short_of_two_stages_are_all_named_with_the_skips() -> None:
    stages, description = _synthetic_rig()
    image = stages[1].frames[0].image.copy()
    for colour in ("green", "red"):
        image[np.all(image == RGB[colour], axis=2)] = 128
    stages[1] = RigStage(
        (RigFrame(1.0, "grey.png", image),), stages[1].reading_t_s, stages[1].readings_m
    )
    with pytest.raises(TofRigError) as refused:
        calibrate_rig(stages[:2], description)
    assert str(refused.value) == (
        "usable stages sensor 2 (green pad): 1, sensor 4 (red pad): 1; at least 2 are needed "
        "per sensor (skipped: {'pad_not_found': [0, 1, 0, 1], 'pad_clipped': [0, 0, 0, 0], "
        "'range_invalid': [0, 0, 0, 0]})"
    )


def test_the_calibration_records_the_rig_it_was_made_on_and_what_was_skipped() -> None:
    stages, description = _synthetic_rig()
    rig = TofRigDescription(
        stages=description.stages,
        min_pad_area_px=4.0,
        camera=CAMERA,
        tof_mount_offsets_c=description.tof_mount_offsets_c,
        tof_max_range_m=4.0,
        metadata={"source": "test"},
    )
    metadata = calibrate_rig(stages, rig).calibration.metadata
    assert metadata == {
        "source": "test",
        "camera": CAMERA.as_dict(),
        "tof_mount_offsets_c": MOUNTS_C.tolist(),
        "tof_max_range_m": 4.0,
        "stages": 4,
        "min_pad_area_px": 4.0,
        "skipped": {"pad_not_found": [0] * 4, "pad_clipped": [0] * 4, "range_invalid": [0] * 4},
    }
    # a rig file without a camera, mounts or maximum range: none recorded
    bare = TofRigDescription(stages=description.stages, min_pad_area_px=4.0)
    assert set(calibrate_rig(stages, bare).calibration.metadata) == {
        "stages",
        "min_pad_area_px",
        "skipped",
    }


def test_a_rig_file_saved_loads_back_as_it_was_and_its_optional_fields_default(
    tmp_path: Path,
) -> None:
    _, description = _synthetic_rig()
    full = TofRigDescription(
        stages=description.stages,
        min_pad_area_px=1.0,  # the smallest allowed
        camera=CAMERA,
        tof_mount_offsets_c=description.tof_mount_offsets_c,
        tof_max_range_m=4.0,
        metadata={"source": "test"},
    )
    full.save(tmp_path / RIG_FILE)
    assert TofRigDescription.load(tmp_path / RIG_FILE) == full
    assert [s.nominal_range_m for s in full.stages] == list(RANGES_M)
    doc = {
        "format": "deck-landing/tof-rig",
        "format_version": 1,
        "stages": [{"t_start_s": 0.0, "t_end_s": 1.0}, {"t_start_s": 1.5, "t_end_s": 2.0}],
    }
    (tmp_path / RIG_FILE).write_text(json.dumps(doc))
    bare = TofRigDescription.load(tmp_path / RIG_FILE)
    assert bare == TofRigDescription(stages=(StageWindow(0.0, 1.0), StageWindow(1.5, 2.0)))
    assert bare.min_pad_area_px == 12.0 and bare.camera is None and bare.metadata == {}
    assert bare.tof_mount_offsets_c is None and bare.tof_max_range_m is None


def test_a_bad_rig_file_is_refused_with_the_file_the_field_and_what_it_needs(
    tmp_path: Path,
) -> None:
    path = tmp_path / RIG_FILE
    good = {
        "format": "deck-landing/tof-rig",
        "format_version": 1,
        "stages": [
            {"t_start_s": 0.0, "t_end_s": 0.5},
            {"t_start_s": 1.0, "t_end_s": 1.5},
            {"t_start_s": 2.0, "t_end_s": 2.5},
        ],
    }

    def refused(doc: object) -> str:
        path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
        with pytest.raises(TofRigError) as error:
            TofRigDescription.load(path)
        return str(error.value)

    with pytest.raises(TofRigError) as error:
        TofRigDescription.load(tmp_path / "nowhere" / RIG_FILE)
    assert str(error.value) == (
        f"{tmp_path / 'nowhere'}: no {RIG_FILE} (the rig's stage windows; see the "
        "recorded-data how-to)"
    )
    assert refused("{no").startswith(f"{path}: not JSON (")
    format_message = f"{path}: format must be 'deck-landing/tof-rig'"
    assert refused([good]) == format_message
    assert refused({**good, "format": "deck-landing/other"}) == format_message
    assert refused({**good, "format_version": 3}) == (
        f"{path}: unsupported format_version 3; readable: 1"
    )
    touching = json.loads(json.dumps(good))
    touching["stages"][1]["t_start_s"] = 0.5  # starts as the one before ends
    assert refused(touching) == (
        f"{path}: stages[1] starts at 0.5 s, not after stages[0] ends (0.5 s): windows must "
        "be in time order and not overlap"
    )
    assert (
        refused({**good, "min_pad_area_px": "x"})
        == f"{path}: min_pad_area_px = 'x' is not a number"
    )
    assert refused({**good, "min_pad_area_px": 0.5}) == f"{path}: min_pad_area_px 0.5 must be >= 1"
    mounts = (
        f"{path}: tof_mount_offsets_c must be 4 rows of [x, y, z] metres (the sensors in the "
        "camera frame)"
    )
    assert refused({**good, "tof_mount_offsets_c": [[0, 0, 0]] * 3 + [[0, 0]]}) == mounts
    assert (
        refused({**good, "tof_max_range_m": "x"})
        == f"{path}: tof_max_range_m = 'x' is not a number"
    )


@pytest.mark.parametrize(
    ("box", "clipped"),
    [
        ((0, 5, 4, 5), True),  # touches the left border
        ((1, 5, 4, 5), False),
        ((10, 0, 4, 5), True),  # the top
        ((10, 1, 4, 5), False),
        ((26, 5, 4, 5), True),  # the right: its last column is the image's
        ((25, 5, 4, 5), False),
        ((10, 15, 4, 5), True),  # the bottom
        ((10, 14, 4, 5), False),
    ],
)
def test_a_pad_touching_an_image_border_is_clipped_and_one_a_pixel_inside_is_found(
    box: tuple[int, int, int, int], clipped: bool
) -> None:
    x, y, w, h = box
    mask = np.zeros((20, 30), bool)
    mask[y : y + h, x : x + w] = True
    # the hull through the pixel centres of a 4 x 5 block: 3 x 4 = 12 px², the minimum
    centroid, reason = pad_centroid_in_image(mask, 12.0)
    if clipped:
        assert centroid is None and reason == "pad_clipped"
    else:
        assert reason == ""
        np.testing.assert_allclose(centroid, [x + 1.5, y + 2.0])
    assert pad_centroid_in_image(mask, 12.5) == (None, "pad_not_found")


def test_a_window_must_be_finite_and_not_end_before_it_starts_and_none_writes_no_nominal(
    tmp_path: Path,
) -> None:
    path = tmp_path / RIG_FILE
    TofRigDescription(stages=(StageWindow(0.0, 1.0), StageWindow(2.0, 3.0))).save(path)
    doc = json.loads(path.read_text())
    assert doc["stages"] == [{"t_start_s": 0.0, "t_end_s": 1.0}, {"t_start_s": 2.0, "t_end_s": 3.0}]
    for start, end in ((2.5, 2.0), (-math.inf, 3.0), (2.0, math.inf)):
        doc["stages"][1] = {"t_start_s": start, "t_end_s": end}
        path.write_text(json.dumps(doc))
        with pytest.raises(TofRigError) as refused:
            TofRigDescription.load(path)
        assert str(refused.value) == (
            f"{path}: stages[1]: need finite t_start_s <= t_end_s, got {start}, {end}"
        )


def test_readings_not_stamped_together_cannot_be_rows_of_a_recording() -> None:
    stages, _ = _synthetic_rig()
    rows = reading_rows(stages[:1])
    assert [t for t, _ in rows] == stages[0].reading_t_s[0].tolist()
    assert [ranges for _, ranges in rows][1:] == [[RANGES_M[0]] * 4] * (READINGS - 1)
    late = stages[1].reading_t_s[0] + 0.01
    stages[1] = RigStage(stages[1].frames, (*stages[1].reading_t_s[:3], late), stages[1].readings_m)
    with pytest.raises(TofRigError) as refused:
        reading_rows(stages)
    assert str(refused.value) == (
        "stage 1: the sensors' readings are not stamped together; a recording's row of ranges "
        "holds the four sensors at one stamp"
    )
