"""The tightly coupled estimator ``tight`` on synthetic geometry (no simulator)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from estimation.atda import AtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.frames import euler_zyx_from_matrix, tof_positions_in_camera_frame
from estimation.ihrcf import IhrcfEstimator
from estimation.noise import TofNoiseModel
from estimation.synthetic import SyntheticScene
from estimation.tight import TightEstimator
from estimation.tight_config import TightConfig
from estimation.tight_problem import TightProblem, rotation_exp
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import CornerTracker, TrackedEstimator
from estimation.types import CameraFrame, RangeReading, TagDetection

TAG_SIZE = 0.12
PIXEL_SIGMA = 0.5
LENSES = {
    "pinhole": CameraIntrinsics(),
    "distorted": CameraIntrinsics(dist=(-0.25, 0.08, 0.001, -0.001, 0.01)),
}
TOF = TofNoiseModel()


def random_pose(rng: np.random.Generator, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Deck tilted up to 15° about a random horizontal axis, any yaw, tag in the central
    half of the view at ``height``."""
    axis = np.array([*rng.normal(size=2), 0.0])
    axis /= np.linalg.norm(axis)
    rotation = (
        Rotation.from_rotvec(math.radians(rng.uniform(0.0, 15.0)) * axis)
        * Rotation.from_euler("z", rng.uniform(-math.pi, math.pi))
    ).as_matrix()
    k = LENSES["pinhole"]
    half = max(0.0, height * k.cx / k.fx - TAG_SIZE)
    return rotation, np.array([*(rng.uniform(-0.5, 0.5, 2) * half), height])


def noisy(scene: SyntheticScene, rotation, translation, rng, tof: TofNoiseModel = TOF):
    """A frame with 0.5 px corner noise and VL53L1X ranges (Gaussian, then 1 mm steps)."""
    m = scene.measure(rotation, translation)
    pixels = m.true_corners_px + rng.normal(0.0, PIXEL_SIGMA, (4, 2))
    valid = np.isfinite(m.true_ranges)
    true_r = np.where(valid, m.true_ranges, 1.0)
    ranges = true_r + (tof.sigma_0_m + tof.sigma_per_m * true_r) * rng.normal(size=4)
    if tof.resolution_m > 0.0:
        ranges = np.round(ranges / tof.resolution_m) * tof.resolution_m
    frame = CameraFrame(0.0, (TagDetection(0, pixels),) if m.frame.detections else ())
    return frame, RangeReading(0.0, np.where(valid, ranges, np.nan), valid)


def pose_error(estimate, rotation, translation) -> np.ndarray:
    """(x, y, z, roll, pitch, yaw) error, metres and radians (angles wrapped)."""
    truth = np.concatenate([translation, euler_zyx_from_matrix(rotation)])
    error = estimate.as_vector() - truth
    error[3:] = (error[3:] + math.pi) % (2.0 * math.pi) - math.pi
    return error


def pose_error_free(rotation, translation) -> np.ndarray:
    return np.concatenate([translation, euler_zyx_from_matrix(rotation)])


def tight(lens: str = "pinhole", **config) -> TightEstimator:
    """tight weighting the corners by the tests' pixel noise (and VL53L1X ranges)."""
    settings = TightConfig(**{"pixel_sigma_px": PIXEL_SIGMA, **config})
    return TightEstimator(intrinsics=LENSES[lens], tag_size=TAG_SIZE, config=settings)


@pytest.mark.parametrize("lens", list(LENSES))
@pytest.mark.parametrize("n_ranges", [4, 2, 0])
def test_noise_free_measurements_give_the_pose_back(lens: str, n_ranges: int) -> None:
    scene = SyntheticScene(LENSES[lens], TAG_SIZE)
    estimator = tight(lens)
    rng = np.random.default_rng(3)
    worst = np.zeros(2)
    for _ in range(200):
        rotation, translation = random_pose(rng, rng.uniform(0.3, 4.0))
        m = scene.measure(rotation, translation)
        valid = m.ranges.valid.copy()
        valid[n_ranges:] = False
        reading = RangeReading(0.0, np.where(valid, m.ranges.ranges, np.nan), valid)
        estimator.reset()
        estimate = estimator.estimate(m.frame, reading)
        assert estimate.valid, estimate.reason
        assert estimate.extras["ranges_used"] == n_ranges
        dt = float(np.linalg.norm(estimate.translation - translation))
        da = math.degrees(Rotation.from_matrix(estimate.rotation @ rotation.T).magnitude())
        worst = np.maximum(worst, [dt, da])
    assert worst[0] < 1e-6 and worst[1] < 1e-4, worst


def test_the_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(1)
    rotation, translation = random_pose(rng, 1.3)
    problem = TightProblem(
        np.array([[-0.06, 0.06, 0.0], [0.06, 0.06, 0.0], [0.06, -0.06, 0.0], [-0.06, -0.06, 0.0]]),
        rng.uniform(200.0, 300.0, (4, 2)),
        LENSES["distorted"],
        PIXEL_SIGMA,
        tof_positions_in_camera_frame(),
        np.array([1.2, 1.3, 1.4, 1.25]),
        TOF.sigma(np.array([1.2, 1.3, 1.4, 1.25])),
    )
    _, jacobian = problem.linearise(rotation, translation)
    numeric = np.empty_like(jacobian)
    h = 1e-7
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        plus = problem.residuals(rotation_exp(d[3:]) @ rotation, translation + d[:3])
        minus = problem.residuals(rotation_exp(-d[3:]) @ rotation, translation - d[:3])
        numeric[:, i] = (plus - minus) / (2.0 * h)
    assert np.allclose(jacobian, numeric, rtol=1e-5, atol=1e-4 * np.abs(jacobian).max())


@pytest.mark.parametrize("lens", list(LENSES))
def test_the_hand_written_solver_agrees_with_scipy_least_squares(lens: str) -> None:
    scene = SyntheticScene(LENSES[lens], TAG_SIZE)
    estimator = tight(lens)
    rng = np.random.default_rng(8)
    for _ in range(30):
        rotation, translation = random_pose(rng, rng.uniform(0.5, 3.0))
        frame, reading = noisy(scene, rotation, translation, rng)
        estimate = estimator.estimate(frame, reading)
        assert estimate.valid
        problem = TightProblem(
            estimator._model,
            frame.detections[0].corners_px,
            LENSES[lens],
            PIXEL_SIGMA,
            tof_positions_in_camera_frame(),
            reading.ranges,
            TOF.sigma(reading.ranges),
        )
        # SciPy from the truth, over a rotation vector and the translation
        r0 = Rotation.from_matrix(rotation)

        def fun(x, r0=r0, problem=problem):
            return problem.residuals(
                Rotation.from_rotvec(x[3:]).as_matrix() @ r0.as_matrix(), x[:3]
            )

        x0 = np.concatenate([translation, np.zeros(3)])
        ref = least_squares(fun, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        r_ref = Rotation.from_rotvec(ref.x[3:]).as_matrix() @ rotation
        # solved to convergence, the LM lands on SciPy's minimum
        exact = problem.solve(estimate.rotation, estimate.translation, 50, cost_tol=0.0)
        assert exact is not None
        assert np.allclose(exact.translation, ref.x[:3], atol=1e-9)
        assert Rotation.from_matrix(exact.rotation @ r_ref.T).magnitude() < 1e-6
        assert exact.cost == pytest.approx(2.0 * ref.cost, rel=1e-9, abs=1e-12)
        # the estimator's own stopping rule leaves it within 2 % of a standard deviation
        sigma = np.sqrt(np.diag(estimate.covariance))
        delta = estimate.as_vector() - pose_error_free(r_ref, ref.x[:3])
        assert np.all(np.abs(delta) <= 0.02 * sigma), delta / sigma


@pytest.fixture(scope="module")
def noisy_errors() -> dict:
    """Errors of tight, ATDA and IHRCF over 300 random poses at each of 0.5, 1, 2, 3 m,
    with 0.5 px corner noise and VL53L1X ranges; and tight's NEES."""
    k = LENSES["pinhole"]
    scene = SyntheticScene(k, TAG_SIZE)
    calibration = TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), 0.04, 5.0)
    estimators = {
        "tight": tight(),
        "atda": AtdaEstimator(intrinsics=k, tag_size=TAG_SIZE, tag_id=0),
        "ihrcf": IhrcfEstimator(
            tag_size=TAG_SIZE,
            tag_id=0,
            tof_calibration=calibration,
            tof_positions_c=None,
            intrinsics=k,
        ),
    }
    rng = np.random.default_rng(2026)
    out: dict = {"nees": []}
    for height in (0.5, 1.0, 2.0, 3.0):
        errors = {name: [] for name in estimators}
        for _ in range(300):
            rotation, translation = random_pose(rng, height)
            frame, reading = noisy(scene, rotation, translation, rng)
            for name, estimator in estimators.items():
                estimator.reset()  # single frames: no history
                estimate = estimator.estimate(frame, reading)
                assert estimate.valid, (name, estimate.reason)
                error = pose_error(estimate, rotation, translation)
                errors[name].append(error)
                if name == "tight":
                    out["nees"].append(float(error @ np.linalg.solve(estimate.covariance, error)))
        out[height] = {name: np.abs(np.array(e)) for name, e in errors.items()}
    return out


@pytest.mark.parametrize("height", [0.5, 1.0, 2.0, 3.0])
def test_with_realistic_noise_tight_beats_atda_and_ihrcf(noisy_errors: dict, height: float) -> None:
    errors = noisy_errors[height]
    mae = {name: e.mean(axis=0) for name, e in errors.items()}
    best = np.minimum(mae["atda"], mae["ihrcf"])
    assert np.all(mae["tight"] <= 1.05 * best), (mae["tight"], best)
    assert np.all(mae["tight"][3:5] < best[3:5])


def test_a_range_noise_floor_holds_sigma_up_to_where_the_linear_model_passes_it() -> None:
    floored = TofNoiseModel(0.0, 0.005, 0.0, sigma_min_m=0.005)
    np.testing.assert_allclose(floored.sigma([0.5, 1.0, 2.0, 3.0]), [5e-3, 5e-3, 1e-2, 1.5e-2])
    assert floored.sigma_scalar(0.5) == pytest.approx(5e-3)
    assert TofNoiseModel().sigma_min_m == 0.0  # the VL53L1X model has no floor
    with pytest.raises(ValueError, match="sigma_min_m"):
        TofNoiseModel(sigma_min_m=-1.0)


def test_the_covariance_is_consistent_nees_in_the_chi2_band(noisy_errors: dict) -> None:
    nees = np.array(noisy_errors["nees"])
    n = len(nees)
    low, high = chi2.ppf([0.025, 0.975], 6 * n) / n
    assert low <= nees.mean() <= high, (nees.mean(), low, high)


def test_the_ranges_resolve_the_planar_flip_that_costs_atda_its_spikes() -> None:
    """A small tag far away, nearly facing the camera: IPPE's two poses fit the corners
    about equally well; the ranges tell them apart."""
    k = LENSES["pinhole"]
    scene = SyntheticScene(k, TAG_SIZE)
    atda = AtdaEstimator(intrinsics=k, tag_size=TAG_SIZE, tag_id=0)
    estimator = tight()
    rng = np.random.default_rng(4)
    worst = {"atda": 0.0, "tight": 0.0}
    for _ in range(200):
        rotation, translation = random_pose(rng, 3.0)
        frame, reading = noisy(scene, rotation, translation, rng)
        for name, e in (("atda", atda), ("tight", estimator)):
            e.reset()
            est = e.estimate(frame, reading)
            angle = math.degrees(Rotation.from_matrix(est.rotation @ rotation.T).magnitude())
            worst[name] = max(worst[name], angle)
    assert worst["atda"] > 10.0  # the flip happens
    assert worst["tight"] < 0.5 * worst["atda"]


def test_a_range_off_the_deck_is_dropped_and_the_pose_solved_again() -> None:
    scene = SyntheticScene(LENSES["pinhole"], TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(6), 1.0)
    m = scene.measure(rotation, translation)
    ranges = m.ranges.ranges.copy()
    ranges[2] += 0.3  # the ray passed the deck's edge
    estimate = tight().estimate(m.frame, RangeReading(0.0, ranges, m.ranges.valid))
    assert estimate.valid
    assert estimate.extras["ranges_dropped"] == 1 and estimate.extras["ranges_used"] == 3
    assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_three_corners_are_enough_with_the_tof_plane_not_without() -> None:
    scene = SyntheticScene(LENSES["distorted"], TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(7), 1.5)
    m = scene.measure(rotation, translation)
    corners = m.frame.detections[0].corners_px.copy()
    corners[1] = np.nan
    frame = CameraFrame(0.0, (TagDetection(0, corners),))
    estimator = tight("distorted")
    estimate = estimator.estimate(frame, m.ranges)
    assert estimate.valid and estimate.extras["corners_used"] == 3
    assert np.linalg.norm(estimate.translation - translation) < 1e-6
    estimator.reset()
    none = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    lost = estimator.estimate(frame, none)
    assert not lost.valid and lost.reason == "no_initial_pose"
    corners[2] = np.nan
    two = estimator.estimate(CameraFrame(0.0, (TagDetection(0, corners),)), m.ranges)
    assert not two.valid and two.reason == "too_few_corners"


def test_a_lost_tag_is_invalid_unless_a_tracker_predicts_it() -> None:
    scene = SyntheticScene(LENSES["pinhole"], TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(9), 1.0)
    m = scene.measure(rotation, translation)
    empty = CameraFrame(0.1, ())
    assert tight().estimate(empty, m.ranges).reason == "no_detection"
    tracked = TrackedEstimator(tight(), CornerTracker(dt=0.05), name="tight")
    assert tracked.estimate(m.frame, m.ranges).valid
    bridged = tracked.estimate(CameraFrame(0.05, ()), m.ranges)
    assert bridged.valid and bridged.predicted


@pytest.mark.parametrize(
    "case",
    ["no_tag", "other_tag", "collinear", "nan", "huge", "wrong_shape", "bad_ranges", "all_nan"],
)
def test_degenerate_inputs_give_invalid_estimates_not_exceptions(case: str) -> None:
    scene = SyntheticScene(LENSES["pinhole"], TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(10), 1.0)
    m = scene.measure(rotation, translation)
    corners = m.frame.detections[0].corners_px.copy()
    reading = m.ranges
    if case == "no_tag":
        frame = CameraFrame(0.0, ())
    elif case == "other_tag":
        frame = CameraFrame(0.0, (TagDetection(5, corners),))
    elif case == "collinear":
        frame = CameraFrame(0.0, (TagDetection(0, np.array([[0, 0], [1, 1], [2, 2], [3, 3.0]])),))
    elif case == "nan":
        frame = CameraFrame(0.0, (TagDetection(0, np.full((4, 2), np.nan)),))
    elif case == "huge":
        frame = CameraFrame(0.0, (TagDetection(0, corners * 1e9),))
    elif case == "wrong_shape":
        frame = CameraFrame(0.0, (TagDetection(0, np.ones(5)),))
    elif case == "all_nan":
        frame = CameraFrame(0.0, (TagDetection(0, corners),))
        reading = RangeReading(0.0, np.full(4, np.nan), np.ones(4, bool))
    else:
        frame = CameraFrame(0.0, (TagDetection(0, corners),))
        reading = RangeReading(0.0, np.array([-1.0, np.inf, 1e9]), np.ones(3, bool))
    estimate = tight().estimate(frame, reading)
    if case in ("all_nan", "bad_ranges"):
        # unusable ranges leave the camera-only pose
        assert estimate.valid and estimate.extras["ranges_used"] == 0
    else:
        assert not estimate.valid and estimate.reason


@settings(max_examples=200, deadline=None)
@given(
    corners=st.lists(
        st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=8, max_size=8
    ),
    ranges=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4),
    valid=st.lists(st.booleans(), min_size=4, max_size=4),
)
def test_fuzzed_inputs_never_raise(corners, ranges, valid) -> None:
    frame = CameraFrame(0.0, (TagDetection(0, np.array(corners).reshape(4, 2)),))
    reading = RangeReading(0.0, np.array(ranges), np.array(valid))
    # with and without the realistic camera's corner offset (estimation/corner_bias.py)
    for estimator in (tight(), tight(corner_bias_px=(-0.017, -0.105, -4.96))):
        estimate = estimator.estimate(frame, reading)
        if estimate.valid:
            assert np.all(np.isfinite(estimate.as_vector()))
            assert np.all(np.isfinite(estimate.covariance))
        else:
            assert estimate.reason


def test_config_rejects_bad_settings_naming_the_key() -> None:
    with pytest.raises(ValueError, match="pixel_sigma_px"):
        TightConfig(pixel_sigma_px=0.0)
    with pytest.raises(ValueError, match="tof_sigma_per_m"):
        TightConfig(tof_sigma_per_m=-1.0)


def test_the_touch_pixels_correct_a_chessboard_principal_point_error() -> None:
    """The pads see where the rays land in the image; a K whose cx, cy are off by a third of
    a pixel is moved back, and x, y lose the bias (1.6 mm at 2 m without)."""
    true_k = LENSES["distorted"]
    wrong_k = dataclasses.replace(true_k, cx=true_k.cx - 0.38, cy=true_k.cy + 0.27)
    pads = TofCameraCalibration.exact(true_k, tof_positions_in_camera_frame(), 0.04, 4.0)
    scene = SyntheticScene(true_k, TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(12), 2.0)
    m = scene.measure(rotation, translation)
    fixed = TightEstimator(
        intrinsics=wrong_k, tag_size=TAG_SIZE, tof_calibration=pads, config=TightConfig()
    )
    np.testing.assert_allclose(fixed.principal_point_offset_px, [0.38, -0.27], atol=1e-9)
    assert np.linalg.norm(fixed.estimate(m.frame, m.ranges).translation - translation) < 1e-6
    kept = TightEstimator(
        intrinsics=wrong_k,
        tag_size=TAG_SIZE,
        tof_calibration=pads,
        config=TightConfig(principal_point="calibrated"),
    )
    assert np.linalg.norm(kept.estimate(m.frame, m.ranges).translation - translation) > 1e-3


def _moving_deck_frames(rng: np.random.Generator, count: int):
    """Frames 50 ms apart of a deck that heaves and tilts slowly, 1.2 m below the camera."""
    scene = SyntheticScene(LENSES["pinhole"], TAG_SIZE)
    base, _ = random_pose(rng, 1.2)
    for i in range(count):
        t = 0.05 * i
        tilt = Rotation.from_euler("xy", [0.05 * math.sin(t), 0.04 * math.cos(0.7 * t)])
        translation = np.array([0.03 * math.sin(0.5 * t), -0.02, 1.2 + 0.1 * math.sin(t)])
        frame, reading = noisy(scene, tilt.as_matrix() @ base, translation, rng)
        yield (
            dataclasses.replace(frame, timestamp=t),
            dataclasses.replace(reading, timestamp=t),
        )


def test_previous_first_keeps_the_previous_solution_and_finds_the_full_search_s_pose() -> None:
    fallback, first = tight(), tight(previous_start="first")
    kept = 0
    for frame, reading in _moving_deck_frames(np.random.default_rng(21), 40):
        full, warm = fallback.estimate(frame, reading), first.estimate(frame, reading)
        assert full.valid and warm.valid
        kept += warm.extras["start"] == "previous"
        np.testing.assert_allclose(warm.translation, full.translation, atol=1e-5)
        np.testing.assert_allclose(warm.rotation, full.rotation, atol=1e-4)
    assert kept >= 35  # every frame after the first, but for a start the gate sent back


def test_previous_first_searches_every_start_when_the_previous_pose_is_off_or_unranged() -> None:
    frames = list(_moving_deck_frames(np.random.default_rng(22), 2))
    # two iterations cannot bring a pose flipped over back: its cost fails the gate, and the
    # search from every start then runs as it does without the previous start first
    first = tight(previous_start="first", max_iterations=2)
    first.estimate(*frames[0])
    flipped = Rotation.from_euler("x", math.pi).as_matrix() @ first._previous[1]
    first._previous = (first._previous[0], flipped, first._previous[2] * 3.0)
    estimate = first.estimate(*frames[1])
    reference = tight(max_iterations=2).estimate(*frames[1])
    assert estimate.extras["start"] == reference.extras["start"] != "previous"
    np.testing.assert_array_equal(estimate.as_vector(), reference.as_vector())
    # without ranges the planar flip is the corners' alone to tell: never the previous alone
    unranged = RangeReading(frames[1][1].timestamp, np.full(4, np.nan), np.zeros(4, bool))
    first.estimate(*frames[0])
    assert first.estimate(frames[1][0], unranged).extras["start"] != "previous"


def test_previous_start_must_be_a_known_rule() -> None:
    with pytest.raises(ValueError, match="previous_start"):
        TightConfig(previous_start="always")
