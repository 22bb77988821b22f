"""Properties of a recording's time alignment, for any stamps: the ranges given to a frame
(:meth:`Recording.ranges_at`) and the vehicle's pose at a stamp (:meth:`PoseSeries.at`) are
the nearest samples within the tolerance, or interpolated between the two around the stamp."""

from __future__ import annotations

import math
from argparse import Namespace
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from agents.io.recording import (
    N_SENSORS,
    PoseSeries,
    Recording,
    RecordingError,
    Topics,
    read_folder,
    write_folder,
)
from estimation.frames import matrix_from_euler_zyx
from estimation.types import ImuSample

PROPERTY = settings(max_examples=200, deadline=None)
MODES = ("nearest", "interpolate")


def stamped(gaps_ms: list[int]) -> list[float]:
    """Stamps in seconds from the gaps between them in milliseconds."""
    return [k * 1e-3 for k in np.cumsum(gaps_ms).tolist()]


#: stamps on a millisecond grid up to 60 ms apart, repeats allowed (two drivers stamping the
#: same instant)
stamps = st.lists(st.integers(0, 60), max_size=25).map(stamped)
#: a sensor's samples: (stamp, range, valid), in time order
samples = st.lists(
    st.tuples(st.integers(0, 60), st.floats(0.05, 8.0), st.booleans()), max_size=20
).map(
    lambda rows: [
        (t, r, ok) for t, (_, r, ok) in zip(stamped([g for g, _, _ in rows]), rows, strict=True)
    ]
)
tolerances = st.floats(0.0, 0.1)


def frame_stamp(data: st.DataObject, times: list[float]) -> float:
    """A frame's stamp over the samples' span and a little beyond."""
    return data.draw(st.floats(-0.02, max(times, default=0.0) + 0.02), label="t_s")


def within(t_i: float, t_s: float, tolerance_s: float) -> bool:
    return abs(t_i - t_s) <= tolerance_s + 1e-12


def expected_range(
    rows: list[tuple[float, float, bool]], t_s: float, tolerance_s: float, mode: str
) -> set[float | None]:
    """What the sensor may give the frame, by search over every sample: the interpolated
    range, or the nearest samples' ranges (None: invalid), or {None} when none is near."""
    if mode == "interpolate":
        before = [row for row in rows if row[0] < t_s]
        after = [row for row in rows if row[0] >= t_s]
        if before and after:
            (t0, r0, ok0), (t1, r1, ok1) = before[-1], after[0]
            if ok0 and ok1 and within(t0, t_s, tolerance_s) and within(t1, t_s, tolerance_s):
                w = (t_s - t0) / (t1 - t0)
                return {(1.0 - w) * r0 + w * r1}
    near = [row for row in rows if within(row[0], t_s, tolerance_s)]
    if not near:
        return {None}
    closest = min(abs(t - t_s) for t, _, _ in near)
    return {r if ok else None for t, r, ok in near if abs(t - t_s) == closest}


@PROPERTY
@given(
    data=st.data(),
    sensors=st.lists(samples, min_size=N_SENSORS, max_size=N_SENSORS),
    tolerance_s=tolerances,
    mode=st.sampled_from(MODES),
)
def test_each_sensors_range_for_a_frame_is_the_nearest_or_the_interpolated_one(
    data: st.DataObject, sensors: list, tolerance_s: float, mode: str
) -> None:
    t_s = frame_stamp(data, [t for rows in sensors for t, _, _ in rows])
    rec = Recording()
    for series, rows in zip(rec.sensors, sensors, strict=True):
        for t, r, ok in rows:
            series.add(t, r, ok, "test")
    reading = rec.ranges_at(t_s, tolerance_s, mode)
    assert reading.timestamp == t_s and reading.valid.dtype == bool
    for i, rows in enumerate(sensors):
        got = float(reading.ranges[i]) if reading.valid[i] else None
        allowed = expected_range(rows, t_s, tolerance_s, mode)
        if got is None:
            assert None in allowed and math.isnan(reading.ranges[i]), (i, allowed)
        else:
            assert any(a is not None and abs(a - got) <= 1e-12 for a in allowed), (i, got, allowed)


def angle_between(a: np.ndarray, b: np.ndarray) -> float:
    return float(Rotation.from_matrix(a.T @ b).magnitude())


@PROPERTY
@given(
    data=st.data(),
    times=stamps,
    headings=st.lists(st.floats(-3.0, 3.0), min_size=25, max_size=25),
    tolerance_s=tolerances,
    mode=st.sampled_from(MODES),
)
def test_the_vehicles_pose_at_a_stamp_is_the_nearest_or_between_the_two_around_it(
    data: st.DataObject, times: list[float], headings: list[float], tolerance_s: float, mode: str
) -> None:
    t_s = frame_stamp(data, times)
    # any order: a bag's /tf need not be sorted
    times = data.draw(st.permutations(times), label="order")
    poses = PoseSeries()
    for t, yaw in zip(times, headings, strict=False):
        poses.add(t, matrix_from_euler_zyx(0.1, -0.2, yaw), np.array([t, 2.0 * t, yaw]))
    found = poses.at(t_s, tolerance_s, mode)
    rows = sorted(zip(times, headings, strict=False), key=lambda row: row[0])
    near = [(t, yaw) for t, yaw in rows if within(t, t_s, tolerance_s)]
    if not near:
        assert found is None
        return
    assert found is not None
    r_wb, t_wb = found
    np.testing.assert_allclose(r_wb.T @ r_wb, np.eye(3), atol=1e-9)
    before = [row for row in rows if row[0] < t_s]
    after = [row for row in rows if row[0] >= t_s]
    if mode == "interpolate" and before and after:
        (t0, yaw0), (t1, yaw1) = before[-1], after[0]
        if within(t0, t_s, tolerance_s) and within(t1, t_s, tolerance_s):
            w = (t_s - t0) / (t1 - t0)
            np.testing.assert_allclose(t_wb[:2], [t_s, 2.0 * t_s], atol=1e-9)
            np.testing.assert_allclose(t_wb[2], (1.0 - w) * yaw0 + w * yaw1, atol=1e-9)
            # slerp: along the shortest arc, at the fraction w of it
            r0 = matrix_from_euler_zyx(0.1, -0.2, yaw0)
            r1 = matrix_from_euler_zyx(0.1, -0.2, yaw1)
            whole = angle_between(r0, r1)
            assert abs(angle_between(r0, r_wb) - w * whole) < 1e-7
            assert abs(angle_between(r_wb, r1) - (1.0 - w) * whole) < 1e-7
            return
    closest = min(abs(t - t_s) for t, _ in near)
    picks = [(t, yaw) for t, yaw in near if abs(t - t_s) == closest]
    assert any(
        t_wb[0] == t and t_wb[2] == yaw and np.allclose(r_wb, matrix_from_euler_zyx(0.1, -0.2, yaw))
        for t, yaw in picks
    ), (t_wb, picks)


# ------------------------------------------------------------------ the plain folder, the IMU

IMU_HEADER = "t_s,ax,ay,az,gx,gy,gz,qx,qy,qz,qw\n"


def folder_with(tmp_path: Path, frames: str, ranges: str = "", imu: str = "") -> Path:
    """A plain folder: one grey image ``f.png`` and the CSV files given (header included)."""
    cv2.imwrite(str(tmp_path / "f.png"), np.full((4, 6), 90, np.uint8))
    (tmp_path / "frames.csv").write_text(frames)
    if ranges:
        (tmp_path / "ranges.csv").write_text(ranges)
    if imu:
        (tmp_path / "imu.csv").write_text(imu)
    return tmp_path


def test_a_folders_imu_reads_each_sample_with_its_attitude_and_counts_rows_not_numbers(
    tmp_path: Path,
) -> None:
    rows = [
        "1.0,0.1,0.2,9.8,0.01,0.02,0.03,0,0,0.6,0.8",  # a unit quaternion
        "1.1,nan,0.2,9.8,0.01,0.02,0.03,,,,",  # skipped
        "1.2,0.4,0.5,9.6,0.04,0.05,0.06,,,,",  # no attitude
        "1.3,0.1,0.2,9.8,0.01,0.02,,,,,",  # skipped
        "1.4,0.1,0.2,9.8,0.01,0.02,0.03,0,0,0,1.49",  # within 0.5 of 1: normalised
        "1.5,0.1,0.2,9.8,0.01,0.02,0.03,0,0,0,1.5",  # not a rotation
        "1.6,0.1,0.2,9.8,0.01,0.02,0.03,0.5,0,0,0",  # not a rotation
        "1.7,0.1,0.2,9.8,0.01,0.02,0.03,0,0,2,0",  # not a rotation
        "1.8,0.1,0.2,9.8,0.01,0.02,0.03,0,nan,0,1",  # not a rotation
    ]
    folder = folder_with(tmp_path, "t_s,image\n1.0,f.png\n", imu=IMU_HEADER + "\n".join(rows))
    rec = read_folder(folder)
    assert rec.skipped == {"imu.csv: a value is not a number": 2}
    assert [s.timestamp for s in rec.imu] == [1.0, 1.2, 1.4, 1.5, 1.6, 1.7, 1.8]
    assert rec.imu[1].accel.tolist() == [0.4, 0.5, 9.6]
    assert rec.imu[1].gyro.tolist() == [0.04, 0.05, 0.06]
    np.testing.assert_allclose(rec.attitude[0], Rotation.from_quat([0, 0, 0.6, 0.8]).as_matrix())
    np.testing.assert_allclose(rec.attitude[2], np.eye(3))
    assert [r is None for r in rec.attitude] == [False, True, False, True, True, True, True]


def test_a_folders_frames_and_ranges_name_the_file_line_and_column_of_a_bad_number(
    tmp_path: Path,
) -> None:
    header = "t_s,range_1_m,range_2_m,range_3_m,range_4_m\n"
    cases = [
        ("t_s,image\nx,f.png\n", "", r"frames.csv line 2: t_s = 'x' is not a number"),
        ("t_s,image\n0.2,f.png\n0.1,f.png\n", "", r"frames.csv line 3: frames out of time order"),
        ("t_s,image\n0,f.png\n", header + "0,1,1,1,1\nx,1,1,1,1\n", r"ranges.csv line 3: t_s = "),
        ("t_s,image\n0,f.png\n", header + ",1,1,1,1\n", r"ranges.csv line 2: t_s is not a number"),
        ("t_s,image\n0,f.png\n", header + "0,1,y,1,1\n", r"ranges.csv line 2: range_2_m = 'y'"),
        ("t_s,image\n0,f.png\n", "t_s,range_1_m\n0,1\n", r"column\(s\) range_2_m, range_3_m, "),
        ("t_s,image\n0,f.png\n", "t_s,range_1_m\n0,1\n", r"; has t_s, range_1_m$"),
        ("t_s,image\n0,f.png\n", "", r"imu.csv line 2: gz = 'z' is not a number"),
    ]
    for frames, ranges, message in cases:
        folder = folder_with(tmp_path, frames, ranges, IMU_HEADER + "0,0,0,0,0,0,z,,,,\n")
        if not ranges:
            (folder / "ranges.csv").unlink(missing_ok=True)
        with pytest.raises(RecordingError, match=message):
            read_folder(folder)
    folder = folder_with(tmp_path, "t_s,image\n0,f.png\n", "", IMU_HEADER + "0,0,0,0,0,0,0,q,,,\n")
    with pytest.raises(RecordingError, match=r"imu.csv line 2: qx = 'q' is not a number"):
        read_folder(folder)
    (tmp_path / "imu.csv").unlink()
    (tmp_path / "frames.csv").write_bytes(b"t_s,image\n\x00\xff\xfe\n")
    with pytest.raises(RecordingError, match=r"frames.csv: not a CSV file \("):
        read_folder(tmp_path)
    with pytest.raises(RecordingError, match=r"empty: no frames.csv \(columns t_s,image\)"):
        read_folder(tmp_path / "empty")


def test_frames_without_a_stamp_or_image_are_each_counted_and_the_rest_read(
    tmp_path: Path,
) -> None:
    frames = (
        "t_s,image\n,f.png\n0.1,f.png\nnan,f.png\n0.1,f.png\n0.2,no.png\n0.3,no.png\n0.4,f.png\n"
    )
    rec = read_folder(folder_with(tmp_path, frames))
    assert [f.timestamp for f in rec.frames] == [0.1, 0.1, 0.4]  # one stamp twice is kept
    assert rec.skipped == {
        "frames.csv: t_s not a number": 2,
        "frames.csv: image missing or unreadable": 2,
    }


def test_a_range_of_zero_is_a_return_and_a_negative_or_missing_one_is_none_and_nan(
    tmp_path: Path,
) -> None:
    ranges = "t_s,range_1_m,range_2_m,range_3_m,range_4_m\n0.0,0.0,-0.5,,nan\n"
    rec = read_folder(folder_with(tmp_path, "t_s,image\n0,f.png\n", ranges))
    assert [s.valid for s in rec.sensors] == [[True], [False], [False], [False]]
    assert rec.sensors[0].range_m == [0.0]
    # an invalid sample keeps no range (the ToF rig reads the ranges alone)
    assert all(math.isnan(s.range_m[0]) for s in rec.sensors[1:])


def test_a_written_folder_reads_back_with_no_return_as_an_empty_cell(tmp_path: Path) -> None:
    image = np.arange(12, dtype=np.uint8).reshape(3, 4)
    folder = tmp_path / "a" / "b"  # made with its parents
    write_folder(folder, [(0.5, "f.png", image)], [(0.5, [1.25, math.nan, 0.0, 2.0])])
    assert (folder / "ranges.csv").read_text().splitlines()[1] == "0.5,1.25,,0.0,2.0"
    write_folder(folder, [(0.5, "f.png", image)], [(0.5, [1.0, 1.0, 1.0, 1.0])])  # again
    rec = read_folder(folder)
    np.testing.assert_array_equal(rec.frames[0].image, image)
    with pytest.raises(RecordingError, match=r"b/none/f.png: OpenCV cannot write this image"):
        write_folder(folder, [(0.5, "none/f.png", image)], [])
    with pytest.raises(RecordingError, match=r"^3 ranges at 0.5 s; need 4$"):
        write_folder(folder, [], [(0.5, [1.0, 1.0, 1.0])])


def imu_recording(stamps_s: list[float], attitudes: list[np.ndarray | None]) -> Recording:
    rec = Recording()
    for t in stamps_s:
        rec.imu.append(ImuSample(t, np.zeros(3), np.zeros(3)))
    rec.attitude.extend(attitudes)
    return rec


def test_the_imu_between_two_frames_is_after_the_first_and_up_to_the_second_to_the_nanosecond() -> (
    None
):
    ns = 1e-9
    stamps = [100.0, 100.0 + 50 * ns, 150.0, 200.0 - 50 * ns, 200.0, 200.0 + 50 * ns]
    rec = imu_recording(stamps, [None] * len(stamps))
    between = [s.timestamp for s in rec.imu_between(100.0, 200.0)]
    assert between == stamps[1:5]
    # a stamp read back off by less than half a nanosecond is the same stamp
    assert [s.timestamp for s in rec.imu_between(100.0 + 0.4 * ns, 200.0 - 0.4 * ns)] == between
    assert [s.timestamp for s in rec.imu_between(-math.inf, 200.0)] == stamps[:5]
    assert rec.imu_between(200.0, 100.0) == []


def test_the_attitude_at_a_stamp_is_the_latest_recorded_at_or_before_it() -> None:
    ns = 1e-9
    r0, r2 = matrix_from_euler_zyx(0.1, 0.0, 0.0), matrix_from_euler_zyx(0.0, 0.2, 0.0)
    rec = imu_recording([100.0, 101.0, 102.0, 103.0], [r0, None, r2, None])
    assert rec.attitude_at(99.0) is None
    assert rec.attitude_at(100.0) is r0
    assert rec.attitude_at(101.5) is r0  # a sample without one leaves the last
    assert rec.attitude_at(102.0 - 50 * ns) is r0
    assert rec.attitude_at(102.0) is r2
    assert rec.attitude_at(1e6) is r2
    rec.attitude.pop()
    with pytest.raises(ValueError):  # an attitude list not one per sample
        rec.attitude_at(1e6)


def test_topics_take_each_option_given_and_the_default_for_each_left_out() -> None:
    given_ = Namespace(
        image_topic="/i", detections_topic="/d", range_topics="/r1, /r2,/r3,/r4",
        range_frames=None, exact_ranges_topic="/x", imu_topic="/u", tf_topic="",
        tf_frames="map,base",
    )  # fmt: skip
    topics = Topics.from_arguments(given_)
    assert topics == Topics(
        image="/i", detections="/d", ranges=("/r1", "/r2", "/r3", "/r4"), exact_ranges="/x",
        imu="/u", tf="", tf_frames=("map", "base"),
    )  # fmt: skip
    assert Topics.from_arguments(Namespace()) == Topics()
    with pytest.raises(RecordingError, match=r"^--tf-frames: give PARENT,CHILD \(e.g. world,body"):
        Topics.from_arguments(Namespace(tf_frames="map"))


def test_one_range_topic_needs_four_frame_ids_and_four_topics_need_none() -> None:
    four = ("/a", "/b", "/c", "/d")
    assert Topics(ranges=four, range_frames=("x",)).ranges == four
    for frames in (("x",), ("a", "b", "c")):
        with pytest.raises(RecordingError, match=r"^range frame ids: give 4, got "):
            Topics(ranges=("/r",), range_frames=frames)
