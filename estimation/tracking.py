"""Kalman tracking of the tag corners across short detection dropouts (CRHF Sec. 2.6).

Each of the 8 corner coordinates follows a constant-velocity model driven by white
acceleration noise.  All coordinates share the same model and are measured together, so
they share one 2x2 covariance: the filter is 8 independent copies of a position–velocity
Kalman filter run as one (8, 2) state array.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from estimation.estimator import DeckPoseEstimator, GuardedEstimator, target_corners
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading, TagDetection

TAG_LOST = "tag_lost"


@dataclass(frozen=True)
class CornerTrackerConfig(Limited):
    """Corner tracker settings.

    ``dt`` (s): step used when ``update`` gets no timestamp.  ``process_noise``
    (px²/s³): white-acceleration spectral density of each corner coordinate.
    ``measurement_noise`` (px): std of a detected corner coordinate.
    ``max_bridged_frames``: consecutive missed detections bridged by prediction before the
    track is dropped.  ``initial_velocity_std`` (px/s): prior on a new track's velocity.
    ``smooth``: output the filtered corners on detected frames; by default the detected
    corners pass through unchanged, because the filter lags an accelerating deck and its
    purpose here is to bridge dropouts.
    """

    dt: float = limited(0.05, POSITIVE)
    process_noise: float = limited(1.0e4, NON_NEGATIVE)
    measurement_noise: float = limited(0.5, POSITIVE)
    max_bridged_frames: int = limited(3, Limit(0))
    initial_velocity_std: float = limited(500.0, NON_NEGATIVE)
    smooth: bool = False


@dataclass(frozen=True)
class TrackedCorners:
    """Tracker output: 4x2 corner pixels (NaN when invalid).

    ``predicted``: the corners are a prediction (no detection this frame).
    ``bridged_count``: consecutive frames without detection so far.
    """

    corners_px: np.ndarray
    predicted: bool
    bridged_count: int
    valid: bool


class CornerTracker:
    """Constant-velocity Kalman filter on the four tag corners (pixels)."""

    def __init__(
        self,
        dt: float = 0.05,
        process_noise: float = 1.0e4,
        measurement_noise: float = 0.5,
        max_bridged_frames: int = 3,
        *,
        initial_velocity_std: float = 500.0,
        smooth: bool = False,
    ) -> None:
        self.config = CornerTrackerConfig(
            dt=dt,
            process_noise=process_noise,
            measurement_noise=measurement_noise,
            max_bridged_frames=max_bridged_frames,
            initial_velocity_std=initial_velocity_std,
            smooth=smooth,
        )
        self.reset()

    @classmethod
    def from_config(cls, config: CornerTrackerConfig) -> CornerTracker:
        return cls(**dataclasses.asdict(config))

    def reset(self) -> None:
        """Drop the track."""
        self._state: np.ndarray | None = None  # (8, 2): position, velocity per coordinate
        self._cov = np.zeros((2, 2))
        self._time: float | None = None
        self._bridged = 0

    @property
    def active(self) -> bool:
        return self._state is not None

    def _predict(self, dt: float) -> None:
        assert self._state is not None
        if dt <= 0.0:
            return
        f = np.array([[1.0, dt], [0.0, 1.0]])
        q = self.config.process_noise * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        self._state = self._state @ f.T
        self._cov = f @ self._cov @ f.T + q

    def _correct(self, measured: np.ndarray) -> None:
        assert self._state is not None
        r = self.config.measurement_noise**2
        innovation_var = self._cov[0, 0] + r
        gain = self._cov[:, 0] / innovation_var
        residual = measured - self._state[:, 0]
        self._state = self._state + np.outer(residual, gain)
        self._cov = self._cov - np.outer(gain, self._cov[0, :])

    def _start(self, measured: np.ndarray, timestamp: float) -> None:
        self._state = np.column_stack([measured, np.zeros(8)])
        self._cov = np.diag([self.config.measurement_noise**2, self.config.initial_velocity_std**2])
        self._time = timestamp
        self._bridged = 0

    def update(
        self, corners_px: np.ndarray | None, timestamp: float | None = None
    ) -> TrackedCorners:
        """Feed this frame's detected corners (4x2) or ``None`` for a missed detection.

        Without ``timestamp`` the filter advances by ``dt``.  A timestamp earlier than the
        last one (a replay or a reset clock) drops the track first.
        """
        now = (self._time or 0.0) + self.config.dt if timestamp is None else float(timestamp)
        if self._time is not None and now < self._time:
            self.reset()
        measured = None
        if corners_px is not None:
            measured = np.asarray(corners_px, dtype=float).reshape(-1)
            if measured.shape != (8,) or not np.all(np.isfinite(measured)):
                measured = None
        if measured is None:
            return self._miss(now)
        if self._state is None:
            self._start(measured, now)
            return TrackedCorners(measured.reshape(4, 2).copy(), False, 0, True)
        self._predict(now - (self._time if self._time is not None else now))
        self._time = now
        self._correct(measured)
        self._bridged = 0
        out = self._state[:, 0] if self.config.smooth else measured
        return TrackedCorners(out.reshape(4, 2).copy(), False, 0, True)

    def _miss(self, now: float) -> TrackedCorners:
        if self._state is None:
            return TrackedCorners(np.full((4, 2), np.nan), False, 0, False)
        bridged = self._bridged + 1
        if bridged > self.config.max_bridged_frames:
            self.reset()
            return TrackedCorners(np.full((4, 2), np.nan), False, bridged, False)
        self._predict(now - (self._time if self._time is not None else now))
        self._time = now
        self._bridged = bridged
        return TrackedCorners(self._state[:, 0].reshape(4, 2).copy(), True, bridged, True)


class TrackedEstimator(GuardedEstimator):
    """Runs an estimator on tracked corners; estimates from bridged corners are ``predicted``.

    The current ranges are always used as measured: only the tag corners are bridged.
    """

    def __init__(
        self,
        estimator: DeckPoseEstimator,
        tracker: CornerTracker,
        *,
        tag_id: int | None = None,
        name: str | None = None,
    ) -> None:
        self.inner = estimator
        self.tracker = tracker
        resolved = getattr(estimator, "tag_id", None) if tag_id is None else tag_id
        if resolved is None:
            raise ValueError("tag_id is needed when the estimator has no tag_id attribute")
        self.tag_id = int(resolved)
        self.name = name or f"{estimator.name}+kf"

    def reset(self) -> None:
        self.inner.reset()
        self.tracker.reset()

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        corners, _ = target_corners(frame, self.tag_id)
        tracked = self.tracker.update(corners, timestamp)
        if not tracked.valid:
            return DeckPoseEstimate.invalid(self.name, timestamp, TAG_LOST)
        detection = TagDetection(tag_id=self.tag_id, corners_px=tracked.corners_px)
        tracked_frame = CameraFrame(timestamp=timestamp, detections=(detection,), image=frame.image)
        estimate = self.inner.estimate(tracked_frame, ranges)
        extras = dict(estimate.extras)
        extras["bridged_count"] = tracked.bridged_count
        return dataclasses.replace(
            estimate, method=self.name, predicted=tracked.predicted, extras=extras
        )
