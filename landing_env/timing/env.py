"""``DeckLandingTiming-v0``: hold over the moving deck and choose the moment to land.

A scripted guidance (:class:`~landing_env.timing.guidance.DeckGuidance`, which reads only the
estimated deck pose and the ToF ranges) holds the drone aligned over the tag at a hold height.
Each step the agent chooses ``0`` (wait) or ``1`` (commit); on commit the same guidance flies
the final descent to touchdown **within that one step** (its control periods run inside
``step``), and the episode ends with the touchdown's outcome.  Running the descent inside the
step keeps the decision problem a clean stopping problem: no steps with ignored actions reach
the learner.  The settings are the config's ``timing`` section
(:class:`~landing_env.timing.config.TimingConfig`); the observation is laid out by
:class:`~landing_env.timing.layout.TimingObservationLayout`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from gymnasium import spaces

from estimation.deck_prediction import LinearMotionPredictor, LinearTiltPredictor
from estimation.frames import (
    euler_zyx_from_matrix,
    level_from_body,
    levelled_deck_pose,
    tilt_deg,
)
from estimation.optimal_stopping import StoppingValues
from landing_env.config import episode_step_limit
from landing_env.envs.actions import WAIT, validate_action
from landing_env.envs.base import DeckLandingBaseEnv
from landing_env.envs.rewards import touchdown_terms, zero_terms
from landing_env.errors import ConfigError
from landing_env.estimators import load_intrinsics
from landing_env.physics.controller import VelocitySetpoint
from landing_env.resources import PREDICTOR_DIR, tilt_predictor_path
from landing_env.sea.hms import HelideckMonitor, HelideckMonitorConfig
from landing_env.sea.hms_forecast import FORECAST_KINDS, deck_forecast_for
from landing_env.timing.config import (
    CAMERA_BELOW_COM_M,
    SCENARIO_TILT_MODEL,
    WAVE_OFF_CLIMB_S,
    TimingConfig,
)
from landing_env.timing.guidance import DeckGuidance, GuidanceGains, OwnState
from landing_env.timing.history import HISTORY_FEATURES, DeckMotionHistory
from landing_env.timing.layout import timing_layout
from landing_env.touchdown import Outcome

_ROLL, _PITCH, _ROLL_RATE, _PITCH_RATE, _VALID = (
    HISTORY_FEATURES.index(n) for n in ("roll", "pitch", "roll_rate", "pitch_rate", "valid")
)


class DeckLandingTimingEnv(DeckLandingBaseEnv):
    """Hold over the moving deck and choose the moment to land.

    .. rubric:: Description

    A scripted guidance (:class:`DeckGuidance`, which reads only the estimated deck pose and
    the ToF ranges) holds the drone aligned over the tag at a hold height.  At each decision
    the agent waits or commits; on a commit the same guidance flies the final descent to
    touchdown **within that one step**, and the episode ends with the touchdown's outcome.
    The decision is a clean stopping problem: no steps with ignored actions reach a learner.
    The touchdown is judged as in ``DeckLanding-v0`` (at most 0.5 m/s relative normal speed,
    5° deck tilt, 10° drone-to-deck attitude, the drone still on the deck after 1 s), so the
    policy's task is to meet the deck when it is level and slow.

    .. rubric:: Action space

    ``Discrete(2)``: 0 waits one decision period (``steps_per_decision`` control periods,
    0.1 s), 1 commits to the final descent.  Anything but the integer 0 or 1 is refused with
    a ``ValueError``.

    .. rubric:: Observation space

    A flat ``Box(-50, 50, (n,), float32)`` laid out by :class:`TimingObservationLayout`; what
    its head holds is ``timing.observation``:

    .. list-table::
       :header-rows: 1
       :widths: 18 30 52

       * - ``observation``
         - head
         - then
       * - ``history`` (default)
         - the last ``history_s`` seconds of the estimated deck pose as a level camera sees
           it (x, y, z, roll, pitch), its least-squares rates and validity, 10 values a row,
           in decimetres and tenths of a radian, z relative to the hold height
         - the four ToF ranges (relative to the hold height) and their validity, the fraction
           of the wait limit used
       * - ``prediction``
         - the scenario's deck-tilt predictor's chance of a deck within 5° at each contact
           time, the value of waiting on, and the prediction's validity, all in [0, 1]
         - as above
       * - ``forecast``
         - the history's newest row only
         - as above, then the ship's helideck forecast 0-8 s ahead (surge, sway, heave,
           roll, pitch at each horizon), 1 when it was made, and the drone's own velocity
           and lean

    A value beyond ±50 is clipped and flagged; :meth:`TimingObservationLayout.decode` undoes
    the scaling.

    .. rubric:: Rewards

    ``-reward.time_cost`` per second waited (0.1); at the end ``+reward.success_bonus`` (10)
    on a successful touchdown, minus ``normal_speed_penalty · v_n + tilt_penalty · tilt_deg +
    offset_penalty · offset_m`` on any touchdown, minus ``crash_penalty`` (10) on a crash or
    a descent that does not touch down.  The terms are those of ``DeckLanding-v0``, from one
    function, and each is in ``info``.

    .. rubric:: Starting state

    The drone starts aligned over the tag at the hold height (``hold_height_m``, 0.7 m over
    the bench; 2.0 m over a ship deck), at most 0.1 m off and 10° of yaw, and a warm-up of
    ``history_s`` (the guidance holds, the history fills) runs before the first decision, so
    ``time_s`` at touchdown includes it.  The ship ids from ``-v6`` start in trim with the
    mean wind.

    .. rubric:: Episode end

    * **Touchdown** (terminated) after a commit, with the outcome and metrics of
      ``DeckLanding-v0``.
    * **Wave-off**: with ``wave_off_tilt_deg`` set, a chosen descent whose predicted deck at
      the contact is too tilted climbs back to the hold inside the step, and the episode
      goes on (``info["wave_offs"]``).
    * **Forced commit**: the wait that reaches ``wait_limit_s`` (15 s) descends in the same
      step.
    * **Crash** (terminated), or a descent that has not touched down after
      ``descent_timeout_s`` (6 s; 15 s over a ship deck).

    .. rubric:: Arguments

    ``gym.make(id, render_mode=None, overrides=None, **sections)``: ``config``, ``overrides``
    and the section keywords as in ``DeckLanding-v0``.  The task's settings are the config's
    ``timing`` section (:class:`~landing_env.timing.config.TimingConfig`), set by the same
    dotted overrides: ``overrides={"timing.observation": "prediction",
    "timing.wave_off_tilt_deg": 5.0}`` (hold height, history length, wait limit, the descent
    profile in ``timing.guidance``, the wave-off, the contact window, the observation).  A
    registered id lays its scenario's settings under the user's; a policy of
    :mod:`agents.policy_registry` lays its own (``predictive``: the 8 s history, the wave-off
    and the contact window).  A pinned drone (``simulation.drone_fixed``) is refused with a
    ``ConfigError``.  A trained model's card records the id, observation and descent it was
    trained on and refuses another.

    .. rubric:: Version History

    * ``DeckLandingTiming-v0``: the task, any config; the history observation, levelled.
    * ``DeckLandingTiming-PaperStewart-v0``: the papers' bench made a landing run, the
      range-scheduled final descent (1.85 ± 0.35 s).
    * ``DeckLandingTiming-BenchSS{3,4,5}``: ``v0`` the range-scheduled descent; ``v1`` the timed
      final descent (the feet touch 1.30 ± 0.06 s after the commit); ``v2``-``v4`` an 8 s
      history, the wave-off by the scenario's deck-tilt predictor (``v3``: below the value of
      waiting on) and (``v4``) the contact window, fixed in the id; ``v5`` v4 observing the
      predictor's chances.  **v6** (current, 1.0.0): the timed descent and the scenario's
      predictor; the wave-off, contact window and observation are ``timing`` settings, so v4
      is v6 with the ``predictive`` policy's settings and v5 adds
      ``timing.observation: prediction``.
    * ``DeckLandingTiming-ShipSS{3,4,5,6}``: ``v1`` the ship decks, ``tight`` observed, a 2 m
      hold, the guidance in the deck's frame; ``v2`` the deck's acceleration tracked and led
      0.2 s; ``v3`` a go-around when the deck is lost, no flare; ``v4`` the scenario's lens and
      the view gate from the camera's calibration; ``v5`` v4 observing the helideck forecast
      and the drone's own state; ``v6`` v5 started in trim with the mean wind, with the
      autopilots' stock limits.  **v7** (current, 1.0.0): v6 observing the deck-pose history by
      default (what ``evaluate landing --scenario ship-ssN`` flies); the forecast is the
      setting ``timing.observation: forecast``.

    The ids before the current ones are no longer registered; their settings are reached
    through the current id's ``overrides`` (``timing.guidance.descent_profile: range`` for v0).
    """

    def __init__(
        self,
        config: Any = "default",
        render_mode: str | None = None,
        overrides: dict[str, Any] | None = None,
        **sections: Any,
    ) -> None:
        super().__init__(config, render_mode, overrides, **sections)
        if self.config.simulation.drone_fixed:
            self.world.close()
            raise ConfigError(
                "simulation.drone_fixed",
                "True pins the drone (the papers' bench); the timing task flies it: set it false",
            )
        sim = self.config.simulation
        rate_window = max(2, round(self.timing.rate_window_s * sim.env_hz))
        self.layout = timing_layout(self.timing, sim.env_hz)
        n_history = self.layout.n_history
        self.history = DeckMotionHistory(n_history, rate_window, self.env_dt)
        self.guidance = DeckGuidance(self._guidance_gains(), self.env_dt)
        #: the scenario's deck-tilt predictor, read by the model wave-off, the contact
        #: window and the prediction observation (None when none is on)
        self.tilt_predictor = self._load_tilt_predictor()
        self.wave_off_values = self._wave_off_values()
        #: the value of waiting on that the prediction observation holds
        self.observed_values = self._observed_values()
        #: the ship's helideck forecast the forecast observation holds (None when not on),
        #: and this episode's HMS record
        self.deck_forecast = self._load_deck_forecast()
        self._monitor: HelideckMonitor | None = None
        self.action_space = spaces.Discrete(2)
        self.observation_space = self.layout.space
        #: set True to keep a record of every control period of a step (a commit step holds
        #: the whole descent): ``periods_of_last_step`` (time, drone and deck positions, true
        #: and observed deck pose) and, with ``render_mode="rgb_array"``, the camera images in
        #: ``frames_of_last_step``.  Off by default: SB3's ``make_vec_env`` asks for
        #: ``rgb_array`` unless told otherwise, and rendering every period is slow
        self.record_periods = False
        self.frames_of_last_step: list[np.ndarray] = []
        self.periods_of_last_step: list[dict[str, Any]] = []
        self._reset_episode_state()

    @property
    def timing(self) -> TimingConfig:
        """The config's ``timing`` section."""
        return self.config.timing

    def _guidance_gains(self) -> GuidanceGains:
        """The guidance's gains, the view gate's half field of view taken from the camera's
        calibration where ``view_from_camera`` asks for it."""
        gains = self.timing.guidance
        if not gains.view_from_camera:
            return gains
        try:
            half_view_tan = load_intrinsics(self.config).half_view_tan()
        except ConfigError:
            self.world.close()
            raise
        return replace(gains, view_half_tan=half_view_tan)

    def _wave_off_values(self) -> StoppingValues | None:
        """The value of waiting on for the ``value`` wave-off: from the chances the
        predictor gave held-out examples at the contact."""
        t = self.timing
        if self.tilt_predictor is None or t.wave_off_rule != "value":
            return None
        if t.wave_off_predictor != "model" or t.wave_off_tilt_deg <= 0.0:
            return None
        values = self.tilt_predictor.stopping_values(t.contact_times_s, t.wave_off_tilt_deg)
        if values is None:
            self.world.close()
            raise ConfigError(
                "timing.wave_off_rule",
                f"'value' needs the chances the predictor {t.tilt_model!r} gave held-out "
                f"examples {t.contact_times_s[0]:g}-{t.contact_times_s[-1]:g} s ahead, which it "
                "does not hold: refit it "
                "with `python -m agents.timing.tilt_fit fit`",
            )
        return values

    def _load_deck_forecast(self) -> LinearMotionPredictor | None:
        """The helideck forecast of this scenario's sea, fitted once per process (the
        ``forecast`` observation's; None otherwise)."""
        if self.timing.observation != "forecast":
            return None
        kind = self.config.motion.kind
        if kind not in FORECAST_KINDS:
            self.world.close()
            raise ConfigError(
                "timing.observation",
                f"'forecast' needs a sea to forecast (motion.kind one of {FORECAST_KINDS}), "
                f"not {kind!r}",
            )
        return deck_forecast_for(self.config.motion, HelideckMonitorConfig())

    def _predictor_columns(self) -> list[int]:
        """The history's columns the deck-tilt predictor reads."""
        assert self.tilt_predictor is not None
        return [HISTORY_FEATURES.index(name) for name in self.tilt_predictor.channels]

    def _observed_values(self) -> StoppingValues | None:
        """The value of waiting on for the prediction observation: from the chances the
        predictor gave held-out examples at the contact times, within the touchdown limit."""
        t = self.timing
        if t.observation != "prediction" or self.tilt_predictor is None:
            return None
        limit = self.config.touchdown.max_deck_tilt_deg
        values = self.tilt_predictor.stopping_values(t.contact_times_s, limit)
        if values is None:
            self.world.close()
            raise ConfigError(
                "timing.observation",
                f"'prediction' needs the chances the predictor {t.tilt_model!r} gave held-out "
                f"examples {t.contact_times_s[0]:g}-{t.contact_times_s[-1]:g} s ahead, which it "
                "does not hold: refit it with `python -m agents.timing.tilt_fit fit`",
            )
        return values

    def resolved_tilt_model(self) -> str:
        """``timing.tilt_model``, ``scenario`` resolved to the config's ``deck_predictor``
        (the predictor fitted to this scenario's deck; empty when it names none)."""
        name = self.timing.tilt_model
        return self.config.deck_predictor if name == SCENARIO_TILT_MODEL else name

    def _load_tilt_predictor(self) -> LinearTiltPredictor | None:
        """The fitted deck-tilt predictor (read by the ``model`` wave-off, the contact
        window and the prediction observation), checked against the history it will read."""
        t = self.timing
        wave_off = t.wave_off_predictor == "model" and t.wave_off_tilt_deg > 0.0
        observed = t.observation == "prediction"
        if not (wave_off or t.contact_window_s or observed):
            return None
        user = (
            "the model wave-off"
            if wave_off
            else "timing.contact_window_s"
            if t.contact_window_s
            else "timing.observation = 'prediction'"
        )
        name = self.resolved_tilt_model()
        if not name:
            self.world.close()
            what = (
                "'scenario' reads the scenario's deck_predictor, which this config does not name"
                if t.tilt_model == SCENARIO_TILT_MODEL
                else "is empty"
            )
            raise ConfigError(
                "timing.tilt_model",
                f"{what}; {user} needs the scenario's deck-tilt predictor "
                "(e.g. bench-ss4, or a file written by `python -m agents.timing.tilt_fit fit`)",
            )
        path = tilt_predictor_path(name)
        try:
            model = LinearTiltPredictor.load(path)
        except (OSError, ValueError) as error:
            self.world.close()
            shipped = sorted(p.stem.removeprefix("deck_tilt_") for p in PREDICTOR_DIR.glob("*.npz"))
            raise ConfigError(
                "timing.tilt_model",
                f"{name!r}: {error}; give a shipped one ({', '.join(shipped)}) "
                "or a file written by `python -m agents.timing.tilt_fit fit`",
            ) from None
        unknown = sorted(set(model.channels) - set(HISTORY_FEATURES))
        if unknown:
            self.world.close()
            raise ConfigError(
                "timing.tilt_model",
                f"{path.name} reads {unknown}, which the history does not hold "
                f"({', '.join(HISTORY_FEATURES)})",
            )
        if abs(model.dt_s - self.env_dt) > 1e-9:
            self.world.close()
            raise ConfigError(
                "timing.tilt_model",
                f"{path.name} was fitted at {1 / model.dt_s:g} Hz; simulation.env_hz is "
                f"{1 / self.env_dt:g}",
            )
        if self.history.length < model.n_window:
            self.world.close()
            raise ConfigError(
                "timing.history_s",
                f"{t.history_s:g} s is shorter than the deck-tilt predictor's {model.window_s:g} s "
                f"window: set timing.history_s={model.window_s:g}",
            )
        return model

    @property
    def episode_step_limit(self) -> int:
        """The most decisions an episode can take: ``wait_limit_s`` forces the commit."""
        return episode_step_limit(self.config, self.timing)

    def _reset_episode_state(self) -> None:
        self._wait_s = 0.0
        self._committed = False
        self._forced = False
        self._descent_s = 0.0
        self._contact_s = self.timing.expected_contact_s
        self._wave_offs = 0
        self._observation_clipped = False
        self._base_observation: dict[str, np.ndarray] | None = None
        #: the warm-up hold ended the episode (the deck rose into the drone, a gust crashed
        #: it); the first step reports that outcome instead of deciding
        self._hold_failed = False
        self._hold_failure_reported = False

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        base_observation, _ = super().reset(seed=seed, options=options)
        self._reset_episode_state()
        self.guidance.reset()
        self.history.reset()
        self._base_observation = base_observation
        if self.deck_forecast is not None:
            # the ship's HMS record of this episode (its errors drawn from the episode's seed)
            hms_seed = int(self.np_random.integers(2**31))
            self._monitor = HelideckMonitor(
                self.world.stewart.motion, HelideckMonitorConfig(), hms_seed
            )
        self.guidance.observe(base_observation, self._own_state())
        self._record()
        self.frames_of_last_step = []
        self.periods_of_last_step = []
        # warm-up: hold until the history is full; the agent decides only from then on.  A
        # warm-up that ends the episode (a ship deck heaving into the hold, a gust) does not
        # raise: reset returns (``info["hold_failed"]``) and the first step, whatever its
        # action, ends the episode with that outcome
        for _ in range(self.history.length - 1):
            self._advance(self._hold_setpoint())
            if self._outcome is not Outcome.IN_FLIGHT:
                self._hold_failed = True
                break
        return self._flat_observation(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._base_observation is None:
            raise RuntimeError("call reset() before step()")
        choice = validate_action(action, self.action_space, "0 = wait, 1 = commit")
        r = self.config.reward
        if self._hold_failed and not self._hold_failure_reported:
            # the warm-up's end, reported once; the action is moot
            self._hold_failure_reported = True
            # no success bonus: the drone did not choose to land
            terms = {**zero_terms(), **touchdown_terms(self._outcome, self._touchdown, r)}
            self._reward_terms = {**terms, "success": 0.0}
            reward = float(sum(self._reward_terms.values()))
            return self._flat_observation(), reward, True, False, self._info()
        if self._outcome is not Outcome.IN_FLIGHT:
            raise RuntimeError("the episode has ended; call reset()")
        self.frames_of_last_step = []
        self.periods_of_last_step = []
        terms = zero_terms()
        if choice == WAIT:
            waited = 0.0
            for _ in range(self.timing.steps_per_decision):
                self._advance(self._hold_setpoint())
                waited += self.env_dt
                if self._outcome is not Outcome.IN_FLIGHT:
                    break
            self._wait_s += waited
            terms["time"] = -r.time_cost * waited
            if self._outcome is Outcome.IN_FLIGHT and self._wait_s >= self.timing.wait_limit_s:
                self._forced = True
                self._descend(wave_off=False)
        else:
            aborted_s = self._descend(wave_off=self._wait_s < self.timing.wait_limit_s)
            terms["time"] = -r.time_cost * aborted_s
        terms.update(touchdown_terms(self._outcome, self._touchdown, r))
        self._reward_terms = terms
        terminated = self._outcome is not Outcome.IN_FLIGHT
        reward = float(sum(terms.values()))
        return self._flat_observation(), reward, terminated, False, self._info()

    # ------------------------------------------------------------------ internals
    def _advance(self, setpoint: VelocitySetpoint) -> None:
        """One control period of the world under ``setpoint``, then sense and record."""
        self._report = self.world.step(setpoint)
        if self.render_mode is not None or self.config.camera.mode == "render":
            self.world.stewart.update_leg_visuals()
        self._steps += 1
        self._outcome = self._outcome_after(self._report)
        self._sensing = self._sense()
        self._base_observation = self._observation()
        self.guidance.observe(self._base_observation, self._own_state())
        self._record()
        if self.record_periods:
            self._record_period()

    def _own_state(self) -> OwnState:
        """The drone's navigation estimate for the guidance (the true state standing in for
        the autopilot's, as for the levelled history)."""
        state = self.world.drone_state()
        return OwnState(state.position_w, state.velocity_w, state.rotation_wb)

    def _hold_setpoint(self) -> VelocitySetpoint:
        assert self._base_observation is not None
        return self.guidance.hold(
            self._base_observation, self.timing.hold_height_m, self._own_state()
        )

    def _record_period(self) -> None:
        assert self._sensing is not None and self._base_observation is not None
        world = self.world
        r_cd, t_cd = world.true_deck_pose_c()
        deck = world.deck_state()
        self.periods_of_last_step.append(
            {
                "time_s": world.time,
                "drone_position_w": world.drone_state().position_w.copy(),
                "deck_position_w": deck.position_w.copy(),
                "deck_euler_w": euler_zyx_from_matrix(deck.rotation_wp),
                "deck_pose_true": np.concatenate([t_cd, euler_zyx_from_matrix(r_cd)]),
                "deck_pose_observed": self._base_observation["deck_pose"].astype(float),
                "deck_pose_valid": bool(self._base_observation["deck_pose_valid"][0]),
                "committed": self._committed,
            }
        )
        if self.render_mode == "rgb_array":
            self.frames_of_last_step.append(world.camera_image(self._sensing.frame))

    def _record(self) -> None:
        assert self._base_observation is not None
        observation = self._base_observation
        if not observation["deck_pose_valid"][0]:
            self.history.push(None)
            return
        pose = observation["deck_pose"].astype(float)
        if self.timing.level_history:
            # the drone's attitude stands in for the autopilot's estimate (good to a fraction
            # of a degree in PX4); the deck pose stays the estimator's
            pose = levelled_deck_pose(pose, level_from_body(self.world.drone_state().rotation_wb))
        self.history.push(pose)

    def _descend(self, wave_off: bool) -> float:
        """The final descent, run to touchdown (or crash, or the descent timeout), or until a
        wave-off (``wave_off`` allows it); returns the seconds a wave-off cost (else 0)."""
        self._committed = True
        self._plan_contact()
        start = self.world.time
        while self._outcome is Outcome.IN_FLIGHT:
            if self.world.time - start >= self.timing.descent_timeout_s:
                # no touchdown: a failed landing of this task, not a time limit of the MDP
                self._outcome = Outcome.TIMEOUT
                break
            assert self._base_observation is not None
            self._advance(self.guidance.descend(self._base_observation, self._own_state()))
            elapsed = self.world.time - start
            if wave_off and self._outcome is Outcome.IN_FLIGHT and self._wave_off_due(elapsed):
                # go around: climb back to the hold (within 5 cm, or for at most 1.5 s) before
                # the agent decides again, so that the next descent starts where they all do
                self._committed = False
                self._wave_offs += 1
                back = self.world.time
                while (
                    self._outcome is Outcome.IN_FLIGHT and self.world.time - back < WAVE_OFF_CLIMB_S
                ):
                    self._advance(self._hold_setpoint())
                    height = self.guidance.range_m(self._base_observation)
                    if abs(height - self.timing.hold_height_m) < 0.05:
                        break
                elapsed = self.world.time - start
                self._wait_s += elapsed
                return elapsed
        end = self._touchdown.time_s if self._touchdown is not None else self.world.time
        self._descent_s = end - start
        return 0.0

    def _plan_contact(self) -> None:
        """The contact time of the descent starting now: with ``contact_window_s``, the one in
        it where the predictor gives the best chance of a deck within the touchdown limit
        (``expected_contact_s`` when it cannot predict); the guidance's timed descent is given
        the duration that meets the deck then."""
        t = self.timing
        self._contact_s = t.expected_contact_s
        if t.contact_window_s and self.tilt_predictor is not None:
            rows = self.history.rows()
            columns = self._predictor_columns()
            best = self.tilt_predictor.best_within(
                rows[:, columns],
                rows[:, _VALID] > 0.5,
                t.contact_times_s,
                self.config.touchdown.max_deck_tilt_deg,
            )
            if best.valid:
                self._contact_s = best.horizon_s
        self.guidance.plan_descent(t.descent_time_for(self._contact_s))

    def _wave_off_chance(self, elapsed_s: float) -> float:
        """The chance of a deck within the limit below which the model wave-off aborts,
        ``elapsed_s`` into the descent: ``wave_off_probability``, or with the ``value`` rule
        the value of waiting on after the climb back."""
        t = self.timing
        if self.wave_off_values is None:
            return t.wave_off_probability
        remaining_s = t.wait_limit_s - self._wait_s - elapsed_s - WAVE_OFF_CLIMB_S
        return self.wave_off_values.threshold(remaining_s, t.opportunity_s)

    def _wave_off_due(self, elapsed_s: float) -> bool:
        """The deck tilt predicted at the contact is beyond ``wave_off_tilt_deg`` while a
        wave-off is still possible (see :class:`TimingConfig`)."""
        t = self.timing
        decision_s = t.steps_per_decision * self.env_dt
        first = max(decision_s, t.wave_off_from_s) - 1e-9
        if t.wave_off_tilt_deg <= 0.0 or not first <= elapsed_s <= t.wave_off_until_s:
            return False
        rows = self.history.rows()
        row = rows[-1]
        if row[_VALID] < 0.5:
            return False  # nothing to predict with: the descent goes on
        ahead = max(self._contact_s - elapsed_s, 0.0)
        if t.wave_off_predictor == "model" and self.tilt_predictor is not None:
            columns = self._predictor_columns()
            prediction = self.tilt_predictor.predict(rows[:, columns], rows[:, _VALID] > 0.5, ahead)
            if not prediction.valid:
                return False  # nothing to predict with: the descent goes on
            return prediction.probability_within(t.wave_off_tilt_deg) < self._wave_off_chance(
                elapsed_s
            )
        roll = row[_ROLL] + row[_ROLL_RATE] * ahead
        pitch = row[_PITCH] + row[_PITCH_RATE] * ahead
        if t.wave_off_predictor == "quadratic":
            recent = rows[-max(3, round(t.wave_off_window_s / self.env_dt)) :]
            times = (np.arange(len(recent)) - (len(recent) - 1)) * self.env_dt
            valid = recent[:, _VALID] > 0.5
            if valid.sum() >= 5:
                fit = np.polyfit(times[valid], recent[valid][:, [_ROLL, _PITCH]], 2)
                roll, pitch = (float(np.polyval(fit[:, k], ahead)) for k in range(2))
        return float(tilt_deg(roll, pitch)) > t.wave_off_tilt_deg

    def _flat_observation(self) -> np.ndarray:
        assert self._base_observation is not None
        tof_valid = self._base_observation["tof_valid"].astype(bool)
        observation, self._observation_clipped = self.layout.encode(
            self.history.rows(),
            self._base_observation["tof_range"].astype(float),
            tof_valid,
            min(self._wait_s / self.timing.wait_limit_s, 1.0),
            None if self.layout.history_observed else self._prediction_values(),
            *self._forecast_observation(),
        )
        return observation

    def _forecast_observation(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The forecast observation's helideck forecast (None: none could be made) and the
        drone's own state; (None, None) when the observation holds none."""
        if self.deck_forecast is None:
            return None, None
        state = self.world.drone_state()
        roll, pitch, yaw = euler_zyx_from_matrix(state.rotation_wb)
        c, s = math.cos(yaw), math.sin(yaw)
        v = np.asarray(state.velocity_w, dtype=float)
        own = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2], roll, pitch])
        if self._monitor is None:
            return None, own
        _, measured = self._monitor.window(float(self.world.time), self.deck_forecast.window_s)
        poses = self.deck_forecast.predict_targets(measured, np.ones(len(measured), dtype=bool))
        if isinstance(poses, str) or not np.all(np.isfinite(poses)):
            return None, own
        poses = np.array(poses, dtype=float)
        poses[:, :3] -= poses[0, :3]
        return poses, own

    def _prediction_values(self) -> np.ndarray:
        """The prediction observation's values (:class:`TimingObservationLayout`): the chance
        at each contact time, the value of waiting on, the validity."""
        t = self.timing
        assert self.tilt_predictor is not None and self.observed_values is not None
        rows = self.history.rows()
        columns = self._predictor_columns()
        limit = self.config.touchdown.max_deck_tilt_deg
        chances = np.zeros(len(t.contact_times_s))
        valid = True
        for k, horizon in enumerate(t.contact_times_s):
            prediction = self.tilt_predictor.predict(
                rows[:, columns], rows[:, _VALID] > 0.5, horizon
            )
            if prediction.valid:
                chances[k] = prediction.probability_within(limit)
            else:
                valid = False
        if not valid:
            chances[:] = 0.0
        remaining_s = max(t.wait_limit_s - self._wait_s, 0.0)
        value = self.observed_values.threshold(remaining_s, t.opportunity_s)
        return np.concatenate([chances, [float(np.clip(value, 0.0, 1.0)), float(valid)]])

    def _start_pose(self, options: dict[str, Any]) -> tuple[np.ndarray, float]:
        """At the hold height over the deck, offset and yawed within ``start``'s limits."""
        options = {**options}
        options.setdefault("height_m", self.timing.hold_height_m + CAMERA_BELOW_COM_M)
        return super()._start_pose(options)

    def _info(self) -> dict[str, Any]:
        info = super()._info()
        hold_failed = getattr(self, "_hold_failed", False)
        info.update(
            {
                # the warm-up hold ended the episode (reported by reset and the one step after)
                "hold_failed": hold_failed,
                "wait_s": self._wait_s,
                "committed": self._committed,
                "forced_commit": self._forced,
                "descent_s": self._descent_s,
                # the contact time the last commit aimed at, seconds after it
                "planned_contact_s": getattr(self, "_contact_s", self.timing.expected_contact_s),
                "wave_offs": getattr(self, "_wave_offs", 0),
                "observation_clipped": getattr(self, "_observation_clipped", False),
                # read by SB3's EvalCallback for its success rate
                "is_success": self._outcome is Outcome.SUCCESS and not hold_failed,
            }
        )
        return info
