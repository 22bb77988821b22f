"""Four downward Time-of-Flight range sensors on the drone's arms (IHRCF Eq. 12).

Each sensor is a ray from its origin along the body's down axis (+z_C, so the rays tilt with
the drone).  The range is the distance from the sensor origin to the first surface hit that
is not the drone itself.  No hit, a hit beyond ``max_range`` or nearer than ``min_range`` gives
NaN with ``valid = False``; a range is never clipped to a limit.

How the drone's own shapes are kept out: ``rayTestBatch`` reports only the first hit of each
ray, so every ray that hits ``exclude_body`` is cast again from just beyond that hit (up to
``MAX_SELF_HITS`` times, only those rays, in one batch per round; a ray still blocked by the
drone after that is reported invalid).  A ray that starts inside a
convex shape (box, sphere, cylinder, hull) does not hit it in Bullet (measured), so a sensor
mounted inside the drone's collision box never sees it; a hit on a face the ray leaves or on
a part below the sensor (a leg, a guard) is stepped over by the re-cast.  The tests check
both a sensor inside the drone's box and a leg right under a sensor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient

from estimation.frames import R_BC, tof_positions_in_camera_frame
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.noise import VL53L1X_RESOLUTION_M, VL53L1X_SIGMA_0_M, VL53L1X_SIGMA_PER_M
from estimation.types import RangeReading
from landing_env._quiet import client_id
from landing_env.errors import ConfigError, require_choice

#: Re-casts allowed per ray past the drone's own shapes (arms, legs, propeller guards...).
MAX_SELF_HITS = 8

#: How far past a self-hit the next cast starts, metres.  Bullet still reports a convex shape
#: hit (at fraction 0) from a start up to about 0.1 mm inside it (measured), so the step is
#: larger and doubles whenever a re-cast makes no progress.
_SELF_HIT_STEP = 1e-3
#: the hit point of a ray that hits nothing
_NAN_POINT = (math.nan, math.nan, math.nan)


def _default_mounts() -> tuple[tuple[float, float, float], ...]:
    return tuple(tuple(float(v) for v in row) for row in tof_positions_in_camera_frame())


@dataclass
class TofConfig:
    """The ToF sensors: geometry, range limits and the noise model.

    ``noise = "vl53l1x"`` models a VL53L1X-class sensor in long-distance mode: Gaussian noise
    with ``sigma = sigma_0 + sigma_per_m * range`` (defaults 2 mm + 2.5 mm/m, the model of
    :mod:`estimation.noise`, with its source, which the estimators weight ranges by),
    readings quantised to the sensor's 1 mm output, and an optional per-reading failure
    probability (ranging status not valid).
    """

    #: beyond this the ranging status is invalid, metres (VL53L1X long mode: 4 m)
    max_range: float = limited(4.0, POSITIVE, physical=Limit.positive(100.0, "VL53L1X: 4 m"))
    #: nearer than this the reading is invalid, metres
    min_range: float = limited(0.04, NON_NEGATIVE, physical=Limit.non_negative(100.0))
    noise: Literal["none", "vl53l1x"] = "none"
    sigma_0: float = limited(VL53L1X_SIGMA_0_M, NON_NEGATIVE, physical=Limit.non_negative(1.0))
    sigma_per_m: float = limited(
        VL53L1X_SIGMA_PER_M, NON_NEGATIVE, physical=Limit.non_negative(1.0)
    )
    #: output resolution in vl53l1x mode, metres (0 = no quantisation)
    resolution: float = limited(
        VL53L1X_RESOLUTION_M, NON_NEGATIVE, physical=Limit.non_negative(1.0)
    )
    #: probability of an invalid ranging status on an in-range target (vl53l1x mode)
    invalid_prob: float = limited(0.0, Limit(0.0, 1.0))
    #: sensor origins in the camera frame C, metres (sensor order ps1..ps4)
    mount_offsets_c: tuple[tuple[float, float, float], ...] = limited(
        _default_mounts(), physical=Limit.symmetric(10.0)
    )
    #: beam misalignment: per sensor, its beam turned about the camera's x then y axis from
    #: the optical axis, degrees (empty: every beam along +z_C, as the estimators assume)
    beam_tilts_deg: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        require_limits(self)
        if self.min_range >= self.max_range:
            raise ConfigError(
                "min_range", f"{self.min_range} must be below max_range = {self.max_range}"
            )
        require_choice("noise", self.noise, ("none", "vl53l1x"))
        if len(self.mount_offsets_c) == 0 or any(len(m) != 3 for m in self.mount_offsets_c):
            raise ConfigError("mount_offsets_c", "need one or more (x, y, z) sensor origins")
        if self.beam_tilts_deg and (
            len(self.beam_tilts_deg) != len(self.mount_offsets_c)
            or any(len(t) != 2 or not all(abs(a) < 45.0 for a in t) for t in self.beam_tilts_deg)
        ):
            raise ConfigError(
                "beam_tilts_deg",
                f"{self.beam_tilts_deg!r}: need one (about x, about y) pair per sensor, "
                "each angle within +-45 deg, or none",
            )

    def beam_directions_c(self) -> np.ndarray:
        """Each sensor's unit beam direction in the camera frame C."""
        count = len(self.mount_offsets_c)
        if not self.beam_tilts_deg:
            return np.tile([0.0, 0.0, 1.0], (count, 1))
        directions = np.empty((count, 3))
        for i, (about_x, about_y) in enumerate(np.radians(self.beam_tilts_deg)):
            # R_y(about_y) R_x(about_x) applied to +z
            directions[i] = (
                np.cos(about_x) * np.sin(about_y),
                -np.sin(about_x),
                np.cos(about_x) * np.cos(about_y),
            )
        return directions

    def sigma(self, ranges: np.ndarray) -> np.ndarray:
        """Noise standard deviation at the given ranges, metres (zero without noise)."""
        if self.noise == "none":
            return np.zeros_like(np.asarray(ranges, dtype=float))
        return self.sigma_0 + self.sigma_per_m * np.asarray(ranges, dtype=float)


class TofArray:
    """The ToF sensors of one drone: ``measure`` casts all rays in one ``rayTestBatch``."""

    def __init__(
        self,
        client: int | BulletClient,
        config: TofConfig,
        rng: np.random.Generator,
        t_bc: np.ndarray,
    ) -> None:
        self.client = client_id(client)
        self.config = config
        self.rng = rng
        mounts_c = np.asarray(config.mount_offsets_c, dtype=float)
        #: sensor origins in the body frame B
        self.origins_b = np.asarray(t_bc, dtype=float) + (R_BC @ mounts_c.T).T
        #: measuring directions in B: the camera's optical axis, the body's down axis, unless
        #: the beams are misaligned (``beam_tilts_deg``)
        self.directions_b = (R_BC @ config.beam_directions_c().T).T

    @property
    def count(self) -> int:
        return len(self.origins_b)

    def true_ranges(
        self, t_wb: np.ndarray, r_wb: np.ndarray, exclude_body: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free ranges (NaN where nothing within ``max_range``) and hit points in W."""
        r_wb = np.asarray(r_wb, dtype=float)
        origins = np.asarray(t_wb, dtype=float) + (r_wb @ self.origins_b.T).T
        directions = (r_wb @ self.directions_b.T).T
        max_range = self.config.max_range
        count = len(origins)
        # plain floats per ray: a handful of rays costs less as lists than as small arrays
        ranges = [math.nan] * count
        points: list[Any] = [_NAN_POINT] * count
        # distance along each ray at which its current cast starts
        start = [0.0] * count
        step = [_SELF_HIT_STEP] * count
        pending = list(range(count))
        froms, tos = origins.tolist(), (origins + max_range * directions).tolist()
        for _ in range(MAX_SELF_HITS + 1):
            results = p.rayTestBatch(froms, tos, physicsClientId=self.client)
            again: list[int] = []
            for index, result in zip(pending, results, strict=True):
                body, fraction = result[0], result[2]
                if body < 0:
                    continue
                distance = start[index] + fraction * (max_range - start[index])
                if body == exclude_body:
                    # a hit right at the start means the cast began inside the tolerance
                    step[index] = 2.0 * step[index] if fraction <= 1e-9 else _SELF_HIT_STEP
                    start[index] = distance + step[index]
                    if start[index] < max_range:
                        again.append(index)
                    continue
                ranges[index] = distance
                points[index] = result[3]
            if not again:
                break
            pending = again
            rays = np.asarray(again)
            starts = np.array([start[index] for index in again])
            froms = (origins[rays] + starts[:, None] * directions[rays]).tolist()
            tos = (origins[rays] + max_range * directions[rays]).tolist()
        return np.array(ranges), np.array(points, dtype=float)

    def measure(
        self, timestamp: float, t_wb: np.ndarray, r_wb: np.ndarray, exclude_body: int
    ) -> RangeReading:
        """The four readings at the body pose (t_wb, r_wb); invalid ones are NaN.

        Validity is decided on the reported (noisy, quantised) value, as the sensor's own
        range limits are: a valid reading always lies in ``[min_range, max_range]``, so the
        observation's ``tof_range`` never leaves its space.
        """
        cfg = self.config
        ranges, _ = self.true_ranges(t_wb, r_wb, exclude_body)
        # draw the random numbers every call so the stream does not depend on the scene
        gauss = self.rng.standard_normal(self.count)
        fails = self.rng.random(self.count) < cfg.invalid_prob
        if cfg.noise == "vl53l1x":
            ranges = ranges + cfg.sigma(ranges) * gauss
            if cfg.resolution > 0.0:
                ranges = np.round(ranges / cfg.resolution) * cfg.resolution
        valid = np.isfinite(ranges) & (ranges >= cfg.min_range) & (ranges <= cfg.max_range)
        if cfg.noise == "vl53l1x":
            valid &= ~fails
        ranges = np.where(valid, ranges, np.nan)
        return RangeReading(timestamp=timestamp, ranges=ranges, valid=valid)
