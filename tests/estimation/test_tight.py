"""The tightly coupled estimator ``tight`` on synthetic geometry (no simulator)."""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from estimation import geometry
from estimation.atda import AtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.errors import ConfigError
from estimation.frames import (
    euler_zyx_from_matrix,
    tag_corners_in_tag_frame,
    tof_positions_in_camera_frame,
)
from estimation.ihrcf import IhrcfEstimator
from estimation.noise import EXACT_RANGE_SIGMA_M, TofNoiseModel
from estimation.synthetic import SyntheticScene
from estimation.tight import TightEstimator, _same_basin, principal_point_offset
from estimation.tight_config import TightConfig
from estimation.tight_problem import TightProblem, euler_jacobian, rotation_exp
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


def _numeric_jacobian(problem, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The residuals' central differences over the pose's six increments (translation, then
    rotation by the exponential map on the left), step 1e-7."""
    h = 1e-7
    columns = []
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        plus = problem.residuals(rotation_exp(d[3:]) @ rotation, translation + d[:3])
        minus = problem.residuals(rotation_exp(-d[3:]) @ rotation, translation - d[:3])
        columns.append((plus - minus) / (2.0 * h))
    return np.stack(columns, axis=1)


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
    numeric = _numeric_jacobian(problem, rotation, translation)
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


def test_a_ranges_sigma_adds_the_gaussian_and_the_steps_uniform_spread_in_quadrature() -> None:
    """3 mm of Gaussian noise (1 + 1 mm/m at 2 m) and 4 mm of quantisation (a step of
    4 mm x sqrt(12)) give 5 mm; a step alone gives step / sqrt(12)."""
    both = TofNoiseModel(0.001, 0.001, 0.004 * math.sqrt(12.0))
    steps = TofNoiseModel(0.0, 0.0, 0.012)
    assert both.sigma_scalar(2.0) == pytest.approx(0.005, rel=1e-12)
    np.testing.assert_allclose(both.sigma(np.array([2.0, 0.0])), [0.005, math.hypot(1e-3, 4e-3)])
    assert steps.sigma_scalar(3.0) == pytest.approx(0.012 / math.sqrt(12.0), rel=1e-12)
    np.testing.assert_allclose(steps.sigma([0.0, 3.0]), [0.012 / math.sqrt(12.0)] * 2, rtol=1e-12)
    float32 = both.sigma(np.array([2.0, 0.0], dtype=np.float32))
    assert float32.dtype == np.float64 and float32[0] == both.sigma(2.0)


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.0, 0.05),
    st.floats(0.0, 0.05),
    st.floats(0.0, 0.01),
    st.floats(0.0, 0.02),
    st.floats(0.0, 10.0),
)
def test_a_single_ranges_sigma_is_the_arrays_sigma_at_that_range(
    sigma_0_m: float, sigma_per_m: float, resolution_m: float, sigma_min_m: float, range_m: float
) -> None:
    model = TofNoiseModel(sigma_0_m, sigma_per_m, resolution_m, sigma_min_m)
    assert model.sigma_scalar(range_m) == pytest.approx(float(model.sigma([range_m])[0]), rel=1e-12)


def test_exact_ranges_have_no_noise_and_the_exact_floor_at_every_range() -> None:
    exact = TofNoiseModel.exact()
    assert exact == TofNoiseModel(0.0, 0.0, 0.0, 0.0)
    np.testing.assert_array_equal(exact.sigma([0.0, 1.0, 4.0]), [EXACT_RANGE_SIGMA_M] * 3)
    np.testing.assert_array_equal(exact.gaussian_sigma([0.0, 4.0]), [0.0, 0.0])
    assert exact.sigma_scalar(4.0) == EXACT_RANGE_SIGMA_M


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


@pytest.mark.parametrize(
    ("settings", "key", "detail"),
    [
        (
            {"principal_point": "median"},
            "principal_point",
            "'median' is not allowed; choose one of 'touch_points', 'calibrated'",
        ),
        (
            {"previous_start": "always"},
            "previous_start",
            "'always' is not allowed; choose one of 'fallback', 'first'",
        ),
        (
            {"corner_bias_px": (0.1, 0.2)},
            "corner_bias_px",
            "(0.1, 0.2): need three finite numbers (a, b, c)",
        ),
    ],
)
def test_a_bad_rule_or_corner_offset_is_refused_under_its_key_saying_what_is_allowed(
    settings: dict, key: str, detail: str
) -> None:
    with pytest.raises(ConfigError) as refused:
        TightConfig(**settings)
    assert refused.value.key == key
    assert refused.value.detail == detail


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


# -- the least-squares problem and its solver (estimation/tight_problem.py) ---------------

TRUE_ROTATION = Rotation.from_euler("xyz", [0.1, -0.05, 0.7]).as_matrix()
TRUE_TRANSLATION = np.array([0.05, -0.03, 1.2])


def _problem(
    lens: str = "pinhole",
    pixel_noise_px: float = 0.0,
    pixel_sigma_px: float = PIXEL_SIGMA,
    range_sigma_scale: float = 1.0,
    sensors_c: np.ndarray | None = None,
    rotation: np.ndarray = TRUE_ROTATION,
    translation: np.ndarray = TRUE_TRANSLATION,
) -> TightProblem:
    """The problem of a 12 cm tag at ``translation`` (1.2 m by default) seen through ``lens``,
    its pixels with ``pixel_noise_px`` of noise (seed 5), the ranges exact."""
    model = tag_corners_in_tag_frame(TAG_SIZE)
    pixels = LENSES[lens].project((rotation @ model.T).T + translation)
    pixels = pixels + np.random.default_rng(5).normal(0.0, 1.0, (4, 2)) * pixel_noise_px
    sensors = tof_positions_in_camera_frame() if sensors_c is None else sensors_c
    normal = rotation[:, 2]
    ranges = (translation - sensors) @ normal / normal[2]
    return TightProblem(
        model,
        pixels,
        LENSES[lens],
        pixel_sigma_px,
        sensors,
        ranges,
        TOF.sigma(ranges) * range_sigma_scale,
    )


def test_the_residuals_are_the_pixel_and_range_errors_each_over_its_sigma() -> None:
    # sensors off the camera plane: a range runs from its sensor's own z
    sensors = tof_positions_in_camera_frame() + np.array([0.0, 0.0, 0.01])
    # a level deck straight below: each range is the depth below its sensor
    level = np.eye(3)
    problem = _problem(sensors_c=sensors, rotation=level)
    assert problem.m == 12 and problem.n_corners == 4 and problem.n_ranges == 4
    exact = problem.residuals(level, TRUE_TRANSLATION)
    np.testing.assert_allclose(exact, 0.0, atol=1e-9)
    moved = TRUE_TRANSLATION + np.array([0.0, 0.0, 0.01])
    residuals = problem.residuals(level, moved)
    k = LENSES["pinhole"]
    model = tag_corners_in_tag_frame(TAG_SIZE)
    shift_px = k.project(model + moved) - k.project(model + TRUE_TRANSLATION)
    np.testing.assert_allclose(residuals[:8], shift_px.reshape(-1) / PIXEL_SIGMA, rtol=1e-9)
    ranges = TRUE_TRANSLATION[2] - sensors[:, 2]
    np.testing.assert_allclose(residuals[8:], 0.01 / TOF.sigma(ranges), rtol=1e-9)
    assert problem.cost(level, moved) == pytest.approx(float(residuals @ residuals), rel=1e-12)


def test_a_deck_seen_edge_on_gives_ranges_that_are_not_finite_not_an_exception() -> None:
    problem = _problem()
    edge_on = Rotation.from_euler("x", math.pi / 2).as_matrix()
    edge_on[2, 2] = 0.0  # exactly: the rays run along the deck
    residuals = problem.residuals(edge_on, TRUE_TRANSLATION)
    assert not np.isfinite(residuals[8:]).any()


def test_corners_at_or_behind_the_camera_give_nan_residuals_and_rows_in_their_places() -> None:
    problem = _problem()
    # at the camera's plane: every corner has depth 0
    assert np.isnan(problem.residuals(np.eye(3), np.array([0.0, 0.0, 0.0]))[:8]).all()
    # tilted 80° about y, 5 cm deep: the corners at +x lie behind the camera
    tilted = Rotation.from_euler("y", math.radians(80.0)).as_matrix()
    depth = (tilted @ tag_corners_in_tag_frame(TAG_SIZE).T)[2] + 0.05
    behind = np.repeat(depth <= 0.0, 2)
    assert 0 < behind.sum() < 8
    residuals, jacobian = problem.linearise(tilted, np.array([0.0, 0.0, 0.05]))
    assert residuals.shape == (12,) and jacobian.shape == (12, 6)
    np.testing.assert_array_equal(np.isnan(residuals[:8]), behind)
    np.testing.assert_array_equal(np.isnan(jacobian[:8]).all(axis=1), behind)
    assert np.isfinite(jacobian[:8][~behind]).all()


def test_the_jacobian_matches_finite_differences_far_out_in_a_strongly_distorted_image() -> None:
    lens = CameraIntrinsics(dist=(-0.3, 0.1, 0.002, -0.002, 0.4))
    model = tag_corners_in_tag_frame(TAG_SIZE)
    # the tag near the image's corner, where r² is largest
    translation = np.array([0.45, 0.4, 0.8])
    pixels = lens.project((TRUE_ROTATION @ model.T).T + translation) + 3.0
    problem = TightProblem(model, pixels, lens, PIXEL_SIGMA, np.empty((0, 3)), [], [])
    _, jacobian = problem.linearise(TRUE_ROTATION, translation)
    numeric = _numeric_jacobian(problem, TRUE_ROTATION, translation)
    np.testing.assert_allclose(jacobian, numeric, rtol=1e-6, atol=1e-6 * np.abs(jacobian).max())


def test_a_tag_model_off_its_plane_is_refused() -> None:
    model = tag_corners_in_tag_frame(TAG_SIZE) + np.array([0.0, 0.0, 0.01])
    with pytest.raises(ValueError, match=r"^the tag model must lie in its plane z = 0$"):
        TightProblem(model, np.zeros((4, 2)), LENSES["pinhole"], 0.5, np.empty((0, 3)), [], [])


def test_a_tiny_rotation_vector_gives_one_plus_its_cross_product_matrix() -> None:
    w = np.array([1e-13, -2e-13, 3e-13])
    skew = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    np.testing.assert_array_equal(rotation_exp(w) - np.eye(3), skew)
    # and a finite one is Rodrigues' rotation
    v = np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(rotation_exp(v), Rotation.from_rotvec(v).as_matrix(), atol=1e-15)


def _lm_iterates(problem: TightProblem, rotation, translation, n: int):
    """Levenberg–Marquardt as documented: damping 1e-6 of the normal equations' diagonal,
    ten times less (to 1e-9 at least) after a step that does not raise the cost, ten times
    more after one that does."""
    lam = 1e-6
    r, j = problem.linearise(rotation, translation)
    for _ in range(n):
        h = j.T @ j
        step = np.linalg.solve(h + lam * np.diag(np.diag(h)), -(j.T @ r))
        new_r, new_t = rotation_exp(step[3:]) @ rotation, translation + step[:3]
        r_new, j_new = problem.linearise(new_r, new_t)
        if r_new @ r_new <= r @ r:
            rotation, translation, r, j = new_r, new_t, r_new, j_new
            lam = max(lam / 10.0, 1e-9)
        else:
            lam *= 10.0
    return rotation, translation


def test_each_iteration_is_a_levenberg_marquardt_step_damped_from_1e_minus_6() -> None:
    problem = _problem(pixel_noise_px=2.0)
    start_r = Rotation.from_rotvec([0.3, 0.2, -0.25]).as_matrix() @ TRUE_ROTATION
    start_t = TRUE_TRANSLATION + np.array([0.05, -0.04, 0.1])
    for n in (1, 2, 3):
        solution = problem.solve(start_r, start_t, n, step_tol=0.0, cost_tol=-1.0)
        assert solution is not None and solution.iterations == n
        rotation, translation = _lm_iterates(problem, start_r, start_t, n)
        np.testing.assert_allclose(solution.translation, translation, rtol=0.0, atol=1e-14)
        np.testing.assert_allclose(solution.rotation, rotation, rtol=0.0, atol=1e-14)
        assert solution.cost == pytest.approx(problem.cost(rotation, translation), rel=1e-12)
    # no iteration: the start and its cost
    none = problem.solve(start_r, start_t, 0)
    assert none is not None and none.iterations == 0
    np.testing.assert_array_equal(none.translation, start_t)
    assert none.cost == pytest.approx(problem.cost(start_r, start_t), rel=1e-12)


class _EveryStepCostsMore(TightProblem):
    """A stand-in problem on which every step away from the start raises the cost."""

    def linearise(self, rotation, translation):
        r, j = super().linearise(rotation, translation)
        return (r if np.array_equal(translation, TRUE_TRANSLATION) else r + 10.0), j


def test_a_start_no_step_improves_is_returned_once_the_damping_passes_1e8() -> None:
    model = tag_corners_in_tag_frame(TAG_SIZE)
    # half a pixel off: the step from the truth is a real one (about a millimetre)
    pixels = LENSES["pinhole"].project((TRUE_ROTATION @ model.T).T + TRUE_TRANSLATION) + 0.5
    no_ranges = (np.empty((0, 3)), [], [])
    problem = _EveryStepCostsMore(model, pixels, LENSES["pinhole"], PIXEL_SIGMA, *no_ranges)
    solution = problem.solve(TRUE_ROTATION, TRUE_TRANSLATION, 100, step_tol=0.0, cost_tol=-1.0)
    # 1e-6 times ten per rejected step: 1e8 after 14, beyond it after 15
    assert solution is not None and solution.iterations == 15
    np.testing.assert_array_equal(solution.translation, TRUE_TRANSLATION)
    np.testing.assert_array_equal(solution.rotation, TRUE_ROTATION)


def test_a_step_below_step_tol_ends_the_solve() -> None:
    problem = _problem(pixel_noise_px=2.0)
    start_t = TRUE_TRANSLATION + np.array([0.02, 0.0, 0.0])
    # every step is below a metre: the first ends it, however much it lowered the cost
    solution = problem.solve(TRUE_ROTATION, start_t, 12, step_tol=1.0, cost_tol=-1.0)
    assert solution is not None and solution.iterations == 1
    assert solution.cost < 0.5 * problem.cost(TRUE_ROTATION, start_t)


def test_a_step_lowering_the_cost_by_less_than_cost_tol_ends_the_solve() -> None:
    problem = _problem(pixel_noise_px=0.5)
    minimum = problem.solve(TRUE_ROTATION, TRUE_TRANSLATION, 50, cost_tol=0.0)
    assert minimum is not None and 1.0 < minimum.cost
    # a micrometre off the minimum, the first step lowers the cost by about 1e-6
    near = minimum.translation + np.array([1e-6, 0.0, 0.0])
    assert 0.0 < problem.cost(minimum.rotation, near) - minimum.cost < 1e-4
    again = problem.solve(minimum.rotation, near, 12, step_tol=0.0)
    assert again is not None and again.iterations == 1


def test_sigmas_all_set_ten_times_too_small_stop_the_solve_where_the_right_ones_do() -> None:
    # 2 px of corner noise: the cost per residual exceeds 1 under either set of sigmas
    right = _problem(pixel_noise_px=2.0, pixel_sigma_px=0.5)
    small = _problem(pixel_noise_px=2.0, pixel_sigma_px=0.05, range_sigma_scale=0.1)
    start_r = Rotation.from_rotvec([0.2, -0.1, 0.15]).as_matrix() @ TRUE_ROTATION
    start_t = TRUE_TRANSLATION + np.array([0.03, 0.02, -0.05])
    a = right.solve(start_r, start_t, 50, step_tol=0.0)
    b = small.solve(start_r, start_t, 50, step_tol=0.0)
    assert a is not None and b is not None
    assert a.cost / right.m > 1.0
    assert a.iterations == b.iterations < 50
    assert b.cost == pytest.approx(100.0 * a.cost, rel=1e-9)
    np.testing.assert_allclose(a.translation, b.translation, atol=1e-12)


def test_the_euler_jacobian_maps_a_small_left_rotation_to_the_angles_it_changes() -> None:
    rng = np.random.default_rng(31)
    h = 1e-6
    for _ in range(50):
        angles = rng.uniform([-3.0, -1.4, -3.0], [3.0, 1.4, 3.0])  # yaw, pitch, roll
        rotation = Rotation.from_euler("ZYX", angles).as_matrix()
        numeric = np.empty((3, 3))
        for i in range(3):
            d = np.zeros(3)
            d[i] = h
            plus = euler_zyx_from_matrix(rotation_exp(d) @ rotation)
            minus = euler_zyx_from_matrix(rotation_exp(-d) @ rotation)
            numeric[:, i] = ((plus - minus + math.pi) % (2.0 * math.pi) - math.pi) / (2.0 * h)
        np.testing.assert_allclose(euler_jacobian(rotation), numeric, atol=1e-6)


# -- the estimator's inputs, starts and history (estimation/tight.py) ----------------------


def _level_view(rng_seed: int = 40, height: float = 1.2):
    """The exact measurements of a random pose at ``height`` (tight's synthetic scene)."""
    scene = SyntheticScene(LENSES["pinhole"], TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(rng_seed), height)
    return scene.measure(rotation, translation), rotation, translation


def test_starts_within_30_degrees_and_5_percent_of_the_depth_are_one_basin() -> None:
    depth = np.array([0.0, 0.0, 2.0])
    base = ("a", TRUE_ROTATION, depth)

    def turned(degrees: float) -> np.ndarray:
        return Rotation.from_euler("x", math.radians(degrees)).as_matrix() @ TRUE_ROTATION

    assert _same_basin(base, ("b", turned(29.0), depth + np.array([0.09, 0.0, 0.0])))
    assert not _same_basin(base, ("b", turned(31.0), depth))
    assert not _same_basin(base, ("b", turned(10.0), depth + np.array([0.11, 0.0, 0.0])))
    assert not _same_basin(base, ("b", turned(10.0), depth + np.array([0.0, 0.0, -0.11])))
    # the gap is a fraction of the first start's depth, along any axis
    assert _same_basin(base, ("b", turned(-29.0), depth + np.array([0.0, 0.06, -0.07])))


def test_agreeing_calibrations_move_no_principal_point_for_sensors_off_the_camera_plane() -> None:
    k = LENSES["distorted"]
    sensors = tof_positions_in_camera_frame() + np.array([0.0, 0.0, 0.01])
    ranges = np.linspace(0.1, 3.0, 30)
    # each pad's touch point lies its range along the axis from its sensor
    samples = [
        np.column_stack([ranges, k.project(s + np.outer(ranges, [0.0, 0.0, 1.0]))]) for s in sensors
    ]
    offset = principal_point_offset(k, sensors, TofCameraCalibration(samples))
    np.testing.assert_allclose(offset, 0.0, atol=1e-9)


def test_a_calibration_of_no_sensors_moves_no_principal_point() -> None:
    none = np.empty((0, 3))
    estimator = TightEstimator(
        intrinsics=LENSES["pinhole"],
        tag_size=TAG_SIZE,
        tof_positions_c=none,
        tof_calibration=TofCameraCalibration([]),
    )
    np.testing.assert_array_equal(estimator.principal_point_offset_px, [0.0, 0.0])
    m, _, translation = _level_view()
    reading = RangeReading(0.0, np.empty(0), np.empty(0, bool))
    estimate = estimator.estimate(m.frame, reading)
    assert estimate.valid and estimate.extras["ranges_used"] == 0
    assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_no_sensors_or_touch_points_behind_the_camera_give_an_offset_of_exactly_zero() -> None:
    k = LENSES["distorted"]
    none = principal_point_offset(k, np.empty((0, 3)), TofCameraCalibration([]))
    np.testing.assert_array_equal(none, [0.0, 0.0])
    # every touch point behind the camera: projected to NaN, no sample is compared
    sensors = tof_positions_in_camera_frame() - np.array([0.0, 0.0, 5.0])
    ranges = np.linspace(0.1, 3.0, 30)
    samples = [np.column_stack([ranges, np.full((30, 2), 300.0)]) for _ in sensors]
    behind = principal_point_offset(k, sensors, TofCameraCalibration(samples))
    np.testing.assert_array_equal(behind, [0.0, 0.0])


@pytest.mark.parametrize(
    ("change", "used", "dropped"),
    [
        ("flags_as_integers", 3, 0),
        ("invalid_flag_on_a_number", 3, 0),
        ("zero_range", 3, 0),
        ("range_at_the_1000_m_bound", 3, 1),
        ("flags_fewer_than_ranges", 0, 0),
    ],
)
def test_only_ranges_flagged_valid_above_0_and_up_to_1000_m_enter_the_cost(
    change: str, used: int, dropped: int
) -> None:
    m, _, translation = _level_view()
    ranges, valid = m.ranges.ranges.copy(), m.ranges.valid.copy()
    assert valid.all()
    if change == "flags_as_integers":
        valid = np.array([1, 1, 0, 1])
    elif change == "invalid_flag_on_a_number":
        valid[2] = False
        ranges[2] += 0.5
    elif change == "zero_range":
        ranges[2] = 0.0
    elif change == "range_at_the_1000_m_bound":
        ranges[2] = 1e3  # taken, then dropped by the gate
    else:
        valid = valid[:3]
    estimate = tight().estimate(m.frame, RangeReading(0.0, ranges, valid))
    assert estimate.valid, estimate.reason
    assert estimate.extras["ranges_used"] == used
    assert estimate.extras["ranges_dropped"] == dropped
    assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_with_three_corners_the_larger_of_the_two_sigmas_weighs_them() -> None:
    m, _, translation = _level_view()
    corners = m.frame.detections[0].corners_px.copy()
    corners[1] = np.nan
    frame = CameraFrame(0.0, (TagDetection(0, corners),))
    estimate = tight(pixel_sigma_axes_px=0.9).estimate(frame, m.ranges)
    assert estimate.valid and estimate.extras["corners_used"] == 3
    assert estimate.extras["pixel_sigma_px"] == 0.9
    assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_three_corners_and_three_ranges_start_from_the_ranges_plane() -> None:
    m, _, translation = _level_view()
    corners = m.frame.detections[0].corners_px.copy()
    corners[1] = np.nan
    valid = m.ranges.valid.copy()
    valid[3] = False
    reading = RangeReading(0.0, np.where(valid, m.ranges.ranges, np.nan), valid)
    estimate = tight().estimate(CameraFrame(0.0, (TagDetection(0, corners),)), reading)
    assert estimate.valid, estimate.reason
    assert estimate.extras["start"] == "plane" and estimate.extras["ranges_used"] == 3
    assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_previous_first_refines_the_previous_pose_from_the_same_instant_to_the_timeout() -> None:
    m, _, _ = _level_view()
    estimator = tight(previous_start="first")  # history_timeout_s 0.5

    def at(t: float, n_ranges: int = 4, n_corners: int = 4) -> str:
        corners = m.frame.detections[0].corners_px.copy()
        corners[n_corners:] = np.nan
        valid = m.ranges.valid.copy()
        valid[n_ranges:] = False
        frame = CameraFrame(t, (TagDetection(0, corners),))
        estimate = estimator.estimate(frame, RangeReading(t, m.ranges.ranges, valid))
        assert estimate.valid, estimate.reason
        if estimate.extras["start"] == "previous":  # one minimum, no choice by history
            assert estimate.extras["ambiguity_ratio"] == 0.0
            assert estimate.extras["chosen_by_history"] is False
        return estimate.extras["start"]

    assert at(0.0) != "previous"  # no previous estimate yet
    assert at(0.0) == "previous"  # the same instant again
    assert at(0.5) == "previous"  # exactly the timeout later
    assert at(1.0, n_ranges=3) == "previous"  # three ranges are enough
    assert at(1.5, n_ranges=2) != "previous"  # two are not
    assert at(2.0, n_corners=3) != "previous"  # nor three corners
    assert at(2.6) != "previous"  # beyond the timeout


@pytest.mark.parametrize("n_ranges", [4, 3])
def test_the_plane_start_is_the_pose_on_exact_corners_and_ranges(n_ranges: int) -> None:
    # sensors 1 cm ahead of the camera's plane, the deck 0.8 m below
    k = CameraIntrinsics(cx=250.0, cy=262.0)
    sensors = tof_positions_in_camera_frame() + np.array([0.0, 0.0, 0.01])
    estimator = TightEstimator(intrinsics=k, tag_size=TAG_SIZE, tof_positions_c=sensors)
    rotation = Rotation.from_euler("xyz", [0.2, -0.1, 2.0]).as_matrix()
    translation = np.array([0.1, -0.05, 0.8])
    model = tag_corners_in_tag_frame(TAG_SIZE)
    corners = k.project((rotation @ model.T).T + translation)
    normal = rotation[:, 2]
    ranges = (translation - sensors) @ normal / normal[2]
    use = np.arange(4) < n_ranges
    start = estimator._plane_start(corners, model, ranges[use], sensors[use])
    assert start is not None
    np.testing.assert_allclose(start[0], rotation, atol=1e-9)
    np.testing.assert_allclose(start[1], translation, atol=1e-9)


def test_a_plane_some_corner_rays_meet_behind_the_camera_gives_no_start() -> None:
    estimator = tight()
    model = tag_corners_in_tag_frame(TAG_SIZE)
    # a plane falling steeply to +x (in front of the camera on the optical axis): the rays
    # of the corners left of u = 163 px meet it behind the camera
    corners = np.array([[100.0, 200.0], [300.0, 200.0], [300.0, 260.0], [100.0, 260.0]])
    sensors = estimator.tof_positions_c
    ranges = 0.5 - 5.0 * sensors[:, 0]
    assert (ranges > 0.0).all()
    assert estimator._plane_start(corners, model, ranges, sensors) is None


def _noisy_view(seed: int, height: float):
    """A random pose of the 12 cm tag at ``height`` seen with 0.5 px of corner noise and
    VL53L1X ranges (``noisy``), through the pinhole lens."""
    scene = SyntheticScene(LENSES["pinhole"], TAG_SIZE)
    rng = np.random.default_rng(seed)
    rotation, translation = random_pose(rng, height)
    frame, reading = noisy(scene, rotation, translation, rng)
    return frame, reading, rotation, translation


def _ambiguous_view():
    """A 12 cm tag 3 m away with 0.5 px of corner noise (seed 42) whose two IPPE minima
    fit the corners about equally well: without ranges the better one is 41° off."""
    return _noisy_view(42, 3.0)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(Rotation.from_matrix(a @ b.T).magnitude())


def _at(frame: CameraFrame, reading: RangeReading, t: float):
    return dataclasses.replace(frame, timestamp=t), dataclasses.replace(reading, timestamp=t)


def test_without_ranges_a_recent_previous_estimate_picks_between_two_close_minima() -> None:
    frame, reading, rotation, translation = _ambiguous_view()
    none = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    estimator = tight()
    alone = estimator.estimate(frame, none)
    assert alone.valid and alone.extras["start"] == "ippe0"
    assert _angle_deg(alone.rotation, rotation) > 30.0
    ratio = alone.extras["ambiguity_ratio"]
    assert 0.8 < ratio < 0.95 and alone.extras["chosen_by_history"] is False
    # the truth as the previous estimate, from the same instant to the timeout before
    for previous_s, now_s in ((10.0, 10.0), (10.0, 10.5)):
        estimator._previous = (previous_s, rotation, translation)
        chosen = estimator.estimate(*_at(frame, none, now_s))
        assert chosen.valid and chosen.extras["chosen_by_history"] is True
        assert chosen.extras["start"] == "ippe1"
        assert chosen.extras["ambiguity_ratio"] == pytest.approx(ratio, rel=1e-9)
        assert _angle_deg(chosen.rotation, rotation) < 10.0
        assert chosen.extras["cost"] > alone.extras["cost"]
    # the better fit as the previous estimate: it stays, and history changed nothing
    estimator._previous = (10.0, alone.rotation, alone.translation)
    kept = estimator.estimate(*_at(frame, none, 10.2))
    assert kept.extras["chosen_by_history"] is False and kept.extras["start"] == "ippe0"
    np.testing.assert_allclose(kept.rotation, alone.rotation, atol=1e-12)
    # older than the timeout: the better fit again
    estimator._previous = (10.0, rotation, translation)
    late = estimator.estimate(*_at(frame, none, 10.6))
    assert late.extras["chosen_by_history"] is False
    np.testing.assert_allclose(late.rotation, alone.rotation, atol=1e-12)
    # with the ranges, the cost alone decides, whatever the previous estimate
    estimator._previous = (10.0, alone.rotation, alone.translation)
    ranged = estimator.estimate(*_at(frame, reading, 10.1))
    assert ranged.extras["chosen_by_history"] is False
    assert _angle_deg(ranged.rotation, rotation) < 10.0


def test_the_lower_of_two_minima_is_kept_when_ippes_second_pose_reaches_it() -> None:
    # seed 1841 at 2 m, no ranges: IPPE's first pose fits the corners better, but refined
    # its minimum costs 0.6 % more than the one refined from the second (and 32° off the
    # truth, where the other is 9° off); the kept minimum is the cheaper, whatever its name
    frame, _, rotation, _ = _noisy_view(1841, 2.0)
    none = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    estimate = tight().estimate(frame, none)
    assert estimate.valid and estimate.extras["start"] == "ippe1"
    # the ratio is sqrt(kept cost / other cost): below 1, the kept minimum is the lower
    assert 0.99 < estimate.extras["ambiguity_ratio"] < 1.0
    assert estimate.extras["chosen_by_history"] is False
    assert _angle_deg(estimate.rotation, rotation) < 15.0


def test_one_minimum_is_unambiguous_however_many_starts_reach_it() -> None:
    m, _, translation = _level_view()
    none = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    for reading in (m.ranges, none):
        # the flipped IPPE start costs far more than the margin: one basin, one minimum
        estimate = tight().estimate(m.frame, reading)
        assert estimate.valid and estimate.extras["start"] in ("ippe0", "plane")
        assert estimate.extras["ambiguity_ratio"] == 0.0
        assert estimate.extras["chosen_by_history"] is False
        # every start refined: those reaching the exact pose count once, and the flipped
        # minimum fits far worse
        every = tight(start_cost_margin=math.inf).estimate(m.frame, reading)
        assert every.valid and every.extras["ambiguity_ratio"] < 1e-6
        assert every.extras["chosen_by_history"] is False
        for e in (estimate, every):
            assert np.linalg.norm(e.translation - translation) < 1e-6


def test_three_corners_without_ranges_start_from_a_recent_previous_estimate() -> None:
    m, rotation, translation = _level_view()
    none = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    corners = m.frame.detections[0].corners_px.copy()
    corners[2] = np.nan
    three = CameraFrame(0.0, (TagDetection(0, corners),))
    estimator = tight()
    assert estimator.estimate(*_at(three, none, 10.0)).reason == "no_initial_pose"
    assert estimator.estimate(*_at(m.frame, none, 10.0)).valid  # four corners: IPPE
    for now_s in (10.0, 10.5, 11.0):  # the same instant, then each the timeout later
        estimate = estimator.estimate(*_at(three, none, now_s))
        assert estimate.valid, estimate.reason
        assert estimate.extras["start"] == "previous" and estimate.extras["corners_used"] == 3
        assert np.linalg.norm(estimate.translation - translation) < 1e-6
        assert _angle_deg(estimate.rotation, rotation) < 1e-4
    assert estimator.estimate(*_at(three, none, 11.6)).reason == "no_initial_pose"


def test_of_two_detections_of_the_tag_the_one_with_fewer_bit_errors_is_used() -> None:
    m, _, translation = _level_view()
    true = m.frame.detections[0].corners_px
    wrong = true + np.array([[3.0, 0.0], [0.0, 3.0], [-3.0, 0.0], [0.0, -3.0]])
    # a detection without a hamming distance counts as one decoded without error
    plain = types.SimpleNamespace(tag_id=0, corners_px=true)
    for detections in (
        (TagDetection(0, wrong, hamming=1), TagDetection(0, true, hamming=0)),
        (TagDetection(0, wrong, hamming=1), plain),
    ):
        estimate = tight().estimate(CameraFrame(0.0, detections), m.ranges)
        assert estimate.valid, estimate.reason
        assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_corners_given_as_whole_pixels_are_taken_as_those_pixels() -> None:
    scene = SyntheticScene(LENSES["distorted"], TAG_SIZE)
    rotation, translation = random_pose(np.random.default_rng(41), 1.2)
    m = scene.measure(rotation, translation)
    whole = np.round(m.frame.detections[0].corners_px).astype(int)
    as_int = tight("distorted").estimate(CameraFrame(0.0, (TagDetection(0, whole),)), m.ranges)
    as_float = tight("distorted").estimate(
        CameraFrame(0.0, (TagDetection(0, whole.astype(float)),)), m.ranges
    )
    assert as_int.valid and as_float.valid
    np.testing.assert_allclose(as_int.as_vector(), as_float.as_vector(), rtol=0.0, atol=1e-12)


@pytest.mark.parametrize(
    "reason",
    [
        "no_detection",
        "bad_corners",
        "no_initial_pose",
        "non_finite_result",
        "reprojection_error",
        "singular_information",
        "covariance_not_finite",
        "covariance_not_positive",
        "refused_by_the_final_check",
    ],
)
def test_each_invalid_estimate_is_tights_at_its_frames_time_with_its_reason(
    reason: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    m, _, _ = _level_view()
    frame, reading = _at(m.frame, m.ranges, 7.25)
    estimator = tight("distorted")
    if reason == "no_detection":
        frame = CameraFrame(7.25, ())
    elif reason == "bad_corners":
        estimator._undistorter = _NanUndistorter()
    elif reason == "no_initial_pose":
        corners = m.frame.detections[0].corners_px.copy()
        corners[0] = np.nan
        frame = CameraFrame(7.25, (TagDetection(0, corners),))
        reading = RangeReading(7.25, np.full(4, np.nan), np.zeros(4, bool))
    elif reason == "non_finite_result":
        monkeypatch.setattr(estimator, "_solve_all", lambda *args: None)
    elif reason == "reprojection_error":
        estimator = tight("distorted", max_reprojection_error_px=1e-3)
        shifted = m.frame.detections[0].corners_px + np.array([[1.0, 0.0], [0, 0], [0, 0], [0, 0]])
        frame = CameraFrame(7.25, (TagDetection(0, shifted),))
    elif reason == "singular_information":

        def singular(matrix: np.ndarray) -> np.ndarray:
            raise np.linalg.LinAlgError("singular matrix")

        monkeypatch.setattr(np.linalg, "inv", singular)
    elif reason == "covariance_not_finite":
        monkeypatch.setattr(np.linalg, "inv", lambda matrix: np.full((6, 6), np.nan))
    elif reason == "covariance_not_positive":
        monkeypatch.setattr(np.linalg, "inv", lambda matrix: np.zeros((6, 6)))
    else:
        # a stand-in determinant: the final check (finish_pose) refuses the rotation
        monkeypatch.setattr(geometry, "det3", lambda matrix: 2.0)
    expected = {
        "covariance_not_finite": "singular_information",
        "covariance_not_positive": "singular_information",
        "refused_by_the_final_check": "non_finite_result",
    }.get(reason, reason)
    estimate = estimator.estimate(frame, reading)
    assert not estimate.valid
    assert (estimate.method, estimate.timestamp, estimate.reason) == ("tight", 7.25, expected)


class _NanUndistorter:
    """A stand-in undistortion that hands back pixels that are not finite."""

    active = True

    def __call__(self, pixels: np.ndarray) -> np.ndarray:
        return np.full_like(np.asarray(pixels, dtype=float), np.nan)


def test_three_corners_are_degenerate_when_their_triangle_spans_less_than_the_minimum() -> None:
    m, _, _ = _level_view()
    corners = m.frame.detections[0].corners_px.copy()
    corners[1] = np.nan
    a, b, c = corners[[0, 2, 3]]
    area = 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    frame = CameraFrame(0.0, (TagDetection(0, corners),))
    assert tight(min_corner_area_px=0.999 * area).estimate(frame, m.ranges).valid
    too_small = tight(min_corner_area_px=1.001 * area).estimate(frame, m.ranges)
    assert too_small.reason == "degenerate_corners"


def test_two_ranges_off_the_deck_are_both_dropped_and_counted() -> None:
    m, _, translation = _level_view()
    ranges = m.ranges.ranges.copy()
    ranges[1] += 0.3
    ranges[3] += 0.2
    reading = RangeReading(0.0, ranges, m.ranges.valid)
    estimate = tight().estimate(m.frame, reading)
    assert estimate.valid
    assert estimate.extras["ranges_dropped"] == 2 and estimate.extras["ranges_used"] == 2
    assert np.linalg.norm(estimate.translation - translation) < 1e-6
    # with three corners (no IPPE start), the pose solved before the drop is the start
    corners = m.frame.detections[0].corners_px.copy()
    corners[0] = np.nan
    three = tight().estimate(CameraFrame(0.0, (TagDetection(0, corners),)), reading)
    assert three.valid and three.extras["start"] == "gated"
    assert three.extras["ranges_dropped"] == 2
    assert np.linalg.norm(three.translation - translation) < 1e-6


def test_after_dropping_a_range_that_pulled_the_pose_off_ippe_starts_are_solved_again() -> None:
    # seed 146 at 3 m, the fourth sensor reading 40 cm short (a ray meeting an obstacle)
    frame, reading, rotation, _ = _noisy_view(146, 3.0)
    ranges = reading.ranges.copy()
    ranges[3] -= 0.4
    short = RangeReading(0.0, ranges, reading.valid)
    # kept, the range pulls the solution 59° off
    kept = tight(range_gate_sigma=1e3).estimate(frame, short)
    assert kept.valid and kept.extras["ranges_dropped"] == 0
    assert _angle_deg(kept.rotation, rotation) > 30.0
    # dropped, the pose is solved again from IPPE's starts too, and IPPE's second one wins
    # (solved again from the pulled solution alone, it stays 40° off at a cost of 537)
    estimate = tight().estimate(frame, short)
    assert estimate.valid and estimate.extras["ranges_dropped"] == 1
    assert estimate.extras["start"] == "ippe1" and estimate.extras["cost"] < 10.0
    assert _angle_deg(estimate.rotation, rotation) < 2.0


def test_the_reprojection_error_is_the_rms_pixel_distance_of_the_corners_alone() -> None:
    scene = SyntheticScene(LENSES["distorted"], TAG_SIZE)
    rng = np.random.default_rng(43)
    rotation, translation = random_pose(rng, 1.5)
    frame, reading = noisy(scene, rotation, translation, rng)
    estimate = tight("distorted").estimate(frame, reading)
    assert estimate.valid and estimate.extras["ranges_used"] == 4
    model = tag_corners_in_tag_frame(TAG_SIZE)
    projected = LENSES["distorted"].project((estimate.rotation @ model.T).T + estimate.translation)
    distances = np.linalg.norm(projected - frame.detections[0].corners_px, axis=1)
    rms = math.sqrt(float(np.mean(distances**2)))
    assert estimate.extras["reprojection_error_px"] == pytest.approx(rms, rel=1e-9)


def test_a_valid_estimate_reports_its_fit_and_its_covariance_is_the_inverse_information() -> None:
    scene = SyntheticScene(LENSES["distorted"], TAG_SIZE)
    rng = np.random.default_rng(44)
    rotation, translation = random_pose(rng, 1.5)
    frame, reading = noisy(scene, rotation, translation, rng)
    estimate = tight("distorted").estimate(frame, reading)
    assert estimate.valid
    assert set(estimate.extras) == {
        "cost",
        "reprojection_error_px",
        "pixel_sigma_px",
        "ranges_used",
        "ranges_dropped",
        "corners_used",
        "start",
        "iterations",
        "ambiguity_ratio",
        "chosen_by_history",
    }
    problem = TightProblem(
        tag_corners_in_tag_frame(TAG_SIZE),
        frame.detections[0].corners_px,
        LENSES["distorted"],
        PIXEL_SIGMA,
        tof_positions_in_camera_frame(),
        reading.ranges,
        TOF.sigma(reading.ranges),
    )
    residuals, jacobian = problem.linearise(estimate.rotation, estimate.translation)
    assert estimate.extras["cost"] == pytest.approx(float(residuals @ residuals), rel=1e-12)
    assert 1 <= estimate.extras["iterations"] <= 12
    to_pose = np.eye(6)
    to_pose[3:, 3:] = euler_jacobian(estimate.rotation)
    covariance = to_pose @ np.linalg.inv(jacobian.T @ jacobian) @ to_pose.T
    np.testing.assert_allclose(estimate.covariance, covariance, rtol=1e-9, atol=0.0)


def test_bad_settings_are_refused_naming_the_argument() -> None:
    k = LENSES["pinhole"]
    with pytest.raises(ConfigError) as refused:
        TightEstimator(intrinsics=k, tag_size=0.0)
    assert refused.value.key == "tag_size"
    assert refused.value.detail == "0.0 is out of range; allowed (0.0, inf]"
    bad = tof_positions_in_camera_frame()
    bad[1, 0] = np.nan
    with pytest.raises(ConfigError) as refused:
        TightEstimator(intrinsics=k, tag_size=TAG_SIZE, tof_positions_c=bad)
    assert refused.value.key == "tof_positions_c"
    assert refused.value.detail == "sensor positions must be finite"
    three = TofCameraCalibration.exact(k, tof_positions_in_camera_frame()[:3], 0.04, 4.0)
    with pytest.raises(ConfigError) as refused:
        TightEstimator(intrinsics=k, tag_size=TAG_SIZE, tof_calibration=three)
    assert refused.value.key == "tof_calibration"
    # no calibration: the principal point stays where it is
    alone = TightEstimator(intrinsics=k, tag_size=TAG_SIZE)
    np.testing.assert_array_equal(alone.principal_point_offset_px, [0.0, 0.0])
    assert (alone.intrinsics.cx, alone.intrinsics.cy) == (k.cx, k.cy)


def test_sensors_in_a_line_give_no_plane_start_and_no_exception() -> None:
    m, _, _ = _level_view()
    line = np.array([[-0.06, 0.0, 0.0], [-0.02, 0.0, 0.0], [0.02, 0.0, 0.0], [0.06, 0.0, 0.0]])
    estimator = TightEstimator(
        intrinsics=LENSES["pinhole"], tag_size=TAG_SIZE, tof_positions_c=line
    )
    corners = m.frame.detections[0].corners_px.copy()
    corners[0] = np.nan
    ranges = RangeReading(0.0, np.full(4, 1.2), np.ones(4, bool))
    estimate = estimator.estimate(CameraFrame(0.0, (TagDetection(0, corners),)), ranges)
    assert estimate.reason == "no_initial_pose"


def test_ranges_and_flags_given_as_a_column_are_read_as_the_four_readings() -> None:
    m, _, translation = _level_view()
    column = RangeReading(0.0, m.ranges.ranges.reshape(-1, 1), m.ranges.valid.reshape(-1, 1))
    estimate = tight().estimate(m.frame, column)
    assert estimate.valid and estimate.extras["ranges_used"] == 4
    assert np.linalg.norm(estimate.translation - translation) < 1e-6


def test_a_start_cost_margin_of_zero_refines_the_cheapest_start_alone() -> None:
    m, _, translation = _level_view()
    estimate = tight(start_cost_margin=0.0).estimate(m.frame, m.ranges)
    assert estimate.valid, estimate.reason
    assert np.linalg.norm(estimate.translation - translation) < 1e-6
