"""Unit tests of the geometric building blocks (estimation.geometry)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimation import geometry
from estimation.camera_model import CameraIntrinsics
from estimation.frames import tag_corners_in_tag_frame, tof_positions_in_camera_frame


def _random_homography(rng: np.random.Generator) -> np.ndarray:
    """A well-conditioned homography from [-1, 1]² to a few hundred pixels."""
    h = np.eye(3) + 0.2 * rng.normal(size=(3, 3))
    h[:2, :2] *= 150.0
    h[:2, 2] = rng.uniform(100.0, 400.0, size=2)
    h[2, :2] = rng.uniform(-0.3, 0.3, size=2)
    return h


@pytest.mark.parametrize("n_points", [4, 9])
@pytest.mark.parametrize("seed", range(5))
def test_the_dlt_homography_reproduces_the_map(n_points: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    h_true = _random_homography(rng)
    src = rng.uniform(-1.0, 1.0, size=(n_points, 2))
    dst = geometry.apply_homography(h_true, src)
    h_dlt = geometry.homography_dlt(src, dst)
    assert h_dlt is not None
    canonical = geometry._canonical_homography(h_true)
    assert canonical is not None
    np.testing.assert_allclose(h_dlt, canonical, atol=1e-12)
    probe = rng.uniform(-1.0, 1.0, size=(20, 2))
    truth = geometry.apply_homography(h_true, probe)
    np.testing.assert_allclose(geometry.apply_homography(h_dlt, probe), truth, atol=1e-9)


def test_sensor_plane_to_pixel_homography_is_exact_for_a_tilted_deck() -> None:
    """Deck points' camera (X, Y) ↔ pixels is a homography: fit on the touch points, check on
    other deck points (the geometric fact IHRCF rests on)."""
    k = CameraIntrinsics()
    normal = Rotation.from_euler("xy", [12.0, -7.0], degrees=True).apply([0.0, 0.0, 1.0])
    offset = 1.3

    def on_plane(xy: np.ndarray) -> np.ndarray:
        z = (offset - xy @ normal[:2]) / normal[2]
        return np.column_stack([xy, z])

    sensors_xy = tof_positions_in_camera_frame()[:, :2]
    h = geometry.homography_dlt(sensors_xy, k.project(on_plane(sensors_xy)))
    assert h is not None
    probe = np.random.default_rng(1).uniform(-0.4, 0.4, size=(10, 2))
    np.testing.assert_allclose(
        geometry.apply_homography(h, probe), k.project(on_plane(probe)), atol=1e-8
    )


def test_degenerate_homographies_are_rejected() -> None:
    src = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0]])  # three collinear
    dst = np.array([[10.0, 10.0], [20.0, 10.0], [30.0, 10.0], [10.0, 20.0]])
    assert geometry.homography_dlt(src, dst) is None
    coincident = np.zeros((4, 2))
    assert geometry.homography_dlt(coincident, dst) is None
    assert geometry.homography_dlt(src, np.full((4, 2), np.nan)) is None


def test_plane_fit_is_exact_on_a_plane_and_its_residual_exposes_one_bad_range() -> None:
    sensors = tof_positions_in_camera_frame()
    normal = Rotation.from_euler("xy", [15.0, 8.0], degrees=True).apply([0.0, 0.0, 1.0])
    offset = 0.9
    points = sensors.copy()
    points[:, 2] = (offset - sensors[:, :2] @ normal[:2]) / normal[2]
    for method in geometry.PLANE_METHODS:
        fit = geometry.fit_plane(points, method)
        assert fit is not None
        np.testing.assert_allclose(fit.normal, normal, atol=1e-12)
        assert fit.offset == pytest.approx(offset, abs=1e-12)
        assert fit.rms_residual < 1e-12
        assert fit.z_at(0.0, 0.0) == pytest.approx(offset / normal[2], abs=1e-12)
    corrupted = points.copy()
    corrupted[3, 2] += 0.05
    lstsq = geometry.fit_plane(corrupted, "lstsq")
    assert lstsq is not None
    # a square's one free residual mode spreads a single error e as e/4 on every point,
    # however large e is
    assert lstsq.rms_residual == pytest.approx(0.05 / 4.0, rel=1e-9)
    corrupted[3, 2] += 0.25
    big = geometry.fit_plane(corrupted, "lstsq")
    assert big is not None and big.rms_residual == pytest.approx(0.3 / 4.0, rel=1e-9)
    cross3 = geometry.fit_plane(corrupted, "cross3")
    assert cross3 is not None
    # the 3-point normal ignores the bad sensor; only its offset average sees it
    np.testing.assert_allclose(cross3.normal, normal, atol=1e-12)
    assert cross3.rms_residual > 0.01


def test_plane_fit_rejects_collinear_and_non_finite_points() -> None:
    line = np.array([[0.0, 0.0, 1.0], [0.1, 0.1, 1.1], [0.2, 0.2, 1.2], [0.3, 0.3, 1.3]])
    # points above one (x, y) line: no plane has a finite z everywhere
    vertical = np.array([[0.0, 0.0, 1.0], [0.1, 0.1, 1.5], [0.2, 0.2, 0.7], [0.3, 0.3, 1.3]])
    for method in geometry.PLANE_METHODS:
        assert geometry.fit_plane(line, method) is None
        assert geometry.fit_plane(vertical, method) is None
        assert geometry.fit_plane(np.full((4, 3), np.nan), method) is None
        assert geometry.fit_plane(np.ones((4, 3)), method) is None


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), planar=st.booleans())
def test_rigid_fit_recovers_a_random_transform(seed: int, planar: bool) -> None:
    rng = np.random.default_rng(seed)
    rotation = Rotation.random(random_state=rng).as_matrix()
    translation = rng.uniform(-3.0, 3.0, size=3)
    model = tag_corners_in_tag_frame(0.2) if planar else rng.normal(size=(6, 3))
    measured = model @ rotation.T + translation
    for fit in (geometry.fit_rigid(model, measured), geometry.RigidFitter(model).fit(measured)):
        assert fit is not None
        np.testing.assert_allclose(fit.rotation, rotation, atol=1e-9)
        np.testing.assert_allclose(fit.translation, translation, atol=1e-9)
        assert fit.rms_residual < 1e-9


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_rigid_fit_never_returns_a_reflection(seed: int) -> None:
    rng = np.random.default_rng(seed)
    model = rng.normal(size=(5, 3))
    mirror = np.diag([1.0, 1.0, -1.0])
    rotation = Rotation.random(random_state=rng).as_matrix()
    # a mirrored copy is best matched by an improper matrix; Kabsch must refuse it
    measured = model @ (rotation @ mirror).T
    fit = geometry.fit_rigid(model, measured)
    assert fit is not None
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(fit.rotation @ fit.rotation.T, np.eye(3), atol=1e-9)
    assert fit.rms_residual > 1e-3


def test_rigid_fit_rejects_collinear_points() -> None:
    model = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    assert geometry.fit_rigid(model, model + 1.0) is None
    assert geometry.RigidFitter(tag_corners_in_tag_frame(0.1)).fit(model + 1.0) is None
    assert geometry.fit_rigid(np.zeros((4, 3)), np.zeros((4, 3))) is None


def test_undistort_pixels_inverts_the_lens_model_tightly() -> None:
    k = CameraIntrinsics(dist=(-0.3, 0.12, 0.001, -0.001, -0.02))
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(-0.5, 0.5, (50, 2)), np.ones(50)])
    ideal = k.project(points, distort=False)
    recovered = geometry.undistort_pixels(k.project(points), k)
    np.testing.assert_allclose(recovered, ideal, atol=1e-6)


def test_the_plane_of_ranges_is_the_deck_under_sensors_off_the_camera_plane() -> None:
    # a deck tilted 10 deg about x_C, 0.5 m along the axis under the camera's centre: each
    # sensor's range runs from its own origin (one of them 2 cm above the camera plane)
    sensors = np.array([[-0.1, -0.1, 0.0], [0.1, -0.1, 0.0], [0.1, 0.1, -0.02], [-0.1, 0.1, 0.0]])
    slope = math.tan(math.radians(10.0))
    ranges = 0.5 + slope * sensors[:, 1] - sensors[:, 2]
    plane = geometry.plane_of_ranges(sensors, ranges)
    assert plane is not None
    assert plane.normal == pytest.approx(
        [0.0, -math.sin(math.radians(10.0)), math.cos(math.radians(10.0))]
    )
    assert plane.offset == pytest.approx(0.5 * math.cos(math.radians(10.0)))
    assert sensors[2, 2] == -0.02  # the sites are not changed
    assert geometry.plane_of_ranges(sensors[:2], ranges[:2]) is None


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_sites=st.integers(3, 7))
def test_a_z_plane_fitter_gives_the_least_squares_plane_of_fit_plane(
    seed: int, n_sites: int
) -> None:
    rng = np.random.default_rng(seed)
    sites_xy = rng.uniform(-0.3, 0.3, size=(n_sites, 2))
    sites_xy[:3] = [[-0.2, -0.2], [0.2, -0.2], [0.0, 0.25]]  # never collinear
    z_m = rng.uniform(0.3, 2.0, size=n_sites)
    fit = geometry.ZPlaneFitter(sites_xy).fit(z_m)
    reference = geometry.fit_plane(np.column_stack([sites_xy, z_m]), "lstsq")
    assert fit is not None and reference is not None
    np.testing.assert_allclose(fit.normal, reference.normal, atol=1e-12)
    assert fit.offset == pytest.approx(reference.offset, abs=1e-12)
    assert fit.rms_residual == pytest.approx(reference.rms_residual, abs=1e-12)
    assert np.linalg.norm(fit.normal) == pytest.approx(1.0, abs=1e-12) and fit.normal[2] > 0.0


def test_a_z_plane_fitter_refuses_collinear_sites_and_fits_nothing_from_bad_heights() -> None:
    for sites_xy in ([[0.0, 0.0], [0.1, 0.1], [0.3, 0.3]], [[0.0, 0.0], [1.0, 0.0]]):
        with pytest.raises(
            ValueError, match=r"^the \(x, y\) sites are collinear: they do not fix a plane$"
        ):
            geometry.ZPlaneFitter(np.array(sites_xy))
    fitter = geometry.ZPlaneFitter(tof_positions_in_camera_frame()[:, :2])
    assert fitter.fit(np.array([1.0, 1.0, 1.0])) is None  # three heights for four sites
    assert fitter.fit(np.array([1.0, 1.0, math.nan, 1.0])) is None
    assert fitter.fit(np.array([1.0, 1.0, math.inf, 1.0])) is None
    level = fitter.fit(np.full(4, 0.7))
    assert level is not None
    np.testing.assert_allclose(level.normal, [0.0, 0.0, 1.0], atol=1e-12)
    assert level.offset == pytest.approx(0.7, abs=1e-12) and level.rms_residual < 1e-12


def test_a_plane_fit_takes_three_points_and_refuses_other_shapes_or_an_unknown_method() -> None:
    # three points ordered clockwise seen from +z: their cross product points down
    three = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 1.2], [1.0, 0.0, 1.1]])
    for method in geometry.PLANE_METHODS:
        fit = geometry.fit_plane(three, method)
        assert fit is not None, method
        assert fit.normal[2] > 0.0
        np.testing.assert_allclose(fit.z_at(three[:, 0], three[:, 1]), three[:, 2], atol=1e-12)
        assert fit.rms_residual < 1e-12
        assert geometry.fit_plane(three[:2], method) is None
        assert geometry.fit_plane(three[:, :2], method) is None
        assert geometry.fit_plane(three.reshape(1, 3, 3), method) is None
        assert geometry.fit_plane(three.ravel(), method) is None
    with pytest.raises(ValueError, match=r"plane method 'svd' is not one of \('lstsq', 'cross3'\)"):
        geometry.fit_plane(three, "svd")


def test_a_cross3_plane_is_the_first_three_points_normal_with_the_offset_of_all() -> None:
    # a level plane at 1 m through the first three; a fourth point 4 cm lower
    points = np.array([[0.0, 0.0, 1.0], [0.0, 0.2, 1.0], [0.2, 0.0, 1.0], [0.2, 0.2, 0.96]])
    fit = geometry.fit_plane(points, "cross3")
    assert fit is not None
    np.testing.assert_allclose(fit.normal, [0.0, 0.0, 1.0], atol=1e-15)
    assert fit.offset == pytest.approx(0.99, abs=1e-12)
    # residuals 0.01, 0.01, 0.01, -0.03 m
    assert fit.rms_residual == pytest.approx(math.sqrt((3 * 0.01**2 + 0.03**2) / 4), rel=1e-9)


@pytest.mark.parametrize("n_points", [4, 6])
def test_a_homography_needs_matching_n_by_2_pairs_of_at_least_four_finite_points(
    n_points: int,
) -> None:
    rng = np.random.default_rng(7)
    h_true = _random_homography(rng)
    src = rng.uniform(-1.0, 1.0, size=(n_points, 2))
    dst = geometry.apply_homography(h_true, src)
    assert geometry.homography_dlt(src, dst) is not None
    assert geometry.homography_dlt(src[:3], dst[:3]) is None
    assert geometry.homography_dlt(src, dst[:-1]) is None
    assert (
        geometry.homography_dlt(
            np.column_stack([src, src[:, 0]]), np.column_stack([dst, dst[:, 0]])
        )
        is None
    )
    assert geometry.homography_dlt(src.ravel(), dst.ravel()) is None
    for bad in (math.nan, math.inf):
        broken = src.copy()
        broken[1, 0] = bad
        assert geometry.homography_dlt(broken, dst) is None
        assert geometry.homography_dlt(src, broken) is None
    # coincident points, or three of them on a line, fix no homography
    coincident = np.repeat(src[:1], n_points, axis=0)
    assert geometry.homography_dlt(coincident, dst) is None
    assert geometry.homography_dlt(src, coincident) is None
    collinear = src.copy()
    collinear[:3] = [[0.0, 0.0], [0.5, 0.5], [1.0, 1.0]]
    if n_points == 4:
        assert geometry.homography_dlt(collinear, dst) is None
        assert geometry.homography_dlt(dst, collinear) is None


def test_a_homography_is_scaled_to_unit_norm_with_a_non_negative_last_entry() -> None:
    rng = np.random.default_rng(11)
    h_true = _random_homography(rng)
    for scale in (3.0, -0.5):
        h = geometry._canonical_homography(scale * h_true)
        assert h is not None
        assert np.sum(h * h) == pytest.approx(1.0, abs=1e-12)
        assert h[2, 2] >= 0.0
        np.testing.assert_allclose(h, h_true / np.linalg.norm(h_true), atol=1e-15)
    singular = h_true.copy()
    singular[2] = singular[0] + singular[1]
    assert geometry._canonical_homography(singular) is None
    assert geometry._canonical_homography(np.zeros((3, 3))) is None
    assert geometry._canonical_homography(np.full((3, 3), math.nan)) is None


def test_points_a_homography_sends_to_infinity_map_to_nan_and_the_rest_exactly() -> None:
    src = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 0.75]])
    # the third row vanishes at x = 0.5: the last point maps to infinity
    h = np.array([[200.0, 10.0, 100.0], [5.0, 180.0, 120.0], [1.0, 0.0, -0.5]])
    mapped = geometry.apply_homography(h, src)
    np.testing.assert_allclose(mapped[:3], [[-200.0, -240.0], [600.0, 250.0], [620.0, 610.0]])
    assert np.isnan(mapped[3]).all()
    finite = geometry.apply_homography(h, src[:3])
    np.testing.assert_allclose(finite, mapped[:3], atol=0.0)


@settings(max_examples=60, deadline=None)
@given(
    m=st.lists(
        st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False), min_size=9, max_size=9
    )
)
def test_det3_is_the_determinant(m: list[float]) -> None:
    matrix = np.array(m).reshape(3, 3)
    assert geometry.det3(matrix) == pytest.approx(np.linalg.det(matrix), abs=1e-9)


def test_a_rigid_fit_refuses_mismatched_or_too_few_or_non_finite_points() -> None:
    model = tag_corners_in_tag_frame(0.2)
    measured = model + np.array([0.1, -0.2, 1.5])
    assert geometry.fit_rigid(model, measured) is not None
    assert geometry.fit_rigid(model, measured[:3]) is None
    assert geometry.fit_rigid(model[:, :2], measured[:, :2]) is None
    assert geometry.fit_rigid(model.ravel(), measured.ravel()) is None
    assert geometry.fit_rigid(model[:2], measured[:2]) is None
    for bad in (math.nan, math.inf):
        broken = measured.copy()
        broken[2, 1] = bad
        assert geometry.fit_rigid(model, broken) is None
        assert geometry.fit_rigid(broken, measured) is None
        assert geometry.RigidFitter(model).fit(broken) is None
    assert geometry.RigidFitter(model).fit(measured[:3]) is None
    for bad_model in (model[:2], model[:, :2], model.ravel()):
        with pytest.raises(ValueError, match=r"^the model must be an Nx3 array with N >= 3$"):
            geometry.RigidFitter(bad_model)
    three = geometry.RigidFitter(model[:3]).fit(measured[:3])
    assert three is not None
    np.testing.assert_allclose(three.translation, [0.1, -0.2, 1.5], atol=1e-12)


def test_a_rigid_fits_residual_is_the_rms_distance_of_the_points() -> None:
    model = tag_corners_in_tag_frame(0.2)
    # one corner 3 cm off along the tag's normal: the fit cannot absorb it all
    measured = model.copy()
    measured[0, 2] += 0.03
    for fit in (geometry.fit_rigid(model, measured), geometry.RigidFitter(model).fit(measured)):
        assert fit is not None
        residual = measured - (model @ fit.rotation.T + fit.translation)
        expected = math.sqrt(float((residual**2).sum()) / 4)
        assert fit.rms_residual == pytest.approx(expected, rel=1e-12)
        assert 0.005 < fit.rms_residual < 0.03


def test_an_undistorter_inverts_a_strong_lens_to_a_picoscale_at_the_image_corners() -> None:
    k = CameraIntrinsics(dist=(-0.25, 0.0, 0.0, 0.0, 0.0))
    # near the image corners, where five fixed-point iterations leave about 0.014 px
    points = np.array([[0.5, 0.5, 1.0], [-0.5, 0.5, 1.0], [0.5, -0.48, 1.0], [-0.45, -0.5, 1.0]])
    ideal = k.project(points, distort=False)
    raw = k.project(points)
    undistorter = geometry.Undistorter(k)
    assert undistorter.active
    np.testing.assert_allclose(undistorter(raw), ideal, atol=1e-9)
    np.testing.assert_allclose(geometry.undistort_pixels(raw, k), ideal, atol=1e-9)
    one = geometry.undistort_pixels(raw[0], k)  # a single pixel, as a 1-D array
    assert one.shape == (1, 2)
    np.testing.assert_allclose(one[0], ideal[0], atol=1e-9)


def test_without_distortion_the_undistorted_pixels_are_a_copy_of_the_raw_ones() -> None:
    k = CameraIntrinsics()
    raw = np.array([[10.0, 20.0], [300.5, 400.25]])
    undistorter = geometry.Undistorter(k)
    assert not undistorter.active
    for out in (undistorter(raw), geometry.undistort_pixels(raw, k)):
        np.testing.assert_array_equal(out, raw)
        out[0, 0] = -1.0
        assert raw[0, 0] == 10.0
    assert geometry.undistort_pixels(raw[1], k).shape == (1, 2)


def test_a_plane_fit_is_least_squares_by_default_and_in_double_precision() -> None:
    sensors = tof_positions_in_camera_frame()
    points = np.column_stack([sensors[:, :2], [0.9, 0.93, 0.95, 0.91]])
    reference = geometry.fit_plane(points, "lstsq")
    assert reference is not None
    for given_points in (points, points.astype(np.float32).astype(float)):
        fit = geometry.fit_plane(given_points)
        assert fit is not None
        assert fit.rms_residual == pytest.approx(
            geometry.fit_plane(given_points, "lstsq").rms_residual, abs=0.0
        )
    single = geometry.fit_plane(points.astype(np.float32), "cross3")
    double = geometry.fit_plane(points.astype(np.float32).astype(float), "cross3")
    assert single is not None and double is not None
    np.testing.assert_array_equal(single.normal, double.normal)
    assert single.offset == double.offset and single.normal.dtype == np.float64
    # integer sites and ranges: the touch points are floats, the sites untouched
    sites = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    plane = geometry.plane_of_ranges(sites, np.array([1.5, 1.5, 2.5, 2.5]))
    assert plane is not None
    np.testing.assert_allclose(plane.normal, np.array([0.0, -0.5, 1.0]) / math.sqrt(1.25))
    assert plane.z_at(0.0, 0.0) == pytest.approx(2.0, abs=1e-12)
    assert sites.dtype.kind == "i" and sites[0, 2] == 0


def test_sites_a_hundredth_of_a_micrometre_off_a_line_fix_no_plane() -> None:
    # 1e-8 m off: the smallest singular value of the design matrix is 3.6e-10 of the largest,
    # under the 1e-9 floor, though the matrix still has full numerical rank
    for offset_m, fitted in ((1e-8, False), (1e-6, True)):
        points = np.array(
            [[0.0, 0.0, 1.0], [5.0, 0.0, 1.0], [10.0, offset_m, 1.0], [2.0, 0.0, 1.0]]
        )
        assert (geometry.fit_plane(points, "lstsq") is not None) is fitted, offset_m
        if fitted:
            assert geometry.ZPlaneFitter(points[:, :2]).fit(points[:, 2]) is not None
        else:
            with pytest.raises(ValueError, match="collinear"):
                geometry.ZPlaneFitter(points[:, :2])


def test_cross3_judges_collinearity_on_the_first_three_points_own_extent() -> None:
    # a triangle of (x, y) 1 m wide and 1e-9 m tall: twice its area is 4 times the floor
    thin = np.array([[100.0, 0.0, 1.0], [101.0, 0.0, 1.0], [100.5, 1e-9, 1.0]])
    assert geometry.fit_plane(thin, "cross3") is not None
    # a fourth point far away does not make it collinear (its offset is averaged only)
    assert geometry.fit_plane(np.vstack([thin, [[110.0, 10.0, 1.0]]]), "cross3") is not None
    # nor does a steep rise of the heights
    steep = thin.copy()
    steep[2, 2] = 4.0
    assert geometry.fit_plane(steep, "cross3") is not None
    # the test is scale-free: a triangle 10 micrometres wide is a plane too
    tiny = np.array([[0.0, 0.0, 1.0], [1e-5, 0.0, 1.0], [0.0, 1e-5, 1.0]])
    fit = geometry.fit_plane(tiny, "cross3")
    assert fit is not None
    np.testing.assert_allclose(fit.normal, [0.0, 0.0, 1.0], atol=1e-12)
    # and below the floor it is a line
    flat = thin.copy()
    flat[2, 1] = 1e-11
    assert geometry.fit_plane(flat, "cross3") is None


def test_four_pairs_are_solved_by_the_eight_by_eight_system_unless_it_is_singular() -> None:
    rng = np.random.default_rng(5)
    h_true = _random_homography(rng)
    src = np.array([[-0.4, -0.3], [0.5, -0.2], [0.3, 0.45], [-0.35, 0.4]])
    dst = geometry.apply_homography(h_true, src)
    direct = geometry._homography_four(src, dst)
    assert direct is not None
    np.testing.assert_allclose(
        geometry._canonical_homography(direct), geometry._canonical_homography(h_true), atol=1e-12
    )
    # a square about the origin is its own normalisation (scale exactly 1)
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    for a, b in ((square, dst), (dst, square)):
        solved = geometry._homography_four(a, b)
        assert solved is not None
        np.testing.assert_allclose(geometry.apply_homography(solved, a), b, atol=1e-9)
    line = np.array([[0.0, 0.0], [0.5, 0.5], [1.0, 1.0], [0.0, 1.0]])
    assert geometry._homography_four(line, dst) is None
    assert geometry._homography_four(src, line * 100.0) is None
    # a map sending the source centroid to infinity has h33 = 0 in normalised coordinates:
    # the system is singular and the SVD solves it
    swap_xw = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    image = geometry.apply_homography(swap_xw, square)
    assert geometry._homography_four(square, image) is None
    h = geometry.homography_dlt(square, image)
    assert h is not None
    # H[2, 2] is 0 up to rounding, so its sign does not fix H's
    np.testing.assert_allclose(h * np.sign(h[1, 1]), swap_xw / math.sqrt(3.0), atol=1e-12)
    np.testing.assert_allclose(geometry.apply_homography(h, square), image, atol=1e-12)


@pytest.mark.parametrize("length_scale", [1e-2, 1.0, 10.0])
def test_a_homography_of_four_points_in_any_order_and_units_is_found(length_scale: float) -> None:
    rng = np.random.default_rng(2)
    h_true = _random_homography(rng)
    # a crossed quadrilateral (0-1 and 2-3 cross), and a kite whose first three points
    # have (x1 - x0)(y2 - y0) = -(y1 - y0)(x2 - x0)
    for quad in (
        [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        [[0.0, 0.0], [1.0, 1.0], [1.0, -1.0], [2.0, 0.0]],
    ):
        src = np.array(quad) * 0.4 - 0.2
        dst = geometry.apply_homography(h_true, src)
        for a, b, forward in ((src, dst, h_true), (dst, src, np.linalg.inv(h_true))):
            scaled = np.diag([length_scale, length_scale, 1.0])
            h = geometry.homography_dlt(a * length_scale, b)
            assert h is not None, (quad, length_scale)
            expected = geometry._canonical_homography(forward @ np.linalg.inv(scaled))
            np.testing.assert_allclose(h, expected, atol=1e-9)
            h = geometry.homography_dlt(a, b * length_scale)
            assert h is not None, (quad, length_scale)
            expected = geometry._canonical_homography(scaled @ forward)
            np.testing.assert_allclose(h, expected, atol=1e-9)


def test_a_homography_of_a_grid_with_a_point_at_its_centre_is_found() -> None:
    rng = np.random.default_rng(4)
    h_true = _random_homography(rng)
    # the centre of a 3x3 grid shares its x and y with the grid's centroid
    grid = np.array([[x, y] for x in (-0.5, 0.0, 0.5) for y in (-0.5, 0.0, 0.5)])
    image = geometry.apply_homography(h_true, grid)
    for src, dst, forward in ((grid, image, h_true), (image, grid, np.linalg.inv(h_true))):
        h = geometry.homography_dlt(src, dst)
        assert h is not None
        np.testing.assert_allclose(h, geometry._canonical_homography(forward), atol=1e-12)


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    log_eps=st.sampled_from([None, -14.0, -12.0, -10.0, -9.0, -8.0, -6.0, -3.0, 0.0]),
)
def test_a_homography_is_kept_unless_its_unit_norm_determinant_is_below_the_floor(
    seed: int, log_eps: float | None
) -> None:
    rng = np.random.default_rng(seed)
    # a rank-2 matrix plus a rank-1 part of size eps: |det| grows with eps
    h = rng.normal(size=(3, 2)) @ rng.normal(size=(2, 3))
    if log_eps is not None:
        h = h + 10.0**log_eps * np.outer(rng.normal(size=3), rng.normal(size=3))
    unit = h / np.linalg.norm(h)
    det = abs(float(np.linalg.det(unit)))
    if 0.5e-9 < det < 2e-9:
        return  # too near the floor for rounding to decide
    canonical = geometry._canonical_homography(h)
    assert (canonical is None) is (det <= 1e-9)
    if canonical is not None:
        np.testing.assert_allclose(canonical, unit * math.copysign(1.0, h[2, 2]), atol=1e-15)


def test_integer_pixels_are_undistorted_as_floats() -> None:
    raw = np.array([[100, 80], [400, 420]])
    for k in (CameraIntrinsics(dist=(-0.25, 0.0, 0.0, 0.0, 0.0)), CameraIntrinsics()):
        expected = geometry.undistort_pixels(raw.astype(float), k)
        for out in (geometry.undistort_pixels(raw, k), geometry.Undistorter(k)(raw)):
            assert out.dtype == np.float64
            np.testing.assert_array_equal(out, expected)


def test_a_point_at_or_within_1e_12_of_the_horizon_maps_to_nan_without_a_warning() -> None:
    # the third row vanishes at x = 0.5; (0.5, -20) also zeroes the first coordinate
    h = np.array([[200.0, 10.0, 100.0], [5.0, 180.0, 120.0], [1.0, 0.0, -0.5]])
    points = np.array([[1.0, 0.0], [0.5, 0.75], [0.5 + 1e-12, 0.0], [0.5, -20.0], [0.5 + 1e-9, 0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mapped = geometry.apply_homography(h, points)
    assert mapped.shape == (5, 2)
    np.testing.assert_allclose(mapped[0], [600.0, 250.0])
    assert np.isnan(mapped[1:4]).all()
    # 1e-9 from the horizon is far but finite, alone or beside a point a million times farther
    far = geometry.apply_homography(h, points[4:])
    assert np.isfinite(far).all() and abs(far[0, 0]) > 1e11
    beside = geometry.apply_homography(h, np.vstack([points[4:], [[1e6, 0.0]]]))
    np.testing.assert_array_equal(beside[0], far[0])
    np.testing.assert_array_equal(mapped[4], far[0])


def test_single_precision_input_is_fitted_in_double_precision() -> None:
    rng = np.random.default_rng(8)
    model = rng.normal(size=(6, 3)).astype(np.float32)
    rotation = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    measured = (model @ rotation.T + [0.5, 0.1, 2.0]).astype(np.float32)
    single = geometry.fit_rigid(model, measured)
    double = geometry.fit_rigid(model.astype(float), measured.astype(float))
    assert single is not None and double is not None
    assert single.rotation.dtype == np.float64
    np.testing.assert_array_equal(single.rotation, double.rotation)
    assert single.rms_residual == double.rms_residual
    h_true = _random_homography(rng)
    grid = np.array([[x, y] for x in (-0.5, 0.1, 0.5) for y in (-0.5, 0.2, 0.5)])
    image = geometry.apply_homography(h_true, grid).astype(np.float32)
    h_single = geometry.homography_dlt(grid.astype(np.float32), image)
    h_double = geometry.homography_dlt(grid.astype(np.float32).astype(float), image.astype(float))
    assert h_single is not None and h_double is not None
    np.testing.assert_array_equal(h_single, h_double)
    fitter = geometry.ZPlaneFitter(grid)
    column = fitter.fit(np.linspace(1.0, 1.8, 9).reshape(-1, 1))
    assert column is not None
    assert column.rms_residual == fitter.fit(np.linspace(1.0, 1.8, 9)).rms_residual


def test_four_pairs_take_the_eight_by_eight_solution_and_five_the_svd() -> None:
    rng = np.random.default_rng(9)
    h_true = _random_homography(rng)
    src = np.array([[-0.4, -0.3], [0.5, -0.2], [0.3, 0.45], [-0.35, 0.4]])
    dst = geometry.apply_homography(h_true, src)
    direct = geometry._homography_four(src, dst)
    assert direct is not None
    np.testing.assert_array_equal(
        geometry.homography_dlt(src, dst), geometry._canonical_homography(direct)
    )
    # five points, the first three on a line: the SVD still fixes the map
    five = np.array([[-0.5, -0.5], [-0.5, 0.0], [-0.5, 0.5], [0.0, -0.5], [0.0, 0.0]])
    h = geometry.homography_dlt(five, geometry.apply_homography(h_true, five))
    assert h is not None
    np.testing.assert_allclose(h, geometry._canonical_homography(h_true), atol=1e-12)


def test_five_points_four_of_them_within_5e_9_of_a_line_fix_no_homography() -> None:
    # 5e-9 off the line the DLT matrix's eighth singular value is 7e-10 of its first, under
    # the 1e-9 floor; 1e-7 off it is 1.4e-8
    h_true = np.array([[1.2, 0.1, 0.3], [0.05, 0.9, -0.2], [0.1, 0.2, 1.0]])
    for offset, found in ((5e-9, False), (1e-7, True)):
        src = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, offset], [1.0, 1.0]])
        h = geometry.homography_dlt(src, geometry.apply_homography(h_true, src))
        assert (h is not None) is found, offset


def test_a_rigid_fit_refuses_points_a_tenth_of_a_millimetre_off_a_ten_metre_line() -> None:
    # the cross-covariance's second singular value (1.7e-9 m^2) is 3e-11 of its first
    # (57 m^2), under the 1e-9 floor
    line = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [10.0, 1e-4, 0.0], [2.0, 0.0, 0.0]])
    assert geometry.fit_rigid(line, line + 1.0) is None
    assert geometry.RigidFitter(line).fit(line + 1.0) is None
    bent = line.copy()
    bent[2, 1] = 0.1
    assert geometry.fit_rigid(bent, bent + 1.0) is not None
    # a one-metre tag moved without turning: the singular values are exactly 1, 1 and 0
    tag = tag_corners_in_tag_frame(1.0)
    fit = geometry.RigidFitter(tag).fit(tag + np.array([0.2, -0.1, 3.0]))
    assert fit is not None
    np.testing.assert_allclose(fit.rotation, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(fit.translation, [0.2, -0.1, 3.0], atol=1e-15)


def test_a_rigid_fitter_fits_single_precision_points_in_double_precision() -> None:
    rng = np.random.default_rng(8)
    model = rng.normal(size=(6, 3)).astype(np.float32)
    rotation = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    measured = (model @ rotation.T + [0.5, 0.1, 2.0]).astype(np.float32)
    fitted = geometry.RigidFitter(model).fit(measured)
    assert fitted is not None
    for fit in (fitted, geometry.RigidFitter(model).fit(measured.astype(float))):
        assert fit is not None
        expected = geometry.RigidFitter(model.astype(float)).fit(measured.astype(float))
        assert expected is not None
        np.testing.assert_array_equal(fit.translation, expected.translation)
