"""Properties of a recording's time alignment, for any stamps: the ranges given to a frame
(:meth:`Recording.ranges_at`) and the vehicle's pose at a stamp (:meth:`PoseSeries.at`) are
the nearest samples within the tolerance, or interpolated between the two around the stamp."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from agents.io.recording import N_SENSORS, PoseSeries, Recording
from estimation.frames import matrix_from_euler_zyx

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
    assert reading.timestamp == t_s
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
