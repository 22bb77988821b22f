"""``deck-landing estimate``'s work (:mod:`agents.io.estimate`): the camera mount read from
``extrinsics.json``, the estimator built for a recording (its calibration, its camera), each
frame's estimate, and the CSV and MCAP it writes; bad input named as the command names it."""

from __future__ import annotations

import csv
import json
import shutil
from argparse import Namespace
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

import landing_env  # noqa: F401  (registers the environments)
from agents.common.user_input import UserError
from agents.io import messages as m
from agents.io.estimate import (
    EXTRINSICS_FORMAT,
    Extrinsics,
    RecordingEstimator,
    _checked,
    _pose_columns,
    _pose_message,
    is_folder_recording,
    read_checked,
    read_recording,
    recording_estimator,
    run_estimate,
    skipped_report,
    user_errors,
    write_estimates,
)
from agents.io.record import McapRecorder
from agents.io.recording import (
    RecordedFrame,
    Recording,
    RecordingError,
    SensorSeries,
    Topics,
    write_folder,
)
from estimation.frames import R_BC
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_calibration import TofCameraCalibration
from estimation.types import DeckPoseEstimate
from landing_env.config import SHIPPED_INTRINSICS_FILE, load_config
from landing_env.physics.quadrotor_params import DEFAULT_PARAMS_PATH, QuadrotorParams

STEPS = 8
ALLOWED = "atda, ihrcf, crhf, tight, fused"
SHIPPED_TOF_FILE = SHIPPED_INTRINSICS_FILE.parent / "tof_camera.json"
#: the default vehicle's camera origin in the body (FLU), metres
T_BC_M = np.asarray(QuadrotorParams.from_yaml(None).camera_offset_b, dtype=float)


def _record(path: Path, mode: str, steps: int) -> Path:
    """An episode hovering, recorded: ``fused`` observed, ``tight`` compared."""
    overrides = {
        "camera.mode": mode,
        "estimation.observed": "fused",
        "estimation.compare": ["tight"],
    }
    env = McapRecorder(gym.make("DeckLanding-v2", config="default", overrides=overrides), path)
    env.reset(seed=3)
    for _ in range(steps):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()
    return path


@pytest.fixture(scope="module")
def episode(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Project mode: the frames are the tag detections."""
    return _record(tmp_path_factory.mktemp("rec") / "episode.mcap", "project", STEPS)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Render mode, two frames: the frames are images."""
    return _record(tmp_path_factory.mktemp("rec") / "rendered.mcap", "render", 1)


def _args(path: Path | str, estimator: str, **extra: object) -> Namespace:
    values: dict = {
        "input": str(path), "estimator": estimator, "config": "default", "calibration": None,
        "set": [], "tolerance": 0.02, "align": "nearest",
    }  # fmt: skip
    values.update(extra)
    return Namespace(**values)


def _runner(name: str, image_size=None, calibration: Path | None = None, **overrides):  # type: ignore[no-untyped-def]
    config = load_config(
        "default", {"estimation.observed": name, "estimation.compare": [], **overrides}
    )
    return RecordingEstimator(name, config, calibration, image_size)


def _messages(path: Path) -> dict[str, list]:
    """Every message of an MCAP, decoded, by topic in order."""
    found: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for connection, _, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            found.setdefault(connection.topic, []).append(message)
    return found


def _log_times(path: Path) -> dict[str, list[int]]:
    """Each message's log time (ns), by topic in order."""
    found: dict[str, list[int]] = {}
    with AnyReader([path]) as reader:
        for connection, log_time_ns, _ in reader.messages():
            found.setdefault(connection.topic, []).append(log_time_ns)
    return found


def _stamp_ns(message) -> int:  # type: ignore[no-untyped-def]
    return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


def _pose_tuple(message) -> tuple[float, ...]:  # type: ignore[no-untyped-def]
    p, q = message.pose.pose.position, message.pose.pose.orientation
    return (p.x, p.y, p.z, q.x, q.y, q.z, q.w)


def _pose_of(message) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    pose = message.pose.pose
    q = [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w]
    t = [pose.position.x, pose.position.y, pose.position.z]
    return Rotation.from_quat(q).as_matrix(), np.array(t)


def _calibration(folder: Path, *names: str, extrinsics: dict | None = None) -> Path:
    """A calibration folder with the shipped files named and, given, an ``extrinsics.json``."""
    folder.mkdir(parents=True, exist_ok=True)
    shipped = {"intrinsics.json": SHIPPED_INTRINSICS_FILE, "tof_camera.json": SHIPPED_TOF_FILE}
    for name in names:
        shutil.copy(shipped[name], folder / name)
    if extrinsics is not None:
        (folder / "extrinsics.json").write_text(json.dumps(extrinsics))
    return folder


def _extrinsics_doc(r_bc: object, t_bc_m: object, changes: dict | None = None) -> dict:
    doc = {"format": EXTRINSICS_FORMAT, "format_version": 1, "r_bc": r_bc, "t_bc_m": t_bc_m}
    return doc | (changes or {})


#: a camera looking down, its x to the body's right: the body's axes of the camera's
R_BC_TURNED = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


# ------------------------------------------------------------------ the camera's mount
def test_extrinsics_saved_load_back_as_floats_and_put_the_deck_in_the_body(tmp_path: Path) -> None:
    path = tmp_path / "extrinsics.json"
    Extrinsics(R_BC_TURNED.astype(int), np.array([1, 0, -3])).save(path)
    assert json.loads(path.read_text()) == {
        "format": "deck-landing/camera-extrinsics",
        "format_version": 1,
        "r_bc": R_BC_TURNED.astype(int).tolist(),
        "t_bc_m": [1, 0, -3],
    }
    loaded = Extrinsics.load(path)
    assert loaded.r_bc.dtype == np.float64 and loaded.t_bc_m.dtype == np.float64
    np.testing.assert_array_equal(loaded.r_bc, R_BC_TURNED)
    np.testing.assert_array_equal(loaded.t_bc_m, [1.0, 0.0, -3.0])
    r_cd = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    estimate = DeckPoseEstimate("tight", 0.5, True, r_cd, np.array([0.2, -0.1, 1.5]))
    r_bd, t_bd = loaded.deck_in_body(estimate)
    np.testing.assert_array_equal(r_bd, R_BC_TURNED @ r_cd)
    np.testing.assert_array_equal(t_bd, [0.1 + 1.0, -0.2, -1.5 - 3.0])


def test_a_rotation_within_a_micro_of_orthonormal_is_a_mount(tmp_path: Path) -> None:
    path = tmp_path / "extrinsics.json"
    nearly = R_BC_TURNED + np.array([[3e-7, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 3e-7]])
    path.write_text(json.dumps(_extrinsics_doc(nearly.tolist(), [0.0, 0.0, 0.0])))
    np.testing.assert_array_equal(Extrinsics.load(path).r_bc, nearly)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"format": "deck-landing/camera-intrinsics"}, "not a format_version 1 {F} file"),
        ({"format_version": 2}, "not a format_version 1 {F} file"),
        ({"format_version": None}, "not a format_version 1 {F} file"),
        ({"r_bc": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]}, "r_bc must be a 3x3 rotation matrix"),
        ({"r_bc": (R_BC_TURNED * 1.001).tolist()}, "r_bc must be a 3x3 rotation matrix"),
        ({"r_bc": (R_BC_TURNED * 2.0).tolist()}, "r_bc must be a 3x3 rotation matrix"),
        ({"r_bc": np.diag([1.0, 1.0, -1.0]).tolist()}, "r_bc must be a 3x3 rotation matrix"),
        ({"t_bc_m": [0.1, 0.0]}, "t_bc_m must be 3 finite numbers (metres)"),
        ({"t_bc_m": [0.1, 0.0, float("nan")]}, "t_bc_m must be 3 finite numbers (metres)"),
        ({"t_bc_m": [float("inf"), 0.0, 0.0]}, "t_bc_m must be 3 finite numbers (metres)"),
    ],
)
def test_an_extrinsics_file_of_another_format_or_a_bad_mount_is_refused_naming_the_file(
    tmp_path: Path, changes: dict, message: str
) -> None:
    path = tmp_path / "extrinsics.json"
    path.write_text(json.dumps(_extrinsics_doc(R_BC_TURNED.tolist(), [0.1, 0.0, -0.03], changes)))
    with pytest.raises(RecordingError) as refused:
        Extrinsics.load(path)
    assert str(refused.value) == f"{path}: " + message.replace("{F}", EXTRINSICS_FORMAT)


# ------------------------------------------------------------------ the estimator built
def test_an_unknown_estimator_is_refused_listing_those_a_recording_can_run(episode: Path) -> None:
    config = load_config("default")
    with pytest.raises(UserError) as refused:
        RecordingEstimator("truth", config, None, None)
    assert str(refused.value) == f"--estimator 'truth'; allowed: {ALLOWED}"
    with pytest.raises(UserError) as refused:
        read_checked(_args(episode, "beacon"))
    assert str(refused.value) == f"--estimator 'beacon'; allowed: {ALLOWED}"


def test_the_configs_camera_must_have_the_recordings_image_size_unless_calibrated() -> None:
    for size in (None, (512, 512)):
        assert list(_runner("tight", size).estimators) == ["tight"]
    with pytest.raises(RecordingError) as refused:
        _runner("tight", (64, 48))
    assert str(refused.value) == (
        "the config's camera is 512x512, the recording's images are 64x48: give --calibration DIR"
    )
    with pytest.raises(RecordingError, match="the config's camera is 512x512, the recording's"):
        _runner("tight", (512, 480))


def test_the_mount_is_the_vehicles_camera_and_the_estimator_alone_is_built(tmp_path: Path) -> None:
    runner = _runner("tight")
    assert runner.name == "tight" and list(runner.estimators) == ["tight"]
    assert runner.extrinsics is not None
    np.testing.assert_array_equal(runner.extrinsics.r_bc, R_BC)
    np.testing.assert_array_equal(runner.extrinsics.t_bc_m, T_BC_M)
    np.testing.assert_array_equal(runner.t_bc, T_BC_M)
    assert runner.stage.link is None and runner.stage.fusion is None  # no latency simulated
    # another vehicle's camera origin
    vehicle = tmp_path / "quadrotor.yaml"
    text = DEFAULT_PARAMS_PATH.read_text()
    assert "camera_offset_b: [0.0, 0.0, -0.03]" in text
    vehicle.write_text(
        text.replace("camera_offset_b: [0.0, 0.0, -0.03]", "camera_offset_b: [0.05, 0.01, -0.04]")
    )
    shutil.copy(DEFAULT_PARAMS_PATH.parent / "quadrotor.urdf", tmp_path / "quadrotor.urdf")
    fused = _runner("fused", vehicle=str(vehicle))
    assert list(fused.estimators) == ["atda", "crhf"]  # fused's sources; fused runs after them
    assert fused.stage.link is None and fused.stage.fusion is not None
    np.testing.assert_array_equal(fused.t_bc, [0.05, 0.01, -0.04])
    np.testing.assert_array_equal(fused.extrinsics.t_bc_m, [0.05, 0.01, -0.04])
    np.testing.assert_array_equal(fused.stage.fusion.t_bc, [0.05, 0.01, -0.04])
    mounts = np.asarray(load_config("default").tof.mount_offsets_c, dtype=float)
    np.testing.assert_allclose(
        fused.stage.fusion.tof_origins_b, [0.05, 0.01, -0.04] + mounts @ R_BC.T, atol=1e-15
    )


def test_the_estimator_named_is_built_whatever_the_config_observes_or_compares(
    tmp_path: Path,
) -> None:
    config = load_config("default", {"estimation.compare": ["crhf", "tight"]})
    assert config.estimation.observed == "ihrcf"
    assert list(RecordingEstimator("atda", config, None, None).estimators) == ["atda"]
    # nor is a ToF calibration asked of the folder for the config's ihrcf
    folder = _calibration(tmp_path / "cal", "intrinsics.json")
    assert list(RecordingEstimator("atda", config, folder, None).estimators) == ["atda"]


def test_a_calibration_gives_the_intrinsics_the_tof_calibration_and_the_mount_of_its_files(
    tmp_path: Path,
) -> None:
    tof = TofCameraCalibration.load(SHIPPED_TOF_FILE)
    mounts = np.asarray(tof.metadata["tof_mount_offsets_c"], dtype=float) * 1.5
    changed = TofCameraCalibration(
        tof.samples, method="pchip", out_of_range=tof.out_of_range,
        metadata={**tof.metadata, "tof_mount_offsets_c": mounts.tolist()},
    )  # fmt: skip
    extrinsics = _extrinsics_doc(R_BC_TURNED.tolist(), [0.1, 0.0, -0.05])
    folder = _calibration(tmp_path / "cal", "intrinsics.json", extrinsics=extrinsics)
    changed.save(folder / "tof_camera.json")
    runner = _runner("fused", (512, 512), folder, **{"estimation.tof_lookup": "hyperbola"})
    assert runner.extrinsics is not None
    np.testing.assert_array_equal(runner.extrinsics.r_bc, R_BC_TURNED)
    np.testing.assert_array_equal(runner.t_bc, [0.1, 0.0, -0.05])
    np.testing.assert_array_equal(runner.stage.fusion.t_bc, [0.1, 0.0, -0.05])
    np.testing.assert_allclose(
        runner.stage.fusion.tof_origins_b, [0.1, 0.0, -0.05] + mounts @ R_BC.T, atol=1e-15
    )
    crhf = runner.estimators["crhf"]
    assert crhf.tof_calibration.method == "hyperbola"  # the config's look-up
    np.testing.assert_array_equal(crhf.tof_positions_c, mounts)
    shipped = IntrinsicsCalibrationResult.load(SHIPPED_INTRINSICS_FILE).to_intrinsics()
    assert crhf.intrinsics == shipped
    # without extrinsics.json: no mount, and the vehicle's camera origin for fused's ranges
    (folder / "extrinsics.json").unlink()
    runner = _runner("fused", None, folder)
    assert runner.extrinsics is None
    np.testing.assert_array_equal(runner.t_bc, T_BC_M)
    # a ToF calibration whose metadata has no mounts: the config's
    TofCameraCalibration(tof.samples, metadata={}).save(folder / "tof_camera.json")
    config_mounts = np.asarray(load_config("default").tof.mount_offsets_c, dtype=float)
    np.testing.assert_array_equal(
        _runner("crhf", None, folder).estimators["crhf"].tof_positions_c, config_mounts
    )


def test_a_calibration_without_the_tof_file_serves_an_estimator_that_needs_no_ranges(
    tmp_path: Path,
) -> None:
    folder = _calibration(tmp_path / "cal", "intrinsics.json")
    # tight, given a ToF calibration (the config's), moves its principal point to the touch
    # pixels; the folder's has none, so tight runs without
    assert np.all(_runner("tight").estimators["tight"].principal_point_offset_px != 0.0)
    tight = _runner("tight", None, folder).estimators["tight"]
    np.testing.assert_array_equal(tight.principal_point_offset_px, [0.0, 0.0])
    assert list(_runner("atda", (512, 512), folder).estimators) == ["atda"]
    for name in ("ihrcf", "crhf", "fused"):  # fused: its source crhf
        with pytest.raises(RecordingError) as refused:
            _runner(name, None, folder)
        assert str(refused.value) == f"--calibration {folder}: {name} needs tof_camera.json"


def test_a_calibration_that_is_no_folder_or_lacks_intrinsics_is_refused_naming_it(
    tmp_path: Path,
) -> None:
    not_a_folder = tmp_path / "intrinsics.json"
    shutil.copy(SHIPPED_INTRINSICS_FILE, not_a_folder)
    for path in (not_a_folder, tmp_path / "nowhere"):
        with pytest.raises(RecordingError) as refused:
            _runner("atda", None, path)
        assert str(refused.value) == f"--calibration {path}: not a folder"
    empty = _calibration(tmp_path / "cal", "tof_camera.json")
    with pytest.raises(RecordingError) as refused:
        _runner("atda", None, empty)
    assert str(refused.value) == f"--calibration {empty}: no intrinsics.json"


def test_a_calibration_for_another_image_size_is_refused_naming_its_file(tmp_path: Path) -> None:
    folder = _calibration(tmp_path / "cal", "intrinsics.json", "tof_camera.json")
    with pytest.raises(ValueError) as refused:
        _runner("ihrcf", (64, 48), folder)
    assert str(refused.value) == (
        f"{folder / 'intrinsics.json'} is for another camera: image size 512x512, but the "
        "images are 64x48"
    )
    # the intrinsics of 64x48 images, the ToF calibration's pads found in 512x512 ones
    doc = json.loads(SHIPPED_INTRINSICS_FILE.read_text())
    doc["image_size"] = [64, 48]
    (folder / "intrinsics.json").write_text(json.dumps(doc))
    tof = TofCameraCalibration.load(SHIPPED_TOF_FILE)
    TofCameraCalibration(tof.samples, metadata=tof.metadata, image_size=(512, 512)).save(
        folder / "tof_camera.json"
    )
    with pytest.raises(ValueError) as refused:
        _runner("ihrcf", (64, 48), folder)
    assert str(refused.value) == (
        f"{folder / 'tof_camera.json'} is for another camera: image size 512x512, but the "
        "images are 64x48"
    )
    assert list(_runner("ihrcf", None, folder).estimators) == ["ihrcf"]  # size not known


def test_the_command_builds_its_estimator_alone_with_the_settings_given(tmp_path: Path) -> None:
    """``--set`` reaches the config; the config's observed and compared estimators are not
    built (nor their calibration loaded)."""
    nowhere = "estimation.tof_calibration_file=/nowhere/tof.json"
    settings = [nowhere, "estimation.observed=crhf", "estimation.compare=[ihrcf]"]
    runner = recording_estimator(_args("rec", "atda", set=settings), Recording())
    assert runner.name == "atda" and list(runner.estimators) == ["atda"]
    with pytest.raises(ValueError, match=r"estimation\.tof_calibration_file: '/nowhere/tof\.json'"):
        recording_estimator(_args("rec", "crhf", set=[nowhere]), Recording())
    # --config: the config named, its intrinsics those of the paper's setup
    paper = recording_estimator(_args("rec", "ihrcf", config="paper-setup-ihrcf"), Recording())
    intrinsics = paper.estimators["ihrcf"].intrinsics
    expected = _runner("ihrcf").estimators["ihrcf"].intrinsics
    assert intrinsics != expected
    config = load_config("paper-setup-ihrcf", {"estimation.observed": "ihrcf"})
    assert (
        intrinsics == RecordingEstimator("ihrcf", config, None, None).estimators["ihrcf"].intrinsics
    )
    # the recording's image size is checked against the config's camera
    images = Recording(frames=[RecordedFrame(0.0, "f0", image=np.zeros((48, 64), np.uint8))])
    wide = ["camera.width=640", "estimation.intrinsics=exact", "estimation.tof_calibration=exact"]
    with pytest.raises(RecordingError, match=r"^the config's camera is 640x512, the recording's"):
        recording_estimator(_args("rec", "tight", set=wide), images)
    # --calibration: the folder's files
    folder = _calibration(tmp_path / "cal", "intrinsics.json")
    runner = recording_estimator(_args("rec", "tight", calibration=str(folder)), Recording())
    assert runner.extrinsics is None
    np.testing.assert_array_equal(runner.estimators["tight"].principal_point_offset_px, [0, 0])


# ------------------------------------------------------------------ each frame's estimate
def test_a_frame_is_its_recorded_detections_or_the_tags_the_detector_finds_in_its_image(
    rendered: Path,
) -> None:
    runner = _runner("tight")
    recorded = RecordedFrame(0.25, "x", detections=(), miss_reason="out_of_view")
    frame = runner._frame(recorded)
    assert (frame.timestamp, frame.detections, frame.image, frame.miss_reason) == (
        0.25, (), None, "out_of_view",
    )  # fmt: skip
    rec = read_recording(rendered, Topics(detections=""))
    assert rec.image_size() == (512, 512)
    frame = runner._frame(rec.frames[0])
    assert frame.timestamp == rec.frames[0].timestamp and frame.image is None
    assert [d.tag_id for d in frame.detections] == [0] and frame.miss_reason == ""
    grey = RecordedFrame(0.5, "y", image=np.full((512, 512), 128, np.uint8))
    frame = runner._frame(grey)
    assert (frame.timestamp, frame.detections, frame.miss_reason) == (0.5, (), "not_detected")


def test_a_rendered_recordings_images_give_the_pose_its_projected_detections_give(
    rendered: Path, tmp_path: Path
) -> None:
    from_images = read_recording(rendered, Topics(detections=""))
    from_tags = read_recording(rendered)
    assert from_tags.frames[0].detections is not None
    runner = _runner("tight", from_images.image_size())
    seen = [e for e, _ in runner.run(from_images, 0.02, "nearest")]
    projected = [e for e, _ in runner.run(from_tags, 0.02, "nearest")]
    assert [e.valid for e in seen] == [True, True]
    for image, tag in zip(seen, projected, strict=True):
        # the detector's corners are the projection's within a fraction of a pixel
        np.testing.assert_allclose(image.translation, tag.translation, atol=0.01)


def test_each_frame_is_estimated_in_order_after_the_pace_is_kept_for_its_stamp(
    episode: Path,
) -> None:
    rec = read_recording(episode)
    stamps = [f.timestamp for f in rec.frames]
    runner = _runner("tight")
    paced: list[float] = []
    estimates = runner.run(rec, 0.02, "nearest", pace=paced.append)
    first, had_ranges = next(estimates)
    assert paced == stamps[:1] and first.timestamp == stamps[0] and had_ranges
    played = [first, *(e for e, _ in estimates)]
    assert paced == stamps == [e.timestamp for e in played]
    # a second run starts afresh: the same estimates
    again = [e for e, _ in runner.run(rec, 0.02, "nearest")]
    for one, other in zip(played, again, strict=True):
        np.testing.assert_array_equal(one.translation, other.translation)


def test_the_ranges_are_those_within_the_tolerance_aligned_as_asked(episode: Path) -> None:
    rec = read_recording(episode)
    for series in rec.sensors:  # the ranges 15 ms after the frames
        series.t_s = [t + 0.015 for t in series.t_s]
    runner = _runner("ihrcf")
    assert {had for _, had in runner.run(rec, 0.01, "nearest")} == {False}
    assert {had for _, had in runner.run(rec, 0.02, "nearest")} == {True}
    nearest = [e.translation for e, _ in runner.run(rec, 0.04, "nearest")]
    between = [e.translation for e, _ in runner.run(rec, 0.04, "interpolate")]
    assert not np.allclose(nearest[1:-1], between[1:-1])
    # one sensor within the tolerance is ranges found
    rec.sensors[1:] = [SensorSeries() for _ in range(3)]
    assert {had for _, had in runner.run(rec, 0.02, "nearest")} == {True}


def test_fused_is_invalid_until_the_imu_gives_an_attitude_then_follows_the_simulators(
    episode: Path,
) -> None:
    rec = read_recording(episode)
    estimates = [e for e, _ in _runner("fused").run(rec, 0.02, "nearest")]
    first = estimates[0]
    assert (first.method, first.valid, first.reason) == (
        "fused", False, "no_attitude: no IMU orientation yet",
    )  # fmt: skip
    assert first.timestamp == rec.frames[0].timestamp
    assert all(e.valid and e.method == "fused" for e in estimates[1:])
    simulated = {_stamp_ns(m): m for m in _messages(episode)["/estimates/fused"]}
    for estimate in estimates[1:]:
        rotation, translation = _pose_of(simulated[m.to_ns(estimate.timestamp)])
        # the simulator's fusion started a frame earlier, with the reset's attitude
        np.testing.assert_allclose(estimate.translation, translation, atol=1e-3)
        np.testing.assert_allclose(estimate.rotation, rotation, atol=1e-3)
    # without an attitude at all, every frame says so
    rec.attitude = [None] * len(rec.imu)
    reasons = {e.reason for e, _ in _runner("fused").run(rec, 0.02, "nearest")}
    assert reasons == {"no_attitude: no IMU orientation yet"}


def test_each_imu_sample_reaches_the_fusion_once_with_the_first_frame_after_it(
    episode: Path,
) -> None:
    rec = read_recording(episode)
    runner = _runner("fused")
    handed: list[tuple[float, list[float], np.ndarray]] = []
    process = runner.stage.process

    def spy(time, results, ranges, imu, r_wb):  # type: ignore[no-untyped-def]
        handed.append((time, [s.timestamp for s in imu], r_wb))
        return process(time, results, ranges, imu, r_wb)

    runner.stage.process = spy  # type: ignore[method-assign]
    assert len(list(runner.run(rec, 0.02, "nearest"))) == STEPS + 1
    stamps = [f.timestamp for f in rec.frames]
    assert [time for time, _, _ in handed] == stamps[1:]  # the first frame: no attitude yet
    assert [t for _, samples, _ in handed for t in samples] == [
        s.timestamp for s in rec.imu if s.timestamp <= stamps[-1] + 1e-9
    ]
    for (time, samples, r_wb), before in zip(handed, stamps, strict=False):
        assert all(before + 1e-9 < t <= time + 1e-9 for t in samples) and samples
        np.testing.assert_array_equal(r_wb, rec.attitude_at(time))


def test_a_valid_estimate_with_a_nan_is_reported_invalid_as_non_finite() -> None:
    turn, place = np.eye(3), np.array([0.1, 0.2, 1.5])
    good = DeckPoseEstimate("tight", 1.5, True, turn, place)
    assert _checked(good) is good
    said = DeckPoseEstimate.invalid("tight", 1.5, "no_detection")  # NaN pose, invalid already
    assert _checked(said) is said
    one_nan = turn.copy()
    one_nan[1, 2] = np.nan
    for rotation, translation in [(turn, place * np.nan), (turn * np.nan, place), (one_nan, place)]:
        checked = _checked(DeckPoseEstimate("crhf", 2.5, True, rotation, translation))
        assert (checked.method, checked.timestamp, checked.valid, checked.reason) == (
            "crhf", 2.5, False, "non_finite_result",
        )  # fmt: skip
    one_inf = place.copy()
    one_inf[2] = np.inf
    assert not _checked(DeckPoseEstimate("crhf", 2.5, True, turn, one_inf)).valid


# ------------------------------------------------------------------ what is written
def test_a_poses_columns_are_its_position_in_metres_and_its_quaternion_named_by_frame() -> None:
    turn = Rotation.from_rotvec([0.0, 0.0, np.pi / 2]).as_matrix()
    columns = _pose_columns("body_flu", turn, np.array([1.0, -2.0, 3.5]))
    assert list(columns) == [
        "x_body_flu_m", "y_body_flu_m", "z_body_flu_m",
        "qx_body_flu", "qy_body_flu", "qz_body_flu", "qw_body_flu",
    ]  # fmt: skip
    assert list(columns.values())[:3] == [1.0, -2.0, 3.5]
    np.testing.assert_allclose(list(columns.values())[3:], [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)])
    assert all(type(v) is float for v in columns.values())


def test_a_pose_message_carries_the_stamp_frame_pose_and_the_methods_covariance() -> None:
    turn = Rotation.from_rotvec([0.1, 0.0, 0.0]).as_matrix()
    place = np.array([0.2, -0.1, 1.5])
    covariance = np.arange(36.0).reshape(6, 6)
    for given, expected in [(None, np.zeros(36)), (covariance, np.arange(36.0))]:
        estimate = DeckPoseEstimate("fused", 1.25, True, turn, place, covariance=given)
        message = _pose_message(1.25, "body_frd", estimate, turn, place)
        back = m.TYPESTORE.deserialize_cdr(
            m.TYPESTORE.serialize_cdr(message, m.POSE_COV), m.POSE_COV
        )
        assert back.header.frame_id == "body_frd" and _stamp_ns(back) == 1_250_000_000
        rotation, translation = _pose_of(back)
        np.testing.assert_allclose(rotation, turn, atol=1e-12)
        np.testing.assert_array_equal(translation, place)
        np.testing.assert_array_equal(back.pose.covariance, expected)


def _rows(path: Path) -> list[dict]:
    with path.open(newline="") as stream:
        return list(csv.DictReader(stream))


def _columns(*frames: str) -> list[str]:
    pose = [
        f"{c}_{f}" + ("_m" if c in "xyz" else "")
        for f in frames
        for c in ("x", "y", "z", "qx", "qy", "qz", "qw")
    ]
    return ["t_s", "method", "valid", "reason", "ranges_in_tolerance", *pose]


def test_estimate_writes_every_frame_to_the_csv_and_each_valid_pose_in_three_frames(
    episode: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "new" / "folder" / "fused.csv"  # made with its parents
    summary = run_estimate(_args(episode, "fused", out=str(out)))
    frames = STEPS + 1
    assert (summary.frames, summary.valid, summary.without_ranges) == (frames, frames - 1, 0)
    assert summary.reasons == {"no_attitude: no IMU orientation yet": 1}
    assert summary.skipped == {}
    csv_path, mcap_path = out.with_suffix(".csv"), out.with_suffix(".mcap")
    assert capsys.readouterr().out == (
        f"{frames} frames, {frames - 1} valid, 0 without ranges within 0.02 s; invalid by "
        "reason: {'no_attitude: no IMU orientation yet': 1}\n"
        "skipped 0 bad messages\n"
        f"wrote {csv_path} and {mcap_path}\n"
    )
    with csv_path.open(newline="") as stream:
        header = next(csv.reader(stream))
    assert header == _columns("camera", "body_flu", "body_frd")
    rows = _rows(csv_path)
    rec = read_recording(episode)
    assert [r["t_s"] for r in rows] == [f"{f.timestamp:.9f}" for f in rec.frames]
    assert rows[1]["t_s"] == "0.050000000"
    assert rows[0] == {
        **dict.fromkeys(header, ""),
        "t_s": "0.000000000", "method": "fused", "valid": "0",
        "reason": "no_attitude: no IMU orientation yet", "ranges_in_tolerance": "1",
    }  # fmt: skip
    written, logged = _messages(mcap_path), _log_times(mcap_path)
    assert sorted(written) == [
        "/deck_pose/body_flu", "/deck_pose/body_frd", "/deck_pose/camera", "/deck_pose/status",
    ]  # fmt: skip
    statuses = written["/deck_pose/status"]
    assert [(s.method, s.valid, s.reason, s.header.frame_id) for s in statuses] == [
        ("fused", r["valid"] == "1", r["reason"], "camera") for r in rows
    ]
    assert [_stamp_ns(s) for s in statuses] == [m.to_ns(f.timestamp) for f in rec.frames]
    # each message logged at its estimate's stamp
    assert logged == {topic: [_stamp_ns(x) for x in written[topic]] for topic in written}
    for frame_id in ("camera", "body_flu", "body_frd"):
        poses = written[f"/deck_pose/{frame_id}"]
        assert [_stamp_ns(p) for p in poses] == [m.to_ns(f.timestamp) for f in rec.frames[1:]]
        assert {p.header.frame_id for p in poses} == {frame_id}
        for row, pose in zip(rows[1:], poses, strict=True):
            rotation, translation = _pose_of(pose)
            assert row["valid"] == "1" and row["reason"] == ""
            assert translation.tolist() == [float(row[f"{a}_{frame_id}_m"]) for a in "xyz"]
            q = [float(row[f"q{a}_{frame_id}"]) for a in "xyzw"]
            np.testing.assert_allclose(rotation, Rotation.from_quat(q).as_matrix(), atol=1e-12)
            covariance = pose.pose.covariance.reshape(6, 6)
            assert np.all(np.diag(covariance) > 0.0)  # fused's own
            np.testing.assert_allclose(covariance, covariance.T, rtol=1e-9, atol=1e-18)
    for row in rows[1:]:
        camera = np.array([float(row[f"{a}_camera_m"]) for a in "xyz"])
        flu = np.array([float(row[f"{a}_body_flu_m"]) for a in "xyz"])
        frd = np.array([float(row[f"{a}_body_frd_m"]) for a in "xyz"])
        np.testing.assert_allclose(flu, R_BC @ camera + T_BC_M, atol=1e-12)
        np.testing.assert_array_equal(frd, flu * [1.0, -1.0, -1.0])
        q_flu = Rotation.from_quat([float(row[f"q{a}_body_flu"]) for a in "xyzw"])
        q_frd = Rotation.from_quat([float(row[f"q{a}_body_frd"]) for a in "xyzw"])
        np.testing.assert_allclose(
            q_frd.as_matrix(), np.diag([1.0, -1.0, -1.0]) @ q_flu.as_matrix(), atol=1e-12
        )
    # run again into the same folder: the files written afresh
    run_estimate(_args(episode, "fused", out=str(out)))
    assert len(_rows(csv_path)) == frames


def test_tight_on_the_recording_is_the_simulators_tight_bit_for_bit(
    episode: Path, tmp_path: Path
) -> None:
    rec = read_checked(_args(episode, "tight"))
    runner = recording_estimator(_args(episode, "tight"), rec)
    summary, csv_path, mcap_path = write_estimates(runner, rec, tmp_path / "t", 0.02, "nearest")
    assert (csv_path, mcap_path) == (tmp_path / "t.csv", tmp_path / "t.mcap")
    assert (summary.frames, summary.valid, summary.without_ranges, summary.reasons) == (
        STEPS + 1, STEPS + 1, 0, {},
    )  # fmt: skip
    replayed = _messages(mcap_path)["/deck_pose/camera"]
    simulated = _messages(episode)["/estimates/tight"]
    assert len(replayed) == len(simulated) == STEPS + 1
    for ours, theirs in zip(replayed, simulated, strict=True):
        assert _stamp_ns(ours) == _stamp_ns(theirs)
        assert _pose_tuple(ours) == _pose_tuple(theirs)
        np.testing.assert_array_equal(ours.pose.covariance, theirs.pose.covariance)
    with csv_path.open(newline="") as stream:
        assert next(csv.reader(stream)) == _columns("camera", "body_flu", "body_frd")


def test_without_a_mount_only_camera_poses_are_written_and_invalid_ones_counted_by_reason(
    episode: Path, tmp_path: Path
) -> None:
    rec = read_recording(episode)
    rec.frames[2:4] = [
        RecordedFrame(f.timestamp, f.source, detections=(), miss_reason="out_of_view")
        for f in rec.frames[2:4]
    ]
    for series in rec.sensors:  # no ranges for the last frames
        series.t_s, series.range_m, series.valid = (
            series.t_s[:-3],
            series.range_m[:-3],
            series.valid[:-3],
        )
    folder = _calibration(tmp_path / "cal", "intrinsics.json")
    runner = _runner("tight", None, folder)
    summary, csv_path, mcap_path = write_estimates(runner, rec, tmp_path / "t.txt", 0.02, "nearest")
    assert (csv_path.name, mcap_path.name) == ("t.csv", "t.mcap")
    assert (summary.frames, summary.valid, summary.without_ranges) == (STEPS + 1, STEPS - 1, 3)
    assert summary.reasons == {"no_detection": 2}
    rows = _rows(csv_path)
    with csv_path.open(newline="") as stream:
        assert next(csv.reader(stream)) == _columns("camera")
    assert [r["valid"] for r in rows] == ["1", "1", "0", "0", *["1"] * (STEPS - 3)]
    assert [r["ranges_in_tolerance"] for r in rows] == ["1"] * (STEPS - 2) + ["0"] * 3
    assert rows[2]["x_camera_m"] == "" and rows[2]["reason"] == "no_detection"
    written = _messages(mcap_path)
    assert sorted(written) == ["/deck_pose/camera", "/deck_pose/status"]
    assert len(written["/deck_pose/camera"]) == STEPS - 1
    # the first frame invalid: the columns are still every pose's
    summary, csv_path, _ = write_estimates(
        _runner("tight"),
        Recording(frames=rec.frames[2:4], sensors=rec.sensors),
        tmp_path / "u",
        0.02,
        "nearest",
    )
    assert (summary.frames, summary.valid, summary.reasons) == (2, 0, {"no_detection": 2})
    with csv_path.open(newline="") as stream:
        assert next(csv.reader(stream)) == _columns("camera", "body_flu", "body_frd")
    assert [r["qw_body_frd"] for r in _rows(csv_path)] == ["", ""]


def test_the_command_aligns_the_ranges_as_asked_and_says_when_no_frame_was_invalid(
    rendered: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """A plain folder of the rendered images, its ranges 15 ms after the frames and 5 cm
    longer at the second sample: the second frame's ranges interpolated are 3.5 cm longer
    than the first sample's, the nearest 5 cm."""
    rec = read_recording(rendered, Topics(detections=""))
    first = [series.range_m[0] for series in rec.sensors]
    folder = write_folder(
        tmp_path / "rec",
        [(f.timestamp, f"f{k}.png", f.image) for k, f in enumerate(rec.frames)],
        [(0.015, first), (0.065, [r + 0.05 for r in first])],
    )
    heights = {}
    for align in ("nearest", "interpolate"):
        out = tmp_path / align
        args = _args(folder, "ihrcf", out=str(out), tolerance=0.04, align=align)
        summary = run_estimate(args)
        assert (summary.frames, summary.valid, summary.reasons) == (2, 2, {})
        assert capsys.readouterr().out.startswith(
            "2 frames, 2 valid, 0 without ranges within 0.04 s; invalid by reason: none\n"
        )
        heights[align] = [float(row["z_camera_m"]) for row in _rows(out.with_suffix(".csv"))]
    assert heights["nearest"][0] == heights["interpolate"][0]
    assert heights["nearest"][1] - heights["interpolate"][1] == pytest.approx(0.015, abs=0.005)


# ------------------------------------------------------------------ the recording read and checked
def _folder(path: Path, frames: str, ranges: bool = True, imu: bool = False) -> Path:
    """A plain folder: ``frames`` the rows of frames.csv (f0.png is a grey 64x48 image)."""
    path.mkdir(parents=True)
    cv2.imwrite(str(path / "f0.png"), np.full((48, 64), 128, np.uint8))
    (path / "frames.csv").write_text("t_s,image\n" + frames)
    if ranges:
        (path / "ranges.csv").write_text("t_s,range_1_m,range_2_m,range_3_m,range_4_m\n0,1,1,1,1\n")
    if imu:
        (path / "imu.csv").write_text("t_s,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n")
    return path


def test_only_a_folder_with_frames_csv_is_read_as_a_plain_folder(
    episode: Path, tmp_path: Path
) -> None:
    folder = _folder(tmp_path / "rec", "0.0,f0.png\n")
    assert is_folder_recording(folder) and is_folder_recording(str(folder))
    assert [f.source for f in read_recording(folder).frames] == ["f0.png"]
    assert not is_folder_recording(episode) and not is_folder_recording(tmp_path / "nowhere")
    (tmp_path / "other").mkdir()
    assert not is_folder_recording(tmp_path / "other")
    (tmp_path / "other" / "frames.csv").mkdir()  # not a file
    assert not is_folder_recording(tmp_path / "other")
    with pytest.raises(RecordingError, match="no recording in this folder"):
        read_recording(tmp_path / "other")
    # an MCAP read with the topics given
    assert read_recording(episode, Topics(tf="")).vehicle.t_s == []
    assert len(read_recording(episode).vehicle) == STEPS + 1


def test_a_recording_without_a_frame_or_what_the_estimator_needs_is_refused_saying_what(
    tmp_path: Path,
) -> None:
    cases = [
        ("atda", _folder(tmp_path / "a", ""), "no usable camera frame (skipped: none)"),
        (
            "atda",
            _folder(tmp_path / "b", "nan,f0.png\n0.1,missing.png\n0.2,missing.png\n"),
            "no usable camera frame (skipped: 1 x frames.csv: t_s not a number; "
            "2 x frames.csv: image missing or unreadable)",
        ),
        (
            "ihrcf",
            _folder(tmp_path / "c", "0.0,f0.png\n", ranges=False),
            "ihrcf needs ranges; missing: ranges.csv",
        ),
        ("crhf", tmp_path / "c", "crhf needs ranges; missing: ranges.csv"),
        ("fused", _folder(tmp_path / "d", "0.0,f0.png\n"), "fused needs the IMU; none read"),
    ]  # fmt: skip
    for estimator, path, message in cases:
        with pytest.raises(RecordingError) as refused:
            read_checked(_args(path, estimator))
        assert str(refused.value) == f"{path}: {message}", estimator
    for estimator in ("atda", "tight"):  # the camera alone
        assert len(read_checked(_args(tmp_path / "c", estimator)).frames) == 1
    path = _folder(tmp_path / "e", "0.0,f0.png\n", imu=True)
    assert len(read_checked(_args(path, "fused")).imu) == 1


def test_a_recording_missing_the_range_topics_names_them(episode: Path, tmp_path: Path) -> None:
    path = tmp_path / "camera_only.mcap"
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        message = m.msg(m.DETECTIONS, header=m.header(0.0, "camera"), miss_reason="", detections=[])
        writer.write("/camera/tag_detections", m.DETECTIONS, message, 0.0)
        writer.finish()
    with pytest.raises(RecordingError) as refused:
        read_checked(_args(path, "crhf"))
    assert str(refused.value) == f"{path}: crhf needs ranges; missing: /imu/data, /tof/range"
    args = _args(episode, "ihrcf", range_topics="/tof/r1,/tof/r2,/tof/r3,/tof/r4")
    args.exact_ranges_topic = ""
    with pytest.raises(RecordingError) as refused:
        read_checked(args)
    assert str(refused.value).startswith(
        f"--range-topics /tof/r1,/tof/r2,/tof/r3,/tof/r4: not in {episode}"
    )
    assert len(read_checked(_args(episode, "ihrcf")).frames) == STEPS + 1


def test_the_bad_messages_skipped_are_reported_by_reason() -> None:
    rec = Recording()
    assert skipped_report(rec) == "skipped 0 bad messages"
    rec.skipped["/imu/data: a non-finite value"] += 2
    rec.skipped["/tf: W -> B not finite or not a rotation"] += 1
    assert skipped_report(rec) == (
        "skipped 3 bad messages\n  2 x /imu/data: a non-finite value\n"
        "  1 x /tf: W -> B not finite or not a rotation"
    )


def test_a_bad_recording_or_value_is_the_commands_one_line_error_and_nothing_else(
    tmp_path: Path,
) -> None:
    for error in (RecordingError("rec.mcap: truncated"), ValueError("a.json: not JSON")):
        with pytest.raises(UserError) as refused:
            with user_errors():
                raise error
        assert str(refused.value) == str(error) and refused.value.__cause__ is None
        assert refused.value.__suppress_context__
    with pytest.raises(KeyError):
        with user_errors():
            raise KeyError("a bug")
    with user_errors():
        pass
    with pytest.raises(UserError) as refused:
        run_estimate(_args(tmp_path / "nowhere", "atda", out=str(tmp_path / "o")))
    assert str(refused.value) == f"{tmp_path / 'nowhere'}: no such file or folder"
    assert not (tmp_path / "o.csv").exists()
