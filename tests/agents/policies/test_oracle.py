"""The oracle timing: exact look-ahead by snapshot, its choice, and its place in the evaluation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.evaluation.landing import LANDING_EVALUATION, evaluate_landing
from agents.evaluation.pipeline import run_episode
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.summary import compare_with_oracle, markdown_table, summarise
from agents.policies.oracle import Candidate, OracleTimingPolicy, choose, touchdown_margin
from agents.policies.registry import make_env_and_policy, make_policy
from landing_env.config import TouchdownConfig
from landing_env.envs.snapshot import release_snapshot, restore_snapshot, save_snapshot


def test_a_restored_snapshot_replays_the_episode_bit_for_bit() -> None:
    env, _ = make_env_and_policy("land-now", "bench-ss4")
    base = env.unwrapped
    try:
        env.reset(seed=3)
        reference = [env.step(0)[0] for _ in range(4)]
        final_reference = env.step(1)[4]["touchdown"]

        env.reset(seed=3)
        start = save_snapshot(base)
        replay = []
        for _ in range(4):
            here = save_snapshot(base)
            looked_ahead = base.step(1)[4]  # a whole descent, then undone
            assert looked_ahead["outcome"] != "in_flight"
            restore_snapshot(base, here, keep=False)
            replay.append(env.step(0)[0])
        final = env.step(1)[4]["touchdown"]
        # and once more from the start, after the look-aheads
        restore_snapshot(base, start, keep=True)
        again = [env.step(0)[0] for _ in range(4)]
        release_snapshot(base, start)
        release_snapshot(base, start)  # idempotent
        with pytest.raises(ValueError, match="released"):
            restore_snapshot(base, start)
    finally:
        env.close()
    for ref, got, got_again in zip(reference, replay, again, strict=True):
        np.testing.assert_array_equal(ref, got)
        np.testing.assert_array_equal(ref, got_again)
    assert final == final_reference


def test_a_snapshot_in_render_mode_shares_the_detector_and_replays_the_episode() -> None:
    # the AprilTag detector holds C pointers: a snapshot shares it (a detection depends on
    # its image alone) instead of failing to copy it, so the oracle runs in render mode too
    env, _ = make_env_and_policy("land-now", "bench-ss4", camera_mode="render")
    base = env.unwrapped
    try:
        env.reset(seed=5)
        here = save_snapshot(base)
        reference = [env.step(0)[0] for _ in range(3)]
        restore_snapshot(base, here, keep=False)
        replay = [env.step(0)[0] for _ in range(3)]
    finally:
        env.close()
    for ref, got in zip(reference, replay, strict=True):
        np.testing.assert_array_equal(ref, got)


def test_a_pickled_detector_detects_what_the_original_detects() -> None:
    import pickle

    from estimation.detection import AprilTagDetector
    from landing_env.scene.deck import opencv_tag_bits

    detector = AprilTagDetector(quad_decimate=2.0)
    image = np.full((400, 400), 255, dtype=np.uint8)
    image[100:300, 100:300] = (np.kron(opencv_tag_bits(0), np.ones((25, 25))) * 255).astype(
        np.uint8
    )
    copy = pickle.loads(pickle.dumps(detector))
    assert copy is not detector and copy.min_side_px == detector.min_side_px
    (original,) = detector.detect(image)
    (copied,) = copy.detect(image)
    assert copied.tag_id == original.tag_id == 0
    np.testing.assert_array_equal(copied.corners_px, original.corners_px)


def test_margin_is_the_smallest_relative_slack_of_the_graded_criteria() -> None:
    limits = TouchdownConfig(max_normal_speed=0.5, max_deck_tilt_deg=5.0)
    touchdown = {"relative_normal_speed": 0.25, "deck_tilt_deg": 4.0, "relative_attitude_deg": 2.0}
    assert touchdown_margin(touchdown, limits) == pytest.approx(0.2)  # the tilt: 1 - 4/5
    touchdown["relative_normal_speed"] = 0.75
    assert touchdown_margin(touchdown, limits) == pytest.approx(-0.5)
    assert touchdown_margin(None, limits) == -math.inf


def test_choice_is_the_best_margin_of_the_first_successful_run() -> None:
    candidates = [
        Candidate(0, "hard_landing", -0.1),
        Candidate(1, "success", 0.1),
        Candidate(2, "success", 0.3),
        Candidate(3, "success", 0.2),
        Candidate(4, "hard_landing", -0.2),
        Candidate(5, "success", 0.9),  # later and better, but not the first window
    ]
    assert choose(candidates).waits == 2
    # nothing lands: the least bad
    failing = [Candidate(0, "hard_landing", -0.4), Candidate(1, "crash", -math.inf)]
    assert choose(failing).waits == 0
    with pytest.raises(ValueError):
        choose([])


def test_the_oracle_lands_where_landing_now_fails_and_predicts_its_own_outcome() -> None:
    # held-out seed 1000005 of bench-ss5: committing at once touches down beyond a limit
    seed, scenario = 1000005, "bench-ss5"
    env, oracle = make_env_and_policy("oracle", scenario)
    try:
        assert (
            isinstance(oracle, OracleTimingPolicy)
            and env.spec.id == "DeckLandingTiming-BenchSS5-v6"
        )
        land_now = make_policy("land-now", env)
        now = run_episode(env, land_now, seed, "land-now", scenario)
        best = run_episode(env, oracle, seed, "oracle", scenario)
    finally:
        env.close()
    plan = oracle.last_plan
    assert plan is not None and plan.chosen is not None
    assert not now.success
    # the first candidate is landing now: the same touchdown as the land-now episode
    assert plan.candidates[0].outcome == now.outcome
    assert best.success and plan.feasible
    assert best.outcome == plan.chosen.outcome
    assert best.wait_s == pytest.approx(plan.chosen.waits * 0.1)
    assert plan.chosen.margin > 0.0


def test_the_oracle_refuses_the_align_descend_task() -> None:
    env, _ = make_env_and_policy("align-descend", "bench-ss4")
    try:
        with pytest.raises(TypeError, match="DeckLandingTiming"):
            OracleTimingPolicy(env)
    finally:
        env.close()


def _episodes(policy: str, successes: list[bool]) -> list[EpisodeRecord]:
    """Episode records of ``policy`` on seeds 0, 1, ... with these successes."""
    return [
        EpisodeRecord(policy, "s", seed, "success" if ok else "hard_landing", ok)
        for seed, ok in enumerate(successes)
    ]


def test_the_summary_gives_the_oracle_the_gap_and_the_unavoidable_failures() -> None:
    results = {
        "land-now": _episodes("land-now", [True, False, False, True]),
        "oracle": _episodes("oracle", [True, True, False, True]),
    }
    summaries = [summarise(rs) for rs in results.values()]
    compare_with_oracle(summaries, results)
    land_now = summaries[0]
    assert land_now.oracle_success_rate == pytest.approx(0.75)
    assert land_now.gap_points == pytest.approx(25.0)
    assert land_now.unavoidable_failures == 1  # seed 2: the oracle failed it too
    table = markdown_table(summaries, LANDING_EVALUATION.columns)
    assert "+25.0" in table and "1 of 2" in table


def test_evaluating_a_timing_policy_runs_the_oracle_beside_it() -> None:
    evaluation = evaluate_landing(
        ["land-now"], "bench-ss4", 2, out_dir=None, workers=1, progress=False
    )
    assert set(evaluation.results) == {"land-now", "oracle"}
    land_now, oracle = evaluation.summaries
    assert oracle.successes >= land_now.successes
    assert land_now.gap_points == pytest.approx(100 * (oracle.success_rate - land_now.success_rate))
    without = evaluate_landing(
        ["land-now"], "bench-ss4", 1, out_dir=None, workers=1, progress=False, oracle=False
    )
    assert set(without.results) == {"land-now"}


# ------------------------------------------------------------------------------ deck oracle
def _hold_steps(env, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The deck's and the drone's positions over ``steps`` waits."""
    base = env.unwrapped
    deck, drone = [], []
    for _ in range(steps):
        env.step(0)
        deck.append(base.world.deck_state().position_w.copy())
        drone.append(base.world.drone_state().position_w.copy())
    return np.array(deck), np.array(drone)


def test_redrawing_the_unknowable_future_keeps_the_deck_and_changes_the_wind() -> None:
    env, _ = make_env_and_policy("land-now", "ship-ss4")
    base = env.unwrapped
    try:
        env.reset(seed=11)
        here = save_snapshot(base)
        runs = {}
        for name, seed in (("a", 1), ("b", 2), ("a again", 1)):
            restore_snapshot(base, here, keep=True)
            gust_now = base.world.wind.gust_w
            base.world.redraw_unknowable_future(np.random.default_rng(seed))
            # the present gust is kept: only its innovations are new
            np.testing.assert_array_equal(base.world.wind.gust_w, gust_now)
            runs[name] = _hold_steps(env, 10)
        release_snapshot(base, here)
    finally:
        env.close()
    (deck_a, drone_a), (deck_b, drone_b), (deck_a2, drone_a2) = runs.values()
    np.testing.assert_array_equal(deck_a, deck_b)  # the deck's future is the episode's own
    assert np.abs(drone_a - drone_b).max() > 1e-4  # the wind's is another draw
    np.testing.assert_array_equal(drone_a, drone_a2)  # and a seeded one
    np.testing.assert_array_equal(deck_a, deck_a2)


def test_the_deck_oracle_looks_ahead_without_changing_the_episode() -> None:
    from agents.policies.oracle import DeckOracleTimingPolicy

    env, _ = make_env_and_policy("land-now", "bench-ss4")
    try:
        env.reset(seed=4)
        reference = [env.step(0)[0] for _ in range(3)]
        env.reset(seed=4)
        oracle = DeckOracleTimingPolicy(env, draws=3, min_chance=0.5)
        chances = [oracle.chance(decision) for decision in range(2)]
        replay = [env.step(0)[0] for _ in range(3)]
        env.reset(seed=4)
        again = [oracle.chance(decision) for decision in range(2)]
    finally:
        env.close()
    for ref, got in zip(reference, replay, strict=True):
        np.testing.assert_array_equal(ref, got)
    assert all(c in (0.0, 1 / 3, 2 / 3, 1.0) for c in chances)
    assert again == chances  # seeded by the episode and the decision


def test_the_deck_oracle_commits_at_its_first_check_whose_draws_land() -> None:
    from agents.policies.oracle import DeckOracleTimingPolicy

    env, oracle = make_env_and_policy("deck-oracle", "bench-ss4")
    try:
        assert isinstance(oracle, DeckOracleTimingPolicy) and oracle.name == "deck-oracle"
        result = run_episode(env, oracle, 1000000, "deck-oracle", "bench-ss4")
        wait_limit_s = env.unwrapped.timing.wait_limit_s
    finally:
        env.close()
    decisions, chances = zip(*oracle.chances, strict=True)
    # it checked every stride-th decision, waited while the chance fell short, then committed
    assert list(decisions) == [k * oracle.stride for k in range(len(decisions))]
    assert all(c < oracle.min_chance for c in chances[:-1])
    # the last check's draws landed, or the wait limit forced the commit
    assert chances[-1] >= oracle.min_chance or result.wait_s >= wait_limit_s - 1e-6
    assert result.outcome in {"success", "hard_landing", "crash", "timeout"}


def test_the_deck_oracle_names_a_bad_setting() -> None:
    from agents.policies.oracle import DeckOracleTimingPolicy
    from landing_env.errors import ConfigError

    env, _ = make_env_and_policy("land-now", "bench-ss4")
    try:
        for kwargs, key in (
            ({"draws": 0}, "draws"),
            ({"min_chance": 0.0}, "min_chance"),
            ({"check_every_s": 0.01}, "check_every_s"),
            ({"min_margin": -0.1}, "min_margin"),
            ({"min_margin": 1.1}, "min_margin"),
        ):
            with pytest.raises(ConfigError, match=key):
                DeckOracleTimingPolicy(env, **kwargs)
    finally:
        env.close()
    env, _ = make_env_and_policy("align-descend", "bench-ss4")
    try:
        with pytest.raises(TypeError, match="DeckLandingTiming"):
            DeckOracleTimingPolicy(env)
    finally:
        env.close()


def test_the_summary_gives_the_gap_to_the_deck_oracle() -> None:
    results = {
        "land-now": _episodes("land-now", [True, False, False, True]),
        "deck-oracle": _episodes("deck-oracle", [True, True, False, True]),
        "oracle": _episodes("oracle", [True, True, True, True]),
    }
    summaries = [summarise(rs) for rs in results.values()]
    compare_with_oracle(summaries, results)
    land_now, deck_oracle, oracle = summaries
    assert land_now.deck_oracle_success_rate == pytest.approx(0.75)
    assert land_now.deck_gap_points == pytest.approx(25.0)
    assert land_now.gap_points == pytest.approx(50.0)
    # the full oracle's lead over the deck oracle: the wind's and the noise's foresight
    assert deck_oracle.gap_points == pytest.approx(25.0)
    assert oracle.deck_gap_points == pytest.approx(-25.0)
    table = markdown_table(summaries, LANDING_EVALUATION.columns)
    assert "gap to deck oracle" in table and "+25.0" in table


def test_evaluating_with_the_deck_oracle_runs_it_and_fills_its_gap() -> None:
    evaluation = evaluate_landing(
        ["land-now"],
        "bench-ss4",
        1,
        out_dir=None,
        workers=1,
        progress=False,
        oracle=False,
        deck_oracle=True,
    )
    assert set(evaluation.results) == {"land-now", "deck-oracle"}
    land_now, deck_oracle = evaluation.summaries
    assert land_now.deck_gap_points == pytest.approx(
        100 * (deck_oracle.success_rate - land_now.success_rate)
    )
    assert math.isnan(land_now.gap_points)  # the full oracle did not run


@given(
    draws=st.integers(-3, 80),
    min_chance=st.floats(-1.0, 2.0) | st.just(math.nan),
    check_every_s=st.floats(-1.0, 20.0) | st.just(math.nan),
    min_margin=st.floats(-1.0, 2.0) | st.just(math.nan),
)
@settings(max_examples=60, deadline=None)
def test_the_deck_oracle_builds_or_names_the_setting_for_any_values(
    draws: int, min_chance: float, check_every_s: float, min_margin: float
) -> None:
    from types import SimpleNamespace

    from agents.policies.oracle import DeckOracleTimingPolicy
    from landing_env.errors import ConfigError

    timing = SimpleNamespace(steps_per_decision=2, wait_limit_s=15.0)
    env = SimpleNamespace(unwrapped=SimpleNamespace(layout=None, env_dt=0.05, timing=timing))
    try:
        oracle = DeckOracleTimingPolicy(
            env, draws, min_chance, check_every_s, min_margin=min_margin
        )
    except ConfigError as error:
        assert error.key in {"draws", "min_chance", "check_every_s", "min_margin"}
        return
    assert 1 <= oracle.draws <= 64 and 0.0 < oracle.min_chance <= 1.0
    assert 0.0 <= oracle.min_margin <= 1.0
    assert oracle.stride >= 1 and oracle.chances == []
