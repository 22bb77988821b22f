"""``DeckLanding-v2``: fly from a hover above the moving deck to a touchdown on it, and choose
the moment to land."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from estimation.frames import camera_to_heading_xy, euler_zyx_from_matrix, tilt_deg
from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.envs.actions import action_fields, validate_action
from landing_env.envs.base import (
    ATTITUDE_HIGH,
    VELOCITY_HIGH,
    DeckLandingBaseEnv,
    flag_space,
    pose_bounds,
)
from landing_env.envs.rewards import touchdown_terms, zero_terms
from landing_env.timing.committed_descent import CommittedDescent
from landing_env.touchdown import Outcome

#: the observation key only a critic may read (``gym.make(id, privileged=True)``)
PRIVILEGED_KEY = "privileged"
#: the true deck tilt in the privileged key is this far ahead, seconds
PRIVILEGED_LOOKAHEAD_S = 1.0
#: the age of the last valid deck estimate is observed up to this, seconds
DECK_AGE_MAX_S = 10.0
#: bound of the deck's angular rates in the privileged key, rad/s
DECK_RATE_HIGH = 10.0
_X, _Y, _Z, _ROLL, _PITCH, _VALID = (
    HISTORY_FEATURES.index(n) for n in ("x", "y", "z", "roll", "pitch", "valid")
)


def _heading(vector_w: np.ndarray, yaw: float) -> np.ndarray:
    """A world-frame vector in the heading frame (the world turned by the drone's yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    x, y, z = (float(v) for v in vector_w)
    return np.array([c * x + s * y, -s * x + c * y, z])


class DeckLandingEnv(CommittedDescent, DeckLandingBaseEnv):
    """Land a quadrotor on a moving deck: velocity set-points fly the approach and the hold, a
    ``land`` trigger commits to the final descent.

    .. rubric:: Description

    A quadrotor starts in a hover above a moving deck: a 6-DOF Stewart platform (the papers'
    bench, sea states 3-5 scaled into its workspace) or a 30 m vessel's helideck at sea
    (``deck_mount: ship``).  A downward camera sees an AprilTag on the deck and four
    time-of-flight (ToF) range sensors on the arms measure it; a camera+ToF estimator
    (``estimation.observed``: IHRCF in ``configs/default.yaml``; CRHF, ATDA, ``tight``,
    ``fused`` or ``truth``) turns them into the deck pose, and that estimate, not the ground
    truth, is what the agent observes.  Physics run at 240 Hz; one ``step`` is one control
    period of 50 ms (20 Hz, ``simulation.env_hz``), 12 physics sub-steps in which a PX4-style
    cascade controller (velocity, attitude, body rates, motor mixing) tracks the action,
    except a step that lands: it flies the timing task's descent
    (``DeckLandingTiming-v0``: the ``timing`` settings' timed descent, contact window and
    wave-off, by :class:`~landing_env.timing.committed_descent.CommittedDescent`) to touchdown
    inside the step.  The agent decides *how* to reach the hold and *when* to land, the
    split of the published landers (a land trigger obeyed near the platform, the descent
    then flown by the autopilot).

    .. rubric:: Action space

    ``Box(-1, 1, (5,), float32)``: ``(vx, vy, vz, yaw_rate, land)``.  The first four are
    velocity set-points in the heading frame (the world frame turned by the drone's yaw: x
    forward, y left, z up), scaled by ``action.max_horizontal_speed`` (1.5 m/s),
    ``action.max_vertical_speed`` (1.0 m/s) and ``action.max_yaw_rate_deg`` (60 °/s).

    ``land`` above ``action.land_threshold`` (0.5) commits to the final descent, obeyed only
    **in the hold band**: the tag seen, the drone centred over it within the guidance's
    alignment tolerance (``timing.guidance.align_tolerance_m`` + ``align_tolerance_per_m``
    per metre of height: 0.08 m + 0.08 m/m by default) and the camera's height over the
    deck (the ToF mean, else the tag's range) within ``action.land_band_m`` (0.2 m) of
    ``timing.hold_height_m`` (0.7 m on the bench: 0.5-0.9 m; 2.0 m over a ship deck).
    Outside the band the trigger is ignored (``info["land_refused"]``) and the set-point is
    flown.  In the band the step runs the descent; a chosen descent waves off (climbs back
    to the hold, and the episode goes on) where ``timing.wave_off_tilt_deg`` asks for it.

    **Forced commit**: every control period spent in the band counts (``info["band_s"]``,
    never reset within an episode); once it reaches ``timing.wait_limit_s`` (15 s) the next
    period in the band descends without a wave-off, as the timing task forces its commit.
    Holding in the band is therefore never an optimum, and holding outside it pays the time
    cost (below) without ever landing.

    ``action.land_trigger: false`` keeps the pure velocity task: ``Box(4)``, no commit, no
    forced descent.  An action outside [-1, 1] is clipped and flagged in
    ``info["action_clipped"]``; one that is not a real, finite array of the space's shape is
    refused with a ``ValueError``.  The scripted policies (``align-descend``) send ``land``
    = -1 and fly their own descent.

    .. rubric:: Observation space

    A ``Dict``; every key is a float32 ``Box`` (the flags are 0 or 1), so SB3's
    ``MultiInputPolicy`` and ``VecNormalize`` and Gymnasium's ``FlattenObservation`` take it
    with their default arguments, and every value lies inside its bounds (clipped to them).
    What is observed is the estimate, never the truth:

    .. list-table::
       :header-rows: 1
       :widths: 18 14 46 22

       * - key
         - shape, bounds
         - meaning
         - frame, unit
       * - ``deck_position``
         - (3,) ±max(50, ceiling + 20)
         - the deck (tag) centre relative to the camera, from the last valid estimate,
           levelled by the drone's attitude (``timing.level_history``); z is negative (the
           deck below); zeros before the first valid estimate
         - heading frame H, levelled; m
       * - ``deck_velocity``
         - (3,) ±30
         - its rate: the least-squares slope over ``timing.rate_window_s`` (0.5 s) of the
           valid estimates, from the last valid one
         - heading frame H; m/s
       * - ``deck_tilt``
         - (2,) ±(π, π/2)
         - the deck's roll and pitch relative to gravity, from the last valid estimate
         - rad
       * - ``deck_age``
         - (1,) [0, 10]
         - seconds since that estimate (0 while the tag is seen); 10 before any
         - s
       * - ``deck_seen``
         - (1,) {0, 1}
         - 1 once a valid estimate has been had this episode
         -
       * - ``prediction``
         - (n + 2,) [0, 1]
         - what ``timing.observation: prediction`` computes
           (:meth:`~landing_env.anticipation.onboard_tilt_prediction.DeckPrediction.prediction_values`):
           the scenario's deck-tilt predictor's chance of a deck within the touchdown limit
           at each of the n contact times of ``timing.contact_times_s`` after a commit now,
           the value of waiting on over the band time left, and the prediction's validity;
           zeros where ``timing.observation`` is not ``prediction`` (the ship ids: no
           predictor yet)
         -
       * - ``band_time``
         - (1,) [0, 1]
         - the band time used, as a fraction of ``timing.wait_limit_s`` (1 - the time left
           before the forced commit)
         -
       * - ``in_band``
         - (1,) {0, 1}
         - 1 when a ``land`` now would be obeyed
         -
       * - ``previous_action``
         - (5,) [-1, 1]
         - the last action, clipped (zeros after a reset)
         -
       * - ``deck_pose``
         - (6,) float32
         - the deck (tag) pose as estimated: x, y, z, roll, pitch, yaw; zeros when invalid
           (what the scripted guidance reads)
         - camera frame C; m, rad (ZYX)
       * - ``deck_pose_valid``
         - (1,) {0, 1}
         - 1 when the estimate is valid (not: no tag, out of view, degenerate)
         -
       * - ``deck_pose_predicted``
         - (1,) {0, 1}
         - 1 when the corner tracker bridged a missed detection
         -
       * - ``tof_range``
         - (4,) [0, ``tof.max_range``]
         - the four ToF ranges along the sensors' axes; 0 when invalid
         - m
       * - ``tof_valid``
         - (4,) {0, 1}
         - 1 when the reading is valid (a return within ``tof.max_range``)
         -
       * - ``imu``
         - (6,) ±16 g, ±2000 °/s
         - mean specific force (3) and angular rate (3) over the step, clipped
           (``info["imu_saturated"]``)
         - body frame B; m/s², rad/s
       * - ``range_down``
         - (1,) [0, ``rangefinder.max_range``]
         - the downward rangefinder's range (to the deck, or the sea beside it); 0 when
           invalid
         - m
       * - ``range_down_valid``
         - (1,) {0, 1}
         - 1 when the rangefinder's reading is valid
         -
       * - ``velocity``
         - (3,) ±30
         - the drone's velocity as its autopilot estimates it (PX4's
           ``vehicle_local_position``); the simulated controller flies on the true state, so
           it is the truth
         - heading frame H (x forward, y left, z up); m/s
       * - ``attitude``
         - (2,) ±(π, π/2)
         - the drone's roll and pitch as its autopilot estimates them (``vehicle_attitude``)
         - world frame, ZYX; rad

    ``estimation.observed: fused`` adds ``deck_pose_std`` (the estimate's 1-sigma).
    ``gym.make(id, privileged=True)`` (a training option, for an asymmetric critic) adds
    ``privileged`` (12,): the **true** deck centre relative to the drone and its relative
    velocity (heading frame, ±50 m, ±30 m/s), the deck's roll and pitch and its angular
    velocity (world, ±10 rad/s), and its true tilt ``PRIVILEGED_LOOKAHEAD_S`` (1 s) ahead
    (rad); :class:`landing_env.privileged.PrivilegedCriticPolicy` hides it from the actor.
    ``info`` carries the ground truth and diagnostics: ``deck_pose_true``, ``estimates``
    (every configured estimator), ``drone``, ``deck``, ``imu_samples``, ``tof_ranges``,
    ``outcome``, the land decision's ``band_s``, ``in_band``, ``land_refused``,
    ``committed``, ``forced_commit``, ``wave_offs``, ``descent_s`` and, after a touchdown,
    ``touchdown`` (its metrics).

    .. rubric:: Rewards

    Term by term (each in ``info`` as ``reward_<term>``; they sum to the reward):

    * ``shaping`` = Φ(s') - Φ(s), potential-based (it does not change the optimal policy),
      with Φ = -``shaping_weight`` (1) · (‖Δxy‖ + ``vertical_weight`` (0.5) · ‖Δz‖) -
      ``velocity_weight`` (0.5) · ‖Δv‖: the true distance from the drone to the tag centre,
      m, and the drone's speed relative to the deck, m/s.
    * ``time`` = -``time_cost`` (0.1 per second) · the seconds the step flew (a landing
      step: its descent too).
    * ``action_rate`` = -``action_rate_weight`` (0.002) · ‖a - a_prev‖² over the four
      set-points (the ``land`` entry is a decision, not charged).
    * on a touchdown: ``touchdown`` = +``touchdown_bonus`` (5) for being on the deck;
      ``normal_speed`` = -``normal_speed_penalty`` (4) · v_n; ``normal_speed_sq`` =
      -``normal_speed_sq_penalty`` (10) · v_n²; ``tilt`` = -``tilt_penalty`` (0.2 per
      degree of deck tilt); ``offset`` = -``offset_penalty`` (5 per metre off the centre);
      ``success`` = +``success_bonus`` (10) on a success.  A 0.3 m/s successful touchdown
      nets about +12.9 less tilt and offset; a 1 m/s one fails and nets about -9.
    * ``crash`` = -``crash_penalty`` (10) on a crash or a descent that does not touch down
      within ``timing.descent_timeout_s``.

    **No hover optimum**: the band's forced commit ends every hold in it within 15 s, and a
    time-out is a truncation (no terminal term) whose bootstrapped value is the hover's own:
    hovering for ever costs 0.005 per step, 5 in all at the recipe's γ = 0.999, while a
    commit from the hold without any timing (``land-now``: 55.5 % on the bench's held-out
    sea, its failures slow but tilted) is worth about +8.  The recipe's γ looks as far
    ahead as an episode lasts: 1 / (1 - 0.999) = 1000 steps ≥ 800 (40 s at 20 Hz).

    .. rubric:: Starting state

    The drone hovers ``start.height_m`` above the deck's home surface (1.8-2.2 m by default;
    the landing scenario ids 1.5-4 m), up to ``start.max_offset_m`` off its centre (0.3 m;
    the scenario ids 1 m) with ``|yaw|`` up to ``start.max_yaw_deg`` (10°; the scenario ids
    30°), drawn from the episode's seed.  The deck motion starts at a seeded phase.  The ship
    scenario ids (from ``-v3``) start in trim with the mean wind (``start.trim_to_wind``).

    .. rubric:: Episode end

    * **Touchdown** (terminated): at the first contact of a foot with the deck the metrics are
      taken (relative normal speed, deck tilt, drone-to-deck attitude, lateral offset), the
      motors idle (or, with ``touchdown.spool_down_s``, idle after a land sequence that
      levels the drone onto its gear while the thrust falls) and the simulation runs on for
      ``touchdown.settle_time_s`` (1 s); ``touchdown.harpoon_force_n`` fits a deck-securing
      harpoon (off by default).  Success
      when the relative normal speed is at most 0.5 m/s, the deck tilt at most 5°, the
      drone-to-deck attitude at most 10°, all four feet touched and the drone still stands on
      the deck after the settle without a bounce above 1 cm or a tip-over; otherwise the
      outcome is ``hard_landing`` with the failed checks listed.  Every threshold is a
      ``touchdown.*`` key.
    * **Crash** (terminated): any other contact (the body on anything, a foot off the deck), a
      flip beyond ``simulation.flip_tilt_deg``, leaving the arena, or a committed descent
      that has not touched down after ``timing.descent_timeout_s``.
    * **Time-out** (truncated) after ``simulation.max_episode_s`` (30 s; the scenario ids
      40 s) of simulated time.

    .. rubric:: Arguments

    ``gym.make("DeckLanding-v2", config="default", render_mode=None, overrides=None,
    privileged=False, **sections)``: ``config`` is a shipped config name (``configs/*.yaml``)
    or a path; ``overrides`` sets dotted keys (``{"action.land_trigger": False}``); a section
    keyword replaces keys of one section (``camera={"mode": "render"}``).  An unknown key or
    a bad value fails at construction with a ``ConfigError`` naming the key and what is
    allowed.  ``privileged=True`` adds the ``privileged`` key (training only: a policy that
    flies reads the env built without it).  ``render_mode="rgb_array"`` returns the camera
    image with the detections drawn; ``"human"`` opens the PyBullet window.  The scenario
    ids (``DeckLanding-BenchSS4-v2``, ``DeckLanding-ShipSS5-v6``, ...) build a shipped config
    with its landing overrides and its timing settings (the bench's: the timed descent, an
    8 s history, the ``predictive`` wave-off and contact window, and
    ``timing.observation: prediction``; the ship's: its deck-frame guidance) and take the
    same ``overrides``.

    .. rubric:: Version History

    * ``DeckLanding-v2`` (current): the ``land`` action (the timing task's descent inside the
      step, obeyed in the hold band, forced after 15 s in it); the observation adds the
      levelled deck position and velocity with the last estimate's age, the deck-tilt
      predictor's chances and the value of waiting, the band time and the previous action
      (and, asked for, the privileged key); the reward adds the relative-velocity potential,
      the action-rate term and the squared touchdown speed.  ``v1``: every observation key
      a float32 ``Box`` (the flags were ``MultiBinary``), the drone's own ``velocity`` and
      ``attitude`` observed, and a ``touchdown_bonus`` for any touchdown on the deck.
      ``v0``: the task, any config.  v0 and v1 are no longer registered.
    * ``DeckLanding-BenchSS{3,4,5}``, ``DeckLanding-PaperStewart``: the bench configs made a
      landing run (the drone flying, the tag projected, IHRCF observed); ``v1``
      ``DeckLanding-v1``'s observation; **v2** (current): ``DeckLanding-v2``'s task, the
      bench's timing settings.
    * ``DeckLanding-HighApproach``: from 20 m up and 5 m off, in gusty wind, over a sea state
      3 deck with nested tags; ``v1`` ``DeckLanding-v1``'s observation; **v2** (current):
      ``DeckLanding-v2``'s task.
    * ``DeckLanding-ShipSS{3,4,5,6}``: ``v1`` the ship decks, ``tight`` observed, the
      standard lens, started level and at rest with the bench's controller limits; ``v2`` the
      scenario's own lens (the wide 80° lens at sea states 5 and 6); ``v3`` started in trim
      with the mean wind, flying with the autopilots' stock limits (a 10 m/s² velocity
      integrator, 45° of tilt); ``v4`` ``DeckLanding-v1``'s observation; ``v5``
      ``DeckLanding-v2``'s task, the ship's timing settings (a 2 m hold).  **v6** (current):
      the touchdown control of ``DeckLandingTiming-ShipSS<n>-v8`` (the descent's relative
      speed held to its plan, a 0.15 s land sequence after the contact).  v1-v5 are no
      longer registered.
    """

    def __init__(
        self,
        config: Any = "default",
        render_mode: str | None = None,
        overrides: dict[str, Any] | None = None,
        privileged: bool = False,
        **sections: Any,
    ) -> None:
        super().__init__(config, render_mode, overrides, **sections)
        #: the ``privileged`` key is observed (a training option for an asymmetric critic)
        self.privileged = bool(privileged)
        sim = self.config.simulation
        self._build_descent(max(1, round(self.timing.history_s * sim.env_hz)))
        self._fields = action_fields(self.config.action)
        n_action = len(self._fields)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_action,), dtype=np.float32)
        _, pose_high = pose_bounds(sim.arena_max_height_m)
        self._position_high = pose_high[:3].astype(np.float32)
        box = spaces.Box
        n_prediction = len(self.timing.contact_times_s) + 2
        lander = {
            "deck_position": box(-self._position_high, self._position_high, dtype=np.float32),
            "deck_velocity": box(-VELOCITY_HIGH, VELOCITY_HIGH, (3,), dtype=np.float32),
            "deck_tilt": box(-ATTITUDE_HIGH, ATTITUDE_HIGH, dtype=np.float32),
            "deck_age": box(0.0, DECK_AGE_MAX_S, (1,), dtype=np.float32),
            "deck_seen": flag_space(1),
            "prediction": box(0.0, 1.0, (n_prediction,), dtype=np.float32),
            "band_time": box(0.0, 1.0, (1,), dtype=np.float32),
            "in_band": flag_space(1),
            "previous_action": box(-1.0, 1.0, (n_action,), dtype=np.float32),
        }
        if self.privileged:
            high = np.array(
                [*self._position_high, *[VELOCITY_HIGH] * 3, *ATTITUDE_HIGH]
                + [DECK_RATE_HIGH] * 3
                + [math.pi],
                dtype=np.float32,
            )
            low = -high
            low[-1] = 0.0
            lander[PRIVILEGED_KEY] = box(low, high, dtype=np.float32)
        self.observation_space = spaces.Dict({**lander, **self.observation_space.spaces})
        self._reset_lander()

    def _reset_lander(self) -> None:
        self._reset_descent()
        #: seconds spent in the hold band this episode (the timing task's wait)
        self._wait_s = 0.0
        self._in_band = False
        self._forced = False
        self._land_refused = False
        self._previous_action = np.zeros(self.action_space.shape, dtype=np.float32)
        self._deck_position = np.zeros(3)
        self._deck_velocity = np.zeros(3)
        self._deck_tilt = np.zeros(2)
        self._deck_age_s = DECK_AGE_MAX_S
        self._deck_seen = False

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        base_observation, _ = super().reset(seed=seed, options=options)
        self._reset_lander()
        self._start_descent_episode(base_observation)
        self._in_band = self._band()
        return self._lander_observation(), self._info()

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self._sensing is None or self._base_observation is None:
            raise RuntimeError("call reset() before step()")
        if self._outcome is not Outcome.IN_FLIGHT:
            raise RuntimeError("the episode has ended; call reset()")
        action = validate_action(action, self.action_space, ", ".join(self._fields))
        self._action_clipped = bool(np.any(np.abs(action) > 1.0))
        action = np.clip(action, -1.0, 1.0)
        self.frames_of_last_step = []
        self.periods_of_last_step = []
        started_s = self.world.time
        settings = self.config.action
        land = settings.land_trigger and float(action[-1]) > settings.land_threshold
        self._land_refused = land and not self._in_band
        # the band as judged on the last observation; None once a descent has moved on
        in_band: bool | None = None
        if land and self._in_band:
            # the chosen descent, waved off where the timing settings ask and time is left
            self._descend(wave_off=self._wait_s < self.timing.wait_limit_s)
        else:
            self._advance(self._action_to_setpoint(action))
            in_band = self._in_band = self._band()
            if in_band:
                self._wait_s += self.env_dt
                forced = settings.land_trigger and self._wait_s >= self.timing.wait_limit_s
                if forced and self._outcome is Outcome.IN_FLIGHT:
                    self._forced = True
                    self._descend(wave_off=False)
                    in_band = None
        self._in_band = self._outcome is Outcome.IN_FLIGHT and (
            self._band() if in_band is None else in_band
        )
        reward = self._step_reward(action, self.world.time - started_s)
        self._previous_action = action.astype(np.float32)
        terminated = self._terminated()
        truncated = not terminated and self._truncated()
        if truncated:
            self._outcome = Outcome.TIMEOUT
        return self._lander_observation(), reward, terminated, truncated, self._info()

    # ------------------------------------------------------------------ the land decision
    def _band(self) -> bool:
        """A ``land`` now would be obeyed: aligned over the tag, and the camera within
        ``action.land_band_m`` of the hold height over the deck."""
        observation = self._base_observation
        assert observation is not None
        if not self.guidance.aligned(observation):
            return False
        height = self.guidance.range_m(observation)
        band = self.config.action.land_band_m
        return math.isfinite(height) and abs(height - self.timing.hold_height_m) <= band

    def _record(self) -> None:
        """Each control period: the history, and the last valid deck estimate with its age."""
        super()._record()
        row = self.history.newest()
        if row[_VALID] < 0.5:
            self._deck_age_s = min(self._deck_age_s + self.env_dt, DECK_AGE_MAX_S)
            return
        forward, left = camera_to_heading_xy(row[[_X, _Y]])
        self._deck_position = np.array([forward, left, -row[_Z]])
        rates = self.history.slope((_X, _Y, _Z))
        forward_rate, left_rate = camera_to_heading_xy(rates[:2])
        self._deck_velocity = np.array([forward_rate, left_rate, -rates[2]])
        self._deck_tilt = row[[_ROLL, _PITCH]].copy()
        self._deck_age_s = 0.0
        self._deck_seen = True

    def _prediction(self) -> np.ndarray:
        """``timing.observation: prediction``'s values over the band time left; zeros (valid
        0) where the observation is not the prediction."""
        prediction = self.deck_prediction
        size = self.observation_space["prediction"].shape[0]
        if prediction.tilt_predictor is None or prediction.observed_values is None:
            return np.zeros(size)
        return prediction.prediction_values(self._wait_s)

    def _lander_observation(self) -> dict[str, np.ndarray]:
        assert self._base_observation is not None
        values: dict[str, Any] = {
            **self._base_observation,
            "deck_position": self._deck_position,
            "deck_velocity": self._deck_velocity,
            "deck_tilt": self._deck_tilt,
            "deck_age": [self._deck_age_s],
            "deck_seen": [float(self._deck_seen)],
            "prediction": self._prediction(),
            "band_time": [self._wait_s / self.timing.wait_limit_s],
            "in_band": [float(self._in_band)],
            "previous_action": self._previous_action,
        }
        if self.privileged:
            values[PRIVILEGED_KEY] = self._privileged_values()
        return self._bounded.observation(values, self.observation_space)

    def _privileged_values(self) -> np.ndarray:
        """The truth a critic may read: the deck relative to the drone (heading frame), its
        attitude and rates, and its tilt ``PRIVILEGED_LOOKAHEAD_S`` ahead."""
        world = self.world
        state = world.drone_state()
        deck = world.deck_state()
        ahead = np.asarray(world.stewart.motion.pose(world.time + PRIVILEGED_LOOKAHEAD_S))
        return np.concatenate(
            [
                _heading(deck.tag_centre_w - state.position_w, state.yaw),
                _heading(deck.velocity_w - state.velocity_w, state.yaw),
                euler_zyx_from_matrix(deck.rotation_wp)[:2],
                deck.angular_velocity_w,
                [math.radians(float(tilt_deg(ahead[3], ahead[4])))],
            ]
        )

    # ------------------------------------------------------------------ reward
    def _shaping_potential(self) -> float:
        """Φ: the distance's potential, less ``velocity_weight`` per m/s of the drone's
        speed relative to the deck."""
        state, deck = self.world.drone_state(), self.world.deck_state()
        speed = float(np.linalg.norm(state.velocity_w - deck.velocity_w))
        return self._distance_potential(state, deck) - self.config.reward.velocity_weight * speed

    def _step_reward(self, action: np.ndarray, flown_s: float) -> float:
        r = self.config.reward
        potential = self._shaping_potential()
        change = action[:4] - self._previous_action[:4]
        terms = zero_terms()
        terms.update(
            {
                "shaping": potential - self._potential,
                "time": -r.time_cost * flown_s,
                "action_rate": -r.action_rate_weight * float(change @ change),
                **touchdown_terms(
                    self._outcome, self._touchdown, r, touchdown_bonus=True, speed_squared=True
                ),
            }
        )
        self._potential = potential
        self._reward_terms = terms
        return float(sum(terms.values()))

    def _info(self) -> dict[str, Any]:
        info = super()._info()
        info.update(
            {
                "band_s": self._wait_s,
                "in_band": self._in_band,
                "land_refused": self._land_refused,
                "committed": self._committed,
                "forced_commit": self._forced,
                "wave_offs": self._wave_offs,
                "descent_s": self._descent_s,
            }
        )
        return info
