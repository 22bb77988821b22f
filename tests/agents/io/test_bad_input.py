"""Bad recordings: each gives an error naming the file, topic or field, or is skipped and
counted; nothing crashes, and no NaN pose is written as valid."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
from mcap.reader import make_reader
from mcap.writer import Writer
from scipy.spatial.transform import Rotation

from agents.cli import main
from agents.io import messages as m
from agents.io.bag import read_bag
from agents.io.recording import RecordingError, Topics, read_folder
from tests.agents.io.test_record import record_episode


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record_episode(tmp_path_factory.mktemp("rec") / "episode.mcap")


def _estimate(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str, str]:
    code = main(["estimate", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _folder(tmp_path: Path, ranges: list[str]) -> Path:
    cv2.imwrite(str(tmp_path / "f0.png"), np.full((48, 64), 128, np.uint8))
    (tmp_path / "frames.csv").write_text("t_s,image\n0.0,f0.png\n0.1,missing.png\n")
    header = "t_s,range_1_m,range_2_m,range_3_m,range_4_m\n"
    (tmp_path / "ranges.csv").write_text(header + "\n".join(ranges) + "\n")
    return tmp_path


def test_folder_ranges_out_of_time_order_name_file_and_line(tmp_path: Path) -> None:
    folder = _folder(tmp_path, ["0.1,1,1,1,1", "0.05,1,1,1,1"])
    with pytest.raises(RecordingError, match=r"ranges.csv line 3: ranges out of time order"):
        read_folder(folder)


def test_folder_missing_column_and_bad_number_are_named(tmp_path: Path) -> None:
    folder = _folder(tmp_path, ["0.1,1,1,1,x"])
    with pytest.raises(RecordingError, match=r"line 2: range_4_m = 'x' is not a number"):
        read_folder(folder)
    (folder / "ranges.csv").write_text("t_s,range_1_m\n0,1\n")
    with pytest.raises(RecordingError, match="missing column"):
        read_folder(folder)


def test_folder_unreadable_image_is_skipped_and_ranges_align(tmp_path: Path) -> None:
    folder = _folder(tmp_path, ["0.0,1.0,,2.0,nan", "0.01,1.2,1,2,3"])
    rec = read_folder(folder)
    assert len(rec.frames) == 1
    assert rec.skipped == {"frames.csv: image missing or unreadable": 1}
    reading = rec.ranges_at(0.004, tolerance_s=0.005)
    assert reading.valid.tolist() == [True, False, True, False]
    assert reading.ranges[0] == 1.0
    half = rec.ranges_at(0.005, tolerance_s=0.01, mode="interpolate")
    assert half.ranges[0] == pytest.approx(1.1) and half.valid.tolist() == [
        True,
        False,
        True,
        False,
    ]
    assert not rec.ranges_at(0.5, tolerance_s=0.02).valid.any()


def test_calibration_for_another_image_size_is_refused_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    (tmp_path / "rec").mkdir()
    folder = _folder(tmp_path / "rec", ["0.0,1,1,1,1"])
    calibration = tmp_path / "cal"
    calibration.mkdir()
    shipped = Path("configs/calibration/intrinsics.json")
    (calibration / "intrinsics.json").write_text(shipped.read_text())
    code, _, err = _estimate(
        capsys,
        "--input",
        str(folder),
        "--estimator",
        "atda",
        "--calibration",
        str(calibration),
        "--out",
        str(tmp_path / "o.csv"),
    )
    assert code == 2
    assert "intrinsics.json is for another camera: image size 512x512" in err
    assert "images are 64x48" in err


def test_missing_camera_topic_lists_what_the_file_has(tmp_path: Path) -> None:
    path = tmp_path / "ranges_only.mcap"
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        message = m.msg(
            m.RANGE,
            header=m.header(0.0, "tof_1"),
            radiation_type=1,
            field_of_view=0.4,
            min_range=0.04,
            max_range=4.0,
            range=1.0,
        )
        writer.write("/tof/range", m.RANGE, message, 0.0)
        writer.finish()
    with pytest.raises(
        RecordingError, match=r"missing topic: .*/camera/image_raw.* has /tof/range"
    ):
        read_bag(path)


def _bag_with_ranges_out_of_order(path: Path, write_range) -> Path:
    """An MCAP with one tag detection and the ranges ``write_range(writer, t)`` writes, at
    t = 0.2 s and then 0.1 s (both received at 0.3 s)."""
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        det = m.msg(m.DETECTIONS, header=m.header(0.0, "camera"), miss_reason="", detections=[])
        writer.write("/camera/tag_detections", m.DETECTIONS, det, 0.0)
        for t in (0.2, 0.1):
            write_range(writer, t)
        writer.finish()
    return path


def test_ranges_out_of_time_order_name_the_topic(tmp_path: Path) -> None:
    def write_range(writer, t: float) -> None:
        message = m.msg(
            m.RANGE,
            header=m.header(t, "tof_2"),
            radiation_type=1,
            field_of_view=0.4,
            min_range=0.04,
            max_range=4.0,
            range=1.0,
        )
        writer.write("/tof/range", m.RANGE, message, 0.3)

    path = _bag_with_ranges_out_of_order(tmp_path / "order.mcap", write_range)
    with pytest.raises(RecordingError, match=r"/tof/range \(sensor 2\): ranges out of time order"):
        read_bag(path)


def test_unknown_image_encoding_is_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "yuv.mcap"
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        image = m.msg(
            m.IMAGE,
            header=m.header(0.0, "camera"),
            height=2,
            width=2,
            encoding="yuv422",
            is_bigendian=0,
            step=4,
            data=np.zeros(8, np.uint8),
        )
        writer.write("/camera/image_raw", m.IMAGE, image, 0.0)
        writer.finish()
    code, _, err = _estimate(
        capsys, "--input", str(path), "--estimator", "atda", "--out", str(tmp_path / "o")
    )
    assert code == 2
    assert "no usable camera frame" in err and "encoding 'yuv422' unknown" in err


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
def test_a_damaged_file_is_a_one_line_error(
    recording: Path,
    tmp_path: Path,
    damage: str,
    capsys: pytest.CaptureFixture,
) -> None:
    data = recording.read_bytes()
    path = tmp_path / f"{damage}.mcap"
    path.write_bytes(
        data[: len(data) // 2] if damage == "truncated" else b"\x89MCAP0\r\n" + bytes(300)
    )
    code, _, err = _estimate(
        capsys, "--input", str(path), "--estimator", "ihrcf", "--out", str(tmp_path / "o")
    )
    assert code == 2
    assert "truncated or corrupt recording" in err and str(path) in err


def test_bad_messages_are_skipped_counted_and_never_a_nan_pose(
    recording: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
) -> None:
    path = tmp_path / "partly_bad.mcap"
    with recording.open("rb") as source, path.open("wb") as stream:
        reader = make_reader(source)
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        ids: dict[int, int] = {}
        cut = 0
        for schema, channel, message in reader.iter_messages():
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(channel.topic, "cdr", sid)
            data = message.data
            if channel.topic == "/camera/tag_detections":
                cut += 1
                if cut % 3 == 0:
                    data = data[:9]  # a cut message
            writer.add_message(ids[channel.id], message.log_time, data, message.publish_time)
        writer.finish()
    out = tmp_path / "est"
    code, printed, err = _estimate(
        capsys, "--input", str(path), "--estimator", "ihrcf", "--out", str(out)
    )
    assert code == 0, err
    assert "skipped 4 bad messages" in printed
    assert "4 x /camera/tag_detections: message cannot be decoded" in printed
    rows = list(csv.DictReader(out.with_suffix(".csv").open()))
    assert rows and all(r["valid"] in ("0", "1") for r in rows)
    for row in rows:
        values = [row[k] for k in ("x_camera_m", "y_camera_m", "z_camera_m")]
        if row["valid"] == "1":
            assert all(np.isfinite(float(v)) for v in values)
        else:
            assert values == ["", "", ""] and row["reason"]


def test_no_ranges_within_tolerance_is_camera_only_or_invalid_with_reason(
    recording: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
) -> None:
    path = tmp_path / "no_ranges.mcap"
    with recording.open("rb") as source, path.open("wb") as stream:
        reader = make_reader(source)
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages():
            if channel.topic in ("/tof/range", "/tof/ranges"):
                continue
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(channel.topic, "cdr", sid)
            writer.add_message(
                ids[channel.id], message.log_time, message.data, message.publish_time
            )
        writer.finish()
    code, _, err = _estimate(
        capsys, "--input", str(path), "--estimator", "ihrcf", "--out", str(tmp_path / "a")
    )
    assert code == 2 and "ihrcf needs ranges; missing: /tof/range" in err
    code, _, _ = _estimate(
        capsys, "--input", str(path), "--estimator", "atda", "--out", str(tmp_path / "b")
    )
    assert code == 0
    rows = list(csv.DictReader((tmp_path / "b.csv").open()))
    assert all(r["ranges_in_tolerance"] == "0" for r in rows)
    assert any(r["valid"] == "1" for r in rows)  # the camera alone


def test_extrinsics_file_gives_body_poses_in_flu_and_frd(
    recording: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
) -> None:
    calibration = tmp_path / "cal"
    calibration.mkdir()
    for name in ("intrinsics.json", "tof_camera.json"):
        (calibration / name).write_text((Path("configs/calibration") / name).read_text())
    r_bc = [[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]
    doc = {
        "format": "deck-landing/camera-extrinsics",
        "format_version": 1,
        "r_bc": r_bc,
        "t_bc_m": [0.1, 0.0, -0.03],
    }
    (calibration / "extrinsics.json").write_text(json.dumps(doc))
    code, _, _ = _estimate(
        capsys,
        "--input",
        str(recording),
        "--estimator",
        "ihrcf",
        "--calibration",
        str(calibration),
        "--out",
        str(tmp_path / "e"),
    )
    assert code == 0
    row = next(r for r in csv.DictReader((tmp_path / "e.csv").open()) if r["valid"] == "1")
    cam = np.array([float(row[f"{a}_camera_m"]) for a in "xyz"])
    flu = np.array([float(row[f"{a}_body_flu_m"]) for a in "xyz"])
    frd = np.array([float(row[f"{a}_body_frd_m"]) for a in "xyz"])
    np.testing.assert_allclose(flu, np.array(r_bc) @ cam + [0.1, 0.0, -0.03], atol=1e-12)
    np.testing.assert_allclose(frd, flu * [1.0, -1.0, -1.0], atol=1e-12)
    assert flu[2] < 0.0 < frd[2]  # the deck below: down in FLU is -z, +z in FRD


def test_a_range_topic_not_in_the_recording_is_refused_naming_it_and_the_topics_there(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    code, _, err = _estimate(
        capsys,
        "--input", str(recording), "--estimator", "ihrcf", "--out", str(tmp_path / "o"),
        "--range-topics", "/tof/rnage",
    )  # fmt: skip
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert f"--range-topics /tof/rnage: not in {recording}; its topics: " in err
    assert "/tof/range" in err.split("its topics: ")[1]
    assert not (tmp_path / "o.csv").exists()


def test_an_empty_folder_says_it_holds_no_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = _estimate(
        capsys, "--input", str(empty), "--estimator", "ihrcf", "--out", str(tmp_path / "o")
    )
    assert code == 2
    assert f"{empty}: no recording in this folder" in err
    assert "corrupt" not in err


# ------------------------------------------------------------------ a recording's messages, each


def _range(t: float, frame_id: str, value: float) -> object:
    return m.msg(
        m.RANGE, header=m.header(t, frame_id), radiation_type=1, field_of_view=0.4,
        min_range=0.04, max_range=4.0, range=value,
    )  # fmt: skip


def _imu(t: float, values: list[float], known: bool) -> object:
    q = m.msg("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.6, w=0.8)
    covariance = np.zeros(9)
    covariance[0] = 0.0 if known else -1.0
    return m.msg(
        m.IMU, header=m.header(t, "body"), orientation=q, orientation_covariance=covariance,
        angular_velocity=m.vector3(values[3:]), angular_velocity_covariance=np.zeros(9),
        linear_acceleration=m.vector3(values[:3]), linear_acceleration_covariance=np.zeros(9),
    )  # fmt: skip


def _tf(t: float, parent: str, child: str, q: list[float], p: list[float]) -> object:
    transform = m.transform(t, parent, child, np.eye(3), np.asarray(p, dtype=float))
    rotation = m.msg("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3])
    transform.transform.rotation = rotation
    return transform


def _every_message(path: Path) -> Path:
    """An MCAP of each kind of message ``read_bag`` reads, good and bad."""
    unit = [0.0, 0.0, 0.0, 1.0]
    with path.open("wb") as stream:
        w = m.McapWriter(stream)
        for k, t in enumerate((0.0, 0.1)):
            detection = m.msg(
                "deck_landing_msgs/msg/TagDetection", id=3, corners_px=np.arange(8.0) + k,
                decision_margin=41.5, hamming=1,
            )  # fmt: skip
            message = m.msg(
                m.DETECTIONS, header=m.header(t, "camera"), miss_reason=f"why {k}",
                detections=[detection] if k == 0 else [],
            )  # fmt: skip
            w.write("/camera/tag_detections", m.DETECTIONS, message, t)
            w.write("/camera/image_raw", m.RANGE, _range(t, "camera", 1.0), t)  # not an image
            yuv = m.msg(
                m.IMAGE, header=m.header(t, "camera"), height=1, width=2, encoding="yuv422",
                is_bigendian=0, step=4, data=np.zeros(4, np.uint8),
            )  # fmt: skip
            w.write("/camera/raw", m.IMAGE, yuv, t)
        w.write("/camera/raw", m.IMAGE, m.image_rgb8(0.2, np.full((1, 2, 3), 7, np.uint8)), 0.2)
        # ranges: one topic by frame id; the min and max range are returns, beyond them none
        for t, frame_id, value in [
            (0.0, "tof_1", 0.04), (0.0, "tof_2", 4.0), (0.0, "tof_3", 4.01),
            (0.0, "tof_4", float("inf")), (0.0, "tof_9", 1.0), (0.1, "tof_9", 1.0),
            (0.1, "tof_1", 2.0),
        ]:  # fmt: skip
            w.write("/tof/range", m.RANGE, _range(t, frame_id, value), t)
            w.write(f"/tof/r{frame_id[-1]}", m.RANGE, _range(t, "any", value), t)
        for t, values, valid in [
            (0.0, [1.0, 2.0, 3.0, 4.0], [True, False, True, True]),
            (0.05, [1.0, 2.0, 3.0], [True, True, True, True]),
            (0.06, [1.0, 2.0, 3.0, 4.0], [True, True, True]),
        ]:
            exact = m.msg(
                m.TOF_RANGES, header=m.header(t, "body"), range_m=np.array(values),
                valid=np.array(valid),
            )  # fmt: skip
            w.write("/tof/ranges", m.TOF_RANGES, exact, t)
        for t, values, known in [
            (0.0, [0.1, 0.2, 9.8, 0.01, 0.02, 0.03], True),
            (0.01, [0.1, float("nan"), 9.8, 0.01, 0.02, 0.03], True),
            (0.02, [0.4, 0.5, 9.6, 0.04, 0.05, float("inf")], False),
            (0.03, [0.4, 0.5, 9.6, 0.04, 0.05, 0.06], False),
        ]:
            w.write("/imu/data", m.IMU, _imu(t, values, known), t)
        transforms = [
            _tf(0.0, "XW", "other", unit, [9.0, 9.0, 9.0]),  # another transform: not read
            _tf(0.0, "/XW", "/XB", [0.0, 0.0, 0.6, 0.8], [3.0, -1.0, 2.0]),
            _tf(0.01, "XW", "XB", [0.5, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),  # |q| 0.5
            _tf(0.02, "XW", "XB", [1.5, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),  # |q| 1.5
            _tf(0.03, "XW", "XB", [0.0, 2.0, 0.0, 0.0], [0.0, 0.0, 0.0]),  # |q| 2
            _tf(0.04, "XW", "XB", unit, [float("nan"), 0.0, 0.0]),
            _tf(0.05, "XW", "XB", [0.0, 0.0, 0.0, 1.4], [1.0, 2.0, 3.0]),  # normalised
        ]
        w.write("/tf", m.TF, m.msg(m.TF, transforms=transforms), 0.0)
        w.write("/not_tf", m.RANGE, _range(0.0, "camera", 1.0), 0.0)  # no transforms
        w.finish()
    return path


def test_each_message_of_a_recording_is_read_or_skipped_under_its_reason(tmp_path: Path) -> None:
    path = _every_message(tmp_path / "every.mcap")
    rec = read_bag(path, Topics(tf_frames=("XW", "XB")))
    # the detections, exactly; the camera topic's other type skipped
    assert [(f.timestamp, f.source, f.miss_reason) for f in rec.frames] == [
        (0.0, "/camera/tag_detections@0.000000000", "why 0"),
        (0.1, "/camera/tag_detections@0.100000000", "why 1"),
    ]
    (detection,) = rec.frames[0].detections
    assert (detection.tag_id, detection.decision_margin, detection.hamming) == (3, 41.5, 1)
    assert isinstance(detection.decision_margin, float) and isinstance(detection.hamming, int)
    np.testing.assert_array_equal(detection.corners_px, np.arange(8.0).reshape(4, 2))
    # the float64 ranges, the two of another length skipped
    assert [s.valid for s in rec.sensors] == [[True], [False], [True], [True]]
    assert [s.range_m[0] for s in rec.sensors if s.valid[0]] == [1.0, 3.0, 4.0]
    # the IMU: a sample with a value not finite skipped; the attitude only where known
    assert [s.timestamp for s in rec.imu] == pytest.approx([0.0, 0.03], abs=1e-12)
    assert rec.imu[1].accel.tolist() == [0.4, 0.5, 9.6]
    assert rec.imu[1].gyro.tolist() == [0.04, 0.05, 0.06]
    np.testing.assert_allclose(rec.attitude[0], Rotation.from_quat([0, 0, 0.6, 0.8]).as_matrix())
    assert rec.attitude[1] is None
    # the vehicle: the world -> body transforms (slashes left off), each a rotation
    assert rec.vehicle.t_s == pytest.approx([0.0, 0.05], abs=1e-12)
    assert rec.vehicle.t_wb[0].tolist() == [3.0, -1.0, 2.0]
    np.testing.assert_allclose(rec.vehicle.r_wb[1], np.eye(3), atol=1e-12)
    assert rec.skipped == {
        "/tof/ranges: range_m/valid not 4 long": 2,
        "/imu/data: a non-finite value": 2,
        "/tf: XW -> XB not finite or not a rotation": 4,
    }
    # the sensor_msgs/Range topics instead: by frame id, or one topic per sensor
    for ranges in (("/tof/range",), ("/tof/r1", "/tof/r2", "/tof/r3", "/tof/r4")):
        rec = read_bag(path, Topics(ranges=ranges, exact_ranges=""))
        assert [s.valid for s in rec.sensors] == [[True, True], [True], [False], [False]]
        # float32 on the wire
        assert rec.sensors[0].range_m == [np.float32(0.04), 2.0]
        assert rec.sensors[1].range_m == [4.0]
        assert math.isnan(rec.sensors[2].range_m[0]) and len(rec.imu) == 2
    assert rec.skipped["/tof/range: header.frame_id 'tof_9' unknown"] == 0
    rec = read_bag(path, Topics(exact_ranges=""))
    assert rec.skipped["/tof/range: header.frame_id 'tof_9' unknown"] == 2
    # the images: one of another type, or of an unknown encoding, skipped under its reason
    rec = read_bag(path, Topics(detections=""))
    assert not rec.frames
    assert rec.skipped["/camera/image_raw: type sensor_msgs/msg/Range is not an image"] == 2
    rec = read_bag(path, Topics(detections="", image="/camera/raw"))
    assert [(f.timestamp, f.source) for f in rec.frames] == [(0.2, "/camera/raw@0.200000000")]
    known = "mono8, 8UC1, rgb8, bgr8, rgba8, bgra8"
    assert rec.skipped[f"/camera/raw: encoding 'yuv422' unknown; known: {known}"] == 2

    # a topic not asked for ("") is not missing, and no other topic is read
    rec = read_bag(path, Topics(tf="", imu="", tf_frames=("XW", "XB")))
    assert rec.missing_topics == [] and len(rec.vehicle) == 0 and not rec.imu
    rec = read_bag(path, Topics(tf="/not_tf"))
    assert len(rec.vehicle) == 0  # a message with no transforms gives none


def test_a_recording_without_what_is_asked_for_is_refused_naming_it_and_what_it_has(
    tmp_path: Path,
) -> None:
    path = _every_message(tmp_path / "every.mcap")
    has = (
        "/camera/image_raw, /camera/raw, /camera/tag_detections, /imu/data, /not_tf, /tf, "
        "/tof/r1, /tof/r2, /tof/r3, /tof/r4, /tof/r9, /tof/range, /tof/ranges"
    )
    cases = [
        (Topics(image="/a", detections="/b"), "missing topic: neither camera topic /a nor /b"),
        (Topics(image="/a", detections=""), "missing topic: camera topic /a"),
        (Topics(image="", detections=""), "missing topic: camera topic (none given)"),
        (Topics(exact_ranges="/x"), "--exact-ranges-topic /x: not in"),
        (Topics(imu="/u"), "--imu-topic /u: not in"),
        (Topics(ranges=("/tof/r1", "/r2", "/tof/r3", "/r4")), "--range-topics /r2,/r4: not in"),
    ]
    for topics, message in cases:
        with pytest.raises(RecordingError) as refused:
            read_bag(path, topics)
        said = str(refused.value)
        assert said.startswith(f"{path}: {message}") or said.startswith(message), said
        assert said.endswith(f"; the file has {has}") or said.endswith(f"; its topics: {has}")
    empty = tmp_path / "empty.mcap"
    with empty.open("wb") as stream:
        m.McapWriter(stream).finish()
    with pytest.raises(RecordingError) as refused:
        read_bag(empty)
    assert str(refused.value).endswith("; the file has none")


def test_a_path_that_is_no_recording_is_refused_saying_why(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"^(.*)/nowhere: no such file or folder$"):
        read_bag(tmp_path / "nowhere")
    with pytest.raises(RecordingError) as refused:
        read_bag(tmp_path)
    assert str(refused.value) == (
        f"{tmp_path}: no recording in this folder (a plain folder has frames.csv, a rosbag2 "
        "folder metadata.yaml)"
    )
    (tmp_path / "metadata.yaml").write_text("not: a rosbag2\n")  # read as one, and refused
    with pytest.raises(RecordingError) as refused:
        read_bag(tmp_path)
    said = str(refused.value)
    assert said.startswith(f"{tmp_path}: truncated or corrupt recording (")
    assert "NoneType" not in said and said.split("(", 1)[1].split(":")[0].isidentifier()


def test_float64_ranges_out_of_time_order_name_the_topic_and_sensor(tmp_path: Path) -> None:
    def write_range(writer, t: float) -> None:
        _, exact = m.tof_messages(
            t, np.ones(4), np.ones(4, bool), min_range_m=0.04, max_range_m=4.0
        )
        writer.write("/tof/ranges", m.TOF_RANGES, exact, 0.3)

    path = _bag_with_ranges_out_of_order(tmp_path / "order.mcap", write_range)
    with pytest.raises(RecordingError, match=r"^/tof/ranges \(sensor 1\): ranges out of time"):
        read_bag(path)


# ------------------------------------------------------------------ the messages written


def test_a_tof_reading_is_one_infrared_range_per_sensor_and_the_float64_ranges(
    tmp_path: Path,
) -> None:
    ranges, exact = m.tof_messages(
        1.5, [1, 2, 3, 4], [1, 0, 1, 1], min_range_m=0.04, max_range_m=4.0
    )  # integers, as a caller may give them
    assert [r.header.frame_id for r in ranges] == ["tof_1", "tof_2", "tof_3", "tof_4"]
    assert [r.range for r in ranges] == [1.0, float("inf"), 3.0, 4.0]  # REP 117: no return
    assert {r.radiation_type for r in ranges} == {1}  # INFRARED
    assert exact.header.frame_id == "body"
    assert exact.range_m.dtype == np.float64 and exact.valid.dtype == bool
    back = m.TYPESTORE.deserialize_cdr(m.TYPESTORE.serialize_cdr(exact, m.TOF_RANGES), m.TOF_RANGES)
    assert back.range_m.tolist() == [1.0, 2.0, 3.0, 4.0]
    assert back.valid.tolist() == [True, False, True, True]
    with pytest.raises(ValueError):  # a frame id per sensor
        m.tof_messages(0.0, [1.0] * 4, [True] * 4, min_range_m=0.0, max_range_m=4.0,
                       frame_ids=("a", "b", "c"))  # fmt: skip


def test_a_stamp_is_whole_nanoseconds_split_into_seconds_and_nanoseconds() -> None:
    for t_s, sec, nanosec in [(100.000000001, 100, 1), (1.999999999, 1, 999_999_999), (0.0, 0, 0)]:
        stamp = m.header(t_s, "f").stamp
        assert (stamp.sec, stamp.nanosec) == (sec, nanosec)
        assert m.to_ns(t_s) == sec * 10**9 + nanosec


def test_an_image_message_is_rgb8_rows_of_the_pictures_bytes() -> None:
    rgba = [[[1, 2, 3, 255], [4, 5, 6, 255]], [[7, 8, 9, 0], [10, 11, 12, 0]]]
    image = m.image_rgb8(0.5, rgba)  # a list of integers, alpha dropped
    assert (image.header.frame_id, image.encoding, image.is_bigendian) == ("camera", "rgb8", 0)
    assert (image.height, image.width, image.step) == (2, 2, 6)
    assert image.data.dtype == np.uint8 and image.data.tolist() == list(range(1, 13))


def test_the_mcap_writer_writes_ros2_cdr_messages_in_order_with_their_schemas(
    tmp_path: Path,
) -> None:
    path = tmp_path / "w.mcap"
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        for t in (0.0, -1.0, 0.25):  # a stamp before 0 is logged at 0
            writer.write("/tof/range", m.RANGE, _range(t, "tof_1", 1.0), t)
        with pytest.raises(ValueError) as refused:
            writer.write("/tof/range", m.IMU, _imu(0.0, [0.0] * 6, True), 0.0)
        assert str(refused.value) == f"topic /tof/range carries {m.RANGE}, not {m.IMU}"
        writer.metadata("rig", {"stages": "2"})
        writer.finish()
    with path.open("rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        assert (header.profile, header.library) == ("ros2", "deck-landing")
        messages = list(reader.iter_messages())
        assert [(msg.sequence, msg.log_time, msg.publish_time) for _, _, msg in messages] == [
            (0, 0, 0), (1, 0, 0), (2, 250_000_000, 250_000_000),
        ]  # fmt: skip
        schema, channel, _ = messages[0]
        assert (schema.name, schema.encoding) == (m.RANGE, "ros2msg")
        assert schema.data.decode() == m.TYPESTORE.generate_msgdef(m.RANGE, ros_version=2)[0]
        assert channel.message_encoding == "cdr"
        summary = reader.get_summary()
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        assert [(r.name, r.metadata) for r in reader.iter_metadata()] == [("rig", {"stages": "2"})]
