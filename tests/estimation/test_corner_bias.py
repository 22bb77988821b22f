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


def _outward_normals(quad: np.ndarray) -> np.ndarray:
    """Each edge's (corner i to i+1) unit normal pointing out of the quadrilateral."""
    edge = np.roll(quad, -1, axis=0) - quad
    area2 = np.sum(
        quad[:, 0] * np.roll(quad, -1, axis=0)[:, 1] - np.roll(quad, -1, axis=0)[:, 0] * quad[:, 1]
    )
    normal = np.column_stack([edge[:, 1], -edge[:, 0]]) / np.linalg.norm(edge, axis=1)[:, None]
    return normal if area2 > 0.0 else -normal


def _turned(quad: np.ndarray, degrees: float) -> np.ndarray:
    angle = np.radians(degrees)
    return quad @ np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]).T


SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
#: a trapezoid turned a little: its edges' midpoints lie off their normals through the centre
TRAPEZOID = _turned(np.array([[0.0, 0.0], [10.0, 0.0], [8.0, 6.0], [2.0, 6.0]]), 5.0)
QUADRILATERALS = {
    "square": SQUARE,
    "diamond": _turned(SQUARE, 45.0),
    "trapezoid": TRAPEZOID,
    "trapezoid wound the other way": TRAPEZOID[::-1].copy(),
    "half-pixel square": 0.05 * SQUARE,
    "trapezoid off the image's diagonal": TRAPEZOID + np.array([450.0, 30.0]),
}


@pytest.mark.parametrize("name", QUADRILATERALS)
def test_each_edge_moves_out_by_its_offset_for_any_winding_size_or_place_in_the_image(
    name: str,
) -> None:
    quad = QUADRILATERALS[name]
    design = corner_design(quad)
    assert design is not None
    normal = _outward_normals(quad)
    edge = np.roll(quad, -1, axis=0) - quad
    length = np.linalg.norm(edge, axis=1)
    sin2 = (2.0 * edge[:, 0] * edge[:, 1] / length**2) ** 2
    for theta, offset in (((1, 0, 0), np.ones(4)), ((0, 1, 0), sin2), ((0, 0, 1), 1.0 / length)):
        moved = design @ np.array(theta, dtype=float)
        # corner i is on edges i-1 and i: both lie `offset` further out along their normals
        np.testing.assert_allclose(np.sum(normal * moved, axis=1), offset, atol=1e-9)
        np.testing.assert_allclose(
            np.sum(np.roll(normal, 1, axis=0) * moved, axis=1), np.roll(offset, 1), atol=1e-9
        )
        np.testing.assert_allclose(CornerBias(*theta).displacement(quad), moved, atol=1e-9)
    assert edge_axis_alignment(0.05 * SQUARE) == pytest.approx(1.0)


def test_corners_not_four_finite_points_or_three_in_a_line_have_no_offset() -> None:
    line = _turned(np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0], [5.0, 8.0]]), 30.0)
    for quad in (
        line,
        SQUARE[:3],
        np.vstack([SQUARE, SQUARE[:1]]),
        np.where(SQUARE > 5.0, np.inf, SQUARE),
    ):
        assert corner_design(quad) is None
        np.testing.assert_array_equal(REALISTIC.displacement(quad), np.zeros((4, 2)))


def test_an_offset_that_overflows_moves_no_corner() -> None:
    diamond = 1e-3 * QUADRILATERALS["diamond"]
    np.testing.assert_array_equal(CornerBias(c_px2=1e308).displacement(diamond), np.zeros((4, 2)))
    far = 1.5e307 * SQUARE  # corners near the largest float, moved out past it
    with np.errstate(over="ignore"):
        np.testing.assert_array_equal(CornerBias(a_px=-1e308).correct(far), far)
    # no offset: the corners come back as floats, as they do corrected
    assert CornerBias().correct(SQUARE.astype(int).tolist()).dtype == np.float64


def test_a_fit_file_without_the_angle_noise_model_loads_it_as_not_measured() -> None:
    doc = CornerBiasFit(REALISTIC, 0.068, 0.19, 240, 0.062, 0.073).as_dict()
    del doc["sigma_diagonal_px"], doc["sigma_axes_px"]
    fit = CornerBiasFit.from_dict(doc)
    assert (fit.sigma_diagonal_px, fit.sigma_axes_px) == (0.0, 0.0)
    assert fit == CornerBiasFit(REALISTIC, 0.068, 0.19, 240)


def _tilted_views(count: int) -> list[np.ndarray]:
    """A tag tilted 35° at 1 m, turned a different way in each view: its corner offsets do
    not average to zero over a view."""
    views = []
    for k in range(count):
        rotation = Rotation.from_euler("zx", [0.7 * k, 0.6]).as_matrix()
        translation = np.array([0.1 * np.cos(k), 0.1 * np.sin(k), 1.0])
        views.append(CAMERA.project(tag_corners_in_tag_frame(TAG_SIZE) @ rotation.T + translation))
    return views


def test_three_noise_free_views_give_the_offset_back_exactly_and_an_unusable_view_is_skipped() -> (
    None
):
    true = _tilted_views(3)
    detected = [
        p + REALISTIC.displacement(p) + shift
        for p, shift in zip(true, ([0.4, -0.2], [0.0, 0.3], [-0.5, 0.1]), strict=True)
    ]
    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    fit = fit_corner_bias([detected[0], line, *detected[1:]], [true[0], line, *true[1:]])
    assert fit.views == 3
    np.testing.assert_allclose(
        [fit.bias.a_px, fit.bias.b_px, fit.bias.c_px2],
        [REALISTIC.a_px, REALISTIC.b_px, REALISTIC.c_px2],
        atol=1e-6,
    )
    assert fit.sigma_px < 1e-6
    with pytest.raises(ValueError, match="zip"):
        fit_corner_bias(detected, true[:2])


def test_the_fits_noise_is_what_the_model_leaves_over_its_degrees_of_freedom() -> None:
    """sigma_px: per coordinate over 6 per view less the 3 parameters; uncorrected: over 6
    per view; the angle model: a line through each view's mean square (over 6) against
    the edges' alignment with the pixel axes."""
    rng = np.random.default_rng(8)
    true = _tilted_views(6)
    detected = [p + REALISTIC.displacement(p) + rng.normal(0.0, 0.05, (4, 2)) for p in true]
    fit = fit_corner_bias(detected, true)
    raw = [q - p - (q - p).mean(axis=0) for q, p in zip(detected, true, strict=True)]
    model = [fit.bias.displacement(p) - fit.bias.displacement(p).mean(axis=0) for p in true]
    left = np.array([r - m for r, m in zip(raw, model, strict=True)])
    assert fit.sigma_px == pytest.approx(np.sqrt(np.sum(left**2) / (6 * 6 - 3)), rel=1e-6)
    assert fit.sigma_uncorrected_px == pytest.approx(
        np.sqrt(np.sum(np.square(raw)) / (6 * 6)), rel=1e-9
    )
    slope, intercept = np.polyfit(
        [edge_axis_alignment(p) for p in true], np.sum(left**2, axis=(1, 2)) / 6.0, 1
    )
    assert fit.sigma_diagonal_px == pytest.approx(np.sqrt(intercept), rel=1e-6)
    assert fit.sigma_axes_px == pytest.approx(np.sqrt(intercept + slope), rel=1e-6)
