"""Scripted policies that read only the observation (never the ground truth)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from landing_env.config import ActionConfig


@dataclass
class DescendGains:
    """Gains and limits of the descend-onto-the-deck policy."""

    #: horizontal velocity per metre of horizontal error, 1/s
    k_xy: float = 0.8
    #: yaw rate per radian of tag yaw, 1/s
    k_yaw: float = 0.8
    #: horizontal error (m) under which the drone descends, plus this fraction of the height
    align_tolerance_m: float = 0.08
    align_tolerance_per_m: float = 0.08
    #: descent speed per metre of height, 1/s, bounded below and above (m/s)
    k_descent: float = 0.45
    min_descent_speed: float = 0.15
    max_descent_speed: float = 0.7
    #: below this camera-to-deck range the tag no longer fits in the image: descend on ToF
    blind_range_m: float = 0.45
    #: steady final descent speed on ToF alone, m/s
    final_descent_speed: float = 0.25
    #: climb speed when the tag is lost above the blind range, m/s
    search_climb_speed: float = 0.3


class DescendPolicy:
    """Centre over the tag, descend while aligned, finish on the ToF ranges.

    The deck pose in the observation is the tag in the camera frame (x right, y down,
    z down the optical axis); the action is a velocity set-point in the heading frame
    (x forward, y left, z up), normalised by :class:`ActionConfig`.
    """

    def __init__(self, action: ActionConfig | None = None, gains: DescendGains | None = None):
        self.action = action or ActionConfig()
        self.gains = gains or DescendGains()
        self._last_range = np.inf

    def reset(self) -> None:
        self._last_range = np.inf

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return self.act(observation)

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        g = self.gains
        pose_valid = bool(observation["deck_pose_valid"][0])
        tof_valid = observation["tof_valid"].astype(bool)
        tof = observation["tof_range"]
        tof_range = float(np.mean(tof[tof_valid])) if tof_valid.any() else np.nan

        vx = vy = vz = yaw_rate = 0.0
        if pose_valid:
            x_c, y_c, z_c, _, _, yaw_c = (float(v) for v in observation["deck_pose"])
            height = tof_range if np.isfinite(tof_range) else z_c
            self._last_range = height
            # camera x right = body -y, camera y down the image = body -x (image top = nose)
            err_forward, err_left = -y_c, -x_c
            vx, vy = g.k_xy * err_forward, g.k_xy * err_left
            yaw_rate = -g.k_yaw * yaw_c
            aligned = np.hypot(err_forward, err_left) < (
                g.align_tolerance_m + g.align_tolerance_per_m * height
            )
            if aligned:
                vz = -float(np.clip(g.k_descent * height, g.min_descent_speed, g.max_descent_speed))
        elif np.isfinite(tof_range) and tof_range < g.blind_range_m:
            # too close for the tag to fit in the image: keep going down on the ToF ranges
            vz = -g.final_descent_speed
            self._last_range = tof_range
        elif self._last_range < g.blind_range_m:
            vz = -g.final_descent_speed
        else:
            vz = g.search_climb_speed
        return self._normalise(vx, vy, vz, yaw_rate)

    def _normalise(self, vx: float, vy: float, vz: float, yaw_rate: float) -> np.ndarray:
        a = self.action
        horizontal = np.array([vx, vy])
        speed = float(np.linalg.norm(horizontal))
        if speed > a.max_horizontal_speed:
            horizontal *= a.max_horizontal_speed / speed
        command = np.array(
            [
                horizontal[0] / a.max_horizontal_speed,
                horizontal[1] / a.max_horizontal_speed,
                vz / a.max_vertical_speed,
                yaw_rate / np.deg2rad(a.max_yaw_rate_deg),
            ]
        )
        return np.clip(command, -1.0, 1.0).astype(np.float32)
