"""The interface every deck-pose estimator implements and the shared input checks.

The estimators are built by name in :mod:`estimation.registry` (single frame) and
:mod:`estimation.pipeline` (everything a host asks for).

An estimator turns one camera frame and one ToF reading into a :class:`DeckPoseEstimate`
(``T_CD``, see :mod:`estimation.frames`).  It never raises for bad input: a missing tag, an
invalid or NaN range, degenerate geometry or non-finite numbers give
``DeckPoseEstimate.invalid(name, t, reason)`` with one of the short reason strings below.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import cv2
import numpy as np

from estimation import geometry
from estimation.camera_model import CameraIntrinsics
from estimation.errors import ConfigError, require_choice, require_range
from estimation.frames import tag_corners_in_tag_frame, tof_positions_in_camera_frame
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading

if TYPE_CHECKING:
    from estimation.tof_calibration import TofCameraCalibration

# Reasons for invalid estimates (stable tokens, so that runs can be tallied by reason).
NO_DETECTION = "no_detection"
BAD_CORNERS = "bad_corners"
DEGENERATE_CORNERS = "degenerate_corners"
RANGE_INVALID = "range_invalid"
TOUCH_POINT_UNAVAILABLE = "touch_point_unavailable"
DEGENERATE_PLANE = "degenerate_plane"
PLANE_RESIDUAL = "plane_residual"
DEGENERATE_HOMOGRAPHY = "degenerate_homography"
DEGENERATE_TOUCH_POINTS = "degenerate_touch_points"
CORNER_BEHIND_CAMERA = "corner_behind_camera"
DEGENERATE_RIGID = "degenerate_rigid"
RIGID_RESIDUAL = "rigid_residual"
PNP_FAILED = "pnp_failed"
NON_FINITE_RESULT = "non_finite_result"
NUMERICAL_ERROR = "numerical_error"
BAD_TIMESTAMP = "bad_timestamp"

#: No camera delivers pixel coordinates this large, nor a ToF sensor ranges this long: such
#: numbers are corrupt input, not measurements.
MAX_ABS_PIXEL = 1e6
MAX_RANGE_M = 1e3

#: How far outside the image (a fraction of its width / height on each side) a corner may
#: lie.  A detector reports corners inside the image; a tracker bridging a missed frame can
#: extrapolate one past the edge, but never by half an image at 20 Hz.  Further out the
#: corners are corrupt input (ATDA once returned a valid pose for corners 9e5 px outside).
MAX_OUTSIDE_IMAGE_FRAC = 0.5


@runtime_checkable
class DeckPoseEstimator(Protocol):
    """Estimates the deck pose ``T_CD`` from a camera frame and the ToF ranges."""

    name: str

    def reset(self) -> None:
        """Forget any state carried between frames."""
        ...

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        """The deck pose at ``frame.timestamp``; an invalid estimate (never an exception)."""
        ...


class GuardedEstimator:
    """Base class: runs ``_estimate`` with floating-point warnings silenced and turns the
    numerical exceptions that adversarial input can still provoke into invalid estimates."""

    name: str = ""

    def reset(self) -> None:
        """Stateless by default."""

    @property
    def image_size(self) -> tuple[int, int] | None:
        """(width, height) of the camera's image when known (from ``intrinsics``, or from a
        wrapped ``inner`` estimator): corners far outside it are refused."""
        intrinsics = getattr(self, "intrinsics", None)
        if intrinsics is not None:
            return int(intrinsics.width), int(intrinsics.height)
        return getattr(getattr(self, "inner", None), "image_size", None)

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = checked_timestamp(getattr(frame, "timestamp", None))
        if timestamp is None:
            return DeckPoseEstimate.invalid(self.name, math.nan, BAD_TIMESTAMP)
        checked = checked_frame(frame, timestamp, self.image_size, getattr(self, "tag_id", None))
        if checked is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, BAD_CORNERS)
        try:
            with np.errstate(all="ignore"):
                return self._estimate(checked, ranges)
        except (
            np.linalg.LinAlgError,
            cv2.error,
            FloatingPointError,
            OverflowError,
            ValueError,
            TypeError,
        ):
            return DeckPoseEstimate.invalid(self.name, timestamp, NUMERICAL_ERROR)

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        raise NotImplementedError


def checked_timestamp(value: object) -> float | None:
    """The timestamp as a finite float, or None (a string, a bool, NaN, inf...)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        return None
    timestamp = float(value)
    return timestamp if math.isfinite(timestamp) else None


def _corners_usable(corners_px: object, image_size: tuple[int, int] | None) -> bool:
    try:
        corners = np.asarray(corners_px, dtype=float)
    except (TypeError, ValueError):
        return False
    # a NaN corner is one the detector did not see (``tight`` solves with three); infinities
    # and numbers no camera delivers are corrupt
    if corners.shape != (4, 2) or np.isinf(corners).any():
        return False
    seen = corners[np.isfinite(corners).all(axis=1)]
    if not (np.abs(seen) <= MAX_ABS_PIXEL).all():
        return False
    if image_size is None:
        return True
    size = np.asarray(image_size, dtype=float)
    margin = MAX_OUTSIDE_IMAGE_FRAC * size
    return bool(((seen >= -margin) & (seen <= size - 1.0 + margin)).all())


def checked_frame(
    frame: CameraFrame,
    timestamp: float,
    image_size: tuple[int, int] | None,
    tag_id: int | None = None,
) -> CameraFrame | None:
    """The frame with its float timestamp and without detections whose corners are not four
    finite pixels in (or near) the image; None when that removed the estimator's tag (or
    every detection): its corners are corrupt."""
    detections = getattr(frame, "detections", None)
    if not isinstance(detections, (tuple, list)):
        return None
    kept = tuple(
        d for d in detections if _corners_usable(getattr(d, "corners_px", None), image_size)
    )
    if len(kept) < len(detections):
        if not kept:
            return None
        if tag_id is not None:
            ids = {getattr(d, "tag_id", None) for d in kept}
            if tag_id not in ids and any(getattr(d, "tag_id", None) == tag_id for d in detections):
                return None
    if kept == tuple(detections) and frame.timestamp == timestamp:
        return frame
    if dataclasses.is_dataclass(frame) and not isinstance(frame, type):
        return dataclasses.replace(frame, timestamp=timestamp, detections=kept)
    return CameraFrame(timestamp, kept, getattr(frame, "image", None))


def target_corners(frame: CameraFrame, tag_id: int) -> tuple[np.ndarray | None, str]:
    """The 4x2 corners of tag ``tag_id`` (best-decoded if several), or ``None`` and a reason."""
    candidates = [d for d in frame.detections if d.tag_id == tag_id]
    if not candidates:
        return None, NO_DETECTION

    def quality(d: object) -> tuple[int, float]:
        margin = float(getattr(d, "decision_margin", math.nan))
        return int(getattr(d, "hamming", 0)), -(margin if math.isfinite(margin) else -math.inf)

    best = candidates[0] if len(candidates) == 1 else min(candidates, key=quality)
    corners = np.asarray(best.corners_px, dtype=float)
    # NaN fails the comparison too
    if corners.shape != (4, 2) or not (np.abs(corners) <= MAX_ABS_PIXEL).all():
        return None, BAD_CORNERS
    return corners, ""


def corners_degenerate(corners_px: np.ndarray, min_area_px: float) -> bool:
    """True unless the corners form a convex quadrilateral of some area.

    A square seen by a camera is always a convex quadrilateral: three (nearly) collinear
    corners, a bow-tie or a dent mean the corners are not a tag's.
    """
    xs = corners_px[:, 0].tolist()
    ys = corners_px[:, 1].tolist()
    turns = []
    for k in range(4):
        i, j = (k + 1) % 4, (k + 2) % 4
        # twice the signed area of the triangle of corners k, k+1, k+2
        turns.append((xs[i] - xs[k]) * (ys[j] - ys[k]) - (ys[i] - ys[k]) * (xs[j] - xs[k]))
    if not (all(t > 0.0 for t in turns) or all(t < 0.0 for t in turns)):
        return True
    # the quadrilateral's area: half the cross product of its diagonals
    area = 0.5 * abs((xs[2] - xs[0]) * (ys[3] - ys[1]) - (ys[2] - ys[0]) * (xs[3] - xs[1]))
    return area < min_area_px or min(abs(t) for t in turns) < 0.5 * min_area_px


def checked_ranges(reading: RangeReading, n_sensors: int) -> np.ndarray | None:
    """The ranges as a float array when all ``n_sensors`` are valid, finite, positive and sane."""
    ranges = np.asarray(reading.ranges, dtype=float).reshape(-1)
    valid = np.asarray(reading.valid).reshape(-1)
    if valid.dtype != bool:
        # only 1 (or True) means valid: NaN, 0.5 or "yes" do not
        valid = np.asarray(valid == 1, dtype=bool).reshape(-1)
    if len(ranges) != n_sensors or len(valid) != n_sensors or not valid.all():
        return None
    # NaN fails both comparisons
    if not ((ranges > 0.0) & (ranges <= MAX_RANGE_M)).all():
        return None
    return ranges


def finish_pose(
    method: str,
    timestamp: float,
    rotation: np.ndarray,
    translation: np.ndarray,
    extras: dict,
) -> DeckPoseEstimate:
    """A valid estimate after a last sanity check (finite, proper rotation, deck in front)."""
    if not (np.isfinite(rotation).all() and np.isfinite(translation).all()):
        return DeckPoseEstimate.invalid(method, timestamp, NON_FINITE_RESULT)
    if abs(geometry.det3(rotation) - 1.0) > 1e-6 or not translation[2] > 0.0:
        return DeckPoseEstimate.invalid(method, timestamp, NON_FINITE_RESULT)
    return DeckPoseEstimate(
        method=method,
        timestamp=timestamp,
        valid=True,
        rotation=rotation,
        translation=translation,
        extras=extras,
    )


@dataclass(frozen=True)
class RangeFusionConfig:
    """Settings shared by the camera+ToF estimators (IHRCF, CRHF).

    ``max_plane_rms_m``: the four touch points must lie on a plane to within this RMS
    (metres), otherwise a range is judged bad (sensor off the deck, multipath) and the
    estimate is invalid with reason ``plane_residual``; ``inf`` disables the check.
    ``max_rigid_rms_rel``: the tag model must fit the reconstructed corners to within this
    RMS, as a fraction of the tag size (a square-ish quad far from the tag's shape is not the
    tag); ``inf`` disables the check.
    ``undistort``: remove lens distortion from corner and touch-point pixels when the
    estimator is given intrinsics with distortion.
    """

    plane_fit: str = "lstsq"
    max_plane_rms_m: float = limited(
        0.05, POSITIVE, physical=Limit(0.0, 100.0, low_inclusive=False, allow_inf=True)
    )
    max_rigid_rms_rel: float = limited(
        0.25, POSITIVE, physical=Limit(0.0, 100.0, low_inclusive=False, allow_inf=True)
    )
    min_corner_area_px: float = limited(4.0, NON_NEGATIVE, physical=Limit.non_negative(1e7))
    undistort: bool = True

    def __post_init__(self) -> None:
        require_choice("plane_fit", self.plane_fit, geometry.PLANE_METHODS)
        require_limits(self)


@dataclass(frozen=True)
class FusionInputs:
    """Checked, undistorted measurements for IHRCF/CRHF."""

    corners_px: np.ndarray
    touch_px: np.ndarray
    ranges: np.ndarray
    plane: geometry.PlaneFit
    extrapolated: bool


def tof_sensor_positions(
    tof_positions_c: np.ndarray | None, tof_calibration: TofCameraCalibration | None
) -> np.ndarray:
    """The ToF sensors' positions in C, (N, 3) (None: the standard layout); ConfigError when
    ``tof_calibration`` holds another number of sensors."""
    positions = (
        tof_positions_in_camera_frame()
        if tof_positions_c is None
        else np.asarray(tof_positions_c, dtype=float).reshape(-1, 3)
    )
    if tof_calibration is not None and tof_calibration.n_sensors != len(positions):
        raise ConfigError(
            "tof_calibration",
            f"has {tof_calibration.n_sensors} sensors, tof_positions_c has {len(positions)}",
        )
    return positions


class RangeFusionEstimator(GuardedEstimator):
    """Shared front end of IHRCF and CRHF: tag corners, ranges, touch points and the plane.

    A subclass names its settings class (``config_class``; ``config=None`` is its defaults)
    and sets up what is its own in :meth:`_configure`.
    """

    config_class: type[RangeFusionConfig] = RangeFusionConfig

    def __init__(
        self,
        *,
        tag_size: float,
        tag_id: int,
        tof_calibration: TofCameraCalibration,
        tof_positions_c: np.ndarray | None = None,
        intrinsics: CameraIntrinsics | None = None,
        config: RangeFusionConfig | None = None,
    ) -> None:
        config = config or self.config_class()
        require_range("tag_size", tag_size, 0.0, low_inclusive=False)
        positions = tof_sensor_positions(tof_positions_c, tof_calibration)
        if len(positions) < 4:
            raise ConfigError("tof_positions_c", f"need at least 4 sensors, got {len(positions)}")
        if not np.allclose(positions[:, 2], 0.0):
            raise ConfigError("tof_positions_c", "sensors must lie in the camera plane z = 0")
        self.tag_size = float(tag_size)
        self.tag_id = int(tag_id)
        self.tof_calibration = tof_calibration
        self.tof_positions_c = positions
        self.intrinsics = intrinsics
        self.config = config
        self.tag_model = tag_corners_in_tag_frame(self.tag_size)
        self._rigid_fitter = geometry.RigidFitter(self.tag_model)
        self._undistort = bool(
            config.undistort and intrinsics is not None and intrinsics.has_distortion
        )
        self._undistorter = (
            geometry.Undistorter(intrinsics) if self._undistort and intrinsics is not None else None
        )
        # the sensors' (x, y) never change: the least-squares plane's pseudo-inverse is fixed
        try:
            self._plane_fitter = geometry.ZPlaneFitter(positions[:, :2])
        except ValueError as err:
            raise ConfigError("tof_positions_c", str(err)) from None
        self._configure()

    def _configure(self) -> None:
        """A subclass's own set-up from ``self.config``, after the shared one."""

    def _inputs(self, frame: CameraFrame, reading: RangeReading) -> FusionInputs | str:
        """The checked inputs, or the reason they cannot be used."""
        corners, reason = target_corners(frame, self.tag_id)
        if corners is None:
            return reason
        if corners_degenerate(corners, self.config.min_corner_area_px):
            return DEGENERATE_CORNERS
        ranges = checked_ranges(reading, len(self.tof_positions_c))
        if ranges is None:
            return RANGE_INVALID
        lookup = self.tof_calibration.lookup(ranges)
        if not np.all(lookup.valid):
            return TOUCH_POINT_UNAVAILABLE
        touch_px = lookup.pixels
        if self._undistorter is not None:
            both = self._undistorter(np.vstack([corners, touch_px]))
            corners, touch_px = both[:4], both[4:]
            if not np.all(np.isfinite(both)):
                return BAD_CORNERS
        # the touch point of sensor i is (s_ix, s_iy, r_i) in C whatever the deck's tilt
        if self.config.plane_fit == "lstsq":
            plane = self._plane_fitter.fit(ranges)
        else:
            touch_points = self.tof_positions_c.copy()
            touch_points[:, 2] = ranges
            plane = geometry.fit_plane(touch_points, self.config.plane_fit)
        if plane is None:
            return DEGENERATE_PLANE
        if plane.rms_residual > self.config.max_plane_rms_m:
            return PLANE_RESIDUAL
        return FusionInputs(
            corners_px=corners,
            touch_px=touch_px,
            ranges=ranges,
            plane=plane,
            extrapolated=bool(np.any(lookup.extrapolated)),
        )

    def _pose_from_corners(
        self, timestamp: float, corners_c: np.ndarray, inputs: FusionInputs, extras: dict
    ) -> DeckPoseEstimate:
        """Rigid fit of the tag model to the reconstructed corners ⇒ ``R_CD, t_CD``."""
        if not np.isfinite(corners_c).all():
            return DeckPoseEstimate.invalid(self.name, timestamp, NON_FINITE_RESULT)
        if not (corners_c[:, 2] > 0.0).all():
            return DeckPoseEstimate.invalid(self.name, timestamp, CORNER_BEHIND_CAMERA)
        fit = self._rigid_fitter.fit(corners_c)
        if fit is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, DEGENERATE_RIGID)
        if fit.rms_residual > self.config.max_rigid_rms_rel * self.tag_size:
            return DeckPoseEstimate.invalid(self.name, timestamp, RIGID_RESIDUAL)
        extras["plane_rms_m"] = inputs.plane.rms_residual
        extras["rigid_rms_m"] = fit.rms_residual
        extras["touch_points_extrapolated"] = inputs.extrapolated
        return finish_pose(self.name, timestamp, fit.rotation, fit.translation, extras)


class RankedEstimator:
    """The first valid estimate of several estimators, in rank order (``auto`` in the env).

    E.g. ``(ihrcf, atda)``: IHRCF wherever all four ToF rays return (near the deck), ATDA
    above the ToF range, where IHRCF is invalid (``range_invalid``).  Every estimator runs
    each frame so that its state stays current; ``extras["source"]`` names the one used.
    An invalid result has the last-ranked one's reason, and all of them in
    ``extras["reasons"]``.
    """

    def __init__(self, name: str, estimators: tuple[DeckPoseEstimator, ...]) -> None:
        if not estimators:
            raise ValueError("a ranked estimator needs at least one estimator")
        self.name = name
        self.estimators = estimators

    def reset(self) -> None:
        for estimator in self.estimators:
            estimator.reset()

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        results = [estimator.estimate(frame, ranges) for estimator in self.estimators]
        for estimator, result in zip(self.estimators, results, strict=True):
            if result.valid:
                extras = {**result.extras, "source": estimator.name}
                return dataclasses.replace(result, method=self.name, extras=extras)
        # the last-ranked estimator needs the least, so its reason says most
        reasons = {e.name: r.reason for e, r in zip(self.estimators, results, strict=True)}
        last = results[-1]
        return dataclasses.replace(last, method=self.name, extras={"reasons": reasons})
