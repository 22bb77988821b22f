"""ATDA, the AprilTag-only baseline: the choice between IPPE's two poses, the reprojection
check, the AprilTag library's homography pose and the joint PnP over nested landmarks."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimation.atda import (
    ATDAConfig,
    AtdaEstimator,
    JointAtdaEstimator,
    _deciding_rotation,
    homography_pose,
)
from estimation.camera_model import CameraIntrinsics
from estimation.errors import ConfigError
from estimation.frames import matrix_from_euler_zyx, tag_corners_in_tag_frame
from estimation.landmarks import Landmark, LandmarkLayout, shortest_side_px
from estimation.synthetic import SyntheticScene
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading, TagDetection

CAMERA = CameraIntrinsics(width=640, height=480, fx=610.0, fy=540.0, cx=331.0, cy=229.0)
TAG = 0.12
NO_RANGES = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, dtype=bool))
#: three nested tags (ids 0-2) of the high-approach deck's sizes
LAYOUT = LandmarkLayout(
    (Landmark(0, 0.12, 0.0, 0.0), Landmark(1, 0.4, 0.345, 0.0), Landmark(2, 1.1, -0.78, 0.0))
)


def _rms_px(rotation: np.ndarray, translation: np.ndarray, objects, pixels) -> float:
    """RMS over the points of the pixel distance between projection and measurement."""
    projected = CAMERA.project(objects @ rotation.T + translation)
    return float(np.sqrt(np.mean(np.sum((projected - pixels) ** 2, axis=1))))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(Rotation.from_matrix(a @ b.T).magnitude())


# ------------------------------------------------------------------ the previous estimate
@settings(max_examples=100, deadline=None)
@given(
    threshold=st.floats(0.01, 1.0),
    ratio=st.floats(0.0, 1.0),
    age_s=st.floats(-1.0, 1.0),
    timeout_s=st.floats(0.0, 0.9),
)
@example(threshold=0.6, ratio=0.6, age_s=0.5, timeout_s=0.5)  # both bounds are inclusive
@example(threshold=0.6, ratio=0.6, age_s=0.0, timeout_s=0.5)  # the same instant counts
@example(threshold=0.6, ratio=0.5999, age_s=0.1, timeout_s=0.5)
@example(threshold=0.6, ratio=0.9, age_s=-1e-9, timeout_s=0.5)  # from the future: not used
@example(threshold=0.6, ratio=0.9, age_s=0.5001, timeout_s=0.5)
def test_the_previous_estimate_decides_from_the_threshold_up_while_it_is_recent(
    threshold: float, ratio: float, age_s: float, timeout_s: float
) -> None:
    config = ATDAConfig(ambiguity_ratio_threshold=threshold, history_timeout_s=timeout_s)
    previous = (10.0, np.diag([1.0, -1.0, -1.0]))
    timestamp = 10.0 + age_s
    rotation = _deciding_rotation(config, previous, ratio, timestamp)
    decides = ratio >= threshold and 0.0 <= timestamp - 10.0 <= timeout_s
    assert (rotation is previous[1]) if decides else rotation is None
    assert _deciding_rotation(config, None, ratio, timestamp) is None


# ---------------------------------------------------------------------- single-tag ATDA
def test_the_estimate_reports_ippes_ambiguity_ratio_its_solver_and_no_history_choice() -> None:
    """The ratio is the best solution's reprojection error over the second's (Sec. IPPE:
    near 0 when the image tells the two poses apart)."""
    rotation = Rotation.from_euler("xyz", [0.2, -0.1, 0.7]).as_matrix()
    translation = np.array([0.1, -0.05, 1.2])
    rng = np.random.default_rng(1)
    m = SyntheticScene(CAMERA, TAG).measure(
        rotation, translation, timestamp=4.0, pixel_noise_px=0.5, rng=rng
    )
    corners = m.frame.detections[0].corners_px
    _, rvecs, _, errors = cv2.solvePnPGeneric(
        tag_corners_in_tag_frame(TAG),
        corners.reshape(4, 1, 2),
        CAMERA.matrix,
        np.zeros(5),
        flags=cv2.SOLVEPNP_IPPE_SQUARE,
    )
    errors = np.asarray(errors, dtype=float).ravel()
    best, second = sorted(errors)
    kept = cv2.Rodrigues(rvecs[int(np.argmin(errors))])[0]
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0).estimate(m.frame, None)
    assert estimate.valid and (estimate.method, estimate.timestamp) == ("atda", 4.0)
    assert estimate.extras["ambiguity_ratio"] == pytest.approx(best / second, rel=1e-9)
    assert estimate.extras["reprojection_error_px"] == pytest.approx(best, rel=1e-9)
    assert estimate.extras["chosen_by_history"] is False
    assert estimate.extras["solver"] == "ippe_square"
    # the better-fitting of the two poses is kept
    assert _angle_deg(estimate.rotation, kept) < 1e-9


def test_corners_no_square_can_project_to_are_refused_by_their_reprojection_error() -> None:
    """A kite is no view of a square: its best pose leaves pixels of error, refused above
    ``max_reprojection_error_px`` and taken at it."""
    kite = np.array([[200.0, 300.0], [300.0, 300.0], [330.0, 200.0], [180.0, 150.0]])
    frame = CameraFrame(1.5, (TagDetection(0, kite),))
    refused = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0).estimate(frame, None)
    assert (refused.valid, refused.method, refused.timestamp) == (False, "atda", 1.5)
    assert refused.reason == "reprojection_error"
    lenient = AtdaEstimator(
        intrinsics=CAMERA, tag_size=TAG, tag_id=0, config=ATDAConfig(max_reprojection_error_px=1e4)
    ).estimate(frame, None)
    assert lenient.valid
    error = lenient.extras["reprojection_error_px"]
    assert error > 10.0
    at_bound = AtdaEstimator(
        intrinsics=CAMERA,
        tag_size=TAG,
        tag_id=0,
        config=ATDAConfig(max_reprojection_error_px=error),
    ).estimate(frame, None)
    assert at_bound.valid and at_bound.extras["reprojection_error_px"] == error


def test_a_tag_below_the_minimum_corner_area_is_degenerate() -> None:
    square = np.array([[100.0, 104.0], [104.0, 104.0], [104.0, 100.0], [100.0, 100.0]])  # 16 px²
    frame = CameraFrame(0.0, (TagDetection(0, square),))
    small = ATDAConfig(min_corner_area_px=16.5)
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0, config=small).estimate(
        frame, None
    )
    assert not estimate.valid and estimate.reason == "degenerate_corners"
    taken = ATDAConfig(min_corner_area_px=15.5)
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0, config=taken).estimate(
        frame, None
    )
    assert estimate.reason != "degenerate_corners"


def test_another_tags_detection_is_no_detection_of_the_estimators_tag() -> None:
    m = SyntheticScene(CAMERA, TAG, tag_id=3).measure(np.eye(3), np.array([0.0, 0.0, 1.0]))
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=4).estimate(m.frame, None)
    assert not estimate.valid and estimate.reason == "no_detection"
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=3).estimate(m.frame, None)
    assert estimate.valid


def test_bad_atda_settings_are_refused_naming_the_key() -> None:
    for key, value in (
        ("ambiguity_ratio_threshold", 0.0),
        ("history_timeout_s", -0.1),
        ("max_reprojection_error_px", 0.0),
        ("min_corner_area_px", -1.0),
    ):
        with pytest.raises(ConfigError, match=key):
            ATDAConfig(**{key: value})
    with pytest.raises(ConfigError, match="pose_method: 'readAprilTag' is not allowed"):
        ATDAConfig(pose_method="readAprilTag")
    with pytest.raises(ConfigError, match="tag_size"):
        AtdaEstimator(intrinsics=CAMERA, tag_size=-0.1, tag_id=0)


# ----------------------------------------------------------------- the homography pose
@settings(max_examples=60, deadline=None)
@given(
    tilt_deg=st.floats(0.0, 45.0),
    tilt_dir=st.floats(-math.pi, math.pi),
    yaw=st.floats(-math.pi, math.pi),
    height=st.floats(0.4, 4.0),
    fx=st.floats(-0.5, 0.5),
    fy=st.floats(-0.5, 0.5),
)
def test_the_homography_pose_is_exact_from_any_side_and_reports_its_rms_pixel_error(
    tilt_deg: float, tilt_dir: float, yaw: float, height: float, fx: float, fy: float
) -> None:
    """Olson 2011: the pose from ``K⁻¹ H`` alone; on exact corners it is the true pose, at
    any tilt and yaw (the first two columns scaled by the geometric mean of their norms)."""
    axis = np.array([math.cos(tilt_dir), math.sin(tilt_dir), 0.0])
    rotation = (
        Rotation.from_rotvec(math.radians(tilt_deg) * axis) * Rotation.from_euler("z", yaw)
    ).as_matrix()
    translation = np.array([fx * height * 0.4, fy * height * 0.3, height])
    corners = CAMERA.project(tag_corners_in_tag_frame(TAG) @ rotation.T + translation)
    (rms, r, t), *rest = homography_pose(tag_corners_in_tag_frame(TAG), corners, CAMERA.matrix)
    assert rest == []
    assert _angle_deg(r, rotation) < 1e-6 and np.allclose(t, translation, atol=1e-8)
    assert np.allclose(r.T @ r, np.eye(3), atol=1e-12) and np.linalg.det(r) > 0.0
    assert rms < 1e-6


def test_the_homography_poses_error_is_the_rms_distance_of_its_reprojected_corners() -> None:
    rng = np.random.default_rng(7)
    rotation = matrix_from_euler_zyx(0.15, -0.1, 0.4)
    translation = np.array([0.05, 0.02, 1.1])
    objects = tag_corners_in_tag_frame(TAG)
    corners = CAMERA.project(objects @ rotation.T + translation) + rng.normal(0.0, 1.0, (4, 2))
    ((rms, r, t),) = homography_pose(objects, corners, CAMERA.matrix)
    assert rms == pytest.approx(_rms_px(r, t, objects, corners), rel=1e-9)
    assert rms > 0.1
    estimate = AtdaEstimator(
        intrinsics=CAMERA, tag_size=TAG, tag_id=0, config=ATDAConfig(pose_method="homography")
    ).estimate(CameraFrame(0.0, (TagDetection(0, corners),)), None)
    assert estimate.valid and estimate.extras["solver"] == "homography"
    assert estimate.extras["reprojection_error_px"] == rms
    assert math.isnan(estimate.extras["ambiguity_ratio"])  # one pose: nothing to choose
    assert np.allclose(estimate.rotation, r) and np.allclose(estimate.translation, t)


def test_the_homography_pose_on_noisy_corners_is_olsons_decomposition_of_k_inverse_h() -> None:
    """Olson 2011 (the AprilTag library's homography pose): with ``M = K⁻¹ H``, the scale
    is the geometric mean of the norms of M's first two columns, ``t = m3 / s`` and R the
    rotation nearest ``[m1/s, m2/s, m1/s x m2/s]``; on noisy corners the two columns are
    neither orthogonal nor of one length, so each step shows."""
    rng = np.random.default_rng(11)
    rotation = matrix_from_euler_zyx(0.3, -0.25, 2.0)
    translation = np.array([-0.08, 0.06, 0.9])
    objects = tag_corners_in_tag_frame(TAG)
    corners = CAMERA.project(objects @ rotation.T + translation) + rng.normal(0.0, 2.0, (4, 2))
    h = cv2.getPerspectiveTransform(
        objects[:, :2].astype(np.float32), corners.astype(np.float32)
    ).astype(float)
    m = np.linalg.solve(CAMERA.matrix, h / h[2, 2])
    n1, n2 = np.linalg.norm(m[:, 0]), np.linalg.norm(m[:, 1])
    assert abs(n1 / n2 - 1.0) > 1e-3  # the noise makes the columns' lengths differ
    scale = math.sqrt(n1 * n2)
    r1, r2 = m[:, 0] / scale, m[:, 1] / scale
    u, _, vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    ((_, r, t),) = homography_pose(objects, corners, CAMERA.matrix)
    assert np.allclose(t, m[:, 2] / scale, rtol=1e-4, atol=0.0)
    assert _angle_deg(r, u @ vt) < 1e-3


# ------------------------------------------------------------------------- joint ATDA
class _Single:
    """A stand-in for the per-landmark ATDA: counts its calls and resets."""

    name = "atda"

    def __init__(self) -> None:
        self.calls = 0
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        self.calls += 1
        return DeckPoseEstimate.invalid("atda", frame.timestamp, "single")


def _detections(r_cd: np.ndarray, t_cd: np.ndarray) -> list[TagDetection]:
    return [
        TagDetection(lm.tag_id, CAMERA.project(lm.corners_d() @ r_cd.T + t_cd))
        for lm in LAYOUT.landmarks
    ]


R_CD = matrix_from_euler_zyx(math.radians(3.0), math.radians(-2.0), math.radians(40.0))
T_CD = np.array([0.1, -0.1, 3.0])


def test_joint_atda_skips_detections_it_cannot_use_and_reports_the_largest_tag() -> None:
    """Unknown ids, a second detection of a tag, corners that are not four finite pixels,
    a degenerate quadrilateral and a tag under ``min_side_px`` are left out of the PnP."""
    good = _detections(R_CD, T_CD)
    small_side = shortest_side_px(good[0].corners_px)
    junk = [
        TagDetection(9, good[1].corners_px + 40.0),  # not in the layout
        TagDetection(2, good[2].corners_px + 60.0),  # tag 2 again
    ]
    frame = CameraFrame(2.5, (*good, *junk))
    single = _Single()
    joint = JointAtdaEstimator(
        intrinsics=CAMERA, layout=LAYOUT, single=single, min_side_px=small_side
    )
    estimate = joint.estimate(frame, NO_RANGES)
    assert estimate.valid and single.calls == 0
    assert (estimate.method, estimate.timestamp) == ("atda", 2.5)
    assert estimate.extras["landmark_ids"] == (0, 1, 2)
    assert estimate.extras["landmark_id"] == 2
    assert estimate.extras["landmark_side_px"] == pytest.approx(
        shortest_side_px(good[2].corners_px)
    )
    assert estimate.extras["solver"] == "joint_ippe"
    assert estimate.extras["reprojection_error_px"] < 1e-6
    assert estimate.extras["chosen_by_history"] is False
    # the ratio of IPPE's two reprojection errors over every corner of the three tags
    objects = np.vstack([lm.corners_d() for lm in LAYOUT.landmarks])
    pixels = np.vstack([d.corners_px for d in good])
    _, _, _, errors = cv2.solvePnPGeneric(
        objects, pixels.reshape(-1, 1, 2), CAMERA.matrix, np.zeros(5), flags=cv2.SOLVEPNP_IPPE
    )
    best, second = sorted(np.asarray(errors, dtype=float).ravel())
    assert estimate.extras["ambiguity_ratio"] == pytest.approx(best / second, rel=1e-6, abs=1e-12)
    assert np.allclose(estimate.rotation, R_CD, atol=1e-8)
    assert np.allclose(estimate.translation, T_CD, atol=1e-8)
    # the smallest tag just under min_side_px is left out
    joint.min_side_px = small_side * 1.001
    assert joint.estimate(frame, NO_RANGES).extras["landmark_ids"] == (1, 2)


def test_joint_atda_needs_two_usable_tags_else_the_single_tag_atda_answers() -> None:
    good = _detections(R_CD, T_CD)
    collinear = np.array([[10.0, 10.0], [20.0, 20.0], [30.0, 30.0], [40.0, 40.0]])
    single = _Single()
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=single)
    frame = CameraFrame(
        1.0, (good[2], TagDetection(1, collinear), TagDetection(0, good[0].corners_px[:3]))
    )
    assert joint.estimate(frame, NO_RANGES).reason == "single" and single.calls == 1
    joint.reset()
    assert single.resets == 1


def test_joint_atda_refuses_tags_that_disagree_by_their_reprojection_error() -> None:
    """Tag 1's corners seen 30 px off where the deck pose puts them: no pose fits all."""
    good = _detections(R_CD, T_CD)
    moved = TagDetection(1, good[1].corners_px + np.array([30.0, 0.0]))
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single())
    estimate = joint.estimate(CameraFrame(0.0, (good[0], moved, good[2])), NO_RANGES)
    assert not estimate.valid and estimate.reason == "reprojection_error"
    lenient = JointAtdaEstimator(
        intrinsics=CAMERA,
        layout=LAYOUT,
        single=_Single(),
        config=ATDAConfig(max_reprojection_error_px=1e3),
    )
    estimate = lenient.estimate(CameraFrame(0.0, (good[0], moved, good[2])), NO_RANGES)
    assert estimate.valid
    objects = np.vstack([lm.corners_d() for lm in LAYOUT.landmarks])
    pixels = np.vstack([good[0].corners_px, moved.corners_px, good[2].corners_px])
    assert estimate.extras["reprojection_error_px"] == pytest.approx(
        _rms_px(estimate.rotation, estimate.translation, objects, pixels), rel=1e-6
    )
    assert estimate.extras["reprojection_error_px"] > 10.0


@pytest.mark.parametrize("yaw_deg", [0.0, 100.0, 179.0, -135.0])
def test_joint_atda_is_exact_at_any_yaw_and_after_a_reset(yaw_deg: float) -> None:
    r_cd = matrix_from_euler_zyx(math.radians(-4.0), math.radians(5.0), math.radians(yaw_deg))
    frame = CameraFrame(0.0, tuple(_detections(r_cd, T_CD)))
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single())
    for _ in range(2):
        estimate = joint.estimate(frame, NO_RANGES)
        assert estimate.valid
        assert _angle_deg(estimate.rotation, r_cd) < 1e-6
        assert np.allclose(estimate.translation, T_CD, atol=1e-8)
        joint.reset()
