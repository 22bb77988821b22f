"""Beacon position from a bearing and one range, as IR-LOCK with a rangefinder gives it.

The IR-LOCK / PX4 precision-landing sensor pair knows only the direction to the beacon (its
centre pixel through the calibrated intrinsics) and one downward range; it knows nothing of
the landing pad's orientation.  The position follows from intersecting the bearing ray with
a plane at the measured distance:

* by default the plane is perpendicular to the optical axis (camera frame only: a level
  drone over a level deck), ``t = b / b_z * (range + offset)``;
* given the camera's attitude relative to a gravity-levelled frame (``r_level_c``), the plane
  is horizontal, as PX4's landing-target estimator assumes (flat ground): the height is the
  range times the cosine of the beam's tilt.

The estimate's rotation is reported as level (``R_CD = I``: the pose a level, zero-yaw drone
sees over a level deck) and flagged ``orientation_known = False`` in its extras: the
observation's roll, pitch and yaw are then zeros, not measurements.

Pure: numpy and OpenCV only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.estimator import (
    NO_DETECTION,
    RANGE_INVALID,
    GuardedEstimator,
    corners_degenerate,
    finish_pose,
    target_corners,
)
from estimation.geometry import Undistorter
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading

#: Reason of an invalid estimate whose bearing misses the range plane (beyond the horizon).
BEARING_MISSES_PLANE = "bearing_misses_plane"
#: Reason of an invalid estimate of a beacon farther than it can be tracked (``max_range_m``).
BEYOND_BEACON_RANGE = "beyond_beacon_range"

#: How far the COTS IR-LOCK beacon (MarkOne) is tracked, metres: "COTS beacons are designed
#: for a maximum tracking altitude of 40 m" (SVGS paper 003, Sec. 2.5.1)
IR_LOCK_MAX_RANGE_M = 40.0


def tag_centre_pixel(corners_px: np.ndarray) -> np.ndarray:
    """The image of the tag's centre: the intersection of the corner quadrilateral's diagonals.

    A projective map keeps lines and their intersections, so this is exact under perspective
    (the mean of the corners is not).  Raises ``ValueError`` for parallel diagonals.
    """
    c = np.asarray(corners_px, dtype=float).reshape(4, 2)
    # solve c0 + s (c2 - c0) = c1 + u (c3 - c1)
    a = np.column_stack([c[2] - c[0], c[1] - c[3]])
    s, _ = np.linalg.solve(a, c[1] - c[0])
    return c[0] + s * (c[2] - c[0])


def bearing_from_pixel(pixel: np.ndarray, undistort: Undistorter, k: np.ndarray) -> np.ndarray:
    """Unit direction in the camera frame C of a raw (distorted) pixel."""
    ideal = undistort(np.asarray(pixel, dtype=float).reshape(1, 2))[0]
    ray = np.array([(ideal[0] - k[0, 2]) / k[0, 0], (ideal[1] - k[1, 2]) / k[1, 1], 1.0])
    return ray / np.linalg.norm(ray)


def beacon_position(
    bearing_c: np.ndarray,
    range_m: float,
    r_level_c: np.ndarray | None = None,
    range_offset_m: float = 0.0,
) -> np.ndarray | None:
    """The beacon's position in C from its bearing and the downward range, or None.

    ``range_m``: the rangefinder's distance along the optical axis (+z_C), measured from the
    camera's plane (``range_offset_m`` is added: the rangefinder's origin below the camera
    along +z_C).  ``r_level_c``: rotation from C to a gravity-levelled frame whose z points
    down (None: the range plane is perpendicular to the optical axis).  None when the bearing
    does not meet the plane in front of the camera.
    """
    b = np.asarray(bearing_c, dtype=float).reshape(3)
    distance = float(range_m) + float(range_offset_m)
    if not (math.isfinite(distance) and distance > 0.0):
        return None
    if r_level_c is None:
        if b[2] <= 1e-9:
            return None
        return b / b[2] * distance
    r = np.asarray(r_level_c, dtype=float).reshape(3, 3)
    down = r.T @ np.array([0.0, 0.0, 1.0])  # gravity's direction in C
    axis_down = float(down[2])  # cosine of the optical axis' tilt
    bearing_down = float(b @ down)
    if axis_down <= 1e-9 or bearing_down <= 1e-9:
        return None
    height = distance * axis_down
    return b / bearing_down * height


@dataclass(frozen=True)
class BeaconConfig(Limited):
    """Settings of the beacon estimator (``estimation.beacon.*``)."""

    #: the tag's quadrilateral must have at least this area to give a bearing, pixels²
    min_corner_area_px: float = limited(
        4.0, NON_NEGATIVE, physical=Limit.non_negative(1e7, "px^2; a 4 K frame has 8.3e6")
    )
    #: rangefinder origin below the camera along the optical axis, metres (a simulator sets
    #: it from its geometry)
    range_offset_m: float = limited(0.0, Limit(-1.0, 1.0))
    #: the beacon is seen only within this distance from the camera, metres (the IR-LOCK
    #: beacon's tracking range, IR_LOCK_MAX_RANGE_M); farther fixes are invalid
    max_range_m: float = limited(
        IR_LOCK_MAX_RANGE_M,
        POSITIVE,
        physical=Limit.positive(1e4, "m; the paper's COTS beacon: 40 m"),
    )


class BeaconEstimator(GuardedEstimator):
    """Position-only deck estimate from the tag centre's bearing and the downward range.

    ``range_source`` returns the latest rangefinder reading (shape (1,)); the ToF reading
    passed to :meth:`estimate` is not used.  A beacon farther than ``max_range_m`` is not seen
    (:data:`BEYOND_BEACON_RANGE`).  Valid estimates carry ``R_CD = I`` and
    ``extras["orientation_known"] = False``.
    """

    name = "beacon"

    def __init__(
        self,
        intrinsics: CameraIntrinsics,
        tag_id: int,
        range_source: Callable[[], RangeReading],
        config: BeaconConfig | None = None,
    ) -> None:
        self.intrinsics = intrinsics
        self.tag_id = int(tag_id)
        self.range_source = range_source
        self.config = config or BeaconConfig()
        self._undistort = Undistorter(intrinsics)
        self._k = intrinsics.matrix

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        corners, reason = target_corners(frame, self.tag_id)
        if corners is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, reason or NO_DETECTION)
        if corners_degenerate(corners, self.config.min_corner_area_px):
            return DeckPoseEstimate.invalid(self.name, timestamp, "degenerate_corners")
        reading = self.range_source()
        if not (bool(np.asarray(reading.valid).reshape(-1)[0])):
            return DeckPoseEstimate.invalid(self.name, timestamp, RANGE_INVALID)
        centre = tag_centre_pixel(corners)
        bearing = bearing_from_pixel(centre, self._undistort, self._k)
        position = beacon_position(
            bearing,
            float(np.asarray(reading.ranges).reshape(-1)[0]),
            None,
            self.config.range_offset_m,
        )
        if position is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, BEARING_MISSES_PLANE)
        if not float(np.linalg.norm(position)) <= self.config.max_range_m:
            return DeckPoseEstimate.invalid(self.name, timestamp, BEYOND_BEACON_RANGE)
        extras = {"orientation_known": False, "centre_px": centre}
        return finish_pose(self.name, timestamp, np.eye(3), position, extras)
