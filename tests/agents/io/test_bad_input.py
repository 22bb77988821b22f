"""Bad recordings: each gives an error naming the file, topic or field, or is skipped and
counted; nothing crashes, and no NaN pose is written as valid."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
from mcap.reader import make_reader
from mcap.writer import Writer

from agents.cli import main
from agents.io import messages as m
from agents.io.bag import read_bag
from agents.io.recording import RecordingError, read_folder
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


def test_ranges_out_of_time_order_name_the_topic(tmp_path: Path) -> None:
    path = tmp_path / "order.mcap"
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        det = m.msg(m.DETECTIONS, header=m.header(0.0, "camera"), miss_reason="", detections=[])
        writer.write("/camera/tag_detections", m.DETECTIONS, det, 0.0)
        for t in (0.2, 0.1):
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
        writer.finish()
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
