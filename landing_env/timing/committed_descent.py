"""The committed descent: hold over the deck, and on a commit fly the final descent to
touchdown (or a wave-off back to the hold) inside one environment step.

:class:`CommittedDescent` is what ``DeckLandingTiming`` (a wait/commit decision) and ``DeckLanding``
(whose ``land`` action commits) share: the scripted guidance
(:class:`~landing_env.timing.guidance.DeckGuidance`) fed every control period, the levelled
deck-motion history (:class:`~landing_env.anticipation.deck_history.DeckMotionHistory`), the
scenario's deck-tilt predictor
(:class:`~landing_env.anticipation.onboard_tilt_prediction.DeckPrediction`) and the descent itself:
the timed descent of the ``timing`` settings, its contact window and its wave-off.  It is a mixin of
:class:`~landing_env.envs.base.DeckLandingBaseEnv`; the task owns the episode state it reads
(``_wait_s``: the time spent waiting, which the wave-off's value of waiting weighs).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from estimation.frames import euler_zyx_from_matrix, level_from_body, levelled_deck_pose
from landing_env.anticipation.deck_history import DeckMotionHistory
from landing_env.anticipation.onboard_tilt_prediction import DeckPrediction
from landing_env.errors import ConfigError
from landing_env.estimators import load_intrinsics
from landing_env.guidance_gains import GuidanceGains
from landing_env.physics.controller import VelocitySetpoint
from landing_env.timing.deck_tracker import OwnState
from landing_env.timing.guidance import DeckGuidance
from landing_env.timing_config import WAVE_OFF_CLIMB_S, TimingConfig
from landing_env.touchdown import Outcome


class CommittedDescent:
    """The hold, the history and the in-step descent of a task over
    :class:`~landing_env.envs.base.DeckLandingBaseEnv` (mixed in before it)."""

    # provided by DeckLandingBaseEnv and the task
    config: Any
    world: Any
    env_dt: float
    render_mode: str | None
    _outcome: Outcome
    _touchdown: Any
    _sensing: Any
    _wait_s: float

    @property
    def timing(self) -> TimingConfig:
        """The config's ``timing`` section."""
        return self.config.timing

    def _build_descent(self, n_history: int) -> None:
        """The guidance, the ``n_history``-row history and the deck-tilt predictor; a bad
        setting closes the world and raises its ``ConfigError``."""
        sim = self.config.simulation
        rate_window = max(2, round(self.timing.rate_window_s * sim.env_hz))
        self.history = DeckMotionHistory(n_history, rate_window, self.env_dt)
        self.guidance = DeckGuidance(self._guidance_gains(), self.env_dt)
        try:
            #: the scenario's deck-tilt predictor and what it foresees (the model wave-off,
            #: the contact window, the prediction observation)
            self.deck_prediction = DeckPrediction(self.config, self.history, self.env_dt)
        except ConfigError:
            self.world.close()
            raise
        #: set True to keep a record of every control period of a step (a commit step holds
        #: the whole descent): ``periods_of_last_step`` (time, drone and deck positions, true
        #: and observed deck pose) and, with ``render_mode="rgb_array"``, the camera images in
        #: ``frames_of_last_step``.  Off by default: SB3's ``make_vec_env`` asks for
        #: ``rgb_array`` unless told otherwise, and rendering every period is slow
        self.record_periods = False
        self.frames_of_last_step: list[np.ndarray] = []
        self.periods_of_last_step: list[dict[str, Any]] = []
        self._reset_descent()

    def _reset_descent(self) -> None:
        self._committed = False
        self._descent_s = 0.0
        self._contact_s = self.timing.expected_contact_s
        self._wave_offs = 0
        self._base_observation: dict[str, np.ndarray] | None = None

    def _start_descent_episode(self, base_observation: dict[str, np.ndarray]) -> None:
        """After the world's reset: the guidance and the history start from this observation."""
        self.guidance.reset()
        self.history.reset()
        self._base_observation = base_observation
        self.guidance.observe(base_observation, self._own_state())
        self._record()
        self.frames_of_last_step = []
        self.periods_of_last_step = []

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

    # ------------------------------------------------------------------ control periods
    def _advance(self, setpoint: VelocitySetpoint) -> None:
        """One control period of the world under ``setpoint``, then sense and record."""
        self._control_period(setpoint)  # type: ignore[attr-defined]
        self._base_observation = self._observation()  # type: ignore[attr-defined]
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
        deck = world.deck_state()
        r_cd, t_cd = world.true_deck_pose_c(deck)
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

    # ------------------------------------------------------------------ the descent
    def _descend(self, wave_off: bool) -> float:
        """The final descent, run to touchdown (or crash, or the descent timeout), or until a
        wave-off (``wave_off`` allows it); returns the seconds a wave-off cost (else 0)."""
        self._committed = True
        # the contact time of the descent starting now (the contact window's choice), and the
        # timed descent's duration that meets the deck then
        self._contact_s = self.deck_prediction.plan_contact()
        self.guidance.plan_descent(self.timing.descent_time_for(self._contact_s))
        start = self.world.time
        while self._outcome is Outcome.IN_FLIGHT:
            if self.world.time - start >= self.timing.descent_timeout_s:
                # no touchdown: a failed landing of this task, not a time limit of the MDP
                self._outcome = Outcome.TIMEOUT
                break
            assert self._base_observation is not None
            self._advance(self.guidance.descend(self._base_observation, self._own_state()))
            elapsed = self.world.time - start
            if (
                wave_off
                and self._outcome is Outcome.IN_FLIGHT
                and self.deck_prediction.wave_off_due(elapsed, self._contact_s, self._wait_s)
            ):
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
