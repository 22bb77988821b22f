"""``svgs-routine``: the SVGS high-altitude landing routine (SVGS paper Sec. 2.5.4, Alg. 2–6).

A state machine on ``DeckLanding-v2`` that reads only the observation (the estimated deck
pose, the ToF ranges, the downward rangefinder and the IMU), never ``info``:

* ``scan`` (Algorithm 2): fly an expanding-square lawn-mower pattern around where the scan
  began until the landmark is found (a valid, measured estimate); each square that ends
  without it starts a larger one.
* ``align`` (Algorithm 3): centre over the landmark at the current height until aligned for
  ``align_hold_s``; the tolerance grows with the height.
* ``descend`` (Algorithm 6): descend while centring; a drift beyond ``misaligned_factor``
  times the tolerance pauses the descent and goes back to ``align``.
* ``relocate_xy`` / ``relocate_xyz`` (Algorithm 4): after ``lost_sight_s`` without an
  estimate, go back to the last position with a trusted estimate, horizontally first (at the
  current height), then in 3D; still nothing there: ``scan`` again from that position.
* ``hold`` / ``land``: the timing task's final approach (its guidance holds at its hold height
  with its deck-motion history): the trained timing model ``agents/models/timing_dqn.zip``
  chooses when to commit where it is installed (one decision per ``steps_per_decision``
  periods, forced at ``wait_limit_s``), else the quiescent heuristic
  (:func:`agents.policies.calm_window.predict_calm`); ``land`` descends to touchdown.
  ``policy.timing_source`` says which.

The SVGS offset manoeuvre (Algorithm 5) is not flown: the tag is the landing spot.

Position without truth: the routine dead-reckons its own position in the *local frame* L (the
heading frame at the start: x forward, y left, z up) from the velocity set-points it sends
(through a first-order lag standing for the velocity loop) and the yaw integrated from the
IMU's rate; heights come from the ToF, the deck estimate or the rangefinder.  ``state`` and
``reason`` say what it is doing and why (for logging).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from agents.common.cards import observation_signature
from agents.policies.base import Policy
from agents.policies.calm_window import CalmConfig, predict_calm
from agents.policies.timing import SHIPPED_TIMING_MODEL, TrainedTimingPolicy
from estimation.frames import R_BC, levelled_deck_pose
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.anticipation.deck_history import DeckMotionHistory
from landing_env.config import ActionConfig
from landing_env.envs.actions import action_from_setpoint
from landing_env.errors import ConfigError
from landing_env.guidance_gains import GuidanceGains
from landing_env.physics.controller import VelocitySetpoint
from landing_env.physics.quadrotor_params import GRAVITY
from landing_env.timing.guidance import DeckGuidance
from landing_env.timing.layout import TimingObservationLayout
from landing_env.timing_config import TimingConfig


class RoutineState(str, Enum):
    """States of the routine, named after the SVGS paper's manoeuvres."""

    SCAN = "scan"
    ALIGN = "align"
    DESCEND = "descend"
    RELOCATE_XY = "relocate_xy"
    RELOCATE_XYZ = "relocate_xyz"
    HOLD = "hold"
    LAND = "land"


# ------------------------------------------------------------------------------ search pattern
def lawnmower_square(
    centre: tuple[float, float], side_m: float, lane_spacing_m: float
) -> list[tuple[float, float]]:
    """Waypoints (forward, left) of a boustrophedon over a square centred on ``centre``.

    Lanes run along the left axis, ``lane_spacing_m`` apart in the forward axis, alternating
    direction (Algorithm 2's ``i mod 2`` rows); the square's edges are lanes.
    """
    if side_m <= 0.0 or lane_spacing_m <= 0.0:
        raise ValueError("side_m and lane_spacing_m must be positive")
    half = 0.5 * side_m
    lanes = max(1, math.ceil(side_m / lane_spacing_m))
    forwards = np.linspace(-half, half, lanes + 1)
    points: list[tuple[float, float]] = []
    for i, f in enumerate(forwards):
        ends = (-half, half) if i % 2 == 0 else (half, -half)
        points.extend((centre[0] + f, centre[1] + left) for left in ends)
    return points


# ------------------------------------------------------------------------------ dead reckoning
class DeadReckoning:
    """The drone's position in the local frame L from its own set-points and the IMU's yaw rate.

    The velocity loop is modelled as a first-order lag of ``time_constant_s`` from the
    set-point (heading frame) to the velocity; the heading frame turns by the yaw integrated
    from the gyro's z rate.  Drift grows with wind gusts the controller has not yet rejected.
    """

    def __init__(self, dt: float, time_constant_s: float) -> None:
        self.dt = dt
        self.time_constant_s = time_constant_s
        self.reset()

    def reset(self) -> None:
        self.position = np.zeros(3)
        self.velocity = np.zeros(3)
        self.yaw = 0.0

    def heading_to_local(self, vector_h: np.ndarray) -> np.ndarray:
        """A heading-frame vector (forward, left, up) in L."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        x, y, z = (float(v) for v in vector_h)
        return np.array([c * x - s * y, s * x + c * y, z])

    def local_to_heading(self, vector_l: np.ndarray) -> np.ndarray:
        """An L vector in the heading frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        x, y, z = (float(v) for v in vector_l)
        return np.array([c * x + s * y, -s * x + c * y, z])

    def advance(self, setpoint: VelocitySetpoint, yaw: float) -> None:
        """One control period under ``setpoint`` (heading frame) at the estimated ``yaw``."""
        self.yaw = yaw
        target = self.heading_to_local(setpoint.velocity_h)
        alpha = 1.0 - math.exp(-self.dt / self.time_constant_s)
        self.velocity = self.velocity + alpha * (target - self.velocity)
        self.position = self.position + self.velocity * self.dt


# ------------------------------------------------------------------------------ attitude
class AttitudeFilter:
    """Roll and pitch from the observation's IMU: a Mahony-style complementary filter.

    The gyro's mean rate over each step is integrated; the specific force (which points up
    in hover and steady flight) pulls the estimated up-direction towards it with gain
    ``gain`` (1/s), so gyro drift and the start error decay.  A flight controller gives its
    companion computer this attitude; here it is rebuilt from the observation alone.
    """

    def __init__(self, dt: float, gain: float = 0.2) -> None:
        self.dt = dt
        self.gain = gain
        self.reset()

    def reset(self) -> None:
        self.rotation = Rotation.identity()

    def update(self, imu: np.ndarray) -> None:
        """One step with the mean specific force (3, m/s²) and rate (3, rad/s) in B."""
        force = np.asarray(imu[:3], dtype=float)
        rate = np.asarray(imu[3:6], dtype=float).copy()
        norm = float(np.linalg.norm(force))
        # only near 1 g does the specific force say where up is
        if 0.7 * GRAVITY < norm < 1.3 * GRAVITY:
            up_estimated = self.rotation.inv().apply([0.0, 0.0, 1.0])
            rate += self.gain * np.cross(force / norm, up_estimated)
        self.rotation = self.rotation * Rotation.from_rotvec(rate * self.dt)

    @property
    def yaw(self) -> float:
        return float(self.rotation.as_euler("ZYX")[0])

    def level_from_body(self) -> np.ndarray:
        """R_HB: body frame to the levelled heading frame (roll and pitch removed, yaw kept)."""
        _, pitch, roll = self.rotation.as_euler("ZYX")
        return Rotation.from_euler("ZYX", [0.0, pitch, roll]).as_matrix()


def levelled_offset(deck_pose: np.ndarray, r_hb: np.ndarray) -> tuple[float, float, float]:
    """(forward, left, height) of the deck-pose origin from the camera in the levelled heading
    frame: the camera-frame position through R_BC and the attitude (at 20 m a 1° tilt would
    otherwise look like a 0.35 m offset, and the centring loop would chase its own tilt)."""
    p_h = r_hb @ (R_BC @ np.asarray(deck_pose[:3], dtype=float))
    return float(p_h[0]), float(p_h[1]), float(-p_h[2])


class ApproachStateMachine(Policy):
    """A high-approach policy as a state machine on the levelled estimate (the SVGS routine and
    the beacon baseline): its state, the reason of the last change, every change as (time,
    state, reason) in ``transitions`` (which the approach evaluation counts) and the time in
    the state."""

    #: the commanded landing point, x and y in the deck frame D, metres: the landing point
    #: itself (the paper's final offset off the beacon is not flown)
    landing_point_d: tuple[float, float] = (0.0, 0.0)

    def __init__(self, action: ActionConfig | None, config: Any, dt: float) -> None:
        self.action = action or ActionConfig()
        self.config = config
        self.dt = dt
        self.attitude = AttitudeFilter(dt, config.attitude_gain)

    def _start(self, state: Enum) -> None:
        """Back to ``state`` at time 0 with no history (the start of :meth:`reset`)."""
        self.state = state
        self.reason = "start"
        self.attitude.reset()
        self.transitions: list[tuple[float, str, str]] = []
        self.time_s = 0.0
        self._unseen_s = 0.0
        self._state_s = 0.0

    def _enter(self, state: Any, reason: str) -> None:
        if state is not self.state:
            self.transitions.append((self.time_s, state.value, reason))
        self.state, self.reason, self._state_s = state, reason, 0.0

    def _act(self, setpoint: VelocitySetpoint) -> np.ndarray:
        """The step's action, the clocks moved on by one step."""
        self.time_s += self.dt
        self._state_s += self.dt
        return action_from_setpoint(setpoint, self.action)


# ------------------------------------------------------------------------------ configuration
@dataclass
class RoutineConfig:
    """Settings of the SVGS routine (heights are camera heights above the surface below)."""

    #: first scan square's side, metres, and its growth per square (Algorithm 2's squareSize)
    scan_first_side_m: float = limited(6.0, POSITIVE)
    scan_growth_m: float = limited(6.0, NON_NEGATIVE)
    #: lane spacing of the lawn-mower, metres (under the camera's footprint at 20 m, 22 m)
    scan_lane_spacing_m: float = limited(3.0, POSITIVE)
    #: squares flown before the scan gives up and lands in place
    scan_squares: int = limited(4, Limit(1, 50))
    #: scan speed, m/s (low: the paper scans slowly so that a sighting is not overflown)
    scan_speed: float = limited(1.0, POSITIVE)
    #: a waypoint counts as reached within this, metres
    waypoint_tolerance_m: float = limited(0.4, POSITIVE)
    #: aligned when the horizontal error is below ``align_tolerance_m`` +
    #: ``align_tolerance_per_m`` * height (wider high up, where the estimate is coarser)
    align_tolerance_m: float = limited(0.1, NON_NEGATIVE)
    align_tolerance_per_m: float = limited(0.06, NON_NEGATIVE)
    #: aligned for this long before the descent (starts), seconds
    align_hold_s: float = limited(0.5, NON_NEGATIVE)
    #: during the descent, an error beyond this times the tolerance pauses it (back to align)
    misaligned_factor: float = limited(2.0, Limit(1.0))
    #: descent speed = descent_gain * (height - hold height), within [min, max], m/s
    descent_gain: float = limited(0.5, POSITIVE)
    descent_min_speed: float = limited(0.3, POSITIVE)
    descent_max_speed: float = limited(1.0, POSITIVE)
    #: sight counts as lost after this long without a valid estimate, seconds (covers the
    #: short dropouts of an intermittent vision link)
    lost_sight_s: float = limited(0.6, NON_NEGATIVE)
    #: consecutive valid measured estimates that count as having the landmark (target lock)
    lock_frames: int = limited(2, Limit(1, 100))
    #: relocation speed, m/s, reach tolerance, metres, and the time each leg may take, s
    relocate_speed: float = limited(1.0, POSITIVE)
    relocate_tolerance_m: float = limited(0.3, POSITIVE)
    relocate_leg_s: float = limited(8.0, NON_NEGATIVE)
    #: the relocation is not invoked below this height (Algorithm 4's U_min), metres
    relocate_min_height_m: float = limited(1.0, NON_NEGATIVE)
    #: velocity-loop lag of the dead reckoning, seconds
    dead_reckoning_lag_s: float = limited(0.35, POSITIVE)
    #: pull of the accelerometer on the attitude filter, 1/s: low, because a manoeuvre's
    #: acceleration tilts the apparent up (0.6 let a 20 m hover orbit the landmark), high
    #: enough that the gyro bias (~0.002 rad/s) leaves under a degree
    attitude_gain: float = limited(0.2, POSITIVE)
    #: use the trained timing model when it is installed (else the quiescent heuristic)
    use_timing_model: bool = True
    timing_model_path: str = ""
    #: the final approach: the timing task's settings (hold height, history, decisions)
    timing: TimingConfig = field(default_factory=TimingConfig)
    #: the quiescent heuristic's calm prediction (without a timing model)
    calm: CalmConfig = field(default_factory=CalmConfig)
    guidance: GuidanceGains = field(default_factory=GuidanceGains)

    def __post_init__(self) -> None:
        require_limits(self)
        if self.descent_min_speed > self.descent_max_speed:
            raise ConfigError(
                "descent_min_speed",
                f"{self.descent_min_speed} must not exceed descent_max_speed = "
                f"{self.descent_max_speed}",
            )


def _load_timing_model(config: RoutineConfig) -> TrainedTimingPolicy | None:
    if not config.use_timing_model:
        return None
    path = Path(config.timing_model_path) if config.timing_model_path else SHIPPED_TIMING_MODEL
    if not path.is_file():
        return None
    return TrainedTimingPolicy(path)


# ------------------------------------------------------------------------------ the routine
class SvgsRoutinePolicy(ApproachStateMachine):
    """The SVGS routine as a ``DeckLanding-v2`` policy (see the module docstring)."""

    name = "svgs-routine"

    def __init__(
        self,
        action: ActionConfig | None = None,
        config: RoutineConfig | None = None,
        dt: float = 0.05,
        timing_model: TrainedTimingPolicy | str | None = "auto",
    ) -> None:
        super().__init__(action, config or RoutineConfig(), dt)
        c = self.config
        self.guidance = DeckGuidance(c.guidance, dt)
        t = c.timing
        n_history = max(1, round(t.history_s / dt))
        self.history = DeckMotionHistory(n_history, max(2, round(t.rate_window_s / dt)), dt)
        self.layout = TimingObservationLayout(n_history, t.hold_height_m)
        self.timing_model = _load_timing_model(c) if timing_model == "auto" else timing_model
        if isinstance(self.timing_model, TrainedTimingPolicy):
            self.timing_model.check_observation(observation_signature(t, 1.0 / dt))
        #: what chooses the moment of the final descent
        self.timing_source = self.timing_model.name if self.timing_model else "quiescent"
        self.odometry = DeadReckoning(dt, c.dead_reckoning_lag_s)
        self.reset()

    # -------------------------------------------------------------- bookkeeping
    def reset(self) -> None:
        self._start(RoutineState.SCAN)
        self.guidance.reset()
        self.history.reset()
        self.odometry.reset()
        self._offset: tuple[float, float, float] | None = None
        self._lock_count = 0
        self._aligned_s = 0.0
        self._hold_s = 0.0
        self._waited_s = 0.0
        self._decision_countdown = 0
        self._last_height = math.nan
        self._height_at = 0.0
        #: local position (L) of the drone at the last trusted estimate (Algorithm 4's
        #: TrustedPose), None before the first
        self.trusted_position: np.ndarray | None = None
        self._scan: list[tuple[float, float]] = []
        self._scan_square = 0
        self._scan_centre = (0.0, 0.0)
        self._scan_height: float | None = None
        self._goal: np.ndarray | None = None

    def _enter(self, state: RoutineState, reason: str) -> None:
        super()._enter(state, reason)
        self._aligned_s = 0.0
        if state is RoutineState.SCAN:
            self._start_scan()
        if state is RoutineState.HOLD:
            self._hold_s = self._waited_s = 0.0
            self._decision_countdown = 0

    # -------------------------------------------------------------- sensing helpers
    def height_m(self, observation: dict[str, np.ndarray]) -> float:
        """Camera height above the surface below: ToF (all valid), the deck estimate, the
        rangefinder, or the last known height moved by the dead reckoning."""
        height = self.guidance.range_m(observation)
        if not math.isfinite(height) and "range_down_valid" in observation:
            if observation["range_down_valid"][0]:
                height = float(observation["range_down"][0])
        if math.isfinite(height):
            self._last_height = height
            self._height_at = float(self.odometry.position[2])
            return height
        if math.isfinite(self._last_height):
            return self._last_height + float(self.odometry.position[2]) - self._height_at
        return math.nan

    def _tolerance(self, height: float) -> float:
        c = self.config
        return c.align_tolerance_m + c.align_tolerance_per_m * max(height, 0.0)

    # -------------------------------------------------------------- the step
    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        c = self.config
        if "imu" in observation:
            self.attitude.update(observation["imu"])
        seen = bool(observation["deck_pose_valid"][0])
        self._offset = (
            levelled_offset(observation["deck_pose"], self.attitude.level_from_body())
            if seen
            else None
        )
        measured = seen and not bool(observation.get("deck_pose_predicted", [0])[0])
        self._unseen_s = 0.0 if seen else self._unseen_s + self.dt
        self._lock_count = self._lock_count + 1 if measured else 0
        locked = self._lock_count >= c.lock_frames
        # the timing task's history holds the deck pose as a level camera sees it
        self.history.push(
            None
            if not seen
            else levelled_deck_pose(observation["deck_pose"], self.attitude.level_from_body())
            if c.timing.level_history
            else observation["deck_pose"].astype(float)
        )
        height = self.height_m(observation)
        if measured:
            self.trusted_position = self.odometry.position.copy()
        self._transition(observation, seen, locked, height)
        setpoint = self._command(observation, seen, height)
        self.odometry.advance(setpoint, self.attitude.yaw)
        return self._act(setpoint)

    def _transition(
        self, observation: dict[str, np.ndarray], seen: bool, locked: bool, height: float
    ) -> None:
        c = self.config
        s = self.state
        hold_height = c.timing.hold_height_m
        lost = self._unseen_s > c.lost_sight_s
        if s is RoutineState.SCAN:
            if locked:
                self._enter(RoutineState.ALIGN, "landmark found")
            return
        if s in (RoutineState.RELOCATE_XY, RoutineState.RELOCATE_XYZ):
            if locked:
                self._enter(RoutineState.ALIGN, "sight recovered during relocation")
            elif self._goal_reached() or self._state_s > c.relocate_leg_s:
                if s is RoutineState.RELOCATE_XY:
                    self._enter(RoutineState.RELOCATE_XYZ, "not recovered at the trusted xy")
                else:
                    self._enter(RoutineState.SCAN, "not recovered at the trusted pose")
            return
        if s is RoutineState.LAND:
            return  # committed: DeckGuidance.descend goes on blind near the deck
        if lost:
            if self.trusted_position is not None and (
                not math.isfinite(height)
                or height >= c.relocate_min_height_m
                or s is RoutineState.HOLD
            ):
                self._enter(RoutineState.RELOCATE_XY, "sight lost")
            elif self.trusted_position is None:
                self._enter(RoutineState.SCAN, "sight lost without a trusted pose")
            return
        if not seen:
            return  # a short gap: hold still (see _command) until sight is lost or back
        assert self._offset is not None
        offset = math.hypot(self._offset[0], self._offset[1])
        tolerance = self._tolerance(height)
        if s is RoutineState.ALIGN:
            self._aligned_s = self._aligned_s + self.dt if offset < tolerance else 0.0
            if self._aligned_s >= c.align_hold_s:
                if height <= hold_height + 0.1:
                    self._enter(RoutineState.HOLD, "aligned at the hold height")
                else:
                    self._enter(RoutineState.DESCEND, "aligned")
        elif s is RoutineState.DESCEND:
            if offset > c.misaligned_factor * tolerance:
                self._enter(RoutineState.ALIGN, "misaligned: descent paused")
            elif height <= hold_height + 0.05:
                self._enter(RoutineState.HOLD, "at the hold height")
        elif s is RoutineState.HOLD:
            self._hold_s += self.dt
            if self._commit(observation):
                self._enter(RoutineState.LAND, f"committed by {self.timing_source}")

    def _commit(self, observation: dict[str, np.ndarray]) -> bool:
        """The timing decision (after a history's length at the hold height)."""
        t = self.config.timing
        if self._hold_s < t.history_s:
            return False
        self._waited_s += self.dt
        if self._waited_s >= t.wait_limit_s:
            return True
        if self.timing_model is None:
            return predict_calm(self.history.rows(), self.dt, self.config.calm).calm
        # one decision per steps_per_decision periods, as the timing task decides
        self._decision_countdown -= 1
        if self._decision_countdown > 0:
            return False
        self._decision_countdown = t.steps_per_decision
        flat, _ = self.layout.encode(
            self.history.rows(),
            observation["tof_range"].astype(float),
            observation["tof_valid"].astype(bool),
            min(self._waited_s / t.wait_limit_s, 1.0),
        )
        return self.timing_model.act(flat) == 1

    # -------------------------------------------------------------- commands
    def _command(
        self, observation: dict[str, np.ndarray], seen: bool, height: float
    ) -> VelocitySetpoint:
        c = self.config
        s = self.state
        g = self.guidance
        hold_height = c.timing.hold_height_m
        if s is RoutineState.SCAN:
            return self._scan_command(height)
        if s is RoutineState.RELOCATE_XY:
            goal = self.trusted_position
            assert goal is not None
            self._goal = np.array([goal[0], goal[1], self.odometry.position[2]])
            return self._goto(self._goal, c.relocate_speed)
        if s is RoutineState.RELOCATE_XYZ:
            assert self.trusted_position is not None
            self._goal = self.trusted_position.copy()
            return self._goto(self._goal, c.relocate_speed)
        if s is RoutineState.LAND:
            return g.descend(observation)
        if s is RoutineState.HOLD:
            return g.hold(observation, hold_height)
        if not seen:
            return VelocitySetpoint(np.zeros(3), 0.0)
        # align and descend: centre over the landmark (and turn to its yaw)
        assert self._offset is not None
        gains = c.guidance
        velocity = gains.k_xy * np.array(self._offset[:2])
        speed = float(np.linalg.norm(velocity))
        if speed > gains.max_horizontal_speed:
            velocity *= gains.max_horizontal_speed / speed
        vx, vy = (float(v) for v in velocity)
        yaw_rate = -gains.k_yaw * float(observation["deck_pose"][5])
        vz = 0.0
        if s is RoutineState.DESCEND and math.isfinite(height):
            speed = c.descent_gain * (height - hold_height)
            vz = -float(np.clip(speed, c.descent_min_speed, c.descent_max_speed))
        return VelocitySetpoint(np.array([vx, vy, vz]), yaw_rate)

    def _goto(self, goal_l: np.ndarray, speed: float) -> VelocitySetpoint:
        """Straight towards ``goal_l`` (L) at up to ``speed``, slowing within a metre."""
        delta = goal_l - self.odometry.position
        distance = float(np.linalg.norm(delta))
        if distance < 1e-6:
            return VelocitySetpoint(np.zeros(3), 0.0)
        velocity_l = delta / distance * min(speed, distance)
        velocity_h = self.odometry.local_to_heading(velocity_l)
        velocity_h[2] = float(
            np.clip(velocity_h[2], -self.action.max_vertical_speed, self.action.max_vertical_speed)
        )
        return VelocitySetpoint(velocity_h, 0.0)

    def _goal_reached(self) -> bool:
        if self._goal is None:
            return False
        delta = self._goal - self.odometry.position
        return float(np.linalg.norm(delta)) < self.config.relocate_tolerance_m

    # -------------------------------------------------------------- scan (Algorithm 2)
    def _start_scan(self) -> None:
        position = self.odometry.position
        self._scan_centre = (float(position[0]), float(position[1]))
        self._scan_height = float(position[2])
        self._scan_square = 0
        self._load_square()

    def _load_square(self) -> None:
        c = self.config
        side = c.scan_first_side_m + self._scan_square * c.scan_growth_m
        self._scan = lawnmower_square(self._scan_centre, side, c.scan_lane_spacing_m)

    def _scan_command(self, height: float) -> VelocitySetpoint:
        c = self.config
        position = self.odometry.position
        while self._scan:
            wx, wy = self._scan[0]
            if math.hypot(wx - position[0], wy - position[1]) > c.waypoint_tolerance_m:
                break
            self._scan.pop(0)
        if not self._scan:
            self._scan_square += 1
            if self._scan_square >= c.scan_squares:
                # SVGS's COTS fallback: after the last search, land in place
                self.reason = "scan exhausted: descending in place"
                return VelocitySetpoint(np.array([0.0, 0.0, -c.descent_min_speed]), 0.0)
            self._load_square()
        wx, wy = self._scan[0]
        z = self._scan_height if self._scan_height is not None else float(position[2])
        return self._goto(np.array([wx, wy, z]), c.scan_speed)


def make_svgs_routine(env: Any, config: RoutineConfig | None = None) -> SvgsRoutinePolicy:
    """The routine for a ``DeckLanding-v2`` environment (its action scaling and step)."""
    return SvgsRoutinePolicy(env.unwrapped.config.action, config, dt=env.unwrapped.env_dt)


def build_svgs_routine(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """The registry's builder: commits through the shipped timing model or ``model_path``'s."""
    return make_svgs_routine(env, RoutineConfig(timing_model_path=model_path or ""))
