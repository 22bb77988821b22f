"""Corner tracking across detection dropouts (estimation.tracking)."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.camera_model import CameraIntrinsics
from estimation.frames import tof_positions_in_camera_frame
from estimation.registry import make_estimator
from estimation.synthetic import SyntheticScene
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import CornerTracker, CornerTrackerConfig, TrackedEstimator
from estimation.types import CameraFrame
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
