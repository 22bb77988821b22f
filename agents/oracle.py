"""``oracle``: the best timing any policy of the timing task could choose (privileged).

The deck motion, the wind and every sensor's noise are deterministic functions of time given
the episode's seed, so the touchdown that a commit *now* would give can be found exactly by
trying it: the oracle saves the environment's state (:mod:`landing_env.envs.snapshot`),
commits, reads the touchdown, and restores the state.  It does so at every decision of the
episode, in order, waiting between them as the guidance holds, and then commits at the
**first moment whose touchdown passes every criterion** (the environment's own judgement, so
new criteria count without a change here) and, within that first run of passing moments (its
first ``max_window_s``: later moments of a long calm spell gain little margin and cost look-ahead
time), at the one with the **largest margin** (:func:`touchdown_margin`).  When no moment passes it
commits where the margin is least negative: no timing could have landed that episode.

Its success over a set of seeds is therefore the upper bound of every timing policy's success
on those seeds (the descent is the same guidance the other policies fly); the gap between a
policy and the oracle is what better timing could still win, and the oracle's failures are
the part of a policy's failures no timing could avoid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from landing_env.config import TouchdownConfig
from landing_env.envs.snapshot import restore_snapshot, save_snapshot
from landing_env.errors import require_range
from landing_env.touchdown import Outcome

#: the margin of an episode that did not touch down (crash, descent timeout)
NO_TOUCHDOWN_MARGIN = -math.inf


def touchdown_margin(touchdown: dict[str, Any] | None, thresholds: TouchdownConfig) -> float:
    """The smallest relative slack of the graded criteria: ``1 - value / limit`` of the normal
    speed, the deck tilt and the relative attitude (1 = perfectly gentle and level, 0 = on a
    limit, negative = beyond it); ``-inf`` without a touchdown."""
    if not touchdown:
        return NO_TOUCHDOWN_MARGIN
    slacks = (
        1.0 - max(float(touchdown["relative_normal_speed"]), 0.0) / thresholds.max_normal_speed,
        1.0 - float(touchdown["deck_tilt_deg"]) / max(thresholds.max_deck_tilt_deg, 1e-9),
        1.0
        - float(touchdown["relative_attitude_deg"])
        / max(thresholds.max_relative_attitude_deg, 1e-9),
    )
    margin = min(slacks)
    return margin if math.isfinite(margin) else NO_TOUCHDOWN_MARGIN


@dataclass
class Candidate:
    """The touchdown a commit after ``waits`` decisions to wait would give."""

    waits: int
    outcome: str
    margin: float
    #: the environment forced this commit (the wait limit), the policy did not choose it
    forced: bool = False


@dataclass
class OraclePlan:
    """What the oracle found for one episode and what it chose."""

    candidates: list[Candidate] = field(default_factory=list)
    chosen: Candidate | None = None

    @property
    def feasible(self) -> bool:
        """Some moment of the episode lands successfully."""
        return any(c.outcome == Outcome.SUCCESS.value for c in self.candidates)


def choose(candidates: list[Candidate]) -> Candidate:
    """The first run of successful candidates' best margin, else the best margin overall."""
    if not candidates:
        raise ValueError("no candidates to choose from")
    run: list[Candidate] = []
    for candidate in candidates:
        if candidate.outcome == Outcome.SUCCESS.value:
            run.append(candidate)
        elif run:
            break
    pool = run or candidates
    return max(pool, key=lambda c: (c.margin, -c.waits))


class OracleTimingPolicy:
    """Commit at the best moment, found by trying every commit in a saved copy of the episode.

    Acts in ``DeckLandingTiming-v0`` like the other timing policies (0 = wait, 1 = commit), but
    reads the environment it was built for, not only the observation.  ``last_plan`` holds the
    latest episode's candidates and choice.
    """

    name = "oracle"

    def __init__(self, env: Any, max_window_s: float = 2.0) -> None:
        self.env = env.unwrapped
        if not hasattr(self.env, "layout"):
            raise TypeError("the oracle acts in DeckLandingTiming-v0")
        require_range("max_window_s", max_window_s, 0.0)
        decision_s = self.env.env_dt * self.env.timing.steps_per_decision
        #: most successful candidates tried in the first window
        self.max_window = max(1, math.floor(max_window_s / decision_s + 1e-9) + 1)
        self.last_plan: OraclePlan | None = None
        self._decisions = 0

    def reset(self) -> None:
        self.last_plan = None
        self._decisions = 0

    def __call__(self, observation: np.ndarray) -> int:
        return self.act(observation)

    def act(self, observation: np.ndarray) -> int:
        del observation  # the oracle reads the environment
        if self.last_plan is None:
            self.last_plan = self.plan()
        assert self.last_plan.chosen is not None
        waits = self._decisions
        self._decisions += 1
        return int(waits >= self.last_plan.chosen.waits)

    def plan(self) -> OraclePlan:
        """Try every commit from the current decision on; the environment is left as found."""
        env = self.env
        thresholds = env.config.touchdown
        plan = OraclePlan()
        start = save_snapshot(env)
        try:
            waits = 0
            while True:
                here = save_snapshot(env)
                _, _, _, _, info = env.step(1)
                plan.candidates.append(
                    Candidate(
                        waits, info["outcome"], touchdown_margin(info.get("touchdown"), thresholds)
                    )
                )
                restore_snapshot(env, here, keep=False)
                passed = [c.outcome == Outcome.SUCCESS.value for c in plan.candidates]
                if len(passed) >= 2 and passed[-2] and not passed[-1]:
                    break  # the first run of successful moments has ended
                if sum(passed) >= self.max_window:
                    break  # long enough into the first run
                _, _, terminated, truncated, info = env.step(0)
                waits += 1
                if terminated or truncated:
                    # the wait limit forced the commit (or the hold itself ended the episode)
                    plan.candidates.append(
                        Candidate(
                            waits,
                            info["outcome"],
                            touchdown_margin(info.get("touchdown"), thresholds),
                            forced=True,
                        )
                    )
                    break
        finally:
            restore_snapshot(env, start, keep=False)
        plan.chosen = choose(plan.candidates)
        return plan
