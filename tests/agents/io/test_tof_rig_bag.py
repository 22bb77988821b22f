"""``deck-landing calibrate tof --recording REC.mcap`` (or a rosbag2 folder): the simulated
rig's run written as ROS 2 messages calibrates to the plain folder's file, and bad input
is named."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer

from agents.cli import main
from agents.io import messages as m
from agents.io.recording import RecordingError, Topics
from agents.io.tof_rig import write_rig_recording
from agents.io.tof_rig_bag import read_rig_bag, rig_topics, write_rig_mcap
from estimation.tof_calibration import TofCameraCalibration
from estimation.tof_rig import RIG_FILE
from landing_env.calibration.tof_camera_sim import TofRigConfig, record_tof_rig_in_sim
from landing_env.config import load_config

FOUR = ("/tof/a", "/tof/b", "/tof/c", "/tof/d")


@pytest.fixture(scope="module")
def rig():  # type: ignore[no-untyped-def]
    """The simulated rig: noisy sensors that miss returns, so the averaging matters."""
    config = load_config("default", overrides={"tof.noise": "vl53l1x"})
    recorded = record_tof_rig_in_sim(
        config, TofRigConfig(stages=8, readings_per_stage=5), np.random.default_rng(7)
    )
    readings = np.concatenate([s.readings_m[0] for s in recorded.stages])
    assert np.nanstd(readings[:5]) > 0.0
    return recorded


@pytest.fixture(scope="module")
def from_folder(rig, tmp_path_factory: pytest.TempPathFactory) -> Path:  # type: ignore[no-untyped-def]
    """The calibration of the rig's plain folder: tof_camera.json."""
    base = tmp_path_factory.mktemp("folder")
    folder = write_rig_recording(base / "rig", rig.stages, rig.description)
    assert main(["calibrate", "tof", "--recording", str(folder), "--out", str(base / "out")]) == 0
    return base / "out" / "tof_camera.json"


def _calibrate(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str]:
    code = main(["calibrate", "tof", *args])
    return code, capsys.readouterr().err


def _to_rosbag2(mcap: Path, folder: Path) -> Path:
    """The same messages in a rosbag2 folder (sqlite3 storage), written by ``rosbags``."""
    with (
        AnyReader([mcap], default_typestore=m.TYPESTORE) as reader,
        Writer(folder, version=9) as writer,
    ):
        out = {
            c.topic: writer.add_connection(c.topic, c.msgtype, typestore=m.TYPESTORE)
            for c in reader.connections
        }
        for connection, timestamp, raw in reader.messages():
            writer.write(out[connection.topic], timestamp, raw)
    return folder


@pytest.mark.parametrize("container", ["mcap", "rosbag2"])
def test_the_rig_through_mcap_or_rosbag2_calibrates_to_the_folders_file_byte_for_byte(
    rig,
    from_folder: Path,
    tmp_path: Path,
    container: str,
    capsys,  # type: ignore[no-untyped-def]
) -> None:
    """Images as rgb8 (lossless) and the float64 TofRanges beside the Range topic: the same
    pads, the same averages, the same file."""
    recording = write_rig_mcap(tmp_path / "rig.mcap", rig.stages, rig.description)
    assert (tmp_path / RIG_FILE).is_file()  # the stage windows beside it
    if container == "rosbag2":
        recording = _to_rosbag2(recording, tmp_path / "rig_bag")
        (tmp_path / RIG_FILE).rename(recording / RIG_FILE)  # found in the bag's folder
    code, err = _calibrate(capsys, "--recording", str(recording), "--out", str(tmp_path / "out"))
    assert code == 0, err
    assert (tmp_path / "out" / "tof_camera.json").read_text() == from_folder.read_text()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert [s["samples"] for s in summary["sensors"]] == [8, 8, 8, 8]


@pytest.mark.parametrize("layout", ["one topic", "four topics"])
def test_the_float32_range_topics_alone_give_the_pixels_and_the_ranges_to_float32(
    rig,
    from_folder: Path,
    tmp_path: Path,
    layout: str,
    capsys,  # type: ignore[no-untyped-def]
) -> None:
    """Without the float64 TofRanges each range is a float32 (sensor_msgs/Range): the pad
    pixels are the folder's exactly, each stage's mean range within float32 rounding (a
    relative 2^-24 per reading, so for their mean too)."""
    topics = Topics(exact_ranges="", ranges=FOUR if layout == "four topics" else ("/tof/range",))
    stages = tmp_path / "windows.json"  # elsewhere, named by --stages-file
    mcap = write_rig_mcap(tmp_path / "rig.mcap", rig.stages, rig.description, topics, stages)
    args = ["--recording", str(mcap), "--stages-file", str(stages), "--out", str(tmp_path / "out")]
    args += ["--range-topics", ",".join(topics.ranges)]
    code, err = _calibrate(capsys, *args)
    assert code == 0, err
    got = TofCameraCalibration.load(tmp_path / "out" / "tof_camera.json")
    want = TofCameraCalibration.load(from_folder)
    assert got.image_size == want.image_size and got.metadata == want.metadata
    for a, b in zip(got.samples, want.samples, strict=True):
        np.testing.assert_array_equal(a[:, 1:], b[:, 1:])
        np.testing.assert_allclose(a[:, 0], b[:, 0], rtol=2.0**-24, atol=0.0)
    # the float32 rounding shows: these ranges are not the folder's to the bit
    pairs = zip(got.samples, want.samples, strict=True)
    assert any(not np.array_equal(a[:, 0], b[:, 0]) for a, b in pairs)


# ------------------------------------------------------------------ bad input
@pytest.fixture(scope="module")
def rig_mcap(rig, tmp_path_factory: pytest.TempPathFactory) -> Path:  # type: ignore[no-untyped-def]
    """The rig's MCAP, Range topic only (no float64 ranges), its stage windows beside it."""
    base = tmp_path_factory.mktemp("rig_mcap")
    return write_rig_mcap(base / "rig.mcap", rig.stages, rig.description, Topics(exact_ranges=""))


def test_an_mcap_without_its_stage_windows_names_the_option(
    rig,
    tmp_path: Path,
    capsys,  # type: ignore[no-untyped-def]
) -> None:
    mcap = write_rig_mcap(tmp_path / "rig.mcap", rig.stages, rig.description)
    (tmp_path / RIG_FILE).unlink()
    code, err = _calibrate(capsys, "--recording", str(mcap), "--out", str(tmp_path / "o"))
    assert code == 2
    assert f"{mcap}: no {RIG_FILE} beside it and no --stages-file FILE given" in err
    missing = tmp_path / "windows.json"
    args = ["--recording", str(mcap), "--stages-file", str(missing), "--out", str(tmp_path / "o")]
    code, err = _calibrate(capsys, *args)
    assert code == 2 and f"--stages-file {missing}: no such file" in err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--image-topic", "/cam/none"], "missing topic: camera topic /cam/none; the file has"),
        (["--range-topics", "/tof/other"], "--range-topics /tof/other: not in"),
        (["--range-topics", ",".join(FOUR)], "--range-topics /tof/a,/tof/b,/tof/c,/tof/d: not in"),
        (
            ["--range-frames", "tof_1,tof_2,tof_3,tof_9"],
            "no range of sensor 4 (frame id tof_9 on /tof/range)",
        ),
        (["--range-topics", "/a,/b"], "range topics: give one (sensors by frame id) or 4"),
    ],
)
def test_a_missing_topic_is_named(
    rig_mcap: Path, tmp_path: Path, extra: list[str], message: str, capsys
) -> None:
    args = ["--recording", str(rig_mcap), "--out", str(tmp_path / "o"), *extra]
    code, err = _calibrate(capsys, *args)
    assert code == 2
    assert message in err


def test_a_truncated_mcap_is_named(rig_mcap: Path, tmp_path: Path, capsys) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(rig_mcap.read_bytes()[: rig_mcap.stat().st_size // 2])
    args = ["--recording", str(cut), "--stages-file", str(rig_mcap.parent / RIG_FILE)]
    code, err = _calibrate(capsys, *args, "--out", str(tmp_path / "o"))
    assert code == 2
    assert f"{cut}: truncated or corrupt recording" in err


def test_a_stage_window_without_an_image_names_the_topic(
    rig_mcap: Path, tmp_path: Path, capsys
) -> None:
    doc = json.loads((rig_mcap.parent / RIG_FILE).read_text())
    doc["stages"].append({"t_start_s": 1000.0, "t_end_s": 1001.0})
    stages = tmp_path / "late.json"
    stages.write_text(json.dumps(doc))
    out = str(tmp_path / "o")
    args = ["--recording", str(rig_mcap), "--stages-file", str(stages), "--out", out]
    code, err = _calibrate(capsys, *args)
    assert code == 2
    assert "stages[8] (1000.0 to 1001.0 s): no frame of /camera/image_raw in it" in err


@pytest.mark.parametrize(
    ("topics", "named"),
    [
        (Topics(), "/tof/ranges"),
        (Topics(exact_ranges=""), "/tof/range"),
        (Topics(exact_ranges="", ranges=FOUR), "/tof/a, /tof/b, /tof/c, /tof/d"),
    ],
)
def test_a_stage_window_without_a_range_names_the_range_topics(
    rig, tmp_path: Path, topics: Topics, named: str, capsys
) -> None:
    mcap = write_rig_mcap(tmp_path / "rig.mcap", rig.stages, rig.description, topics)
    t_frame = rig.stages[0].frames[0].t_s
    assert all(t_frame not in t for t in rig.stages[0].reading_t_s)  # the frame's instant alone
    doc = json.loads((tmp_path / RIG_FILE).read_text())
    doc["stages"][0] = {"t_start_s": t_frame, "t_end_s": t_frame}
    (tmp_path / RIG_FILE).write_text(json.dumps(doc))
    args = ["--recording", str(mcap), "--out", str(tmp_path / "o")]
    args += ["--range-topics", ",".join(topics.ranges), "--exact-ranges-topic", topics.exact_ranges]
    code, err = _calibrate(capsys, *args)
    assert code == 2
    assert f"s): no range sample of {named} in it\n" in err, err


def test_a_rigs_run_is_read_from_its_images_and_ranges_alone() -> None:
    topics = rig_topics(Topics(image="/cam", ranges=("/r",), range_frames=("a", "b", "c", "d")))
    assert (topics.detections, topics.imu, topics.tf) == ("", "", "")
    assert (topics.image, topics.ranges, topics.range_frames) == (
        "/cam",
        ("/r",),
        ("a", "b", "c", "d"),
    )
    assert rig_topics() == dataclasses.replace(Topics(), detections="", imu="", tf="")


def _ranges_written(path: Path) -> list:
    with AnyReader([path], default_typestore=m.TYPESTORE) as reader:
        ranges = [c for c in reader.connections if c.msgtype == m.RANGE]
        return [
            (c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages(ranges)
        ]


def test_a_rigs_ranges_are_written_with_its_frame_ids_and_maximum_and_read_as_the_folder(
    rig, tmp_path: Path
) -> None:
    stage = rig.stages[0]
    first = [np.array(r, dtype=float) for r in stage.readings_m]
    first[0][1], first[1][1] = 0.0, -0.5  # a range of 0 m is a return, a negative one is not
    stages = [dataclasses.replace(stage, readings_m=tuple(first)), *rig.stages[1:]]
    frames = ("a", "b", "c", "d")
    for max_range, maximum in ((None, float(np.finfo(np.float32).max)), (3.5, 3.5)):
        description = dataclasses.replace(rig.description, tof_max_range_m=max_range)
        topics = Topics(ranges=("/r",), range_frames=frames)
        path = write_rig_mcap(tmp_path / "new" / "folder" / "rig.mcap", stages, description, topics)
        written = _ranges_written(path)
        assert {message.header.frame_id for _, message in written} == set(frames)
        assert {message.max_range for _, message in written} == {np.float32(maximum)}
        rec = read_rig_bag(path, topics)
        assert rec.sensors[0].valid[1] and rec.sensors[0].range_m[1] == 0.0
        assert not rec.sensors[1].valid[1] and math.isnan(rec.sensors[1].range_m[1])
    four = Topics(ranges=FOUR, range_frames=frames)  # a topic per sensor: the sensors' own ids
    path = write_rig_mcap(tmp_path / "four.mcap", stages, rig.description, four)
    assert {(t, msg.header.frame_id) for t, msg in _ranges_written(path)} == set(
        zip(FOUR, m.TOF_FRAME_IDS, strict=True)
    )


def test_a_rigs_missing_range_topic_or_sensor_is_named_exactly(rig, tmp_path: Path) -> None:
    path = write_rig_mcap(
        tmp_path / "rig.mcap", rig.stages, rig.description, Topics(ranges=FOUR, exact_ranges="")
    )
    with pytest.raises(RecordingError) as refused:
        read_rig_bag(path, Topics(exact_ranges=""))
    assert str(refused.value) == (
        f"{path}: missing topic(s) /tof/range (sensor_msgs/Range of the ToF sensors; nor an "
        "exact ranges topic)"
    )
    with pytest.raises(RecordingError) as refused:
        read_rig_bag(path, Topics())
    assert str(refused.value).endswith("ToF sensors; nor /tof/ranges)")
    twice = ("/tof/a", "/tof/a", "/tof/c", "/tof/d")  # sensor 2's topic names sensor 1's
    with pytest.raises(RecordingError) as refused:
        read_rig_bag(path, Topics(ranges=twice, exact_ranges=""))
    assert str(refused.value) == f"{path}: no range of sensor 2 (topic /tof/a)"
