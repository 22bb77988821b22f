"""One downward long-range rangefinder (a LIDAR-Lite v3-class laser), IR-LOCK's companion.

The beam points along the body's down axis (it tilts with the drone) from a mount in the
body frame.  It measures the distance to the first surface that is not the drone itself (the
deck when the drone is over it, the sea otherwise).  No return within ``max_range``, or a
target nearer than ``min_range`` (judged on the reported, noisy value), gives NaN with
``valid = False``, never a clipped value.

The ray cast reuses :class:`~landing_env.sensors.tof.TofArray` (one sensor, the same
self-hit handling); the noise model is the LIDAR-Lite's: Gaussian with
``sigma = sigma_0 + sigma_per_m * range`` (defaults 2.5 cm + 0.1 %/m, the part's "+-2.5 cm
at > 1 m" accuracy), quantised to its 1 cm output, and an optional per-reading failure
probability (a weak return).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pybullet_utils.bullet_client import BulletClient

from estimation.frames import R_BC
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.types import RangeReading
from landing_env.errors import ConfigError
from landing_env.sensors.tof import TofArray, TofConfig


@dataclass
class RangefinderConfig:
    """The downward rangefinder (``rangefinder.*``); on by default."""

    enabled: bool = True
    #: longest valid range, metres (LIDAR-Lite v3: 40 m)
    max_range: float = limited(40.0, POSITIVE, physical=Limit.positive(1e3, "LIDAR-Lite v3: 40 m"))
    #: shortest valid range, metres
    min_range: float = limited(0.05, NON_NEGATIVE, physical=Limit.non_negative(1e3))
    #: noise standard deviation at zero range, metres
    sigma_0: float = limited(0.025, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    #: growth of the standard deviation with range, metres per metre
    sigma_per_m: float = limited(0.001, NON_NEGATIVE, physical=Limit.non_negative(1.0))
    #: output resolution, metres (0 = no quantisation)
    resolution: float = limited(0.01, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    #: probability of no reading on an in-range target
    invalid_prob: float = limited(0.0, Limit(0.0, 1.0))
    #: beam origin in the body frame B, metres (beside the camera, under the centre of mass)
    mount_offset_b: tuple[float, float, float] = limited(
        (0.0, 0.0, -0.03), physical=Limit.symmetric(10.0)
    )

    def __post_init__(self) -> None:
        require_limits(self)
        if self.min_range >= self.max_range:
            raise ConfigError(
                "min_range", f"{self.min_range} must be below max_range = {self.max_range}"
            )
        if len(self.mount_offset_b) != 3:
            raise ConfigError("mount_offset_b", "needs (x, y, z) in the body frame, metres")
        self.mount_offset_b = tuple(float(v) for v in self.mount_offset_b)


class Rangefinder:
    """The downward rangefinder of one drone; ``measure`` casts its ray."""

    def __init__(
        self, client: int | BulletClient, config: RangefinderConfig, rng: np.random.Generator
    ) -> None:
        self.config = config
        self.rng = rng
        # one ToF-style ray from the mount along the body's down axis (the camera's +z)
        ray = TofConfig(
            max_range=config.max_range,
            min_range=config.min_range,
            mount_offsets_c=((0.0, 0.0, 0.0),),
        )
        self._ray = TofArray(client, ray, rng, np.asarray(config.mount_offset_b, dtype=float))
        assert np.allclose(self._ray.directions_b[0], R_BC[:, 2])

    def measure(
        self, timestamp: float, t_wb: np.ndarray, r_wb: np.ndarray, exclude_body: int
    ) -> RangeReading:
        """One reading (shape (1,)): NaN and invalid without a return in range or when off."""
        cfg = self.config
        # draw the random numbers every call so the stream does not depend on the scene
        gauss = float(self.rng.standard_normal())
        fails = bool(self.rng.random() < cfg.invalid_prob)
        if not cfg.enabled:
            return RangeReading(timestamp, np.full(1, np.nan), np.zeros(1, dtype=bool))
        ranges, _ = self._ray.true_ranges(t_wb, r_wb, exclude_body)
        true = float(ranges[0])
        value = true + (cfg.sigma_0 + cfg.sigma_per_m * true) * gauss
        # no return (NaN, e.g. the beam pointing up) stays NaN: never round a non-finite value
        if cfg.resolution > 0.0 and math.isfinite(value):
            value = round(value / cfg.resolution) * cfg.resolution
        # the limits apply to what the sensor reports, so a valid reading is always within them
        valid = math.isfinite(value) and cfg.min_range <= value <= cfg.max_range and not fails
        if not valid:
            return RangeReading(timestamp, np.full(1, np.nan), np.zeros(1, dtype=bool))
        return RangeReading(timestamp, np.array([value]), np.ones(1, dtype=bool))
