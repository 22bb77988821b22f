"""DeckLandingTiming-v0: API checks, the observation layout, the deck-motion history, waiting,
committing, the wait limit."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import landing_env  # noqa: F401  (registers the environments)
from estimation.frames import level_from_body, levelled_deck_pose, matrix_from_euler_zyx
from landing_env.anticipation.deck_history import HISTORY_FEATURES, DeckMotionHistory
from landing_env.config_loading import nested_to_dotted
from landing_env.errors import ConfigError
from landing_env.timing.guidance import DeckGuidance
from landing_env.timing.layout import (
    TimingObservationLayout,
    observed_prediction_size,
    timing_layout,
)
from landing_env.timing_config import TimingConfig

#: the bench of the papers with a bench-ss4 deck, the drone flying, IHRCF observed
FLYING = {
    "simulation.drone_fixed": False,
    "camera.mode": "project",
    "estimation.observed": "ihrcf",
    "estimation.compare": [],
    "start.max_offset_m": 0.1,
}
#: a shorter history and settle keep the API checks quick
QUICK = {"history_s": 0.5, "wait_limit_s": 3.0}


def make(timing: dict | None = None, config: str = "bench-ss4", **overrides) -> gym.Env:
    return gym.make(
        "DeckLandingTiming-v0",
        config=config,
        overrides={
            **FLYING,
            "touchdown.settle_time_s": 0.3,
            **nested_to_dotted(timing if timing is not None else QUICK, "timing"),
            **overrides,
        },
    )


def test_gymnasium_check_env() -> None:
    env = make()
    gym_check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_sb3_check_env() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make()
    sb3_check_env(env.unwrapped, warn=True)
    env.close()


def test_spaces_and_layout_of_the_default_task() -> None:
    env = make(timing={})
    base = env.unwrapped
    assert env.action_space == gym.spaces.Discrete(2)
    # 2 s at 20 Hz of 10 features, then 4 ranges, 4 validities and the wait fraction
    assert base.layout.n_history == 40
    assert env.observation_space.shape == (40 * len(HISTORY_FEATURES) + 9,)
    observation, info = env.reset(seed=3)
    assert env.observation_space.contains(observation)
    parts = base.layout.decode(observation)
    # after the warm-up the whole history holds valid estimates, and nothing has been waited
    assert parts.history[:, HISTORY_FEATURES.index("valid")].all()
    assert parts.wait_fraction == 0.0
    # the decoded last estimate is the observed estimator's pose, in SI units, as a level
    # camera sees it (the drone's roll and pitch removed)
    r_wb = matrix_from_euler_zyx(*info["drone"]["euler_w"])
    expected = levelled_deck_pose(info["estimates"]["ihrcf"]["pose"], level_from_body(r_wb))
    np.testing.assert_allclose(parts.history[-1, :6], expected, atol=1e-5, rtol=1e-4)
    # the drone holds at the hold height: camera range about 0.7 m
    assert abs(np.nanmean(parts.tof_range) - 0.7) < 0.05
    env.close()


def test_layout_round_trip_and_clipping_flag() -> None:
    layout = TimingObservationLayout(n_history=3, hold_height_m=0.7)
    history = np.zeros((3, len(HISTORY_FEATURES)))
    history[1:, :6] = [[0.01, -0.02, 0.72, 0.05, -0.03, 0.2]] * 2
    history[1:, 6:9] = [0.1, -0.2, 0.3]
    history[1:, 9] = 1.0
    tof = np.array([0.70, 0.71, np.nan, 0.69])
    flat, clipped = layout.encode(history, tof, np.isfinite(tof), 0.25)
    assert not clipped
    parts = layout.decode(flat)
    np.testing.assert_allclose(parts.history, history, atol=1e-6)
    np.testing.assert_allclose(parts.tof_range[[0, 1, 3]], tof[[0, 1, 3]], atol=1e-6)
    assert np.isnan(parts.tof_range[2]) and not parts.tof_valid[2]
    assert parts.wait_fraction == pytest.approx(0.25)
    history[2, 3] = 10.0  # 10 rad of roll: beyond the bounds, clipped and flagged
    flat, clipped = layout.encode(history, tof, np.isfinite(tof), 0.25)
    assert clipped and np.max(np.abs(flat)) <= 50.0


#: no ToF range and nothing waited: the encoding's arguments after the history
FLAT_TAIL = (np.full(4, np.nan), np.zeros(4, dtype=bool), 0.0)


def test_the_layout_holds_the_newest_rows_with_heights_relative_to_the_hold() -> None:
    layout = TimingObservationLayout(n_history=2, hold_height_m=0.7)
    history = np.zeros((4, len(HISTORY_FEATURES)))
    history[:, 2] = [0.9, 0.8, 0.72, 0.5]
    history[1:3, 9] = 1.0  # the newest row is not valid: its zero stays zero
    history[3, 2] = 0.0
    flat, _ = layout.encode(history, *FLAT_TAIL)
    rows = flat[: 2 * len(HISTORY_FEATURES)].reshape(2, -1)
    np.testing.assert_allclose(rows[:, 2], [0.2, 0.0], atol=1e-6)  # decimetres over the hold
    parts = layout.decode(flat)
    np.testing.assert_allclose(parts.history, history[2:], atol=1e-6)
    assert parts.prediction.size == 0
    # a batch of one (a vectorised env's row) decodes as the flat observation
    np.testing.assert_array_equal(layout.decode(flat[None, :]).history, parts.history)
    # integer rows are taken as numbers
    zeros, _ = layout.encode(np.zeros((2, len(HISTORY_FEATURES)), dtype=int), *FLAT_TAIL)
    np.testing.assert_array_equal(zeros, np.zeros_like(zeros))


def test_a_value_at_the_bound_is_kept_and_one_beyond_either_bound_is_clipped_and_flagged() -> None:
    layout = TimingObservationLayout(n_history=1, hold_height_m=0.7)
    history = np.zeros((1, len(HISTORY_FEATURES)))
    history[0, 3] = 5.0  # 5 rad of roll: 50 in the observation, the bound itself
    flat, clipped = layout.encode(history, *FLAT_TAIL)
    assert not clipped and flat[3] == 50.0
    history[0, 3] = -7.0
    flat, clipped = layout.encode(history, *FLAT_TAIL)
    assert clipped and flat[3] == -50.0


def test_the_prediction_layout_holds_the_predictors_values_instead_of_the_history() -> None:
    layout = TimingObservationLayout(n_history=40, hold_height_m=0.7, n_prediction=5)
    assert not layout.history_observed and layout.observed_rows == 0
    assert layout.space == gym.spaces.Box(-50.0, 50.0, (5 + 9,), dtype=np.float32)
    prediction = np.array([0.2, np.nan, 0.9, 0.5, 1.0])
    tof = np.array([0.75, 0.65, np.nan, 0.7])
    history = np.zeros((40, len(HISTORY_FEATURES)))
    flat, clipped = layout.encode(history, tof, np.isfinite(tof), 0.5, prediction)
    assert not clipped and flat.dtype == np.float32
    expected = [0.2, 0.0, 0.9, 0.5, 1.0, 0.5, -0.5, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.5]
    np.testing.assert_allclose(flat, expected, atol=1e-6)
    # a column of values is taken as the row it holds
    column, _ = layout.encode(history, tof, np.isfinite(tof), 0.5, prediction[:, None])
    np.testing.assert_array_equal(column, flat)
    parts = layout.decode(flat)
    assert parts.history.shape == (0, len(HISTORY_FEATURES))
    np.testing.assert_allclose(parts.prediction, [0.2, 0.0, 0.9, 0.5, 1.0], atol=1e-6)
    np.testing.assert_allclose(parts.tof_range, tof, atol=1e-6)
    assert parts.tof_valid.tolist() == [True, True, False, True] and parts.wait_fraction == 0.5
    with pytest.raises(ValueError, match=r"^4 prediction values; the layout needs 5$"):
        layout.encode(history, tof, np.isfinite(tof), 0.5, prediction[:4])
    with pytest.raises(ValueError, match=r"^observation has 13 values; the layout needs 14$"):
        layout.decode(flat[:13])


def test_the_timing_settings_give_the_layouts_rows_and_prediction_values() -> None:
    layout = timing_layout(TimingConfig(history_s=0.5, hold_height_m=0.9), env_hz=20.0)
    assert layout == TimingObservationLayout(n_history=10, hold_height_m=0.9)
    assert layout.size == 10 * len(HISTORY_FEATURES) + 9
    # a history shorter than a decision period still holds one row
    assert timing_layout(TimingConfig(history_s=0.1, rate_window_s=0.1), env_hz=4.0).n_history == 1
    predicting = TimingConfig(observation="prediction")
    assert observed_prediction_size(predicting) == len(predicting.contact_times_s) + 2 == 3
    assert observed_prediction_size(TimingConfig()) == 0
    assert timing_layout(predicting, env_hz=20.0).n_prediction == 3


def test_history_rates_are_least_squares_slopes_and_skip_invalid_samples() -> None:
    history = DeckMotionHistory(length=6, rate_window=4, dt=0.05)
    slope = np.array([0.0, 0.0, -0.2, 0.5, -0.1, 0.0])
    for k in range(6):
        pose = None if k == 3 else np.array([0.0, 0.0, 0.7, 0.0, 0.0, 0.1]) + slope * 0.05 * k
        history.push(pose)
    rows = history.rows()
    assert rows[3, HISTORY_FEATURES.index("valid")] == 0.0
    np.testing.assert_allclose(rows[-1, 6:9], slope[2:5], atol=1e-9)


def test_a_history_needs_a_row_and_two_samples_for_a_rate() -> None:
    for length, rate_window in ((0, 2), (1, 1)):
        with pytest.raises(ValueError, match=r"^need length >= 1 and rate_window >= 2$"):
            DeckMotionHistory(length=length, rate_window=rate_window, dt=0.05)
    history = DeckMotionHistory(length=1, rate_window=2, dt=0.05)
    np.testing.assert_array_equal(history.newest(), np.zeros(len(HISTORY_FEATURES)))
    np.testing.assert_array_equal(history.slope((2, 3)), [0.0, 0.0])
    history.push(np.array([0.0, 0.0, 0.7, 0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(history.newest()[6:10], [0.0, 0.0, 0.0, 1.0])  # no rate yet
    history.push(np.array([0.0, 0.0, 0.8, 0.1, 0.0, 0.0]))
    np.testing.assert_allclose(history.newest()[6:9], [2.0, 2.0, 0.0])
    np.testing.assert_array_equal(history.rows(), history.newest()[None, :])


def test_the_rates_are_fitted_to_the_last_rate_window_samples_only() -> None:
    history = DeckMotionHistory(length=3, rate_window=3, dt=0.1)
    for k, z in enumerate((0.0, 5.0, 0.1, 0.2, 0.3)):  # a jump, then 1 m/s
        history.push(np.array([0.5 * k, 0.0, z, 0.0, 0.0, 0.0]))
    assert history.newest()[6] == pytest.approx(1.0)
    np.testing.assert_allclose(history.slope((0, 2)), [5.0, 1.0])
    np.testing.assert_allclose(history.rows()[:, 2], [0.1, 0.2, 0.3])


def test_a_pose_not_finite_is_an_invalid_row_and_a_reset_forgets_every_sample() -> None:
    history = DeckMotionHistory(length=3, rate_window=3, dt=0.1)
    history.push(np.array([0.0, 0.0, 0.7, 0.0, 0.0, 0.0]))
    history.push(np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0]))
    rows = history.rows()
    np.testing.assert_array_equal(rows[[0, 2]], np.zeros((2, len(HISTORY_FEATURES))))
    assert rows[1, 2] == 0.7 and rows[1, 9] == 1.0
    history.newest()[:] = 9.0  # a copy: the history is left as it was
    history.rows()[:] = 9.0
    np.testing.assert_array_equal(history.rows(), rows)
    history.reset()
    np.testing.assert_array_equal(history.rows(), np.zeros((3, len(HISTORY_FEATURES))))
    np.testing.assert_array_equal(history.slope((2,)), [0.0])
    for z in (1.0, 1.1):
        history.push(np.array([0.0, 0.0, z, 0.0, 0.0, 0.0]))
    assert history.newest()[6] == pytest.approx(1.0)  # nothing from before the reset


def test_guidance_steers_towards_the_tag_and_holds_height() -> None:
    guidance = DeckGuidance()
    # tag 0.1 m ahead (camera y up the image = -y_C) and 0.05 m to the right (x_C > 0)
    observation = {
        "deck_pose": np.array([0.05, -0.1, 0.9, 0.0, 0.0, 0.0], dtype=np.float32),
        "deck_pose_valid": np.array([1], dtype=np.int8),
        "tof_range": np.full(4, 0.9, dtype=np.float32),
        "tof_valid": np.ones(4, dtype=np.int8),
    }
    setpoint = guidance.hold(observation, target_range_m=0.7)
    vx, vy, vz = setpoint.velocity_h
    assert vx > 0.0 and vy < 0.0  # forward, and right (heading y is left)
    assert vz < 0.0  # 0.2 m too high: down
    descent = guidance.descend(observation)
    assert descent.velocity_h[2] <= -guidance.gains.touchdown_speed


def test_wait_costs_time_and_commit_lands() -> None:
    env = make()
    env.reset(seed=11)
    _, reward, terminated, truncated, info = env.step(0)
    assert not terminated and not truncated
    # one decision = 2 control periods of 50 ms at 0.1 per second
    assert reward == pytest.approx(-0.1 * 0.1)
    assert info["wait_s"] == pytest.approx(0.1)
    _, reward, terminated, truncated, info = env.step(1)
    assert terminated and not truncated
    assert info["committed"] and not info["forced_commit"]
    assert info["outcome"] in ("success", "hard_landing")
    touchdown = info["touchdown"]
    # the final descent arrives slowly and over the tag
    assert 0.1 < touchdown["relative_normal_speed"] < 0.45
    assert touchdown["lateral_offset_m"] < 0.1
    assert 0.5 < info["descent_s"] < 2.0
    expected = -(
        4.0 * touchdown["relative_normal_speed"]
        + 0.2 * touchdown["deck_tilt_deg"]
        + 5.0 * touchdown["lateral_offset_m"]
    ) + (10.0 if info["outcome"] == "success" else 0.0)
    assert reward == pytest.approx(expected)
    assert info["is_success"] == (info["outcome"] == "success")
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    env.close()


def test_the_wait_limit_forces_the_descent() -> None:
    env = make(timing={"history_s": 0.5, "wait_limit_s": 0.3})
    env.reset(seed=2)
    steps = 0
    while True:
        _, _, terminated, _, info = env.step(0)
        steps += 1
        if terminated:
            break
    assert steps == 3
    assert info["forced_commit"] and info["committed"]
    assert "touchdown" in info
    env.close()


def test_same_seed_same_episode() -> None:
    def run(seed: int) -> tuple[np.ndarray, float]:
        env = make()
        observation, _ = env.reset(seed=seed)
        trace = [observation]
        for action in (0, 0, 0, 1):
            observation, reward, terminated, _, _ = env.step(action)
            trace.append(observation)
            if terminated:
                break
        env.close()
        return np.concatenate(trace), reward

    first, second, other = run(5), run(5), run(6)
    np.testing.assert_array_equal(first[0], second[0])
    assert first[1] == second[1]
    assert not np.array_equal(first[0], other[0])


def test_bad_settings_fail_with_the_key() -> None:
    with pytest.raises(ConfigError, match=r"timing\.hold_height_m"):
        make(timing={"hold_height_m": 0.1})
    with pytest.raises(ConfigError, match=r"timing\.guidance\.k_xy"):
        make(timing={"guidance": {"k_xy": -1.0}})
    with pytest.raises(ConfigError, match=r"timing\.wait_limit"):
        make(timing={"wait_limit": 3.0})
    # the papers' bench pins the drone: the timing task refuses it
    with pytest.raises(ConfigError, match=r"simulation\.drone_fixed"):
        gym.make("DeckLandingTiming-v0", config="paper-stewart")
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\[0, 1\] \(0 = wait, 1 = commit\)"):
        env.step(2)
    env.close()
