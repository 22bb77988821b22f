"""Sensor noise models that the estimators weight their measurements with.

The simulator draws its noise from the same models (``landing_env.sensors.tof.TofConfig``
takes its defaults from here), so that an estimator configured with the defaults weights
each measurement by the noise it really has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.limits import NON_NEGATIVE, Limit, Limited, limited

#: VL53L1X-class ToF ranging noise (long-distance mode): sigma = SIGMA_0 + SIGMA_PER_M * r.
#: 2 mm + 2.5 mm/m is a few mm up close and 12 mm at 4 m, of the order of the +-20 mm
#: ranging accuracy that ST's VL53L1X datasheet (DS12385) quotes,
#: with the spread growing as the return signal weakens with distance.
VL53L1X_SIGMA_0_M = 0.002
VL53L1X_SIGMA_PER_M = 0.0025
#: the VL53L1X reports whole millimetres
VL53L1X_RESOLUTION_M = 0.001
#: the physical range of an IMU noise density or bias random walk
IMU_NOISE_DENSITY = Limit.non_negative(10.0, "IMU noise densities: MEMS datasheets give 1e-5..1e-2")

#: The sigma of an "exact" range.  On the noise-free bench CRHF's tilt MAE of 0.004° (the
#: README's paper-stewart table) says the simulator's ray casts agree with the plate's plane
#: to about 10 µm over the 14 cm sensor square, so exact ranges are weighted as 20 µm.
EXACT_RANGE_SIGMA_M = 2e-5

#: Default corner-pixel noise (1-sigma per coordinate) of pupil-apriltags on the simulator's
#: rendered 512 x 512 image: on `realistic` (tag 2 m below) tight's x, y scatter is 0.41 mm
#: where its covariance at 0.5 px says 1.18 mm, i.e. about 0.17 px; weighting by 0.25 px
#: instead of 0.5 px brought tight's roll/pitch MAE from 1.45/1.42 to 1.00/0.96 deg (120 s).
#: A real camera's detection noise (blur, exposure, a smaller tag) is larger: set
#: `pixel_sigma_px` to the measured one.
DEFAULT_PIXEL_SIGMA_PX = 0.2


@dataclass(frozen=True)
class TofNoiseModel(Limited):
    """Gaussian range noise ``sigma(r) = max(sigma_min_m, sigma_0_m + sigma_per_m * r)``,
    plus the uniform quantisation of a sensor that reports in steps of ``resolution_m``
    (variance step²/12).  ``sigma_min_m`` (default 0) gives a floor, e.g. ``max(5 mm, 0.5 %
    of range)``.

    Exact ranges (all zero) keep the floor :data:`EXACT_RANGE_SIGMA_M`, so that weights
    stay finite and a range is still compared with the plane at a scale it can meet.
    """

    sigma_0_m: float = limited(VL53L1X_SIGMA_0_M, NON_NEGATIVE)
    sigma_per_m: float = limited(VL53L1X_SIGMA_PER_M, NON_NEGATIVE)
    resolution_m: float = limited(VL53L1X_RESOLUTION_M, NON_NEGATIVE)
    sigma_min_m: float = limited(0.0, NON_NEGATIVE)

    @classmethod
    def exact(cls) -> TofNoiseModel:
        """Noise-free ranges (the papers' bench)."""
        return cls(0.0, 0.0, 0.0)

    def gaussian_sigma(self, ranges: np.ndarray | float) -> np.ndarray:
        """1-sigma of the Gaussian part at ``ranges`` metres (no quantisation, no floor for
        exact ranges): what a simulator draws before rounding to ``resolution_m``."""
        linear = self.sigma_0_m + self.sigma_per_m * np.asarray(ranges, dtype=float)
        return np.maximum(linear, self.sigma_min_m)

    def sigma(self, ranges: np.ndarray | float) -> np.ndarray:
        """1-sigma of a reading at ``ranges`` metres, quantisation included (floored)."""
        gauss = self.gaussian_sigma(ranges)
        return np.maximum(np.sqrt(gauss * gauss + self.resolution_m**2 / 12.0), EXACT_RANGE_SIGMA_M)

    def sigma_scalar(self, range_m: float) -> float:
        gauss = max(self.sigma_0_m + self.sigma_per_m * range_m, self.sigma_min_m)
        return max(math.sqrt(gauss * gauss + self.resolution_m**2 / 12.0), EXACT_RANGE_SIGMA_M)
