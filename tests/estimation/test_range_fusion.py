"""IHRCF and CRHF (the papers' camera + ToF estimators) against the papers' equations.

The synthetic scenes use a camera that is not the project's default (fx != fy, the principal
point off the image centre), so that an estimator reading one axis for the other, or the
default camera for the one calibrated, gets the pose wrong.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimation.camera_model import CameraIntrinsics
from estimation.crhf import CRHFConfig, CrhfEstimator
from estimation.errors import ConfigError
from estimation.frames import tof_positions_in_camera_frame
from estimation.ihrcf import IHRCFConfig, IhrcfEstimator
from estimation.synthetic import SyntheticScene
from estimation.tof_calibration import TofCameraCalibration
from estimation.types import RangeReading

TAG_SIZE = 0.12
#: a camera unlike the default one: every intrinsic differs from the others
CAMERA = CameraIntrinsics(width=640, height=480, fx=610.0, fy=540.0, cx=331.0, cy=229.0)
SENSORS = tof_positions_in_camera_frame()
#: sensors on the camera's axes: each says nothing about the focal length along one axis
DIAMOND = np.array([[0.07, 0.0, 0.0], [0.0, 0.06, 0.0], [-0.07, 0.0, 0.0], [0.0, -0.06, 0.0]])


def _calibration(sensors: np.ndarray = SENSORS) -> TofCameraCalibration:
    return TofCameraCalibration.exact(CAMERA, sensors, 0.2, 5.0)


def _pose(tilt_deg: float, tilt_dir: float, yaw: float, height: float, x: float, y: float):
    axis = np.array([math.cos(tilt_dir), math.sin(tilt_dir), 0.0])
    rotation = Rotation.from_rotvec(math.radians(tilt_deg) * axis) * Rotation.from_euler("z", yaw)
    return rotation.as_matrix(), np.array([x, y, height])


def _errors(estimate, rotation: np.ndarray, translation: np.ndarray) -> tuple[float, float]:
    dt = float(np.linalg.norm(estimate.translation - translation))
    da = math.degrees(Rotation.from_matrix(estimate.rotation @ rotation.T).magnitude())
    return dt, da


def _crhf(sensors: np.ndarray = SENSORS, method: str = "range_weighted") -> CrhfEstimator:
    return CrhfEstimator(
        tag_size=TAG_SIZE,
        tag_id=0,
        tof_calibration=_calibration(sensors),
        tof_positions_c=sensors,
        config=CRHFConfig(principal_point=method),
    )


POSES = st.tuples(
    st.floats(0.0, 20.0),
    st.floats(-math.pi, math.pi),
    st.floats(-math.pi, math.pi),
    st.floats(0.4, 3.0),
    st.floats(-0.25, 0.25),
    st.floats(-0.2, 0.2),
)


@settings(max_examples=40, deadline=None)
@given(pose=POSES)
def test_ihrcf_needs_no_camera_matrix_only_its_touch_points(pose: tuple) -> None:
    """Paper Sec. 2.4-2.7: the homography from the sensors' (X, Y) to their touch pixels
    (Eq. 13-19) and the plane through the touch points (Eq. 20-22) give the corners in C
    whatever camera took the pixels, so an IHRCF given no intrinsics recovers the pose."""
    rotation, translation = _pose(*pose)
    m = SyntheticScene(CAMERA, TAG_SIZE).measure(rotation, translation, timestamp=3.25)
    assume(len(m.frame.detections) == 1)
    estimator = IhrcfEstimator(tag_size=TAG_SIZE, tag_id=0, tof_calibration=_calibration())
    estimate = estimator.estimate(m.frame, m.ranges)
    assert estimate.valid, estimate.reason
    assert estimate.method == "ihrcf" and estimate.timestamp == 3.25
    dt, da = _errors(estimate, rotation, translation)
    assert dt < 1e-9 and da < 1e-7
    assert estimate.extras["plane_rms_m"] < 1e-12 and estimate.extras["rigid_rms_m"] < 1e-12


@settings(max_examples=40, deadline=None)
@given(pose=POSES, method=st.sampled_from(["range_weighted", "lstsq"]))
def test_crhf_recovers_each_focal_length_and_the_principal_point_of_its_camera(
    pose: tuple, method: str
) -> None:
    """Paper Eq. 40-45: f_x from the touch points' u and s_x, f_y from their v and s_y, and
    the principal point as their range-weighted mean (or the joint least-squares fit): each
    of the four intrinsics comes back on its own, and so does the pose (Eq. 46-53)."""
    rotation, translation = _pose(*pose)
    m = SyntheticScene(CAMERA, TAG_SIZE).measure(rotation, translation, timestamp=0.5)
    assume(len(m.frame.detections) == 1)
    estimate = _crhf(method=method).estimate(m.frame, m.ranges)
    assert estimate.valid, estimate.reason
    assert estimate.method == "crhf" and estimate.timestamp == 0.5
    for key in ("fx", "fy", "cx", "cy"):
        assert estimate.extras[key] == pytest.approx(getattr(CAMERA, key), abs=1e-7), key
    dt, da = _errors(estimate, rotation, translation)
    assert dt < 1e-9 and da < 1e-7


@pytest.mark.parametrize("method", ["range_weighted", "lstsq"])
def test_crhf_leaves_a_sensor_on_an_axis_out_of_that_axis_focal_length(method: str) -> None:
    """Sensors on the camera's x axis have s_y = 0 and say nothing about f_y (and those on
    the y axis nothing about f_x): CRHF averages Eq. 44 over the others instead of dividing
    by zero."""
    rotation, translation = _pose(14.0, 0.8, 2.1, 1.3, 0.1, -0.05)
    m = SyntheticScene(CAMERA, TAG_SIZE, tof_positions_c=DIAMOND).measure(rotation, translation)
    estimate = _crhf(DIAMOND, method).estimate(m.frame, m.ranges)
    assert estimate.valid, estimate.reason
    for key in ("fx", "fy", "cx", "cy"):
        assert estimate.extras[key] == pytest.approx(getattr(CAMERA, key), abs=1e-7), key
    dt, da = _errors(estimate, rotation, translation)
    assert dt < 1e-9 and da < 1e-7


def test_one_sensor_off_an_axis_is_enough_and_none_is_refused_naming_the_layout() -> None:
    """A focal length needs at least one sensor offset along its axis; the joint fit takes a
    layout with one, and a layout with none (all sensors within a micrometre of the x axis,
    which still fixes a plane, each sensor off along x) is refused naming
    ``tof_positions_c``."""
    one = np.array([[-0.07, 0.0, 0.0], [0.07, 0.0, 0.0], [0.0, 0.06, 0.0], [0.03, 0.0, 0.0]])
    rotation, translation = _pose(10.0, -0.4, 0.3, 1.1, -0.05, 0.08)
    m = SyntheticScene(CAMERA, TAG_SIZE, tof_positions_c=one).measure(rotation, translation)
    estimate = _crhf(one, "lstsq").estimate(m.frame, m.ranges)
    assert estimate.valid, estimate.reason
    assert estimate.extras["fy"] == pytest.approx(CAMERA.fy, abs=1e-7)
    flat = np.array([[-0.07, 0.0, 0.0], [0.07, 0.0, 0.0], [0.03, 5e-7, 0.0], [-0.03, -5e-7, 0.0]])
    with pytest.raises(ConfigError, match="tof_positions_c: no sensor is offset") as err:
        _crhf(flat, "lstsq")
    assert err.value.key == "tof_positions_c"


def test_the_range_weighted_principal_point_is_refused_for_a_layout_not_centred() -> None:
    """Eq. 45 is the principal point only when the sensors' positions sum to zero: a layout
    off by a millimetre is refused naming ``principal_point`` and the alternative, one
    centred up to rounding is taken."""
    shifted = SENSORS + np.array([0.001, -0.001, 0.0])  # off along x and along y
    with pytest.raises(
        ConfigError,
        match=r"principal_point: 'range_weighted' \(Eq\. 45\) is exact only for "
        r".* use 'lstsq' for this layout$",
    ):
        _crhf(shifted)
    rounded = SENSORS * (1.0 + 1e-12) + np.array([1e-13, -1e-13, 0.0])
    assert _crhf(rounded).config.principal_point == "range_weighted"
    with pytest.raises(ConfigError, match=r"^principal_point: 'mean' is not allowed"):
        CRHFConfig(principal_point="mean")


def _calibration_off_by(offsets_px: np.ndarray) -> TofCameraCalibration:
    """The exact calibration's samples with each sensor's pads found ``offsets_px`` away
    (a calibration error): touch pixels that no single pinhole explains."""
    exact = _calibration()
    samples = [
        s + np.array([0.0, *offset]) for s, offset in zip(exact.samples, offsets_px, strict=True)
    ]
    return TofCameraCalibration(samples, method="pchip")


def test_crhfs_intrinsics_are_the_papers_range_weighted_mean_and_per_sensor_average() -> None:
    """With touch pixels that disagree (pads found a few pixels off), CRHF's principal point
    is Eq. 45, the range-weighted mean of the touch pixels, and its focal length Eq. 44, the
    mean of the per-sensor ``(u_i - c_x) r_i / s_ix``; the joint least-squares fit gives
    other values."""
    offsets = np.array([[2.0, -1.0], [-0.5, 1.5], [1.0, 0.5], [-1.5, -2.0]])
    cal = _calibration_off_by(offsets)
    m = SyntheticScene(CAMERA, TAG_SIZE).measure(*_pose(9.0, 0.3, 0.2, 1.4, 0.05, -0.04))
    ranges = m.ranges.ranges
    touch = cal.lookup(ranges).pixels
    centre = ranges @ touch / ranges.sum()  # Eq. 45
    focal = ((touch - centre) * ranges[:, None] / SENSORS[:, :2]).mean(axis=0)  # Eq. 40-44
    weighted, joint = (
        CrhfEstimator(
            tag_size=TAG_SIZE,
            tag_id=0,
            tof_calibration=cal,
            config=CRHFConfig(principal_point=method, max_rigid_rms_rel=np.inf),
        ).estimate(m.frame, m.ranges)
        for method in ("range_weighted", "lstsq")
    )
    assert weighted.valid and joint.valid
    expected = {"fx": focal[0], "fy": focal[1], "cx": centre[0], "cy": centre[1]}
    for key, value in expected.items():
        assert weighted.extras[key] == pytest.approx(value, abs=1e-9), key
    assert max(abs(joint.extras[key] - value) for key, value in expected.items()) > 1e-3


def _coincident_touch_points() -> TofCameraCalibration:
    """A calibration that puts every sensor's touch point on one pixel (pads all found in
    one place): no homography, no focal length."""
    one_pixel = np.array([[0.2, 300.0, 200.0], [5.0, 300.0, 200.0]])
    return TofCameraCalibration([one_pixel] * 4)


def test_touch_points_on_one_pixel_give_an_invalid_estimate_with_the_methods_reason() -> None:
    m = SyntheticScene(CAMERA, TAG_SIZE).measure(
        *_pose(5.0, 0.0, 0.0, 1.0, 0.0, 0.0), timestamp=7.0
    )
    cal = _coincident_touch_points()
    ihrcf = IhrcfEstimator(tag_size=TAG_SIZE, tag_id=0, tof_calibration=cal).estimate(
        m.frame, m.ranges
    )
    assert (ihrcf.valid, ihrcf.method, ihrcf.timestamp) == (False, "ihrcf", 7.0)
    assert ihrcf.reason == "degenerate_homography"
    crhf = CrhfEstimator(tag_size=TAG_SIZE, tag_id=0, tof_calibration=cal).estimate(
        m.frame, m.ranges
    )
    assert (crhf.valid, crhf.method, crhf.timestamp) == (False, "crhf", 7.0)
    assert crhf.reason == "degenerate_touch_points"


def test_a_calibration_mirrored_left_to_right_gives_crhf_no_positive_focal_length() -> None:
    """The image's x axis and the camera's X point the same way, so f_x > 0: touch pixels
    of a calibration taken with the sensors' x mirrored (pads swapped left to right) give
    a negative f_x (Eq. 44), which CRHF refuses rather than reconstruct a mirrored deck."""
    mirrored = TofCameraCalibration.exact(CAMERA, SENSORS * np.array([-1.0, 1.0, 1.0]), 0.2, 5.0)
    m = SyntheticScene(CAMERA, TAG_SIZE).measure(*_pose(8.0, 1.0, 0.5, 1.2, 0.05, 0.0))
    estimate = CrhfEstimator(tag_size=TAG_SIZE, tag_id=0, tof_calibration=mirrored).estimate(
        m.frame, m.ranges
    )
    assert not estimate.valid and estimate.reason == "degenerate_touch_points"


@pytest.mark.parametrize("estimator_class", [IhrcfEstimator, CrhfEstimator])
def test_a_range_the_calibration_cannot_place_gives_touch_point_unavailable(
    estimator_class: type,
) -> None:
    """With ``out_of_range="nan"`` a range beyond the calibrated span has no touch pixel."""
    cal = _calibration().with_method("pchip", out_of_range="nan")
    m = SyntheticScene(CAMERA, TAG_SIZE).measure(*_pose(5.0, 0.0, 0.0, 1.0, 0.0, 0.0))
    far = RangeReading(m.ranges.timestamp, m.ranges.ranges + 4.5, m.ranges.valid)
    estimate = estimator_class(tag_size=TAG_SIZE, tag_id=0, tof_calibration=cal).estimate(
        m.frame, far
    )
    assert not estimate.valid and estimate.reason == "touch_point_unavailable"


def test_ihrcf_settings_are_the_shared_range_fusion_ones() -> None:
    with pytest.raises(ConfigError, match="plane_fit"):
        IHRCFConfig(plane_fit="ransac")
