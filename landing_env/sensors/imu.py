"""A MEMS IMU: specific force and angular rate in the body frame with noise and bias drift.

The accelerometer measures the specific force ``f_B = R_WB^T (a_W - g_W)`` with
``g_W = (0, 0, -9.81)``, so a drone at rest reads ``+9.81`` on body z.  Each axis carries
white noise of density ``N`` (discrete sigma ``N sqrt(rate_hz)``) and a bias that performs a
random walk of density ``K`` (step sigma ``K sqrt(dt)``).  The default white-noise densities
are an ICM-20602-class part's (about 100 ug/sqrt(Hz) and 0.004 deg/s/sqrt(Hz)); datasheets do
not give bias random walks, so those defaults are values of the order that Allan-variance
fits give for consumer MEMS IMUs of this class.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.types import ImuSample
from landing_env.errors import require_range

#: Gravity in the world frame, m/s^2 (z up).
GRAVITY_W = np.array([0.0, 0.0, -9.81])


@dataclass
class ImuConfig:
    """IMU noise model (continuous-time densities, as datasheets and Kalibr give them)."""

    #: whether the environment creates an IMU at all (the model itself ignores it)
    enabled: bool = True
    #: accelerometer white-noise density, m/s^2/sqrt(Hz) (~100 ug/sqrt(Hz))
    accel_noise_density: float = 1.0e-3
    #: gyroscope white-noise density, rad/s/sqrt(Hz) (~0.004 deg/s/sqrt(Hz))
    gyro_noise_density: float = 7.0e-5
    #: accelerometer bias random-walk density, m/s^3/sqrt(Hz)
    accel_bias_random_walk: float = 4.0e-4
    #: gyroscope bias random-walk density, rad/s^2/sqrt(Hz)
    gyro_bias_random_walk: float = 2.0e-5
    #: standard deviation of the bias drawn at each reset (after a factory calibration)
    accel_bias_sigma: float = 0.05
    gyro_bias_sigma: float = 0.002

    def __post_init__(self) -> None:
        for name in (
            "accel_noise_density",
            "gyro_noise_density",
            "accel_bias_random_walk",
            "gyro_bias_random_walk",
            "accel_bias_sigma",
            "gyro_bias_sigma",
        ):
            require_range(name, getattr(self, name), 0.0)


class ImuModel:
    """Turns true motion into IMU samples at ``rate_hz`` (see the module docstring)."""

    def __init__(self, config: ImuConfig, rng: np.random.Generator, rate_hz: float) -> None:
        if rate_hz <= 0.0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        self.config = config
        self.rng = rng
        self.rate_hz = float(rate_hz)
        self.accel_bias = np.zeros(3)
        self.gyro_bias = np.zeros(3)
        self._last_timestamp: float | None = None
        self.reset()

    def reset(self) -> None:
        """Draw new initial biases and forget the last sample time."""
        cfg = self.config
        self.accel_bias = self.rng.normal(0.0, 1.0, 3) * cfg.accel_bias_sigma
        self.gyro_bias = self.rng.normal(0.0, 1.0, 3) * cfg.gyro_bias_sigma
        self._last_timestamp = None

    @property
    def accel_sigma(self) -> float:
        """Discrete accelerometer white-noise sigma per sample, m/s^2."""
        return self.config.accel_noise_density * np.sqrt(self.rate_hz)

    @property
    def gyro_sigma(self) -> float:
        """Discrete gyroscope white-noise sigma per sample, rad/s."""
        return self.config.gyro_noise_density * np.sqrt(self.rate_hz)

    def _advance_bias(self, timestamp: float) -> None:
        """Random-walk the biases over the time since the last sample (none at the first)."""
        last = self._last_timestamp
        self._last_timestamp = timestamp
        if last is None:
            return
        dt = timestamp - last
        if dt < 0.0:
            raise ValueError(f"IMU timestamps went backwards: {last} -> {timestamp}")
        root_dt = np.sqrt(dt)
        cfg = self.config
        self.accel_bias = self.accel_bias + (
            self.rng.normal(0.0, 1.0, 3) * cfg.accel_bias_random_walk * root_dt
        )
        self.gyro_bias = self.gyro_bias + (
            self.rng.normal(0.0, 1.0, 3) * cfg.gyro_bias_random_walk * root_dt
        )

    def sample(
        self, timestamp: float, r_wb: np.ndarray, accel_w: np.ndarray, omega_b: np.ndarray
    ) -> ImuSample:
        """One sample from the attitude ``r_wb``, the world acceleration of the IMU point
        (m/s^2) and the body angular rate ``omega_b`` (rad/s, in B)."""
        self._advance_bias(timestamp)
        specific_force = np.asarray(r_wb, dtype=float).T @ (
            np.asarray(accel_w, dtype=float) - GRAVITY_W
        )
        accel = specific_force + self.accel_bias + self.rng.normal(0.0, 1.0, 3) * self.accel_sigma
        gyro = (
            np.asarray(omega_b, dtype=float)
            + self.gyro_bias
            + self.rng.normal(0.0, 1.0, 3) * self.gyro_sigma
        )
        return ImuSample(timestamp=timestamp, accel=accel, gyro=gyro)
