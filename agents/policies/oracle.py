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

from agents.policies.base import Policy
from landing_env.config import TouchdownConfig
from landing_env.envs.snapshot import restore_snapshot, save_snapshot
from landing_env.errors import require_range
from landing_env.scenarios import TIMING_TASK
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


class OracleTimingPolicy(Policy):
    """Commit at the best moment, found by trying every commit in a saved copy of the episode.

    Acts in ``DeckLandingTiming-v0`` like the other timing policies (0 = wait, 1 = commit), but
    reads the environment it was built for, not only the observation.  ``last_plan`` holds the
    latest episode's candidates and choice.
    """

    name = "oracle"

    def __init__(self, env: Any, max_window_s: float = 2.0) -> None:
        self.env = env.unwrapped
        if not hasattr(self.env, "layout"):
            raise TypeError(f"the oracle acts in {TIMING_TASK}")
        require_range("max_window_s", max_window_s, 0.0)
        decision_s = self.env.env_dt * self.env.timing.steps_per_decision
        #: most successful candidates tried in the first window
        self.max_window = max(1, math.floor(max_window_s / decision_s + 1e-9) + 1)
        self.last_plan: OraclePlan | None = None
        self._decisions = 0

    def reset(self) -> None:
        self.last_plan = None
        self._decisions = 0

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


@dataclass(frozen=True)
class TriedCommit:
    """One look-ahead's commit: whether it counts as landing (:meth:`DeckOracleTimingPolicy.lands`:
    success with the required slack), whether it succeeded at all, and its
    :func:`touchdown_margin`."""

    lands: bool
    success: bool
    margin: float


class DeckOracleTimingPolicy(Policy):
    """``deck-oracle``: the bound of deck prediction in the strict sense, the timing that
    **knows the deck's future motion** and nothing else to come.

    :class:`OracleTimingPolicy` knows the whole future: the deck's, and also the gusts' and
    every sensor's noise (they are all fixed by the episode's seed), so it commits where the
    wind will happen to be kind; no policy on board could foresee a gust's innovations, and
    a share of its lead over every policy is that foresight.  This oracle acts causally: at
    every ``check_every_s`` of the wait it tries a commit *now* in ``draws`` futures that share
    the deck's motion (a fixed function of time) and the present state (the drone, the gust,
    the estimates) but draw the gusts' innovations and the sensors' noise anew
    (:meth:`~landing_env.world.World.redraw_unknowable_future`), and commits at the
    first moment where at least ``min_chance`` of them land.  The episode
    itself then goes on with its own future.  Its success is what a timing policy with
    perfect deck prediction reaches with this rule: the part of the full oracle's lead that
    better deck sensing and prediction could win; the rest is the wind's.
    """

    name = "deck-oracle"

    def __init__(
        self,
        env: Any,
        draws: int = 16,
        min_chance: float = 1.0,
        check_every_s: float = 0.2,
        seed: int = 0,
        min_margin: float = 0.0,
    ) -> None:
        self.env = env.unwrapped
        if not hasattr(self.env, "layout"):
            raise TypeError(f"{self.name} acts in {TIMING_TASK}")
        require_range("draws", draws, 1, 64)
        require_range("min_margin", min_margin, 0.0, 1.0)
        #: a tried commit lands only with this much slack on every graded criterion
        self.min_margin = float(min_margin)
        require_range("min_chance", min_chance, 0.0, 1.0, low_inclusive=False)
        decision_s = self.env.env_dt * self.env.timing.steps_per_decision
        require_range("check_every_s", check_every_s, decision_s - 1e-9, 10.0)
        self.draws = int(draws)
        self.min_chance = float(min_chance)
        #: decisions between two look-aheads
        self.stride = max(1, round(check_every_s / decision_s))
        self.seed = int(seed)
        self._decisions = 0
        #: (decision, chance) of each look-ahead of the episode so far
        self.chances: list[tuple[int, float]] = []

    def reset(self) -> None:
        self._decisions = 0
        self.chances = []

    def act(self, observation: np.ndarray) -> int:
        del observation  # the oracle reads the environment
        decision = self._decisions
        self._decisions += 1
        if decision % self.stride:
            return 0
        chance = self.chance(decision)
        self.chances.append((decision, chance))
        return int(chance >= self.min_chance - 1e-12)

    def chance(self, decision: int = 0) -> float:
        """The share of ``draws`` futures (the deck's own, the rest drawn anew) in which a
        commit now lands; the environment is left as found.  It stops trying once
        ``min_chance`` is out of reach."""
        tries = self.try_commits(decision, self.min_chance * self.draws - 1e-9)
        if tries is None:
            return 0.0  # no future to try (a forecast that cannot be made): wait
        return sum(t.lands for t in tries) / self.draws

    def try_commits(self, decision: int = 0, needed: float = 0.0) -> list[TriedCommit] | None:
        """A commit now tried in each of ``draws`` futures (the deck's own, the rest drawn
        anew), in order; the environment is left as found.  It stops once fewer than
        ``needed`` of them could land (0: try them all).  None when there is no deck future
        to try (a forecast that cannot be made)."""
        env = self.env
        episode_seed = int(env.np_random_seed) % 2**32
        deck_future = self.deck_future(decision)
        if deck_future is None:
            return None
        tries: list[TriedCommit] = []
        landed = 0
        here = save_snapshot(env)
        try:
            for k in range(self.draws):
                restore_snapshot(env, here, keep=True)
                sequence = np.random.SeedSequence([self.seed, episode_seed, decision, k])
                env.world.redraw_unknowable_future(np.random.default_rng(sequence))
                if deck_future is not True:
                    env.world.stewart.motion = deck_future
                self.model_draw(decision, k)
                _, _, _, _, info = env.step(1)
                tried = TriedCommit(
                    lands=self.lands(info),
                    success=info["outcome"] == Outcome.SUCCESS.value,
                    margin=touchdown_margin(info.get("touchdown"), env.config.touchdown),
                )
                tries.append(tried)
                landed += int(tried.lands)
                if landed + (self.draws - k - 1) < needed:
                    break  # the rest cannot reach min_chance
        finally:
            restore_snapshot(env, here, keep=False)
        return tries

    def deck_future(self, decision: int = 0) -> Any:
        """The deck's motion the look-ahead of ``decision`` plays: ``True`` for the episode's
        own (this oracle's), a motion source to play instead, or None when there is none
        (wait)."""
        del decision
        return True

    def model_draw(self, decision: int, draw: int) -> None:
        """Change the restored copy before look-ahead ``draw`` of ``decision`` plays it: what
        the look-ahead does not know of the present (this oracle knows it all: nothing)."""
        del decision, draw

    def lands(self, info: dict[str, Any]) -> bool:
        """Whether a tried commit counts as landing: success, and at least ``min_margin``
        of slack on the graded criteria (:func:`touchdown_margin`)."""
        if info["outcome"] != Outcome.SUCCESS.value:
            return False
        if self.min_margin <= 0.0:
            return True
        return touchdown_margin(info.get("touchdown"), self.env.config.touchdown) >= (
            self.min_margin - 1e-12
        )


def build_oracle(env: Any, model_path: str | None, allow: tuple[str, ...]) -> OracleTimingPolicy:
    """``oracle`` for ``env`` (:mod:`agents.policies.registry`'s builder)."""
    return OracleTimingPolicy(env)


def build_deck_oracle(
    env: Any, model_path: str | None, allow: tuple[str, ...]
) -> DeckOracleTimingPolicy:
    """``deck-oracle`` for ``env`` (:mod:`agents.policies.registry`'s builder)."""
    return DeckOracleTimingPolicy(env)
