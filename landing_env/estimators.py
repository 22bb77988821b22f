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

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from estimation.atda import JointAtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.estimator import DeckPoseEstimator, RankedEstimator, make_estimator
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.landmarks import LandmarkChoiceConfig, LandmarkEstimator
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import CornerTracker, TrackedEstimator
from estimation.types import CameraFrame, DeckPoseEstimate, ImuSample, RangeReading
from landing_env.config import AUTO_RANKING, DeckLandingConfig
from landing_env.errors import ConfigError
from landing_env.vision_link import VisionStage

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
        # `fused` runs after the per-frame estimators (VisionStage), on its sources' output
        fusion = config.estimation.fusion if "fused" in names else None
        if fusion is not None:
            names = [n for n in dict.fromkeys((*names, *fusion.sources)) if n != "fused"]
        self._intrinsics: CameraIntrinsics | None = None
        self._tof_calibration: TofCameraCalibration | None = None
        self.estimators: dict[str, DeckPoseEstimator | TruthEstimator] = {
            name: self._make(name, world) for name in names
        }
        self._world = world
        mounts = np.asarray(config.tof.mount_offsets_c, dtype=float)
        self.vision = VisionStage(config.estimation.vision_link, fusion, mounts, world.t_bc)

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
        if name == "beacon":
            return _make_beacon(self.intrinsics, self.config, world)
        if name == "auto":
            # its own instances: the ranked ones may also be compared under their names
            return RankedEstimator(name, tuple(self._make(n, world) for n in AUTO_RANKING))
        layout = self.config.deck.layout
        if layout.is_single_centred:
            only = layout.landmarks[0]
            return self._make_for_tag(name, only.tag_id, only.size)
        # nested landmarks: one estimator per tag, run on the chosen one, reporting T_CD of D;
        # the ToF estimators prefer the tag nearest the landing point (estimation.landmarks)
        choice = LandmarkChoiceConfig(prefer="nearest" if name in ("ihrcf", "crhf") else "largest")
        single = LandmarkEstimator(
            name, layout, lambda lm: self._make_for_tag(name, lm.tag_id, lm.size), choice
        )
        atda = self.config.estimation.atda
        if name != "atda" or not atda.joint_landmarks:
            return single
        # ATDA: one PnP over every detected tag, the chosen tag alone when only one is seen
        return JointAtdaEstimator(
            intrinsics=self.intrinsics,
            layout=layout,
            single=single,
            min_side_px=choice.min_side_px,
            config=atda,
        )

    def _make_for_tag(self, name: str, tag_id: int, tag_size: float) -> DeckPoseEstimator:
        cfg = self.config
        est = cfg.estimation
        mounts = np.asarray(cfg.tof.mount_offsets_c, dtype=float)
        needs_tof = name in ("ihrcf", "crhf")
        # loaded outside the try: their errors already name their full keys
        intrinsics = self.intrinsics
        tof_calibration = self.tof_calibration if needs_tof else None
        try:
            estimator = make_estimator(
                name,
                # IHRCF and CRHF need no K: they only undistort with it (when it has distortion)
                intrinsics=intrinsics,
                tag_size=tag_size,
                tag_id=tag_id,
                tof_calibration=tof_calibration,
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


def _make_beacon(
    intrinsics: CameraIntrinsics, config: DeckLandingConfig, world: World
) -> DeckPoseEstimator:
    """The IR-LOCK-style ``beacon`` estimator: tag-centre bearing + the downward rangefinder
    (position only; its orientation is reported level, ``orientation_known = False``)."""
    from estimation.beacon import BeaconConfig, BeaconEstimator

    # the rangefinder's origin below the camera along the optical axis (+z_C = -z_B)
    offset = float(world.t_bc[2] - config.rangefinder.mount_offset_b[2])

    def one(tag_id: int) -> BeaconEstimator:
        return BeaconEstimator(
            intrinsics, tag_id, lambda: world.last_range_down, BeaconConfig(range_offset_m=offset)
        )

    layout = config.deck.layout
    if layout.is_single_centred:
        return one(layout.landmarks[0].tag_id)
    # nested landmarks: the chosen tag's centre, moved to D's origin under the level assumption
    return LandmarkEstimator("beacon", layout, lambda lm: one(lm.tag_id))


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
    "load_intrinsics",
    "load_tof_calibration",
]
