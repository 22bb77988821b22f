"""The estimators the environment runs each step: the observed one and those compared.

``estimation.observed`` and ``estimation.compare`` name them (the names of
:data:`estimation.registry.ESTIMATOR_NAMES`); all run on the same camera frame and ToF
reading.  They are built by :mod:`estimation.pipeline` from one options object; this module
adds the ground truth and loads the calibration files.  Their calibrations come from
the files in ``configs/calibration/`` (or the configured ones, or the exact model), and are
checked against the configured camera and ToF layout when the environment is built: a
calibration made for another camera is refused there, not discovered as bad estimates.
Nothing raises while stepping: an estimator that cannot estimate (or that raises, or whose
pose falls outside the observation's bounds) gives an invalid estimate with its reason.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.corner_bias import CornerBiasFit
from estimation.estimator import DeckPoseEstimator
from estimation.fusion import FusionConfig
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.noise import TofNoiseModel
from estimation.pipeline import (
    EstimationOptions,
    build_estimators,
    names_to_build,
    needs_intrinsics,
    needs_tof_calibration,
)
from estimation.registry import REGISTRY
from estimation.tight_config import TightConfig
from estimation.tof_calibration import TofCameraCalibration
from estimation.types import CameraFrame, DeckPoseEstimate, ImuSample, RangeReading
from landing_env.config import DeckLandingConfig
from landing_env.errors import ConfigError
from landing_env.vision_link import VisionStage

if TYPE_CHECKING:
    from landing_env.world import World

#: tight's pixel sigma for the exact corners of ``camera.mode: project`` without pixel noise.
PROJECT_PIXEL_SIGMA_FLOOR_PX = 0.01

#: Reason of a valid estimate refused because it lies outside the observation's bounds.
OUT_OF_BOUNDS = "out_of_observation_bounds"

_RECALIBRATE = (
    "run `deck-landing calibrate --config <your config> --out DIR` and set "
    "estimation.intrinsics_file / estimation.tof_calibration_file to the files in DIR, "
    "or use the exact models (estimation.intrinsics: exact, estimation.tof_calibration: exact)"
)


class TruthEstimator:
    """The ground-truth deck pose, in the estimate type; the reference and the default."""

    name = "truth"

    def __init__(self, world: World) -> None:
        self.world = world

    def reset(self) -> None:
        """Nothing to forget."""

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        rotation, translation = self.world.true_deck_pose_c()
        return DeckPoseEstimate(
            method=self.name,
            timestamp=frame.timestamp,
            valid=True,
            rotation=rotation,
            translation=translation,
        )


#: The config keys of the distortion coefficients, in OpenCV's order.
_DIST_KEYS = ("camera.k1", "camera.k2", "camera.p1", "camera.p2", "camera.k3")


def _camera_differences(metadata: dict, camera: CameraIntrinsics) -> list[str]:
    """The camera keys in which a calibration's recorded camera differs from ``camera``."""
    recorded = metadata.get("camera")
    if not isinstance(recorded, dict):
        return []
    actual = {
        "width": camera.width,
        "height": camera.height,
        "fx": camera.fx,
        "fy": camera.fy,
        "cx": camera.cx,
        "cy": camera.cy,
        "dist": list(camera.dist),
    }
    differences = []
    for key, value in actual.items():
        if key not in recorded:
            continue
        calibrated = np.asarray(recorded[key], dtype=float).reshape(-1)
        configured = np.asarray(value, dtype=float).reshape(-1)
        if calibrated.shape == configured.shape and np.allclose(
            calibrated, configured, rtol=1e-9, atol=1e-12
        ):
            continue
        if key != "dist" or calibrated.shape != configured.shape:
            differences.append(f"camera.{key} = {value} (calibrated for {recorded[key]})")
            continue
        for name, cal, conf in zip(_DIST_KEYS, calibrated, configured, strict=False):
            if not np.isclose(cal, conf, rtol=1e-9, atol=1e-12):
                differences.append(f"{name} = {conf} (calibrated for {cal})")
    return differences


def _changed_camera(path: object, differences: list[str]) -> str:
    return (
        f"the configured camera differs from the one {path} was calibrated for: "
        f"{'; '.join(differences)}; a changed camera needs a matching calibration: "
        f"{_RECALIBRATE}"
    )


def load_intrinsics(config: DeckLandingConfig) -> CameraIntrinsics:
    """The camera model the estimators use: the calibration file's, or the exact one."""
    camera = config.camera.intrinsics
    est = config.estimation
    if est.intrinsics == "exact":
        return camera
    path = est.intrinsics_path
    try:
        result = IntrinsicsCalibrationResult.load(path)
    except (OSError, ValueError, KeyError) as exc:
        raise ConfigError("estimation.intrinsics_file", f"{path}: {exc}") from None
    if tuple(result.image_size) != (camera.width, camera.height):
        differences = [
            f"camera.{key} = {value} (calibrated for {calibrated})"
            for key, value, calibrated in zip(
                ("width", "height"), (camera.width, camera.height), result.image_size, strict=True
            )
            if value != calibrated
        ]
        raise ConfigError("estimation.intrinsics_file", _changed_camera(path, differences))
    differences = _camera_differences(result.metadata, camera)
    if differences:
        raise ConfigError("estimation.intrinsics_file", _changed_camera(path, differences))
    return result.to_intrinsics()


def load_tag_corner_fit(config: DeckLandingConfig) -> CornerBiasFit | None:
    """The tag corners' offset and noise the intrinsics file measured for its camera (None
    with ``estimation.intrinsics: exact`` or a file made without them)."""
    if config.estimation.intrinsics == "exact":
        return None
    path = config.estimation.intrinsics_path
    try:
        result = IntrinsicsCalibrationResult.load(path)
        return None if result.tag_corners is None else CornerBiasFit.from_dict(result.tag_corners)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError("estimation.intrinsics_file", f"{path}: {exc}") from None


def load_tof_calibration(config: DeckLandingConfig) -> TofCameraCalibration:
    """The ToF–camera look-up IHRCF and CRHF use: the calibration file's, or the exact map."""
    est = config.estimation
    mounts = np.asarray(config.tof.mount_offsets_c, dtype=float)
    camera = config.camera.intrinsics
    if est.tof_calibration == "exact":
        return TofCameraCalibration.exact(
            camera, mounts, config.tof.min_range, config.tof.max_range
        )
    path = est.tof_calibration_path
    try:
        calibration = TofCameraCalibration.load(path)
    except (OSError, ValueError, KeyError) as exc:
        raise ConfigError("estimation.tof_calibration_file", f"{path}: {exc}") from None
    if calibration.n_sensors != len(mounts):
        raise ConfigError(
            "estimation.tof_calibration_file",
            f"{path} has {calibration.n_sensors} sensors, tof.mount_offsets_c has {len(mounts)}",
        )
    differences = _camera_differences(calibration.metadata, camera)
    recorded_mounts = calibration.metadata.get("tof_mount_offsets_c")
    if recorded_mounts is not None and not np.allclose(recorded_mounts, mounts, atol=1e-9):
        differences.append(
            f"tof.mount_offsets_c = {mounts.tolist()} (calibrated for {recorded_mounts})"
        )
    if differences:
        raise ConfigError("estimation.tof_calibration_file", _changed_camera(path, differences))
    return calibration.with_method(est.tof_lookup)


def _tof_calibration_for(
    config: DeckLandingConfig, names: list[str]
) -> TofCameraCalibration | None:
    """The ToF–camera calibration when a name needs it, or can use it and it exists."""
    if needs_tof_calibration(names):
        return load_tof_calibration(config)
    est = config.estimation
    if needs_tof_calibration(names, optional=True) and (
        est.tof_calibration == "exact" or est.tof_calibration_path.is_file()
    ):
        return load_tof_calibration(config)
    return None


def sensor_tof_noise(config: DeckLandingConfig) -> TofNoiseModel:
    """The configured ToF sensors' noise model (exact ranges for ``tof.noise: none``)."""
    tof = config.tof
    if tof.noise == "none":
        return TofNoiseModel.exact()
    return TofNoiseModel(tof.sigma_0, tof.sigma_per_m, tof.resolution)


def _with_sensor_noise(settings: object, config: DeckLandingConfig) -> object:
    """An estimator's settings with the configured sensors' noise, where it asks for it."""
    if isinstance(settings, TightConfig) and settings.noise_from_sensors:
        noise = sensor_tof_noise(config)
        changes: dict = {
            "tof_sigma_0_m": noise.sigma_0_m,
            "tof_sigma_per_m": noise.sigma_per_m,
            "tof_resolution_m": noise.resolution_m,
        }
        camera = config.camera
        if camera.mode == "project":
            # the analytic camera's corner noise is exactly the configured one (0: exact
            # corners, weighted as 0.01 px so that the weights stay finite)
            changes["pixel_sigma_px"] = max(camera.pixel_noise_px, PROJECT_PIXEL_SIGMA_FLOOR_PX)
        else:
            fit = load_tag_corner_fit(config)
            if fit is not None:
                # the detector's corner offset and noise measured on this camera
                bias = fit.bias
                changes["corner_bias_px"] = (bias.a_px, bias.b_px, bias.c_px2)
                measured = fit.sigma_diagonal_px > 0.0 and fit.sigma_axes_px > 0.0
                changes["pixel_sigma_px"] = fit.sigma_diagonal_px if measured else fit.sigma_px
                changes["pixel_sigma_axes_px"] = fit.sigma_axes_px if measured else 0.0
        return dataclasses.replace(settings, **changes)
    return settings


def deck_waves_of_motion(config: DeckLandingConfig) -> dict | None:
    """The fusion's wave components from a ``sinusoids`` motion: per roll and pitch the
    periods of its two largest components and the axis' RMS, ``sqrt(sum A² / 2)`` (None for
    another motion or an axis with fewer than two components)."""
    motion = config.motion
    if motion.kind != "sinusoids":
        return None
    waves: dict = {}
    rms = []
    for axis, key in ((3, "deck_roll_periods_s"), (4, "deck_pitch_periods_s")):
        amplitudes = np.abs(np.asarray(motion.sinusoids.amplitudes[axis], dtype=float))
        frequencies = np.asarray(motion.sinusoids.frequencies_hz[axis], dtype=float)
        if len(amplitudes) < 2:
            return None
        largest = np.argsort(amplitudes)[::-1][:2]
        waves[key] = tuple(sorted((float(1.0 / frequencies[i]) for i in largest), reverse=True))
        rms.append(float(np.sqrt(np.sum(amplitudes**2) / 2.0)))
    waves["deck_attitude_rms_deg"] = tuple(rms)
    return waves


def fusion_settings(config: DeckLandingConfig) -> FusionConfig:
    """The fusion's settings with the configured ToF sensors' noise and the sea's wave
    components, where it asks for them."""
    fusion = config.estimation.fusion
    if fusion.deck_waves_from_motion:
        waves = deck_waves_of_motion(config)
        if waves is not None:
            try:
                fusion = dataclasses.replace(fusion, **waves)
            except ValueError as error:  # estimation's ConfigError: a wave out of its range
                raise ConfigError("motion.sinusoids", f"as the fusion's waves: {error}") from None
    if not fusion.noise_from_sensors:
        return fusion
    noise = sensor_tof_noise(config)
    return dataclasses.replace(
        fusion,
        tof_sigma_m=noise.sigma_0_m,
        tof_sigma_per_m=noise.sigma_per_m,
        tof_resolution_m=noise.resolution_m,
    )


def estimation_options(config: DeckLandingConfig, world: World) -> EstimationOptions:
    """The one options object the estimators are built from: the configured names and
    settings, the calibrations they need (loaded here) and the world's sensor glue."""
    est = config.estimation
    names = names_to_build(est.observed, est.compare, est.fusion.sources)
    # the rangefinder's origin below the camera along the optical axis (+z_C = -z_B)
    range_offset = float(world.t_bc[2] - config.rangefinder.mount_offset_b[2])
    return EstimationOptions(
        names=tuple(names),
        layout=config.deck.layout,
        intrinsics=load_intrinsics(config) if needs_intrinsics(names) else None,
        tof_calibration=_tof_calibration_for(config, names),
        tof_positions_c=np.asarray(est.tof_positions_c or config.tof.mount_offsets_c, dtype=float),
        # a registered estimator without a section in the config runs with its defaults
        configs={
            name: _with_sensor_noise(getattr(est, name), config)
            for name in (*REGISTRY, "beacon")
            if hasattr(est, name)
        },
        tracking=est.tracking,
        tracking_names=tuple(est.tracking_estimators),
        tracking_smooth=est.tracking_smooth,
        tracking_dt_s=1.0 / config.simulation.env_hz,
        max_bridged_frames=est.max_bridged_frames,
        range_down=lambda: world.last_range_down,
        range_offset_m=range_offset,
    )


class EstimatorBank:
    """Runs the observed estimator and every compared one on the same sensor data.

    The estimators come from :func:`estimation.pipeline.build_estimators` with the options
    :func:`estimation_options` fills from the configuration; the bank adds only the ground
    truth and the observation's bounds.  ``pose_bounds``: (low, high) of (x, y, z, roll,
    pitch, yaw); a valid estimate outside them is reported invalid
    (``out_of_observation_bounds``) rather than clipped.
    """

    def __init__(
        self,
        config: DeckLandingConfig,
        world: World,
        pose_bounds: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.config = config
        self.pose_bounds = pose_bounds
        est = config.estimation
        # `fused` runs after the per-frame estimators (VisionStage), on its sources' output
        fusion = fusion_settings(config) if "fused" in (est.observed, *est.compare) else None
        options = estimation_options(config, world)
        self.estimators: dict[str, DeckPoseEstimator | TruthEstimator] = dict(
            build_estimators(options, {"truth": TruthEstimator(world)})
        )
        self._world = world
        mounts = np.asarray(config.tof.mount_offsets_c, dtype=float)
        self.vision = VisionStage(est.vision_link, fusion, mounts, world.t_bc)

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """A new episode (``rng``: the env's generator, for the vision link's stream)."""
        for estimator in self.estimators.values():
            estimator.reset()
        self.vision.reset(rng)

    def estimate(
        self, frame: CameraFrame, ranges: RangeReading, imu_samples: Sequence[ImuSample] = ()
    ) -> dict[str, DeckPoseEstimate]:
        """Every estimate of this frame, through the vision link and the fusion (if set)."""
        results = {}
        for name, estimator in self.estimators.items():
            try:
                estimate = estimator.estimate(frame, ranges)
            except Exception as exc:  # an estimator must never break step(): flag it instead
                estimate = DeckPoseEstimate.invalid(
                    name, frame.timestamp, f"estimator error: {type(exc).__name__}: {exc}"
                )
            results[name] = self._within_bounds(estimate)
        r_wb = self._world.drone_state().rotation_wb
        results = self.vision.process(frame.timestamp, results, ranges, imu_samples, r_wb)
        if "fused" in results:
            fused = self._within_bounds(results["fused"])
            if fused.valid and fused.covariance is not None and self.pose_bounds is not None:
                # a 1-sigma beyond the observation's range says nothing: refuse, never clip
                if not np.all(_std(fused.covariance) <= self.pose_bounds[1]):
                    fused = DeckPoseEstimate.invalid("fused", fused.timestamp, OUT_OF_BOUNDS)
            results["fused"] = fused
        return results

    def _within_bounds(self, estimate: DeckPoseEstimate) -> DeckPoseEstimate:
        if not estimate.valid or self.pose_bounds is None:
            return estimate
        low, high = self.pose_bounds
        vector = estimate.as_vector()
        # the observation is float32: compare in float32 so a pose at a bound stays inside
        as_f32 = vector.astype(np.float32)
        if np.all(np.isfinite(vector)) and np.all((as_f32 >= low) & (as_f32 <= high)):
            return estimate
        return DeckPoseEstimate(
            method=estimate.method,
            timestamp=estimate.timestamp,
            valid=False,
            reason=OUT_OF_BOUNDS,
            predicted=estimate.predicted,
            extras={**estimate.extras, "pose": vector},
        )


def describe_estimate(estimate: DeckPoseEstimate) -> dict:
    """The estimate as ``info["estimates"][name]`` carries it (numpy scalars made plain)."""
    extras = {
        key: value.item() if isinstance(value, np.generic) else value
        for key, value in estimate.extras.items()
    }
    return {
        "pose": estimate.as_vector(),
        "valid": estimate.valid,
        "reason": estimate.reason,
        "predicted": estimate.predicted,
        "extras": extras,
        # 1-sigma of (x, y, z, roll, pitch, yaw) where the method gives a covariance (fused)
        **({"std": _std(estimate.covariance)} if estimate.covariance is not None else {}),
    }


def _std(covariance: np.ndarray) -> np.ndarray:
    # the clip only removes round-off below zero on the diagonal of a PSD matrix
    return np.sqrt(np.clip(np.diag(covariance), 0.0, None))


__all__ = [
    "OUT_OF_BOUNDS",
    "EstimatorBank",
    "TruthEstimator",
    "describe_estimate",
    "estimation_options",
    "load_intrinsics",
    "load_tof_calibration",
]
