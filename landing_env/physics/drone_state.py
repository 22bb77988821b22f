"""The drone's rigid-body state at one instant, as plain floats and as numpy arrays.

:class:`DroneState` is what :meth:`~landing_env.physics.quadrotor.Quadrotor.read_state`
returns and what the controller and the IMU read; :class:`StateFloats` is its plain-float
form for the code that runs every physics step.  Frames follow :mod:`estimation.frames`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np


class StateFloats(NamedTuple):
    """A :class:`DroneState` as plain Python floats, for the per-physics-step code.

    Tiny numpy arrays cost far more to make and to index than tuples, and the controller,
    the motors and the IMU run 240 times per simulated second.
    """

    #: body-frame origin in W (m)
    position_w: tuple[float, ...]
    #: orientation of B in W as a quaternion (x, y, z, w)
    quaternion_xyzw: tuple[float, ...]
    #: R_WB row-major: (r00, r01, r02, r10, ..., r22)
    rotation_wb: tuple[float, ...]
    #: CoM velocity in W (m/s)
    velocity_w: tuple[float, ...]
    #: angular velocity in the BODY frame (rad/s)
    angular_velocity_b: tuple[float, ...]


class DroneState:
    """The drone's rigid-body state at one instant (read-only).

    The state is held as plain floats (:attr:`floats`); the numpy arrays below are built from
    them on first access and then kept, because most physics steps never look at them.
    """

    __slots__ = ("_arrays", "_euler", "floats")

    floats: StateFloats

    def __init__(
        self,
        position_w: np.ndarray,
        quaternion_xyzw: np.ndarray,
        rotation_wb: np.ndarray,
        velocity_w: np.ndarray,
        angular_velocity_b: np.ndarray,
        euler: np.ndarray | None = None,
    ) -> None:
        """A state from arrays (``euler`` defaults to the ZYX angles of ``rotation_wb``)."""
        self.floats = StateFloats(
            _float_tuple(position_w, 3),
            _float_tuple(quaternion_xyzw, 4),
            _float_tuple(rotation_wb, 9),
            _float_tuple(velocity_w, 3),
            _float_tuple(angular_velocity_b, 3),
        )
        self._euler: tuple[float, ...] | None = None if euler is None else _float_tuple(euler, 3)
        self._arrays: dict[str, np.ndarray] | None = None

    @classmethod
    def from_floats(cls, values: StateFloats) -> DroneState:
        """Wrap plain floats without copying (what
        :meth:`~landing_env.physics.quadrotor.Quadrotor.read_state` uses)."""
        state = cls.__new__(cls)
        state.floats = values
        state._euler = None
        state._arrays = None
        return state

    def _array(self, name: str) -> np.ndarray:
        arrays = self._arrays
        if arrays is None:
            arrays = self._arrays = {}
        array = arrays.get(name)
        if array is None:
            if name == "rotation_wb":
                array = np.array(self.floats.rotation_wb).reshape(3, 3)
            elif name == "euler":
                array = np.array(self.euler_tuple)
            else:
                array = np.array(getattr(self.floats, name))
            arrays[name] = array
        return array

    @property
    def position_w(self) -> np.ndarray:
        """Body-frame origin in W (m): the base link's CoM, 0.7 mm above the vehicle's CoM."""
        return self._array("position_w")

    @property
    def quaternion_xyzw(self) -> np.ndarray:
        """Orientation of B in W as a quaternion (x, y, z, w)."""
        return self._array("quaternion_xyzw")

    @property
    def rotation_wb(self) -> np.ndarray:
        """R_WB (3, 3): columns are the body axes in W."""
        return self._array("rotation_wb")

    @property
    def velocity_w(self) -> np.ndarray:
        """CoM velocity in W (m/s)."""
        return self._array("velocity_w")

    @property
    def angular_velocity_b(self) -> np.ndarray:
        """Angular velocity in the BODY frame (rad/s), as a gyro measures it."""
        return self._array("angular_velocity_b")

    @property
    def euler(self) -> np.ndarray:
        """(roll, pitch, yaw) in radians, ZYX convention."""
        return self._array("euler")

    @property
    def euler_tuple(self) -> tuple[float, ...]:
        """:attr:`euler` as plain floats."""
        if self._euler is None:
            r00, _, _, r10, _, _, r20, r21, r22 = self.floats.rotation_wb
            self._euler = (
                math.atan2(r21, r22),
                math.asin(-r20 if -1.0 <= -r20 <= 1.0 else math.copysign(1.0, -r20)),
                math.atan2(r10, r00),
            )
        return self._euler

    @property
    def yaw(self) -> float:
        """Yaw (rad)."""
        if self._euler is not None:
            return self._euler[2]
        rotation = self.floats.rotation_wb
        return math.atan2(rotation[3], rotation[0])

    def __repr__(self) -> str:
        f = self.floats
        return (
            f"DroneState(position_w={f.position_w}, quaternion_xyzw={f.quaternion_xyzw}, "
            f"velocity_w={f.velocity_w}, angular_velocity_b={f.angular_velocity_b})"
        )


def _float_tuple(value: Any, size: int) -> tuple[float, ...]:
    """``value`` (array-like of ``size`` numbers, any shape) as a tuple of floats."""
    return tuple(np.asarray(value, dtype=float).reshape(size).tolist())


def rotation_from_quaternion(q: Any) -> tuple[float, ...]:
    """Row-major R_WB (9 floats) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    xx = x * x
    yy = y * y
    zz = z * z
    xy = x * y
    xz = x * z
    yz = y * z
    wx = w * x
    wy = w * y
    wz = w * z
    return (
        1.0 - 2.0 * (yy + zz),
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        1.0 - 2.0 * (xx + zz),
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        1.0 - 2.0 * (xx + yy),
    )
