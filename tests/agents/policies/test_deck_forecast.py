"""The ship's helideck monitoring system, the helideck forecast fitted on it, the forecast motion a
look-ahead plays, and the onboard look-ahead that tries commits in it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.policies.deck_forecast import DeckForecastTimingPolicy, OnboardModelConfig
from agents.policies.registry import make_env_and_policy
from estimation.anticipation.linear_predictors import LinearMotionPredictor, LinearTiltPredictor
from landing_env.anticipation.hms_forecast import HORIZONS_S, fit_deck_forecast, forecast_rms
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.physics.wind import WindConfig, WindModel
from landing_env.scenarios import SCENARIOS
from landing_env.sea.hms import (
    HMS_CHANNELS,
    HelideckMonitor,
    HelideckMonitorConfig,
)
from landing_env.stewart.motion import (
    ForecastMotion,
    MotionConfig,
    make_motion_source,
    sample_poses,
)


def _ship_motion(sea_state: int = 4) -> MotionConfig:
    return load_config(SCENARIOS[f"ship-ss{sea_state}"].config).motion


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
def test_a_forecast_that_cannot_be_made_means_waiting(small_forecast, monkeypatch):
    env = _holding_with_an_estimate("ship-ss4", seed=2)
    try:
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


def test_the_onboard_model_starts_the_drone_where_its_estimate_puts_it(small_forecast):
    """With no error drawn, the copy's drone sees the deck exactly where its estimate put
    it, flies in its wind estimate's gust and keeps its velocity; the episode is unchanged."""
    env, _ = make_env_and_policy(
        "land-now", "ship-ss4", "tight", extra_overrides={"sensors": "realistic"}
    )
    exact = OnboardModelConfig(
        thrust_error_fraction=0.0,
        gust_error_mps=(0.0, 0.0, 0.0),
        drag_error_fraction=0.0,
        position_error_m=(0.0, 0.0, 0.0),
    )
    try:
        env.reset(seed=3)
        for _ in range(3):
            env.step(0)
        base = env.unwrapped
        policy = DeckForecastTimingPolicy(env, draws=1, forecast=small_forecast, onboard=exact)
        estimate = base._sensing.estimates["tight"]
        assert estimate.valid
        _, t_true = base.world.true_deck_pose_c()
        velocity = base.world.drone_state().velocity_w.copy()
        gust = base.world.wind.gust_w.copy()
        drag = base.world.drone.params.linear_drag_b.copy()
        k_f = base.world.drone.params.k_f
        assert policy.deck_future(7) is not None
        policy.model_draw(7, 0)
        _, t_model = base.world.true_deck_pose_c()
        moved_velocity = base.world.drone_state().velocity_w
        np.testing.assert_allclose(t_model, estimate.translation, atol=1e-9)
        assert np.linalg.norm(t_model - t_true) > 0.0  # the estimate was not the truth
        np.testing.assert_allclose(moved_velocity, velocity, atol=1e-12)
        np.testing.assert_allclose(base.world.wind.gust_w, gust, atol=1e-12)
        np.testing.assert_array_equal(base.world.drone.params.linear_drag_b, drag)
        assert base.world.drone.params.k_f == k_f
    finally:
        env.close()


def _holding_with_an_estimate(scenario: str, seed: int):
    """The timing task of ``scenario`` with realistic sensing, reset with ``seed`` and held
    until ``tight`` gives a valid deck-pose estimate."""
    env, _ = make_env_and_policy(
        "land-now", scenario, "tight", extra_overrides={"sensors": "realistic"}
    )
    env.reset(seed=seed)
    while not env.unwrapped._sensing.estimates["tight"].valid:
        env.step(0)
    return env


def test_the_onboard_model_draws_its_errors_with_the_spreads_set():
    model = OnboardModelConfig(
        gust_error_mps=(0.4, 0.4, 0.2), drag_error_fraction=0.2, position_from_estimate=False
    )
    forecast = fit_deck_forecast(_ship_motion(5), realizations=2, record_s=300.0)
    env = _holding_with_an_estimate("ship-ss5", seed=4)
    base = env.unwrapped
    try:
        policy = DeckForecastTimingPolicy(env, draws=1, forecast=forecast, onboard=model)
        truth = base.world.wind.gust_w.copy()
        drag = base.world.drone.params.linear_drag_b.copy()
        k_f = base.world.drone.params.k_f
        estimates, gusts, scales = [], [], []
        for decision in range(60):
            policy.deck_future(decision)
            assert policy._belief is not None
            estimates.append(policy._belief[2])
            for draw in range(4):
                policy.model_draw(decision, draw)
                gusts.append(base.world.wind.gust_w - policy._belief[2])
                params = base.world.drone.params
                scales.append([*(params.linear_drag_b / drag), params.k_f / k_f])
                base.world.wind.set_present_gust_w(truth)
                base.world.drone.params = dataclasses.replace(params, linear_drag_b=drag, k_f=k_f)
    finally:
        env.close()
    estimate_spread = np.std(np.asarray(estimates) - truth, axis=0)
    draw_spread = np.std(np.asarray(gusts), axis=0)
    for spread in (estimate_spread, draw_spread):
        np.testing.assert_allclose(spread, [0.4, 0.4, 0.2], rtol=0.35)
    scales = np.asarray(scales)
    assert np.allclose(scales[:, :3], scales[:, :1])  # one scale for the whole drag
    assert 0.8 - 1e-9 <= scales[:, 0].min() < 0.9 and 1.1 < scales[:, 0].max() <= 1.2 + 1e-9
    assert 0.95 - 1e-9 <= scales[:, 3].min() < 0.97 and 1.03 < scales[:, 3].max() <= 1.05 + 1e-9


def test_an_airframe_drawn_in_trim_feels_the_same_drag_force_and_spins_for_its_thrust():
    """With ``airframe_in_trim`` a draw moves the wind at the drone so that the drawn drag
    gives the force the drone holds (scale x (v - w') = v - w), and its rotors and thrust model
    are the drawn thrust's; the rest of the draw is the same as without it."""
    from landing_env.envs.snapshot import restore_snapshot, save_snapshot

    forecast = fit_deck_forecast(_ship_motion(6), realizations=2, record_s=300.0)
    env = _holding_with_an_estimate("ship-ss6", seed=4)
    base = env.unwrapped
    try:
        drawn = {}
        for in_trim in (False, True):
            model = OnboardModelConfig(position_from_estimate=False, airframe_in_trim=in_trim)
            policy = DeckForecastTimingPolicy(env, draws=1, forecast=forecast, onboard=model)
            policy.deck_future(0)
            here = save_snapshot(base)
            world = base.world
            felt = np.asarray(world.drone.last_wind_w)
            air = world.drone_state().velocity_w - felt
            omega = world.drone.rotor_speeds.copy()
            k_f = world.controller._k_f
            nominal = world.drone.params
            for draw in range(3):
                restore_snapshot(base, here, keep=True)
                world = base.world  # the restored copy
                policy.model_draw(0, draw)
                drawn[in_trim, draw] = (
                    world.wind.gust_w,
                    world.drone.params.linear_drag_b[0] / nominal.linear_drag_b[0],
                    world.drone.params.k_f / nominal.k_f,
                    world.drone.rotor_speeds / omega,
                    world.controller._k_f / k_f,
                )
            restore_snapshot(base, here, keep=False)
        # 2 m over the deck: inside the airwake, where a gust reaches the drone x 1.5
        factor = base.config.wind.airwake_turbulence_factor
        for draw in range(3):
            gust, drag, thrust, spin, model_k_f = drawn[True, draw]
            plain_gust, plain_drag, plain_thrust, plain_spin, plain_k_f = drawn[False, draw]
            assert drag == plain_drag != 1.0 and thrust == plain_thrust != 1.0
            np.testing.assert_allclose(
                factor * (gust - plain_gust), air * (1.0 - 1.0 / drag), atol=1e-9
            )
            np.testing.assert_allclose(spin, 1.0 / np.sqrt(thrust))
            assert model_k_f == pytest.approx(thrust) and plain_k_f == 1.0
            np.testing.assert_array_equal(plain_spin, np.ones(4))
    finally:
        env.close()
    assert "airframe_in_trim" not in OnboardModelConfig().signature()  # cards sign as before
    assert OnboardModelConfig(airframe_in_trim=True).signature()["airframe_in_trim"] is True
    with pytest.raises(ConfigError, match="airframe_in_trim"):
        OnboardModelConfig(airframe_in_trim="yes")


def test_the_onboard_model_waits_when_the_drone_has_no_deck_estimate(small_forecast, monkeypatch):
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        env.reset(seed=2)
        base = env.unwrapped
        policy = DeckForecastTimingPolicy(
            env, draws=2, forecast=small_forecast, onboard=OnboardModelConfig()
        )
        invalid = dataclasses.replace(base._sensing.estimates["tight"], valid=False)
        monkeypatch.setitem(base._sensing.estimates, "tight", invalid)
        assert policy.chance(0) == 0.0
        assert "no valid deck-pose estimate" in policy.last_forecast
    finally:
        env.close()


def test_the_onboard_look_ahead_leaves_the_episode_as_it_was_and_repeats(small_forecast):
    env, _ = make_env_and_policy(
        "land-now", "ship-ss4", "tight", extra_overrides={"sensors": "realistic"}
    )
    try:
        env.reset(seed=8)
        reference = [env.step(0)[0] for _ in range(3)]
        env.reset(seed=8)
        policy = DeckForecastTimingPolicy(env, draws=2, min_chance=0.5, forecast=small_forecast)
        chances = [policy.chance(decision) for decision in range(2)]
        forecast = policy.last_forecast
        replay = [env.step(0)[0] for _ in range(3)]
        env.reset(seed=8)
        again = [policy.chance(decision) for decision in range(2)]
    finally:
        env.close()
    for ref, got in zip(reference, replay, strict=True):
        np.testing.assert_array_equal(ref, got)
    assert again == chances  # seeded by the episode and the decision
    assert isinstance(forecast, np.ndarray) and forecast.shape == (len(HORIZONS_S), 5)
    assert all(c in (0.0, 0.5, 1.0) for c in chances)


@settings(max_examples=40, deadline=None)
@given(
    gust=st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3),
    drag=st.floats(-1.0, 2.0),
    position=st.lists(st.floats(-0.5, 2.0), min_size=3, max_size=3),
    thrust=st.floats(-1.0, 1.0),
)
def test_any_onboard_setting_builds_or_is_refused_naming_its_key(gust, drag, position, thrust):
    valid = (
        all(0 <= g <= 10 for g in gust)
        and 0 <= drag <= 0.9
        and all(0 <= p <= 1 for p in position)
        and 0 <= thrust <= 0.5
    )
    build = lambda: OnboardModelConfig(tuple(gust), drag, True, tuple(position), thrust)  # noqa: E731
    if valid:
        build()
        return
    with pytest.raises(
        ConfigError,
        match=r"gust_error_mps|drag_error_fraction|position_error_m|thrust_error_fraction",
    ):
        build()


def test_a_present_gust_can_be_set_and_the_process_goes_on_from_it():
    config = WindConfig(enabled=True, mean_velocity_w=(8.0, 6.0, 0.0), turbulence="dryden")
    wind = WindModel(config, np.random.default_rng(1))
    wind.velocity(0.0, 0.01)
    wind.set_present_gust_w(np.array([1.0, -2.0, 0.5]))
    np.testing.assert_allclose(wind.gust_w, [1.0, -2.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(wind.velocity(0.0, 0.01), [9.0, 4.0, 0.5], atol=1e-12)
    after = wind.velocity(0.01, 0.01) - np.array([8.0, 6.0, 0.0])
    assert np.linalg.norm(after - [1.0, -2.0, 0.5]) < 0.5  # it goes on from there
    with pytest.raises(ValueError, match="gust_w"):
        wind.set_present_gust_w(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="gust_w"):
        wind.set_present_gust_w(np.zeros(2))
    calm = WindModel(WindConfig(enabled=False), np.random.default_rng(1))
    calm.set_present_gust_w(np.ones(3))
    np.testing.assert_array_equal(calm.velocity(0.0, 0.01), np.zeros(3))


def test_shifting_the_drone_keeps_its_attitude_and_velocities_and_refuses_a_bad_shift():
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        env.reset(seed=5)
        env.step(0)
        world = env.unwrapped.world
        before = world.drone_state()
        position, velocity = before.position_w.copy(), before.velocity_w.copy()
        attitude = before.quaternion_xyzw.copy()
        world.shift_drone(np.array([0.1, -0.2, 0.05]))
        after = world.drone_state()
        np.testing.assert_allclose(after.position_w - position, [0.1, -0.2, 0.05], atol=1e-9)
        np.testing.assert_allclose(after.velocity_w, velocity, atol=1e-12)
        np.testing.assert_allclose(after.quaternion_xyzw, attitude, atol=1e-12)
        for bad in (np.array([np.nan, 0.0, 0.0]), np.zeros(2)):
            with pytest.raises(ValueError, match="shift_w"):
                world.shift_drone(bad)
    finally:
        env.close()


# ------------------------------------------------------------------------------ online
def test_the_online_forecast_is_identified_from_the_episodes_own_record_and_refitted_when_old():
    from landing_env.anticipation.hms_forecast import ONLINE_REFIT_S, EpisodeForecast

    source = make_motion_source(_ship_motion(5), np.random.default_rng([3]))
    monitor = HelideckMonitor(source, HelideckMonitorConfig(), seed=3)
    episode = EpisodeForecast(None, monitor)
    first = episode.at(2.0)
    assert first.metadata["t_end_s"] == 2.0 and first.metadata["online_record_s"] == 1200.0
    assert episode.at(2.0 + ONLINE_REFIT_S - 1.0) is first
    later = episode.at(2.0 + ONLINE_REFIT_S)
    assert later is not first and later.metadata["t_end_s"] == 2.0 + ONLINE_REFIT_S
    # it forecasts the heave a second ahead far better than holding the present does
    rms = forecast_rms(first, _ship_motion(5), record_s=300.0)
    one_s = list(first.horizons_s).index(1.0)
    times, _ = monitor.window(300.0, 300.0)
    heave = sample_poses(source, times)[:, 2]
    hold = np.sqrt(np.mean((heave[10:] - heave[:-10]) ** 2))
    assert rms[one_s, 2] < 0.25 * hold
    # a fitted forecast is flown as it is; at a time that is not finite there is none to fit
    assert EpisodeForecast(first, monitor).at(500.0) is first
    for bad in (math.nan, math.inf):
        assert EpisodeForecast(None, monitor).at(bad) is None


def test_the_deck_forecast_policy_identifies_the_sea_online_when_the_config_says_so():
    env = _holding_with_an_estimate("ship-ss4", seed=5)
    try:
        env.unwrapped.config.deck_forecast = "online"
        policy = DeckForecastTimingPolicy(env, draws=1)
        assert policy.forecast is None
        future = policy.deck_future(0)
        assert isinstance(future, ForecastMotion)
        assert isinstance(policy.last_forecast, np.ndarray)
        assert policy.last_forecast.shape == (len(HORIZONS_S), 5)
        assert np.all(np.isfinite(policy.last_forecast))
    finally:
        env.close()
