"""``predictive`` over a ship's helideck: the optimal stopping of the bench's ``predictive`` on the
ship's helideck forecast (the HMS record's surge, sway, heave, roll and pitch a few seconds
ahead), the deck's tilt and its chance read from a forecast of many targets."""

from __future__ import annotations

import contextlib
import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

from agents.policies.registry import env_settings, make_env_and_policy
from agents.policies.timing import SHIP_CONTACT_TIMES_S, HelideckPredictivePolicy
from estimation.anticipation.linear_predictors import LinearTiltPredictor
from estimation.anticipation.stopping import StoppingValues, value_before_forced
from landing_env.errors import ConfigError
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitorConfig

_ROLL, _PITCH = HMS_CHANNELS.index("roll"), HMS_CHANNELS.index("pitch")


def _history(forecast, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A window of HMS-like values (the forecast's own fitting scale) and its flags."""
    rng = np.random.default_rng(seed)
    n = forecast.n_window
    t = np.arange(n) * forecast.dt_s
    values = np.column_stack(
        [0.3 * np.sin(2 * np.pi * t / (7.0 + k)) + 0.01 * rng.standard_normal(n) for k in range(5)]
    )
    values[:, _ROLL] *= 0.05
    values[:, _PITCH] *= 0.05
    return values, np.ones(n, dtype=bool)


# ------------------------------------------------------------------ the tilt of a forecast
def test_the_tilt_of_a_forecast_of_many_targets_is_its_roll_and_pitch(small_forecast):
    values, valid = _history(small_forecast)
    poses = small_forecast.predict_targets(values, valid)
    k = 8  # a fitted horizon
    horizon_s = float(small_forecast.horizons_s[k])
    prediction = small_forecast.predict(values, valid, horizon_s)
    assert prediction.valid, prediction.reason
    assert prediction.roll == pytest.approx(poses[k, _ROLL])
    assert prediction.pitch == pytest.approx(poses[k, _PITCH])
    block = small_forecast.covariance[k][np.ix_([_ROLL, _PITCH], [_ROLL, _PITCH])]
    np.testing.assert_allclose(prediction.covariance, block)


def test_a_forecast_without_roll_and_pitch_has_no_tilt_and_says_why(small_forecast):
    heave_only = dataclasses.replace(small_forecast, targets=("surge", "sway", "heave", "x", "y"))
    values, valid = _history(small_forecast)
    prediction = heave_only.predict(values, valid, 2.0)
    assert not prediction.valid
    assert "roll and pitch" in prediction.reason
    assert heave_only.chances((4.5, 5.0), 5.0, combine="mean").size == 0
    chance, predictions = heave_only.mean_within(values, valid, (4.5, 5.0), 5.0)
    assert chance == 0.0 and not predictions[0].valid


def test_the_mean_chance_of_spread_contact_times_is_the_mean_of_each_time_s(small_forecast):
    times = (4.5, 5.0, 5.5, 6.0)
    each = np.array([small_forecast.chances(t, 5.0) for t in times])
    mean = small_forecast.chances(times, 5.0, combine="mean")
    best = small_forecast.chances(times, 5.0, combine="best")
    np.testing.assert_allclose(mean, each.mean(axis=0))
    np.testing.assert_allclose(best, each.max(axis=0))
    assert np.all(mean <= best + 1e-12) and np.any(mean < best - 1e-6)
    values, valid = _history(small_forecast)
    chance, predictions = small_forecast.mean_within(values, valid, times, 5.0)
    assert [p.horizon_s for p in predictions] == list(times)
    assert chance == pytest.approx(np.mean([p.probability_within(5.0) for p in predictions]))


def test_a_chance_combined_neither_as_best_nor_mean_is_refused(small_forecast):
    with pytest.raises(ValueError, match="combine"):
        small_forecast.chances((4.5, 5.0), 5.0, combine="worst")


def test_the_bench_tilt_predictor_s_chances_are_the_best_of_its_contact_times_as_before(
    small_forecast,
):
    tilt = LinearTiltPredictor(
        small_forecast.window_s,
        small_forecast.dt_s,
        small_forecast.block,
        small_forecast.horizons_s,
        small_forecast.coefficients[:, :, [_ROLL, _PITCH]],
        small_forecast.covariance[:, [_ROLL, _PITCH]][:, :, [_ROLL, _PITCH]],
        channels=small_forecast.channels,
        scales=small_forecast.scales,
        heldout_means=small_forecast.heldout_means[:, :, [_ROLL, _PITCH]],
    )
    np.testing.assert_allclose(
        tilt.chances((4.5, 5.0, 5.5), 5.0), small_forecast.chances((4.5, 5.0, 5.5), 5.0)
    )
    values, valid = _history(small_forecast)
    a = tilt.best_within(values, valid, (4.5, 5.0), 5.0)
    b = small_forecast.best_within(values, valid, (4.5, 5.0), 5.0)
    assert (a.roll, a.pitch, a.horizon_s) == pytest.approx((b.roll, b.pitch, b.horizon_s))


# ------------------------------------------------------------------------------ the policy
def test_predictive_over_a_ship_identifies_its_forecast_online_and_not_the_bench_s_settings():
    for scenario in ("ship-ss6", "ship-unseen-5"):
        _, overrides = env_settings("predictive", scenario)
        assert overrides["deck_forecast"] == "online"
        assert overrides["timing.opportunity_s"] == 2.0
        assert not any(key.startswith("timing.wave_off") for key in overrides)
    _, bench = env_settings("predictive", "bench-ss4")
    assert bench["timing.wave_off_predictor"] == "model"
    assert "deck_forecast" not in bench


def _ship_env(seed: int = 2):
    env = gym.make("DeckLandingTiming-ShipSS4-v8", overrides={"sensors": "realistic"})
    env.reset(seed=seed)
    return env


@contextlib.contextmanager
def _ship_policy(forecast, opportunity_s: float = 2.0):
    """A ship env and ``predictive`` over it (tilt limit 5 deg, wait limit 15 s), closed after."""
    env = _ship_env()
    try:
        yield (
            env,
            HelideckPredictivePolicy(
                env, forecast, HelideckMonitorConfig(), 5.0, 15.0, opportunity_s
            ),
        )
    finally:
        env.close()


def test_the_policy_commits_when_its_chance_clears_the_value_of_waiting_on(
    small_forecast, monkeypatch
):
    with _ship_policy(small_forecast) as (env, policy):
        observation, _ = env.reset(seed=2)
        chance = policy.chance(0.0)
        assert 0.0 <= chance <= 1.0 and len(policy.last) == len(SHIP_CONTACT_TIMES_S)
        thresholds = []
        for fraction in (0.0, 0.5, 0.9):
            policy.chance(fraction)
            thresholds.append(policy.last_threshold)
        policy.chance(1.0)
        assert policy.last_threshold == 0.0
        assert thresholds[0] >= thresholds[1] >= thresholds[2] > 0.0
        # a level deck for sure clears any value; a deck surely past the limit waits
        monkeypatch.setattr(policy, "chance", lambda fraction: _set(policy, 1.0, 0.9))
        assert policy.act(observation) == 1
        monkeypatch.setattr(policy, "chance", lambda fraction: _set(policy, 0.0, 0.9))
        assert policy.act(observation) == 0


def test_once_the_wait_limit_is_within_the_forecasts_reach_the_forced_commit_is_foreseen(
    small_forecast,
):
    """Beyond the forecast's reach the bar is the long-run value of waiting; within it (the
    forced commit's contact no more than the forecast's last horizon ahead) the value is
    built on the chance the forecast gives the forced commit itself."""
    with _ship_policy(small_forecast) as (env, policy):
        env.reset(seed=2)
        samples = small_forecast.chances(SHIP_CONTACT_TIMES_S, 5.0, combine="mean")
        long_run = StoppingValues.from_samples(samples)
        reach_s = float(small_forecast.horizons_s[-1]) - max(SHIP_CONTACT_TIMES_S)
        t_s = float(env.unwrapped.world.time)
        for remaining_s in (10.0, reach_s + 0.5):  # out of reach
            policy.chance(1.0 - remaining_s / 15.0)
            assert policy.last_threshold == pytest.approx(
                long_run.threshold(remaining_s, 2.0), rel=1e-12
            )
        monitor = policy._episode_forecast.monitor
        _, measured = monitor.window(t_s, small_forecast.window_s)
        ok = np.ones(len(measured), dtype=bool)
        seen = set()
        for remaining_s in (reach_s, 2.0, 0.5):  # within reach
            policy.chance(1.0 - remaining_s / 15.0)
            forced, _ = small_forecast.mean_within(
                measured, ok, [remaining_s + c for c in SHIP_CONTACT_TIMES_S], 5.0
            )
            expected = value_before_forced(samples, forced, remaining_s, 2.0)
            assert policy.last_threshold == pytest.approx(expected, rel=1e-12)
            seen.add(round(policy.last_threshold - long_run.threshold(remaining_s, 2.0), 9))
        assert seen != {0.0}  # the foreseen commit moved the bar


def _set(policy: HelideckPredictivePolicy, chance: float, threshold: float) -> float:
    """Stand in for a forecast that gives ``chance`` against ``threshold``."""
    from estimation.anticipation.linear_predictors import TiltPrediction

    policy.last = [TiltPrediction(True, "", 5.0, 0.0, 0.0, np.eye(2) * 1e-4)]
    policy.last_threshold = threshold
    return chance


def test_a_forecast_that_cannot_be_made_means_waiting_even_at_the_wait_limit(
    small_forecast, monkeypatch
):
    with _ship_policy(small_forecast) as (env, policy):
        monkeypatch.setattr(small_forecast, "features", lambda values, valid: "no HMS record")
        observation, _ = env.reset(seed=2)
        assert policy.act(observation) == 0
        assert policy.last[0].reason == "no HMS record"


@pytest.mark.parametrize(
    ("times", "key"),
    [((), "contact_times_s"), ((4.5, 9.0), "contact_times_s"), ((-1.0,), "contact_times_s")],
)
def test_contact_times_the_forecast_cannot_reach_are_refused_naming_the_key(
    small_forecast, times, key
):
    env = _ship_env()
    try:
        with pytest.raises(ConfigError, match=key):
            HelideckPredictivePolicy(
                env, small_forecast, HelideckMonitorConfig(), 5.0, 15.0, 2.0, times
            )
        with pytest.raises(ConfigError, match="opportunity_s"):
            HelideckPredictivePolicy(env, small_forecast, HelideckMonitorConfig(), 5.0, 15.0, 0)
    finally:
        env.close()


def test_a_seeded_episode_of_predictive_at_sea_repeats_and_decides_in_its_space(small_forecast):
    outcomes = []
    for _ in range(2):
        with _ship_policy(small_forecast) as (env, policy):
            observation, _ = env.reset(seed=11)
            policy.reset()
            actions = []
            while True:
                action = policy.act(observation)
                assert env.action_space.contains(action)
                actions.append(action)
                observation, _, terminated, truncated, info = env.step(action)
                assert env.observation_space.contains(observation)
                if terminated or truncated:
                    break
            outcomes.append((actions, info["outcome"], round(info["wait_s"], 6)))
    assert outcomes[0] == outcomes[1]
    assert math.isfinite(outcomes[0][2])


def test_the_registry_builds_predictive_over_a_ship_as_the_helideck_policy(monkeypatch):
    import agents.policies.timing as timing

    fitted = []
    monkeypatch.setattr(
        timing, "deck_forecast_for", lambda config, hms: fitted.append(config) or None
    )
    env, policy = make_env_and_policy("predictive", "ship-ss5")
    try:
        assert isinstance(policy, HelideckPredictivePolicy)
        assert fitted[0].deck_forecast == "online"
    finally:
        env.close()


def test_without_a_fitted_forecast_each_episode_identifies_its_own_from_the_hms_record():
    with _ship_policy(None, opportunity_s=1.0) as (env, policy):
        observation, _ = env.reset(seed=5)
        policy.reset()
        policy.act(observation)
        online = policy._episode_forecast._online
        assert online is not None and online.metadata["online_record_s"] == 1200.0
        assert all(p.valid for p in policy.last) and 0.0 < policy.last_threshold < 1.0
        # the value of waiting on is the online forecast's own chances
        expected = online.chances(SHIP_CONTACT_TIMES_S, 5.0, combine="mean")
        assert policy.last_threshold <= expected.max() + 1e-12
        assert policy.last_threshold >= np.mean(expected) - 1e-12
