"""Where the deck is and how fast it moves: the deck-frame guidance's Kalman filter.

:class:`DeckTracker` tracks the tag centre in the world frame, one Kalman filter per axis,
from the tag seen by a level camera and, with the tag lost, the ToF ranges, plus the drone's
own navigation estimate (:class:`OwnState`).  The deck-frame guidance
(:class:`~landing_env.timing.guidance.DeckGuidance` with ``GuidanceGains.track_deck``) feeds
its velocity forward.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.frames import (
    camera_to_heading_xy,
    euler_zyx_from_matrix,
    level_from_body,
    levelled_deck_pose,
)
from landing_env.errors import require_choice
from landing_env.guidance_gains import TRACKER_MODELS


@dataclass(frozen=True)
class OwnState:
    """The drone's own navigation estimate, as the autopilot gives it to the guidance (PX4's
    EKF2 local position: position and velocity in a local level frame, attitude); in the
    simulation the true state stands in for it, as for the levelled history."""

    position_w: np.ndarray
    velocity_w: np.ndarray
    rotation_wb: np.ndarray

    @property
    def yaw(self) -> float:
        return float(euler_zyx_from_matrix(self.rotation_wb)[2])


class DeckTracker:
    """Where the deck (the tag centre) is and how fast it moves, in the world frame.

    One constant-velocity Kalman filter per axis (white-noise acceleration of spectral density
    ``accel_psd``; Bar-Shalom, Li & Kirubarajan 2001, *Estimation with Applications to Tracking and
    Navigation*, Sec. 6.2.2), or with ``model = "acceleration"`` a constant-acceleration one
    (white-noise jerk of density ``jerk_psd``, Sec. 6.2.3).  A measurement is the drone's position
    plus the tag offset seen by a level camera (the deck pose rotated by the drone's roll and pitch,
    then by its yaw); with the tag lost, the ToF ranges (their mean along the body axis, times the
    cosine of the drone's tilt) still measure the height.  The vertical position tracked is the
    drone's centre's height minus the camera's range, so that ``range = own z - tracked z``.
    Without measurements a track coasts with its velocity decaying (``velocity_decay_s``): the deck
    of a ship hove-to oscillates about a fixed mean, so the last position is the best guess of where
    to look again; the height track is dropped after ``coast_s`` without a range."""

    def __init__(
        self,
        accel_psd: float,
        position_sigma_m: float,
        coast_s: float,
        velocity_decay_s: float = math.inf,
        model: str = "velocity",
        jerk_psd: float = 2.0,
    ) -> None:
        require_choice("tracker_model", model, TRACKER_MODELS)
        self.accel_psd = accel_psd
        self.jerk_psd = jerk_psd
        self.r = position_sigma_m**2
        self.coast_s = coast_s
        self.velocity_decay_s = velocity_decay_s
        self.model = model
        #: states per axis: position, velocity (and acceleration)
        self.order = 3 if model == "acceleration" else 2
        self.reset()

    def reset(self) -> None:
        #: per axis (x, y, z): state [position, velocity(, acceleration)] and its covariance
        self.state = np.zeros((3, self.order))
        self.cov = np.zeros((3, self.order, self.order))
        self.started = np.zeros(3, dtype=bool)
        self.unseen_s = np.full(3, math.inf)
        #: the deck's height when its track was last measured (None: never measured)
        self.last_height_w: float | None = None

    @property
    def valid(self) -> bool:
        """The height has a track (the horizontal axes may have lost theirs)."""
        return bool(self.started[2])

    @property
    def horizontal_valid(self) -> bool:
        return bool(self.started[:2].all())

    @property
    def position_w(self) -> np.ndarray:
        return self.state[:, 0].copy()

    @property
    def velocity_w(self) -> np.ndarray:
        return self.state[:, 1].copy()

    @property
    def acceleration_w(self) -> np.ndarray:
        """The tracked acceleration (zeros for the constant-velocity model)."""
        return self.state[:, 2].copy() if self.order == 3 else np.zeros(3)

    def update(self, observation: dict[str, np.ndarray], own: OwnState, dt: float) -> None:
        """Predict by ``dt`` and correct with whatever this observation measures."""
        self.update_measured(self.measure(observation, own), dt)

    def update_measured(self, measured: np.ndarray, dt: float) -> None:
        """Predict by ``dt`` and correct with a measured deck position (world; NaN where an
        axis is not measured), as :meth:`update` does with an observation's."""
        self._predict(dt)
        for axis in range(3):
            value = measured[axis]
            if math.isfinite(value):
                self._correct(axis, value)
                self.unseen_s[axis] = 0.0
                if axis == 2:
                    self.last_height_w = float(self.state[2, 0])
            elif axis == 2 and self.unseen_s[axis] > self.coast_s:
                # no range for that long: the height track is dropped (the horizontal ones
                # coast on: a hove-to ship's deck oscillates about a fixed mean position)
                self.started[axis] = False
            else:
                # coasting: let the velocity (and acceleration) decay (an oscillating
                # deck's stale velocity would carry the track away)
                self.state[axis, 1:] *= math.exp(-dt / self.velocity_decay_s)

    @staticmethod
    def measure(observation: dict[str, np.ndarray], own: OwnState) -> np.ndarray:
        """The deck position in the world this observation gives (NaN where it gives none)."""
        measured = np.full(3, math.nan)
        yaw = own.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        if observation["deck_pose_valid"][0]:
            level = levelled_deck_pose(
                observation["deck_pose"].astype(float), level_from_body(own.rotation_wb)
            )
            forward, left = camera_to_heading_xy(level[:2])
            measured[0] = own.position_w[0] + c * forward - s * left
            measured[1] = own.position_w[1] + s * forward + c * left
            measured[2] = own.position_w[2] - float(level[2])
            return measured
        valid = observation["tof_valid"].astype(bool)
        if valid.any():
            cos_tilt = float(np.clip(own.rotation_wb[2, 2], 0.5, 1.0))
            height = float(np.mean(observation["tof_range"][valid])) * cos_tilt
            measured[2] = own.position_w[2] - height
        return measured

    def _predict(self, dt: float) -> None:
        if self.order == 3:
            f = np.array([[1.0, dt, dt**2 / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
            q = self.jerk_psd * np.array(
                [
                    [dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0],
                    [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0],
                    [dt**3 / 6.0, dt**2 / 2.0, dt],
                ]
            )
        else:
            f = np.array([[1.0, dt], [0.0, 1.0]])
            q = self.accel_psd * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        for axis in range(3):
            if self.started[axis]:
                self.state[axis] = f @ self.state[axis]
                self.cov[axis] = f @ self.cov[axis] @ f.T + q
        self.unseen_s += dt

    def _correct(self, axis: int, value: float) -> None:
        if not self.started[axis]:
            self.state[axis] = 0.0
            self.state[axis, 0] = value
            # a deck moving at up to ~2 m/s and accelerating at up to ~1 m/s^2: start with
            # those uncertainties
            self.cov[axis] = np.diag([self.r, 4.0, 1.0][: self.order])
            self.started[axis] = True
            return
        p = self.cov[axis]
        innovation = value - self.state[axis, 0]
        gain = p[:, 0] / (p[0, 0] + self.r)
        self.state[axis] = self.state[axis] + gain * innovation
        self.cov[axis] = p - np.outer(gain, p[0, :])
