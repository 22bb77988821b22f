"""IHRCF: Inverse Homography Range Camera Fusion (Sefidgar & Landry, Sensors 2022).

Steps (paper Sec. 2.4–2.7), in the project frames of :mod:`estimation.frames`:

1. touch-point pixels of the four ToF sensors from the ToF–camera calibration at the
   current ranges (Sec. 2.2);
2. the homography H from the sensors' camera-plane (X, Y) (Eq. 12) to those pixels
   (Eq. 13–18).  Every deck point's (X, Y) in C maps to its pixel by a homography (the deck
   is a plane, its Z is affine in X and Y), and the touch point of sensor i has exactly the
   sensor's (X, Y), so H is exact for noise-free data;
3. the tag corners' (X, Y) by the inverse homography (Eq. 19);
4. their Z from the deck plane through the four touch points ``(s_ix, s_iy, r_i)``
   (Eq. 20–22; least squares over all four by default, the paper's 3-point cross product
   as an option);
5. the rigid transform from the tag model to the corners (Sec. 2.7), which is ``T_CD``.

The paper's Sec. 2.8 axis flips and negated X only undo its simulator's image conventions;
the frames here need no correction.  IHRCF needs no camera matrix: intrinsics are only
used to undistort pixels when the lens has distortion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation import geometry
from estimation.estimator import (
    DEGENERATE_HOMOGRAPHY,
    RangeFusionConfig,
    RangeFusionEstimator,
)
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading


@dataclass(frozen=True)
class IHRCFConfig(RangeFusionConfig):
    """IHRCF settings: the range-fusion ones (the homography is the normalised DLT, exact
    with four noise-free points)."""


class IhrcfEstimator(RangeFusionEstimator):
    """The IHRCF deck-pose estimator."""

    name = "ihrcf"
    config_class = IHRCFConfig
    config: IHRCFConfig

    def _configure(self) -> None:
        self._sensors_xy = self.tof_positions_c[:, :2].copy()

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        inputs = self._inputs(frame, ranges)
        if isinstance(inputs, str):
            return DeckPoseEstimate.invalid(self.name, timestamp, inputs)
        # Eq. 13–19: H maps the sensors' (X, Y) to the touch pixels and H⁻¹ takes the corner
        # pixels back to the deck's (X, Y) in C.  Four exact correspondences fix a
        # homography uniquely, so H⁻¹ is estimated directly from the pixels to the (X, Y):
        # the same map, without a matrix inversion per frame
        h_inv = geometry.homography_dlt(inputs.touch_px, self._sensors_xy)
        if h_inv is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, DEGENERATE_HOMOGRAPHY)
        corners_xy = geometry.apply_homography(h_inv, inputs.corners_px)
        corners_c = np.empty((4, 3))
        corners_c[:, :2] = corners_xy
        corners_c[:, 2] = inputs.plane.z_at(corners_xy[:, 0], corners_xy[:, 1])
        return self._pose_from_corners(timestamp, corners_c, inputs, {})
