"""The timed final descent: its reference, the fixed commit-to-contact time it gives on the
bench, the bench ids that fly it, and the model cards that tell it from the range schedule."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import landing_env  # noqa: F401  (registers the environments)
from agents.common.cards import (
    LEGACY_OBSERVATION,
    check_compatible,
    descent_signature,
    env_signature,
    read_metadata,
)
from agents.policies.timing import SHIPPED_TIMING_MODEL
from landing_env.config import load_config
from landing_env.config_loading import nested_to_dotted
from landing_env.errors import ConfigError
from landing_env.guidance_gains import GuidanceGains
from landing_env.scenarios import BENCH_TIMING, SCENARIO_IDS
from landing_env.timing.guidance import DeckGuidance
from landing_env.timing.timed_descent import timed_descent_reference, timed_descent_references

REALISTIC = {"sensors": "realistic", "estimation.observed": "tight"}
RANGE_DESCENT = {"timing.guidance.descent_profile": "range"}


def test_the_reference_leaves_the_hold_at_rest_and_meets_the_deck_at_the_touchdown_speed() -> None:
    start, duration, speed, end = 0.7, 1.2, 0.25, 0.05
    assert timed_descent_reference(0.0, start, duration, speed, end) == pytest.approx((start, 0.0))
    assert timed_descent_reference(duration, start, duration, speed, end) == pytest.approx(
        (end, -speed)
    )
    # beyond its end it goes on down at the touchdown speed
    assert timed_descent_reference(duration + 0.4, start, duration, speed, end) == pytest.approx(
        (end - 0.4 * speed, -speed)
    )
    # in between it only goes down, and its rate is the derivative of its height
    t = np.linspace(0.0, duration, 241)
    heights = np.array([timed_descent_reference(s, start, duration, speed, end)[0] for s in t])
    rates = np.array([timed_descent_reference(s, start, duration, speed, end)[1] for s in t])
    assert np.all(np.diff(heights) < 0.0)
    np.testing.assert_allclose(np.gradient(heights, t)[1:-1], rates[1:-1], atol=2e-3)


def test_the_reference_of_many_descents_is_the_reference_of_each() -> None:
    duration, speed, end = 1.2, 0.25, 0.05
    t = np.array([[-0.3, 0.0, 0.4], [0.9, 1.2, 1.7]])
    start = np.array([[0.7, 0.9, 0.6], [0.8, 0.7, 1.1]])
    heights, rates = timed_descent_references(t, start, duration, speed, end)
    for i, j in np.ndindex(t.shape):
        one = timed_descent_reference(t[i, j], start[i, j], duration, speed, end)
        assert (heights[i, j], rates[i, j]) == pytest.approx(one, abs=1e-12)
    # without an end height the reference ends on the deck
    assert timed_descent_reference(duration, 0.7, duration, speed) == pytest.approx((0.0, -speed))
    assert timed_descent_references(np.array([duration]), np.array([0.7]), duration, speed) == (
        pytest.approx([0.0]),
        pytest.approx([-speed]),
    )
    # before the commit the reference waits at the start, at rest
    assert timed_descent_reference(-0.3, 0.7, duration, speed, end) == pytest.approx((0.7, 0.0))


def _contact_times(
    seeds: range, waits: tuple[int, ...], extra: dict | None = None
) -> tuple[list, list]:
    overrides = {**REALISTIC, "touchdown.settle_time_s": 0.3, **(extra or {})}
    env = gym.make("DeckLandingTiming-BenchSS4-v6", overrides=overrides)
    descents, speeds = [], []
    for seed in seeds:
        for wait in waits:
            env.reset(seed=seed)
            for _ in range(wait):
                env.step(0)
            _, _, terminated, _, info = env.step(1)
            assert terminated
            descents.append(info["descent_s"])
            speeds.append(info["touchdown"]["relative_normal_speed"])
    env.close()
    return descents, speeds


def test_the_timed_descent_touches_down_a_fixed_time_after_commit_unlike_the_range_schedule() -> (
    None
):
    seeds, waits = range(4), (0, 12, 25)
    timed, timed_speeds = _contact_times(seeds, waits)
    ranged, _ = _contact_times(seeds, waits, RANGE_DESCENT)
    # the 1.2 s reference plus the velocity loop's lag: 1.30 +- 0.06 s measured over 24 commits
    assert 1.15 < np.mean(timed) < 1.45
    assert np.std(timed) < 0.1
    assert np.std(ranged) > 2.0 * np.std(timed)
    assert np.mean(ranged) > np.mean(timed) + 0.3
    # and it still meets the deck gently: inside the 0.5 m/s limit with a margin
    assert max(timed_speeds) < 0.42


def test_a_gate_that_holds_the_timed_descent_stops_its_clock() -> None:
    guidance = DeckGuidance(GuidanceGains(descent_profile="timed", descent_time_s=1.0), dt=0.05)
    first = guidance._descent_speed(0.7)
    held = [guidance._descent_speed(0.7, progress=0.0) for _ in range(10)]
    # the clock has not moved: the reference is where it was one period in
    assert guidance._descent_clock_s == pytest.approx(0.05)
    assert all(h == pytest.approx(held[0]) for h in held)
    assert first >= 0.0
    # holding resets it: the next descent starts from the drone's height again
    guidance.hold(
        {
            "deck_pose": np.array([0, 0, 0.7, 0, 0, 0], np.float32),
            "deck_pose_valid": np.array([1]),
            "tof_range": np.full(4, 0.7, np.float32),
            "tof_valid": np.ones(4, bool),
        },
        0.7,
    )
    assert guidance._descent_clock_s is None


def test_bad_descent_settings_are_refused_with_their_key() -> None:
    with pytest.raises(ConfigError, match="descent_profile"):
        GuidanceGains(descent_profile="fast")
    with pytest.raises(ConfigError, match="descent_time_s"):
        GuidanceGains(descent_time_s=0.0)
    with pytest.raises(ConfigError, match="contact_range_m"):
        GuidanceGains(contact_range_m=-0.1)


def test_the_bench_ids_fly_the_timed_descent_unless_told_the_range_schedule() -> None:
    for n in (3, 4, 5):
        overrides = SCENARIO_IDS[f"DeckLandingTiming-BenchSS{n}-v6"].overrides
        assert overrides["timing.guidance.descent_profile"] == "timed"
    env = gym.make("DeckLandingTiming-BenchSS4-v6")
    assert env.unwrapped.timing.guidance.descent_profile == "timed"
    env.close()
    env = gym.make("DeckLandingTiming-BenchSS4-v6", overrides=RANGE_DESCENT)
    assert env.unwrapped.timing.guidance.descent_profile == "range"
    env.close()


def test_a_model_trained_on_the_range_schedule_is_refused_on_the_timed_descent() -> None:
    card = read_metadata(SHIPPED_TIMING_MODEL)
    assert card is not None and "descent" not in card.observation
    env = gym.make("DeckLandingTiming-BenchSS4-v6")
    signature = env_signature(env)
    env.close()
    assert signature["observation"]["descent"] == descent_signature(
        GuidanceGains(descent_profile="timed")
    )
    with pytest.raises(ConfigError, match=r"observation\.descent"):
        check_compatible(card, signature, allow=("sensing", "estimator"))
    # on the range schedule it describes (a card written before the descent was recorded)
    env = gym.make("DeckLandingTiming-BenchSS4-v6", overrides=RANGE_DESCENT)
    legacy = env_signature(env)
    env.close()
    assert legacy["observation"]["descent"] == LEGACY_OBSERVATION["descent"]
    check_compatible(card, legacy, allow=("sensing", "estimator"))


def test_timing_keys_of_the_overrides_set_the_configs_timing_section() -> None:
    config = load_config(
        "bench-ss4", {"tof.noise": "vl53l1x", "timing.guidance.descent_profile": "range"}
    )
    assert config.tof.noise == "vl53l1x"
    assert config.timing.guidance.descent_profile == "range"
    # the scenario's own settings are not changed in place
    assert BENCH_TIMING["guidance"] == {"descent_profile": "timed"}
    with pytest.raises(ConfigError, match=r"timing\.hold_height_m"):
        load_config("bench-ss4", {"timing.hold_height_m.x": 1})


def _bench_timing(**timing) -> gym.Env:
    settings = {"guidance": {"descent_profile": "timed"}, **timing}
    return gym.make(
        "DeckLandingTiming-v0",
        config="bench-ss4",
        overrides={
            "simulation.drone_fixed": False,
            "camera.mode": "project",
            "estimation.observed": "tight",
            "estimation.compare": [],
            "touchdown.settle_time_s": 0.3,
            **nested_to_dotted(settings, "timing"),
        },
    )


def test_a_commit_onto_a_deck_predicted_too_tilted_is_waved_off_and_the_drone_climbs_back() -> None:
    # a threshold no deck meets: every chosen descent is waved off
    env = _bench_timing(wave_off_tilt_deg=0.001, wait_limit_s=4.0)
    base = env.unwrapped
    env.reset(seed=3)
    _, reward, terminated, truncated, info = env.step(1)
    assert not terminated and not truncated
    assert info["wave_offs"] == 1 and not info["committed"] and not info.get("touchdown")
    # the abort came 0.4-0.7 s in, and the climb back to the hold is in the same step
    assert 0.4 <= info["wait_s"] <= 0.7 + 1.5 + 1e-9
    assert abs(base.guidance.range_m(base._base_observation) - 0.7) < 0.05 or (info["wait_s"] > 1.9)
    assert reward == pytest.approx(-base.config.reward.time_cost * info["wait_s"])
    # past the wait limit the commit is forced, and a forced descent is never waved off
    for _ in range(60):
        _, _, terminated, _, info = env.step(1)
        if terminated:
            break
    # every descent was waved off until the wait limit; past it none is (forced or chosen)
    assert terminated and info["wait_s"] >= 4.0 and info["wave_offs"] >= 2
    assert info.get("touchdown")
    env.close()


def test_no_wave_off_without_the_threshold_and_none_on_the_range_schedule() -> None:
    env = _bench_timing()
    env.reset(seed=3)
    _, _, terminated, _, info = env.step(1)
    assert terminated and info["wave_offs"] == 0
    env.close()
    with pytest.raises(ConfigError, match="wave_off_tilt_deg"):
        gym.make(
            "DeckLandingTiming-v0",
            config="bench-ss4",
            overrides={"simulation.drone_fixed": False, "timing.wave_off_tilt_deg": 4.0},
        )
    with pytest.raises(ConfigError, match="wave_off_until_s"):
        _bench_timing(wave_off_from_s=0.6, wave_off_until_s=0.5)
    with pytest.raises(ConfigError, match="wave_off_predictor"):
        _bench_timing(wave_off_tilt_deg=4.0, wave_off_predictor="cubic")


def test_the_card_records_the_wave_off() -> None:
    gains = GuidanceGains(descent_profile="timed")
    assert "wave_off_tilt_deg" not in descent_signature(gains)
    assert descent_signature(gains, 4.5)["wave_off_tilt_deg"] == 4.5
    assert "wave_off_predictor" not in descent_signature(gains, 4.5)
    assert descent_signature(gains, 4.5, "quadratic")["wave_off_predictor"] == "quadratic"


def test_the_evaluation_checks_timing_overrides_before_it_starts() -> None:
    from agents.evaluation.landing import LANDING_EVALUATION, landing_task

    good = {"timing.wave_off_tilt_deg": 4.5, "sensors": "realistic"}
    LANDING_EVALUATION.validate(
        landing_task("land-now", "bench-ss4", "tight", extra_overrides=good)
    )
    with pytest.raises(ConfigError, match="wave_off_tilt_deg"):
        LANDING_EVALUATION.validate(
            landing_task(
                "land-now",
                "bench-ss4",
                "tight",
                extra_overrides={"timing.wave_off_tilt_deg": 4.5, **RANGE_DESCENT},
            )
        )
    with pytest.raises(ConfigError, match="no_such_key"):
        LANDING_EVALUATION.validate(
            landing_task("land-now", "bench-ss4", extra_overrides={"timing.no_such_key": 1})
        )


def test_the_predictive_timing_beats_land_now_on_held_out_seeds_under_realistic_sensing() -> None:
    from agents.evaluation.landing import evaluate_policy

    episodes, first, realistic = 24, 2_000_000, {"sensors": "realistic"}
    learned = evaluate_policy(
        "predictive", "bench-ss4", episodes, first, "tight", extra_overrides=realistic
    )
    now = evaluate_policy(
        "land-now", "bench-ss4", episodes, first, "tight", extra_overrides=realistic
    )
    learned_rate = np.mean([r.success for r in learned])
    now_rate = np.mean([r.success for r in now])
    assert learned_rate > now_rate + 0.1
    assert learned_rate >= 0.8


def test_the_quadratic_wave_off_predictor_follows_a_curving_deck() -> None:
    # a deck whose roll has just peaked (4 deg, 0.2 s ago): a parabola through the last second
    # sees it fall back before the contact; the straight line sees it still above the threshold
    env = _bench_timing(wave_off_tilt_deg=3.0)
    base = env.unwrapped
    env.reset(seed=3)
    base.history.reset()
    dt = base.env_dt
    times = np.arange(-1.0 + dt, dt / 2, dt)
    for t in times:
        roll = np.radians(2.0 - 4.0 * (t + 0.2) ** 2 + 2.0)  # peak 4 deg at t = -0.2 s
        base.history.push(np.array([0.0, 0.0, 0.7, roll, 0.0, 0.0]))
    rows = base.history.rows()
    assert rows[-1, 9] == 1.0
    base.timing.wave_off_predictor = "linear"
    linear = base.deck_prediction.wave_off_due(0.5, base._contact_s, base._wait_s)
    base.timing.wave_off_predictor = "quadratic"
    quadratic = base.deck_prediction.wave_off_due(0.5, base._contact_s, base._wait_s)
    env.close()
    # 0.8 s ahead the parabola is at 4 - 4 * 1.0^2 = 0 deg: no wave-off; the straight line
    # carries the newest 3.84 deg along the rate window's slope (+0.2 deg/s, the parabola's
    # at the window's centre, 0.225 s back) to 4.0 deg: a wave-off
    assert np.degrees(rows[-1, 7]) == pytest.approx(0.2, abs=0.05)
    assert linear and not quadratic
