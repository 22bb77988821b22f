"""The timing task's ``forecast`` observation (the ship ids' v5): the history, then the ship's
helideck forecast and the drone's own velocity and lean."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import landing_env  # noqa: F401  (registers the ids)
from agents.common.cards import check_compatible, env_signature
from estimation.frames import euler_zyx_from_matrix
from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.anticipation.hms_forecast import HORIZONS_S
from landing_env.errors import ConfigError
from landing_env.scenarios import SCENARIO_IDS
from landing_env.stewart.motion import sample_poses
from landing_env.timing.layout import OWN_STATE_FEATURES, TimingObservationLayout

FORECAST_ID = "DeckLandingTiming-ShipSS5-v7"
#: the forecast observation, a setting of the ship timing ids
FORECAST = {"timing.observation": "forecast"}


@pytest.fixture(scope="module")
def ship_env():
    env = gym.make(FORECAST_ID, overrides={"sensors": "realistic", **FORECAST})
    yield env
    env.close()


def test_the_ship_ids_observe_the_history_and_the_forecast_on_request() -> None:
    for n in (3, 4, 5, 6):
        env_id = f"DeckLandingTiming-ShipSS{n}-v7"
        assert "timing.observation" not in SCENARIO_IDS[env_id].overrides
    env = gym.make(FORECAST_ID, overrides=FORECAST)
    try:
        layout = env.unwrapped.layout
        assert layout.n_forecast == len(HORIZONS_S) and layout.observed_rows == 1
    finally:
        env.close()


def test_the_layout_round_trips_the_forecast_and_own_state() -> None:
    layout = TimingObservationLayout(n_history=3, hold_height_m=2.0, n_forecast=len(HORIZONS_S))
    history = np.zeros((3, len(HISTORY_FEATURES)))
    history[:, 2] = 2.0
    history[:, 9] = 1.0
    rng = np.random.default_rng(1)
    forecast = rng.normal(0.0, [0.5, 0.5, 1.0, 0.05, 0.05], (len(HORIZONS_S), 5))
    own = np.array([0.3, -0.2, 0.1, 0.2, -0.35])
    tof = np.full(4, 2.0)
    flat, clipped = layout.encode(history, tof, np.ones(4, bool), 0.5, None, forecast, own)
    assert not clipped and flat.shape == (layout.size,) == (1 * 10 + 9 + 17 * 5 + 1 + 5,)
    parts = layout.decode(flat)
    np.testing.assert_allclose(parts.history, history[-1:], atol=1e-6)  # the newest row only
    np.testing.assert_allclose(parts.forecast, forecast, atol=1e-5)
    np.testing.assert_allclose(parts.own_state, own, atol=1e-6)
    assert parts.forecast_valid and parts.wait_fraction == pytest.approx(0.5)
    # no forecast made: zeros, flagged invalid; the own state is still there
    flat, _ = layout.encode(history, tof, np.ones(4, bool), 0.5, None, None, own)
    parts = layout.decode(flat)
    assert not parts.forecast_valid and not parts.forecast.any()
    np.testing.assert_allclose(parts.own_state, own, atol=1e-6)


def test_the_layout_refuses_a_forecast_or_own_state_of_the_wrong_shape() -> None:
    layout = TimingObservationLayout(n_history=2, hold_height_m=2.0, n_forecast=4)
    history = np.zeros((2, len(HISTORY_FEATURES)))
    tof = np.full(4, 2.0)
    with pytest.raises(ValueError, match=r"forecast has shape \(3, 5\); the layout needs \(4, 5\)"):
        layout.encode(history, tof, np.ones(4, bool), 0.0, None, np.zeros((3, 5)), np.zeros(5))
    with pytest.raises(ValueError, match=r"own_state has 0 values.*vx_h"):
        layout.encode(history, tof, np.ones(4, bool), 0.0, None, np.zeros((4, 5)), None)


@settings(max_examples=40, deadline=None)
@given(
    values=st.lists(
        st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=90, max_size=90
    )
)
def test_any_forecast_values_encode_inside_the_space(values: list[float]) -> None:
    layout = TimingObservationLayout(n_history=2, hold_height_m=2.0, n_forecast=17)
    forecast = np.array(values[:85]).reshape(17, 5)
    own = np.array(values[85:])
    history = np.zeros((2, len(HISTORY_FEATURES)))
    flat, _ = layout.encode(history, np.full(4, 2.0), np.ones(4, bool), 0.0, None, forecast, own)
    assert layout.space.contains(flat)


def test_the_observed_forecast_follows_the_ship_and_the_own_state_is_the_drones(
    ship_env,
) -> None:
    base = ship_env.unwrapped
    assert ship_env.observation_space.shape == (base.layout.size,) == (10 + 9 + 91,)
    observation, _ = ship_env.reset(seed=5003)
    errors, spreads = [], []
    for _ in range(30):
        parts = base.layout.decode(observation)
        assert ship_env.observation_space.contains(observation)
        assert parts.forecast_valid
        # the own state is the drone's: its speed and its roll and pitch
        state = base.world.drone_state()
        roll, pitch, _ = euler_zyx_from_matrix(state.rotation_wb)
        np.testing.assert_allclose(parts.own_state[3:], [roll, pitch], atol=1e-5)
        assert np.linalg.norm(parts.own_state[:3]) == pytest.approx(
            np.linalg.norm(state.velocity_w), abs=1e-4
        )
        # the forecast's roll and pitch 0-2 s ahead against the ship's true motion then
        t0 = float(base.world.time)
        ahead = HORIZONS_S[HORIZONS_S <= 2.0]
        truth = sample_poses(base.world.stewart.motion, t0 + ahead)[:, 3:5]
        errors.append(parts.forecast[: len(ahead), 3:5] - truth)
        spreads.append(truth)
        observation, _, terminated, _, _ = ship_env.step(0)
        if terminated:
            break
    error = np.sqrt(np.mean(np.concatenate(errors) ** 2))
    spread = np.std(np.concatenate(spreads))
    # the HMS's 0.1 deg and the forecast's error against a deck rolling degrees
    assert error < 0.3 * spread, (np.degrees(error), np.degrees(spread))


def test_a_seeded_reset_repeats_the_forecast_observation(ship_env) -> None:
    first, _ = ship_env.reset(seed=5010)
    again, _ = ship_env.reset(seed=5010)
    other, _ = ship_env.reset(seed=5011)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_a_model_card_of_the_forecast_observation_refuses_the_history(ship_env) -> None:
    from agents.common.cards import ModelMetadata

    signature = env_signature(ship_env)
    assert signature["observation"]["observation"] == "forecast"
    assert signature["observation"]["forecast"]["own_state"] == list(OWN_STATE_FEATURES)
    assert signature["observation"]["forecast"]["hms"]["angle_noise_deg"] == 0.1
    card = ModelMetadata(
        env_id=signature["env_id"],
        observation=signature["observation"],
        estimator=signature["estimator"],
        sensing=[signature["sensing"]],
    )
    check_compatible(card, signature)
    history = gym.make(FORECAST_ID, overrides={"sensors": "realistic"})
    try:
        with pytest.raises(ConfigError, match=r"observation\.observation: .*'forecast'"):
            check_compatible(card, env_signature(history))
    finally:
        history.close()


def test_the_history_rules_refuse_the_forecast_observation(ship_env) -> None:
    from agents.policies.registry import make_policy

    for name in ("quiescent", "predictive"):
        with pytest.raises(ConfigError, match=r"timing\.observation: is 'forecast'"):
            make_policy(name, ship_env)


def test_the_forecast_observation_needs_a_sea() -> None:
    with pytest.raises(ConfigError, match=r"timing\.observation: 'forecast' needs a sea"):
        gym.make(
            "DeckLandingTiming-v0",
            config="paper-stewart",
            overrides={
                "simulation.drone_fixed": False,
                "camera.mode": "project",
                "timing.observation": "forecast",
            },
        )


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), decisions=st.lists(st.integers(0, 1), max_size=25))
def test_fuzzed_decisions_on_the_forecast_ids_keep_every_observation_in_its_space(
    ship_env, seed: int, decisions: list[int]
) -> None:
    observation, _ = ship_env.reset(seed=seed)
    assert ship_env.observation_space.contains(observation)
    for decision in decisions:
        observation, reward, terminated, truncated, _ = ship_env.step(decision)
        assert ship_env.observation_space.contains(observation)
        assert np.isfinite(reward)
        if terminated or truncated:
            break


def test_a_forecast_that_cannot_be_made_is_flagged_not_raised(ship_env, monkeypatch) -> None:
    base = ship_env.unwrapped
    ship_env.reset(seed=5030)
    forecast = base.forecast_observation.deck_forecast
    monkeypatch.setattr(forecast, "predict_targets", lambda *_: "too few HMS samples")
    observation, _, _, _, _ = ship_env.step(0)
    parts = base.layout.decode(observation)
    assert ship_env.observation_space.contains(observation)
    assert not parts.forecast_valid and not parts.forecast.any()
    assert np.isfinite(parts.own_state).all() and parts.own_state.any()
    # a forecast with a NaN in it is no forecast either
    nan = np.full((len(HORIZONS_S), 5), np.nan)
    monkeypatch.setattr(forecast, "predict_targets", lambda *_: nan)
    observation, _, _, _, _ = ship_env.step(0)
    assert ship_env.observation_space.contains(observation)
    assert not base.layout.decode(observation).forecast_valid
