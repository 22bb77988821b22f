"""The landing reward's terms, in one place for both tasks.

Each term is reported in ``info`` as ``reward_<term>`` (as Gymnasium's MuJoCo environments
do), and the step's reward is their sum.  The touchdown terms (:func:`touchdown_terms`) are
the same in ``DeckLanding-v2`` and ``DeckLandingTiming-v0``; the first adds potential-based
shaping, both charge the time flown.
"""

from __future__ import annotations

from landing_env.config import RewardConfig
from landing_env.touchdown import Outcome, TouchdownMetrics

#: every term, in the order ``info`` lists them
REWARD_TERMS: tuple[str, ...] = (
    "shaping",
    "time",
    "action_rate",
    "success",
    "touchdown",
    "crash",
    "normal_speed",
    "normal_speed_sq",
    "tilt",
    "offset",
)


def zero_terms() -> dict[str, float]:
    """Every term at zero (a reset, a step with nothing to reward)."""
    return dict.fromkeys(REWARD_TERMS, 0.0)


def touchdown_terms(
    outcome: Outcome,
    touchdown: TouchdownMetrics | None,
    reward: RewardConfig,
    touchdown_bonus: bool = False,
    speed_squared: bool = False,
) -> dict[str, float]:
    """The end-of-episode terms: ``-crash_penalty`` on a crash or a descent that never touched
    down (``TIMEOUT``); on any touchdown ``-(normal_speed_penalty * v_n + tilt_penalty * tilt_deg
    + offset_penalty * offset_m)`` (the normal speed counted only towards the deck),
    ``+touchdown_bonus`` where the task pays it (``DeckLanding``), with ``speed_squared``
    ``-normal_speed_sq_penalty * v_n**2`` more (``DeckLanding``: a hard touchdown costs more
    than in proportion), and ``+success_bonus`` on success; zero while in flight."""
    terms = {
        "success": 0.0,
        "touchdown": 0.0,
        "crash": 0.0,
        "normal_speed": 0.0,
        "normal_speed_sq": 0.0,
        "tilt": 0.0,
        "offset": 0.0,
    }
    if outcome in (Outcome.CRASH, Outcome.TIMEOUT):
        terms["crash"] = -reward.crash_penalty
        return terms
    if touchdown is None or outcome is Outcome.IN_FLIGHT:
        return terms
    speed = max(touchdown.relative_normal_speed, 0.0)
    terms["normal_speed"] = -reward.normal_speed_penalty * speed
    if speed_squared:
        terms["normal_speed_sq"] = -reward.normal_speed_sq_penalty * speed**2
    terms["tilt"] = -reward.tilt_penalty * touchdown.deck_tilt_deg
    terms["offset"] = -reward.offset_penalty * touchdown.lateral_offset_m
    if touchdown_bonus:
        terms["touchdown"] = reward.touchdown_bonus

    if outcome is Outcome.SUCCESS:
        terms["success"] = reward.success_bonus
    return terms


def reward_info(terms: dict[str, float]) -> dict[str, float]:
    """The terms as ``info`` entries: ``reward_<term>``."""
    return {f"reward_{name}": float(terms.get(name, 0.0)) for name in REWARD_TERMS}
