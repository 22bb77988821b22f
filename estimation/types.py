"""Measurement and estimate types shared by the simulator and the estimators.

Frames and conventions are defined in :mod:`estimation.frames`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimation.frames import euler_zyx_from_matrix


@dataclass(frozen=True)
class TagDetection:
    """One detected tag: corner pixels (4x2, OpenCV pixel convention, AprilTag corner order)."""

    tag_id: int
    corners_px: np.ndarray
    decision_margin: float = float("nan")
    hamming: int = 0


@dataclass(frozen=True)
class CameraFrame:
    """What the camera delivers at one instant: detections and, in render mode, the image."""

    timestamp: float
    detections: tuple[TagDetection, ...]
    image: np.ndarray | None = None
    #: why the tag is not among the detections (``""`` when it is): e.g. "out_of_view",
    #: "too_oblique", "too_small", "dropout", "not_detected".
    miss_reason: str = ""


@dataclass(frozen=True)
class RangeReading:
    """The four ToF ranges (metres, along each sensor's axis) with their validity.

    An invalid reading (no return within the maximum range) holds NaN, never a clipped value.
    """

    timestamp: float
    ranges: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True)
class ImuSample:
    """One IMU sample in the body frame: specific force (m/s^2) and angular rate (rad/s)."""

    timestamp: float
    accel: np.ndarray
    gyro: np.ndarray


@dataclass(frozen=True)
class DeckPoseEstimate:
    """The deck (tag frame D) pose in the camera frame C, as estimated by one method."""

    method: str
    timestamp: float
    valid: bool
    rotation: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    translation: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    #: why the estimate is invalid; empty when valid
    reason: str = ""
    #: 6x6 covariance of (x, y, z, roll, pitch, yaw) where the method gives one
    covariance: np.ndarray | None = None
    #: True when the estimate was bridged by prediction rather than measured
    predicted: bool = False
    #: method-specific diagnostics (plane residual, ambiguity ratio, ...)
    extras: dict = field(default_factory=dict)

    @property
    def euler_zyx(self) -> np.ndarray:
        """(roll, pitch, yaw) in radians; NaN when invalid."""
        if not self.valid:
            return np.full(3, np.nan)
        return euler_zyx_from_matrix(self.rotation)

    def as_vector(self) -> np.ndarray:
        """(x, y, z, roll, pitch, yaw): metres and radians; NaN when invalid."""
        return np.concatenate([self.translation, self.euler_zyx])

    @classmethod
    def invalid(cls, method: str, timestamp: float, reason: str) -> DeckPoseEstimate:
        """An estimate that says why the method could not estimate."""
        return cls(method=method, timestamp=timestamp, valid=False, reason=reason)
