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
    ippe_solutions,
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
    # the RMS corner distance of the kept pose (OpenCV's error is the RMS over coordinates)
    assert estimate.extras["reprojection_error_px"] == pytest.approx(
        _rms_px(estimate.rotation, estimate.translation, tag_corners_in_tag_frame(TAG), corners),
        rel=1e-6,
    )
    assert estimate.extras["reprojection_error_px"] == pytest.approx(math.sqrt(2) * best, rel=1e-9)
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
    for size_m in (-0.1, 0.0):
        with pytest.raises(ConfigError, match=r"^tag_size: "):
            AtdaEstimator(intrinsics=CAMERA, tag_size=size_m, tag_id=0)


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
        self.ranges: RangeReading | None = None

    def reset(self) -> None:
        self.resets += 1

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        self.calls += 1
        self.ranges = ranges
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
    assert single.ranges is NO_RANGES
    joint.reset()
    assert single.resets == 1


def test_joint_atda_refuses_tags_that_disagree_by_their_reprojection_error() -> None:
    """Tag 1's corners seen 30 px off where the deck pose puts them: no pose fits all."""
    good = _detections(R_CD, T_CD)
    moved = TagDetection(1, good[1].corners_px + np.array([30.0, 0.0]))
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single())
    estimate = joint.estimate(CameraFrame(3.5, (good[0], moved, good[2])), NO_RANGES)
    assert not estimate.valid and estimate.reason == "reprojection_error"
    assert (estimate.method, estimate.timestamp) == ("atda", 3.5)
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
    error = estimate.extras["reprojection_error_px"]
    assert error > 10.0
    at_bound = JointAtdaEstimator(
        intrinsics=CAMERA,
        layout=LAYOUT,
        single=_Single(),
        config=ATDAConfig(max_reprojection_error_px=error),
    ).estimate(CameraFrame(0.0, (good[0], moved, good[2])), NO_RANGES)
    assert at_bound.valid and at_bound.extras["reprojection_error_px"] == error


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


def _ambiguous_view(
    yaw_deg: float = 30.0,
) -> tuple[CameraFrame, np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Tags 0 and 1 (12 and 40 cm) nearly face-on at 6 m, with 0.5 px of corner noise: the
    perspective is too weak for IPPE's two poses to differ much in reprojection error, and
    the two are over 20 degrees apart.  Returns the frame (at 1.1 s), its object points and
    IPPE's two poses over its eight corners, the better first."""
    landmarks = LAYOUT.landmarks[:2]
    objects = np.vstack([lm.corners_d() for lm in landmarks])
    rotation = matrix_from_euler_zyx(math.radians(2.0), math.radians(-3.0), math.radians(yaw_deg))
    pixels = CAMERA.project(objects @ rotation.T + np.array([0.05, -0.05, 6.0]))
    pixels = pixels + np.random.default_rng(3).normal(0.0, 0.5, pixels.shape)
    frame = CameraFrame(
        1.1,
        tuple(TagDetection(lm.tag_id, pixels[4 * i : 4 * i + 4]) for i, lm in enumerate(landmarks)),
    )
    _, rvecs, tvecs, errors = cv2.solvePnPGeneric(
        objects, pixels.reshape(-1, 1, 2), CAMERA.matrix, np.zeros(5), flags=cv2.SOLVEPNP_IPPE
    )
    order = np.argsort(np.asarray(errors, dtype=float).ravel())
    poses = [(cv2.Rodrigues(rvecs[i])[0], np.asarray(tvecs[i], dtype=float).ravel()) for i in order]
    return frame, objects, poses


def _exact_view(timestamp: float, objects: np.ndarray, r_cd: np.ndarray, t_cd: np.ndarray):
    pixels = CAMERA.project(objects @ r_cd.T + t_cd)
    return CameraFrame(
        timestamp, tuple(TagDetection(i, pixels[4 * i : 4 * i + 4]) for i in range(2))
    )


# D's x axis to the right, to the left; at 145 degrees the pose farther from the previous
# one has entries near zero where the previous one's are not (a ratio of them would pick it)
@pytest.mark.parametrize("yaw_deg", [30.0, 145.0, 210.0])
@pytest.mark.parametrize("history", ["none", "better", "worse", "worse, then a reset"])
def test_on_an_ambiguous_view_of_two_tags_the_joint_estimate_follows_the_previous_one(
    history: str, yaw_deg: float
) -> None:
    """With IPPE's two joint poses comparable (ratio >= 0.6), the previous estimate decides:
    the pose refined is the one nearer it, even the worse-fitting one (flagged as chosen by
    history); without a previous estimate, or after a reset, the better-fitting one."""
    frame, objects, poses = _ambiguous_view(yaw_deg)
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single(), min_side_px=1.0)
    if history != "none":
        # an exact view of the layout at that pose, 0.1 s earlier: unambiguous (ratio ~0)
        pose = poses[0 if history == "better" else 1]
        before = joint.estimate(_exact_view(1.0, objects, *pose), NO_RANGES)
        assert before.valid and before.extras["ambiguity_ratio"] < 1e-6
        assert _angle_deg(before.rotation, pose[0]) < 1e-6
    if history.endswith("reset"):
        joint.reset()
    estimate = joint.estimate(frame, NO_RANGES)
    assert estimate.valid and estimate.extras["landmark_ids"] == (0, 1)
    ratio = estimate.extras["ambiguity_ratio"]
    assert isinstance(ratio, float) and ratio >= 0.6
    followed = 1 if history == "worse" else 0
    other = 1 - followed
    assert _angle_deg(poses[0][0], poses[1][0]) > 20.0
    assert _angle_deg(estimate.rotation, poses[followed][0]) < 3.0
    assert _angle_deg(estimate.rotation, poses[other][0]) > 15.0
    assert estimate.extras["chosen_by_history"] is (followed == 1)


def test_a_previous_joint_estimate_older_than_the_timeout_does_not_decide() -> None:
    frame, objects, poses = _ambiguous_view()
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single(), min_side_px=1.0)
    assert joint.estimate(_exact_view(0.5, objects, *poses[1]), NO_RANGES).valid
    estimate = joint.estimate(frame, NO_RANGES)  # 0.6 s later, past the 0.5 s timeout
    assert _angle_deg(estimate.rotation, poses[0][0]) < 3.0
    assert estimate.extras["chosen_by_history"] is False


def test_a_single_joint_ippe_pose_is_refined_with_no_ratio_and_no_history_choice(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Where IPPE returns one pose for the joint points (OpenCV's fallbacks), that pose is
    refined, the ratio is NaN and the previous estimate has nothing to decide."""
    frame, objects, poses = _ambiguous_view()
    solve = cv2.solvePnPGeneric

    def first_only(*args, **kwargs):
        _, rvecs, tvecs, errors = solve(*args, **kwargs)
        order = np.argsort(np.asarray(errors, dtype=float).ravel())
        return 1, rvecs[order[1]][None], tvecs[order[1]][None], errors[order[1]][None]

    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single(), min_side_px=1.0)
    assert joint.estimate(_exact_view(1.0, objects, *poses[0]), NO_RANGES).valid
    monkeypatch.setattr(cv2, "solvePnPGeneric", first_only)
    estimate = joint.estimate(frame, NO_RANGES)
    assert estimate.valid and math.isnan(estimate.extras["ambiguity_ratio"])
    assert estimate.extras["chosen_by_history"] is False
    # the one pose given (the worse-fitting of the two) is the one refined
    assert _angle_deg(estimate.rotation, poses[1][0]) < 3.0


@pytest.mark.parametrize("yaw_deg", [0.0, 180.0, -180.0])
def test_joint_atda_is_exact_face_on_with_the_deck_upright_or_turned_half_a_turn(
    yaw_deg: float,
) -> None:
    """OpenCV's rotation vectors lose precision near 180 degrees (a wrong pose at exactly
    180): the layout is solved turned by half a turn exactly when D's x axis points left in
    the image, so both face-on views, at yaw 0 and 180, come out exact."""
    r_cd = matrix_from_euler_zyx(0.0, 0.0, math.radians(yaw_deg))
    frame = CameraFrame(0.0, tuple(_detections(r_cd, T_CD)))
    estimate = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single()).estimate(
        frame, NO_RANGES
    )
    assert estimate.valid
    assert _angle_deg(estimate.rotation, r_cd) < 1e-9
    assert np.allclose(estimate.translation, T_CD, rtol=0.0, atol=1e-12)


def test_joint_atda_is_exact_from_under_a_metre() -> None:
    """Tags 0 and 1 from 0.8 m: every solution in front of the camera is kept, however near."""
    landmarks = LAYOUT.landmarks[:2]
    t_cd = np.array([-0.15, 0.0, 0.8])
    frame = CameraFrame(
        0.0,
        tuple(
            TagDetection(lm.tag_id, CAMERA.project(lm.corners_d() @ R_CD.T + t_cd))
            for lm in landmarks
        ),
    )
    estimate = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single()).estimate(
        frame, NO_RANGES
    )
    assert estimate.valid and estimate.extras["landmark_ids"] == (0, 1)
    assert _angle_deg(estimate.rotation, R_CD) < 1e-6
    assert np.allclose(estimate.translation, t_cd, atol=1e-8)


@pytest.mark.parametrize("distance_m", [3.0, 5.0])
def test_joint_atda_is_exact_face_on_over_the_decks_origin_at_every_yaw(distance_m: float) -> None:
    """Face-on with D's origin on the optical axis OpenCV's IPPE gives no finite pose at some
    yaws (3 m: 15, 45, 120, 165, 195, 225, 255 and 345 deg; 5 m: 75 deg); SQPNP's pose
    answers there, named as the solver, and every yaw comes out exact."""
    solvers = set()
    for yaw_deg in range(0, 360, 15):
        r_cd = matrix_from_euler_zyx(0.0, 0.0, math.radians(yaw_deg))
        t_cd = np.array([0.0, 0.0, distance_m])
        frame = CameraFrame(0.0, tuple(_detections(r_cd, t_cd)))
        estimate = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single()).estimate(
            frame, NO_RANGES
        )
        assert estimate.valid, (yaw_deg, estimate.reason)
        assert _angle_deg(estimate.rotation, r_cd) < 1e-6
        assert np.allclose(estimate.translation, t_cd, rtol=0.0, atol=1e-9)
        solvers.add(estimate.extras["solver"])
    assert solvers == {"joint_ippe", "joint_sqpnp"}


DISTORTED = CameraIntrinsics(
    width=640,
    height=480,
    fx=610.0,
    fy=540.0,
    cx=331.0,
    cy=229.0,
    dist=(-0.25, 0.08, 0.001, -0.001, 0.0),
)


def test_joint_atda_removes_the_lens_distortion_before_solving() -> None:
    frame = CameraFrame(
        0.0,
        tuple(
            TagDetection(lm.tag_id, DISTORTED.project(lm.corners_d() @ R_CD.T + T_CD))
            for lm in LAYOUT.landmarks
        ),
    )
    estimate = JointAtdaEstimator(intrinsics=DISTORTED, layout=LAYOUT, single=_Single()).estimate(
        frame, NO_RANGES
    )
    assert estimate.valid and estimate.extras["reprojection_error_px"] < 1e-6
    assert _angle_deg(estimate.rotation, R_CD) < 1e-6
    assert np.allclose(estimate.translation, T_CD, atol=1e-7)


@pytest.mark.parametrize("joint", [False, True])
def test_pixels_the_undistortion_leaves_not_finite_are_refused_as_bad_corners(
    joint: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stand-in for OpenCV's undistortion that gives NaN (OpenCV itself hands back a
    pixel it cannot undistort as it was)."""
    frame = CameraFrame(
        2.5,
        tuple(
            TagDetection(lm.tag_id, DISTORTED.project(lm.corners_d() @ R_CD.T + T_CD))
            for lm in LAYOUT.landmarks
        ),
    )
    monkeypatch.setattr(
        cv2, "undistortPoints", lambda pixels, *args, **kwargs: np.full(pixels.shape, np.nan)
    )
    if joint:
        estimator = JointAtdaEstimator(intrinsics=DISTORTED, layout=LAYOUT, single=_Single())
    else:
        estimator = AtdaEstimator(intrinsics=DISTORTED, tag_size=0.12, tag_id=0)
    estimate = estimator.estimate(frame, NO_RANGES)
    assert (estimate.valid, estimate.method, estimate.timestamp) == (False, "atda", 2.5)
    assert estimate.reason == "bad_corners"


@pytest.mark.parametrize("joint", [False, True])
@pytest.mark.parametrize(
    "corrupt",
    [
        "rotation not finite",
        "translation not finite",
        "error not finite",
        "behind",
        "at the camera",
    ],
)
def test_ippe_poses_not_finite_or_not_in_front_of_the_camera_are_dropped(
    corrupt: str, joint: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stand-in for OpenCV's PnP that spoils the better of its poses: the other one is
    taken (the joint ATDA refines it into the true pose); with every pose spoilt the estimate
    is invalid (``pnp_failed``)."""
    solve = cv2.solvePnPGeneric
    spoilt = 1

    def spoiling(*args, **kwargs):
        count, rvecs, tvecs, errors = solve(*args, **kwargs)
        rvecs, tvecs = [r.copy() for r in rvecs], [t.copy() for t in tvecs]
        errors = np.asarray(errors, dtype=float).copy()
        for i in np.argsort(errors.ravel())[:spoilt]:
            if corrupt == "rotation not finite":
                rvecs[i][0] = np.nan
            elif corrupt == "translation not finite":
                tvecs[i][0] = np.inf
            elif corrupt == "error not finite":
                errors[i] = np.nan
            else:
                depth_m = -3.0 if corrupt == "behind" else 0.0
                tvecs[i] = np.array([0.1, 0.2, depth_m]).reshape(tvecs[i].shape)
        return count, tuple(rvecs), tuple(tvecs), errors

    monkeypatch.setattr(cv2, "solvePnPGeneric", spoiling)
    frame = CameraFrame(2.5, tuple(_detections(R_CD, T_CD)))
    if joint:
        estimator = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single())
    else:
        estimator = AtdaEstimator(intrinsics=CAMERA, tag_size=0.12, tag_id=0)
    estimate = estimator.estimate(frame, NO_RANGES)
    assert estimate.valid and math.isnan(estimate.extras["ambiguity_ratio"])
    if joint:
        assert _angle_deg(estimate.rotation, R_CD) < 1e-6
    spoilt = 3
    estimate = estimator.estimate(frame, NO_RANGES)
    assert (estimate.valid, estimate.method, estimate.timestamp) == (False, "atda", 2.5)
    assert estimate.reason == "pnp_failed"


def test_joint_atda_goes_on_past_each_detection_it_cannot_use() -> None:
    """Unusable detections ahead of the usable ones: each is skipped, none ends the search."""
    good = _detections(R_CD, T_CD)
    collinear = np.array([[10.0, 10.0], [20.0, 20.0], [30.0, 30.0], [40.0, 40.0]])
    tiny = np.array([[300.0, 200.0], [302.0, 200.0], [302.0, 198.0], [300.0, 198.0]])
    nan_corner = good[0].corners_px.copy()
    nan_corner[1] = np.nan
    frame = CameraFrame(
        1.0,
        (
            TagDetection(9, good[1].corners_px),  # not in the layout
            TagDetection(0, nan_corner),
            TagDetection(0, collinear),
            TagDetection(0, tiny),  # 2 px a side, under min_side_px (area above the minimum)
            *good,
            TagDetection(2, good[2].corners_px + 5.0),  # tag 2 again
        ),
    )
    estimate = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single()).estimate(
        frame, NO_RANGES
    )
    assert estimate.valid and estimate.extras["landmark_ids"] == (0, 1, 2)
    assert _angle_deg(estimate.rotation, R_CD) < 1e-6


def test_joint_atda_takes_corners_given_as_whole_pixels() -> None:
    """A detector's corners as integers: used as pixels, not refused by OpenCV's PnP."""
    whole = [
        TagDetection(d.tag_id, np.rint(d.corners_px).astype(int)) for d in _detections(R_CD, T_CD)
    ]
    estimate = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single()).estimate(
        CameraFrame(0.0, tuple(whole)), NO_RANGES
    )
    assert estimate.valid and estimate.extras["landmark_ids"] == (0, 1, 2)
    assert _angle_deg(estimate.rotation, R_CD) < 0.5


def test_joint_atda_uses_tags_from_12_px_a_side_by_default() -> None:
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single())
    for height_m, used in ((5.6, (0, 1, 2)), (5.8, (1, 2))):
        detections = _detections(R_CD, np.array([0.1, -0.1, height_m]))
        side_px = shortest_side_px(detections[0].corners_px)
        assert (side_px >= 12.0) == (used == (0, 1, 2)) and abs(side_px - 12.0) < 0.25
        estimate = joint.estimate(CameraFrame(0.0, tuple(detections)), NO_RANGES)
        assert estimate.extras["landmark_ids"] == used


def test_joint_atda_leaves_out_a_detection_far_outside_the_image() -> None:
    good = _detections(R_CD, T_CD)
    outside = TagDetection(2, good[2].corners_px + np.array([2.0 * CAMERA.width, 0.0]))
    estimate = JointAtdaEstimator(intrinsics=CAMERA, layout=LAYOUT, single=_Single()).estimate(
        CameraFrame(0.0, (good[0], good[1], outside)), NO_RANGES
    )
    assert estimate.valid and estimate.extras["landmark_ids"] == (0, 1)
    assert _angle_deg(estimate.rotation, R_CD) < 1e-6


# ---------------------------------------------------------- single-tag ATDA, continued
def _single_ambiguous_view(
    yaw_deg: float,
) -> tuple[CameraFrame, list[tuple[np.ndarray, np.ndarray]]]:
    """The 12 cm tag nearly face-on at 2 m, with 0.5 px of corner noise: IPPE_SQUARE's two
    poses fit about as well and are over 20 degrees apart.  The frame (at 1.1 s) and the two
    poses, the better first."""
    objects = tag_corners_in_tag_frame(TAG)
    rotation = matrix_from_euler_zyx(math.radians(2.0), math.radians(-3.0), math.radians(yaw_deg))
    corners = CAMERA.project(objects @ rotation.T + np.array([0.05, -0.05, 2.0]))
    corners = corners + np.random.default_rng(23).normal(0.0, 0.5, corners.shape)
    _, rvecs, tvecs, errors = cv2.solvePnPGeneric(
        objects,
        corners.reshape(4, 1, 2),
        CAMERA.matrix,
        np.zeros(5),
        flags=cv2.SOLVEPNP_IPPE_SQUARE,
    )
    order = np.argsort(np.asarray(errors, dtype=float).ravel())
    poses = [(cv2.Rodrigues(rvecs[i])[0], np.asarray(tvecs[i], dtype=float).ravel()) for i in order]
    return CameraFrame(1.1, (TagDetection(0, corners),)), poses


@pytest.mark.parametrize("yaw_deg", [30.0, 95.0])  # 95: as the joint view's 145 degrees
@pytest.mark.parametrize("history", ["none", "better", "worse", "worse, then a reset"])
def test_on_an_ambiguous_view_of_one_tag_the_estimate_follows_the_previous_one(
    history: str, yaw_deg: float
) -> None:
    frame, poses = _single_ambiguous_view(yaw_deg)
    atda = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0)
    if history != "none":
        pose = poses[0 if history == "better" else 1]
        exact = CAMERA.project(tag_corners_in_tag_frame(TAG) @ pose[0].T + pose[1])
        before = atda.estimate(CameraFrame(1.0, (TagDetection(0, exact),)), None)
        assert before.valid and _angle_deg(before.rotation, pose[0]) < 1e-6
    if history.endswith("reset"):
        atda.reset()
    estimate = atda.estimate(frame, None)
    assert estimate.valid and estimate.extras["ambiguity_ratio"] >= 0.6
    followed = 1 if history == "worse" else 0
    assert _angle_deg(poses[0][0], poses[1][0]) > 20.0
    assert _angle_deg(estimate.rotation, poses[followed][0]) < 1e-6
    assert estimate.extras["chosen_by_history"] is (followed == 1)


@pytest.mark.parametrize("yaw_deg", [0.0, 180.0, -180.0])
def test_the_single_tag_pose_is_exact_face_on_upright_or_turned_half_a_turn(
    yaw_deg: float,
) -> None:
    """As for the joint PnP: the corners are relabelled by half a turn exactly when the tag's
    x axis points left in the image, so the face-on views at yaw 0 and 180 are exact."""
    rotation = matrix_from_euler_zyx(0.0, 0.0, math.radians(yaw_deg))
    translation = np.array([0.1, -0.1, 1.5])
    corners = CAMERA.project(tag_corners_in_tag_frame(TAG) @ rotation.T + translation)
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0).estimate(
        CameraFrame(0.0, (TagDetection(0, corners),)), None
    )
    assert estimate.valid
    assert _angle_deg(estimate.rotation, rotation) < 1e-9
    assert np.allclose(estimate.translation, translation, rtol=0.0, atol=1e-12)


def test_the_single_tag_atda_refuses_its_tag_far_outside_the_image() -> None:
    corners = CAMERA.project(tag_corners_in_tag_frame(TAG) + np.array([0.0, 0.0, 1.5]))
    outside = CameraFrame(0.5, (TagDetection(0, corners + np.array([2.0 * CAMERA.width, 0.0])),))
    estimate = AtdaEstimator(intrinsics=CAMERA, tag_size=TAG, tag_id=0).estimate(outside, None)
    assert not estimate.valid and estimate.reason == "bad_corners"


R_A = matrix_from_euler_zyx(0.1, 0.0, 0.3)
R_B = matrix_from_euler_zyx(-0.1, 0.05, 0.3)
T_AB = np.array([0.0, 0.0, 2.0])


def _scripted_solvers(monkeypatch: pytest.MonkeyPatch, script: dict) -> list[int]:
    """A stand-in for OpenCV's PnP: for each solver flag, the poses (error px, R) it returns;
    the flags asked for, in order, are recorded."""
    asked: list[int] = []

    def solve(*args, flags: int, **kwargs):
        asked.append(flags)
        poses = script.get(flags, [])
        rvecs = tuple(cv2.Rodrigues(r)[0] for _, r in poses)
        tvecs = tuple(T_AB.reshape(3, 1).copy() for _ in poses)
        errors = np.array([[e] for e, _ in poses]).reshape(-1, 1)
        return len(poses), rvecs, tvecs, errors

    monkeypatch.setattr(cv2, "solvePnPGeneric", solve)
    return asked


def _solved(monkeypatch: pytest.MonkeyPatch, script: dict) -> tuple[str, list, list[int]]:
    asked = _scripted_solvers(monkeypatch, script)
    corners = CAMERA.project(tag_corners_in_tag_frame(TAG) @ R_A.T + T_AB)
    solver, solutions = ippe_solutions(tag_corners_in_tag_frame(TAG), corners, CAMERA.matrix)
    # the errors in the stand-in's units, OpenCV's RMS over coordinates: ippe_solutions
    # reports the RMS corner distance, √2 times it
    return solver, [(round(e / math.sqrt(2.0), 12), r) for e, r, _ in solutions], asked


SQUARE, IPPE, SQPNP = cv2.SOLVEPNP_IPPE_SQUARE, cv2.SOLVEPNP_IPPE, cv2.SOLVEPNP_SQPNP


def test_ippe_squares_two_poses_are_taken_as_they_come_and_end_the_search(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Even two that coincide (an exactly face-on view, where IPPE's two poses are one)."""
    solver, solutions, asked = _solved(monkeypatch, {SQUARE: [(0.4, R_B), (0.2, R_A)]})
    assert (solver, asked) == ("ippe_square", [SQUARE])
    assert [e for e, _ in solutions] == [0.2, 0.4]
    assert _angle_deg(solutions[0][1], R_A) < 1e-9 and _angle_deg(solutions[1][1], R_B) < 1e-9
    solver, solutions, _ = _solved(monkeypatch, {SQUARE: [(0.2, R_A), (0.2, R_A)]})
    assert solver == "ippe_square" and len(solutions) == 2


def test_generic_ippe_is_asked_when_ippe_square_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    solver, solutions, asked = _solved(monkeypatch, {IPPE: [(0.3, R_A), (0.5, R_B)]})
    assert (solver, asked) == ("ippe", [SQUARE, IPPE])
    assert [e for e, _ in solutions] == [0.3, 0.5]


def test_without_two_poses_from_one_solver_the_two_best_distinct_of_all_are_kept(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """IPPE_SQUARE and IPPE give one pose each, the same pose a rounding apart and of the
    same error; SQPNP another: the best pose, then the best other, named by the solver of
    the best (the first asked, of two that fit alike)."""
    rounded = R_A + np.array([[0.0, 0.0, 5e-7], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    script = {SQUARE: [(0.2, R_A)], IPPE: [(0.2, rounded)], SQPNP: [(0.6, R_B)]}
    solver, solutions, asked = _solved(monkeypatch, script)
    assert (solver, asked) == ("ippe_square", [SQUARE, IPPE, SQPNP])
    assert [e for e, _ in solutions] == [0.2, 0.6]
    assert _angle_deg(solutions[1][1], R_B) < 1e-9
    # SQPNP's pose the best: it names the solver
    worse = matrix_from_euler_zyx(0.3, 0.3, 0.3)
    script = {SQUARE: [(0.5, R_A)], IPPE: [(0.7, worse)], SQPNP: [(0.1, R_B)]}
    solver, solutions, _ = _solved(monkeypatch, script)
    assert solver == "sqpnp" and [e for e, _ in solutions] == [0.1, 0.5]


def test_with_no_pose_from_any_solver_none_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    solver, solutions, asked = _solved(monkeypatch, {})
    assert (solver, solutions, asked) == ("none", [], [SQUARE, IPPE, SQPNP])
