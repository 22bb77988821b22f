"""The Stewart platform in a PyBullet world: base plate, leg visuals and the driven top plate.

How the top plate is driven (why this way): the top plate is an ordinary *dynamic* body
(created elsewhere, base frame = deck frame P) so that contacts with the drone are real
rigid-body contacts.  Before every physics step :meth:`StewartPlatform.step_to` sets the
plate's velocity so that one integration step carries it from where it *is* exactly to the
commanded pose (a dead-beat velocity servo): the linear velocity is the required
displacement over the step, with gravity's velocity increment of the coming step taken off
in advance; the angular velocity is the rotation vector of the required rotation over the
step.  The contact solver therefore sees the true plate velocity, a body resting on the
plate is carried and pushed by it, and whatever a contact does to the plate within a step
(a 1 kg box shifts a 10 kg plate by ~0.02 mm per 240 Hz step) is undone at the next step
instead of accumulating, so the plate is not pushed off its path.  The plate's damping is
set to zero and sleeping disabled, since both would defeat the servo.

Measured at 240 Hz on the default sinusoids: unloaded, the plate tracks to ~1e-16 m and
~1e-7 rad (the rest is Bullet's gyroscopic term); with a 1 kg box on a 10 kg plate, to
< 0.1 mm and < 0.01 deg.  A world fixed constraint updated with ``changeConstraint``
(maxForce 1e5) lagged by up to 0.87 mm and 0.096 deg, whatever its erp, so it was dropped;
resetting the pose every step was not used because it teleports the plate through whatever
rests on it.

Legs are visual-only bodies (no collision shape, so rays, the drone and the deck never hit
them): each is a cylinder fixed at the base joint and a rod fixed at the top joint, sliding
inside each other like a real actuator.  They are only moved by
:meth:`StewartPlatform.update_leg_visuals`, at the environment rate.

Cost per physics step (it runs 240 times per simulated second): :meth:`StewartPlatform.advance`
is :meth:`~StewartPlatform.step_to` without building the :class:`StewartStatus` (built when
``last_status`` is read); a cheap sufficient reachability test
(:meth:`StewartKinematics.surely_reachable`) leaves the exact leg check and clamping to poses
near the workspace boundary; the motion source is evaluated several steps ahead in one call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from estimation.frames import euler_zyx_from_matrix
from estimation.limits import NON_NEGATIVE, POSITIVE, limited, require_limits
from landing_env.errors import require_range
from landing_env.stewart.kinematics import (
    StewartGeometry,
    StewartKinematics,
    angular_velocity_from_euler_rates,
    rotation_matrix_zyx,
)
from landing_env.stewart.motion import BatchMotionSource, MotionSource

Quaternion = tuple[float, float, float, float]


@dataclass(frozen=True)
class PlatformConfig:
    """Appearance of the base and legs; none of it affects the plate's motion."""

    #: thickness of the static base plate below the base-joint plane (m)
    base_plate_thickness: float = limited(0.04, POSITIVE)
    #: how far the square base plate extends beyond the base-joint circle (m)
    base_plate_margin: float = limited(0.08, NON_NEGATIVE)
    #: radius of the actuator cylinders (m) and of the piston rods (m)
    cylinder_radius: float = limited(0.03, POSITIVE)
    rod_radius: float = 0.016
    base_plate_rgba: tuple[float, float, float, float] = (0.25, 0.25, 0.28, 1.0)
    cylinder_rgba: tuple[float, float, float, float] = (0.15, 0.15, 0.15, 1.0)
    rod_rgba: tuple[float, float, float, float] = (0.75, 0.75, 0.78, 1.0)

    def __post_init__(self) -> None:
        require_limits(self)
        require_range(
            "rod_radius",
            self.rod_radius,
            0.0,
            self.cylinder_radius,
            low_inclusive=False,
            bounds_from=f"cylinder_radius = {self.cylinder_radius}",
        )


@dataclass(frozen=True)
class StewartStatus:
    """What :meth:`StewartPlatform.step_to` commanded for one physics step.

    The leg lengths and stroke usage are computed from the applied pose when first asked
    for: most physics steps never look at them.
    """

    #: simulation time the pose is commanded for (end of the coming physics step), s
    t: float
    #: pose asked for by the motion source (6,): m, rad, relative to home
    commanded_pose: np.ndarray
    #: pose actually commanded after workspace clamping (6,)
    applied_pose: np.ndarray
    #: True when the workspace clamp modified the command
    clamped: bool
    #: legs whose limits the commanded pose violated (empty unless clamped)
    violated_legs: tuple[int, ...]
    #: the platform's kinematics (computes the leg lengths)
    kinematics: StewartKinematics = field(repr=False, compare=False)

    @cached_property
    def leg_lengths(self) -> np.ndarray:
        """Leg lengths of the applied pose (6,), m."""
        return self.kinematics.inverse_kinematics(self.applied_pose)

    @cached_property
    def stroke_usage(self) -> np.ndarray:
        """Fraction of the stroke in use per leg (6,): 0 fully retracted, 1 fully extended."""
        return self.kinematics.stroke_usage(self.leg_lengths)

    @property
    def max_stroke_usage(self) -> float:
        """Worst leg's distance from mid-stroke as a fraction of half the stroke (0..1)."""
        return float(np.max(np.abs(2.0 * self.stroke_usage - 1.0)))


class StewartPlatform:
    """Drives a dynamic top-plate body along a motion source, with a base plate and legs.

    ``base_position_w`` is the base frame's origin in the world: the centre of the base-joint
    plane, which is the top face of the base plate (so a base plate standing on the ground
    at z = 0 needs ``base_position_w[2] = config.base_plate_thickness``).  The base frame is
    yawed by ``base_yaw`` (rad) about world z.  The top-plate body's base frame must be P (the
    centre of the deck's top surface, z up).  Create it without ``baseInertialFramePosition``:
    PyBullet's ``createMultiBody`` attaches collision shapes relative to the inertial frame,
    so an offset would move the surface away from the base frame.  (Measured: even then the
    velocity given to ``resetBaseVelocity`` moves the *reported* base position exactly, so
    the servo needs no centre-of-mass correction, for multibodies and maximal bodies alike.)
    """

    #: physics steps of motion evaluated ahead in one call (see _motion_pose)
    _PLAN_STEPS = 24

    def __init__(
        self,
        client: BulletClient,
        geometry: StewartGeometry,
        base_position_w: np.ndarray,
        top_plate_body_id: int,
        motion: MotionSource,
        base_yaw: float = 0.0,
        *,
        config: PlatformConfig | None = None,
    ) -> None:
        self.client = client
        # The per-step path calls pybullet with the client id directly (BulletClient's
        # attribute lookup costs about a microsecond per call).
        self._cid: int = client._client
        self.geometry = geometry
        self.kinematics = StewartKinematics(geometry)
        self.motion = motion
        self.config = config or PlatformConfig()
        self.top_plate_body_id = top_plate_body_id
        self.base_position_w = np.asarray(base_position_w, dtype=float).reshape(3).copy()
        self.base_yaw = float(base_yaw)
        self._cos_yaw, self._sin_yaw = math.cos(base_yaw), math.sin(base_yaw)
        self._half_yaw_q: Quaternion = (0.0, 0.0, math.sin(base_yaw / 2), math.cos(base_yaw / 2))
        self.rotation_wb = rotation_matrix_zyx(0.0, 0.0, self.base_yaw)
        self._home_position_w = self.base_position_w + self.rotation_wb @ np.array(
            [0.0, 0.0, geometry.home_height]
        )
        hx, hy, hz = self._home_position_w.tolist()
        self._home_floats = (hx, hy, hz)
        self.base_anchors_w = (
            self.base_position_w + self.kinematics.base_anchors @ self.rotation_wb.T
        )
        # A servoed body must neither lose velocity to damping nor fall asleep.
        client.changeDynamics(
            top_plate_body_id,
            -1,
            linearDamping=0.0,
            angularDamping=0.0,
            activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
        )
        self.base_body_id = self._create_base_plate()
        self.cylinder_body_ids, self.rod_body_ids = self._create_legs()
        self._dt = 0.0
        self._gravity_step = (0.0, 0.0, 0.0)
        self._read_engine_parameters()
        #: world position and quaternion of P for the last commanded pose
        self._target: tuple[tuple[float, float, float], Quaternion] = ((0.0, 0.0, 0.0), _IDENTITY)
        # The last command, from which last_status is built when asked for:
        # (t, commanded pose, applied pose or None when it is the commanded one, clamped,
        # violated legs), and the status once built.
        self._record: tuple[float, np.ndarray, np.ndarray | None, bool, tuple[int, ...]] | None
        self._record = None
        self._status: StewartStatus | None = None
        # Motion commands evaluated ahead (see _motion_pose): time -> (pose, pose as floats)
        self._plan: dict[float, tuple[np.ndarray, list[float]]] = {}
        self._plan_motion: MotionSource | None = None
        self._last_t: float | None = None
        self._batch_check: tuple[MotionSource | None, bool] = (None, False)

    # ---------------------------------------------------------------- creation
    def _create_base_plate(self) -> int:
        c, cfg = self.client, self.config
        half = self.geometry.base_radius + cfg.base_plate_margin
        half_extents = [half, half, 0.5 * cfg.base_plate_thickness]
        offset = [0.0, 0.0, -0.5 * cfg.base_plate_thickness]
        collision = c.createCollisionShape(
            pybullet.GEOM_BOX, halfExtents=half_extents, collisionFramePosition=offset
        )
        visual = c.createVisualShape(
            pybullet.GEOM_BOX,
            halfExtents=half_extents,
            visualFramePosition=offset,
            rgbaColor=list(cfg.base_plate_rgba),
        )
        return c.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=self.base_position_w.tolist(),
            baseOrientation=list(self._half_yaw_q),
        )

    def _create_legs(self) -> tuple[list[int], list[int]]:
        c, cfg, geometry = self.client, self.config, self.geometry
        # The cylinder and the rod must together span the longest leg without either
        # sticking out past the far joint at the shortest leg.
        self._cylinder_length = min(geometry.min_leg_length, 0.55 * geometry.max_leg_length)
        self._rod_length = min(
            geometry.min_leg_length, geometry.max_leg_length - self._cylinder_length + 0.02
        )
        cylinder_shape = c.createVisualShape(
            pybullet.GEOM_CYLINDER,
            radius=cfg.cylinder_radius,
            length=self._cylinder_length,
            rgbaColor=list(cfg.cylinder_rgba),
        )
        rod_shape = c.createVisualShape(
            pybullet.GEOM_CYLINDER,
            radius=cfg.rod_radius,
            length=self._rod_length,
            rgbaColor=list(cfg.rod_rgba),
        )
        # No collision shape: invisible to rayTest and to contacts.
        cylinders = [
            c.createMultiBody(baseMass=0.0, baseVisualShapeIndex=cylinder_shape) for _ in range(6)
        ]
        rods = [c.createMultiBody(baseMass=0.0, baseVisualShapeIndex=rod_shape) for _ in range(6)]
        return cylinders, rods

    def _read_engine_parameters(self) -> None:
        params = self.client.getPhysicsEngineParameters()
        substeps = max(1, int(params["numSubSteps"]))
        self._dt = float(params["fixedTimeStep"])
        sub_dt = self._dt / substeps
        # Semi-implicit Euler over n substeps moves a body by v dt + g sub_dt^2 n (n+1) / 2;
        # subtracting g sub_dt (n+1)/2 from v cancels it (exact for n = 1, where the contact
        # solver then also sees exactly the commanded velocity).
        factor = sub_dt * (substeps + 1) / 2.0
        self._gravity_step = (
            params["gravityAccelerationX"] * factor,
            params["gravityAccelerationY"] * factor,
            params["gravityAccelerationZ"] * factor,
        )

    # ---------------------------------------------------------------- frames
    def home_pose_w(self) -> tuple[np.ndarray, np.ndarray]:
        """(position_w, rotation_wp) of the top plate at the home pose."""
        return self._home_position_w.copy(), self.rotation_wb.copy()

    def pose_to_world(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(position_w, rotation_wp) of P for a pose relative to home."""
        pose = np.asarray(pose, dtype=float)
        rotation = self.rotation_wb @ rotation_matrix_zyx(*pose[3:].tolist())
        return self._home_position_w + self.rotation_wb @ pose[:3], rotation

    def top_plate_pose_w(self) -> tuple[np.ndarray, np.ndarray]:
        """(position_w, rotation_wp) of the top-plate body as PyBullet has it (ground truth)."""
        position, orientation = self.client.getBasePositionAndOrientation(self.top_plate_body_id)
        rotation = np.array(self.client.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        return np.array(position), rotation

    def top_plate_velocity_w(self) -> tuple[np.ndarray, np.ndarray]:
        """(velocity of P's origin, angular velocity) in the world frame, from PyBullet."""
        linear, angular = self.client.getBaseVelocity(self.top_plate_body_id)
        return np.array(linear), np.array(angular)

    def measured_pose(self) -> np.ndarray:
        """The top plate's actual pose relative to home (6,): m, rad."""
        position, rotation = self.top_plate_pose_w()
        rotation_home = self.rotation_wb.T @ rotation
        translation = self.rotation_wb.T @ (position - self._home_position_w)
        return np.concatenate([translation, euler_zyx_from_matrix(rotation_home)])

    # ---------------------------------------------------------------- driving
    def reset(self, t0: float = 0.0) -> StewartStatus:
        """Place the plate at the (clamped) pose of ``t0`` with the motion's velocity.

        Re-reads the time step and gravity from PyBullet, so call it after changing them.
        """
        self._read_engine_parameters()
        self._plan = {}
        self._command(t0)
        status = self.last_status
        assert status is not None
        position, quaternion = self._target
        c = self.client
        c.resetBasePositionAndOrientation(self.top_plate_body_id, position, quaternion)
        if status.clamped:
            linear_w, angular_w = np.zeros(3), np.zeros(3)
        else:
            rates = np.asarray(self.motion.velocity(t0), dtype=float)
            angular = angular_velocity_from_euler_rates(status.applied_pose[3:], rates[3:])
            linear_w = self.rotation_wb @ rates[:3]
            angular_w = self.rotation_wb @ angular
        c.resetBaseVelocity(self.top_plate_body_id, linear_w.tolist(), angular_w.tolist())
        self.update_leg_visuals()
        return status

    @property
    def last_status(self) -> StewartStatus | None:
        """What the last :meth:`step_to`, :meth:`advance` or :meth:`reset` commanded."""
        if self._status is None and self._record is not None:
            t, commanded, applied, clamped, violated = self._record
            if applied is None:
                applied = commanded.copy()
            self._status = StewartStatus(t, commanded, applied, clamped, violated, self.kinematics)
        return self._status

    def step_to(self, t: float) -> StewartStatus:
        """Command the pose for time ``t``; call once per physics step before stepSimulation.

        ``t`` is the simulation time at the *end* of the coming step: after
        ``stepSimulation`` the plate is at ``motion.pose(t)`` (clamped to the workspace).
        """
        self.advance(t)
        status = self.last_status
        assert status is not None
        return status

    def advance(self, t: float) -> bool:
        """:meth:`step_to` without building the status; returns whether the command was clamped.

        The per-physics-step form: :attr:`last_status` still describes the command when read.
        """
        clamped = self._command(t)
        (tx, ty, tz), target_q = self._target
        body, cid = self.top_plate_body_id, self._cid
        (px, py, pz), q = pybullet.getBasePositionAndOrientation(body, physicsClientId=cid)
        inv_dt = 1.0 / self._dt
        # Required rotation over the step, in the world frame: q_rel = q_target * conj(q).
        rx, ry, rz, rw = _quat_multiply(target_q, (-q[0], -q[1], -q[2], q[3]))
        if rw < 0.0:
            rx, ry, rz, rw = -rx, -ry, -rz, -rw
        sin_half = math.sqrt(rx * rx + ry * ry + rz * rz)
        gain = 2.0 * math.atan2(sin_half, rw) / sin_half if sin_half > 1e-12 else 2.0
        angular = (rx * gain * inv_dt, ry * gain * inv_dt, rz * gain * inv_dt)
        gx, gy, gz = self._gravity_step
        linear = ((tx - px) * inv_dt - gx, (ty - py) * inv_dt - gy, (tz - pz) * inv_dt - gz)
        pybullet.resetBaseVelocity(body, linear, angular, physicsClientId=cid)
        return clamped

    def _command(self, t: float) -> bool:
        """Work out the (clamped) pose for time ``t``; record it and its world target.

        Returns whether the command was clamped.
        """
        commanded, (x, y, z, roll, pitch, yaw) = self._motion_pose(t)
        q = _quat_from_euler_zyx(roll, pitch, yaw)
        applied = None
        violated: tuple[int, ...] = ()
        clamped = False
        # A cheap sufficient test first; the exact check (and clamping) only near the limits.
        if not self.kinematics.surely_reachable(
            math.sqrt(x * x + y * y + z * z), math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        ):
            result = self.kinematics.clamp_to_workspace(commanded)
            applied, clamped, violated = result.pose, result.clamped, result.violated_legs
            if clamped:
                x, y, z, roll, pitch, yaw = applied.tolist()
                q = _quat_from_euler_zyx(roll, pitch, yaw)
        self._record = (float(t), commanded, applied, clamped, violated)
        self._status = None
        self._target = self._target_world(x, y, z, q)
        return clamped

    def _motion_pose(self, t: float) -> tuple[np.ndarray, list[float]]:
        """``motion.pose(t)`` as an array and as floats.

        When the calls step by exactly the physics time step (as the world's do), a
        :class:`BatchMotionSource` is evaluated ``_PLAN_STEPS`` steps ahead in one call: 24
        poses cost what 3 (sinusoids) to 12 (150-component sea state) single ones do.  The
        planned times are summed exactly as the caller's clock is, so they match it bit for bit.
        """
        motion = self.motion
        last_t, self._last_t = self._last_t, t
        if motion is self._plan_motion:
            planned = self._plan.get(t)
            if planned is not None:
                return planned
        if last_t is not None and t == last_t + self._dt and self._batch_capable(motion):
            times = [t]
            for _ in range(self._PLAN_STEPS - 1):
                times.append(times[-1] + self._dt)  # the same sums as the caller's clock
            poses = np.asarray(motion.poses(np.array(times)), dtype=float)
            self._plan = {
                time: (pose, floats)
                for time, pose, floats in zip(times, poses, poses.tolist(), strict=True)
            }
            self._plan_motion = motion
            return self._plan[t]
        pose = np.asarray(motion.pose(t), dtype=float)
        return pose, pose.tolist()

    def _batch_capable(self, motion: MotionSource) -> bool:
        """Whether ``motion`` is a :class:`BatchMotionSource` (remembered: the check is slow)."""
        known, capable = self._batch_check
        if known is not motion:
            capable = isinstance(motion, BatchMotionSource)
            self._batch_check = (motion, capable)
        return capable

    def _target_world(
        self, x: float, y: float, z: float, q: Quaternion
    ) -> tuple[tuple[float, float, float], Quaternion]:
        """World position and quaternion (x, y, z, w) of P for a pose relative to home, given
        as its translation and its quaternion in the base frame."""
        cos_b, sin_b = self._cos_yaw, self._sin_yaw
        hx, hy, hz = self._home_floats
        position = (hx + cos_b * x - sin_b * y, hy + sin_b * x + cos_b * y, hz + z)
        return position, _quat_multiply(self._half_yaw_q, q)

    # ---------------------------------------------------------------- legs
    def leg_anchor_points_w(self) -> tuple[np.ndarray, np.ndarray]:
        """(base anchors, top anchors), each (6, 3) in the world, top from the actual plate."""
        position, rotation = self.top_plate_pose_w()
        top = position + self.kinematics.top_anchors_p @ rotation.T
        return self.base_anchors_w.copy(), top

    def update_leg_visuals(self) -> None:
        """Move the leg cylinders and rods onto the plate's actual pose (call at env rate)."""
        base, top = self.leg_anchor_points_w()
        legs = top - base
        units = legs / np.linalg.norm(legs, axis=1, keepdims=True)
        half_cylinder, half_rod = 0.5 * self._cylinder_length, 0.5 * self._rod_length
        reset = self.client.resetBasePositionAndOrientation
        for i in range(6):
            u = units[i]
            orientation = _quat_z_to(u)
            reset(self.cylinder_body_ids[i], (base[i] + half_cylinder * u).tolist(), orientation)
            reset(self.rod_body_ids[i], (top[i] - half_rod * u).tolist(), orientation)


_IDENTITY: Quaternion = (0.0, 0.0, 0.0, 1.0)


def _quat_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product a * b of (x, y, z, w) quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _quat_from_euler_zyx(roll: float, pitch: float, yaw: float) -> Quaternion:
    """(x, y, z, w) quaternion of Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def _quat_z_to(u: np.ndarray) -> Quaternion:
    """Shortest-arc quaternion turning +z onto the unit vector u (u never points down here)."""
    ux, uy, uz = u.tolist()
    w = 1.0 + uz
    norm = math.sqrt(uy * uy + ux * ux + w * w)
    return (-uy / norm, ux / norm, 0.0, w / norm)
