"""The deck-relative guidance that the timing task and the scripted policies fly.

:class:`DeckGuidance` turns the *observation* (the estimated deck pose and the ToF ranges, never
the truth) into velocity set-points: hold centred over the tag at a height, or fly the final
descent to touchdown.  ``DeckLandingTiming-v0`` holds and descends with it, and the
``align-descend`` policy of ``DeckLanding-v0`` flies its approach and descent with the same
gains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.frames import camera_to_heading_xy
from landing_env.errors import ConfigError, require_range
from landing_env.physics.controller import VelocitySetpoint


@dataclass
class GuidanceGains:
    """Gains and limits of the deck-relative guidance (hold, approach and final descent)."""

    #: horizontal velocity per metre of horizontal error, 1/s
    k_xy: float = 0.8
    max_horizontal_speed: float = 1.0
    #: yaw rate per radian of tag yaw, 1/s
    k_yaw: float = 0.8
    #: vertical velocity per metre of height error while holding, 1/s
    k_z: float = 1.2
    max_vertical_speed: float = 0.8
    #: final descent: speed = descent_gain * range, between touchdown_speed and descent_speed
    descent_gain: float = 1.5
    descent_speed: float = 0.8
    touchdown_speed: float = 0.25
    #: below this range the tag no longer fits the image: descend on the ToF alone, metres
    blind_range_m: float = 0.3
    #: aligned when the horizontal error is below this plus ``align_tolerance_per_m`` * range
    align_tolerance_m: float = 0.08
    align_tolerance_per_m: float = 0.08

    def __post_init__(self) -> None:
        for name in (
            "k_xy",
            "max_horizontal_speed",
            "k_z",
            "max_vertical_speed",
            "descent_gain",
            "descent_speed",
            "touchdown_speed",
        ):
            require_range(name, getattr(self, name), 0.0, low_inclusive=False)
        for name in ("k_yaw", "blind_range_m", "align_tolerance_m", "align_tolerance_per_m"):
            require_range(name, getattr(self, name), 0.0)
        if self.touchdown_speed > self.descent_speed:
            raise ConfigError(
                "touchdown_speed",
                f"{self.touchdown_speed} must not exceed descent_speed = {self.descent_speed}",
            )


class DeckGuidance:
    """Velocity set-points from the *observation* (estimated deck pose and ToF), never the truth.

    The deck pose is the tag in the camera frame (x right, y down the image, z along the
    optical axis, image top = nose); :func:`~estimation.frames.camera_to_heading_xy` maps its
    offset to the heading frame.  Set-points are in the heading frame (x forward, y left,
    z up), m/s, rad/s.
    """

    def __init__(self, gains: GuidanceGains | None = None) -> None:
        self.gains = gains or GuidanceGains()
        self._last_range = math.inf

    def reset(self) -> None:
        self._last_range = math.inf

    def range_m(self, observation: dict[str, np.ndarray]) -> float:
        """Camera height above the deck: the mean of the valid ToF ranges, else the tag's z.

        The four sensors sit symmetrically about the camera, so on a tilted plane their mean
        is the range at the centre.  NaN when neither is available.
        """
        valid = observation["tof_valid"].astype(bool)
        if valid.all():
            return float(np.mean(observation["tof_range"]))
        if observation["deck_pose_valid"][0]:
            return float(observation["deck_pose"][2])
        if valid.any():
            return float(np.mean(observation["tof_range"][valid]))
        return math.nan

    def horizontal_error(self, observation: dict[str, np.ndarray]) -> tuple[float, float] | None:
        """(forward, left) offset of the tag centre from the camera, metres; None if unseen."""
        if not observation["deck_pose_valid"][0]:
            return None
        forward, left = camera_to_heading_xy(observation["deck_pose"][:2])
        return float(forward), float(left)

    def aligned(self, observation: dict[str, np.ndarray]) -> bool:
        """The tag is seen and the drone is centred over it within the tolerance."""
        error = self.horizontal_error(observation)
        if error is None:
            return False
        height = self.range_m(observation)
        g = self.gains
        tolerance = g.align_tolerance_m + g.align_tolerance_per_m * max(height, 0.0)
        return math.hypot(*error) < tolerance

    def _centre(self, observation: dict[str, np.ndarray]) -> tuple[float, float, float]:
        """Horizontal velocity and yaw rate that centre the drone over the tag."""
        error = self.horizontal_error(observation)
        if error is None:
            return 0.0, 0.0, 0.0
        g = self.gains
        vx, vy = g.k_xy * error[0], g.k_xy * error[1]
        speed = math.hypot(vx, vy)
        if speed > g.max_horizontal_speed:
            vx, vy = vx * g.max_horizontal_speed / speed, vy * g.max_horizontal_speed / speed
        yaw_rate = -g.k_yaw * float(observation["deck_pose"][5])
        return vx, vy, yaw_rate

    def hold(self, observation: dict[str, np.ndarray], target_range_m: float) -> VelocitySetpoint:
        """Centre over the tag and hold the camera ``target_range_m`` above the deck.

        With nothing seen the drone holds its height (zero vertical set-point).
        """
        g = self.gains
        vx, vy, yaw_rate = self._centre(observation)
        height = self.range_m(observation)
        vz = 0.0
        if math.isfinite(height):
            self._last_range = height
            vz = float(
                np.clip(
                    g.k_z * (target_range_m - height), -g.max_vertical_speed, g.max_vertical_speed
                )
            )
        return VelocitySetpoint(np.array([vx, vy, vz]), yaw_rate)

    def descend(self, observation: dict[str, np.ndarray]) -> VelocitySetpoint:
        """The final descent: centre while the tag is seen, slow to ``touchdown_speed`` near the
        deck, and keep going down on the last range when everything is lost close to it."""
        g = self.gains
        height = self.range_m(observation)
        if math.isfinite(height):
            self._last_range = height
        else:
            height = self._last_range
        vx = vy = yaw_rate = 0.0
        if height > g.blind_range_m:
            vx, vy, yaw_rate = self._centre(observation)
        if math.isfinite(height):
            speed = float(np.clip(g.descent_gain * height, g.touchdown_speed, g.descent_speed))
        else:
            speed = g.touchdown_speed
        return VelocitySetpoint(np.array([vx, vy, -speed]), yaw_rate)
