"""CRHF: Camera and Range sensor Homogeneous Fusion (Sefidgar & Landry, Drones 2022).

Per frame (paper Sec. 2.7–2.8), in the project frames of :mod:`estimation.frames`:

1. touch-point pixels ``(u_i, v_i)`` of the four sensors from the ToF–camera calibration;
   the touch point itself is ``(s_ix, s_iy, r_i)`` in C;
2. the principal point as the range-weighted mean of the touch pixels (Eq. 45);
3. per-sensor focal lengths ``f_x,i = (u_i - c_x) r_i / s_ix`` (and likewise in y) from the
   touch points' homogeneous equations (Eq. 40–43), averaged over the sensors (Eq. 44);
4. each corner's Z where its ray meets the deck plane ``n · p = d`` (Eq. 46–49), then
   ``X = Z x / f_x``, ``Y = Z y / f_y`` with ``(x, y)`` the corner pixel relative to the
   principal point (Eq. 50–53);
5. the rigid transform from the tag model (Eq. 62) to the corners by SVD with the
   reflection fix (Eq. 54–61), which is ``T_CD``.

Why step 2 works: from one sensor, ``u_i = f_x s_ix / r_i + c_x`` cannot separate ``f_x``
from ``c_x``.  Multiplying by ``r_i`` and summing over the sensors gives
``Σ r_i u_i = f_x Σ s_ix + c_x Σ r_i``, so when the sensors are laid out symmetrically about
the camera (``Σ s_i = 0``, as in :func:`estimation.frames.tof_positions_in_camera_frame`)
Eq. 45 is exactly ``c_x``, for any deck tilt; step 3 then gives ``f_x`` from every sensor.
For a layout that is not centred, ``principal_point="lstsq"`` solves
``r_i u_i = f s_i + c r_i`` for ``(f, c)`` by least squares over the sensors instead.

Where the paper's text is ambiguous or mistyped:

* Eq. 40–44 use pixels relative to the principal point, so Eq. 45 is evaluated first;
* Eq. 47–49 repeat ``x1, y1``: each corner uses its own pixel;
* the paper computes ``n`` from three touch points (Eq. 25) with ``d`` averaged over all
  sensors; here the least-squares plane over all four is the default (``plane_fit``);
* sensors with (near) zero ``s_ix`` (or ``s_iy``) say nothing about ``f_x`` (``f_y``) and
  are left out of that average instead of dividing by zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.errors import ConfigError, require_choice
from estimation.estimator import (
    DEGENERATE_TOUCH_POINTS,
    RangeFusionConfig,
    RangeFusionEstimator,
)
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading

PRINCIPAL_POINT_METHODS = ("range_weighted", "lstsq")

#: A sensor offset below this (metres) along an axis is not used for that axis' focal length.
_MIN_SENSOR_OFFSET_M = 1e-6


@dataclass(frozen=True)
class CRHFConfig(RangeFusionConfig):
    """CRHF settings: ``principal_point`` is ``"range_weighted"`` (paper Eq. 45 + Eq. 44,
    exact for a centred sensor layout) or ``"lstsq"`` (joint fit, any layout)."""

    principal_point: str = "range_weighted"

    def __post_init__(self) -> None:
        super().__post_init__()
        require_choice("principal_point", self.principal_point, PRINCIPAL_POINT_METHODS)


class CrhfEstimator(RangeFusionEstimator):
    """The CRHF deck-pose estimator."""

    name = "crhf"
    config_class = CRHFConfig
    config: CRHFConfig

    def _configure(self) -> None:
        self._pp_method = self.config.principal_point
        s = self.tof_positions_c[:, :2]
        self._use = np.abs(s) > _MIN_SENSOR_OFFSET_M
        if not np.all(self._use.sum(axis=0) >= 1):
            raise ConfigError("tof_positions_c", "no sensor is offset from the camera along x or y")
        scale = float(np.max(np.abs(s)))
        if self._pp_method == "range_weighted" and np.any(np.abs(s.sum(axis=0)) > 1e-9 * scale):
            raise ConfigError(
                "principal_point",
                "'range_weighted' (Eq. 45) is exact only for sensors centred on the camera "
                "(sum of positions = 0); use 'lstsq' for this layout",
            )

    def _intrinsics_from_touch_points(
        self, touch_px: np.ndarray, ranges: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(fx, fy) and (cx, cy) from the touch points (Eq. 40–45)."""
        s = self.tof_positions_c[:, :2]
        focal = np.empty(2)
        centre = np.empty(2)
        for axis in range(2):
            use = self._use[:, axis]
            if self._pp_method == "range_weighted":
                centre[axis] = np.dot(ranges, touch_px[:, axis]) / ranges.sum()  # Eq. 45
                f_i = (touch_px[use, axis] - centre[axis]) * ranges[use] / s[use, axis]
                focal[axis] = f_i.mean()  # Eq. 44
            else:
                design = np.column_stack([s[:, axis], ranges])
                (focal[axis], centre[axis]), *_ = np.linalg.lstsq(
                    design, ranges * touch_px[:, axis], rcond=None
                )
        return focal, centre

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        inputs = self._inputs(frame, ranges)
        if isinstance(inputs, str):
            return DeckPoseEstimate.invalid(self.name, timestamp, inputs)
        focal, centre = self._intrinsics_from_touch_points(inputs.touch_px, inputs.ranges)
        # the image x and y axes point the same way as the camera's X and Y: f must be > 0
        if not (np.all(np.isfinite(focal)) and np.all(focal > 0.0)):
            return DeckPoseEstimate.invalid(self.name, timestamp, DEGENERATE_TOUCH_POINTS)
        # normalised ray directions (x / f_x, y / f_y, 1) of the corners
        rays = np.ones((4, 3))
        rays[:, :2] = (inputs.corners_px - centre) / focal
        n = inputs.plane.normal
        z = inputs.plane.offset / (rays @ n)  # Eq. 46–49
        corners_c = rays * z[:, None]  # Eq. 50–53
        extras = {"fx": focal[0], "fy": focal[1], "cx": centre[0], "cy": centre[1]}
        return self._pose_from_corners(timestamp, corners_c, inputs, extras)
