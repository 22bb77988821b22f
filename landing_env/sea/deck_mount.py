"""The helideck mount: a deck body moved kinematically along a ship's motion, no legs.

:class:`ShipDeck` drives the deck body with the Stewart platform's dead-beat velocity servo
(:class:`~landing_env.stewart.platform.StewartPlatform`, whose docstring explains it) but
has no legs, no base plate and no workspace: every commanded pose is applied, metres of heave
included.  It keeps the platform's interface (``motion``, ``reset``, ``advance``,
``last_status``, ``update_leg_visuals``, ``home_pose_w``) so the world drives either mount.
"""

from __future__ import annotations

import numpy as np
from pybullet_utils.bullet_client import BulletClient

from landing_env.stewart.kinematics import StewartGeometry
from landing_env.stewart.motion import MotionSource
from landing_env.stewart.platform import StewartPlatform, _quat_from_euler_zyx


class ShipDeck(StewartPlatform):
    """A deck body carried by a ship: servoed along ``motion`` about ``home_position_w``."""

    def __init__(
        self,
        client: BulletClient,
        home_position_w: np.ndarray,
        deck_body_id: int,
        motion: MotionSource,
    ) -> None:
        geometry = StewartGeometry()
        # the servo measures poses from the home frame; the geometry only places home
        base = np.asarray(home_position_w, dtype=float) - np.array([0.0, 0.0, geometry.home_height])
        super().__init__(client, geometry, base, deck_body_id, motion)

    def _create_base_plate(self) -> int:
        return -1

    def _create_legs(self) -> tuple[list[int], list[int]]:
        return [], []

    def _command(self, t: float) -> bool:
        commanded, (x, y, z, roll, pitch, yaw) = self._motion_pose(t)
        self._record = (float(t), commanded, None, False, ())
        self._status = None
        self._target = self._target_world(x, y, z, _quat_from_euler_zyx(roll, pitch, yaw))
        return False

    def update_leg_visuals(self) -> None:
        """No legs to move."""
