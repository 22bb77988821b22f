"""One action validation for both tasks, one touchdown penalty, the reward's terms in info."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import given, settings
from hypothesis import strategies as st

import landing_env  # noqa: F401  (registers the environments)
from landing_env.config import ActionConfig, RewardConfig
from landing_env.envs.actions import (
    action_from_setpoint,
    setpoint_from_action,
    validate_action,
)
from landing_env.envs.rewards import REWARD_TERMS, touchdown_terms
from landing_env.physics.controller import VelocitySetpoint
from landing_env.touchdown import Outcome, TouchdownMetrics

TIMING_OVERRIDES = {
    "simulation.drone_fixed": False,
    "camera.mode": "project",
    "estimation.compare": [],
    "start.max_offset_m": 0.1,
    "touchdown.settle_time_s": 0.3,
}
QUICK_TIMING = {"history_s": 0.5, "wait_limit_s": 3.0}

BAD_DISCRETE = ["1", [1, 0], True, np.bool_(False), [[0]], math.inf, [], None, 1.0, 2, -1]
BAD_BOX = [
    np.zeros((2, 2)),
    np.zeros(4, dtype=complex),
    [0.1, 0.2, 0.3],
    [0.0, 0.0, 0.0, math.nan],
    [0.0, 0.0, 0.0, math.inf],
    "abcd",
    None,
    [[0.0, 0.0], [0.0]],
    np.zeros(4, dtype=bool),
    np.zeros((1, 4)),
]


@pytest.mark.parametrize("action", BAD_DISCRETE, ids=repr)
def test_a_bad_discrete_action_is_refused_with_a_value_error(action: object) -> None:
    with pytest.raises(ValueError, match=r"action must be"):
        validate_action(action, spaces.Discrete(2), "0 = wait, 1 = commit")


@pytest.mark.parametrize("action", [0, 1, np.int64(1), np.array(0), np.array(1, dtype=np.int8)])
def test_integer_actions_of_the_space_pass(action: object) -> None:
    value = validate_action(action, spaces.Discrete(2))
    assert type(value) is int and value == int(action)  # type: ignore[call-overload]


@pytest.mark.parametrize("action", BAD_BOX, ids=lambda a: type(a).__name__)
def test_a_bad_box_action_is_refused_with_a_value_error(action: object) -> None:
    with pytest.raises(ValueError, match=r"action must be"):
        validate_action(action, spaces.Box(-1.0, 1.0, (4,), dtype=np.float32))


def test_box_actions_keep_every_value_and_out_of_bounds_values_pass_to_the_env() -> None:
    space = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
    out = validate_action([1, 0, 2.5, -1], space)
    assert out.dtype == np.float64 and out.tolist() == [1.0, 0.0, 2.5, -1.0]


def test_both_environments_refuse_bad_actions_before_moving() -> None:
    timing = gym.make(
        "DeckLandingTiming-v0",
        config="bench-ss4",
        overrides=TIMING_OVERRIDES,
        timing=QUICK_TIMING,
    )
    landing = gym.make("DeckLanding-v2")
    try:
        timing.reset(seed=0)
        landing.reset(seed=0)
        time_before = timing.unwrapped.world.time
        for action in ["1", [1, 0], True, [[0]], math.inf, [], None]:
            with pytest.raises(ValueError, match=r"0 = wait, 1 = commit"):
                timing.unwrapped.step(action)
        assert timing.unwrapped.world.time == time_before
        for action in (np.zeros((2, 2)), np.zeros(4, dtype=complex)):
            with pytest.raises(ValueError, match=r"shape \(5,\)"):
                landing.unwrapped.step(action)
        # and the episodes go on with good actions
        _, _, _, _, info = timing.step(np.int64(0))
        assert info["outcome"] == "in_flight"
        _, _, _, _, info = landing.step(np.zeros(landing.action_space.shape, dtype=np.float32))
        assert info["outcome"] == "in_flight"
    finally:
        timing.close()
        landing.close()


def test_setpoint_encoding_round_trips() -> None:
    config = ActionConfig()
    setpoint = VelocitySetpoint(np.array([0.6, -0.3, -0.5]), 0.4)
    back = setpoint_from_action(action_from_setpoint(setpoint, config), config)
    np.testing.assert_allclose(back.velocity_h, setpoint.velocity_h, atol=1e-6)
    assert back.yaw_rate == pytest.approx(0.4, abs=1e-6)


def test_touchdown_terms_penalise_speed_tilt_offset_and_reward_success() -> None:
    r = RewardConfig()
    metrics = TouchdownMetrics(relative_normal_speed=0.3, deck_tilt_deg=2.0, lateral_offset_m=0.04)
    terms = touchdown_terms(Outcome.SUCCESS, metrics, r)
    assert terms["success"] == r.success_bonus and terms["crash"] == 0.0
    assert terms["normal_speed"] == pytest.approx(-r.normal_speed_penalty * 0.3)
    assert terms["tilt"] == pytest.approx(-r.tilt_penalty * 2.0)
    assert terms["offset"] == pytest.approx(-r.offset_penalty * 0.04)
    hard = touchdown_terms(Outcome.HARD_LANDING, metrics, r)
    assert hard["success"] == 0.0 and hard["tilt"] == terms["tilt"]
    # the touchdown bonus only where the task pays it (DeckLanding), on any touchdown
    assert terms["touchdown"] == hard["touchdown"] == 0.0
    paid = touchdown_terms(Outcome.HARD_LANDING, metrics, r, touchdown_bonus=True)
    assert paid["touchdown"] == r.touchdown_bonus and paid["success"] == 0.0
    assert touchdown_terms(Outcome.CRASH, None, r, touchdown_bonus=True)["touchdown"] == 0.0
    # a failed touchdown within about 1 m/s and 5 degrees is worth more than a 40 s hover
    rough = TouchdownMetrics(relative_normal_speed=1.0, deck_tilt_deg=5.0, lateral_offset_m=0.1)
    failed = touchdown_terms(Outcome.HARD_LANDING, rough, r, touchdown_bonus=True)
    assert sum(failed.values()) > -r.time_cost * 40.0

    # moving away from the deck at contact is not penalised as speed
    metrics.relative_normal_speed = -0.1
    assert touchdown_terms(Outcome.SUCCESS, metrics, r)["normal_speed"] == 0.0
    for outcome in (Outcome.CRASH, Outcome.TIMEOUT):
        ended = touchdown_terms(outcome, None, r)
        assert ended["crash"] == -r.crash_penalty and sum(ended.values()) == -r.crash_penalty
    assert sum(touchdown_terms(Outcome.IN_FLIGHT, None, r).values()) == 0.0


def _terms(info: dict) -> dict[str, float]:
    return {name: info[f"reward_{name}"] for name in REWARD_TERMS}


def test_the_reward_is_the_sum_of_its_terms_in_info_in_both_tasks() -> None:
    timing = gym.make(
        "DeckLandingTiming-v0",
        config="bench-ss4",
        overrides=TIMING_OVERRIDES,
        timing=QUICK_TIMING,
    )
    landing = gym.make("DeckLanding-v2")
    try:
        _, info = timing.reset(seed=1)
        assert sum(_terms(info).values()) == 0.0
        _, reward, _, _, info = timing.step(0)
        assert info["reward_time"] < 0.0 and reward == pytest.approx(sum(_terms(info).values()))
        _, reward, terminated, _, info = timing.step(1)
        assert terminated and "touchdown" in info
        assert reward == pytest.approx(sum(_terms(info).values()))
        assert info["reward_tilt"] == pytest.approx(
            -RewardConfig().tilt_penalty * info["touchdown"]["deck_tilt_deg"]
        )
        landing.reset(seed=1)
        _, reward, _, _, info = landing.step(np.array([0.0, 0.0, -0.5, 0.0, -1.0]))
        assert info["reward_shaping"] != 0.0
        assert reward == pytest.approx(sum(_terms(info).values()))
    finally:
        timing.close()
        landing.close()


_ANYTHING = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.complex_numbers(),
    st.text(max_size=5),
    st.lists(st.floats(-2.0, 2.0), max_size=6),
    st.lists(st.lists(st.integers(-2, 2), max_size=3), max_size=3),
    st.builds(np.array, st.lists(st.floats(-3.0, 3.0, width=32), min_size=4, max_size=4)),
    st.builds(np.int64, st.integers(-3, 3)),
)


@settings(max_examples=300, deadline=None)
@given(_ANYTHING)
def test_fuzzed_actions_are_accepted_as_the_space_says_or_refused_with_a_value_error(
    action: object,
) -> None:
    discrete = spaces.Discrete(2)
    try:
        value = validate_action(action, discrete)
    except ValueError:
        pass
    else:
        assert type(value) is int and value in (0, 1)
    box = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
    try:
        array = validate_action(action, box)
    except ValueError:
        pass
    else:
        assert array.shape == (4,) and array.dtype == np.float64
        assert np.all(np.isfinite(array))
