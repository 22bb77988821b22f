"""The ship's helideck monitoring system, the helideck forecast fitted on it, the forecast motion a
look-ahead plays, and the deck-forecast timing policy that tries commits in it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.deck_forecast import HORIZONS_S, DeckForecastTimingPolicy, fit_deck_forecast
from agents.evaluation.landing import SCENARIOS, make_env_and_policy
from estimation.deck_prediction import LinearMotionPredictor, LinearTiltPredictor
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.stewart.motion import ForecastMotion, MotionConfig, make_motion_source


def _ship_motion(sea_state: int = 4) -> MotionConfig:
    return load_config(SCENARIOS[f"ship-ss{sea_state}"].config).motion


@pytest.fixture(scope="module")
def small_forecast() -> LinearMotionPredictor:
    """A forecast of ship-ss4's sea fitted on three short records (seconds to fit)."""
    return fit_deck_forecast(_ship_motion(4), realizations=3, record_s=400.0)


# ------------------------------------------------------------------------------ the HMS
def test_the_hms_record_is_one_fixed_record_read_through_any_window() -> None:
    source = make_motion_source(_ship_motion(4), np.random.default_rng(3))
    monitor = HelideckMonitor(source, seed=11)
    early_t, early = monitor.window(10.0, 20.0)
    late_t, late = monitor.window(15.0, 20.0)
    shared = np.isin(np.round(early_t, 6), np.round(late_t, 6))
    assert shared.sum() == 150  # 15 s at 10 Hz in both windows
    np.testing.assert_array_equal(early[shared], late[: shared.sum()])
    _again_t, again = HelideckMonitor(source, seed=11).window(10.0, 20.0)
    np.testing.assert_array_equal(again, early)
    _, other = HelideckMonitor(source, seed=12).window(10.0, 20.0)
    assert not np.array_equal(other, early)  # another seed, other errors
    assert early_t[-1] == pytest.approx(10.0) and early_t[0] < 0.0  # before the episode too


def test_the_hms_errors_are_the_standards_bounds() -> None:
    source = make_motion_source(_ship_motion(5), np.random.default_rng(4))
    monitor = HelideckMonitor(source, seed=2)
    times, measured = monitor.window(0.0, 3000.0)
    error = measured - source.poses(times)[:, :5]
    std = error.std(axis=0)
    # roll and pitch: the HCA's 0.1 deg; positions: 5 cm or 5 % of the motion, the larger
    np.testing.assert_allclose(np.degrees(std[3:]), 0.1, rtol=0.05)
    spread = source.poses(times)[:, :3].std(axis=0)
    np.testing.assert_allclose(std[:3], np.maximum(0.05, 0.05 * spread), rtol=0.05)
    assert abs(float(np.corrcoef(error[1:, 2], error[:-1, 2])[0, 1])) < 0.05  # white


@settings(max_examples=40, deadline=None)
@given(
    rate=st.floats(-10.0, 2000.0, allow_nan=False),
    angle=st.floats(-1.0, 20.0, allow_nan=False),
    position=st.floats(-1.0, 20.0, allow_nan=False),
    fraction=st.floats(-1.0, 2.0, allow_nan=False),
)
def test_any_hms_setting_builds_or_is_refused_naming_its_key(rate, angle, position, fraction):
    try:
        config = HelideckMonitorConfig(rate, angle, position, fraction)
    except ConfigError as error:
        assert error.key in (
            "rate_hz",
            "angle_noise_deg",
            "position_noise_m",
            "position_noise_fraction",
        )
        return
    assert config.dt_s == pytest.approx(1.0 / rate)


# ------------------------------------------------------------------------------ forecast motion
class Swell:
    """Heave and roll as one slow wave (a fixed function of time)."""

    def poses(self, times: np.ndarray) -> np.ndarray:
        times = np.asarray(times, dtype=float).reshape(-1)
        out = np.zeros((len(times), 6))
        out[:, 2] = np.sin(0.7 * times)
        out[:, 3] = 0.05 * np.cos(0.7 * times)
        return out

    def pose(self, t: float) -> np.ndarray:
        return self.poses(np.array([t]))[0]

    def velocity(self, t: float) -> np.ndarray:
        out = np.zeros(6)
        out[2] = 0.7 * math.cos(0.7 * t)
        out[3] = -0.035 * math.sin(0.7 * t)
        return out


def test_forecast_motion_keeps_the_past_and_joins_the_present_without_a_jump() -> None:
    truth, t0 = Swell(), 3.0
    forecast = truth.poses(t0 + HORIZONS_S) + np.array([0, 0, 0.3, 0.01, 0, 0])  # biased
    motion = ForecastMotion(truth, t0, HORIZONS_S, forecast)
    past = np.linspace(-5.0, t0, 30)
    np.testing.assert_array_equal(motion.poses(past), truth.poses(past))
    np.testing.assert_allclose(motion.pose(t0 + 1e-4), truth.pose(t0), atol=1e-3)
    np.testing.assert_allclose(motion.velocity(t0 + 1e-6), truth.velocity(t0), atol=1e-3)
    # the forecast's own error at the present (here 0.3 m of heave) fades: late on, the
    # forecast itself
    late = t0 + 6.0
    assert motion.pose(late)[2] == pytest.approx(forecast[12, 2], abs=0.01)
    # beyond the last horizon it holds still
    end = t0 + HORIZONS_S[-1]
    np.testing.assert_allclose(motion.pose(end + 5.0), motion.pose(end))
    assert not motion.velocity(end + 1.0).any()


def test_forecast_motion_refuses_poses_that_do_not_fit_its_horizons() -> None:
    truth = Swell()
    with pytest.raises(ValueError, match="poses must be"):
        ForecastMotion(truth, 0.0, HORIZONS_S, np.zeros((3, 6)))
    with pytest.raises(ValueError, match="start at 0"):
        ForecastMotion(truth, 0.0, HORIZONS_S + 1.0, np.zeros((len(HORIZONS_S), 6)))
    with pytest.raises(ConfigError):
        ForecastMotion(truth, 0.0, HORIZONS_S, np.zeros((len(HORIZONS_S), 6)), fade_s=0.0)


@settings(max_examples=40, deadline=None)
@given(
    t0=st.floats(-100.0, 100.0) | st.just(math.nan),
    offset=st.floats(-50.0, 50.0) | st.just(math.nan) | st.just(math.inf),
    times=st.lists(st.floats(-200.0, 200.0), min_size=1, max_size=20),
)
def test_forecast_motion_of_any_finite_forecast_is_finite_and_refuses_a_non_finite_one(
    t0, offset, times
):
    truth = Swell()
    forecast = truth.poses(np.nan_to_num(t0) + HORIZONS_S) + offset
    try:
        motion = ForecastMotion(truth, t0, HORIZONS_S, forecast)
    except ValueError as error:
        assert not (math.isfinite(t0) and math.isfinite(offset))
        assert "finite" in str(error)
        return
    poses = motion.poses(np.array(times))
    assert poses.shape == (len(times), 6) and np.all(np.isfinite(poses))
    assert all(np.all(np.isfinite(motion.velocity(t))) for t in times)


# ------------------------------------------------------------------------------ the forecast
def test_the_helideck_forecast_beats_holding_the_present_on_a_sea_it_never_saw(small_forecast):
    source = make_motion_source(_ship_motion(4), np.random.default_rng(777))
    monitor = HelideckMonitor(source, seed=5)
    errors, holds = [], []
    for t0 in np.arange(30.0, 600.0, 7.3):
        _, measured = monitor.window(t0, small_forecast.window_s)
        predicted = small_forecast.predict_targets(measured, np.ones(len(measured), bool))
        assert not isinstance(predicted, str)
        truth = source.poses(t0 + HORIZONS_S)[:, :5]
        errors.append(predicted - truth)
        holds.append(truth[0] - truth)
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    hold = np.sqrt(np.mean(np.square(holds), axis=0))
    two_s = list(HORIZONS_S).index(2.0)
    # heave, roll and pitch two seconds ahead: under half the error of holding the present
    for channel in (2, 3, 4):
        assert rms[two_s, channel] < 0.5 * hold[two_s, channel], HMS_CHANNELS[channel]
    assert rms[-1, 2] > rms[two_s, 2]  # and the error grows with the horizon
    assert small_forecast.metadata["heldout_rms"][two_s][2] < 0.5 * hold[two_s, 2]


def test_a_motion_predictor_of_many_targets_saves_and_loads_and_a_tilt_one_refuses_them(
    small_forecast, tmp_path
):
    path = small_forecast.save(tmp_path / "forecast.npz")
    loaded = LinearMotionPredictor.load(path)
    assert loaded.targets == HMS_CHANNELS and loaded.channels == HMS_CHANNELS
    history = np.random.default_rng(0).normal(0.0, 0.1, (200, 5))
    np.testing.assert_allclose(
        loaded.predict_targets(history, np.ones(200, bool)),
        small_forecast.predict_targets(history, np.ones(200, bool)),
    )
    with pytest.raises(ValueError, match="not a deck-tilt predictor file"):
        LinearTiltPredictor.load(path)


def test_the_deck_forecast_needs_a_sea() -> None:
    with pytest.raises(ConfigError) as error:
        fit_deck_forecast(MotionConfig(kind="sinusoids"))
    assert error.value.key == "motion.kind"


# ------------------------------------------------------------------------------ the policy
def test_the_deck_forecast_looks_ahead_without_changing_the_episode(small_forecast):
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        env.reset(seed=8)
        reference = [env.step(0)[0] for _ in range(3)]
        env.reset(seed=8)
        policy = DeckForecastTimingPolicy(env, draws=2, min_chance=0.5, forecast=small_forecast)
        chances = [policy.chance(decision) for decision in range(2)]
        forecast = policy.last_forecast
        replay = [env.step(0)[0] for _ in range(3)]
        env.reset(seed=8)
        policy.reset()
        again = [policy.chance(decision) for decision in range(2)]
    finally:
        env.close()
    for ref, got in zip(reference, replay, strict=True):
        np.testing.assert_array_equal(ref, got)
    assert isinstance(forecast, np.ndarray) and forecast.shape == (len(HORIZONS_S), 5)
    assert all(c in (0.0, 0.5, 1.0) for c in chances)
    assert again == chances  # seeded by the episode and the decision


def test_a_forecast_that_cannot_be_made_means_waiting(small_forecast, monkeypatch):
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        env.reset(seed=2)
        policy = DeckForecastTimingPolicy(env, draws=2, forecast=small_forecast)
        monkeypatch.setattr(
            small_forecast, "predict_targets", lambda values, valid: "too few valid samples"
        )
        assert policy.chance(0) == 0.0
        assert policy.last_forecast == "too few valid samples"
        assert policy.act(np.zeros(1)) == 0
    finally:
        env.close()


def test_a_tried_commit_lands_only_with_the_margin_asked_for(small_forecast):
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        env.reset(seed=1)
        strict = DeckForecastTimingPolicy(env, forecast=small_forecast, min_margin=0.2)
        loose = DeckForecastTimingPolicy(env, forecast=small_forecast, min_margin=0.0)
        limit = env.unwrapped.config.touchdown.max_normal_speed
    finally:
        env.close()

    def touchdown(speed: float) -> dict:
        return {"deck_tilt_deg": 0.0, "relative_attitude_deg": 0.0, "relative_normal_speed": speed}

    gentle = {"outcome": "success", "touchdown": touchdown(0.5 * limit)}
    close = {"outcome": "success", "touchdown": touchdown(0.9 * limit)}
    failed = {"outcome": "hard_landing", "touchdown": touchdown(0.5 * limit)}
    assert strict.lands(gentle) and not strict.lands(close) and not strict.lands(failed)
    assert loose.lands(gentle) and loose.lands(close) and not loose.lands(failed)


def test_the_deck_forecast_refuses_a_forecast_of_another_rate_or_channels(small_forecast):
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        with pytest.raises(ValueError, match="HMS gives 5 Hz"):
            DeckForecastTimingPolicy(
                env, forecast=small_forecast, hms=HelideckMonitorConfig(rate_hz=5.0)
            )
        with pytest.raises(ConfigError):
            DeckForecastTimingPolicy(env, forecast=small_forecast, min_margin=1.5)
    finally:
        env.close()


def test_the_forecast_plot_draws_a_sea_the_forecast_never_saw(small_forecast, tmp_path):
    from agents.deck_forecast import plot_forecasts

    source = make_motion_source(_ship_motion(4), np.random.default_rng(5))
    path = plot_forecasts(small_forecast, source, "ship-ss4", str(tmp_path / "forecast.png"))
    with open(path, "rb") as handle:
        assert handle.read(8) == b"\x89PNG\r\n\x1a\n"
