"""Nested landmarks: layout geometry, the choice rule, T_CD of D from an offset tag, the
high-approach scenario (project and render mode)."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

import landing_env  # noqa: F401  (registers the environments)
from estimation.atda import JointAtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.detection import AprilTagDetector
from estimation.estimator import RankedEstimator
from estimation.frames import (
    R_PD,
    matrix_from_euler_zyx,
    tag_corners_in_tag_frame,
    tof_positions_in_camera_frame,
)
from estimation.landmarks import (
    NO_LANDMARK,
    Landmark,
    LandmarkChoiceConfig,
    LandmarkEstimator,
    LandmarkLayout,
    choose_landmark,
    compose_deck_pose,
    landmark_pose_w,
    layout_from_pairs,
    shortest_side_px,
)
from estimation.registry import make_estimator
from estimation.synthetic import SyntheticScene
from estimation.tof_calibration import TofCameraCalibration
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading, TagDetection
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.scene.deck import DeckSurfaceConfig, make_deck_texture, plate_to_texel

CAMERA = CameraIntrinsics(width=512, height=512, fx=458.5, fy=457.855, cx=255.5, cy=255.5)
HIGH = load_config("high-approach")
LAYOUT = HIGH.deck.layout


def _square(side_px: float, centre: tuple[float, float] = (256.0, 256.0)) -> np.ndarray:
    half = 0.5 * side_px
    signs = np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])
    return np.asarray(centre) + half * signs


def _frame(*detections: tuple[int, float]) -> CameraFrame:
    return CameraFrame(0.0, tuple(TagDetection(i, _square(s)) for i, s in detections))


# ---------------------------------------------------------------------------------- layout
def test_high_approach_layout_fits_the_deck_with_quiet_zones_apart() -> None:
    q = LAYOUT.quiet_zone_cells
    assert len(set(LAYOUT.ids)) == len(LAYOUT.landmarks) == 3
    assert LAYOUT.extent() <= 0.5 * HIGH.deck.size
    landmarks = LAYOUT.landmarks
    for i, a in enumerate(landmarks):
        for b in landmarks[i + 1 :]:
            reach = a.outer_half_extent(q) + b.outer_half_extent(q)
            assert max(abs(a.x - b.x), abs(a.y - b.y)) >= reach
    # the smallest tag marks the landing point, the origin of D
    smallest = min(landmarks, key=lambda lm: lm.size)
    assert (smallest.x, smallest.y) == (0.0, 0.0)


def test_layout_refuses_overlap_duplicates_and_off_deck() -> None:
    with pytest.raises(ConfigError, match="overlap"):
        layout_from_pairs([(0, 0.2, 0.0, 0.0), (1, 0.2, 0.2, 0.0)])
    with pytest.raises(ConfigError, match="distinct"):
        layout_from_pairs([(0, 0.2, 0.0, 0.0), (0, 0.2, 1.0, 0.0)])
    with pytest.raises(ConfigError, match="landmarks"):
        DeckSurfaceConfig(size=1.0, landmarks=(Landmark(0, 0.3, 0.4, 0.0),))
    with pytest.raises(ConfigError):
        load_config("high-approach", overrides={"deck.size": 2.0})


def test_default_deck_is_one_centred_tag() -> None:
    layout = load_config("default").deck.layout
    assert layout.is_single_centred
    assert layout.landmarks == (Landmark(0, 0.30),)


def test_texture_draws_every_landmark_where_the_layout_says() -> None:
    # a coarser texture than the scenario's, detected directly: ids and corner texels
    config = DeckSurfaceConfig(size=HIGH.deck.size, texture_px=2048, landmarks=HIGH.deck.landmarks)
    texture = make_deck_texture(config)
    detector = AprilTagDetector()
    try:
        found = {d.tag_id: d.corners_px for d in detector.detect(texture)}
    finally:
        detector.close()
    assert set(found) == set(LAYOUT.ids)
    for landmark in LAYOUT.landmarks:
        corners_p = (R_PD @ landmark.corners_d().T).T
        expected = plate_to_texel(config, corners_p[:, :2])
        # the texture is the deck seen from above (a camera with R_CD = I): same corner order
        assert np.max(np.abs(found[landmark.tag_id] - expected)) < 1.0


# ----------------------------------------------------------------------------- choice rule
def test_choice_prefers_the_largest_image_within_the_band() -> None:
    band = LandmarkChoiceConfig(min_side_px=16.0, max_side_px=300.0)
    assert choose_landmark(_frame((2, 25.0), (1, 9.0)), LAYOUT, band).landmark.tag_id == 2
    assert choose_landmark(_frame((0, 60.0), (1, 180.0)), LAYOUT, band).landmark.tag_id == 1
    # a tag filling the view is out of the band: the in-band one wins although smaller
    chosen = choose_landmark(_frame((1, 420.0), (0, 120.0)), LAYOUT, band)
    assert chosen.landmark.tag_id == 0 and chosen.in_band
    # nothing in the band: the largest still serves
    chosen = choose_landmark(_frame((0, 10.0), (1, 12.0)), LAYOUT, band)
    assert chosen.landmark.tag_id == 1 and not chosen.in_band
    # tags not in the layout are ignored
    assert choose_landmark(_frame((7, 100.0)), LAYOUT, band) is None


def test_choice_for_the_tof_estimators_prefers_the_tag_at_the_landing_point() -> None:
    nearest = LandmarkChoiceConfig(prefer="nearest")
    frame = _frame((2, 168.0), (1, 61.0), (0, 18.0))
    assert choose_landmark(frame, LAYOUT, nearest).landmark.tag_id == 0
    # below the band it gives way to an in-band tag farther off
    assert choose_landmark(_frame((0, 9.0), (1, 30.0)), LAYOUT, nearest).landmark.tag_id == 1
    with pytest.raises(ConfigError, match="prefer"):
        LandmarkChoiceConfig(prefer="smallest")


# --------------------------------------------------- estimates of D from a small offset tag
def _offset_scene(landmark: Landmark, r_cd: np.ndarray, t_cd: np.ndarray):
    """Measurements of one landmark only (the others out of the picture)."""
    scene = SyntheticScene(CAMERA, landmark.size, tag_id=landmark.tag_id)
    t_cl = t_cd + r_cd @ landmark.offset_d
    return scene.measure(r_cd, t_cl)


def _estimator(name: str, layout: LandmarkLayout) -> LandmarkEstimator:
    positions = tof_positions_in_camera_frame()
    calibration = TofCameraCalibration.exact(CAMERA, positions, 0.04, 4.0)

    def one(lm: Landmark):
        needs_tof = name != "atda"
        return make_estimator(
            name,
            intrinsics=CAMERA,
            tag_size=lm.size,
            tag_id=lm.tag_id,
            tof_calibration=calibration if needs_tof else None,
            tof_positions_c=positions if needs_tof else None,
        )

    return LandmarkEstimator(name, layout, one)


@pytest.mark.parametrize("name", ["atda", "ihrcf", "crhf"])
def test_every_estimator_reports_the_deck_frame_from_an_offset_tag(name: str) -> None:
    # a small tag 0.3 m off the landing point; the deck tilted, the camera 0.8 m above
    layout = layout_from_pairs([(5, 0.10, 0.30, -0.12), (6, 0.60, -0.60, 0.0)])
    r_cd = matrix_from_euler_zyx(math.radians(4.0), math.radians(-3.0), math.radians(20.0))
    t_cd = np.array([-0.25, 0.05, 0.8])
    small = next(lm for lm in layout.landmarks if lm.tag_id == 5)
    measurement = _offset_scene(small, r_cd, t_cd)
    assert [d.tag_id for d in measurement.frame.detections] == [5]
    assert measurement.ranges.valid.all()
    estimate = _estimator(name, layout).estimate(measurement.frame, measurement.ranges)
    assert estimate.valid, estimate.reason
    assert estimate.extras["landmark_id"] == 5
    assert np.allclose(estimate.translation, t_cd, atol=2e-3)
    assert np.allclose(estimate.rotation, r_cd, atol=2e-3)


def _frame_of_all(layout: LandmarkLayout, r_cd: np.ndarray, t_cd: np.ndarray) -> CameraFrame:
    """Noise-free detections of every landmark of ``layout`` at deck pose (R_CD, t_CD)."""
    detections = []
    for lm in layout.landmarks:
        corners_c = lm.corners_d() @ r_cd.T + t_cd
        detections.append(TagDetection(lm.tag_id, CAMERA.project(corners_c)))
    return CameraFrame(0.0, tuple(detections))


@pytest.mark.parametrize("yaw_deg", [15.0, 170.0, -100.0])
def test_joint_atda_uses_every_detected_tag_and_reports_the_deck_frame(yaw_deg: float) -> None:
    layout = LAYOUT
    r_cd = matrix_from_euler_zyx(math.radians(3.0), math.radians(-2.0), math.radians(yaw_deg))
    t_cd = np.array([0.1, -0.1, 3.0])
    single = _estimator("atda", layout)
    joint = JointAtdaEstimator(intrinsics=CAMERA, layout=layout, single=single)
    no_ranges = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, dtype=bool))
    estimate = joint.estimate(_frame_of_all(layout, r_cd, t_cd), no_ranges)
    assert estimate.valid and estimate.extras["solver"] == "joint_ippe"
    assert set(estimate.extras["landmark_ids"]) == set(layout.ids)
    assert estimate.extras["landmark_id"] == 2  # the largest image
    assert np.allclose(estimate.translation, t_cd, atol=1e-6)
    assert np.allclose(estimate.rotation, r_cd, atol=1e-6)
    # one tag only: the single-tag ATDA on the chosen landmark answers
    one = layout_from_pairs([(1, 0.40, 0.345, 0.0)])
    frame = _frame_of_all(one, r_cd, t_cd)
    estimate = joint.estimate(frame, no_ranges)
    assert estimate.valid and estimate.extras["landmark_id"] == 1
    assert "landmark_ids" not in estimate.extras
    assert np.allclose(estimate.translation, t_cd, atol=1e-3)


def test_compose_moves_the_tag_pose_to_the_deck_frame() -> None:
    landmark = Landmark(3, 0.2, 0.5, -0.25)
    r_cd = matrix_from_euler_zyx(0.1, -0.05, 1.0)
    t_cd = np.array([0.1, 0.2, 3.0])
    r, t = compose_deck_pose(r_cd, t_cd + r_cd @ landmark.offset_d, landmark)
    assert np.allclose(r, r_cd) and np.allclose(t, t_cd)


def test_ranked_estimator_uses_atda_above_the_tof_range_and_ihrcf_within() -> None:
    layout = layout_from_pairs([(0, 0.12, 0.0, 0.0), (2, 1.1, -0.78, 0.0)])
    auto = RankedEstimator("auto", (_estimator("ihrcf", layout), _estimator("atda", layout)))
    level = np.eye(3)
    high = _offset_scene(layout.by_id(2), level, np.array([0.3, -0.2, 12.0]))
    # far above the ToF range: no ray returns
    high = dataclasses.replace(
        high, ranges=RangeReading(0.0, np.full(4, np.nan), np.zeros(4, dtype=bool))
    )
    estimate = auto.estimate(high.frame, high.ranges)
    assert estimate.valid and estimate.extras["source"] == "atda"
    assert np.allclose(estimate.translation, [0.3, -0.2, 12.0], atol=0.02)
    low = _offset_scene(layout.by_id(0), level, np.array([0.02, 0.0, 0.6]))
    estimate = auto.estimate(low.frame, low.ranges)
    assert estimate.valid and estimate.extras["source"] == "ihrcf"
    nothing = auto.estimate(CameraFrame(1.0, ()), low.ranges)
    assert not nothing.valid and set(nothing.extras["reasons"]) == {"ihrcf", "atda"}


# ------------------------------------------------------------------------------- scenario
def test_high_approach_starts_20_m_up_and_5_m_off_with_only_atda_valid() -> None:
    env = gym.make("DeckLanding-v2", config="high-approach")
    try:
        for seed in (0, 1):
            _, info = env.reset(seed=seed)
            offset = info["drone"]["position_w"] - env.unwrapped.world.deck_home_w
            assert math.hypot(offset[0], offset[1]) == pytest.approx(5.0, abs=1e-9)
            assert offset[2] == pytest.approx(20.0, abs=1e-9)
            estimates = info["estimates"]
            assert estimates["atda"]["valid"]
            assert estimates["atda"]["extras"]["landmark_id"] == 2
            for name in ("ihrcf", "crhf"):
                assert estimates[name]["reason"] == "range_invalid"
            # a 25 px tag with 0.3 px corner noise: a few percent of the 20.6 m range
            error = estimates["atda"]["pose"][:3] - info["deck_pose_true"][:3]
            assert np.linalg.norm(error) < 0.05 * np.linalg.norm(info["deck_pose_true"][:3])
    finally:
        env.close()


@pytest.mark.parametrize(("height_m", "tag_id"), [(20.0, 2), (0.5, 0)])
def test_render_mode_decodes_the_large_tag_high_and_the_small_one_low(
    height_m: float, tag_id: int
) -> None:
    env = gym.make(
        "DeckLanding-v2",
        config="high-approach",
        overrides={
            "camera.mode": "render",
            "simulation.drone_fixed": True,
            "wind.enabled": False,
            "estimation.observed": "auto",
            "estimation.compare": ["atda"],
        },
    )
    try:
        # the camera 3 cm below the drone's centre, 5 cm off the landing point
        _, info = env.reset(seed=3, options={"height_m": height_m + 0.03, "offset_m": (0.05, 0.0)})
        frame = env.unwrapped._sensing.frame
        assert tag_id in {d.tag_id for d in frame.detections}
        auto = info["estimates"]["auto"]
        assert auto["valid"] and auto["extras"]["landmark_id"] == tag_id
        assert auto["extras"]["source"] == ("atda" if height_m > 4.0 else "ihrcf")
        error = np.linalg.norm(auto["pose"][:3] - info["deck_pose_true"][:3])
        assert error < 0.03 * height_m
    finally:
        env.close()


def test_start_offset_bounds_are_validated() -> None:
    with pytest.raises(ConfigError, match="min_offset_m"):
        load_config("default", overrides={"start.min_offset_m": 1.0})
    assert load_config("default").start.min_offset_m == 0.0


# ------------------------------------------------------------------- the layout, exactly
def _config_error(call, *args, **kwargs) -> ConfigError:
    with pytest.raises(ConfigError) as error:
        call(*args, **kwargs)
    return error.value


@pytest.mark.parametrize(("field", "value"), [("x", math.nan), ("y", math.inf), ("y", -math.inf)])
def test_a_landmark_off_the_real_line_is_refused_naming_its_coordinate(
    field: str, value: float
) -> None:
    error = _config_error(Landmark, 3, 0.2, **{field: value})
    assert (error.key, error.detail) == (field, f"{value!r} is not finite")
    assert _config_error(Landmark, 587, 0.2).key == "tag_id"


def test_a_landmarks_corners_and_quiet_zone_are_its_size_about_its_centre() -> None:
    landmark = Landmark(1, 0.4, 0.5, -0.25)
    np.testing.assert_array_equal(
        landmark.corners_d(), tag_corners_in_tag_frame(0.4) + np.array([0.5, -0.25, 0.0])
    )
    # half of the 8 cells of the tag and the quiet zone's cells on either side, 0.05 m each
    assert landmark.outer_half_extent(0.0) == pytest.approx(0.2)
    assert landmark.outer_half_extent(1.0) == pytest.approx(0.25)
    assert landmark.outer_half_extent(2.0) == pytest.approx(0.3)


def test_a_layout_names_what_is_wrong_with_it() -> None:
    error = _config_error(LandmarkLayout, ())
    assert (error.key, error.detail) == ("landmarks", "need at least one landmark")
    error = _config_error(layout_from_pairs, [(4, 0.2, 0.0, 0.0), (4, 0.2, 1.0, 0.0)])
    assert (error.key, error.detail) == ("landmarks", "tag ids [4, 4] must be distinct")
    error = _config_error(layout_from_pairs, [(0, 0.2, 0.0, 0.0), (1, 0.2, 0.2, 0.0)])
    assert error.key == "landmarks"
    assert error.detail == (
        "tags 0 and 1 overlap (with their quiet zones) by 0.050 m; move them apart or shrink them"
    )
    assert _config_error(LandmarkLayout, (Landmark(0, 0.2),), -1.0).key == "quiet_zone_cells"


@pytest.mark.parametrize(
    "pairs",
    [
        [(0, 0.2, 0.1, 0.1), (1, 0.2, 0.3, 0.1)],  # 0.2 m apart in x
        [(0, 0.2, 0.1, 0.1), (1, 0.2, 0.1, 0.3)],  # in y
        [(0, 0.2, 0.1, 0.1), (1, 0.2, 3.0, 3.0), (2, 0.2, 0.3, 0.1)],  # the first and the last
        [(0, 0.2, 3.0, 3.0), (1, 0.2, 0.1, 0.1), (2, 0.2, 0.1, 0.3)],  # the last two
    ],
)
def test_tags_whose_quiet_zones_overlap_in_either_direction_are_refused(pairs) -> None:
    assert "overlap" in _config_error(layout_from_pairs, pairs).detail


def test_quiet_zones_that_touch_are_allowed_and_nothing_but_the_gap_is_checked() -> None:
    # 0.125 m of reach each, 0.25 m apart: they touch
    layout = layout_from_pairs([(0, 0.2, 0.0, 0.0), (1, 0.2, 0.25, 0.0), (2, 0.2, 0.0, -0.25)])
    assert layout.ids == (0, 1, 2) and layout.quiet_zone_cells == 1.0
    assert layout.by_id(1) is layout.landmarks[1] and layout.by_id(9) is None
    assert layout_from_pairs([(0, 0.2, 0.0, 0.0)], 2.0).quiet_zone_cells == 2.0
    assert LandmarkLayout.single(4, 0.25) == LandmarkLayout((Landmark(4, 0.25),), 1.0)
    assert LandmarkLayout.single(4, 0.25, 2.0) == LandmarkLayout((Landmark(4, 0.25),), 2.0)


def test_the_layouts_extent_is_the_farthest_reach_of_a_quiet_zone_and_must_fit_the_deck() -> None:
    # tag 1 reaches 0.5 + 0.25 m in x, tag 2 0.6 + 0.125 m in y
    layout = layout_from_pairs([(0, 0.12, 0.0, 0.0), (1, 0.4, -0.5, 0.2), (2, 0.2, 0.1, -0.6)])
    assert layout.extent() == pytest.approx(0.75)
    layout.check_fits(1.5)  # exactly on the edge
    error = _config_error(layout.check_fits, 1.4)
    assert error.key == "landmarks"
    assert error.detail == (
        "tag 1 (size 0.4 m at (-0.5, 0.2)) reaches 0.750 m from the deck centre with its quiet "
        "zone; the 1.4 m deck allows 0.700 m"
    )
    error = _config_error(layout_from_pairs([(2, 0.2, 0.1, -0.6)]).check_fits, 1.44)
    assert "tag 2 (size 0.2 m at (0.1, -0.6)) reaches 0.725 m" in error.detail


def test_a_choice_rule_names_what_is_wrong_with_it() -> None:
    error = _config_error(LandmarkChoiceConfig, prefer="smallest")
    assert error.key == "prefer"
    assert error.detail == "'smallest' is not allowed; choose one of 'largest', 'nearest'"
    error = _config_error(LandmarkChoiceConfig, min_side_px=20.0, max_side_px=20.0)
    assert (error.key, error.detail) == ("max_side_px", "20.0 must exceed min_side_px = 20.0")
    assert _config_error(LandmarkChoiceConfig, min_side_px=-1.0).key == "min_side_px"


def test_the_shortest_side_of_a_quadrilateral_not_its_diagonal() -> None:
    # a kite: sides 5, 5, sqrt(65), sqrt(65); diagonals 8 and 8.06
    kite = np.array([[0.0, 0.0], [4.0, 3.0], [8.0, 0.0], [4.0, -4.0]])
    assert shortest_side_px(kite) == pytest.approx(5.0)
    assert shortest_side_px(kite.reshape(-1)) == pytest.approx(5.0)
    assert shortest_side_px(np.array([[0, 0], [30, 0], [30, 10], [0, 10]])) == 10.0
    assert math.isnan(shortest_side_px(np.where(kite == 8.0, np.nan, kite)))


def test_the_choice_takes_its_band_ends_as_in_it_and_skips_what_it_cannot_use() -> None:
    band = LandmarkChoiceConfig(min_side_px=20.0, max_side_px=80.0)
    # exactly at either end of the band counts as in it
    chosen = choose_landmark(_frame((0, 20.0), (1, 10.0)), LAYOUT, band)
    assert chosen.landmark.tag_id == 0 and chosen.in_band and chosen.side_px == 20.0
    chosen = choose_landmark(_frame((1, 80.0), (2, 90.0)), LAYOUT, band)
    assert chosen.landmark.tag_id == 1 and chosen.in_band
    # a tag not in the layout and a tag without finite corners are passed over
    broken = TagDetection(2, np.full((4, 2), np.nan))
    detections = (TagDetection(7, _square(50.0)), broken, TagDetection(1, _square(30.0)))
    chosen = choose_landmark(CameraFrame(0.0, detections), LAYOUT, band)
    assert chosen.landmark.tag_id == 1 and chosen.detection is detections[2]
    assert choose_landmark(CameraFrame(0.0, (broken,)), LAYOUT, band) is None
    # without a rule: the default band, 12 to 400 px
    assert choose_landmark(_frame((2, 420.0), (1, 11.0), (0, 12.0)), LAYOUT).landmark.tag_id == 0


def test_ties_go_to_the_larger_image_when_as_near_and_to_the_better_decoded_when_as_large() -> None:
    layout = layout_from_pairs([(1, 0.2, 0.5, 0.0), (2, 0.2, -0.5, 0.0), (3, 0.2, 0.0, 0.9)])
    nearest = LandmarkChoiceConfig(prefer="nearest")
    frame = _frame((1, 40.0), (2, 60.0), (3, 90.0))
    assert choose_landmark(frame, layout, nearest).landmark.tag_id == 2
    decoded = CameraFrame(
        0.0,
        (
            TagDetection(1, _square(50.0), hamming=1),
            TagDetection(2, _square(50.0), hamming=0),
            TagDetection(3, _square(50.0), hamming=2),
        ),
    )
    assert choose_landmark(decoded, layout).landmark.tag_id == 2


def test_a_landmarks_world_pose_is_the_deck_pose_moved_to_its_centre() -> None:
    landmark = Landmark(3, 0.2, 0.5, -0.25)
    r_wd = matrix_from_euler_zyx(0.1, -0.05, 1.0)
    t_wd = np.array([10.0, -2.0, 0.5])
    t_wl, r_wl = landmark_pose_w(t_wd, r_wd, landmark)
    np.testing.assert_allclose(t_wl, t_wd + r_wd @ np.array([0.5, -0.25, 0.0]))
    np.testing.assert_array_equal(r_wl, r_wd)
    # and back: the deck frame from the landmark's pose
    r, t = compose_deck_pose(r_wl, t_wl, landmark)
    np.testing.assert_allclose(t, t_wd)
    np.testing.assert_array_equal(r, r_wd)


class _Stub:
    """A per-landmark estimator that records its calls and answers the tag at 1 m."""

    def __init__(self, landmark: Landmark, valid: bool = True) -> None:
        self.landmark = landmark
        self.valid = valid
        self.calls: list[tuple[CameraFrame, RangeReading]] = []
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        self.calls.append((frame, ranges))
        if not self.valid:
            invalid = DeckPoseEstimate.invalid("stub", frame.timestamp, "too_oblique")
            return dataclasses.replace(invalid, extras={"inner": self.landmark.tag_id})
        return DeckPoseEstimate(
            "stub",
            frame.timestamp,
            True,
            rotation=np.eye(3),
            translation=np.array([0.0, 0.0, 1.0]),
            extras={"inner": self.landmark.tag_id},
        )


def test_a_landmark_estimator_runs_the_chosen_tags_estimator_and_keeps_it_through_a_miss() -> None:
    stubs: dict[int, _Stub] = {}

    def make_one(landmark: Landmark) -> _Stub:
        stubs[landmark.tag_id] = _Stub(landmark, valid=landmark.tag_id != 2)
        return stubs[landmark.tag_id]

    estimator = LandmarkEstimator("mine", LAYOUT, make_one)
    ranges = RangeReading(0.0, np.full(4, 1.0), np.ones(4, dtype=bool))
    # nothing seen yet: invalid, no estimator asked
    nothing = estimator.estimate(CameraFrame(0.25, ()), ranges)
    assert (nothing.valid, nothing.method, nothing.timestamp) == (False, "mine", 0.25)
    assert nothing.reason == NO_LANDMARK
    assert all(not stub.calls for stub in stubs.values())
    frame = CameraFrame(0.5, (TagDetection(1, _square(60.0)),))
    seen = estimator.estimate(frame, ranges)
    assert seen.valid and seen.method == "mine" and seen.timestamp == 0.5
    assert seen.extras == {"inner": 1, "landmark_id": 1, "landmark_side_px": 60.0}
    assert stubs[1].calls == [(frame, ranges)]
    landmark = LAYOUT.by_id(1)
    np.testing.assert_allclose(seen.translation, [-landmark.x, -landmark.y, 1.0])
    # a frame without the tag still goes to the last chosen tag's estimator (a tracker bridges)
    missed = estimator.estimate(CameraFrame(0.55, ()), ranges)
    assert (
        missed.valid
        and missed.extras["landmark_id"] == 1
        and stubs[1].calls[-1][0].timestamp == 0.55
    )
    assert math.isnan(missed.extras["landmark_side_px"])
    # an invalid estimate of the chosen tag: renamed, with the landmark, the pose left unset
    invalid = estimator.estimate(CameraFrame(0.6, (TagDetection(2, _square(90.0)),)), ranges)
    assert (invalid.valid, invalid.method, invalid.reason) == (False, "mine", "too_oblique")
    assert invalid.extras == {"inner": 2, "landmark_id": 2, "landmark_side_px": 90.0}
    assert np.all(np.isnan(invalid.translation))
    estimator.reset()
    assert all(stub.resets == 1 for stub in stubs.values())
    assert estimator.estimate(CameraFrame(0.7, ()), ranges).reason == NO_LANDMARK


def test_the_shortest_side_of_unsigned_integer_corners_is_measured_without_wrapping() -> None:
    # sides 10, 100, 100 and 134.5 px; each corner minus the next is negative along the 10 px one
    corners = np.array([[100, 110], [110, 110], [110, 10], [10, 10]], dtype=np.uint16)
    assert shortest_side_px(corners) == 10.0


#: a quarter turn about z and a half turn about x, in integers
_INTEGER_ROTATIONS = ([[0, -1, 0], [1, 0, 0], [0, 0, 1]], [[1, 0, 0], [0, -1, 0], [0, 0, -1]])


@pytest.mark.parametrize("rotation", _INTEGER_ROTATIONS)
def test_a_pose_given_in_integers_comes_out_in_float_arrays(rotation: list[list[int]]) -> None:
    landmark = Landmark(3, 0.2, 0.5, -0.25)
    r = np.array(rotation, dtype=float)
    r_cd, t_cd = compose_deck_pose(rotation, [1, 2, 3], landmark)
    t_wl, r_wl = landmark_pose_w([1, 2, 3], rotation, landmark)
    for out in (r_cd, t_cd, t_wl, r_wl):
        assert isinstance(out, np.ndarray) and out.dtype == np.float64
    np.testing.assert_array_equal(r_cd, r)
    np.testing.assert_array_equal(r_wl, r)
    np.testing.assert_allclose(t_cd, np.array([1.0, 2.0, 3.0]) - r @ [0.5, -0.25, 0.0])
    np.testing.assert_allclose(t_wl, np.array([1.0, 2.0, 3.0]) + r @ [0.5, -0.25, 0.0])


class _IntegerPose(_Stub):
    """A per-landmark estimator that answers its pose in integer arrays."""

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        estimate = super().estimate(frame, ranges)
        rotation = np.array(_INTEGER_ROTATIONS[0])
        return dataclasses.replace(estimate, rotation=rotation, translation=np.array([0, 0, 2]))


def test_a_landmark_estimator_reports_the_deck_pose_in_floats_whatever_its_inner_one_gives() -> (
    None
):
    estimator = LandmarkEstimator("mine", LAYOUT, _IntegerPose)
    ranges = RangeReading(0.0, np.full(4, 1.0), np.ones(4, dtype=bool))
    seen = estimator.estimate(CameraFrame(0.5, (TagDetection(1, _square(60.0)),)), ranges)
    assert seen.valid and seen.rotation.dtype == np.float64
    assert seen.translation.dtype == np.float64
    rotation = np.array(_INTEGER_ROTATIONS[0], dtype=float)
    np.testing.assert_array_equal(seen.rotation, rotation)
    landmark = LAYOUT.by_id(1)
    np.testing.assert_allclose(seen.translation, [0.0, 0.0, 2.0] - rotation @ landmark.offset_d)
