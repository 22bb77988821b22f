"""``DeckLandingTiming-v0``: hold over the moving deck and choose the moment to land.

A scripted guidance (:class:`~landing_env.timing.guidance.DeckGuidance`, which reads only the
estimated deck pose and the ToF ranges) holds the drone aligned over the tag at a hold height.
Each step the agent chooses ``0`` (wait) or ``1`` (commit); on commit the same guidance flies
the final descent to touchdown **within that one step** (its control periods run inside
``step``), and the episode ends with the touchdown's outcome.  Running the descent inside the
step keeps the decision problem a clean stopping problem: no steps with ignored actions reach
the learner.  The settings are the config's ``timing`` section
(:class:`~landing_env.timing_config.TimingConfig`); the observation is laid out by
:class:`~landing_env.timing.layout.TimingObservationLayout`.  The scenario's deck-tilt predictor
(the wave-off, the contact window, the prediction observation) is read through
:class:`~landing_env.anticipation.onboard_tilt_prediction.DeckPrediction`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from landing_env.config import episode_step_limit
from landing_env.envs.actions import WAIT, validate_action
from landing_env.envs.base import DeckLandingBaseEnv
from landing_env.envs.rewards import touchdown_terms, zero_terms
from landing_env.errors import ConfigError
from landing_env.timing.committed_descent import CommittedDescent
from landing_env.timing.layout import timing_layout
from landing_env.timing_config import CAMERA_BELOW_COM_M
from landing_env.touchdown import Outcome


class DeckLandingTimingEnv(CommittedDescent, DeckLandingBaseEnv):
    """Hold over the moving deck and choose the moment to land.

    .. rubric:: Description

    A scripted guidance (:class:`DeckGuidance`, which reads only the estimated deck pose and
    the ToF ranges) holds the drone aligned over the tag at a hold height.  At each decision
    the agent waits or commits; on a commit the same guidance flies the final descent to
    touchdown **within that one step**, and the episode ends with the touchdown's outcome.
    The decision is a clean stopping problem: no steps with ignored actions reach a learner.
    The touchdown is judged as in ``DeckLanding-v2`` (at most 0.5 m/s relative normal speed,
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

    A value beyond ±50 is clipped and flagged; :meth:`TimingObservationLayout.decode` undoes
    the scaling.

    .. rubric:: Rewards

    ``-reward.time_cost`` per second waited (0.1); at the end ``+reward.success_bonus`` (10)
    on a successful touchdown, minus ``normal_speed_penalty · v_n + tilt_penalty · tilt_deg +
    offset_penalty · offset_m`` on any touchdown, minus ``crash_penalty`` (10) on a crash or
    a descent that does not touch down.  The terms are those of ``DeckLanding-v2``, from one
    function, and each is in ``info``.

    .. rubric:: Starting state

    The drone starts aligned over the tag at the hold height (``hold_height_m``, 0.7 m over
    the bench; 2.0 m over a ship deck), at most 0.1 m off and 10° of yaw, and a warm-up of
    ``history_s`` (the guidance holds, the history fills) runs before the first decision, so
    ``time_s`` at touchdown includes it.  The ship ids from ``-v6`` start in trim with the
    mean wind.

    .. rubric:: Episode end

    * **Touchdown** (terminated) after a commit, with the outcome and metrics of
      ``DeckLanding-v2``.
    * **Wave-off**: with ``wave_off_tilt_deg`` set, a chosen descent whose predicted deck at
      the contact is too tilted climbs back to the hold inside the step, and the episode
      goes on (``info["wave_offs"]``).
    * **Forced commit**: the wait that reaches ``wait_limit_s`` (15 s) descends in the same
      step.
    * **Crash** (terminated), or a descent that has not touched down after
      ``descent_timeout_s`` (6 s; 15 s over a ship deck).

    .. rubric:: Arguments

    ``gym.make(id, render_mode=None, overrides=None, **sections)``: ``config``, ``overrides``
    and the section keywords as in ``DeckLanding-v2``.  The task's settings are the config's
    ``timing`` section (:class:`~landing_env.timing_config.TimingConfig`), set by the same
    dotted overrides: ``overrides={"timing.observation": "prediction",
    "timing.wave_off_tilt_deg": 5.0}`` (hold height, history length, wait limit, the descent
    profile in ``timing.guidance``, the wave-off, the contact window, the observation).  A
    registered id lays its scenario's settings under the user's; a policy of
    :mod:`agents.policies.registry` lays its own (``predictive``: the 8 s history, the wave-off
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
      autopilots' stock limits; ``v7`` (1.0.0) v6 observing the deck-pose history by default;
      the forecast observation of v5 and v6 was the setting ``timing.observation: forecast``
      until it left the package after 1.0.0.  **v8** (current): the touchdown control, the
      descent's relative speed held to its plan (``timing.guidance.descent_rate_gain``) and a
      0.15 s land sequence along the measured deck normal after the contact
      (``touchdown.spool_down_s``): ``quiescent`` lands 79.5 % of 200 ``ship-ss6`` seeds
      against 67.0 % on v7, the deck oracle 95.0 % against 77.5 %.

    The ids before the current ones are no longer registered, but for v7 of the ship ids,
    kept (superseded) for the look-ahead DQN trained on it; the others' settings are reached
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
        self.layout = timing_layout(self.timing, self.config.simulation.env_hz)
        self._build_descent(self.layout.n_history)
        self.action_space = spaces.Discrete(2)
        self.observation_space = self.layout.space
        self._reset_episode_state()

    @property
    def episode_step_limit(self) -> int:
        """The most decisions an episode can take: ``wait_limit_s`` forces the commit."""
        return episode_step_limit(self.config, self.timing)

    def _reset_episode_state(self) -> None:
        self._reset_descent()
        self._wait_s = 0.0
        self._forced = False
        self._observation_clipped = False
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
        self._start_descent_episode(base_observation)
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
    def _flat_observation(self) -> np.ndarray:
        assert self._base_observation is not None
        tof_valid = self._base_observation["tof_valid"].astype(bool)
        observation, self._observation_clipped = self.layout.encode(
            self.history.rows(),
            self._base_observation["tof_range"].astype(float),
            tof_valid,
            min(self._wait_s / self.timing.wait_limit_s, 1.0),
            None
            if self.layout.history_observed
            else self.deck_prediction.prediction_values(self._wait_s),
        )
        return observation

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
