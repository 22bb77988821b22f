"""The onboard look-ahead's reduced model: the drone's own closed loop flown as a point mass,
all the look-ahead's draws at once.

The look-ahead of :mod:`agents.policies.deck_forecast` flies each drawn future through a
restored copy of the whole simulation (PyBullet, the sensors, the estimators): about 0.17 s of
CPU a draw, some three times slower than the flight it decides.  A drone cannot carry that; it
can carry a model of its own closed loop.  :class:`ReducedDescentModel` is that model:

* **the guidance** of the final descent (:class:`~landing_env.timing.guidance.DeckGuidance` in
  the deck's frame): the timed descent's reference
  (:func:`~landing_env.timing.timed_descent.timed_descent_reference`, its rate fed forward
  ``descent_lead_s`` early, its height error corrected by ``descent_track_gain``), the deck's
  velocity led ``deck_lead_s`` by its acceleration, the horizontal correction towards the
  camera's aim point (upwind of the tag by the height times the low-passed lean);
* **the velocity loop** of :class:`~landing_env.physics.controller.CascadedController` (its
  proportional and integral gains, the integrators' present values, the limits on speed and
  tilt) and the attitude loop as a first-order lag of the thrust's direction
  (``1 / att_p_rp``);
* **the vehicle** as a point mass under its thrust, gravity and the linear body drag of the
  air going past it (a drawn airframe's drag and thrust scales, a drawn present gust held);
* **the deck** following the HMS forecast the look-ahead plays
  (:class:`~landing_env.stewart.motion.ForecastMotion`), sampled once for all draws;
* **the touchdown** at the first foot's contact with the deck's plane, graded as
  :func:`landing_env.touchdown.evaluate_touchdown` grades the relative normal speed, the deck
  tilt and the relative attitude (the settle's checks, which need the contact's physics, are
  taken as passed), so that :func:`~agents.policies.oracle.touchdown_margin` means the same.

Every draw is a row of the same NumPy arrays: a check of 16 draws is one integration of
(16, 3) states.  The draws themselves are the look-ahead's own
(:func:`~agents.policies.deck_forecast.onboard_draws`: the same streams, so draw ``k`` of a
check is the same drawn airframe, gust and position error in both models).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from agents.policies.deck_forecast import DeckForecastTimingPolicy
from agents.policies.oracle import TriedCommit, touchdown_margin
from estimation.frames import R_BC
from landing_env.config import TouchdownConfig
from landing_env.physics.quadrotor_params import GRAVITY as GRAVITY_MPS2
from landing_env.stewart.kinematics import rotation_matrix_zyx
from landing_env.timing.timed_descent import timed_descent_references
from landing_env.touchdown import Outcome, TouchdownMetrics, evaluate_touchdown

#: the reduced model's integration step, s (the guidance runs at the task's control period)
MODEL_DT_S = 1.0 / 40.0

#: how long after the commit the reduced model flies before a draw without a contact counts
#: as no touchdown, s
MODEL_HORIZON_S = 4.0


@dataclass(frozen=True)
class DeckTrack:
    """The deck's predicted motion at the model's steps: times (T,), the tag centre (T, 3),
    the plate's rotation (T, 3, 3), its velocity (T, 3) and acceleration (T, 3), all world."""

    times_s: np.ndarray
    position_w: np.ndarray
    rotation_wp: np.ndarray
    velocity_w: np.ndarray
    acceleration_w: np.ndarray

    def finite(self) -> bool:
        """Every sample is finite."""
        return _all_finite(self.position_w, self.rotation_wp, self.velocity_w, self.acceleration_w)

    @classmethod
    def from_motion(
        cls,
        motion: Any,
        home_position_w: np.ndarray,
        base_rotation_wb: np.ndarray,
        t0_s: float,
        horizon_s: float = MODEL_HORIZON_S,
        dt_s: float = MODEL_DT_S,
    ) -> DeckTrack:
        """``motion``'s poses (relative to the platform's home: m, rad) from ``t0_s`` on,
        placed in the world as the platform places them."""
        steps = math.ceil(horizon_s / dt_s) + 3
        times = t0_s + dt_s * np.arange(steps)
        poses = np.asarray(motion.poses(times), dtype=float)
        base = np.asarray(base_rotation_wb, dtype=float)
        position = np.asarray(home_position_w, dtype=float) + poses[:, :3] @ base.T
        rotation = base @ rotation_matrix_zyx(poses[:, 3], poses[:, 4], poses[:, 5])
        velocity = np.gradient(position, dt_s, axis=0)
        acceleration = np.gradient(velocity, dt_s, axis=0)
        return cls(times, position, rotation, velocity, acceleration)


@dataclass(frozen=True)
class DescentStart:
    """What the reduced model starts a check's descent from (shared by its draws), world frame.

    ``velocity_integral_w``: the velocity loop's integrators (m/s^2); ``wind_w``: the air at the
    drone less the present gust's share of it (the mean wind and the ship's airwake), of which
    the gust reaches the drone ``gust_gain`` times (the airwake's turbulence factor);
    ``lean``: the guidance's low-passed lean; ``feet_b`` (F, 3): the feet's centres in the
    body frame.
    """

    position_w: np.ndarray
    velocity_w: np.ndarray
    rotation_wb: np.ndarray
    velocity_integral_w: np.ndarray
    wind_w: np.ndarray
    lean: np.ndarray
    descent_time_s: float
    feet_b: np.ndarray
    foot_radius_m: float
    camera_offset_b: np.ndarray
    camera_rotation_bc: np.ndarray
    #: the guidance's deck tracker (:class:`~landing_env.timing.deck_tracker.DeckTracker`) as
    #: it is now: the model feeds a copy the predicted deck
    tracker: Any = None
    #: the rotors' hubs in the body frame (4, 3), for the ground effect
    rotor_hubs_b: np.ndarray | None = None
    gust_gain: float = 1.0

    def finite(self) -> bool:
        """Every state the flight starts from is finite."""
        return _all_finite(
            self.position_w,
            self.velocity_w,
            self.rotation_wb,
            self.velocity_integral_w,
            self.wind_w,
            self.lean,
            np.array([self.descent_time_s, self.gust_gain]),
        )


@dataclass(frozen=True)
class DrawSet:
    """The drawn unknowns of a check's futures, one row per draw: the drone's shift from where
    it is (m, world), the present gust (m/s, world), the drag and thrust scales."""

    shift_w: np.ndarray
    gust_w: np.ndarray
    drag_scale: np.ndarray
    thrust_scale: np.ndarray

    def __len__(self) -> int:
        return len(self.drag_scale)

    def finite(self) -> bool:
        """Every drawn value is finite."""
        return _all_finite(self.shift_w, self.gust_w, self.drag_scale, self.thrust_scale)

    def row(self, k: int) -> DrawSet:
        """Draw ``k`` alone."""
        pick = slice(k, k + 1)
        return DrawSet(
            self.shift_w[pick], self.gust_w[pick], self.drag_scale[pick], self.thrust_scale[pick]
        )


@dataclass(frozen=True)
class ReducedTouchdown:
    """Each draw's contact (NaN where it did not touch down within the model's horizon):
    the time after the commit and :class:`~landing_env.touchdown.TouchdownMetrics`' graded
    values."""

    time_s: np.ndarray
    relative_normal_speed: np.ndarray
    deck_tilt_deg: np.ndarray
    relative_attitude_deg: np.ndarray
    lateral_offset_m: np.ndarray

    def metrics(self, k: int) -> TouchdownMetrics | None:
        """Draw ``k``'s touchdown as the environment measures one (None: no touchdown); the
        settle's checks, which the point mass cannot judge, read as passed."""
        if not math.isfinite(float(self.time_s[k])):
            return None
        return TouchdownMetrics(
            time_s=float(self.time_s[k]),
            relative_normal_speed=float(self.relative_normal_speed[k]),
            deck_tilt_deg=float(self.deck_tilt_deg[k]),
            relative_attitude_deg=float(self.relative_attitude_deg[k]),
            lateral_offset_m=float(self.lateral_offset_m[k]),
            all_feet_touched=True,
            on_deck_after_settle=True,
            bounce_height_m=0.0,
        )

    def judged(self, k: int, thresholds: TouchdownConfig) -> tuple[Outcome, dict[str, Any] | None]:
        """Draw ``k``'s outcome by :func:`~landing_env.touchdown.evaluate_touchdown` and its
        touchdown as ``info["touchdown"]`` gives it (None and a timeout: no touchdown)."""
        metrics = self.metrics(k)
        if metrics is None:
            return Outcome.TIMEOUT, None
        outcome, metrics = evaluate_touchdown(metrics, thresholds)
        return outcome, metrics.as_dict()


def _all_finite(*arrays: Any) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(a, dtype=float)))) for a in arrays)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (N, k) arrays."""
    return np.einsum("ij,ij->i", a, b)


def _normalised(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.sqrt(_dot(v, v)), 1e-9)[:, None]


def _shrink(v: np.ndarray, limit: Any) -> np.ndarray:
    """The factor (N, 1) that brings each row of ``v`` within the norm ``limit``."""
    size = np.sqrt(_dot(v, v))[:, None]
    return np.minimum(1.0, limit / np.maximum(size, 1e-9))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (N, 3) arrays (``np.cross`` costs more for small N)."""
    return np.stack(
        (
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ),
        axis=1,
    )


def _axes(z_b: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each draw's body axes (x, y, z as (N, 3) rows in the world) with the body z axes
    ``z_b`` and the nose towards ``heading`` (yaw is held through the descent)."""
    x = _normalised(heading[None, :] - (z_b @ heading)[:, None] * z_b)
    return x, _cross(z_b, x), z_b


def _body_to_world(axes: tuple[np.ndarray, ...], vector_b: np.ndarray) -> np.ndarray:
    """A body-frame vector (3,) in each draw's world frame (N, 3)."""
    x, y, z = axes
    return x * vector_b[0] + y * vector_b[1] + z * vector_b[2]


def _world_to_body(axes: tuple[np.ndarray, ...], vector_w: np.ndarray) -> np.ndarray:
    """World vectors ((3,) or (N, 3)) in each draw's body frame (N, 3)."""
    x, y, z = axes
    if vector_w.ndim == 1:
        return np.stack((x @ vector_w, y @ vector_w, z @ vector_w), axis=1)
    return np.stack((_dot(x, vector_w), _dot(y, vector_w), _dot(z, vector_w)), axis=1)


class ReducedDescentModel:
    """The drone's closed loop through a commit, as a point mass: ``fly`` takes the
    :class:`DescentStart`, the :class:`DeckTrack` and a :class:`DrawSet` and gives each draw's
    :class:`ReducedTouchdown`.

    ``gains``: the guidance's (:class:`~landing_env.guidance_gains.GuidanceGains`);
    ``controller``: the velocity loop's (:class:`~landing_env.physics.controller.ControllerGains`);
    ``mass_kg`` and ``linear_drag_b`` (N per m/s, body x, y, z): the nominal airframe;
    ``control_dt_s``: the guidance's period.
    """

    def __init__(
        self,
        gains: Any,
        controller: Any,
        mass_kg: float,
        linear_drag_b: np.ndarray,
        control_dt_s: float,
        dt_s: float = MODEL_DT_S,
        horizon_s: float = MODEL_HORIZON_S,
        ground_effect: Any = None,
        ground_effect_reach_m: float = 0.5,
    ) -> None:
        self.gains = gains
        self.controller = controller
        self.mass_kg = float(mass_kg)
        drag = np.asarray(linear_drag_b, dtype=float).reshape(3)
        #: the drag across (body x, y: their mean) and along the body z axis
        self.drag_xy = float(np.mean(drag[:2]))
        self.drag_z = float(drag[2])
        #: the rotors' T_IGE/T_OGE at hub heights (the drone's
        #: :meth:`~landing_env.physics.quadrotor.Quadrotor.ground_effect_gains`; None: none)
        #: and how far below a hub it reaches
        self.ground_effect = ground_effect
        self.ground_effect_reach_m = ground_effect_reach_m
        self.dt_s = float(dt_s)
        self.horizon_s = float(horizon_s)
        #: model steps per guidance period
        self.per_control = max(1, round(control_dt_s / self.dt_s))
        self.control_dt_s = self.per_control * self.dt_s
        #: the attitude loop's time constant (its proportional gain's inverse)
        self.attitude_tau_s = 1.0 / max(float(controller.att_p_rp), 1e-3)

    def fly(self, start: DescentStart, deck: DeckTrack, draws: DrawSet) -> ReducedTouchdown:
        """Each draw's commit now, flown to its first contact (or the model's horizon)."""
        if (
            len(deck.times_s) < 2
            or abs(float(deck.times_s[1] - deck.times_s[0]) - self.dt_s) > 1e-9
        ):
            raise ValueError(
                f"the deck track must be sampled every {self.dt_s:g} s, the model's step"
            )
        g = self.gains
        c = self.controller
        n = len(draws)
        dt = self.dt_s
        m = self.mass_kg
        steps = min(len(deck.times_s) - 1, math.ceil(self.horizon_s / dt))
        p = np.asarray(start.position_w, dtype=float)[None, :] + draws.shift_w
        v = np.repeat(np.asarray(start.velocity_w, dtype=float)[None, :], n, axis=0)
        rotation0 = np.asarray(start.rotation_wb, dtype=float)
        z_b = np.repeat(rotation0[:, 2][None, :], n, axis=0)
        heading = rotation0[:, 0].copy()
        integral = np.repeat(np.asarray(start.velocity_integral_w, dtype=float)[None, :], n, axis=0)
        wind = np.asarray(start.wind_w, dtype=float)[None, :] + start.gust_gain * draws.gust_w
        lean = np.repeat(np.asarray(start.lean, dtype=float)[None, :], n, axis=0)
        drag_xy = self.drag_xy * draws.drag_scale[:, None]
        drag_z = self.drag_z * draws.drag_scale[:, None]
        thrust_scale = draws.thrust_scale[:, None]
        feet_b = np.asarray(start.feet_b, dtype=float)
        camera_b = np.asarray(start.camera_offset_b, dtype=float)
        hubs_b = None if start.rotor_hubs_b is None else np.asarray(start.rotor_hubs_b, float)
        # the ground effect's reach below the body's origin
        reach = (
            -math.inf
            if self.ground_effect is None or hubs_b is None
            else self.ground_effect_reach_m + float(np.max(np.linalg.norm(hubs_b, axis=1)))
        )
        self._rotation_bc = np.asarray(start.camera_rotation_bc, dtype=float)
        self._duration_s = float(start.descent_time_s)

        touched = np.zeros(n, dtype=bool)
        out = {key: np.full(n, np.nan) for key in ("time", "speed", "tilt", "attitude", "offset")}
        setpoint = np.zeros((n, 3))
        #: each draw's timed descent: its clock and start height (NaN: to start)
        state = {
            "clock": np.zeros(n),
            "start": np.full(n, np.nan),
            "reference": np.zeros(n),
            "progress": np.ones(n),
        }
        tracker = copy.deepcopy(start.tracker) if start.tracker is not None else None
        lean_alpha = self.control_dt_s / (g.lean_filter_s + self.control_dt_s)
        tan_tilt = math.tan(c.max_tilt)
        gain_p = np.array([c.vel_p_xy, c.vel_p_xy, c.vel_p_z])
        gain_i = np.array([c.vel_i_xy, c.vel_i_xy, c.vel_i_z]) * dt
        limit_i = np.array([c.vel_i_limit_xy, c.vel_i_limit_xy, c.vel_i_limit_z])
        turn = dt / self.attitude_tau_s
        axes = _axes(z_b, heading)
        local = _world_to_body(axes, deck.rotation_wp[0][:, 2])
        clearance = np.full(n, math.inf)
        for step in range(steps):
            d = deck.position_w[step]
            normal = deck.rotation_wp[step][:, 2]
            if step % self.per_control == 0:
                lean = lean + lean_alpha * (z_b[:, :2] / np.maximum(z_b[:, 2:], 0.5) - lean)
                camera = p + _body_to_world(axes, camera_b)
                height = ((camera - d) @ normal) / np.maximum(z_b @ normal, 0.2)
                progress = self._view_progress(axes, camera, d, height)
                speed = self._descent_speed(height, progress, state)
                if tracker is not None and tracker.valid:
                    # the guidance's tracker, measuring the predicted deck (the tag centre, the
                    # height as the drone's centre less the camera's range)
                    measured = d.copy()
                    measured[2] += float(np.mean(p[:, 2] - camera[:, 2]))
                    if step:
                        tracker.update_measured(measured, self.control_dt_s)
                    deck_v = tracker.velocity_w + g.deck_lead_s * tracker.acceleration_w
                else:
                    deck_v = deck.velocity_w[step] + g.deck_lead_s * deck.acceleration_w[step]
                aim = d[None, :2] + np.maximum(height, 0.0)[:, None] * lean
                relative = g.k_xy * (aim - p[:, :2]) - speed[:, None] * lean
                relative *= _shrink(relative, g.max_horizontal_speed)
                setpoint = np.empty((n, 3))
                setpoint[:, :2] = deck_v[None, :2] + relative
                setpoint[:, 2] = np.clip(deck_v[2] - speed, -c.max_descent_rate, c.max_climb_rate)
                setpoint[:, :2] *= _shrink(setpoint[:, :2], c.max_horizontal_speed)
            # the velocity loop (PI; the integrators as the controller holds them)
            error = setpoint - v
            accel = gain_p * error + integral
            accel[:, 2] = np.clip(accel[:, 2], -c.max_accel_down, c.max_accel_up)
            accel[:, :2] *= _shrink(accel[:, :2], (accel[:, 2:] + GRAVITY_MPS2) * tan_tilt)
            integral = np.clip(integral + gain_i * error, -limit_i, limit_i)
            force = m * accel
            force[:, 2] += m * GRAVITY_MPS2
            desired = _normalised(force)
            thrust = _dot(force, z_b)[:, None] * thrust_scale
            if float(np.min(clearance)) < reach:
                # the hubs' heights over the deck along the body's -z (the rays the drone's
                # ground effect casts), the thrust scaled by the rotors' mean gain
                heights = ((p - d) @ normal)[:, None] + local @ hubs_b.T
                heights /= np.maximum(z_b @ normal, 0.2)[:, None]
                thrust = thrust * np.mean(self.ground_effect(heights), axis=1, keepdims=True)
            # the vehicle: thrust on the body z axis, gravity, the linear drag of the air
            air = v - wind
            along = _dot(air, z_b)[:, None]
            a = (thrust * z_b - drag_xy * (air - along * z_b) - drag_z * along * z_b) / m
            a[:, 2] -= GRAVITY_MPS2
            v = v + a * dt
            p = p + v * dt
            z_b = _normalised(z_b + (desired - z_b) * turn)
            axes = _axes(z_b, heading)
            # the touchdown: the first foot on the deck's plane
            d1 = deck.position_w[step + 1]
            normal1 = deck.rotation_wp[step + 1][:, 2]
            local = _world_to_body(axes, normal1)
            clearance = ((p - d1) @ normal1) + np.min(local @ feet_b.T, axis=1)
            hit = (clearance - start.foot_radius_m <= 0.0) & ~touched
            if hit.any():
                omega = self._angular_velocity(deck, step + 1)
                point_v = deck.velocity_w[step + 1] + _cross(omega[None, :], p[hit] - d1)
                relative_v = v[hit] - point_v
                offset = p[hit] - d1
                offset -= np.outer(offset @ normal1, normal1)
                out["time"][hit] = (step + 1) * dt
                out["speed"][hit] = -(relative_v @ normal1)
                out["tilt"][hit] = math.degrees(math.acos(float(np.clip(normal1[2], -1.0, 1.0))))
                out["attitude"][hit] = np.degrees(np.arccos(np.clip(z_b[hit] @ normal1, -1.0, 1.0)))
                out["offset"][hit] = np.linalg.norm(offset, axis=1)
                touched |= hit
                if touched.all():
                    break
        return ReducedTouchdown(
            out["time"], out["speed"], out["tilt"], out["attitude"], out["offset"]
        )

    def _view_progress(
        self, axes: tuple[np.ndarray, ...], camera: np.ndarray, tag: np.ndarray, height: np.ndarray
    ) -> np.ndarray:
        """How far each draw's descent may go on (the guidance's view gate): 1 while the tag
        sits well inside the image, 0 at ``view_margin`` from its edge, -1 (climb) at the edge;
        1 below ``blind_range_m`` (no gate)."""
        g = self.gains
        if g.view_half_tan <= 0.0:
            return np.ones(len(height))
        # the tag in each camera frame: R_CB R_BW (tag - camera)
        tag_c = _world_to_body(axes, tag[None, :] - camera) @ self._rotation_bc
        z = tag_c[:, 2]
        safe_z = np.where(z > 0.0, z, 1.0)
        extent = (np.maximum(np.abs(tag_c[:, 0]), np.abs(tag_c[:, 1])) + g.tag_half_size_m) / safe_z
        room = g.view_half_tan - extent
        progress = np.where(
            room >= 2.0 * g.view_margin,
            1.0,
            np.clip((room - g.view_margin) / max(g.view_margin, 1e-9), -1.0, 1.0),
        )
        progress = np.where(z > 0.0, progress, 0.0)
        return np.where(height > g.blind_range_m, progress, 1.0)

    def _descent_speed(
        self, height: np.ndarray, progress: np.ndarray, state: dict[str, np.ndarray]
    ) -> np.ndarray:
        """Each draw's descent speed (down, relative to the deck), as
        :meth:`~landing_env.timing.guidance.DeckGuidance.descend` gives it on the timed
        profile: the reference's rate fed forward and its height error corrected, times the
        view gate's progress; a climb at the touchdown speed where the gate is negative, which
        restarts the timed descent from where the draw then is."""
        g = self.gains
        state["progress"] = progress
        if g.descent_profile == "range":
            scheduled = np.clip(g.descent_gain * height, g.touchdown_speed, g.descent_speed)
            speed = progress * scheduled
        else:
            climb = progress < 0.0
            restart = np.isnan(state["start"]) | climb
            state["start"] = np.where(
                restart, np.maximum(height, g.contact_range_m), state["start"]
            )
            state["clock"] = np.where(restart, 0.0, state["clock"])
            reference, _ = timed_descent_references(
                state["clock"],
                state["start"],
                self._duration_s,
                g.touchdown_speed,
                g.contact_range_m,
            )
            _, rate = timed_descent_references(
                state["clock"] + g.descent_lead_s,
                state["start"],
                self._duration_s,
                g.touchdown_speed,
                g.contact_range_m,
            )
            state["clock"] = state["clock"] + self.control_dt_s * np.clip(progress, 0.0, 1.0)
            state["reference"] = reference
            timed = np.clip(
                -rate + g.descent_track_gain * (height - reference), 0.0, g.max_vertical_speed
            )
            speed = np.where(climb, progress * g.touchdown_speed, progress * timed)
            # a climb restarts the timed descent from where the drone then is
            state["start"] = np.where(climb, np.nan, state["start"])
        return np.where((speed < 0.0) & (height >= g.max_search_range_m), 0.0, speed)

    def _angular_velocity(self, deck: DeckTrack, step: int) -> np.ndarray:
        """The plate's angular velocity (world) at ``step`` from its rotations' change."""
        k0, k1 = max(step - 1, 0), min(step + 1, len(deck.times_s) - 1)
        if k1 == k0:
            return np.zeros(3)
        dr = (deck.rotation_wp[k1] - deck.rotation_wp[k0]) / ((k1 - k0) * self.dt_s)
        skew = dr @ deck.rotation_wp[step].T
        return (
            np.array([skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1]])
            / 2.0
        )


def descent_start(env: Any) -> DescentStart:
    """The :class:`DescentStart` of the timing task ``env`` (unwrapped) now: the drone's
    navigation state, its controller's integrators, the guidance's lean and the descent it
    would plan, the air at the drone less the present gust, the airframe's feet."""
    world = env.world
    state = world.drone_state()
    position = np.asarray(state.position_w, dtype=float)
    rotation = np.asarray(state.rotation_wb, dtype=float)
    feet = world.client.getLinkStates(world.drone.body_id, sorted(world.foot_links))
    feet_b = (np.array([f[0] for f in feet], dtype=float) - position) @ rotation
    timing = env.timing
    gain = float(world.gust_gain_at_drone())
    return DescentStart(
        position_w=position,
        velocity_w=np.asarray(state.velocity_w, dtype=float),
        rotation_wb=rotation,
        velocity_integral_w=np.asarray(world.controller.velocity_integral_w, dtype=float),
        wind_w=np.asarray(world.drone.last_wind_w, dtype=float) - gain * world.wind.gust_w,
        lean=np.asarray(env.guidance.lean, dtype=float),
        descent_time_s=float(timing.descent_time_for(env.deck_prediction.plan_contact())),
        feet_b=feet_b,
        foot_radius_m=float(world.foot_radius_m),
        camera_offset_b=np.asarray(world.t_bc, dtype=float),
        camera_rotation_bc=np.asarray(R_BC, dtype=float),
        tracker=copy.deepcopy(env.guidance.tracker),
        rotor_hubs_b=np.asarray(world.drone.params.rotor_positions_b, dtype=float),
        gust_gain=gain,
    )


class ReducedLookahead(DeckForecastTimingPolicy):
    """The onboard look-ahead with its futures flown by :class:`ReducedDescentModel`: the same
    belief, forecast and draws as :class:`~agents.policies.deck_forecast.DeckForecastTimingPolicy`
    (whose settings it takes), every draw of a check in one vectorised flight instead of a
    replay of the simulation each."""

    name = "onboard-look-ahead-reduced"

    def __init__(self, env: Any, *args: Any, **kwargs: Any) -> None:
        super().__init__(env, *args, **kwargs)
        base = self.env
        world = base.world
        self.model = ReducedDescentModel(
            base.guidance.gains,
            world.controller.gains,
            float(world.drone.params.mass),
            np.asarray(world.drone.params.linear_drag_b, dtype=float),
            base.env_dt,
            ground_effect=world.drone.ground_effect_gains,
            ground_effect_reach_m=float(world.drone.params.ground_effect_ray_length),
        )
        #: the latest check's reduced touchdowns (None: no check flown)
        self.last_touchdowns: ReducedTouchdown | None = None

    def drawn_set(self, decision: int) -> DrawSet:
        """This decision's draws (after :meth:`deck_future`), as rows.

        With :attr:`~agents.policies.deck_forecast.OnboardModelConfig.airframe_in_trim` a drawn
        airframe starts in its own trim, as :meth:`model_draw` makes it: the air goes past it
        ``1 / drag_scale`` as fast (the gust shifted by the difference, as much of it as
        reaches the drone), and the controller's thrust model is the drawn rotors' (the
        thrust it commands is the thrust it gets)."""
        rows = [self.drawn_unknowns(decision, k) for k in range(self.draws)]
        gust = np.array([r[1] for r in rows])
        drag_scale = np.array([r[2] for r in rows])
        thrust_scale = np.array([r[3] for r in rows])
        if self.onboard.airframe_in_trim:
            world = self.env.world
            air_w = world.drone_state().velocity_w - np.asarray(world.drone.last_wind_w)
            gain = max(float(world.gust_gain_at_drone()), 1e-9)
            gust = gust + np.outer(1.0 - 1.0 / drag_scale, air_w) / gain
            thrust_scale = np.ones_like(thrust_scale)
        return DrawSet(np.array([r[0] for r in rows]), gust, drag_scale, thrust_scale)

    def deck_track(self, motion: Any) -> DeckTrack:
        """The deck's predicted motion ``motion`` (the forecast) at the model's steps."""
        stewart = self.env.world.stewart
        home_w, _ = stewart.home_pose_w()
        return DeckTrack.from_motion(
            motion, home_w, stewart.rotation_wb, float(self.env.world.time), self.model.horizon_s
        )

    def try_commits(self, decision: int = 0, needed: float = 0.0) -> list[TriedCommit] | None:
        """A commit now, flown by the reduced model in each of ``draws`` futures (all of them:
        ``needed`` is not used, the flight is one); None when there is no deck future."""
        del needed
        self.last_touchdowns = None
        deck_future = self.deck_future(decision)
        if deck_future is None or self._belief is None:
            return None
        try:
            start = descent_start(self.env)
            track = self.deck_track(deck_future)
            draws = self.drawn_set(decision)
        except (ValueError, FloatingPointError):
            return None
        if not (start.finite() and track.finite() and draws.finite()):
            return None  # a state the model cannot start from: no look-ahead
        touchdowns = self.model.fly(start, track, draws)
        self.last_touchdowns = touchdowns
        return self.verdicts(touchdowns)

    def verdicts(self, touchdowns: ReducedTouchdown) -> list[TriedCommit]:
        """Each draw's :class:`TriedCommit`, judged by the environment's touchdown criteria
        and thresholds."""
        thresholds = self.env.config.touchdown
        tries = []
        for k in range(len(touchdowns.time_s)):
            outcome, touchdown = touchdowns.judged(k, thresholds)
            margin = touchdown_margin(touchdown, thresholds)
            success = outcome is Outcome.SUCCESS
            tries.append(
                TriedCommit(
                    lands=success and margin >= self.min_margin - 1e-12,
                    success=success,
                    margin=margin,
                )
            )
        return tries
