"""The papers' two calibrations run in the simulator, on reduced runs, and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.calibration.simulated import run_calibration
from agents.cli import main
from estimation.frames import tof_positions_in_camera_frame
from estimation.intrinsics_calibration import (
    IntrinsicsCalibrationResult,
    chessboard_object_points,
    find_chessboard,
)
from estimation.tof_calibration import TofCameraCalibration
from landing_env.calibration.intrinsics_sim import (
    ChessboardRigConfig,
    ChessboardScene,
    calibrate_intrinsics_in_sim,
    sample_board_poses,
)
from landing_env.calibration.tof_camera_sim import (
    PAD_NOT_FOUND,
    TofRigConfig,
    calibrate_tof_camera_in_sim,
)
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.sensors.camera_config import CameraConfig


def test_rendered_chessboard_corners_land_on_the_projected_ones() -> None:
    """The rig's board, rendered, is detected where the camera model puts its corners."""
    rig = ChessboardRigConfig(views=4)
    scene = ChessboardScene(CameraConfig(), rig)
    try:
        poses = sample_board_poses(rig, scene.intrinsics, np.random.default_rng(1))
        model = chessboard_object_points(rig.pattern, rig.square_size_m)
        for r_cg, t_cg in poses:
            corners = find_chessboard(scene.render(r_cg, t_cg), rig.pattern)
            assert corners is not None
            projected = scene.intrinsics.project(model @ r_cg.T + t_cg)
            # OpenCV may number a symmetric board from either end
            error = min(np.abs(corners - projected).max(), np.abs(corners - projected[::-1]).max())
            assert error < 0.4
    finally:
        scene.close()


@pytest.mark.parametrize("k1", [0.0, -0.1])
def test_intrinsics_calibration_recovers_k_within_a_percent(k1: float) -> None:
    camera = CameraConfig(k1=k1)
    rig = ChessboardRigConfig(views=10)
    report = calibrate_intrinsics_in_sim(camera, rig, np.random.default_rng(0))
    assert report.views_used >= 8
    assert report.result.rms_reprojection_error < 0.2
    for key, error in report.k_error_pct().items():
        assert abs(error) < 1.0, (key, error)
    # the principal point within a pixel, the radial distortion to 0.01
    assert abs(report.k_error_px()["cx"]) < 1.0 and abs(report.k_error_px()["cy"]) < 1.0
    assert report.result.dist[0] == pytest.approx(k1, abs=0.01)
    assert report.result.metadata["camera"]["dist"][0] == k1


def test_chessboard_rig_refuses_bad_settings() -> None:
    with pytest.raises(ConfigError, match="distortion_model"):
        ChessboardRigConfig(distortion_model="fisheye")
    with pytest.raises(ConfigError, match="distance_m"):
        ChessboardRigConfig(distance_m=(2.0, 1.0))


def test_tof_camera_calibration_reproduces_the_touch_points() -> None:
    config = load_config("default")
    report = calibrate_tof_camera_in_sim(config, TofRigConfig(stages=20), np.random.default_rng(0))
    assert all(sum(counts) == 0 for counts in report.skipped.values())
    cal = report.calibration
    assert cal.method == "pchip"
    span = cal.range_span
    assert np.allclose(span[:, 0], 0.3, atol=0.01) and np.all(span[:, 1] > 3.95)
    # PCHIP through the 20 measured centroids stays within a pixel of the analytic
    # touch-point pixel over the whole span (measured: about 0.3 px)
    assert np.all(report.exact_error_px < 1.0), report.exact_error_px
    assert np.all(report.sample_error_px < 0.3), report.sample_error_px
    # CRHF Table 4: a = f * (sensor offset), c = principal point
    camera = config.camera.intrinsics
    sensors = tof_positions_in_camera_frame()
    for i, (hu, hv) in enumerate(report.hyperbolas):
        assert hu.a == pytest.approx(camera.fx * sensors[i, 0], rel=0.01)
        assert hv.a == pytest.approx(camera.fy * sensors[i, 1], rel=0.01)
        assert hu.c == pytest.approx(camera.cx, abs=0.5)
        assert hv.c == pytest.approx(camera.cy, abs=0.5)
        assert hu.rms < 0.3 and hv.rms < 0.3


def test_pads_too_small_to_find_are_skipped_and_counted() -> None:
    report = calibrate_tof_camera_in_sim(
        load_config("default"),
        TofRigConfig(stages=6, pad_radius_m=0.01, min_pad_area_px=12.0),
        np.random.default_rng(0),
    )
    missed = np.asarray(report.skipped[PAD_NOT_FOUND])
    # a 1 cm pad covers fewer than 12 px beyond about 1.3 m: the far stages are skipped
    assert np.all(missed >= 1)
    assert np.all(np.isnan(report.ranges[-1]))
    kept = np.isfinite(report.ranges).sum(axis=0)
    np.testing.assert_array_equal(kept + missed, 6)
    assert report.metadata["skipped"][PAD_NOT_FOUND] == missed.tolist()


def test_calibrate_command_writes_the_files_and_a_plot(tmp_path) -> None:
    out = tmp_path / "calibration"
    assert main(["calibrate", "--out", str(out), "--views", "6", "--stages", "8"]) == 0
    for name in ("intrinsics.json", "tof_camera.json", "tof_camera_curves.png", "summary.json"):
        assert (out / name).is_file(), name
    intrinsics = IntrinsicsCalibrationResult.load(out / "intrinsics.json")
    assert intrinsics.metadata["views_used"] + intrinsics.metadata["views_rejected"] == 6
    tof = TofCameraCalibration.load(out / "tof_camera.json")
    assert [len(s) for s in tof.samples] == [8, 8, 8, 8]
    summary = json.loads((out / "summary.json").read_text())
    assert abs(summary["intrinsics"]["k_error_pct"]["fx"]) < 1.0
    assert (out / "tof_camera_curves.png").stat().st_size > 10_000


def test_install_is_refused_for_another_camera(tmp_path) -> None:
    config = load_config("default", overrides={"camera.fx": 500.0})
    with pytest.raises(ConfigError, match="install"):
        run_calibration(config, out_dir=tmp_path, views=3, stages=2, install=True, progress=False)
    assert not any(tmp_path.iterdir())


def test_the_tag_rig_measures_the_realistic_cameras_shrunken_tag() -> None:
    """The realistic camera blurs in linear light before its gamma: the detected tag is
    smaller than the tag, most on diagonal edges; the fitted offset explains most of the
    corners' scatter."""
    from landing_env.calibration.tag_corner_sim import TagRigConfig, calibrate_tag_corners_in_sim

    config = load_config("realistic")
    rig = TagRigConfig(stages=3, views_per_stage=8, min_height_m=1.5, max_height_m=2.5)
    report = calibrate_tag_corners_in_sim(config, rig=rig, rng=np.random.default_rng(1))
    fit = report.fit
    assert report.missed_views == 0 and fit.views == 24
    assert -0.2 < fit.bias.b_px < -0.05  # diagonal edges move inwards by 0.05-0.2 px more
    assert fit.sigma_px < 0.6 * fit.sigma_uncorrected_px


def test_the_realistic_intrinsics_file_gives_tight_its_corner_offset_and_noise() -> None:
    """Rendering with the realistic calibration: tight gets the file's measured offset and
    corner noise; project mode's analytic corners have no offset."""
    from estimation.tight_config import TightConfig
    from landing_env.estimators import _with_sensor_noise, load_tag_corner_fit

    config = load_config("realistic")
    fit = load_tag_corner_fit(config)
    assert fit is not None
    settings = _with_sensor_noise(TightConfig(), config)
    assert settings.corner_bias_px == (fit.bias.a_px, fit.bias.b_px, fit.bias.c_px2)
    assert settings.pixel_sigma_px == fit.sigma_diagonal_px
    assert settings.pixel_sigma_axes_px == fit.sigma_axes_px
    project = load_config("realistic", overrides={"camera.mode": "project"})
    assert _with_sensor_noise(TightConfig(), project).corner_bias_px == (0.0, 0.0, 0.0)
    exact = load_config("realistic", overrides={"estimation.intrinsics": "exact"})
    assert load_tag_corner_fit(exact) is None
