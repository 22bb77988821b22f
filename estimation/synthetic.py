"""Synthetic measurements of a known deck pose, for tests and benchmarks.

Given the deck pose ``(R_CD, t_CD)``, the tag corners are projected through the camera
model and each ToF ray ``s_i + r e_z`` (sensor origin, along +z_C) is intersected with the
deck plane.  Noise is optional and comes only from a caller's ``numpy.random.Generator``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.frames import tag_corners_in_tag_frame, tof_positions_in_camera_frame
from estimation.types import CameraFrame, RangeReading, TagDetection

#: |cos| of the angle between a ToF ray and the deck normal below which the ray is taken
#: as parallel to the deck (no return).
_MIN_RAY_COSINE = 1e-9


@dataclass(frozen=True)
class SyntheticMeasurement:
    """One synthetic frame: what the sensors deliver and the noise-free truth behind it."""

    frame: CameraFrame
    ranges: RangeReading
    corners_c: np.ndarray
    true_corners_px: np.ndarray
    true_ranges: np.ndarray


@dataclass(frozen=True)
class SyntheticScene:
    """Camera, tag and ToF layout used to synthesise measurements.

    ``max_range_m``: rays longer than this give no return.  ``max_view_angle_deg``: the tag
    is not detected when the angle between its normal and the line of sight to its centre
    is larger.  ``deck_half_size_m``: if set,
    the deck is a square of this half-size centred on the tag (in D's x–y), and rays that
    land outside it give no return; otherwise the deck plane is unbounded.
    """

    intrinsics: CameraIntrinsics
    tag_size: float
    tag_id: int = 0
    tof_positions_c: np.ndarray | None = None
    max_range_m: float = np.inf
    deck_half_size_m: float | None = None
    max_view_angle_deg: float = 80.0

    @property
    def sensors(self) -> np.ndarray:
        if self.tof_positions_c is None:
            return tof_positions_in_camera_frame()
        return np.asarray(self.tof_positions_c, dtype=float).reshape(-1, 3)

    def true_ranges(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """Noise-free ranges along +z_C (NaN where the ray misses or exceeds the max range)."""
        sensors = self.sensors
        normal = rotation[:, 2]
        cosine = normal[2]
        ranges = np.full(len(sensors), np.nan)
        if abs(cosine) <= _MIN_RAY_COSINE:
            return ranges
        r = ((translation - sensors) @ normal) / cosine
        hit = (r > 0.0) & (r <= self.max_range_m)
        if self.deck_half_size_m is not None:
            touch = sensors + np.outer(r, [0.0, 0.0, 1.0])
            in_deck = (touch - translation) @ rotation[:, :2]
            hit &= np.all(np.abs(in_deck) <= self.deck_half_size_m, axis=1)
        ranges[hit] = r[hit]
        return ranges

    def measure(
        self,
        rotation: np.ndarray,
        translation: np.ndarray,
        *,
        timestamp: float = 0.0,
        pixel_noise_px: float = 0.0,
        range_noise_m: float = 0.0,
        rng: np.random.Generator | None = None,
    ) -> SyntheticMeasurement:
        """Camera frame and ToF reading of the deck at pose ``(R_CD, t_CD)``.

        The tag is detected when all four corners are in front of the camera, inside the
        image, and the tag faces the camera; otherwise the frame has no detection and a
        ``miss_reason``.  Gaussian noise (std ``pixel_noise_px`` per corner coordinate,
        ``range_noise_m`` per valid range) needs ``rng``.
        """
        if (pixel_noise_px > 0.0 or range_noise_m > 0.0) and rng is None:
            raise ValueError("noise needs a numpy.random.Generator (rng)")
        rotation = np.asarray(rotation, dtype=float)
        translation = np.asarray(translation, dtype=float)
        corners_c = tag_corners_in_tag_frame(self.tag_size) @ rotation.T + translation
        pixels = self.intrinsics.project(corners_c)
        miss_reason = ""
        k = self.intrinsics
        if np.any(corners_c[:, 2] <= 0.0) or not np.all(np.isfinite(pixels)):
            miss_reason = "out_of_view"
        elif (
            np.any(pixels < -0.5)
            or np.any(pixels[:, 0] > k.width - 0.5)
            or np.any(pixels[:, 1] > k.height - 0.5)
        ):
            miss_reason = "out_of_view"
        elif float(rotation[:, 2] @ translation) <= np.linalg.norm(translation) * np.cos(
            np.radians(self.max_view_angle_deg)
        ):
            # the tag's z points into the deck: seen edge-on or from behind, it is not visible
            miss_reason = "too_oblique"
        measured_px = pixels.copy()
        if pixel_noise_px > 0.0 and rng is not None:
            measured_px = measured_px + rng.normal(0.0, pixel_noise_px, size=measured_px.shape)
        detections: tuple[TagDetection, ...] = ()
        if not miss_reason:
            detections = (TagDetection(tag_id=self.tag_id, corners_px=measured_px),)
        true_r = self.true_ranges(rotation, translation)
        valid = np.isfinite(true_r)
        measured_r = true_r.copy()
        if range_noise_m > 0.0 and rng is not None:
            measured_r[valid] += rng.normal(0.0, range_noise_m, size=int(valid.sum()))
        return SyntheticMeasurement(
            frame=CameraFrame(timestamp=timestamp, detections=detections, miss_reason=miss_reason),
            ranges=RangeReading(timestamp=timestamp, ranges=measured_r, valid=valid),
            corners_c=corners_c,
            true_corners_px=pixels,
            true_ranges=true_r,
        )
