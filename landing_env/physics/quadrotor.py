"""The quadrotor in flight: its PyBullet body and its rotor, drag and ground-effect physics.

Frames follow :mod:`estimation.frames`: world W z-up, body B FLU with its origin at the centre of
mass.  PyBullet integrates the rigid body; this module adds, once per physics step, the rotor
thrusts and yaw torques (with a first-order motor lag), the linear body drag against the
air-relative velocity (see :mod:`landing_env.physics.wind`), and ground effect computed from the
surface actually under each rotor (one ray batch per step, so a moving deck at any height works).
The vehicle's parameters are :class:`~landing_env.physics.quadrotor_params.QuadrotorParams`, its
state :class:`~landing_env.physics.drone_state.DroneState`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from landing_env.errors import ConfigError
from landing_env.physics.drone_state import DroneState, StateFloats, rotation_from_quaternion
from landing_env.physics.quadrotor_params import QuadrotorParams
from landing_env.physics.wind import WindModel


def ground_effect_denominator(h: Any, const: float, terms: tuple[float, ...] | None) -> Any:
    """T_OGE/T_IGE of a rotor whose hub is ``h`` > 0 above a surface (a float or an array).

    Cheeseman-Bennett: T_IGE/T_OGE = 1/(1 - c (R/4h)^2) (``const`` = c (R/4)^2), which diverges
    at h = R/4 (c = 1); with ``terms`` (d^2, 2 d^2, b^2, R^2, R^2 / 2, 2 K_b R^2), Sanchez-Cuevas
    et al. (2017): the neighbours' and the body's images too.
    """
    denominator = 1.0 - const / (h * h)
    if terms is not None:
        d2, d2x2, b2, r2, r2_half, body = terms
        four_h2 = 4.0 * h * h
        denominator -= (
            r2 * h / (d2 + four_h2) ** 1.5
            + r2_half * h / (d2x2 + four_h2) ** 1.5
            + body * h / (b2 + four_h2) ** 1.5
        )
    return denominator


class Quadrotor:
    """One quadrotor body in a PyBullet world, driven by rotor speed commands."""

    def __init__(
        self,
        client: BulletClient,
        params: QuadrotorParams | None = None,
        wind: WindModel | None = None,
        position_w: tuple[float, float, float] = (0.0, 0.0, 1.0),
        yaw: float = 0.0,
    ) -> None:
        self.client = client
        self.params = QuadrotorParams.from_yaml() if params is None else params
        self.wind = wind
        # The hot path calls pybullet's module functions with the client id directly: going
        # through BulletClient's attribute lookup costs about a microsecond per call.
        self._cid: int = client._client
        self.body_id: int = client.loadURDF(
            str(self.params.urdf_path),
            basePosition=position_w,
            baseOrientation=client.getQuaternionFromEuler((0.0, 0.0, yaw)),
            flags=p.URDF_USE_INERTIA_FROM_FILE,
        )
        feet = []
        for joint in range(client.getNumJoints(self.body_id)):
            info = client.getJointInfo(self.body_id, joint)
            if info[12].decode().startswith("foot"):
                feet.append(joint)
        #: link indices of the four landing feet (front, left, back, right)
        self.foot_link_indices: tuple[int, ...] = tuple(feet)
        # PyBullet's default linear/angular damping would be a second, unmodelled drag.
        for link in (-1, *feet):
            client.changeDynamics(self.body_id, link, linearDamping=0.0, angularDamping=0.0)
        self._apply_landing_gear()

        #: the whole body's centre of mass in the base frame (m): the feet lower it slightly
        self.com_offset_b: tuple[float, float, float] = self._combined_com_offset()
        prm = self.params
        self._zero3 = (0.0, 0.0, 0.0)
        self._nan4 = (math.nan, math.nan, math.nan, math.nan)
        # Plain-float copies of the parameters for the per-step path, refreshed by
        # _sync_constants whenever ``params`` is replaced or the step length changes.
        self._constants_for: tuple[QuadrotorParams, float] | None = None
        self._alpha = 0.0
        self._k_f = 0.0
        self._omega_range = (0.0, 0.0)
        self._rotor_terms: tuple[tuple[float, float, float], ...] = ()
        self._rotors: tuple[tuple[float, float, float], ...] = ()
        self._drag = self._zero3
        self._ground_effect_on = False
        self._ge_const = 0.0
        self._ge_min_denominator = 1.0
        self._ge_max_gain = 1.0
        self._ge_ray_length = 0.0
        self._ge_reach = 0.0
        #: no surface of the world stands above this height (m, W); a drone whose rays cannot
        #: reach below it casts none (the world sets it; infinite: always cast)
        self.surfaces_below_z: float = math.inf

        #: True while the motors respond to commands; disarmed rotors spin down to zero
        self.armed: bool = True
        #: time advanced by :meth:`apply_rotor_commands` (s); drives the wind model
        self.time: float = 0.0
        self._omega = [prm.hover_omega] * 4
        #: True when the last command had a rotor outside [omega_min, omega_max] (it was clamped)
        self.last_saturated: bool = False
        #: per-rotor thrust applied in the last step (N), ground effect included
        self.last_thrusts: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)
        #: per-rotor distance from the hub to the surface below along body -z (m); NaN: none
        self.last_ground_heights: tuple[float, ...] = self._nan4
        #: per-rotor thrust gain T_IGE/T_OGE of the last step
        self.last_ground_effect_gains: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
        #: True when a rotor's ground-effect gain hit ground_effect_max_gain in the last step
        self.last_ground_effect_capped: bool = False
        #: wind velocity (m/s, W) used when no WindModel is attached: set it before each
        #: apply_rotor_commands to drive the wind from outside
        self.wind_velocity_w: np.ndarray | tuple[float, float, float] = self._zero3
        #: wind velocity (m/s, W) used for the drag in the last step
        self.last_wind_w: tuple[float, float, float] = self._zero3

    def _apply_landing_gear(self) -> None:
        """Give each foot its contact stiffness, damping and friction (quadrotor.yaml).

        Bullet turns stiffness k and damping c into a soft constraint (ERP = dt k / (dt k + c),
        CFM = 1 / (dt k + c)); restitution stays 0, the energy loss is the damping's.
        """
        prm = self.params
        for link in self.foot_link_indices:
            if prm.gear_stiffness > 0.0:
                self.client.changeDynamics(
                    self.body_id,
                    link,
                    contactStiffness=prm.gear_stiffness,
                    contactDamping=prm.gear_damping,
                    lateralFriction=prm.gear_friction,
                    restitution=0.0,
                )
            else:
                self.client.changeDynamics(
                    self.body_id, link, lateralFriction=prm.gear_friction, restitution=0.0
                )

    def _combined_com_offset(self) -> tuple[float, float, float]:
        """Centre of mass of base and feet together, in the base frame."""
        client = self.client
        base_pos, base_quat = client.getBasePositionAndOrientation(self.body_id)
        rotation = np.array(client.getMatrixFromQuaternion(base_quat)).reshape(3, 3)
        total = client.getDynamicsInfo(self.body_id, -1)[0]
        moment = np.zeros(3)
        for link in self.foot_link_indices:
            mass = client.getDynamicsInfo(self.body_id, link)[0]
            centre = np.array(client.getLinkState(self.body_id, link)[0]) - base_pos
            moment += mass * (rotation.T @ centre)
            total += mass
        offset = moment / total
        if math.hypot(offset[0], offset[1]) > 1e-6:
            raise ConfigError("urdf", "the feet must not move the CoM off the body z axis")
        return (0.0, 0.0, float(offset[2]))

    # ------------------------------------------------------------------ state

    def reset(
        self,
        position_w: np.ndarray | tuple[float, float, float],
        yaw: float,
        velocity_w: np.ndarray | tuple[float, float, float] | None = None,
        rotation_wb: np.ndarray | None = None,
    ) -> None:
        """Put the drone level at ``position_w`` (m, W) with ``yaw`` (rad), rotors at hover;
        ``rotation_wb`` (a rotation matrix) replaces the level attitude."""
        position = [float(v) for v in position_w]
        velocity = self._zero3 if velocity_w is None else [float(v) for v in velocity_w]
        quaternion = (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw))
        if rotation_wb is not None:
            quaternion = tuple(float(v) for v in Rotation.from_matrix(rotation_wb).as_quat())
        self.client.resetBasePositionAndOrientation(self.body_id, position, quaternion)
        self.client.resetBaseVelocity(self.body_id, velocity, self._zero3)
        self._omega = [self.params.hover_omega] * 4
        self.armed = True
        self.last_saturated = False
        self.last_thrusts = (0.0, 0.0, 0.0, 0.0)
        self.last_ground_heights = self._nan4
        self.last_ground_effect_gains = (1.0, 1.0, 1.0, 1.0)
        self.last_ground_effect_capped = False

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Current (lagged) rotor speeds (rad/s)."""
        return np.array(self._omega)

    def set_rotor_speeds(self, omega: np.ndarray | list[float]) -> None:
        """Set the actual rotor speeds (rad/s) directly, e.g. for a test or a warm start."""
        self._omega = [float(v) for v in omega]

    def read_state(self) -> DroneState:
        """Query PyBullet (one pose and one velocity call) and return the state."""
        cid = self._cid
        pos, quat = p.getBasePositionAndOrientation(self.body_id, physicsClientId=cid)
        vel, (wx, wy, wz) = p.getBaseVelocity(self.body_id, physicsClientId=cid)
        rot = rotation_from_quaternion(quat)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot
        omega_b = (
            r00 * wx + r10 * wy + r20 * wz,
            r01 * wx + r11 * wy + r21 * wz,
            r02 * wx + r12 * wy + r22 * wz,
        )
        return DroneState.from_floats(StateFloats(pos, quat, rot, vel, omega_b))

    # ---------------------------------------------------------------- actuation

    def _sync_constants(self, dt: float) -> None:
        """Copy the parameters the per-step path needs into plain floats."""
        prm = self.params
        self._constants_for = (prm, dt)
        # Exact discretisation of the first-order motor lag over one step.
        self._alpha = 1.0 - math.exp(-dt / prm.motor_time_constant)
        self._k_f = float(prm.k_f)
        self._omega_range = (float(prm.omega_min), float(prm.omega_max))
        self._rotors = tuple(
            (float(x), float(y), float(z)) for x, y, z in prm.rotor_positions_b.tolist()
        )
        # per rotor: hub x, hub y (m) and the yaw reaction torque per (rad/s)^2 (N m)
        self._rotor_terms = tuple(
            (x, y, -float(spin) * prm.k_m)
            for (x, y, _), spin in zip(self._rotors, prm.spin_directions.tolist(), strict=True)
        )
        d0, d1, d2 = prm.linear_drag_b.tolist()
        self._drag = (float(d0), float(d1), float(d2))
        # drag = linear_b (airframe + (1 - airframe) * mean rotor speed / hover speed)
        self._drag_airframe = float(prm.drag_airframe_fraction)
        self._drag_per_omega = (1.0 - self._drag_airframe) / (4.0 * float(prm.hover_omega))
        self._ground_effect_on = bool(prm.ground_effect_enabled)
        self._ge_const = prm.ground_effect_coefficient * (prm.rotor_radius / 4.0) ** 2
        self._ge_multirotor = prm.ground_effect_model == "sanchez_cuevas"
        hubs = prm.rotor_positions_b[:, :2]
        gaps = np.linalg.norm(hubs[:, None, :] - hubs[None, :, :], axis=-1)
        adjacent = float(np.min(gaps[gaps > 1e-9]))
        r2 = float(prm.rotor_radius) ** 2
        # (d^2, 2 d^2, b^2, R^2, R^2 / 2, 2 K_b R^2) of the four-rotor model
        self._ge_terms = (
            adjacent**2,
            2.0 * adjacent**2,
            float(prm.arm_length) ** 2,
            r2,
            0.5 * r2,
            2.0 * float(prm.ground_effect_body_coefficient) * r2,
        )
        self._ge_min_denominator = 1.0 / prm.ground_effect_max_gain
        self._ge_max_gain = float(prm.ground_effect_max_gain)
        self._ge_ray_length = float(prm.ground_effect_ray_length)
        # the lowest a ray reaches below the body origin: the farthest hub, then the ray
        self._ge_reach = self._ge_ray_length + max(math.hypot(*hub) for hub in self._rotors)

    def apply_rotor_commands(
        self, omega_cmd: np.ndarray | list[float], dt: float, state: DroneState | None = None
    ) -> None:
        """Advance the motors by ``dt`` towards ``omega_cmd`` (rad/s) and apply this step's forces.

        Commands are clamped to [omega_min, omega_max] and ``last_saturated`` reports it.  The
        forces hold for the next ``stepSimulation`` only (PyBullet clears them).  ``state``:
        the state read this step, which saves the pose queries; ``None`` queries PyBullet.
        """
        constants_for = self._constants_for
        if constants_for is None or constants_for[0] is not self.params or constants_for[1] != dt:
            self._sync_constants(dt)
        alpha = self._alpha
        omega = self._omega
        saturated = False
        if self.armed:
            lo, hi = self._omega_range
            commands = omega_cmd.tolist() if isinstance(omega_cmd, np.ndarray) else omega_cmd
            for i in range(4):
                c = commands[i]
                if c < lo:
                    c = lo
                    saturated = True
                elif c > hi:
                    c = hi
                    saturated = True
                elif c != c:  # NaN: a broken controller; hold idle and say so
                    c = lo
                    saturated = True
                omega[i] += (c - omega[i]) * alpha
        else:
            for i in range(4):
                omega[i] -= omega[i] * alpha
        self.last_saturated = saturated

        # Pose and velocity: the state read this step when given.
        if state is not None:
            floats = state.floats
            pos = floats.position_w
            rot = floats.rotation_wb
            vel = floats.velocity_w
        else:
            cid = self._cid
            pos, quat = p.getBasePositionAndOrientation(self.body_id, physicsClientId=cid)
            vel = p.getBaseVelocity(self.body_id, physicsClientId=cid)[0]
            rot = rotation_from_quaternion(quat)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot

        k_f = self._k_f
        thrusts = [k_f * w * w for w in omega]
        if self._ground_effect_on:
            gains = self._ground_effect(pos, rot)
            if gains is not None:
                thrusts = [t * g for t, g in zip(thrusts, gains, strict=True)]
        fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for t, w, (x, y, yaw_coeff) in zip(thrusts, omega, self._rotor_terms, strict=True):
            fz += t
            tx += y * t  # r x (0, 0, T) = (y T, -x T, 0)
            ty -= x * t
            tz += yaw_coeff * w * w
        self.last_thrusts = tuple(thrusts)

        # Linear drag against the air-relative velocity, in the body frame.
        self.time += dt
        if self.wind is not None:
            wind = self.wind.velocity_tuple(self.time, dt)
        else:
            outside = self.wind_velocity_w
            ox, oy, oz = outside.tolist() if isinstance(outside, np.ndarray) else outside
            wind = (float(ox), float(oy), float(oz))
        self.last_wind_w = wind
        ax = vel[0] - wind[0]
        ay = vel[1] - wind[1]
        az = vel[2] - wind[2]
        d0, d1, d2 = self._drag
        # the rotor drag grows with the rotor speed (Mahony, Kumar & Corke 2012), the
        # airframe's does not: at hover the scale is 1
        scale = self._drag_airframe + self._drag_per_omega * (
            omega[0] + omega[1] + omega[2] + omega[3]
        )
        fx = -scale * d0 * (r00 * ax + r10 * ay + r20 * az)
        fy = -scale * d1 * (r01 * ax + r11 * ay + r21 * az)
        fz -= scale * d2 * (r02 * ax + r12 * ay + r22 * az)

        # The net force acts at the whole body's CoM (drag through the CoM, as modelled); the
        # thrusts' torques about it equal the torques computed above because the CoM lies on
        # the body z axis, parallel to the thrusts.  One force and one torque call replace
        # four per-rotor forces.
        cid = self._cid
        p.applyExternalForce(
            self.body_id, -1, (fx, fy, fz), self.com_offset_b, p.LINK_FRAME, physicsClientId=cid
        )
        p.applyExternalTorque(self.body_id, -1, (tx, ty, tz), p.LINK_FRAME, physicsClientId=cid)

    def ground_effect_gains(self, heights_m: np.ndarray) -> np.ndarray:
        """T_IGE/T_OGE of rotors whose hubs are ``heights_m`` above a surface (any shape; NaN
        or beyond the ray's reach: no surface, gain 1), as :meth:`apply_rotor_commands` applies
        them (capped at ``ground_effect_max_gain``); all 1 with the ground effect off."""
        heights = np.asarray(heights_m, dtype=float)
        gains = np.ones_like(heights)
        if not self._ground_effect_on:
            return gains
        near = np.isfinite(heights) & (heights <= self._ge_ray_length)
        h = np.where(near & (heights > 0.0), heights, 1.0)
        terms = self._ge_terms if self._ge_multirotor else None
        denominator = np.where(
            near & (heights > 0.0), ground_effect_denominator(h, self._ge_const, terms), -1.0
        )
        capped = denominator <= self._ge_min_denominator
        gains = np.where(
            near, np.where(capped, self._ge_max_gain, 1.0 / np.where(capped, 1.0, denominator)), 1.0
        )
        return gains

    @property
    def ground_effect_reach_m(self) -> float:
        """How far below a rotor hub the ground effect's ray looks, m."""
        return self._ge_ray_length

    def _ground_effect(self, pos: Any, rot: Any) -> list[float] | None:
        """Per-rotor T_IGE/T_OGE from one ray batch down body -z from the four hubs.

        ``None`` when no ray hits anything (all gains 1, the usual case in flight).
        """
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot
        px, py, pz = pos
        if pz - self._ge_reach > self.surfaces_below_z:
            # every ray ends above every surface: nothing within reach, without casting
            self.last_ground_heights = self._nan4
            self.last_ground_effect_gains = (1.0, 1.0, 1.0, 1.0)
            self.last_ground_effect_capped = False
            return None
        length = self._ge_ray_length
        dx = -length * r02
        dy = -length * r12
        dz = -length * r22
        starts = [
            (
                px + r00 * x + r01 * y + r02 * z,
                py + r10 * x + r11 * y + r12 * z,
                pz + r20 * x + r21 * y + r22 * z,
            )
            for x, y, z in self._rotors
        ]
        ends = [(hx + dx, hy + dy, hz + dz) for hx, hy, hz in starts]
        # The hubs lie outside the drone's collision shapes (frame box and feet), so the rays
        # start at the hubs; a hit on the drone itself is ignored all the same.
        hits = p.rayTestBatch(starts, ends, physicsClientId=self._cid)
        body = self.body_id
        for hit in hits:
            if hit[0] >= 0 and hit[0] != body:
                break
        else:
            # Nothing within reach (the usual case in flight).
            self.last_ground_heights = self._nan4
            self.last_ground_effect_gains = (1.0, 1.0, 1.0, 1.0)
            self.last_ground_effect_capped = False
            return None
        heights = []
        gains = []
        capped = False
        const = self._ge_const
        min_den = self._ge_min_denominator
        for hit in hits:
            if hit[0] < 0 or hit[0] == body:
                heights.append(math.nan)
                gains.append(1.0)
                continue
            h = hit[2] * length
            heights.append(h)
            denominator = (
                ground_effect_denominator(h, const, self._ge_terms if self._ge_multirotor else None)
                if h > 0.0
                else -1.0
            )
            if denominator <= min_den:
                gains.append(self._ge_max_gain)
                capped = True
            else:
                gains.append(1.0 / denominator)
        self.last_ground_heights = tuple(heights)
        self.last_ground_effect_gains = tuple(gains)
        self.last_ground_effect_capped = capped
        return gains
