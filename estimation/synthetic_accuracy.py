"""The estimators' accuracy on synthetic geometry: random deck poses at fixed heights.

The issue's test case (issue 12): corner pixels with Gaussian noise (0.5 px) and ToF ranges
with ``sigma = max(5 mm, 0.5 % of range)``; over ``poses`` random poses per height (deck
tilted up to 15° about a random horizontal axis, any yaw, the tag in the central half of
the view), each estimator gets the same single frame (no history) and its absolute errors
are kept.  ``tight`` is told the noise it gets (the pixel sigma and the ToF model), as the
simulator tells it the configured sensors'.  Used by ``benchmarks/bench_synthetic_accuracy.py``
(the table) and ``tests/test_synthetic_accuracy.py`` (the ordering).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from estimation.camera_model import CameraIntrinsics
from estimation.frames import euler_zyx_from_matrix, tof_positions_in_camera_frame
from estimation.noise import TofNoiseModel
from estimation.registry import make_estimator
from estimation.synthetic import SyntheticScene
from estimation.tight_config import TightConfig
from estimation.tof_calibration import TofCameraCalibration
from estimation.types import CameraFrame, RangeReading, TagDetection

#: The issue's synthetic ToF model: sigma = max(5 mm, 0.5 % of the range), no quantisation.
ISSUE_TOF_NOISE = TofNoiseModel(0.0, 0.005, 0.0, sigma_min_m=0.005)
#: The issue's corner noise, pixels (1-sigma per coordinate).
ISSUE_PIXEL_SIGMA_PX = 0.5
ESTIMATORS = ("atda", "ihrcf", "crhf", "tight")


@dataclass(frozen=True)
class SyntheticAccuracy:
    """Absolute errors per height and estimator: (poses, 6) in metres and degrees."""

    errors: dict[float, dict[str, np.ndarray]]

    def mae(self, height: float) -> dict[str, np.ndarray]:
        return {name: e.mean(axis=0) for name, e in self.errors[height].items()}


def random_pose(
    rng: np.random.Generator, height: float, tag_size: float, camera: CameraIntrinsics
) -> tuple[np.ndarray, np.ndarray]:
    """A deck tilted up to 15° about a random horizontal axis, any yaw, the tag's centre in
    the central half of the view at ``height``."""
    axis = np.array([*rng.normal(size=2), 0.0])
    axis /= np.linalg.norm(axis)
    rotation = (
        Rotation.from_rotvec(math.radians(rng.uniform(0.0, 15.0)) * axis)
        * Rotation.from_euler("z", rng.uniform(-math.pi, math.pi))
    ).as_matrix()
    half = max(0.0, height * camera.cx / camera.fx - tag_size)
    return rotation, np.array([*(rng.uniform(-0.5, 0.5, 2) * half), height])


def synthetic_accuracy(
    heights: Sequence[float] = (0.5, 1.0, 2.0, 3.0),
    poses: int = 300,
    pixel_sigma_px: float = ISSUE_PIXEL_SIGMA_PX,
    tof_noise: TofNoiseModel = ISSUE_TOF_NOISE,
    tag_size: float = 0.30,
    camera: CameraIntrinsics | None = None,
    seed: int = 0,
) -> SyntheticAccuracy:
    """Errors of ATDA, IHRCF, CRHF and tight on the same noisy single frames (see above)."""
    k = camera or CameraIntrinsics()
    scene = SyntheticScene(k, tag_size)
    calibration = TofCameraCalibration.exact(k, tof_positions_in_camera_frame(), 0.04, 6.0)
    tight = TightConfig(
        pixel_sigma_px=pixel_sigma_px,
        tof_sigma_0_m=tof_noise.sigma_0_m,
        tof_sigma_per_m=tof_noise.sigma_per_m,
        tof_resolution_m=tof_noise.resolution_m,
        tof_sigma_min_m=tof_noise.sigma_min_m,
    )
    estimators = {
        name: make_estimator(
            name,
            intrinsics=k,
            tag_size=tag_size,
            tof_calibration=calibration,
            config=tight if name == "tight" else None,
        )
        for name in ESTIMATORS
    }
    rng = np.random.default_rng(seed)
    errors: dict[float, dict[str, np.ndarray]] = {}
    for height in heights:
        rows: dict[str, list[np.ndarray]] = {name: [] for name in estimators}
        for _ in range(poses):
            rotation, translation = random_pose(rng, height, tag_size, k)
            m = scene.measure(rotation, translation)
            pixels = m.true_corners_px + rng.normal(0.0, pixel_sigma_px, (4, 2))
            valid = np.isfinite(m.true_ranges)
            true_r = np.where(valid, m.true_ranges, 1.0)
            ranges = true_r + tof_noise.gaussian_sigma(true_r) * rng.normal(size=len(true_r))
            if tof_noise.resolution_m > 0.0:
                ranges = np.round(ranges / tof_noise.resolution_m) * tof_noise.resolution_m
            frame = CameraFrame(0.0, (TagDetection(0, pixels),) if m.frame.detections else ())
            reading = RangeReading(0.0, np.where(valid, ranges, np.nan), valid)
            truth = np.concatenate([translation, euler_zyx_from_matrix(rotation)])
            for name, estimator in estimators.items():
                estimator.reset()  # single frames: no history
                estimate = estimator.estimate(frame, reading)
                error = np.full(6, np.nan)
                if estimate.valid:
                    error = estimate.as_vector() - truth
                    error[3:] = (error[3:] + math.pi) % (2.0 * math.pi) - math.pi
                rows[name].append(np.abs(error) * [1.0, 1.0, 1.0, *[math.degrees(1.0)] * 3])
        errors[float(height)] = {name: np.array(r) for name, r in rows.items()}
    return SyntheticAccuracy(errors)


__all__ = [
    "ESTIMATORS",
    "ISSUE_PIXEL_SIGMA_PX",
    "ISSUE_TOF_NOISE",
    "SyntheticAccuracy",
    "random_pose",
    "synthetic_accuracy",
]
