"""The landing policies: calm prediction, the timing heuristics, align-descend, the registry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.evaluation.landing import LANDING_EVALUATION
from agents.evaluation.pipeline import run_episode
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.summary import markdown_table, summarise, wilson_interval
from agents.policies.align_descend import AlignDescendPolicy, Phase
from agents.policies.calm_window import CalmConfig, predict_calm
from agents.policies.registry import make_env_and_policy, make_policy
from agents.policies.svgs_routine import SvgsRoutinePolicy
from agents.policies.timing import LandNowPolicy
from estimation.frames import tilt_deg
from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.errors import ConfigError

DT = 0.05


def history_of(roll_deg: np.ndarray, pitch_deg: np.ndarray, z: float = 0.7) -> np.ndarray:
    """History rows (SI) of a deck with the given roll and pitch traces."""
    rows = np.zeros((len(roll_deg), len(HISTORY_FEATURES)))
    rows[:, 2] = z
    rows[:, 3] = np.radians(roll_deg)
    rows[:, 4] = np.radians(pitch_deg)
    rows[:, 9] = 1.0
    return rows


def test_tilt_is_the_angle_of_the_deck_normal() -> None:
    assert tilt_deg(0.0, 0.0) == pytest.approx(0.0)
    assert tilt_deg(math.radians(3.0), 0.0) == pytest.approx(3.0)
    assert tilt_deg(math.radians(3.0), math.radians(4.0)) == pytest.approx(5.0, abs=0.01)


def test_calm_prediction_judges_level_tilted_and_turning_decks() -> None:
    config = CalmConfig(window_s=1.0, descent_s=1.0, trend_weight=1.0, max_tilt_deg=3.0)
    n = 40
    level = predict_calm(history_of(np.full(n, 1.0), np.full(n, -1.0)), DT, config)
    assert level.calm and level.reason == ""
    tilted = predict_calm(history_of(np.full(n, 4.0), np.zeros(n)), DT, config)
    assert not tilted.calm and tilted.reason == "tilt in the window"
    # level now but rolling at 4 deg/s: 4 degrees within the 1 s descent (the last 0.5 s
    # stayed within 2 degrees)
    ramp = 4.0 * (np.arange(n) - (n - 1)) * DT
    short_window = CalmConfig(window_s=0.5, descent_s=1.0, trend_weight=1.0, max_tilt_deg=3.0)
    rising = predict_calm(history_of(ramp, np.zeros(n)), DT, short_window)
    assert not rising.calm and rising.reason == "tilt predicted"
    assert rising.predicted_tilt_deg == pytest.approx(4.0, abs=1e-6)
    # the same ramp with a persistence prediction (no trend) counts as calm
    persistent = predict_calm(
        history_of(ramp, np.zeros(n)), DT, CalmConfig(window_s=0.2, trend_weight=0.0)
    )
    assert persistent.calm
    # the deck falling away at 0.3 m/s (tag z growing) fails the heave check
    falling = history_of(np.zeros(n), np.zeros(n))
    falling[:, 2] = 0.7 + 0.3 * np.arange(n) * DT
    heave = predict_calm(falling, DT, config)
    assert heave.reason == "heave rate" and heave.heave_rate == pytest.approx(-0.3)
    # too few valid estimates: no judgement, no commit
    blind = history_of(np.zeros(n), np.zeros(n))
    blind[-10:, 9] = 0.0
    assert predict_calm(blind, DT, config).reason == "too few valid estimates"


def test_calm_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="trend_weight"):
        CalmConfig(trend_weight=2.0)
    with pytest.raises(ConfigError, match="max_tilt_deg"):
        CalmConfig(max_tilt_deg=0.0)


def test_align_descend_seeks_the_deck_with_the_tof_ranges() -> None:
    policy = AlignDescendPolicy()
    mounts = np.asarray(policy._tof_directions)
    # the two sensors on the forward side see the deck (0.6 m nearer than the sea)
    forward = mounts[:, 0] > 0.0
    observation = {
        "deck_pose": np.zeros(6, dtype=np.float32),
        "deck_pose_valid": np.array([0], dtype=np.int8),
        "tof_range": np.where(forward, 2.0, 2.6).astype(np.float32),
        "tof_valid": np.ones(4, dtype=np.int8),
    }
    action = policy.act(observation)
    assert action[0] > 0.1 and abs(action[1]) < 1e-6 and action[2] == 0.0
    # every sensor on the sea: climb to bring the tag into view
    observation["tof_range"] = np.full(4, 2.6, dtype=np.float32)
    assert policy.act(observation)[2] > 0.0
    # nothing within the ToF range: far above everything, come down
    observation["tof_valid"] = np.zeros(4, dtype=np.int8)
    assert policy.act(observation)[2] < 0.0


def test_align_descend_lands_from_far_off_the_deck_on_the_papers_bench() -> None:
    env, policy = make_env_and_policy("align-descend", "paper-stewart")
    try:
        # 3.5 m up and 0.8 m off: the tag is seen, every ToF spot on the sea
        observation, _ = env.reset(seed=4, options={"height_m": 3.5, "offset_m": (0.8, 0.0)})
        policy.reset()
        phases = set()
        while True:
            observation, _, terminated, truncated, info = env.step(policy(observation))
            phases.add(policy.phase)
            if terminated or truncated:
                break
    finally:
        env.close()
    assert phases == {Phase.APPROACH, Phase.FLARE, Phase.DESCENT}
    assert info["outcome"] == "success", info.get("touchdown")
    assert info["touchdown"]["deck_tilt_deg"] < 5.0


def test_timing_heuristics_on_a_sea_state_deck() -> None:
    env, quiescent = make_env_and_policy("quiescent", "bench-ss4")
    try:
        land_now = make_policy("land-now", env)
        assert isinstance(land_now, LandNowPolicy)
        now = run_episode(env, land_now, 7, "land-now", "bench-ss4")
        waited = run_episode(env, quiescent, 7, "quiescent", "bench-ss4")
    finally:
        env.close()
    assert now.wait_s == 0.0
    assert math.isfinite(now.relative_normal_speed)
    # the quiescent policy commits only on a calm prediction (or at the wait limit)
    assert waited.wait_s >= 0.0
    if waited.wait_s < 15.0:
        assert quiescent.last is not None and quiescent.last.calm
    assert waited.deck_tilt_deg < 5.0


def test_unknown_policy_and_scenario_name_the_choices() -> None:
    with pytest.raises(ConfigError, match=r"policy.*align-descend"):
        make_env_and_policy("hover", "bench-ss4")
    with pytest.raises(ConfigError, match=r"scenario.*bench-ss3"):
        make_env_and_policy("land-now", "bench-ss9")


def test_wilson_interval_and_summary() -> None:
    low, high = wilson_interval(95, 100)
    # Wilson: (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n), z = 1.95996
    z, n, p = 1.959964, 100, 0.95
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert low == pytest.approx(centre - half, abs=1e-6)
    assert high == pytest.approx(centre + half, abs=1e-6)
    results = [
        EpisodeRecord("p", "s", 0, "success", True, 0.2, 1.0, 0.01, 1.0, 5.0),
        EpisodeRecord("p", "s", 1, "hard_landing", False, 0.6, 6.0, 0.03, 6.0, 7.0),
        EpisodeRecord("p", "s", 2, "crash", False),
    ]
    summary = summarise(results)
    assert summary.successes == 1 and summary.success_rate == pytest.approx(1 / 3)
    assert summary.normal_speed_mean == pytest.approx(0.4)
    assert summary.time_to_land_mean_s == pytest.approx(6.0)
    assert summary.outcomes == {"success": 1, "hard_landing": 1, "crash": 1}
    table = markdown_table([summary], LANDING_EVALUATION.columns)
    assert "33.3%" in table and table.count("\n") == 2


#: shipped configs of the Box(5) task: the ship at sea states 5-6, the held-out seas, the approach
BOX5_CONFIGS = ("ship-ss5", "ship-ss6", "ship-unseen-4", "ship-unseen-5", "svgs-100m")


@pytest.mark.slow
@pytest.mark.parametrize("config", [*BOX5_CONFIGS, "svgs-100m-irlock"])
def test_every_landing_policy_and_random_actions_fly_40_steps_on_the_box5_configs(
    config: str,
) -> None:
    """Each landing policy made for the config (align-descend everywhere, the SVGS routine
    and the beacon baseline on their approach configs) and actions drawn from the space give
    actions of the space's shape, in the project camera mode, 40 steps each (2 s)."""
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the ids)
    from agents.policies.registry import POLICIES

    names = ["align-descend"]
    names += [n for n in ("svgs-routine", "beacon-range") if config in POLICIES[n].scenarios]
    for name in [*names, "random"]:
        overrides = {"camera.mode": "project"}
        estimator = POLICIES[name].estimator if name != "random" else None
        if estimator:
            overrides["estimation.observed"] = estimator
        env = gym.make("DeckLanding-v2", config=config, overrides=overrides)
        try:
            assert env.action_space.shape == (5,)
            policy = None if name == "random" else make_policy(name, env)
            env.action_space.seed(0)
            observation, _ = env.reset(seed=3)
            if policy is not None and hasattr(policy, "reset"):
                policy.reset()
            for _ in range(40):
                action = env.action_space.sample() if policy is None else policy(observation)
                assert np.shape(action) == (5,), (name, config)
                observation, _, terminated, truncated, _ = env.step(action)
                assert env.observation_space.contains(observation)
                if terminated or truncated:
                    observation, _ = env.reset()
                    if policy is not None and hasattr(policy, "reset"):
                        policy.reset()
        finally:
            env.close()


def _landing_policies_and_their_scenarios() -> list[tuple[str, str]]:
    """(policy, scenario) for every registered policy of the landing task that flies without
    a model of the user's, on every scenario it is made for (all of its task's where it names
    none)."""
    from agents.policies.registry import POLICIES
    from landing_env.scenarios import APPROACH_SCENARIOS, LANDING_TASK, SCENARIOS

    of_the_task = [
        name for name, s in {**SCENARIOS, **APPROACH_SCENARIOS}.items() if LANDING_TASK in s.ids
    ]
    return [
        (name, scenario)
        for name, spec in POLICIES.items()
        if spec.task == LANDING_TASK and (spec.kind != "trained" or spec.model is not None)
        for scenario in (spec.scenarios or of_the_task)
    ]


@pytest.mark.slow
@pytest.mark.parametrize(("policy_name", "scenario"), _landing_policies_and_their_scenarios())
def test_every_landing_policy_built_by_the_registry_acts_inside_its_scenarios_action_space(
    policy_name: str, scenario: str
) -> None:
    """What ``evaluate landing --policy P --scenario S`` and ``evaluate approach`` build: the
    scenario's id with the policy's settings, and the policy in it; its first actions lie in
    that environment's action space (the land entry included)."""
    env, policy = make_env_and_policy(policy_name, scenario)
    try:
        observation, _ = env.reset(seed=1)
        policy.reset()
        for _ in range(3):
            action = policy(observation)
            assert np.shape(action) == env.action_space.shape, (policy_name, scenario)
            assert env.action_space.contains(np.asarray(action, dtype=np.float32))
            observation, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    finally:
        env.close()


def test_a_scripted_policys_guidance_runs_at_the_policys_own_control_period() -> None:
    # at 40 Hz a timed descent's clock advances 25 ms a period, not the default 50 ms
    assert AlignDescendPolicy(dt=0.025).guidance.dt == 0.025
    assert SvgsRoutinePolicy(dt=0.025, timing_model=None).guidance.dt == 0.025
