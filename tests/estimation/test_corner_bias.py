"""The tag detector's corner offset model: its geometry, its fit and its correction."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimation.camera_model import CameraIntrinsics
from estimation.corner_bias import (
    CornerBias,
    CornerBiasFit,
    corner_design,
    edge_axis_alignment,
    fit_corner_bias,
)
from estimation.frames import tag_corners_in_tag_frame
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.synthetic import SyntheticScene
from estimation.tight import TightEstimator
from estimation.tight_config import TightConfig
from estimation.types import CameraFrame, RangeReading, TagDetection

CAMERA = CameraIntrinsics()
TAG_SIZE = 0.3
#: the realistic camera's measured offset (configs/calibration/realistic/intrinsics.json)
REALISTIC = CornerBias(-0.017, -0.105, -4.96)


def tag_pixels(rng: np.random.Generator, height: float) -> np.ndarray:
    rotation = Rotation.from_euler(
        "zyx", [rng.uniform(-np.pi, np.pi), *rng.uniform(-0.1, 0.1, 2)]
    ).as_matrix()
    translation = np.array([*rng.uniform(-0.2, 0.2, 2), height])
    return CAMERA.project(tag_corners_in_tag_frame(TAG_SIZE) @ rotation.T + translation)


def test_an_axis_aligned_square_shrunk_by_its_edges_moves_each_corner_diagonally() -> None:
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    moved = CornerBias(a_px=-0.5).displacement(square)
    # each edge moves 0.5 px inwards: each corner by (0.5, 0.5) towards the centre
    np.testing.assert_allclose(moved, [[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    # sin²(2φ) is 0 along the pixel axes and 1 on the diagonals; c scales with 1/L
    np.testing.assert_allclose(CornerBias(b_px=-0.5).displacement(square), 0.0, atol=1e-12)
    diamond = np.array([[5.0, 0.0], [10.0, 5.0], [5.0, 10.0], [0.0, 5.0]])
    shrunk = CornerBias(b_px=-0.5).displacement(diamond)
    np.testing.assert_allclose(np.linalg.norm(shrunk, axis=1), 0.5 * np.sqrt(2.0))
    np.testing.assert_allclose(CornerBias(c_px2=-5.0).displacement(square), moved)


def test_the_fit_recovers_a_known_offset_and_the_noise_left_over() -> None:
    rng = np.random.default_rng(3)
    true, detected = [], []
    for _ in range(200):
        pixels = tag_pixels(rng, rng.uniform(0.8, 3.5))
        true.append(pixels)
        shift = rng.normal(0.0, 0.3, 2)  # a principal-point error: not an edge offset
        noise = rng.normal(0.0, 0.05, (4, 2))
        detected.append(pixels + REALISTIC.displacement(pixels) + shift + noise)
    fit = fit_corner_bias(detected, true)
    assert fit.bias.a_px == pytest.approx(REALISTIC.a_px, abs=0.01)
    assert fit.bias.b_px == pytest.approx(REALISTIC.b_px, abs=0.01)
    assert fit.bias.c_px2 == pytest.approx(REALISTIC.c_px2, abs=0.6)
    assert fit.sigma_px == pytest.approx(0.05, rel=0.1)
    assert fit.sigma_uncorrected_px > fit.sigma_px
    assert fit.sigma_diagonal_px == pytest.approx(0.05, rel=0.15)
    assert fit.sigma_axes_px == pytest.approx(0.05, rel=0.15)
    assert CornerBiasFit.from_dict(fit.as_dict()) == fit


def test_the_fit_finds_noisier_corners_where_the_edges_lie_along_the_pixel_axes() -> None:
    rng = np.random.default_rng(6)
    true, detected = [], []
    for _ in range(400):
        pixels = tag_pixels(rng, rng.uniform(0.8, 3.5))
        sigma = np.sqrt(0.04**2 + (0.12**2 - 0.04**2) * edge_axis_alignment(pixels))
        true.append(pixels)
        detected.append(pixels + REALISTIC.displacement(pixels) + rng.normal(0, sigma, (4, 2)))
    fit = fit_corner_bias(detected, true)
    assert fit.sigma_diagonal_px == pytest.approx(0.04, abs=0.01)
    assert fit.sigma_axes_px == pytest.approx(0.12, rel=0.1)
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    assert edge_axis_alignment(square) == pytest.approx(1.0)
    assert edge_axis_alignment(square @ np.array([[1, 1], [-1, 1]]) / np.sqrt(2)) < 1e-12
    assert np.isnan(edge_axis_alignment(np.zeros((4, 2))))


def test_tight_weights_each_frame_by_its_edges_angle() -> None:
    """With both ends of the noise model set, an axis-aligned tag's corners are weighted
    by the axes' sigma and a diagonal one's by the diagonals'."""
    scene = SyntheticScene(CAMERA, TAG_SIZE)
    no_ranges = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    settings = TightConfig(pixel_sigma_px=0.05, pixel_sigma_axes_px=0.1)
    sigmas = []
    for yaw in (0.0, np.pi / 4.0):
        rotation = Rotation.from_euler("z", yaw).as_matrix()
        m = scene.measure(rotation, np.array([0.0, 0.0, 2.0]))
        estimator = TightEstimator(intrinsics=CAMERA, tag_size=TAG_SIZE, config=settings)
        sigmas.append(estimator.estimate(m.frame, no_ranges).extras["pixel_sigma_px"])
    np.testing.assert_allclose(sigmas, [0.1, 0.05], atol=1e-5)  # perspective: nearly diagonal


def test_the_per_frame_displacement_equals_the_fits_design() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        pixels = tag_pixels(rng, rng.uniform(0.8, 3.5))
        design = corner_design(pixels)
        assert design is not None
        theta = np.array([REALISTIC.a_px, REALISTIC.b_px, REALISTIC.c_px2])
        np.testing.assert_allclose(REALISTIC.displacement(pixels), design @ theta, atol=1e-12)


def test_correcting_detected_corners_gives_the_true_ones_back() -> None:
    rng = np.random.default_rng(4)
    for _ in range(20):
        pixels = tag_pixels(rng, rng.uniform(0.8, 3.5))
        detected = pixels + REALISTIC.displacement(pixels)
        # computed on the detected quadrilateral: what is left is second order in the
        # offset, under 1 % of it
        np.testing.assert_allclose(REALISTIC.correct(detected), pixels, atol=2e-3)
        assert np.abs(detected - pixels).max() > 0.05


def test_degenerate_or_missing_corners_are_left_as_they_are() -> None:
    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    assert corner_design(line) is None
    np.testing.assert_array_equal(REALISTIC.correct(line), line)
    missing = np.array([[0.0, 0.0], [10.0, 0.0], [np.nan, np.nan], [0.0, 10.0]])
    np.testing.assert_array_equal(REALISTIC.correct(missing), missing)
    with pytest.raises(ValueError, match="3 usable views"):
        fit_corner_bias([line], [line])


def test_tight_with_the_offset_configured_removes_the_distance_bias_it_causes() -> None:
    """A tag that looks 0.1 px smaller per edge reads about 3 mm further away at 2 m;
    with the measured offset configured, tight lands on the true pose."""
    scene = SyntheticScene(CAMERA, TAG_SIZE)
    rotation = Rotation.from_euler("zyx", [0.3, 0.02, -0.03]).as_matrix()
    translation = np.array([0.05, -0.03, 2.0])
    m = scene.measure(rotation, translation)
    pixels = m.true_corners_px + REALISTIC.displacement(m.true_corners_px)
    frame = CameraFrame(0.0, (TagDetection(0, pixels),))
    no_ranges = RangeReading(0.0, np.full(4, np.nan), np.zeros(4, bool))
    plain = TightEstimator(intrinsics=CAMERA, tag_size=TAG_SIZE, config=TightConfig())
    assert plain.estimate(frame, no_ranges).translation[2] - translation[2] > 2e-3
    bias = (REALISTIC.a_px, REALISTIC.b_px, REALISTIC.c_px2)
    fixed = TightEstimator(
        intrinsics=CAMERA, tag_size=TAG_SIZE, config=TightConfig(corner_bias_px=bias)
    )
    estimate = fixed.estimate(frame, no_ranges)
    assert np.linalg.norm(estimate.translation - translation) < 2e-5


def test_tight_config_rejects_a_bad_offset_naming_the_key() -> None:
    with pytest.raises(ValueError, match="corner_bias_px"):
        TightConfig(corner_bias_px=(0.1, 0.2))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="corner_bias_px"):
        TightConfig(corner_bias_px=(0.1, np.nan, 0.0))


def test_the_intrinsics_file_keeps_the_tag_corner_fit(tmp_path) -> None:
    fit = CornerBiasFit(REALISTIC, 0.068, 0.19, 240, 0.062, 0.073)
    result = IntrinsicsCalibrationResult(
        K=np.eye(3), dist=np.zeros(5), rms_reprojection_error=0.1,
        per_view_errors=np.zeros(2), image_size=(512, 512), tag_corners=fit.as_dict(),
    )  # fmt: skip
    path = tmp_path / "intrinsics.json"
    result.save(path)
    loaded = IntrinsicsCalibrationResult.load(path)
    assert CornerBiasFit.from_dict(loaded.tag_corners or {}) == fit
    # a file without the block (made before the tag rig) still loads
    doc = json.loads(path.read_text())
    del doc["tag_corners"]
    path.write_text(json.dumps(doc))
    assert IntrinsicsCalibrationResult.load(path).tag_corners is None


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=8, max_size=8))
def test_fuzzed_corners_never_raise_and_stay_finite_where_they_were(values) -> None:
    corners = np.array(values).reshape(4, 2)
    corrected = REALISTIC.correct(corners)
    assert corrected.shape == (4, 2)
    finite = np.isfinite(corners)
    # a correction is applied only to a finite quadrilateral, and is finite (or it is skipped)
    assert np.array_equal(np.isfinite(corrected), finite) or not finite.all()
    if not finite.all():
        np.testing.assert_array_equal(corrected, corners)
