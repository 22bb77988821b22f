"""``tight``: the tag corners and the ToF ranges in one weighted least-squares problem.

IHRCF and CRHF take the deck's tilt from the four ToF ranges alone and ATDA from the four
corners alone; under realistic noise each throws away what the other sensor knows.  Here the
deck pose ``T_CD`` minimises one cost::

    sum_i |pi(R X_i + t) - u_i|² / sigma_px²  +  sum_j (rho_j(R, t) - r_j)² / sigma_r(r_j)²

* ``pi``: the calibrated camera (pinhole with OpenCV's k1 k2 p1 p2 k3 distortion), applied to
  the tag corners ``X_i`` (tag frame D, z = 0), compared with the detected corner pixels
  ``u_i`` (raw, distorted) with the pixel noise ``sigma_px``;
* ``rho_j``: the distance along sensor j's ray (origin ``s_j`` in C, direction +z_C) to the
  deck plane through ``t_CD`` with normal ``R_CD e_z``: ``n·(t - s_j) / n_z``, compared with
  the reading ``r_j`` with the ToF noise model ``sigma_r`` (:mod:`estimation.noise`).

The problem has six unknowns and at most 8 + 4 residuals, so a Levenberg–Marquardt loop over
a left-multiplicative rotation update ``R <- Exp(dtheta) R`` and ``t <- t + dt`` with analytic
Jacobians (:class:`TightProblem`) is written out here: SciPy's ``least_squares(method="lm")``
with the same residuals and analytic Jacobian takes 207 µs (median thread CPU time,
``benchmarks/bench_estimators.py``, shared machine) for the refinement this loop does in
82 µs, half of the frame's 400 µs budget (the tests check the two reach the same minimum).
It starts from both IPPE poses of the corners and from the pose on the ToF plane (corners
back-projected on the plane fitted to the touch points, then a rigid fit), and keeps the
lowest final cost: the ranges thus decide the planar flip ambiguity that costs camera-only
estimates their 10° spikes.  The 6x6 covariance of ``(x, y, z, roll, pitch, yaw)`` is
``(JᵀJ)⁻¹`` of the whitened Jacobian at the solution, mapped to the Euler angles.

Degradation: with no valid range it is the maximum-likelihood camera-only pose (IPPE
refined through the distortion model); 1 to 3 valid ranges still enter the cost; 3 corners
(one NaN) are used when the ToF plane (3 or more ranges) or a recent estimate gives a start;
with fewer corners or no tag the estimate is invalid (wrap it in
:class:`~estimation.tracking.TrackedEstimator` to bridge a lost tag by prediction).  A range
whose residual at the solution exceeds ``range_gate_sigma`` (a ray off the deck, multipath)
is dropped and the pose solved again.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from estimation import geometry
from estimation.atda import ippe_solutions
from estimation.camera_model import CameraIntrinsics
from estimation.corner_bias import CornerBias, edge_axis_alignment
from estimation.errors import ConfigError, require_choice, require_range
from estimation.estimator import (
    BAD_CORNERS,
    DEGENERATE_CORNERS,
    MAX_ABS_PIXEL,
    MAX_RANGE_M,
    NO_DETECTION,
    NON_FINITE_RESULT,
    GuardedEstimator,
    corners_degenerate,
    finish_pose,
)
from estimation.frames import tag_corners_in_tag_frame, tof_positions_in_camera_frame
from estimation.noise import (
    DEFAULT_PIXEL_SIGMA_PX,
    VL53L1X_RESOLUTION_M,
    VL53L1X_SIGMA_0_M,
    VL53L1X_SIGMA_PER_M,
    TofNoiseModel,
)
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading

if TYPE_CHECKING:
    from estimation.tof_calibration import TofCameraCalibration

PRINCIPAL_POINT_SOURCES = ("touch_points", "calibrated")

TOO_FEW_CORNERS = "too_few_corners"
NO_INITIAL_POSE = "no_initial_pose"
REPROJECTION_ERROR = "reprojection_error"
SINGULAR_INFORMATION = "singular_information"

_E_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class TightConfig:
    """Settings of :class:`TightEstimator`.

    ``pixel_sigma_px``: 1-sigma of a detected corner coordinate (default
    :data:`estimation.noise.DEFAULT_PIXEL_SIGMA_PX`); with ``pixel_sigma_axes_px`` set (> 0)
    it is the sigma when the tag's edges lie on the image diagonals, ``pixel_sigma_axes_px``
    the sigma when they lie along the pixel axes, and each frame's is
    ``sqrt(d² + (a² - d²) cos²(2φ))`` for its edges' angle φ
    (:func:`estimation.corner_bias.edge_axis_alignment`; the tag rig measures both).
    ``tof_sigma_0_m``,
    ``tof_sigma_per_m``, ``tof_resolution_m``, ``tof_sigma_min_m`` (a floor, 0 by default):
    the ToF noise model
    (:class:`estimation.noise.TofNoiseModel`; defaults: the VL53L1X model the simulator's
    ``tof.noise: vl53l1x`` draws from).  ``max_iterations``: LM iterations per start.
    ``range_gate_sigma``: a range further than this many sigma from the solution is dropped
    and the pose solved again.  ``max_reprojection_error_px``: a larger RMS corner error
    at the solution means the corners are not the tag's (invalid).
    ``ambiguity_ratio_threshold`` / ``history_timeout_s``: without ranges, two IPPE
    solutions whose RMS errors are this close are told apart by the previous estimate
    (as ATDA does).  ``start_cost_margin``: only the starts whose whitened cost is within
    this of the lowest start's are refined (``inf``: all of them); the others start in
    another basin with a cost higher by more than sqrt(50) ≈ 7 sigma.
    ``principal_point``: ``"touch_points"`` (with a ToF–camera calibration) moves the
    calibrated principal point by the median offset between the pads' measured touch pixels
    and their projection through the calibrated camera (the calibrations' disagreement,
    which CRHF removes by estimating its own principal point, CRHF Sec. 2.7: a chessboard
    calibration off by 0.3 px in cx shifts x by 1.3 mm at 2 m); ``"calibrated"`` keeps K.
    ``corner_bias_px``: the detector's edge offset ``(a, b, c)`` on this camera
    (:class:`estimation.corner_bias.CornerBias`: ``a + b sin²(2φ) + c / L`` pixels outward
    per tag edge), removed from the detected corners before they enter the cost; measured
    with the intrinsics (``deck-landing calibrate`` stores it in the intrinsics file).
    ``noise_from_sensors``: a host that knows its sensors (the simulator) replaces the ToF
    noise above by the configured sensor's model, and the pixel sigma and corner offset by
    the camera's: the configured corner noise in ``project`` mode (no offset), the
    calibrated ones of the intrinsics file when rendering.
    """

    pixel_sigma_px: float = DEFAULT_PIXEL_SIGMA_PX
    pixel_sigma_axes_px: float = 0.0
    tof_sigma_0_m: float = VL53L1X_SIGMA_0_M
    tof_sigma_per_m: float = VL53L1X_SIGMA_PER_M
    tof_resolution_m: float = VL53L1X_RESOLUTION_M
    tof_sigma_min_m: float = 0.0
    max_iterations: int = 12
    range_gate_sigma: float = 6.0
    max_reprojection_error_px: float = 10.0
    min_corner_area_px: float = 4.0
    ambiguity_ratio_threshold: float = 0.6
    history_timeout_s: float = 0.5
    start_cost_margin: float = 50.0
    principal_point: str = "touch_points"
    corner_bias_px: tuple[float, float, float] = (0.0, 0.0, 0.0)
    noise_from_sensors: bool = True

    def __post_init__(self) -> None:
        require_range("pixel_sigma_px", self.pixel_sigma_px, 0.0, low_inclusive=False)
        require_range("pixel_sigma_axes_px", self.pixel_sigma_axes_px, 0.0)
        require_range("tof_sigma_0_m", self.tof_sigma_0_m, 0.0)
        require_range("tof_sigma_per_m", self.tof_sigma_per_m, 0.0)
        require_range("tof_resolution_m", self.tof_resolution_m, 0.0)
        require_range("tof_sigma_min_m", self.tof_sigma_min_m, 0.0)
        require_range("max_iterations", self.max_iterations, 1)
        require_range("range_gate_sigma", self.range_gate_sigma, 0.0, low_inclusive=False)
        require_range(
            "max_reprojection_error_px", self.max_reprojection_error_px, 0.0, low_inclusive=False
        )
        require_range("min_corner_area_px", self.min_corner_area_px, 0.0)
        require_range(
            "ambiguity_ratio_threshold", self.ambiguity_ratio_threshold, 0.0, 1.0,
            low_inclusive=False,
        )  # fmt: skip
        require_range("history_timeout_s", self.history_timeout_s, 0.0)
        require_range("start_cost_margin", self.start_cost_margin, 0.0)
        require_choice("principal_point", self.principal_point, PRINCIPAL_POINT_SOURCES)
        if len(self.corner_bias_px) != 3 or not all(
            math.isfinite(float(v)) for v in self.corner_bias_px
        ):
            raise ConfigError(
                "corner_bias_px", f"{self.corner_bias_px!r}: need three finite numbers (a, b, c)"
            )

    @property
    def tof_noise(self) -> TofNoiseModel:
        return TofNoiseModel(
            self.tof_sigma_0_m, self.tof_sigma_per_m, self.tof_resolution_m, self.tof_sigma_min_m
        )


def rotation_exp(dtheta: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: the rotation matrix of the rotation vector ``dtheta``."""
    wx, wy, wz = float(dtheta[0]), float(dtheta[1]), float(dtheta[2])
    angle2 = wx * wx + wy * wy + wz * wz
    if angle2 < 1e-24:
        return np.array([[1.0, -wz, wy], [wz, 1.0, -wx], [-wy, wx, 1.0]])
    angle = math.sqrt(angle2)
    a = math.sin(angle) / angle
    b = (1.0 - math.cos(angle)) / angle2
    return np.array(
        [
            [1.0 - b * (wy * wy + wz * wz), b * wx * wy - a * wz, b * wx * wz + a * wy],
            [b * wx * wy + a * wz, 1.0 - b * (wx * wx + wz * wz), b * wy * wz - a * wx],
            [b * wx * wz - a * wy, b * wy * wz + a * wx, 1.0 - b * (wx * wx + wy * wy)],
        ]
    )


@dataclass(frozen=True)
class TightSolution:
    """A local minimum of the tight cost."""

    rotation: np.ndarray
    translation: np.ndarray
    cost: float
    jacobian: np.ndarray
    residuals: np.ndarray
    iterations: int


class TightProblem:
    """The whitened residuals and their Jacobian for one frame's measurements.

    Parameters are ``(dt, dtheta)`` of ``t <- t + dt``, ``R <- Exp(dtheta) R``.  Residual
    order: each corner's (u, v), then the ranges.  The problem is small (at most 8 + 4
    residuals), so the residuals and the Jacobian rows are computed in plain floats: numpy's
    per-call overhead on 4-element arrays costs more than the arithmetic.
    """

    def __init__(
        self,
        model_d: np.ndarray,
        pixels: np.ndarray,
        intrinsics: CameraIntrinsics,
        pixel_sigma_px: float,
        sensors_c: np.ndarray,
        ranges: np.ndarray,
        range_sigma_m: np.ndarray,
    ) -> None:
        model = np.asarray(model_d, dtype=float)
        if not np.allclose(model[:, 2], 0.0):
            raise ValueError("the tag model must lie in its plane z = 0")
        pixels = np.asarray(pixels, dtype=float)
        k = intrinsics
        # the model's (x, y) and the measured pixels in normalised camera units
        normalised = (pixels - (k.cx, k.cy)) / (k.fx, k.fy)
        self._corners = np.hstack([model[:, :2], normalised]).tolist()
        self.n_corners = len(self._corners)
        sensors = np.asarray(sensors_c, dtype=float).reshape(-1, 3)
        ranges = np.asarray(ranges, dtype=float).reshape(-1, 1)
        weights = 1.0 / np.asarray(range_sigma_m, dtype=float).reshape(-1, 1)
        self._ranges = np.hstack([sensors, ranges, weights]).tolist()
        self.n_ranges = len(self._ranges)
        self.pixel_sigma_px = float(pixel_sigma_px)
        self._wu = k.fx / self.pixel_sigma_px
        self._wv = k.fy / self.pixel_sigma_px
        self._dist = tuple(float(d) for d in k.dist) if k.has_distortion else None
        self.m = 2 * self.n_corners + self.n_ranges

    def cost(self, rotation: np.ndarray, translation: np.ndarray) -> float:
        """The whitened cost (sum of squared residuals) of a pose; NaN behind the camera."""
        res = self._evaluate(rotation, translation, False)[0]
        return math.fsum(v * v for v in res)

    def residuals(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """Whitened residuals (m) of a pose (NaN where a corner is behind the camera)."""
        return np.array(self._evaluate(rotation, translation, False)[0])

    def linearise(
        self, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residuals (m) and their Jacobian (m x 6) of a pose."""
        res, rows = self._evaluate(rotation, translation, True)
        return np.array(res), np.array(rows).reshape(self.m, 6)

    def _evaluate(
        self, rotation: np.ndarray, translation: np.ndarray, jacobian: bool
    ) -> tuple[list[float], list[list[float]]]:
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation.tolist()
        tx, ty, tz = translation.tolist()
        wu, wv = self._wu, self._wv
        dist = self._dist
        res: list[float] = []
        rows: list[list[float]] = []
        for mx, my, mu, mv in self._corners:
            qx = r00 * mx + r01 * my
            qy = r10 * mx + r11 * my
            qz = r20 * mx + r21 * my
            pz = qz + tz
            if not pz > 0.0:
                res += [math.nan, math.nan]
                rows += [[math.nan] * 6, [math.nan] * 6]
                continue
            iz = 1.0 / pz
            x = (qx + tx) * iz
            y = (qy + ty) * iz
            if dist is None:
                res += [(x - mu) * wu, (y - mv) * wv]
                if jacobian:
                    cu0, cu1, cu2 = wu * iz, 0.0, -wu * iz * x
                    cv0, cv1, cv2_ = 0.0, wv * iz, -wv * iz * y
            else:
                k1, k2, p1, p2, k3 = dist
                xx, yy, xy = x * x, y * y, x * y
                r2 = xx + yy
                radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
                xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
                yd = y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
                res += [(xd - mu) * wu, (yd - mv) * wv]
                if jacobian:
                    dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
                    a11 = radial + 2.0 * xx * dr + 2.0 * p1 * y + 6.0 * p2 * x
                    a12 = 2.0 * xy * dr + 2.0 * p1 * x + 2.0 * p2 * y
                    a22 = radial + 2.0 * yy * dr + 6.0 * p1 * y + 2.0 * p2 * x
                    fu, fv = wu * iz, wv * iz
                    cu0, cu1 = fu * a11, fu * a12
                    cu2 = -(cu0 * x + cu1 * y)
                    cv0, cv1 = fv * a12, fv * a22
                    cv2_ = -(cv0 * x + cv1 * y)
            if jacobian:
                # dp/dtheta = -[q]x  =>  the row c becomes q x c
                rows.append(
                    [cu0, cu1, cu2, qy * cu2 - qz * cu1, qz * cu0 - qx * cu2, qx * cu1 - qy * cu0]
                )
                rows.append(
                    [
                        cv0,
                        cv1,
                        cv2_,
                        qy * cv2_ - qz * cv1,
                        qz * cv0 - qx * cv2_,
                        qx * cv1 - qy * cv0,
                    ]
                )
        if self._ranges:
            inz = 1.0 / r22 if r22 != 0.0 else math.inf
            for sx, sy, sz, measured, w in self._ranges:
                ax, ay, az = tx - sx, ty - sy, tz - sz
                rho = (ax * r02 + ay * r12 + az * r22) * inz
                res.append((rho - measured) * w)
                if jacobian:
                    wn = w * inz
                    gx, gy, gz = ax * wn, ay * wn, (az - rho) * wn
                    rows.append(
                        [
                            r02 * wn,
                            r12 * wn,
                            r22 * wn,
                            r12 * gz - r22 * gy,
                            r22 * gx - r02 * gz,
                            r02 * gy - r12 * gx,
                        ]
                    )
        return res, rows

    def solve(
        self,
        rotation: np.ndarray,
        translation: np.ndarray,
        max_iterations: int,
        step_tol: float = 1e-9,
        cost_tol: float = 1e-4,
    ) -> TightSolution | None:
        """Levenberg–Marquardt from ``(rotation, translation)``; None if it breaks down.

        It stops when a step is below ``step_tol`` (metres and radians), which on noise-free
        data leaves errors far below 1e-6 m (Gauss–Newton converges quadratically there), or
        when a step lowered the whitened cost by less than ``cost_tol`` (times the cost per
        residual where that exceeds 1, i.e. where the sigmas are set too small): the pose
        then moved by about sqrt(cost_tol) = 1 % of its standard deviation.
        """
        rotation = np.asarray(rotation, dtype=float)
        translation = np.asarray(translation, dtype=float)
        r, j = self.linearise(rotation, translation)
        cost = float(r @ r)
        if not math.isfinite(cost):
            return None
        lam = 1e-6
        iterations = 0
        for iterations in range(1, max_iterations + 1):  # noqa: B007
            h = j.T @ j
            damped = h + np.diag(lam * (np.diag(h) + 1e-12))
            step = np.linalg.solve(damped, -(j.T @ r))
            new_t = translation + step[:3]
            new_r = rotation_exp(step[3:]) @ rotation
            r_new, j_new = self.linearise(new_r, new_t)
            cost_new = float(r_new @ r_new)
            small = float(np.max(np.abs(step))) < step_tol
            if cost_new <= cost:  # NaN is never accepted
                # in units of the cost per residual, so that a mis-set sigma does not
                # change when it stops
                small = small or cost - cost_new <= cost_tol * max(1.0, cost / self.m)
                rotation, translation, r, j, cost = new_r, new_t, r_new, j_new, cost_new
                lam = max(lam * 0.1, 1e-9)
            else:
                lam *= 10.0
                if lam > 1e8:
                    break
            if small:
                break
        return TightSolution(rotation, translation, cost, j, r, iterations)


#: Starts closer than this (rotation angle, translation relative to depth) are refined as
#: one, from the lower-cost start: the IPPE pose on the deck's side and the ToF-plane pose
#: converge to the same minimum, and with 0.5 px, VL53L1X ranges and a 12 cm tag at 0.5–3 m
#: they lie up to 23° and 2.6 % of the depth apart (measured over 300 random poses).
_SAME_BASIN_COS = math.cos(math.radians(30.0))
_SAME_BASIN_REL = 0.05


def _same_basin(
    a: tuple[str, np.ndarray, np.ndarray], b: tuple[str, np.ndarray, np.ndarray]
) -> bool:
    # trace(R_a^T R_b) = 1 + 2 cos(angle)
    cos_angle = 0.5 * (float(np.sum(a[1] * b[1])) - 1.0)
    gap = float(np.linalg.norm(a[2] - b[2]))
    return cos_angle >= _SAME_BASIN_COS and gap <= _SAME_BASIN_REL * float(abs(a[2][2]))


def euler_jacobian(rotation: np.ndarray) -> np.ndarray:
    """d(roll, pitch, yaw)/d(dtheta) for the left update ``R <- Exp(dtheta) R`` (ZYX)."""
    sp = -float(rotation[2, 0])
    cp = math.sqrt(max(0.0, 1.0 - sp * sp))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    cy, sy = math.cos(yaw), math.sin(yaw)
    # the angular velocity in C of (roll, pitch, yaw) rates: columns Rz Ry e_x, Rz e_y, e_z
    e = np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])
    return np.linalg.inv(e)


def principal_point_offset(
    intrinsics: CameraIntrinsics,
    tof_positions_c: np.ndarray,
    tof_calibration: TofCameraCalibration,
) -> np.ndarray:
    """The median (du, dv) by which the ToF–camera calibration's touch pixels lie from the
    projection of the touch points ``s_i + r e_z`` through ``intrinsics``, pixels.

    Both calibrations see the same image, but the pads' touch pixels are measured directly
    while the chessboard's principal point is a fitted parameter; their median disagreement
    over every sample is the principal-point error (zero for consistent calibrations).
    """
    offsets = []
    for sensor, samples in zip(tof_positions_c, tof_calibration.samples, strict=False):
        points = np.tile(sensor, (len(samples), 1))
        points[:, 2] += samples[:, 0]
        offsets.append(samples[:, 1:3] - intrinsics.project(points))
    stacked = np.vstack(offsets) if offsets else np.empty((0, 2))
    stacked = stacked[np.all(np.isfinite(stacked), axis=1)]
    if len(stacked) == 0:
        return np.zeros(2)
    return np.median(stacked, axis=0)


class TightEstimator(GuardedEstimator):
    """The deck pose from the tag corners and the ToF ranges in one least-squares problem."""

    name = "tight"

    def __init__(
        self,
        *,
        intrinsics: CameraIntrinsics,
        tag_size: float,
        tag_id: int = 0,
        tof_positions_c: np.ndarray | None = None,
        tof_calibration: TofCameraCalibration | None = None,
        config: TightConfig | None = None,
    ) -> None:
        require_range("tag_size", tag_size, 0.0, low_inclusive=False)
        positions = (
            tof_positions_in_camera_frame()
            if tof_positions_c is None
            else np.asarray(tof_positions_c, dtype=float).reshape(-1, 3)
        )
        if not np.isfinite(positions).all():
            raise ConfigError("tof_positions_c", "sensor positions must be finite")
        if tof_calibration is not None and tof_calibration.n_sensors != len(positions):
            raise ConfigError(
                "tof_calibration",
                f"has {tof_calibration.n_sensors} sensors, tof_positions_c has {len(positions)}",
            )
        self.tag_size = float(tag_size)
        self.tag_id = int(tag_id)
        self.tof_positions_c = positions
        self.config = config or TightConfig()
        self.principal_point_offset_px = np.zeros(2)
        if tof_calibration is not None and self.config.principal_point == "touch_points":
            self.principal_point_offset_px = principal_point_offset(
                intrinsics, positions, tof_calibration
            )
            dx, dy = self.principal_point_offset_px
            intrinsics = dataclasses.replace(
                intrinsics, cx=intrinsics.cx + float(dx), cy=intrinsics.cy + float(dy)
            )
        self.intrinsics = intrinsics
        self._noise = self.config.tof_noise
        self._corner_bias = CornerBias(*(float(v) for v in self.config.corner_bias_px))
        self._model = tag_corners_in_tag_frame(self.tag_size)
        self._k = intrinsics.matrix
        self._undistorter = geometry.Undistorter(intrinsics)
        self._rigid_fitter = geometry.RigidFitter(self._model)
        # the sensors' (x, y) never change: the plane's least-squares pseudo-inverse is fixed
        try:
            self._plane_fitter: geometry.ZPlaneFitter | None = geometry.ZPlaneFitter(
                positions[:, :2]
            )
        except ValueError:
            self._plane_fitter = None
        self._previous: tuple[float, np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        self._previous = None

    # -- inputs ------------------------------------------------------------------------
    def _corners(self, frame: CameraFrame) -> tuple[np.ndarray | None, np.ndarray, str]:
        """The tag's raw corner pixels (4x2), the mask of usable ones, or a reason."""
        candidates = [d for d in frame.detections if d.tag_id == self.tag_id]
        if not candidates:
            return None, np.zeros(4, bool), NO_DETECTION
        best = min(candidates, key=lambda d: int(getattr(d, "hamming", 0)))
        corners = np.asarray(best.corners_px, dtype=float)
        if corners.shape != (4, 2):
            return None, np.zeros(4, bool), BAD_CORNERS
        usable = np.all(np.abs(corners) <= MAX_ABS_PIXEL, axis=1)  # NaN fails too
        count = int(usable.sum())
        if count < 3:
            return None, usable, TOO_FEW_CORNERS
        if count == 4:
            if corners_degenerate(corners, self.config.min_corner_area_px):
                return None, usable, DEGENERATE_CORNERS
        else:
            a, b, c = corners[usable]
            area = 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
            if not area >= self.config.min_corner_area_px:
                return None, usable, DEGENERATE_CORNERS
        return corners, usable, ""

    def _ranges(self, reading: RangeReading) -> tuple[np.ndarray, np.ndarray]:
        """The usable ranges and the sensors they belong to (any number, 0 included)."""
        n = len(self.tof_positions_c)
        ranges = np.asarray(reading.ranges, dtype=float).reshape(-1)
        valid = np.asarray(reading.valid, dtype=bool).reshape(-1)
        if len(ranges) != n or len(valid) != n:
            return np.empty(0), np.empty((0, 3))
        use = valid & (ranges > 0.0) & (ranges <= MAX_RANGE_M)
        return ranges[use], self.tof_positions_c[use]

    def _pixel_sigma(self, corners: np.ndarray, usable: np.ndarray) -> float:
        """This frame's corner sigma: the configured one, or its model against the edges'
        angle to the pixel axes (the larger of the two ends when the angle is unknown)."""
        cfg = self.config
        diagonal, axes = cfg.pixel_sigma_px, cfg.pixel_sigma_axes_px
        if not axes > 0.0:
            return diagonal
        alignment = edge_axis_alignment(corners) if usable.all() else math.nan
        if not math.isfinite(alignment):
            return max(diagonal, axes)
        return math.sqrt(diagonal * diagonal + (axes * axes - diagonal * diagonal) * alignment)

    # -- starts ------------------------------------------------------------------------
    def _plane_start(
        self, undistorted: np.ndarray, model: np.ndarray, ranges: np.ndarray, sensors: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Corners back-projected onto the plane of the touch points, then a rigid fit."""
        if len(ranges) < 3:
            return None
        if len(ranges) == len(self.tof_positions_c) and self._plane_fitter is not None:
            plane = self._plane_fitter.fit(ranges + self.tof_positions_c[:, 2])
        else:
            touch = sensors.copy()
            touch[:, 2] += ranges
            plane = geometry.fit_plane(touch, "lstsq")
        if plane is None:
            return None
        k = self.intrinsics
        rays = np.ones((len(undistorted), 3))
        rays[:, 0] = (undistorted[:, 0] - k.cx) / k.fx
        rays[:, 1] = (undistorted[:, 1] - k.cy) / k.fy
        along = rays @ plane.normal
        if not np.all(along > 1e-9) or not plane.offset > 0.0:
            return None
        points = rays * (plane.offset / along)[:, None]
        if len(points) == len(self._model):
            fit = self._rigid_fitter.fit(points)
        else:
            fit = geometry.fit_rigid(model, points)
        if fit is None:
            return None
        return fit.rotation, fit.translation

    def _starts(
        self,
        timestamp: float,
        undistorted: np.ndarray,
        usable: np.ndarray,
        ranges: np.ndarray,
        sensors: np.ndarray,
    ) -> list[tuple[str, np.ndarray, np.ndarray]]:
        starts: list[tuple[str, np.ndarray, np.ndarray]] = []
        if usable.all():
            _, solutions = ippe_solutions(self._model, undistorted, self._k)
            starts += [(f"ippe{i}", s[1], s[2]) for i, s in enumerate(solutions[:2])]
        plane = self._plane_start(undistorted[usable], self._model[usable], ranges, sensors)
        if plane is not None:
            starts.append(("plane", *plane))
        previous = self._previous
        if (
            not starts
            and previous is not None
            and 0.0 <= timestamp - previous[0] <= self.config.history_timeout_s
        ):
            starts.append(("previous", previous[1], previous[2]))
        return starts

    # -- the estimate ------------------------------------------------------------------
    def _solve_all(
        self,
        problem: TightProblem,
        starts: list[tuple[str, np.ndarray, np.ndarray]],
        timestamp: float,
    ) -> tuple[str, TightSolution, float, bool] | None:
        """The lowest-cost solution over the starts (with ATDA's history rule when
        there are no ranges), its start's name, the ambiguity ratio and whether history
        decided."""
        if len(starts) > 1 and math.isfinite(self.config.start_cost_margin):
            # only the starts whose cost is near the best start's are refined
            initial = [problem.cost(rotation, translation) for _, rotation, translation in starts]
            lowest = min(initial)  # NaN never compares lower
            if math.isfinite(lowest):
                margin = self.config.start_cost_margin
                ranked = sorted(zip(initial, range(len(starts)), strict=True))
                kept: list[tuple[str, np.ndarray, np.ndarray]] = []
                for c, i in ranked:
                    if c <= lowest + margin and not any(_same_basin(starts[i], s) for s in kept):
                        kept.append(starts[i])
                starts = kept
        found = []
        for label, rotation, translation in starts:
            solution = problem.solve(rotation, translation, self.config.max_iterations)
            if solution is not None:
                found.append((label, solution))
        if not found:
            return None
        found.sort(key=lambda f: f[1].cost)
        # starts that converged to the same minimum count once
        distinct: list[tuple[str, TightSolution]] = []
        for label, solution in found:
            if not any(
                float(np.sum(s.rotation * solution.rotation)) > 3.0 - 1e-8
                and float(np.sum((s.translation - solution.translation) ** 2)) < 1e-10
                for _, s in distinct
            ):
                distinct.append((label, solution))
        found = distinct
        ratio = 0.0  # one distinct minimum: unambiguous
        by_history = False
        if len(found) > 1:
            second = found[1][1].cost
            ratio = 1.0 if second <= 0.0 else math.sqrt(found[0][1].cost / second)
            previous = self._previous
            if (
                problem.n_ranges == 0
                and ratio >= self.config.ambiguity_ratio_threshold
                and previous is not None
                and 0.0 <= timestamp - previous[0] <= self.config.history_timeout_s
            ):
                closest = max(found[:2], key=lambda f: float(np.sum(previous[1] * f[1].rotation)))
                by_history = closest is not found[0]
                return closest[0], closest[1], ratio, by_history
        return found[0][0], found[0][1], ratio, by_history

    def _estimate(self, frame: CameraFrame, reading: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        corners, usable, reason = self._corners(frame)
        if corners is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, reason)
        if usable.all():
            corners = self._corner_bias.correct(corners)
        undistorted = corners.copy()
        if self._undistorter.active:
            undistorted[usable] = self._undistorter(corners[usable])
            if not np.isfinite(undistorted[usable]).all():
                return DeckPoseEstimate.invalid(self.name, timestamp, BAD_CORNERS)
        ranges, sensors = self._ranges(reading)
        starts = self._starts(timestamp, undistorted, usable, ranges, sensors)
        if not starts:
            return DeckPoseEstimate.invalid(self.name, timestamp, NO_INITIAL_POSE)
        dropped = 0
        pixel_sigma = self._pixel_sigma(corners, usable)
        while True:
            problem = TightProblem(
                self._model[usable],
                corners[usable],
                self.intrinsics,
                pixel_sigma,
                sensors,
                ranges,
                self._noise.sigma(ranges),
            )
            best = self._solve_all(problem, starts, timestamp)
            if best is None:
                return DeckPoseEstimate.invalid(self.name, timestamp, NON_FINITE_RESULT)
            label, solution, ratio, by_history = best
            range_res = np.abs(solution.residuals[2 * problem.n_corners :])
            if not len(range_res) or range_res.max() <= self.config.range_gate_sigma:
                break
            # drop the worst range and solve again, from this solution and the others
            keep = np.ones(len(ranges), bool)
            keep[int(np.argmax(range_res))] = False
            ranges, sensors = ranges[keep], sensors[keep]
            dropped += 1
            starts = [("gated", solution.rotation, solution.translation)] + [
                s for s in starts if s[0].startswith("ippe")
            ]
        n_px = 2 * problem.n_corners
        pixel_res = solution.residuals[:n_px] * problem.pixel_sigma_px
        rms_px = math.sqrt(float(pixel_res @ pixel_res) / problem.n_corners)
        if not rms_px <= self.config.max_reprojection_error_px:
            return DeckPoseEstimate.invalid(self.name, timestamp, REPROJECTION_ERROR)
        information = solution.jacobian.T @ solution.jacobian
        try:
            covariance = np.linalg.inv(information)
        except np.linalg.LinAlgError:
            return DeckPoseEstimate.invalid(self.name, timestamp, SINGULAR_INFORMATION)
        if not (np.isfinite(covariance).all() and np.all(np.diag(covariance) > 0.0)):
            return DeckPoseEstimate.invalid(self.name, timestamp, SINGULAR_INFORMATION)
        to_pose = np.eye(6)
        to_pose[3:, 3:] = euler_jacobian(solution.rotation)
        covariance = to_pose @ covariance @ to_pose.T
        extras = {
            "cost": solution.cost,
            "reprojection_error_px": rms_px,
            "pixel_sigma_px": problem.pixel_sigma_px,
            "ranges_used": problem.n_ranges,
            "ranges_dropped": dropped,
            "corners_used": problem.n_corners,
            "start": label,
            "iterations": solution.iterations,
            "ambiguity_ratio": ratio,
            "chosen_by_history": by_history,
        }
        estimate = finish_pose(
            self.name, timestamp, solution.rotation, solution.translation, extras
        )
        if not estimate.valid:
            return estimate
        self._previous = (timestamp, solution.rotation, solution.translation)
        return DeckPoseEstimate(
            method=self.name,
            timestamp=timestamp,
            valid=True,
            rotation=solution.rotation,
            translation=solution.translation,
            covariance=0.5 * (covariance + covariance.T),
            extras=extras,
        )
