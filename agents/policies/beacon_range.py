"""``beacon-range``: the IR-LOCK / PX4 precision-landing baseline on ``DeckLanding-v2``.

It knows what an IR-LOCK camera and a downward rangefinder give: the bearing to the beacon's
centre and one range, turned into a position by the ``beacon`` estimator
(:mod:`estimation.beacon`, ``estimation.observed: beacon``; the observation's orientation
fields are zeros; the beacon is seen only within ``estimation.beacon.max_range_m``, the
IR-LOCK's 40 m), and the height from the rangefinder (``range_down``).  No deck orientation,
no deck-motion timing.  As PX4 does, it steers on the landing-target filter's estimate
(:class:`estimation.landing_target.LandingTargetFilter`: the beacon's relative position
propagated with the vehicle's acceleration from the IMU, each fix through a 10-SD innovation
gate, SVGS paper Table 1), not on the raw fixes.  It flies PX4's precision-landing states
(``PrecLand``):

* ``horizontal_approach``: centre over the beacon at the current height, until within
  ``acceptance_radius_m``;
* ``descend_above_target``: descend while centring, at ``descent_speed`` high up,
  ``land_speed`` below ``slow_height_m`` and ``crawl_speed`` below ``crawl_height_m`` (PX4's
  MPC_LAND_* speeds with a distance sensor);
* ``final_approach``: below ``final_approach_height_m``, straight down without corrections;
* ``search``: no fix accepted for ``beacon_timeout_s`` above the final-approach height: go
  to ``search_height_m`` (climbing or descending, as PX4's PLD_SRCH_ALT) and hover for
  ``search_timeout_s``; found: approach again; after ``max_searches`` searches (20, the SVGS
  paper's setting, Sec. 2.5.4) ``fallback``: land in place.

The horizontal offset is levelled with the attitude from the IMU (PX4 rotates the beacon's
ray into the local frame with the vehicle attitude), by the same filter as the SVGS routine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from agents.policies.svgs_routine import GRAVITY, ApproachStateMachine, levelled_offset
from estimation.landing_target import (
    ACCEPTED,
    INITIALISED,
    LandingTargetConfig,
    LandingTargetFilter,
)
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited
from landing_env.config import ActionConfig
from landing_env.errors import ConfigError
from landing_env.physics.controller import VelocitySetpoint


class PrecLandState(str, Enum):
    """PX4 ``PrecLand`` states."""

    HORIZONTAL_APPROACH = "horizontal_approach"
    DESCEND_ABOVE_TARGET = "descend_above_target"
    FINAL_APPROACH = "final_approach"
    SEARCH = "search"
    FALLBACK = "fallback"


@dataclass
class BeaconRangeConfig(Limited):
    """Settings of the baseline (PX4 parameter names in the comments)."""

    #: horizontal acceptance radius before the descent, metres (PLD_HACC_RAD)
    acceptance_radius_m: float = limited(0.2, POSITIVE)
    #: below this height the descent goes on blind, metres (PLD_FAPPR_ALT)
    final_approach_height_m: float = limited(0.3, NON_NEGATIVE)
    #: beacon lost after this long without it, seconds (PLD_BTOUT)
    beacon_timeout_s: float = limited(2.0, NON_NEGATIVE)
    #: climb to this height to search, metres (PLD_SRCH_ALT)
    search_height_m: float = limited(20.0, NON_NEGATIVE)
    #: hover this long at the search height, seconds (PLD_SRCH_TOUT)
    search_timeout_s: float = limited(10.0, NON_NEGATIVE)
    #: searches before landing in place (PLD_MAX_SRCH; the SVGS paper's IR-LOCK flights: 20)
    max_searches: int = limited(20, Limit(0, 100))
    #: descent speeds, m/s, and the heights where they change, metres (MPC_LAND_*)
    descent_speed: float = limited(1.0, POSITIVE)
    land_speed: float = limited(0.5, POSITIVE)
    crawl_speed: float = limited(0.3, POSITIVE)
    slow_height_m: float = limited(5.0, NON_NEGATIVE)
    crawl_height_m: float = limited(1.0, NON_NEGATIVE)
    #: horizontal velocity per metre of offset, 1/s, and its limit, m/s
    k_xy: float = limited(0.8, POSITIVE)
    max_horizontal_speed: float = limited(1.0, POSITIVE)
    climb_speed: float = limited(1.0, POSITIVE)
    #: the attitude filter's accelerometer gain, 1/s (see
    #: agents.policies.svgs_routine.AttitudeFilter)
    attitude_gain: float = limited(0.2, POSITIVE)
    #: the landing-target filter (gate in standard deviations: 10, the paper's)
    target_filter: LandingTargetConfig = field(default_factory=LandingTargetConfig)


class BeaconRangePolicy(ApproachStateMachine):
    """PX4-style precision landing on the beacon estimate (see the module docstring)."""

    name = "beacon-range"

    def __init__(
        self,
        action: ActionConfig | None = None,
        config: BeaconRangeConfig | None = None,
        dt: float = 0.05,
    ) -> None:
        super().__init__(action, config or BeaconRangeConfig(), dt)
        self.target = LandingTargetFilter(self.config.target_filter)
        self.reset()

    def reset(self) -> None:
        self._start(PrecLandState.HORIZONTAL_APPROACH)
        self.target.reset()
        self.searches = 0
        self._height = math.nan
        self._hover_s = 0.0
        self._search_from_m = math.nan

    def _enter(self, state: PrecLandState, reason: str) -> None:
        super()._enter(state, reason)
        self._hover_s = 0.0

    def height_m(self, observation: dict[str, np.ndarray]) -> float:
        """The rangefinder's range (the last one when it has none), else the beacon's z."""
        if observation["range_down_valid"][0]:
            self._height = float(observation["range_down"][0])
        elif observation["deck_pose_valid"][0]:
            self._height = float(observation["deck_pose"][2])
        return self._height

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        imu = np.asarray(observation["imu"], dtype=float)
        self.attitude.update(imu)
        r_hb = self.attitude.level_from_body()
        # the vehicle's acceleration in the levelled heading frame: the filter's input
        accel_h = r_hb @ imu[:3] - np.array([0.0, 0.0, GRAVITY])
        self.target.predict(accel_h[:2], self.dt)
        fused = False
        if observation["deck_pose_valid"][0]:
            fix = levelled_offset(observation["deck_pose"], r_hb)
            result = self.target.update(np.array(fix[:2]), math.hypot(*fix))
            fused = result in (ACCEPTED, INITIALISED)
        self._unseen_s = 0.0 if fused else self._unseen_s + self.dt
        height = self.height_m(observation)
        # PX4 steers on the filter's estimate, predicted between fixes, while it is valid
        offset = (
            (*(float(v) for v in self.target.position_xy), height) if self.target.valid else None
        )
        self._transition(offset, height)
        return self._act(self._command(offset, height))

    def _transition(self, offset: tuple[float, float, float] | None, height: float) -> None:
        c = self.config
        s = self.state
        if s in (PrecLandState.FINAL_APPROACH, PrecLandState.FALLBACK):
            return
        low = math.isfinite(height) and height < c.final_approach_height_m
        if s is PrecLandState.SEARCH:
            if self._unseen_s == 0.0:
                self._enter(PrecLandState.HORIZONTAL_APPROACH, "beacon found")
            else:
                at_height = math.isfinite(height) and abs(height - c.search_height_m) < 0.5
                self._hover_s = self._hover_s + self.dt if at_height else self._hover_s
                # the climb may never end (a ceiling, a sensor fault): bound the whole search
                # by twice the time the height change takes at the slower of the two speeds
                change = abs(self._search_from_m - c.search_height_m)
                change = change if math.isfinite(change) else c.search_height_m
                climb_limit = 2.0 * (change + 1.0) / min(c.climb_speed, c.descent_speed)
                if self._hover_s > c.search_timeout_s or self._state_s > (
                    c.search_timeout_s + climb_limit
                ):
                    self._search_or_fallback("search timed out")
            return
        if self._unseen_s > c.beacon_timeout_s:
            if low:
                self._enter(PrecLandState.FINAL_APPROACH, "beacon lost near the ground")
            else:
                self._search_or_fallback("beacon lost")
            return
        if offset is None:
            return
        if low:
            self._enter(PrecLandState.FINAL_APPROACH, "below the final-approach height")
        elif s is PrecLandState.HORIZONTAL_APPROACH:
            if math.hypot(offset[0], offset[1]) < c.acceptance_radius_m:
                self._enter(PrecLandState.DESCEND_ABOVE_TARGET, "over the beacon")

    def _search_or_fallback(self, reason: str) -> None:
        if self.searches >= self.config.max_searches:
            self._enter(PrecLandState.FALLBACK, f"{reason}; searches exhausted: land in place")
        else:
            self.searches += 1
            self._search_from_m = self._height
            self._enter(PrecLandState.SEARCH, f"{reason}: search {self.searches}")

    def _descent_speed(self, height: float) -> float:
        c = self.config
        if not math.isfinite(height) or height < c.crawl_height_m:
            return c.crawl_speed
        return c.land_speed if height < c.slow_height_m else c.descent_speed

    def _command(
        self, offset: tuple[float, float, float] | None, height: float
    ) -> VelocitySetpoint:
        c = self.config
        s = self.state
        if s in (PrecLandState.FINAL_APPROACH, PrecLandState.FALLBACK):
            return VelocitySetpoint(np.array([0.0, 0.0, -self._descent_speed(height)]), 0.0)
        if s is PrecLandState.SEARCH:
            # no height (above the rangefinder's reach, which is above the search height):
            # descend until the rangefinder measures one
            vz = -c.descent_speed
            if math.isfinite(height):
                vz = float(np.clip(c.search_height_m - height, -c.descent_speed, c.climb_speed))
            return VelocitySetpoint(np.array([0.0, 0.0, vz]), 0.0)
        if offset is None:
            # no valid target estimate yet: hold still, as PX4 holds its last set-point
            return VelocitySetpoint(np.zeros(3), 0.0)
        velocity = c.k_xy * np.array(offset[:2])
        speed = float(np.linalg.norm(velocity))
        if speed > c.max_horizontal_speed:
            velocity *= c.max_horizontal_speed / speed
        vz = 0.0
        if s is PrecLandState.DESCEND_ABOVE_TARGET:
            vz = -self._descent_speed(height)
        return VelocitySetpoint(np.array([velocity[0], velocity[1], vz]), 0.0)


def make_beacon_range(env: Any, config: BeaconRangeConfig | None = None) -> BeaconRangePolicy:
    """The baseline for a ``DeckLanding-v2`` environment with ``estimation.observed: beacon``."""
    base = env.unwrapped
    if base.config.estimation.observed != "beacon":
        raise ConfigError(
            "estimation.observed",
            f"{base.config.estimation.observed!r}: beacon-range needs 'beacon' (bearing + range)",
        )
    return BeaconRangePolicy(base.config.action, config, dt=base.env_dt)


def build_beacon_range(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """``beacon-range`` (:mod:`agents.policies.registry`'s builder)."""
    return make_beacon_range(env)
