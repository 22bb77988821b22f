"""The base Gymnasium environment over the simulated world; tasks override a few hooks."""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from estimation.frames import euler_zyx_from_matrix, euler_zyx_from_rows
from estimation.types import CameraFrame, DeckPoseEstimate, ImuSample, RangeReading
from landing_env.config import DeckLandingConfig, episode_step_limit, load_config
from landing_env.envs.actions import setpoint_from_action
from landing_env.envs.rewards import reward_info, touchdown_terms, zero_terms
from landing_env.errors import PinnedDroneWarning
from landing_env.estimators import EstimatorBank, describe_estimate
from landing_env.physics.controller import VelocitySetpoint
from landing_env.physics.drone_state import DroneState
from landing_env.sensors.imu import mean_reading
from landing_env.touchdown import Outcome, TouchdownMetrics, evaluate_touchdown
from landing_env.world import DeckState, PhysicsReport, World

#: bounds of the deck-pose observation: metres for x, y, z and radians for the angles
POSE_LOW = np.array([-50.0, -50.0, -50.0, -math.pi, -math.pi / 2, -math.pi], dtype=np.float32)


def pose_bounds(arena_max_height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The deck pose's observation bounds: POSE_LOW and its negative, the positions widened to
    20 m beyond the arena's ceiling where that is higher (an approach from 100 m)."""
    low = POSE_LOW.copy()
    low[:3] = -max(float(-POSE_LOW[0]), float(arena_max_height_m) + 20.0)
    return low, -low


#: full-scale range of the IMU (an ICM-20602-class part: ±16 g, ±2000 °/s); a mean reading
#: beyond it is clipped to the range, as the part itself would, and flagged in info
IMU_HIGH = np.array([16 * 9.81] * 3 + [math.radians(2000.0)] * 3, dtype=np.float32)
#: bound of the drone's velocity observation, m/s (beyond any set-point's reach; clipped)
VELOCITY_HIGH = 30.0
#: bounds of the drone's attitude observation (roll, pitch), radians
ATTITUDE_HIGH = np.array([math.pi, math.pi / 2], dtype=np.float32)


def flag_space(n: int) -> spaces.Box:
    """A validity flag observation: 0 or 1 as float32 in a ``Box(0, 1)``, so that the standard
    wrappers (SB3's ``VecNormalize``, Gymnasium's ``FlattenObservation``) take every key."""
    return spaces.Box(0.0, 1.0, shape=(n,), dtype=np.float32)


def flags(values: Any) -> np.ndarray:
    """Validity flags as the observation carries them (float32 0/1)."""
    return np.asarray(values, dtype=bool).astype(np.float32).reshape(-1)


#: the types that never hold a NaN
_NAN_FREE = frozenset({bool, int, str, type(None), np.bool_})


def without_nan(value: Any) -> Any:
    """``info`` without NaN, so that two runs of one seed compare equal (Gymnasium's
    determinism check; NaN != NaN): a float array's NaN entries become 0 (every such array has
    its validity beside it: ``tof_valid``, an estimate's ``valid``), a NaN scalar None."""
    kind = type(value)
    # the common leaves first, by exact type (each call of a step's info is one of these)
    if kind is np.ndarray:
        return _array_without_nan(value)
    if kind is dict:
        # a dict's plain leaves in place, without a call each
        out = {}
        for key, item in value.items():
            item_kind = type(item)
            if item_kind is float:
                out[key] = None if item != item else item
            elif item_kind in _NAN_FREE:
                out[key] = item
            elif item_kind is np.ndarray:
                out[key] = _array_without_nan(item)
            else:
                out[key] = without_nan(item)
        return out
    if kind is float:
        return None if math.isnan(value) else value
    if kind in _NAN_FREE:
        return value
    if isinstance(value, dict):
        return {key: without_nan(item) for key, item in value.items()}
    if isinstance(value, list):
        return [without_nan(item) for item in value]
    if isinstance(value, tuple):
        return tuple(without_nan(item) for item in value)
    if isinstance(value, np.ndarray):
        return _array_without_nan(value)
    if isinstance(value, float | np.floating) and math.isnan(value):
        return None
    return value


def finite_or_nan_to_num(values: np.ndarray) -> np.ndarray:
    """``np.nan_to_num(values, nan=0.0)``, or ``values`` itself (not a copy) when every entry
    is finite: the test costs a tenth of the conversion, and most arrays pass it."""
    if np.isfinite(values).all():
        return values
    return np.nan_to_num(values, nan=0.0)


def _array_without_nan(value: np.ndarray) -> np.ndarray:
    """:func:`without_nan` of an array (``count_nonzero`` is the cheapest test of a mask)."""
    if value.dtype.kind == "f" and np.count_nonzero(np.isnan(value)):
        return np.nan_to_num(value, nan=0.0)
    return value


def imu_sample_rows(samples: Sequence[ImuSample]) -> np.ndarray:
    """``info["imu_samples"]``: one row (timestamp, accel xyz, gyro xyz) per sample, (n, 7).

    Filled column block by column block: unpacking each sample's arrays into a row makes a
    numpy scalar of every value."""
    rows = np.empty((len(samples), 7))
    if samples:
        rows[:, 0] = [s.timestamp for s in samples]
        rows[:, 1:4] = [s.accel for s in samples]
        rows[:, 4:7] = [s.gyro for s in samples]
    return rows


class BoundedObservation:
    """Values as a ``spaces.Dict`` of ``Box`` keys observes them: NaN as 0, clipped to each
    key's bounds, float32.

    All keys in one pass: the values are laid end to end (float64), NaN set to 0, clipped to
    the bounds laid out alike and cast once, and each key gets its slice.  Element by element
    this is ``np.clip(np.nan_to_num(value, nan=0.0), low, high).astype(np.float32)`` of each
    key (an infinity clips to the bound, or stays infinite against an infinite one, either
    way); a value whose size is not its key's goes that way.
    """

    def __init__(self) -> None:
        self._space: spaces.Dict | None = None
        self._layout: tuple[tuple[str, int, int, tuple[int, ...] | None], ...] = ()
        self._low = self._high = np.zeros(0)

    def _lay_out(self, space: spaces.Dict) -> None:
        layout, lows, highs, offset = [], [], [], 0
        for key, box in space.spaces.items():
            size = int(np.prod(box.shape))
            # a key of one axis keeps its slice as it is (None: no reshape needed)
            shape = None if tuple(box.shape) == (size,) else box.shape
            layout.append((key, offset, offset + size, shape))
            lows.append(np.asarray(box.low, dtype=np.float64).reshape(-1))
            highs.append(np.asarray(box.high, dtype=np.float64).reshape(-1))
            offset += size
        self._layout = tuple(layout)
        self._low, self._high = np.concatenate(lows), np.concatenate(highs)
        self._space = space

    def observation(self, values: dict[str, Any], space: spaces.Dict) -> dict[str, np.ndarray]:
        if space is not self._space:
            self._lay_out(space)
        parts = [np.asarray(values[key], dtype=np.float64) for key, *_ in self._layout]
        if any(
            part.size != end - start
            for part, (_, start, end, _) in zip(parts, self._layout, strict=True)
        ):
            return {
                key: np.clip(np.nan_to_num(part, nan=0.0), box.low, box.high).astype(np.float32)
                for part, (key, box) in zip(parts, space.spaces.items(), strict=True)
            }
        flat = np.concatenate(parts, axis=None)
        flat[np.isnan(flat)] = 0.0
        flat = np.clip(flat, self._low, self._high).astype(np.float32)
        return {
            key: flat[start:end] if shape is None else flat[start:end].reshape(shape)
            for key, start, end, shape in self._layout
        }


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


#: slot -> live environment of this process (for distinct config seeds of vector members)
_SLOTS: dict[int, weakref.ref] = {}


def _claim_slot(env: object) -> int:
    slot = 0
    while slot in _SLOTS and _SLOTS[slot]() is not None:
        slot += 1
    _SLOTS[slot] = weakref.ref(env)
    return slot


def _release_slot(env: DeckLandingBaseEnv) -> None:
    slot = getattr(env, "_slot", None)
    if slot is not None and slot in _SLOTS and _SLOTS[slot]() is env:
        del _SLOTS[slot]


def _process_key() -> tuple[int, ...]:
    """A child process's creation index (multiprocessing's ``_identity``); () in the main one."""
    import multiprocessing

    return tuple(getattr(multiprocessing.current_process(), "_identity", ()) or ())


@dataclass
class Sensing:
    """The sensor data and estimates of one control step."""

    frame: CameraFrame
    ranges: RangeReading
    estimates: dict[str, DeckPoseEstimate]
    #: the downward rangefinder (shape (1,), NaN when invalid)
    range_down: RangeReading | None = None


class DeckLandingBaseEnv(gym.Env):
    """A quadrotor over a moving deck; the observation carries the *estimated* deck pose.

    Subclasses define the task: its ``action_space`` and ``step``, through ``_reward``,
    ``_terminated`` and friends.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}

    def __init__(
        self,
        config: str | DeckLandingConfig | None = "default",
        render_mode: str | None = None,
        overrides: dict[str, Any] | None = None,
        **sections: Any,
    ) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            allowed = ", ".join(self.metadata["render_modes"])
            raise ValueError(f"render_mode: {render_mode!r} is not allowed; choose {allowed}")
        self.config = load_config(config, overrides, **sections)
        if self.config.simulation.drone_fixed:
            warnings.warn(
                "simulation.drone_fixed is true: the drone is pinned at its start pose (the "
                "estimators' bench), the action is ignored and this environment cannot land; "
                "set simulation.drone_fixed: false to fly (the registered scenario ids do)",
                PinnedDroneWarning,
                stacklevel=2,
            )
        self._config_seed = self.config.seed
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.config.simulation.env_hz}
        sim = self.config.simulation
        gui = render_mode == "human" or sim.gui
        if render_mode == "human" and not sim.gui and not _has_display():
            # as Gymnasium's own envs on a headless machine: run, show nothing, say so once
            gym.logger.warn(
                "render_mode='human' without a display (DISPLAY/WAYLAND_DISPLAY unset): the "
                "simulation runs headless and nothing is shown; use 'rgb_array' or Xvfb"
            )
            gui = False
        self._slot = _claim_slot(self)
        self.world = World(self.config, gui=gui)
        pose_low, pose_high = pose_bounds(sim.arena_max_height_m)
        self.bank = EstimatorBank(self.config, self.world, (pose_low, pose_high))
        self.max_steps = round(sim.max_episode_s * sim.env_hz)
        self.env_dt = 1.0 / sim.env_hz

        tof_max = float(self.config.tof.max_range)
        self.observation_space = spaces.Dict(
            {
                "deck_pose": spaces.Box(pose_low, pose_high, dtype=np.float32),
                "deck_pose_valid": flag_space(1),
                "deck_pose_predicted": flag_space(1),
                "tof_range": spaces.Box(0.0, tof_max, shape=(4,), dtype=np.float32),
                "tof_valid": flag_space(4),
                "imu": spaces.Box(-IMU_HIGH, IMU_HIGH, dtype=np.float32),
                "range_down": spaces.Box(
                    0.0, float(self.config.rangefinder.max_range), shape=(1,), dtype=np.float32
                ),
                "range_down_valid": flag_space(1),
                "velocity": spaces.Box(-VELOCITY_HIGH, VELOCITY_HIGH, (3,), dtype=np.float32),
                "attitude": spaces.Box(-ATTITUDE_HIGH, ATTITUDE_HIGH, dtype=np.float32),
            }
        )
        if self.config.estimation.observed == "fused":
            # the fused estimate's 1-sigma (x, y, z, roll, pitch, yaw); zeros when invalid
            std_space = spaces.Box(0.0, pose_high, dtype=np.float32)
            self.observation_space = spaces.Dict(
                {**self.observation_space.spaces, "deck_pose_std": std_space}
            )
        self._steps = 0
        self._sensing: Sensing | None = None
        self._report = PhysicsReport()
        self._outcome = Outcome.IN_FLIGHT
        self._touchdown: TouchdownMetrics | None = None
        self._potential = 0.0
        self._reward_terms = zero_terms()
        self._bounded = BoundedObservation()

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed if seed is not None else self._first_seed())
        position, yaw = self._start_pose(options or {})
        self.world.reset(self.np_random, position, yaw)
        self.bank.reset(self.np_random)
        self._steps = 0
        self._outcome = Outcome.IN_FLIGHT
        self._touchdown = None
        self._report = PhysicsReport()
        self._sensing = self._sense()
        self._potential = self._shaping_potential()
        self._reward_terms = zero_terms()
        return self._observation(), self._info()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        assert self._sensing is not None, "call reset() before render()"
        return self.world.camera_image(self._sensing.frame)

    def close(self) -> None:
        _release_slot(self)
        self.world.close()

    def _control_period(self, setpoint: VelocitySetpoint) -> None:
        """One control period of the world under ``setpoint``: step the world, count the
        step, judge the outcome and sense (each task builds its reward and observation)."""
        self._report = self.world.step(setpoint)
        if self.render_mode is not None or self.config.camera.mode == "render":
            # the legs are visual only: move them when someone (or the camera) looks
            self.world.stewart.update_leg_visuals()
        self._steps += 1
        self._outcome = self._outcome_after(self._report, setpoint)
        self._sensing = self._sense()

    # ------------------------------------------------------------------ spec
    @property
    def spec(self) -> EnvSpec | None:  # type: ignore[override]
        """The registration spec, with ``max_episode_steps`` of this env's config where the id
        leaves it open (``DeckLanding-v2``, ``DeckLandingTiming-v0``)."""
        return self.__dict__.get("_spec")

    @spec.setter
    def spec(self, value: EnvSpec | None) -> None:
        if value is not None and value.max_episode_steps is None:
            value = dataclasses.replace(value, max_episode_steps=self.episode_step_limit)
        self.__dict__["_spec"] = value

    @property
    def episode_step_limit(self) -> int:
        """The most steps an episode can take: it truncates at ``simulation.max_episode_s``."""
        return episode_step_limit(self.config)

    # ------------------------------------------------------------------ task hooks
    def _action_to_setpoint(self, action: np.ndarray) -> VelocitySetpoint:
        return setpoint_from_action(action, self.config.action)

    def _start_pose(self, options: dict[str, Any]) -> tuple[np.ndarray, float]:
        start = self.config.start
        rng = self.np_random
        height = float(options.get("height_m", rng.uniform(*start.height_m)))
        if start.min_offset_m > 0.0:
            # uniform over the annulus between the two radii
            low, high = start.min_offset_m**2, start.max_offset_m**2
            radius = math.sqrt(low + (high - low) * rng.uniform())
        else:  # the original draw, so that existing seeded episodes stay the same
            radius = start.max_offset_m * math.sqrt(rng.uniform())
        bearing = rng.uniform(-math.pi, math.pi)
        offset = np.asarray(
            options.get("offset_m", (radius * math.cos(bearing), radius * math.sin(bearing))),
            dtype=float,
        )
        yaw = float(options.get("yaw", math.radians(rng.uniform(-1.0, 1.0) * start.max_yaw_deg)))
        position = self.world.deck_home_w + np.array([offset[0], offset[1], height])
        return position, yaw

    def _outcome_after(
        self, report: PhysicsReport, setpoint: VelocitySetpoint | None = None
    ) -> Outcome:
        if report.forbidden_contact:
            return Outcome.CRASH
        if report.first_contact is not None:
            feet, on_deck, forbidden, _ = self.world.settle(
                self.config.touchdown.settle_time_s, setpoint
            )
            metrics = report.first_contact
            metrics.all_feet_touched = feet == set(self.world.foot_links)
            metrics.on_deck_after_settle = on_deck
            outcome, self._touchdown = evaluate_touchdown(metrics, self.config.touchdown)
            if forbidden:
                self._touchdown.failed_checks += (f"contact during settle: {forbidden}",)
            return outcome
        if self._flipped() or self._left_arena():
            return Outcome.CRASH
        return Outcome.IN_FLIGHT

    def _flipped(self) -> bool:
        rotation = self.world.drone_state().rotation_wb
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(rotation[2, 2])))))
        return tilt > self.config.simulation.flip_tilt_deg

    def _left_arena(self) -> bool:
        sim = self.config.simulation
        offset = self.world.drone_state().position_w - self.world.deck_home_w
        return bool(
            math.hypot(offset[0], offset[1]) > sim.arena_half_extent_m
            or offset[2] > sim.arena_max_height_m
        )

    def _terminated(self) -> bool:
        return self._outcome is not Outcome.IN_FLIGHT

    def _truncated(self) -> bool:
        return self._steps >= self.max_steps

    def _shaping_potential(self) -> float:
        return self._distance_potential(self.world.drone_state(), self.world.deck_state())

    def _distance_potential(self, state: DroneState, deck: DeckState) -> float:
        """Φ of the distance from the drone (``state``) to the tag's centre (``deck``)."""
        r = self.config.reward
        drone = state.position_w
        offset = drone - deck.tag_centre_w
        horizontal = math.hypot(offset[0], offset[1])
        return -r.shaping_weight * (horizontal + r.vertical_weight * abs(offset[2]))

    def _reward(self) -> float:
        r = self.config.reward
        potential = self._shaping_potential()
        terms = {
            "shaping": potential - self._potential,
            "time": -r.time_cost * self.env_dt,
            **touchdown_terms(self._outcome, self._touchdown, r, touchdown_bonus=True),
        }
        self._potential = potential
        self._reward_terms = terms
        return float(sum(terms.values()))

    # ------------------------------------------------------------------ observation and info
    def _first_seed(self) -> int | None:
        """The config's seed applies to the first reset without a seed only, as Gymnasium
        seeds on the first reset.  Each vector worker gets its own seed from it: the first
        live environment of the main process uses the seed as given; another environment
        alive beside it (a ``SyncVectorEnv`` or ``DummyVecEnv`` member) or one in a child
        process (``AsyncVectorEnv``, ``SubprocVecEnv``) uses a seed spawned from it with
        ``SeedSequence`` and its (process, slot) key, so workers never replay one episode."""
        seed, self._config_seed = self._config_seed, None
        if seed is None:
            return None
        key = (*_process_key(), self._slot)
        if not any(key):
            return seed
        return int(np.random.SeedSequence([seed, *key]).generate_state(1, np.uint64)[0] >> 1)

    def _sense(self) -> Sensing:
        frame = self.world.capture()
        ranges = self.world.measure_ranges()
        # before the estimators: the beacon estimator reads it from the world
        range_down = self.world.measure_range_down()
        estimates = self.bank.estimate(frame, ranges, self._report.imu_samples)
        return Sensing(frame, ranges, estimates, range_down)

    def _observation(self) -> dict[str, np.ndarray]:
        assert self._sensing is not None
        estimate = self._sensing.estimates[self.config.estimation.observed]
        pose = np.zeros(6, dtype=np.float32)
        if estimate.valid:
            pose[:] = estimate.as_vector()
        ranges = self._sensing.ranges
        tof = np.where(ranges.valid, finite_or_nan_to_num(ranges.ranges), 0.0)
        samples = self._report.imu_samples
        imu = np.zeros(6, dtype=np.float32)
        if samples:
            imu[:] = mean_reading(samples)
        self._imu_saturated = bool((np.abs(imu) > IMU_HIGH).any())
        imu = np.clip(imu, -IMU_HIGH, IMU_HIGH)
        down = self._sensing.range_down
        assert down is not None
        return {
            "deck_pose": pose,
            "deck_pose_valid": flags([estimate.valid]),
            # bridged by the corner tracker rather than measured (estimation.tracking)
            "deck_pose_predicted": flags([estimate.predicted]),
            "tof_range": tof.astype(np.float32),
            "tof_valid": flags(ranges.valid),
            "imu": imu,
            # the downward rangefinder (rangefinder.*): 0 when invalid (no return in range)
            "range_down": finite_or_nan_to_num(down.ranges).astype(np.float32),
            "range_down_valid": flags(down.valid),
            **self._autopilot_state(),
            **self._pose_std(estimate),
        }

    def _autopilot_state(self) -> dict[str, np.ndarray]:
        """The drone's own state as its autopilot estimates it (PX4's ``vehicle_local_position``
        and ``vehicle_attitude``): the velocity in the heading frame and the roll and pitch.
        The simulated cascade controller flies on the true state, so these are the truth."""
        state = self.world.drone_state()
        yaw = state.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy, vz = state.floats.velocity_w
        velocity_h = np.array([c * vx + s * vy, -s * vx + c * vy, vz], dtype=np.float32)
        roll, pitch, _ = euler_zyx_from_rows(state.floats.rotation_wb)
        return {
            "velocity": np.clip(velocity_h, -VELOCITY_HIGH, VELOCITY_HIGH),
            "attitude": np.clip(
                np.array((roll, pitch), dtype=np.float32), -ATTITUDE_HIGH, ATTITUDE_HIGH
            ),
        }

    def _pose_std(self, estimate: DeckPoseEstimate) -> dict[str, np.ndarray]:
        """``deck_pose_std`` (only with ``estimation.observed: fused``): zeros when invalid."""
        if self.config.estimation.observed != "fused":
            return {}
        std = np.zeros(6, dtype=np.float32)
        if estimate.valid and estimate.covariance is not None:
            std[:] = np.sqrt(np.clip(np.diag(estimate.covariance), 0.0, None))
        return {"deck_pose_std": std}

    def _info(self) -> dict[str, Any]:
        assert self._sensing is not None
        world = self.world
        state = world.drone_state()
        deck = world.deck_state()
        r_cd, t_cd = world.true_deck_pose_c(deck)
        report = self._report
        info: dict[str, Any] = {
            "time_s": world.time,
            "outcome": self._outcome.value,
            "deck_pose_true": np.concatenate([t_cd, euler_zyx_from_matrix(r_cd)]),
            "estimates": {
                name: describe_estimate(est) for name, est in self._sensing.estimates.items()
            },
            "tag_miss_reason": self._sensing.frame.miss_reason,
            "tof_ranges": self._sensing.ranges.ranges.copy(),
            "tof_valid": self._sensing.ranges.valid.copy(),
            "range_down": float(self._sensing.range_down.ranges[0])
            if self._sensing.range_down is not None
            else float("nan"),
            "range_down_valid": bool(
                self._sensing.range_down is not None and self._sensing.range_down.valid[0]
            ),
            "drone": {
                "position_w": state.position_w.copy(),
                "velocity_w": state.velocity_w.copy(),
                "euler_w": np.array(euler_zyx_from_rows(state.floats.rotation_wb)),
                "angular_velocity_b": state.angular_velocity_b.copy(),
                "rotor_speeds": np.asarray(world.drone.rotor_speeds, dtype=float).copy(),
            },
            "deck": {
                "position_w": deck.position_w.copy(),
                "euler_w": euler_zyx_from_matrix(deck.rotation_wp),
                "velocity_w": deck.velocity_w.copy(),
            },
            "imu_samples": imu_sample_rows(report.imu_samples),
            "stewart_clamped": report.stewart_clamped,
            "motor_saturated": report.motor_saturated,
            "action_clipped": getattr(self, "_action_clipped", False),
            "imu_saturated": getattr(self, "_imu_saturated", False),
            # read by SB3's EvalCallback for its success rate (a task may judge it further)
            "is_success": self._outcome is Outcome.SUCCESS,
            # the step's reward, term by term (they sum to it)
            **reward_info(self._reward_terms),
        }
        if report.forbidden_contact:
            info["crash_contact"] = report.forbidden_contact
        if self._touchdown is not None:
            info["touchdown"] = self._touchdown.as_dict()
        return without_nan(info)
