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

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from estimation.limits import NON_NEGATIVE, Limit, Limited, limited
from estimation.noise import IMU_NOISE_DENSITY
from estimation.types import ImuSample
from landing_env.physics.quadrotor_params import GRAVITY

#: Gravity's magnitude (m/s^2) and the gravity vector in the world frame (z up).
GRAVITY_W = np.array([0.0, 0.0, -GRAVITY])


@dataclass
class ImuConfig(Limited):
    """IMU noise model (continuous-time densities, as datasheets and Kalibr give them)."""

    #: whether the environment creates an IMU at all (the model itself ignores it)
    enabled: bool = True
    #: accelerometer white-noise density, m/s^2/sqrt(Hz) (~100 ug/sqrt(Hz))
    accel_noise_density: float = limited(1.0e-3, NON_NEGATIVE, physical=IMU_NOISE_DENSITY)
    #: gyroscope white-noise density, rad/s/sqrt(Hz) (~0.004 deg/s/sqrt(Hz))
    gyro_noise_density: float = limited(7.0e-5, NON_NEGATIVE, physical=IMU_NOISE_DENSITY)
    #: accelerometer bias random-walk density, m/s^3/sqrt(Hz)
    accel_bias_random_walk: float = limited(4.0e-4, NON_NEGATIVE, physical=IMU_NOISE_DENSITY)
    #: gyroscope bias random-walk density, rad/s^2/sqrt(Hz)
    gyro_bias_random_walk: float = limited(2.0e-5, NON_NEGATIVE, physical=IMU_NOISE_DENSITY)
    #: standard deviation of the bias drawn at each reset (after a factory calibration)
    accel_bias_sigma: float = limited(0.05, NON_NEGATIVE, physical=Limit.non_negative(100.0))
    gyro_bias_sigma: float = limited(0.002, NON_NEGATIVE, physical=Limit.non_negative(100.0))


class ImuModel:
    """Turns true motion into IMU samples at ``rate_hz`` (see the module docstring).

    Random numbers: each sample draws 12 standard normals from ``rng`` in one call, in the
    order accelerometer bias step, gyro bias step, accelerometer noise, gyro noise (3 each; the
    first sample after :meth:`reset` has no bias step and draws 6), and :meth:`sample_many`
    draws a whole batch in one call: the same stream, value for value, as drawing each group
    of 3 separately.  The per-sample arithmetic is plain Python floats: this runs at the
    physics rate.
    """

    def __init__(self, config: ImuConfig, rng: np.random.Generator, rate_hz: float) -> None:
        if rate_hz <= 0.0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        self.config = config
        self.rng = rng
        self.rate_hz = float(rate_hz)
        self._accel_bias = [0.0, 0.0, 0.0]
        self._gyro_bias = [0.0, 0.0, 0.0]
        self._last_timestamp: float | None = None
        self.reset()

    def reset(self) -> None:
        """Draw new initial biases and forget the last sample time."""
        cfg = self.config
        self.accel_bias = self.rng.normal(0.0, 1.0, 3) * cfg.accel_bias_sigma
        self.gyro_bias = self.rng.normal(0.0, 1.0, 3) * cfg.gyro_bias_sigma
        self._last_timestamp = None

    @property
    def accel_bias(self) -> np.ndarray:
        """Current accelerometer bias (3,), m/s^2 (a copy)."""
        return np.array(self._accel_bias)

    @accel_bias.setter
    def accel_bias(self, value: np.ndarray) -> None:
        self._accel_bias = np.asarray(value, dtype=float).reshape(3).tolist()

    @property
    def gyro_bias(self) -> np.ndarray:
        """Current gyroscope bias (3,), rad/s (a copy)."""
        return np.array(self._gyro_bias)

    @gyro_bias.setter
    def gyro_bias(self, value: np.ndarray) -> None:
        self._gyro_bias = np.asarray(value, dtype=float).reshape(3).tolist()

    @property
    def accel_sigma(self) -> float:
        """Discrete accelerometer white-noise sigma per sample, m/s^2."""
        return self.config.accel_noise_density * math.sqrt(self.rate_hz)

    @property
    def gyro_sigma(self) -> float:
        """Discrete gyroscope white-noise sigma per sample, rad/s."""
        return self.config.gyro_noise_density * math.sqrt(self.rate_hz)

    def sample(
        self,
        timestamp: float,
        r_wb: np.ndarray | Sequence[float],
        accel_w: np.ndarray | Sequence[float],
        omega_b: np.ndarray | Sequence[float],
    ) -> ImuSample:
        """One sample from the attitude ``r_wb``, the world acceleration of the IMU point
        (m/s^2) and the body angular rate ``omega_b`` (rad/s, in B).

        ``r_wb`` is R_WB as a (3, 3) array or as 9 row-major floats; the vectors are arrays or
        sequences of 3 floats.
        """
        return self.sample_many((timestamp,), (r_wb,), (accel_w,), (omega_b,))[0]

    def sample_many(
        self,
        timestamps: Sequence[float],
        rotations_wb: Sequence[np.ndarray | Sequence[float]],
        accels_w: Sequence[np.ndarray | Sequence[float]],
        omegas_b: Sequence[np.ndarray | Sequence[float]],
    ) -> list[ImuSample]:
        """Consecutive samples, as many :meth:`sample` calls, with one random draw for all.

        The arguments are parallel sequences, one item per sample, in :meth:`sample`'s form.
        """
        count = len(timestamps)
        if not (len(rotations_wb) == len(accels_w) == len(omegas_b) == count):
            raise ValueError("timestamps, rotations_wb, accels_w and omegas_b differ in length")
        if count == 0:
            return []
        # Check every timestamp before drawing, so that an error leaves the model unchanged.
        last = self._last_timestamp
        previous = last
        for timestamp in timestamps:
            if previous is not None and timestamp - previous < 0.0:
                raise ValueError(f"IMU timestamps went backwards: {previous} -> {timestamp}")
            previous = timestamp
        normals = self.rng.standard_normal(12 * count - (6 if last is None else 0)).tolist()
        cfg = self.config
        root_rate = math.sqrt(self.rate_hz)
        accel_sigma = cfg.accel_noise_density * root_rate
        gyro_sigma = cfg.gyro_noise_density * root_rate
        accel_walk = cfg.accel_bias_random_walk
        gyro_walk = cfg.gyro_bias_random_walk
        ba0, ba1, ba2 = self._accel_bias
        bg0, bg1, bg2 = self._gyro_bias
        samples = []
        k = 0
        for timestamp, r_wb, accel_w, omega_b in zip(
            timestamps, rotations_wb, accels_w, omegas_b, strict=True
        ):
            if last is not None:
                # Random-walk the biases over the time since the last sample.
                root_dt = math.sqrt(timestamp - last)
                n0, n1, n2, n3, n4, n5 = normals[k : k + 6]
                k += 6
                ba0 += n0 * accel_walk * root_dt
                ba1 += n1 * accel_walk * root_dt
                ba2 += n2 * accel_walk * root_dt
                bg0 += n3 * gyro_walk * root_dt
                bg1 += n4 * gyro_walk * root_dt
                bg2 += n5 * gyro_walk * root_dt
            last = timestamp
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
                r_wb.ravel().tolist() if isinstance(r_wb, np.ndarray) else r_wb
            )
            ax, ay, az = accel_w.tolist() if isinstance(accel_w, np.ndarray) else accel_w
            wx, wy, wz = omega_b.tolist() if isinstance(omega_b, np.ndarray) else omega_b
            # specific force f_B = R_WB^T (a_W - g_W), g_W = (0, 0, -GRAVITY)
            az += GRAVITY
            n0, n1, n2, n3, n4, n5 = normals[k : k + 6]
            k += 6
            accel = (
                r00 * ax + r10 * ay + r20 * az + ba0 + n0 * accel_sigma,
                r01 * ax + r11 * ay + r21 * az + ba1 + n1 * accel_sigma,
                r02 * ax + r12 * ay + r22 * az + ba2 + n2 * accel_sigma,
            )
            gyro = (
                wx + bg0 + n3 * gyro_sigma,
                wy + bg1 + n4 * gyro_sigma,
                wz + bg2 + n5 * gyro_sigma,
            )
            samples.append(ImuSample(timestamp, np.array(accel), np.array(gyro)))
        self._accel_bias = [ba0, ba1, ba2]
        self._gyro_bias = [bg0, bg1, bg2]
        self._last_timestamp = last
        return samples


def mean_reading(samples: Sequence[ImuSample]) -> tuple[float, ...]:
    """The samples' mean specific force and angular rate: (accel x, y, z, gyro x, y, z).

    Bit for bit ``np.mean`` of the stacked float64 readings over the samples: summed from 0
    in the samples' order, then divided by the count (NumPy's reduction over the outer axis
    adds the rows one after another to its identity, so that a sum of -0.0 is 0.0).  Plain
    floats cost a third of stacking the arrays; readings that are not float64 arrays go
    through ``np.mean`` itself.
    """
    for sample in samples:
        accel, gyro = sample.accel, sample.gyro
        if not (
            type(accel) is np.ndarray
            and type(gyro) is np.ndarray
            and accel.dtype == np.float64
            and gyro.dtype == np.float64
            and accel.shape == gyro.shape == (3,)
        ):
            return (
                *np.mean([s.accel for s in samples], axis=0).tolist(),
                *np.mean([s.gyro for s in samples], axis=0).tolist(),
            )
    a0 = a1 = a2 = g0 = g1 = g2 = 0.0
    for sample in samples:
        x, y, z = sample.accel.tolist()
        a0 += x
        a1 += y
        a2 += z
        x, y, z = sample.gyro.tolist()
        g0 += x
        g1 += y
        g2 += z
    count = len(samples)
    return (a0 / count, a1 / count, a2 / count, g0 / count, g1 / count, g2 / count)
