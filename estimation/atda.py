"""ATDA: the AprilTag-only baseline (pose from the four tag corners and the camera model).

OpenCV's ``solvePnPGeneric(..., SOLVEPNP_IPPE_SQUARE)`` returns both poses that a planar
square admits (IPPE).  The one with the lower reprojection error is kept, except when the
two errors are comparable (``err_best / err_second >= ambiguity_ratio_threshold``: the image
cannot tell them apart, typically a small or fronto-parallel tag): then the one whose
rotation is closer to the previous estimate (within ``history_timeout_s``) is kept, for
temporal consistency instead of a pose that flips between the two solutions from frame to
frame.  The ratio is reported in ``extras["ambiguity_ratio"]`` (0: unambiguous, 1: both
solutions equally good, NaN: only one solution was found, see the fallbacks in the code).

Lens distortion is removed from the corners before IPPE with a tight iterative stopping rule
(:func:`estimation.geometry.undistort_pixels`), and IPPE then runs on the ideal pinhole:
``solvePnP``'s own undistortion stops after 5 iterations, which left errors of ~3e-5 m and
~3e-3° on noise-free data with k1 = -0.25 (measured); the reprojection errors in ``extras``
are therefore in undistorted pixels.

``pose_method="homography"`` is the papers' ATDA pose as an option: their ATDA is MATLAB's
``readAprilTag``, which is built on the AprilTag library.  That library's homography pose
(Olson 2011; ``estimate_pose_for_tag_homography``) scales the first two columns of
``K⁻¹ H`` to unit length, takes their cross product as the third and makes the result a
rotation by SVD: one pose straight from the four-point homography, with no refinement and no
choice between the two poses a planar square admits (IPPE's second solution is never
looked at).  MATLAB's documentation does not state readAprilTag's pose algorithm, so this
option is the closest published candidate, not a confirmed copy; see
docs/papers-reproduction.md for what it changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from estimation import geometry
from estimation.camera_model import CameraIntrinsics
from estimation.errors import require_choice, require_range
from estimation.estimator import (
    BAD_CORNERS,
    DEGENERATE_CORNERS,
    PNP_FAILED,
    DeckPoseEstimator,
    GuardedEstimator,
    corners_degenerate,
    finish_pose,
    target_corners,
)
from estimation.frames import tag_corners_in_tag_frame
from estimation.landmarks import LandmarkLayout, shortest_side_px
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading

REPROJECTION_ERROR = "reprojection_error"
_NO_DISTORTION = np.zeros(5)
#: ATDA's pose from the corners: OpenCV's IPPE with disambiguation, or the AprilTag library's
#: homography decomposition (one pose, no disambiguation; the papers' MATLAB readAprilTag)
POSE_METHODS = ("ippe", "homography")


def homography_pose(
    object_points: np.ndarray, corners: np.ndarray, k: np.ndarray
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """The AprilTag library's homography pose of a planar tag: ``[(RMS error px, R_CD, t_CD)]``
    (empty when the homography is degenerate).

    ``H`` maps the tag-plane points (x, y) of ``object_points`` (four) to the undistorted
    corner pixels, exactly.  With ``M = K⁻¹ H = s [r1 r2 t]``, ``s`` is the
    geometric mean of the norms of M's first two columns, its sign puts the tag in front of
    the camera, ``r3 = r1 × r2``, and the nearest rotation to ``[r1 r2 r3]`` (SVD) is R.
    """
    # the four-point DLT in double precision (OpenCV's homography routines lose ~1e-5 px)
    xy = np.asarray(object_points[:, :2], dtype=float)
    uv = np.asarray(corners, dtype=float)
    design = np.zeros((8, 8))
    rhs = uv.reshape(-1)
    for i, ((x, y), (u, v)) in enumerate(zip(xy, uv, strict=True)):
        design[2 * i] = (x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y)
        design[2 * i + 1] = (0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y)
    try:
        homography = np.append(np.linalg.solve(design, rhs), 1.0).reshape(3, 3)
    except np.linalg.LinAlgError:
        return []
    m = np.linalg.solve(k, homography)
    norms = np.linalg.norm(m[:, :2], axis=0)
    if not (np.all(np.isfinite(m)) and np.all(norms > 0.0)):
        return []
    scale = math.sqrt(float(norms[0] * norms[1]))
    if m[2, 2] < 0.0:
        scale = -scale
    r1, r2, translation = m[:, 0] / scale, m[:, 1] / scale, m[:, 2] / scale
    u, _, vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    rotation = u @ vt
    if np.linalg.det(rotation) < 0.0:
        rotation = u @ np.diag([1.0, 1.0, -1.0]) @ vt
    if not (np.all(np.isfinite(rotation)) and translation[2] > 0.0):
        return []
    rvec, _ = cv2.Rodrigues(rotation)
    projected, _ = cv2.projectPoints(object_points, rvec, translation, k, _NO_DISTORTION)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - corners) ** 2, axis=1))))
    return [(rms, rotation, translation)]


def _solve_pnp(
    object_points: np.ndarray, corners: np.ndarray, k: np.ndarray, flag: int
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """The finite PnP solutions in front of the camera as (RMS error px, R, t): the RMS over
    the corners of the pixel distance between reprojection and measurement, as
    :func:`homography_pose` and the joint PnP report it (OpenCV's own error is the RMS over
    the eight coordinates, smaller by a factor of √2)."""
    count, rvecs, tvecs, errors = cv2.solvePnPGeneric(
        object_points, corners.reshape(4, 1, 2), k, _NO_DISTORTION, flags=flag
    )
    errors = np.asarray(errors, dtype=float).reshape(-1) * math.sqrt(2.0)
    solutions = []
    for i in range(int(count)):
        tvec = np.asarray(tvecs[i], dtype=float).reshape(3)
        rvec = np.asarray(rvecs[i], dtype=float).reshape(3)
        finite = np.all(np.isfinite(tvec)) and np.all(np.isfinite(rvec))
        if finite and np.isfinite(errors[i]) and tvec[2] > 0.0:
            rotation, _ = cv2.Rodrigues(rvec)
            solutions.append((float(errors[i]), rotation, tvec))
    return solutions


def ippe_solutions(
    object_points: np.ndarray, corners: np.ndarray, k: np.ndarray
) -> tuple[str, list[tuple[float, np.ndarray, np.ndarray]]]:
    """IPPE_SQUARE's two poses of a square tag from its 4 undistorted corner pixels, sorted
    by reprojection error, as (RMS error px, R_CD, t_CD), with the solver that gave them.

    OpenCV 5.0 returns rotation vectors, and its conversion loses precision for
    rotations near 180° (measured: 0.03° error 1e-6 rad from a yaw of 180°, a wrong pose
    at exactly 180°).  When the tag's x axis points left in the image (``|yaw|`` > 90°) the
    corners are therefore relabelled by half a turn, which is the same square turned
    by 180° about its normal, and the result is turned back.

    IPPE also returns NaN for some exactly symmetric views (tag centre on an image axis,
    tilt about the other); IPPE_SQUARE and generic IPPE fail on different cases, and
    SQPNP (one, globally optimal pose) is the last resort.
    """
    x_axis_u = corners[1, 0] + corners[2, 0] - corners[0, 0] - corners[3, 0]
    half_turn = x_axis_u < 0.0
    if half_turn:
        corners = corners[[2, 3, 0, 1]]
    best: tuple[str, list] = ("none", [])
    tried: list[tuple[float, str, tuple[float, np.ndarray, np.ndarray]]] = []
    for solver, flag in (
        ("ippe_square", cv2.SOLVEPNP_IPPE_SQUARE),
        ("ippe", cv2.SOLVEPNP_IPPE),
        ("sqpnp", cv2.SOLVEPNP_SQPNP),
    ):
        sols = _solve_pnp(object_points, corners, k, flag)
        tried += [(s[0], solver, s) for s in sols]
        if len(sols) > len(best[1]):
            best = (solver, sols)
        if len(best[1]) >= 2:
            break
    if len(best[1]) < 2 and tried:
        # no solver gave both poses: keep the best-fitting of everything found (IPPE_SQUARE
        # can return a single pose 13° off with a 3 px error on an exactly face-on view at
        # 0.3 m, where SQPNP finds the exact one; found by hypothesis)
        tried.sort(key=lambda entry: entry[0])
        kept: list[tuple[float, np.ndarray, np.ndarray]] = []
        for _, _, solution in tried:
            if not any(np.allclose(solution[1], other[1], atol=1e-6) for other in kept):
                kept.append(solution)
        best = (tried[0][1], kept[:2])
    solutions = sorted(best[1], key=lambda s: s[0])
    if half_turn:
        # R_CD = R' Rz(180°): negate the first two columns
        solutions = [(e, r * np.array([-1.0, -1.0, 1.0]), t) for e, r, t in solutions]
    return best[0], solutions


@dataclass(frozen=True)
class ATDAConfig:
    """ATDA settings.

    ``ambiguity_ratio_threshold``: from this ratio of reprojection errors up, the previous
    estimate decides between the two IPPE solutions (measured on a static 15 cm tag at 1 m
    with 0.3 px corner noise: 0 wrong-branch picks in 300 frames at 0.6 against 4 without
    history; much lower thresholds let an early wrong pick persist).
    ``history_timeout_s``: an older previous estimate is not used.
    ``max_reprojection_error_px``: a larger RMS error of the chosen pose means the corners
    are not a square's image (invalid).
    ``joint_landmarks``: on a deck with nested landmarks, estimate from all detected tags
    at once (:class:`JointAtdaEstimator`) rather than from the chosen one alone.
    ``pose_method``: ``"ippe"`` (both planar poses, the better or the one nearer the last
    estimate) or ``"homography"`` (the AprilTag library's single homography pose, as the
    papers' MATLAB readAprilTag; single tags only, the joint PnP keeps IPPE).
    """

    ambiguity_ratio_threshold: float = limited(0.6, Limit(0.0, 1.0, low_inclusive=False))
    history_timeout_s: float = limited(0.5, NON_NEGATIVE, physical=Limit.non_negative(60.0))
    max_reprojection_error_px: float = limited(10.0, POSITIVE, physical=Limit.positive(1e4))
    min_corner_area_px: float = limited(4.0, NON_NEGATIVE, physical=Limit.non_negative(1e7))
    joint_landmarks: bool = True
    pose_method: str = "ippe"

    def __post_init__(self) -> None:
        require_choice("pose_method", self.pose_method, POSE_METHODS)
        require_limits(self)


def _deciding_rotation(
    config: ATDAConfig,
    previous: tuple[float, np.ndarray] | None,
    ratio: float,
    timestamp: float,
) -> np.ndarray | None:
    """The previous estimate's rotation where it decides between the two best solutions (an
    ambiguity ``ratio`` at the threshold or above, the estimate recent enough), else None."""
    if (
        ratio >= config.ambiguity_ratio_threshold
        and previous is not None
        and 0.0 <= timestamp - previous[0] <= config.history_timeout_s
    ):
        return previous[1]
    return None


class AtdaEstimator(GuardedEstimator):
    """AprilTag-only pose by IPPE: needs the calibrated intrinsics, ignores the ranges."""

    name = "atda"

    def __init__(
        self,
        *,
        intrinsics: CameraIntrinsics,
        tag_size: float,
        tag_id: int,
        config: ATDAConfig | None = None,
    ) -> None:
        require_range("tag_size", tag_size, 0.0, low_inclusive=False)
        self.intrinsics = intrinsics
        self.tag_size = float(tag_size)
        self.tag_id = int(tag_id)
        self.config = config or ATDAConfig()
        # IPPE_SQUARE's required point order is exactly frames.TAG_CORNER_SIGNS
        self._object_points = tag_corners_in_tag_frame(self.tag_size)
        self._k = intrinsics.matrix
        self._undistorter = geometry.Undistorter(intrinsics)
        self._previous: tuple[float, np.ndarray] | None = None

    def reset(self) -> None:
        self._previous = None

    def _solutions(self, corners: np.ndarray) -> tuple[str, list]:
        if self.config.pose_method == "homography":
            return "homography", homography_pose(self._object_points, corners, self._k)
        return ippe_solutions(self._object_points, corners, self._k)

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        corners, reason = target_corners(frame, self.tag_id)
        if corners is None:
            return DeckPoseEstimate.invalid(self.name, timestamp, reason)
        if corners_degenerate(corners, self.config.min_corner_area_px):
            return DeckPoseEstimate.invalid(self.name, timestamp, DEGENERATE_CORNERS)
        if self._undistorter.active:
            corners = self._undistorter(corners)
            if not np.all(np.isfinite(corners)):
                return DeckPoseEstimate.invalid(self.name, timestamp, BAD_CORNERS)
        solver, solutions = self._solutions(corners)
        if not solutions:
            return DeckPoseEstimate.invalid(self.name, timestamp, PNP_FAILED)
        chosen = solutions[0]
        ratio = math.nan  # unknown with a single solution
        by_history = False
        if len(solutions) > 1:
            second = solutions[1][0]
            ratio = 1.0 if second <= 0.0 else chosen[0] / second
            rotation = _deciding_rotation(self.config, self._previous, ratio, timestamp)
            if rotation is not None:
                # trace(R_prevᵀ R) grows as the angle between the rotations shrinks
                closest = max(solutions[:2], key=lambda s: float(np.sum(rotation * s[1])))
                by_history = closest is not chosen
                chosen = closest
        if not chosen[0] <= self.config.max_reprojection_error_px:
            return DeckPoseEstimate.invalid(self.name, timestamp, REPROJECTION_ERROR)
        extras = {
            "ambiguity_ratio": ratio,
            "reprojection_error_px": chosen[0],
            "chosen_by_history": by_history,
            "solver": solver,
        }
        estimate = finish_pose(self.name, timestamp, chosen[1], chosen[2], extras)
        if estimate.valid:
            self._previous = (timestamp, chosen[1])
        return estimate


class JointAtdaEstimator(GuardedEstimator):
    """ATDA over nested landmarks: one PnP over the corners of every detected tag.

    With two or more tags of the layout detected (each side >= ``min_side_px``), their
    corners in D (:meth:`Landmark.corners_d`) and pixels go into one planar PnP (IPPE, then
    Levenberg–Marquardt refinement), which gives ``T_CD`` directly; the points spread over
    the whole layout, so the pose is better conditioned than from any one tag (measured in
    render mode on the high-approach deck: 21 mm against 68 mm at 10 m, 8 against 13 mm at
    5 m, 3.9 against 6.1 mm at 2 m).  With fewer tags, ``single`` (the per-landmark ATDA of
    :class:`~estimation.landmarks.LandmarkEstimator`) estimates instead.
    """

    name = "atda"

    def __init__(
        self,
        *,
        intrinsics: CameraIntrinsics,
        layout: LandmarkLayout,
        single: DeckPoseEstimator,
        min_side_px: float = 12.0,
        config: ATDAConfig | None = None,
    ) -> None:
        self.intrinsics = intrinsics
        self.layout = layout
        self.single = single
        self.min_side_px = float(min_side_px)
        self.config = config or ATDAConfig()
        self._k = intrinsics.matrix
        self._no_dist = np.zeros(5)
        self._undistorter = geometry.Undistorter(intrinsics)
        self._previous: tuple[float, np.ndarray] | None = None

    def reset(self) -> None:
        self.single.reset()
        self._previous = None

    def _pick(self, timestamp: float, solutions: list) -> tuple[int, float, bool]:
        """Index of the IPPE solution to refine, the ambiguity ratio and whether the previous
        estimate decided (the rule of :class:`AtdaEstimator`)."""
        order = sorted(range(len(solutions)), key=lambda i: solutions[i][0])
        if len(order) < 2:
            return order[0], math.nan, False
        best, second = solutions[order[0]], solutions[order[1]]
        ratio = 1.0 if second[0] <= 0.0 else best[0] / second[0]
        rotation = _deciding_rotation(self.config, self._previous, ratio, timestamp)
        if rotation is not None:
            closest = max(order[:2], key=lambda i: float(np.sum(rotation * solutions[i][1])))
            return closest, ratio, closest != order[0]
        return order[0], ratio, False

    def _joint_inputs(self, frame: CameraFrame) -> tuple[list[int], np.ndarray, np.ndarray]:
        """Ids, object points in D (N x 3) and pixels (N x 2) of the usable detections."""
        ids: list[int] = []
        objects, pixels = [], []
        for detection in frame.detections:
            landmark = self.layout.by_id(detection.tag_id)
            if landmark is None or landmark.tag_id in ids:
                continue
            corners = np.asarray(detection.corners_px, dtype=float)
            if corners.shape != (4, 2) or not np.all(np.isfinite(corners)):
                continue
            if corners_degenerate(corners, self.config.min_corner_area_px):
                continue
            if not shortest_side_px(corners) >= self.min_side_px:
                continue
            ids.append(landmark.tag_id)
            objects.append(landmark.corners_d())
            pixels.append(corners)
        if len(ids) < 2:
            return ids, np.empty((0, 3)), np.empty((0, 2))
        return ids, np.vstack(objects), np.vstack(pixels)

    def _estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        timestamp = float(frame.timestamp)
        ids, objects, pixels = self._joint_inputs(frame)
        if len(ids) < 2:
            return self.single.estimate(frame, ranges)
        if self._undistorter.active:
            pixels = self._undistorter(pixels)
            if not np.all(np.isfinite(pixels)):
                return DeckPoseEstimate.invalid(self.name, timestamp, BAD_CORNERS)
        # as in AtdaEstimator._solutions: solve with the layout turned by half a turn when
        # D's x axis points left in the image (OpenCV's rotation vectors lose precision
        # near 180 degrees), and turn the result back
        first = pixels[:4]
        half_turn = bool(first[1, 0] + first[2, 0] - first[0, 0] - first[3, 0] < 0.0)
        flip = np.array([-1.0, -1.0, 1.0])
        points = objects * flip if half_turn else objects
        image = pixels.reshape(-1, 1, 2)
        # IPPE's two poses; on some exactly symmetric views (face-on, D's origin on the
        # optical axis) it gives no finite pose, and SQPNP's one globally optimal pose is
        # the last resort, as for a single tag
        for solver, flag in (
            ("joint_ippe", cv2.SOLVEPNP_IPPE),
            ("joint_sqpnp", cv2.SOLVEPNP_SQPNP),
        ):
            count, rvecs, tvecs, errors = cv2.solvePnPGeneric(
                points, image, self._k, self._no_dist, flags=flag
            )
            errors = np.asarray(errors, dtype=float).reshape(-1)
            # (error, R_CD, rvec, tvec) of the finite solutions in front of the camera
            solutions = []
            for k in range(int(count)):
                rvec = np.asarray(rvecs[k], dtype=float)
                tvec = np.asarray(tvecs[k], dtype=float)
                finite = np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))
                if finite and np.isfinite(errors[k]) and tvec.reshape(3)[2] > 0.0:
                    rotation, _ = cv2.Rodrigues(rvec)
                    solutions.append(
                        (errors[k], rotation * flip if half_turn else rotation, rvec, tvec)
                    )
            if solutions:
                used_solver = solver
                break
        else:
            return DeckPoseEstimate.invalid(self.name, timestamp, PNP_FAILED)
        chosen, ratio, by_history = self._pick(timestamp, solutions)
        rvec, tvec = cv2.solvePnPRefineLM(
            points, image, self._k, self._no_dist, solutions[chosen][2], solutions[chosen][3]
        )
        rotation, _ = cv2.Rodrigues(rvec)
        translation = np.asarray(tvec, dtype=float).reshape(3)
        projected, _ = cv2.projectPoints(points, rvec, tvec, self._k, self._no_dist)
        rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - pixels) ** 2, axis=1))))
        if not rms <= self.config.max_reprojection_error_px:
            return DeckPoseEstimate.invalid(self.name, timestamp, REPROJECTION_ERROR)
        if half_turn:
            rotation = rotation * flip  # R_CD = R' Rz(180°): negate the first two columns
        # reported as the landmark: the largest in the image (the single-tag rule's pick)
        sides = [shortest_side_px(pixels[4 * i : 4 * i + 4]) for i in range(len(ids))]
        largest = int(np.argmax(sides))
        extras = {
            "ambiguity_ratio": ratio,
            "reprojection_error_px": rms,
            "chosen_by_history": by_history,
            "solver": used_solver,
            "landmark_id": ids[largest],
            "landmark_ids": tuple(ids),
            "landmark_side_px": sides[largest],
        }
        estimate = finish_pose(self.name, timestamp, rotation, translation, extras)
        if estimate.valid:
            self._previous = (timestamp, rotation)
        return estimate
