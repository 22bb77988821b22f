"""``align-descend``: the scripted lander of ``DeckLanding`` (Box actions).

Visual servoing on the estimated deck pose: centre over the tag while descending to a hold
height, flare there until a calm window is predicted (:mod:`agents.policies.calm_window`), then the
final descent to touchdown.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from agents.policies.base import Policy
from agents.policies.calm_window import CalmConfig, CalmPrediction, predict_calm
from estimation.frames import camera_to_heading_xy
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.anticipation.deck_history import DeckMotionHistory
from landing_env.anticipation.onboard_tilt_prediction import commit_by_prediction
from landing_env.config import ActionConfig
from landing_env.envs.actions import action_from_setpoint
from landing_env.errors import ConfigError, require_range
from landing_env.guidance_gains import GuidanceGains
from landing_env.physics.controller import VelocitySetpoint
from landing_env.sensors.tof import TofConfig
from landing_env.timing.guidance import DeckGuidance


# ------------------------------------------------------------------------------ align-descend
class Phase(str, Enum):
    """Phases of :class:`AlignDescendPolicy`."""

    APPROACH = "approach"
    FLARE = "flare"
    DESCENT = "descent"


def _flare_calm() -> CalmConfig:
    # low over the deck the descent is short (about 1 s), so a straight-line extrapolation of
    # the last half second predicts the tilt at touchdown well, even on the papers' slow bench
    return CalmConfig(
        window_s=0.5,
        descent_s=1.0,
        trend_weight=1.0,
        max_tilt_deg=3.5,
        require_calm_window=False,
    )


@dataclass
class AlignDescendConfig:
    """Settings of the align-descend policy (heights are camera ranges above the deck)."""

    #: height of the flare, where the policy waits for a calm window, metres (low, so that
    #: the final descent is short and the calm prediction short-range; the tag still fits
    #: the image)
    hold_height_m: float = limited(0.4, Limit(0.3, 3.0))
    #: the flare starts when the range is within this of the hold height, metres
    hold_tolerance_m: float = limited(0.1, POSITIVE)
    #: the final descent starts regardless after this long in the flare, seconds
    max_flare_s: float = limited(25.0, NON_NEGATIVE)
    #: search speed without an estimate: climb (to widen the view) while a ToF sees a
    #: surface, descend while none does (every surface is beyond the ToF range), m/s
    search_climb_speed: float = limited(0.3, NON_NEGATIVE)
    #: horizontal speed towards the deck when the ToF ranges show its edge, m/s
    edge_seek_speed: float = limited(0.3, NON_NEGATIVE)
    #: ToF ranges shorter than the longest by more than this are taken as on the deck, metres
    edge_step_m: float = limited(0.1, POSITIVE)
    #: back to the approach after this long without a tag in the flare, seconds
    lost_tag_s: float = limited(1.0, NON_NEGATIVE)
    #: length of the motion history kept for the calm prediction, seconds
    history_s: float = 2.0
    rate_window_s: float = 0.5
    calm: CalmConfig = field(default_factory=_flare_calm)
    guidance: GuidanceGains = field(default_factory=GuidanceGains)
    #: fly its own final descent after the flare; False: the flare holds until the
    #: environment's ``land`` action descends (:class:`AlignPredictivePolicy`)
    own_descent: bool = True

    def __post_init__(self) -> None:
        require_limits(self)
        require_range(
            "history_s",
            self.history_s,
            self.calm.window_s,
            10.0,
            bounds_from=f"calm.window_s = {self.calm.window_s}",
        )
        require_range(
            "rate_window_s",
            self.rate_window_s,
            0.1,
            self.history_s,
            bounds_from=f"history_s = {self.history_s}",
        )


class AlignDescendPolicy(Policy):
    """Visual servoing for ``DeckLanding-v2`` on the estimated deck pose.

    Approach: centre over the tag and descend while aligned to the hold height; without a
    valid estimate, move towards the deck when the ToF ranges show its edge (IHRCF and CRHF
    need every ToF spot on the deck), else climb to bring the tag into view (or descend when
    no ToF sees anything: every surface is then beyond its range).  Flare: hold
    there, aligned, until :func:`predict_calm` predicts a calm window as long as the descent
    (or ``max_flare_s`` has passed).  Descent: the final descent of
    :class:`~landing_env.timing.guidance.DeckGuidance` down to touchdown.  Output: the Box
    action of :func:`~landing_env.envs.actions.action_from_setpoint` under the environment's
    :class:`ActionConfig` (``land`` at -1 where it has that entry: the policy flies its own
    descent).
    """

    name = "align-descend"

    def __init__(
        self,
        action: ActionConfig | None = None,
        config: AlignDescendConfig | None = None,
        dt: float = 0.05,
        tof_mounts_c: np.ndarray | None = None,
    ) -> None:
        self.action = action or ActionConfig()
        self.config = config or AlignDescendConfig()
        self.dt = dt
        mounts = np.asarray(
            tof_mounts_c if tof_mounts_c is not None else TofConfig().mount_offsets_c, dtype=float
        )
        # each sensor's direction from the camera in the heading frame, for seeking the deck
        # with the ranges
        directions = camera_to_heading_xy(mounts[:, :2])
        norms = np.linalg.norm(directions, axis=1, keepdims=True)
        self._tof_directions = directions / np.where(norms > 0.0, norms, 1.0)
        self.guidance = DeckGuidance(self.config.guidance, dt)
        self.history = DeckMotionHistory(
            max(1, round(self.config.history_s / dt)),
            max(2, round(self.config.rate_window_s / dt)),
            dt,
        )
        self.reset()

    def reset(self) -> None:
        self.phase = Phase.APPROACH
        self.guidance.reset()
        self.history.reset()
        self._flare_s = 0.0
        self._unseen_s = 0.0
        self.last: CalmPrediction | None = None

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        c = self.config
        seen = bool(observation["deck_pose_valid"][0])
        self._unseen_s = 0.0 if seen else self._unseen_s + self.dt
        self.history.push(observation["deck_pose"].astype(float) if seen else None)
        height = self.guidance.range_m(observation)

        if self.phase is Phase.FLARE and self._unseen_s > c.lost_tag_s:
            self.phase = Phase.APPROACH
        if self.phase is Phase.APPROACH and self.guidance.aligned(observation):
            if abs(height - c.hold_height_m) < c.hold_tolerance_m:
                self.phase, self._flare_s = Phase.FLARE, 0.0
        if self.phase is Phase.FLARE and c.own_descent:
            self._flare_s += self.dt
            if self._flare_s >= c.calm.window_s:
                self.last = predict_calm(self.history.rows(), self.dt, c.calm)
                if self.last.calm or self._flare_s >= c.max_flare_s:
                    self.phase = Phase.DESCENT

        if self.phase is Phase.DESCENT:
            setpoint = self.guidance.descend(observation)
        elif self.phase is Phase.FLARE:
            setpoint = self.guidance.hold(observation, c.hold_height_m)
        elif seen:
            setpoint = self.guidance.hold(observation, c.hold_height_m)
            if not self.guidance.aligned(observation):
                # centre first, then descend: the tag stays in view on the way down
                setpoint = VelocitySetpoint(
                    np.array([*setpoint.velocity_h[:2], max(setpoint.velocity_h[2], 0.0)]),
                    setpoint.yaw_rate,
                )
        else:
            towards = self._deck_direction(observation)
            if towards is not None:
                setpoint = VelocitySetpoint(np.array([*(c.edge_seek_speed * towards), 0.0]), 0.0)
            elif observation["tof_valid"].any():
                setpoint = VelocitySetpoint(np.array([0.0, 0.0, c.search_climb_speed]), 0.0)
            else:
                # nothing within the ToF range below: high above the sea, safe to come down
                setpoint = VelocitySetpoint(np.array([0.0, 0.0, -c.search_climb_speed]), 0.0)
        return action_from_setpoint(setpoint, self.action)

    def _deck_direction(self, observation: dict[str, np.ndarray]) -> np.ndarray | None:
        """Unit heading-frame direction towards the deck when the ToF ranges straddle its edge.

        The deck stands above the sea: sensors whose ranges are clearly shorter than the
        longest (a sensor without a return counts as longest) are over the deck.
        """
        valid = observation["tof_valid"].astype(bool)
        ranges = np.where(valid, observation["tof_range"].astype(float), np.inf)
        on_deck = ranges < np.max(ranges) - self.config.edge_step_m
        if not on_deck.any():
            return None
        vector = self._tof_directions[on_deck].sum(axis=0)
        norm = float(np.linalg.norm(vector))
        return vector / norm if norm > 0.0 else None


class AlignPredictivePolicy(AlignDescendPolicy):
    """``align-predictive``: ``align-descend``'s approach to the ``DeckLanding-v2`` hold band,
    its flare held at the band's height (the timing task's ``hold_height_m``), and ``land``
    sent when ``predictive``'s stopping rule holds on the observation's ``prediction`` (the
    deck-tilt predictor's best chance of a level deck at the contact at least the value of
    waiting on, :func:`~landing_env.anticipation.onboard_tilt_prediction.commit_by_prediction`).
    The environment then flies the timing task's descent, with its wave-off, inside the step.
    The teacher of the lander's imitation stage (:mod:`agents.training.imitation`)."""

    name = "align-predictive"

    def __init__(
        self,
        action: ActionConfig,
        hold_height_m: float,
        dt: float = 0.05,
        tof_mounts_c: np.ndarray | None = None,
    ) -> None:
        if not action.land_trigger:
            raise ConfigError(
                "action.land_trigger",
                "align-predictive commits through the land action: build the environment "
                "with action.land_trigger true (DeckLanding-v2's default)",
            )
        config = AlignDescendConfig(hold_height_m=hold_height_m, own_descent=False)
        super().__init__(action, config, dt=dt, tof_mounts_c=tof_mounts_c)

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        command = super().act(observation)
        command[-1] = 1.0 if commit_by_prediction(observation["prediction"]) else -1.0
        return command


def build_align_descend(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """``align-descend`` for ``env`` (a ``DeckLanding`` environment)."""
    base = env.unwrapped
    return AlignDescendPolicy(
        base.config.action, dt=base.env_dt, tof_mounts_c=base.config.tof.mount_offsets_c
    )


def build_align_predictive(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """``align-predictive`` for ``env`` (a ``DeckLanding-v2`` environment with the land action
    and the deck-tilt predictor's ``prediction`` observation)."""
    base = env.unwrapped
    prediction = getattr(base, "deck_prediction", None)
    if prediction is None or prediction.tilt_predictor is None:
        raise ConfigError(
            "timing.observation",
            "align-predictive reads the deck-tilt predictor's chances: fly it on a scenario "
            "with timing.observation prediction (bench-ss3, bench-ss4, bench-ss5)",
        )
    return AlignPredictivePolicy(
        base.config.action,
        base.timing.hold_height_m,
        dt=base.env_dt,
        tof_mounts_c=base.config.tof.mount_offsets_c,
    )
