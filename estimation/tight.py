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
Jacobians is written out (:class:`~estimation.tight_problem.TightProblem`): SciPy's
``least_squares(method="lm")`` with the same residuals and analytic Jacobian takes 207 µs
(median thread CPU time, ``benchmarks/bench_estimators.py``, shared machine) for the
refinement this loop does in 82 µs, half of the frame's 400 µs budget (the tests check the
two reach the same minimum).
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
from typing import TYPE_CHECKING

import numpy as np

from estimation import geometry
from estimation.atda import ippe_solutions
from estimation.camera_model import CameraIntrinsics
from estimation.corner_bias import CornerBias, edge_axis_alignment
from estimation.errors import ConfigError, require_range
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
    tof_sensor_positions,
)
from estimation.frames import tag_corners_in_tag_frame
from estimation.tight_config import TightConfig
from estimation.tight_problem import TightProblem, TightSolution, euler_jacobian
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading

if TYPE_CHECKING:
    from estimation.tof_calibration import TofCameraCalibration

TOO_FEW_CORNERS = "too_few_corners"
NO_INITIAL_POSE = "no_initial_pose"
REPROJECTION_ERROR = "reprojection_error"
SINGULAR_INFORMATION = "singular_information"


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


def principal_point_offset(
    intrinsics: CameraIntrinsics,
    tof_positions_c: np.ndarray,
    tof_calibration: TofCameraCalibration,
) -> np.ndarray:
    """The median (du, dv) by which the ToF–camera calibration's touch pixels lie from the
    projection of the touch points ``s_i + r e_z`` through ``intrinsics``, pixels.

    Both calibrations see the same image, but the pads' touch pixels are measured directly
    while the chessboard's principal point is a fitted parameter; their median disagreement
    over every sample is the principal-point error (zero for consistent calibrations, and
    where no sensor or no touch point in front of the camera gives one).
    """
    offsets = []
    for sensor, samples in zip(tof_positions_c, tof_calibration.samples, strict=False):
        points = np.tile(sensor, (len(samples), 1))
        points[:, 2] += samples[:, 0]
        offsets.append(samples[:, 1:3] - intrinsics.project(points))
    if not offsets:
        return np.zeros(2)  # no sensor: no touch pixel to compare
    stacked = np.vstack(offsets)
    stacked = stacked[np.all(np.isfinite(stacked), axis=1)]
    if len(stacked) == 0:
        return np.zeros(2)  # no touch point the camera sees
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
        positions = tof_sensor_positions(tof_positions_c, tof_calibration)
        if not np.isfinite(positions).all():
            raise ConfigError("tof_positions_c", "sensor positions must be finite")
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
        self._previous_cost = 0.0

    def reset(self) -> None:
        self._previous = None
        self._previous_cost = 0.0

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
            plane = geometry.plane_of_ranges(sensors, ranges)
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
        decided; with ``previous_start: first``, the previous estimate's solution alone
        where it is kept (:meth:`_warm`)."""
        if self.config.previous_start == "first":
            warm = self._warm(problem, timestamp)
            if warm is not None:
                return "previous", warm, 0.0, False
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

    def _warm(self, problem: TightProblem, timestamp: float) -> TightSolution | None:
        """The solution from the previous estimate alone, where the frame has four corners
        and three or more ranges (the ranges tell the planar flip apart) and its whitened
        cost is within ``start_cost_margin`` of the number of residuals; else None."""
        previous = self._previous
        if (
            previous is None
            or not 0.0 <= timestamp - previous[0] <= self.config.history_timeout_s
            or problem.n_corners < len(self._model)
            or problem.n_ranges < 3
        ):
            return None
        solution = problem.solve(previous[1], previous[2], self.config.max_iterations)
        # what a pose in the right basin costs: the residuals' count, or the previous
        # minimum's cost where the model fits this camera less well
        expected = max(float(problem.m), self._previous_cost)
        if solution is None or not solution.cost <= expected + self.config.start_cost_margin:
            return None
        return solution

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
        self._previous_cost = solution.cost
        return DeckPoseEstimate(
            method=self.name,
            timestamp=timestamp,
            valid=True,
            rotation=solution.rotation,
            translation=solution.translation,
            covariance=0.5 * (covariance + covariance.T),
            extras=extras,
        )
