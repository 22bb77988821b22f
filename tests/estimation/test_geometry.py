"""Unit tests of the geometric building blocks (estimation.geometry)."""

from __future__ import annotations

import math

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
