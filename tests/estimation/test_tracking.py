"""Corner tracking across detection dropouts (estimation.tracking)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.camera_model import CameraIntrinsics
from estimation.frames import tof_positions_in_camera_frame
from estimation.registry import make_estimator
from estimation.synthetic import SyntheticScene
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import TAG_LOST, CornerTracker, CornerTrackerConfig, TrackedEstimator
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading, TagDetection
from landing_env.errors import ConfigError

DT = 0.05
START = np.array([[200.0, 300.0], [300.0, 300.0], [300.0, 200.0], [200.0, 200.0]])
VELOCITY = np.array([[40.0, -25.0], [42.0, -25.0], [42.0, -22.0], [40.0, -22.0]])  # px/s


def truth(k: int) -> np.ndarray:
    return START + VELOCITY * k * DT


def test_a_short_dropout_is_bridged_close_to_constant_velocity_truth() -> None:
    tracker = CornerTracker(dt=DT, process_noise=20.0, measurement_noise=0.3, max_bridged_frames=3)
    rng = np.random.default_rng(0)
    for k in range(30):
        out = tracker.update(truth(k) + rng.normal(0.0, 0.3, size=(4, 2)), k * DT)
        assert out.valid and not out.predicted and out.bridged_count == 0
    for k in range(30, 33):
        out = tracker.update(None, k * DT)
        assert out.valid and out.predicted and out.bridged_count == k - 29
        # 0.3 px detection noise: the extrapolated corners stay within a pixel (worst
        # coordinate; measured ≤ 0.85 px over 20 seeds)
        assert np.max(np.abs(out.corners_px - truth(k))) < 1.0
    # the fourth consecutive miss exceeds max_bridged_frames: the track is dropped
    lost = tracker.update(None, 33 * DT)
    assert not lost.valid and lost.bridged_count == 4 and np.all(np.isnan(lost.corners_px))
    assert not tracker.active
    assert not tracker.update(None, 34 * DT).valid
    # a new detection starts a new track
    restart = tracker.update(truth(35), 35 * DT)
    assert restart.valid and not restart.predicted
    np.testing.assert_array_equal(restart.corners_px, truth(35))


def test_noise_free_constant_velocity_is_extrapolated_almost_exactly() -> None:
    tracker = CornerTracker(dt=DT, process_noise=1e3, measurement_noise=0.1, max_bridged_frames=5)
    for k in range(40):
        tracker.update(truth(k), k * DT)
    for k in range(40, 45):
        out = tracker.update(None, k * DT)
        assert np.max(np.abs(out.corners_px - truth(k))) < 1e-3


def test_without_timestamps_the_tracker_steps_by_dt() -> None:
    tracker = CornerTracker(dt=DT, process_noise=1e3, measurement_noise=0.1, max_bridged_frames=2)
    for k in range(40):
        tracker.update(truth(k))
    out = tracker.update(None)
    assert np.max(np.abs(out.corners_px - truth(40))) < 1e-3


def test_nothing_is_bridged_before_the_first_detection_and_time_going_back_resets() -> None:
    tracker = CornerTracker()
    first = tracker.update(None, 0.0)
    assert not first.valid and not first.predicted
    tracker.update(truth(0), 1.0)
    tracker.update(truth(1), 1.05)
    # a replayed clock: the old track (and its velocity) must not leak into the new one
    out = tracker.update(None, 0.5)
    assert not out.valid
    out = tracker.update(truth(3), 0.6)
    assert out.valid and not out.predicted


def test_nan_corners_count_as_a_missed_detection() -> None:
    tracker = CornerTracker(dt=DT, max_bridged_frames=1)
    tracker.update(truth(0), 0.0)
    out = tracker.update(np.full((4, 2), np.nan), DT)
    assert out.valid and out.predicted and out.bridged_count == 1


def test_smoothing_reduces_corner_noise_on_a_static_tag() -> None:
    rng = np.random.default_rng(4)
    raw = CornerTracker(dt=DT, process_noise=10.0, measurement_noise=1.0)
    smooth = CornerTracker(dt=DT, process_noise=10.0, measurement_noise=1.0, smooth=True)
    raw_err, smooth_err = [], []
    for k in range(200):
        measured = START + rng.normal(0.0, 1.0, size=(4, 2))
        raw_err.append(np.abs(raw.update(measured, k * DT).corners_px - START).mean())
        smooth_err.append(np.abs(smooth.update(measured, k * DT).corners_px - START).mean())
    # pass-through is the raw detection; the filter averages the noise down
    assert np.mean(raw_err[50:]) == pytest.approx(np.sqrt(2.0 / np.pi), rel=0.15)
    assert np.mean(smooth_err[50:]) < 0.5 * np.mean(raw_err[50:])


def test_tracker_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="dt"):
        CornerTracker(dt=0.0)
    with pytest.raises(ConfigError, match="max_bridged_frames"):
        CornerTrackerConfig(max_bridged_frames=-1)
    tracker = CornerTracker.from_config(CornerTrackerConfig(max_bridged_frames=7))
    assert tracker.config.max_bridged_frames == 7


@pytest.mark.parametrize("name", ["atda", "ihrcf", "crhf"])
def test_tracked_estimator_bridges_a_dropout_then_reports_the_tag_lost(name: str) -> None:
    k = CameraIntrinsics()
    cal = TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), 0.2, 5.0)
    inner = make_estimator(name, intrinsics=k, tag_size=0.15, tof_calibration=cal)
    tracked = TrackedEstimator(
        inner, CornerTracker(dt=DT, process_noise=1e3, measurement_noise=0.1, max_bridged_frames=3)
    )
    assert tracked.name == f"{name}+kf"
    scene = SyntheticScene(k, 0.15)
    rotation = np.eye(3)
    velocity = np.array([0.2, -0.1, 0.0])  # m/s, a deck drifting sideways

    def step(i: int, drop: bool):
        t = i * DT
        translation = np.array([0.0, 0.0, 1.5]) + velocity * t
        m = scene.measure(rotation, translation, timestamp=t)
        frame = CameraFrame(t, (), miss_reason="dropout") if drop else m.frame
        return tracked.estimate(frame, m.ranges), translation

    for i in range(20):
        estimate, translation = step(i, drop=False)
        assert estimate.valid and not estimate.predicted
        assert np.linalg.norm(estimate.translation - translation) < 1e-6
    for i in range(20, 23):
        estimate, translation = step(i, drop=True)
        assert estimate.valid and estimate.predicted, estimate.reason
        assert estimate.extras["bridged_count"] == i - 19
        # the projected motion is not exactly constant-velocity in pixels: mm-level error
        assert np.linalg.norm(estimate.translation - translation) < 5e-3
    estimate, _ = step(23, drop=True)
    assert not estimate.valid and estimate.reason == "tag_lost"
    tracked.reset()
    estimate, _ = step(24, drop=True)
    assert not estimate.valid


class _ReferenceTracker:
    """The tracker's specification, written out: per corner coordinate a textbook Kalman
    filter on (position, velocity) in matrix form, with the track's start, bridging and drop."""

    def __init__(self, config: CornerTrackerConfig) -> None:
        self.c = config
        self.x: np.ndarray | None = None  # (8, 2)
        self.p = np.zeros((2, 2))
        self.time: float | None = None
        self.misses = 0

    def step(self, corners: np.ndarray | None, stamp: float | None):
        now = (self.time if self.time is not None else 0.0) + self.c.dt if stamp is None else stamp
        if self.time is not None and now < self.time:
            self.x, self.time = None, None
        if corners is not None:
            corners = np.asarray(corners, dtype=float)
            if corners.shape != (4, 2) or not np.all(np.isfinite(corners)):
                corners = None
        if corners is None:
            if self.x is None:
                return None, False, 0, False
            self.misses += 1
            if self.misses > self.c.max_bridged_frames:
                self.x, self.time = None, None
                return None, False, self.misses, False
            self._predict(now)
            return self.x[:, 0].reshape(4, 2), True, self.misses, True
        z = corners.reshape(-1)
        if self.x is None:
            self.x = np.column_stack([z, np.zeros(8)])
            self.p = np.diag([self.c.measurement_noise**2, self.c.initial_velocity_std**2])
            self.time, self.misses = now, 0
            return corners, False, 0, True
        self._predict(now)
        h = np.array([[1.0, 0.0]])
        k = self.p @ h.T / (h @ self.p @ h.T + self.c.measurement_noise**2)  # (2, 1)
        self.x = self.x + (z - self.x[:, 0])[:, None] * k.T
        self.p = (np.eye(2) - k @ h) @ self.p
        self.misses = 0
        return (self.x[:, 0].reshape(4, 2) if self.c.smooth else corners), False, 0, True

    def _predict(self, now: float) -> None:
        dt = now - self.time
        f = np.array([[1.0, dt], [0.0, 1.0]])
        # white acceleration of spectral density q: Q = q * integral over dt of g g^T,
        # g = (s, 1) the effect of an acceleration s before the end of the step
        q = self.c.process_noise * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        self.x = self.x @ f.T
        self.p = f @ self.p @ f.T + q
        self.time = now


_STAMP_STEPS = st.one_of(
    st.none(),  # no timestamp: the tracker steps by its dt
    st.just(0.0),  # a second frame at the same stamp
    st.just(-0.2),  # the clock going back
    st.floats(0.005, 0.3),
)
_DETECTIONS = st.sampled_from(["corners", "corners", "corners", "none", "nan", "three"])


@settings(max_examples=80, deadline=None)
@given(
    dt=st.floats(0.01, 0.2),
    process_noise=st.floats(0.0, 1.0e5),
    measurement_noise=st.floats(0.05, 5.0),
    max_bridged_frames=st.integers(0, 3),
    initial_velocity_std=st.floats(0.0, 1000.0),
    smooth=st.booleans(),
    steps=st.lists(st.tuples(_STAMP_STEPS, _DETECTIONS), min_size=1, max_size=25),
    seed=st.integers(0, 2**16),
)
def test_the_tracker_is_a_constant_velocity_kalman_filter_on_each_corner_coordinate(
    dt: float,
    process_noise: float,
    measurement_noise: float,
    max_bridged_frames: int,
    initial_velocity_std: float,
    smooth: bool,
    steps: list,
    seed: int,
) -> None:
    config = CornerTrackerConfig(
        dt=dt,
        process_noise=process_noise,
        measurement_noise=measurement_noise,
        max_bridged_frames=max_bridged_frames,
        initial_velocity_std=initial_velocity_std,
        smooth=smooth,
    )
    tracker = CornerTracker(
        dt,
        process_noise,
        measurement_noise,
        max_bridged_frames,
        initial_velocity_std=initial_velocity_std,
        smooth=smooth,
    )
    assert tracker.config == config
    reference = _ReferenceTracker(config)
    rng = np.random.default_rng(seed)
    stamp = 1.0
    for gap_s, kind in steps:
        if gap_s is not None:
            stamp += gap_s
        given_stamp = None if gap_s is None else stamp
        corners = {
            "corners": START + rng.normal(0.0, 20.0, size=(4, 2)),
            "none": None,
            "nan": np.full((4, 2), np.nan),
            "three": START[:3],
        }[kind]
        want, predicted, bridged, valid = reference.step(corners, given_stamp)
        got = tracker.update(corners, given_stamp)
        if gap_s is None:
            stamp = reference.time if reference.time is not None else stamp
        assert (got.valid, got.predicted, got.bridged_count) == (valid, predicted, bridged)
        assert got.corners_px.shape == (4, 2)
        if valid:
            np.testing.assert_allclose(got.corners_px, want, rtol=1e-9, atol=1e-7)
        else:
            assert np.all(np.isnan(got.corners_px))
        assert tracker.active == (reference.x is not None)


def test_a_tracker_built_without_arguments_has_the_configs_defaults() -> None:
    assert CornerTracker().config == CornerTrackerConfig()
    assert CornerTracker.from_config(CornerTrackerConfig()).config == CornerTrackerConfig()


def test_integer_corners_come_out_as_float_pixels() -> None:
    tracker = CornerTracker()
    assert tracker.update(START.astype(int), 0.0).corners_px.dtype == float
    assert tracker.update(START.astype(int) + 1, 0.05).corners_px.dtype == float


def test_without_timestamps_the_first_frame_is_at_dt_and_the_next_ones_dt_apart() -> None:
    tracker = CornerTracker(dt=0.1, max_bridged_frames=1)
    tracker.update(START)  # at 0.1 s
    tracker.update(START + 1.0)  # at 0.2 s
    # a stamp given afterwards is measured from there: 0.25 s is after 0.2 s, 0.15 s before it
    assert tracker.update(None, 0.25).valid
    tracker.reset()
    tracker.update(START)
    tracker.update(START + 1.0)
    assert not tracker.update(None, 0.15).valid


class _RecordingEstimator:
    """An inner estimator that records what it is given and answers a fixed valid pose."""

    name = "stub"

    def __init__(self, tag_id: int | None) -> None:
        if tag_id is not None:
            self.tag_id = tag_id
        self.calls: list[tuple[CameraFrame, RangeReading]] = []
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        self.calls.append((frame, ranges))
        return DeckPoseEstimate(
            method=self.name,
            timestamp=frame.timestamp,
            valid=True,
            rotation=np.eye(3),
            translation=np.array([0.0, 0.0, 1.0]),
            extras={"inner_residual": 0.25},
        )


def _ranges(stamp: float) -> RangeReading:
    return RangeReading(stamp, np.full(4, 1.0), np.ones(4, dtype=bool))


def test_a_tracked_estimator_hands_its_inner_one_the_tracked_tag_alone_with_the_frames_image() -> (
    None
):
    inner = _RecordingEstimator(tag_id=7)
    tracked = TrackedEstimator(inner, CornerTracker(dt=DT), name="mine")
    assert tracked.tag_id == 7 and tracked.name == "mine"
    image = np.zeros((8, 8, 3), dtype=np.uint8)
    other = TagDetection(tag_id=3, corners_px=START + 50.0)
    frame = CameraFrame(0.5, (other, TagDetection(tag_id=7, corners_px=START)), image=image)
    ranges = _ranges(0.5)
    estimate = tracked.estimate(frame, ranges)
    assert estimate.valid and estimate.method == "mine" and not estimate.predicted
    assert estimate.timestamp == 0.5
    assert estimate.extras == {"inner_residual": 0.25, "bridged_count": 0}
    ((seen, seen_ranges),) = inner.calls
    assert seen_ranges is ranges
    assert seen.timestamp == 0.5 and seen.image is image
    (detection,) = seen.detections
    assert detection.tag_id == 7
    np.testing.assert_array_equal(detection.corners_px, START)
    # a missed frame: the inner estimator sees the bridged corners, flagged predicted
    estimate = tracked.estimate(CameraFrame(0.55, (other,)), _ranges(0.55))
    assert estimate.valid and estimate.predicted and estimate.method == "mine"
    assert estimate.extras["bridged_count"] == 1
    assert inner.calls[-1][0].detections[0].tag_id == 7
    tracked.reset()
    assert inner.resets == 1 and not tracked.tracker.active


def test_a_tracked_estimator_follows_the_tag_id_given_over_its_inner_ones() -> None:
    inner = _RecordingEstimator(tag_id=7)
    tracked = TrackedEstimator(inner, CornerTracker(dt=DT), tag_id=3)
    assert tracked.tag_id == 3 and tracked.name == "stub+kf"
    frame = CameraFrame(
        0.0,
        (TagDetection(tag_id=7, corners_px=START), TagDetection(tag_id=3, corners_px=START + 9.0)),
    )
    assert tracked.estimate(frame, _ranges(0.0)).valid
    np.testing.assert_array_equal(inner.calls[-1][0].detections[0].corners_px, START + 9.0)
    assert TrackedEstimator(_RecordingEstimator(tag_id=None), CornerTracker(), tag_id=0).tag_id == 0
    with pytest.raises(ValueError, match=r"^tag_id is needed when the estimator has no tag_id"):
        TrackedEstimator(_RecordingEstimator(tag_id=None), CornerTracker())


def test_a_tracked_estimator_bridges_over_the_frames_own_stamps_then_reports_the_tag_lost() -> None:
    inner = _RecordingEstimator(tag_id=7)
    tracked = TrackedEstimator(
        inner, CornerTracker(dt=DT, process_noise=1e4, measurement_noise=0.01, max_bridged_frames=1)
    )
    step_px = np.array([10.0, -4.0])  # per 0.1 s
    for stamp, corners in ((0.0, START), (0.1, START + step_px)):
        frame = CameraFrame(stamp, (TagDetection(tag_id=7, corners_px=corners),))
        assert tracked.estimate(frame, _ranges(stamp)).valid
    # 0.2 s after the last detection (four of the tracker's dt): two steps on
    bridged = tracked.estimate(CameraFrame(0.3, ()), _ranges(0.3))
    assert bridged.valid and bridged.predicted and bridged.timestamp == 0.3
    np.testing.assert_allclose(
        inner.calls[-1][0].detections[0].corners_px, START + 3.0 * step_px, atol=0.1
    )
    lost = tracked.estimate(CameraFrame(0.4, ()), _ranges(0.4))
    assert not lost.valid and lost.reason == TAG_LOST
    assert lost.method == "stub+kf" and lost.timestamp == 0.4
