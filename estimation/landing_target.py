"""The landing-target filter of a precision-landing autopilot (PX4's ``landing_target_estimator``).

An IR-LOCK-style sensor gives the target's horizontal position relative to the vehicle (the
beacon's bearing and a range, levelled with the vehicle attitude).  The autopilot does not
steer on those raw fixes: a Kalman filter per horizontal axis keeps the target's relative
position and velocity, propagated with the vehicle's own acceleration as the input (a static
target's relative acceleration is minus the vehicle's), and each fix passes an innovation gate
before it is fused.  The SVGS paper (003, Sec. 2.4, Table 1) runs the IR beacon's fixes
through a 10-SD gate; the gate here is in standard deviations, 10 by default.

Per axis, with ``p`` the target's position relative to the vehicle and ``a`` the vehicle's
acceleration (levelled, gravity removed)::

    p' = p + v dt - a dt^2 / 2,    v' = v - a dt

with white acceleration noise of ``accel_sigma`` (m/s^2).  A fix ``z`` of ``p`` has the
1-sigma ``measurement_sigma_m + measurement_sigma_per_m * distance`` (a bearing error grows
with the distance); it is rejected when ``|z - p| > gate_sd * sqrt(S)`` on either axis.

Without an accepted fix for ``timeout_s`` the estimate is invalid and the next fix
re-initialises the filter.  Nothing raises: a non-finite input is ignored and reported.

Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.fusion.config import PAPER_GATE_SD
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited

#: What :meth:`LandingTargetFilter.update` did with a fix.
INITIALISED = "initialised"
ACCEPTED = "accepted"
REJECTED = "rejected"
INVALID_INPUT = "invalid_input"


@dataclass(frozen=True)
class LandingTargetConfig(Limited):
    """Settings of the landing-target filter (PX4's ``LTEST_*`` in the comments)."""

    #: innovation gate, standard deviations (the SVGS paper's 10 for the IR beacon)
    gate_sd: float = limited(PAPER_GATE_SD, Limit(0.0, 1e3, low_inclusive=False))
    #: 1-sigma of the vehicle acceleration input, m/s^2 (LTEST_ACC_UNC = 10 (m/s^2)^2)
    accel_sigma: float = limited(math.sqrt(10.0), POSITIVE)
    #: 1-sigma of a fix: a floor, metres, and its growth per metre of distance
    #: (LTEST_MEAS_UNC = 0.005 m^2 per m^2 of distance: 0.071 m per m)
    measurement_sigma_m: float = limited(0.02, POSITIVE)
    measurement_sigma_per_m: float = limited(math.sqrt(0.005), NON_NEGATIVE)
    #: 1-sigma of the position and velocity at (re)initialisation (LTEST_POS_UNC_IN,
    #: LTEST_VEL_UNC_IN = 0.1 m^2 and 0.1 (m/s)^2)
    initial_position_sigma_m: float = limited(math.sqrt(0.1), POSITIVE)
    initial_velocity_sigma: float = limited(math.sqrt(0.1), POSITIVE)
    #: the estimate is invalid this long after the last accepted fix, seconds
    timeout_s: float = limited(2.0, POSITIVE)


def _finite(*values: np.ndarray | float) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(v, dtype=float)))) for v in values)


class LandingTargetFilter:
    """Two decoupled constant-velocity Kalman filters (x, y) of the target's relative position.

    ``predict(accel_xy, dt)`` each control period; ``update(position_xy, distance_m)`` with
    each fix.  ``position_xy`` / ``velocity_xy``: the estimate (target minus vehicle);
    ``valid``: an accepted fix within ``timeout_s``.  ``last_innovation_sd``: the larger of
    the two axes' normalised innovations of the last fix; ``rejections``: fixes gated out.
    """

    def __init__(self, config: LandingTargetConfig | None = None) -> None:
        self.config = config or LandingTargetConfig()
        self.reset()

    def reset(self) -> None:
        self.state = np.zeros((2, 2))  # rows x, y: (position, velocity)
        self.covariance = np.zeros((2, 2, 2))
        self.initialised = False
        self.since_fix_s = math.inf
        self.rejections = 0
        self.last_innovation_sd = math.nan

    @property
    def valid(self) -> bool:
        return self.initialised and self.since_fix_s <= self.config.timeout_s

    @property
    def position_xy(self) -> np.ndarray:
        return self.state[:, 0].copy()

    @property
    def velocity_xy(self) -> np.ndarray:
        return self.state[:, 1].copy()

    def predict(self, accel_xy: np.ndarray, dt: float) -> bool:
        """Propagate by ``dt`` seconds under the vehicle's acceleration (levelled, m/s^2).

        A non-finite or missing acceleration propagates at constant velocity; False then.
        """
        if not (_finite(dt) and dt >= 0.0):
            return False
        self.since_fix_s += dt
        if not self.initialised:
            return True
        accel = np.asarray(accel_xy, dtype=float).reshape(2)
        usable = _finite(accel)
        if not usable:
            accel = np.zeros(2)
        f = np.array([[1.0, dt], [0.0, 1.0]])
        b = np.array([-0.5 * dt * dt, -dt])
        q = self.config.accel_sigma**2 * np.outer(b, b)
        for axis in range(2):
            self.state[axis] = f @ self.state[axis] + b * accel[axis]
            self.covariance[axis] = f @ self.covariance[axis] @ f.T + q
        if self.since_fix_s > self.config.timeout_s:
            self.initialised = False  # stale: the next fix starts again
        return usable

    def measurement_sigma_m(self, distance_m: float) -> float:
        c = self.config
        return c.measurement_sigma_m + c.measurement_sigma_per_m * max(float(distance_m), 0.0)

    def innovation_sd(self, position_xy: np.ndarray, distance_m: float) -> np.ndarray:
        """Each axis' innovation of a fix in standard deviations of its innovation."""
        z = np.asarray(position_xy, dtype=float).reshape(2)
        r = self.measurement_sigma_m(distance_m) ** 2
        s = self.covariance[:, 0, 0] + r
        return np.abs(z - self.state[:, 0]) / np.sqrt(s)

    def update(self, position_xy: np.ndarray, distance_m: float) -> str:
        """Fuse one fix of the target's relative position (metres) taken ``distance_m`` away.

        Returns :data:`INITIALISED`, :data:`ACCEPTED`, :data:`REJECTED` (the gate) or
        :data:`INVALID_INPUT`.
        """
        z = np.asarray(position_xy, dtype=float).reshape(-1)
        if z.size != 2 or not _finite(z, distance_m):
            return INVALID_INPUT
        c = self.config
        if not self.initialised:
            self.state = np.column_stack([z, np.zeros(2)])
            p0 = np.diag([c.initial_position_sigma_m**2, c.initial_velocity_sigma**2])
            self.covariance = np.stack([p0, p0])
            self.initialised = True
            self.since_fix_s = 0.0
            self.last_innovation_sd = 0.0
            return INITIALISED
        ratio = self.innovation_sd(z, distance_m)
        self.last_innovation_sd = float(ratio.max())
        if self.last_innovation_sd > c.gate_sd:
            self.rejections += 1
            return REJECTED
        r = self.measurement_sigma_m(distance_m) ** 2
        h = np.array([1.0, 0.0])
        for axis in range(2):
            p = self.covariance[axis]
            s = float(h @ p @ h) + r
            gain = p @ h / s
            self.state[axis] = self.state[axis] + gain * (z[axis] - self.state[axis, 0])
            joseph = np.eye(2) - np.outer(gain, h)
            self.covariance[axis] = joseph @ p @ joseph.T + r * np.outer(gain, gain)
        self.since_fix_s = 0.0
        return ACCEPTED
