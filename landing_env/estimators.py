"""The estimators the environment runs each step: the observed one and those compared.

``estimation.observed`` and ``estimation.compare`` name them (``truth``, ``atda``, ``ihrcf``,
``crhf``); all run on the same camera frame and ToF reading.  Their calibrations come from
the files in ``configs/calibration/`` (or the configured ones, or the exact model), and are
checked against the configured camera and ToF layout when the environment is built: a
calibration made for another camera is refused there, not discovered as bad estimates.
Nothing raises while stepping: an estimator that cannot estimate (or that raises, or whose
pose falls outside the observation's bounds) gives an invalid estimate with its reason.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.estimator import DeckPoseEstimator, make_estimator
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import CornerTracker, TrackedEstimator
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading
from landing_env.config import DeckLandingConfig
from landing_env.errors import ConfigError

if TYPE_CHECKING:
    from landing_env.world import World

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


def _camera_differences(metadata: dict, camera: CameraIntrinsics) -> list[str]:
    """The camera parameters in which a calibration's recorded camera differs from ``camera``."""
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
        if not np.allclose(np.asarray(recorded[key], dtype=float), value, rtol=1e-9, atol=1e-12):
            differences.append(f"{key} {recorded[key]} (configured {value})")
    return differences


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
        raise ConfigError(
            "estimation.intrinsics_file",
            f"{path} is for {result.image_size[0]}x{result.image_size[1]} images, the camera "
            f"gives {camera.width}x{camera.height}; {_RECALIBRATE}",
        )
    differences = _camera_differences(result.metadata, camera)
    if differences:
        raise ConfigError(
            "estimation.intrinsics_file",
            f"{path} was calibrated for another camera: {'; '.join(differences)}; {_RECALIBRATE}",
        )
    return result.to_intrinsics()


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
        differences.append(f"tof_mount_offsets_c {recorded_mounts} (configured {mounts.tolist()})")
    if differences:
        raise ConfigError(
            "estimation.tof_calibration_file",
            f"{path} was calibrated for another camera or ToF layout: "
            f"{'; '.join(differences)}; {_RECALIBRATE}",
        )
    return calibration.with_method(est.tof_lookup)


class EstimatorBank:
    """Runs the observed estimator and every compared one on the same sensor data.

    ``pose_bounds``: (low, high) of (x, y, z, roll, pitch, yaw); a valid estimate outside
    them is reported invalid (``out_of_observation_bounds``) rather than clipped.
    """

    def __init__(
        self,
        config: DeckLandingConfig,
        world: World,
        pose_bounds: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.config = config
        self.pose_bounds = pose_bounds
        names = list(dict.fromkeys((config.estimation.observed, *config.estimation.compare)))
        self._intrinsics: CameraIntrinsics | None = None
        self._tof_calibration: TofCameraCalibration | None = None
        self.estimators: dict[str, DeckPoseEstimator | TruthEstimator] = {
            name: self._make(name, world) for name in names
        }

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera model the estimators use (loaded once)."""
        if self._intrinsics is None:
            self._intrinsics = load_intrinsics(self.config)
        return self._intrinsics

    @property
    def tof_calibration(self) -> TofCameraCalibration:
        """The ToF–camera look-up IHRCF and CRHF use (loaded once)."""
        if self._tof_calibration is None:
            self._tof_calibration = load_tof_calibration(self.config)
        return self._tof_calibration

    def _make(self, name: str, world: World) -> DeckPoseEstimator | TruthEstimator:
        if name == "truth":
            return TruthEstimator(world)
        cfg = self.config
        est = cfg.estimation
        mounts = np.asarray(cfg.tof.mount_offsets_c, dtype=float)
        needs_tof = name in ("ihrcf", "crhf")
        try:
            estimator = make_estimator(
                name,
                # IHRCF and CRHF need no K: they only undistort with it (when it has distortion)
                intrinsics=self.intrinsics,
                tag_size=cfg.deck.tag_size,
                tag_id=cfg.deck.tag_id,
                tof_calibration=self.tof_calibration if needs_tof else None,
                tof_positions_c=mounts if needs_tof else None,
                config=getattr(est, name),
            )
        except ConfigError as exc:
            raise exc.under(f"estimation.{name}") from None
        if est.tracking:
            tracker = CornerTracker(
                dt=1.0 / cfg.simulation.env_hz, max_bridged_frames=est.max_bridged_frames
            )
            estimator = TrackedEstimator(estimator, tracker, name=name)
        return estimator

    def reset(self) -> None:
        for estimator in self.estimators.values():
            estimator.reset()

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> dict[str, DeckPoseEstimate]:
        results = {}
        for name, estimator in self.estimators.items():
            try:
                estimate = estimator.estimate(frame, ranges)
            except Exception as exc:  # an estimator must never break step(): flag it instead
                estimate = DeckPoseEstimate.invalid(
                    name, frame.timestamp, f"estimator error: {type(exc).__name__}: {exc}"
                )
            results[name] = self._within_bounds(estimate)
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
    }


__all__ = [
    "OUT_OF_BOUNDS",
    "EstimatorBank",
    "TruthEstimator",
    "describe_estimate",
    "load_intrinsics",
    "load_tof_calibration",
]
