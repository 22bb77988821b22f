"""The deck-tilt predictor: the Wiener predictor fitted on estimated motion, its honest error,
the predictive timing policy and the wave-off that read it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agents.training.tilt_predictor_fit import CHANNELS, HORIZONS_S, futures
from estimation.anticipation.linear_predictors import LinearTiltPredictor, TiltPrediction
from estimation.anticipation.stopping import predictor_stopping_values
from estimation.frames import euler_zyx_from_matrix, level_from_body, levelled_deck_pose
from landing_env.config import load_config
from landing_env.config_loading import nested_to_dotted
from landing_env.errors import ConfigError
from landing_env.resources import PREDICTOR_DIR, tilt_predictor_path
from landing_env.scenarios import PREDICTIVE_TIMING
from landing_env.sea.heldout import HELD_OUT_SEAS
from landing_env.sea.training_seas import training_family
from tests.paths import ROOT

DT = 0.05
WINDOW_S = 4.0

#: the ``predictive`` policy's timing settings over the bench ids', and with the prediction
#: observation (``timing-dqn-predictive``'s)
PREDICTIVE = nested_to_dotted(PREDICTIVE_TIMING, "timing")
PREDICTION = {**PREDICTIVE, "timing.observation": "prediction"}


def _deck_series(seed: int, seconds: float, noise_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """A deck rolling and pitching as a few random-phase waves (3-6 s periods), the truth and
    a noisy estimate of it, at 20 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, DT)
    truth = np.zeros((len(t), 2))
    for axis in range(2):
        for period in rng.uniform(3.0, 6.0, 4):
            truth[:, axis] += math.radians(1.5) * np.sin(
                2 * math.pi * t / period + rng.uniform(0, 2 * math.pi)
            )
    return truth, truth + noise_rad * rng.standard_normal(truth.shape)


def _examples(
    seeds: range, noise_rad: float = math.radians(0.3)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Examples every decision (0.1 s) of each series: the window of estimates and the truth at
    each horizon."""
    n = round(WINDOW_S / DT)
    histories, truth_rows, groups = [], [], []
    for seed in seeds:
        truth, estimate = _deck_series(seed, 60.0, noise_rad)
        for k in range(n, len(truth), 2):
            window = np.column_stack([estimate[k - n + 1 : k + 1], np.ones(n)])
            histories.append(window)
            truth_rows.append(truth[k])
            groups.append(seed)
    groups_array = np.array(groups)
    future = futures(np.array(truth_rows), groups_array, HORIZONS_S, 2 * DT)
    return np.array(histories), future, groups_array


@pytest.fixture(scope="module")
def predictor() -> LinearTiltPredictor:
    histories, future, groups = _examples(range(12))
    return LinearTiltPredictor.fit(histories, future, groups, HORIZONS_S, WINDOW_S, DT)


def test_the_fitted_predictor_beats_holding_the_last_estimate_a_second_ahead(predictor):
    histories, future, _ = _examples(range(100, 104))
    k = int(np.argmin(abs(HORIZONS_S - 1.0)))
    errors, hold = [], []
    for history, target in zip(histories, future[:, k], strict=True):
        if not np.all(np.isfinite(target)):
            continue
        p = predictor.predict(history[:, :2], history[:, 2] > 0.5, 1.0)
        assert p.valid
        errors.append([p.roll - target[0], p.pitch - target[1]])
        hold.append(history[-1, :2] - target)
    rms = np.sqrt(np.mean(np.square(errors)))
    assert rms < 0.5 * np.sqrt(np.mean(np.square(hold)))


def test_the_held_out_covariance_matches_the_error_on_new_episodes(predictor):
    histories, future, _ = _examples(range(200, 206))
    k = int(np.argmin(abs(HORIZONS_S - 1.3)))
    residuals = []
    for history, target in zip(histories, future[:, k], strict=True):
        if np.all(np.isfinite(target)):
            p = predictor.predict(history[:, :2], history[:, 2] > 0.5, 1.3)
            residuals.append([p.roll - target[0], p.pitch - target[1]])
    measured = np.sqrt(np.mean(np.square(residuals), axis=0))
    claimed = np.sqrt(np.diag(predictor.covariance[k]))
    np.testing.assert_allclose(measured, claimed, rtol=0.3)


def test_a_channel_that_leads_the_tilt_is_used_to_predict_it():
    """Heave that leads roll by a second (as a wave reaches the heave before it tilts the
    deck) makes the roll a second ahead predictable: a predictor with ``z`` among its channels
    finds it, one on roll and pitch alone cannot."""
    n = round(WINDOW_S / DT)
    histories, targets, groups = [], [], []
    for seed in range(8):
        truth, _ = _deck_series(seed, 70.0, 0.0)
        lead = round(1.0 / DT)
        # z(t) = roll(t + 1 s): the heave channel shows now the roll a second ahead
        roll, pitch, z = truth[:-lead, 0], truth[:-lead, 1], truth[lead:, 0]
        noise = np.random.default_rng(seed).normal(0.0, math.radians(0.1), (len(roll), 3))
        series = np.column_stack([z, roll, pitch]) + noise
        for k in range(n, len(roll) - 20, 2):
            histories.append(np.column_stack([series[k - n + 1 : k + 1], np.ones(n)]))
            targets.append([roll[k], pitch[k]])
            groups.append(seed)
    histories_a = np.array(histories)
    future = futures(np.array(targets), np.array(groups), HORIZONS_S, 2 * DT)
    both = LinearTiltPredictor.fit(
        histories_a,
        future,
        np.array(groups),
        HORIZONS_S,
        WINDOW_S,
        DT,
        channels=("z", "roll", "pitch"),
    )
    alone = LinearTiltPredictor.fit(
        histories_a[:, :, 1:], future, np.array(groups), HORIZONS_S, WINDOW_S, DT
    )
    k = int(np.argmin(abs(HORIZONS_S - 1.0)))
    assert both.channels == ("z", "roll", "pitch") and len(both.scales) == 3
    assert both.covariance[k][0, 0] < 0.2 * alone.covariance[k][0, 0]


def test_the_error_grows_with_the_horizon(predictor):
    sigma = np.sqrt(predictor.covariance[:, 0, 0])
    assert sigma[int(np.argmin(abs(HORIZONS_S - 1.5)))] > 2.0 * sigma[1]


def test_a_horizon_between_fitted_ones_interpolates_the_two(predictor):
    history, _, _ = _examples(range(300, 301))
    rows = history[10]
    a = predictor.predict(rows[:, :2], rows[:, 2] > 0.5, 1.2)
    b = predictor.predict(rows[:, :2], rows[:, 2] > 0.5, 1.3)
    mid = predictor.predict(rows[:, :2], rows[:, 2] > 0.5, 1.25)
    assert mid.roll == pytest.approx(0.5 * (a.roll + b.roll), abs=1e-12)
    np.testing.assert_allclose(mid.covariance, 0.5 * (a.covariance + b.covariance), atol=1e-15)


def test_the_chance_of_a_level_isotropic_prediction_is_rayleigh():
    sigma_deg = 2.0
    cov = np.eye(2) * math.radians(sigma_deg) ** 2
    p = TiltPrediction(True, "", 1.3, 0.0, 0.0, cov)
    for limit in (1.0, 2.0, 5.0):
        expected = 1.0 - math.exp(-(limit**2) / (2 * sigma_deg**2))
        assert p.probability_within(limit) == pytest.approx(expected, abs=0.01)


def test_the_chance_falls_as_the_predicted_tilt_nears_and_passes_the_limit():
    cov = np.eye(2) * math.radians(1.0) ** 2
    chances = [
        TiltPrediction(True, "", 1.3, math.radians(r), 0.0, cov).probability_within(5.0)
        for r in (0.0, 3.0, 5.0, 8.0)
    ]
    # at the limit: below one half, since the pitch spread only adds tilt
    assert chances[0] > 0.99 and 0.4 < chances[2] < 0.5
    assert chances[3] < 0.01 and chances == sorted(chances, reverse=True)


def test_an_invalid_prediction_has_no_chance_and_says_why():
    p = TiltPrediction(False, "too few valid estimates in the window")
    assert p.probability_within(5.0) == 0.0 and math.isnan(p.tilt_deg)


def test_too_few_valid_estimates_give_an_invalid_prediction_with_the_reason(predictor):
    n = predictor.n_window
    rows = np.zeros((n, 2))
    valid = np.zeros(n, dtype=bool)
    valid[-3:] = True
    p = predictor.predict(rows, valid, 1.3)
    assert not p.valid and "too few valid" in p.reason
    valid = np.ones(n, dtype=bool)
    valid[-10:] = False
    p = predictor.predict(rows, valid, 1.3)
    assert not p.valid and "newest" in p.reason


def test_a_short_history_or_a_horizon_beyond_the_fit_is_refused_with_the_reason(predictor):
    p = predictor.predict(np.zeros((5, 2)), np.ones(5, dtype=bool), 1.3)
    assert not p.valid and "needs" in p.reason
    n = predictor.n_window
    p = predictor.predict(np.zeros((n, 2)), np.ones(n, dtype=bool), 5.0)
    assert not p.valid and "outside" in p.reason


def test_gaps_are_filled_so_a_few_dropouts_barely_move_the_prediction(predictor):
    history, _, _ = _examples(range(400, 401))
    rows = history[50]
    full = predictor.predict(rows[:, :2], np.ones(len(rows), dtype=bool), 1.3)
    valid = np.ones(len(rows), dtype=bool)
    valid[10:15] = False
    holed = rows[:, :2].copy()
    holed[10:15] = 1e3  # garbage where invalid must not be read
    gapped = predictor.predict(holed, valid, 1.3)
    assert gapped.valid and abs(gapped.roll - full.roll) < math.radians(0.3)


@pytest.fixture(scope="module")
def small_predictor() -> LinearTiltPredictor:
    """A predictor fitted on two series: fitted once, for every example drawn below."""
    histories, future, groups = _examples(range(2))
    return LinearTiltPredictor.fit(histories, future, groups, HORIZONS_S, WINDOW_S, DT)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(0, 100), st.integers(1, 3)),
        elements=st.floats(allow_nan=True, allow_infinity=True, width=64),
    ),
    st.floats(allow_nan=True, allow_infinity=True),
)
def test_prediction_never_raises_on_any_input(small_predictor, history, horizon):
    small = small_predictor
    valid = np.isfinite(history).all(axis=1) if history.ndim == 2 else np.ones(0, dtype=bool)
    p = small.predict(history, valid, horizon)
    assert p.valid or p.reason
    assert 0.0 <= p.probability_within(5.0) <= 1.0


def test_save_and_load_give_the_same_predictions(predictor, tmp_path):
    path = predictor.save(tmp_path / "p.npz")
    loaded = LinearTiltPredictor.load(path)
    history, _, _ = _examples(range(500, 501))
    rows = history[7]
    a = predictor.predict(rows[:, :2], rows[:, 2] > 0.5, 1.3)
    b = loaded.predict(rows[:, :2], rows[:, 2] > 0.5, 1.3)
    assert (a.roll, a.pitch) == (b.roll, b.pitch) and loaded.channels == predictor.channels
    assert loaded.metadata["heldout_rms_deg"] == predictor.metadata["heldout_rms_deg"]


def test_the_held_out_chances_match_how_often_the_deck_is_within_the_limit(predictor):
    # the distribution of chances recorded at fitting describes the sea: their mean is the
    # fraction of new episodes' moments whose deck is within the limit a second later
    limit = 2.0
    chances = predictor.chances(1.0, limit)
    assert 100 <= len(chances) <= 1000 and np.all((chances >= 0.0) & (chances <= 1.0))
    _, future, _ = _examples(range(50, 60))
    k = int(np.argmin(np.abs(HORIZONS_S - 1.0)))
    truth = future[:, k][np.all(np.isfinite(future[:, k]), axis=1)]
    within = np.mean(np.degrees(np.hypot(truth[:, 0], truth[:, 1])) <= limit)
    assert chances.mean() == pytest.approx(within, abs=0.06)
    assert predictor.chances(9.0, limit).size == 0
    # the value of waiting with nothing left is the forced commit's: the mean chance
    assert predictor_stopping_values(predictor, 1.0, limit).value(0) == pytest.approx(
        chances.mean()
    )
    assert predictor_stopping_values(predictor, 9.0, limit) is None


def test_the_best_of_several_contact_times_is_the_one_with_the_best_chance(predictor):
    _, estimate = _deck_series(41, 20.0, math.radians(0.3))
    n = round(WINDOW_S / DT)
    horizons = (0.8, 1.0, 1.2, 1.4)
    chosen = set()
    for end in range(n, len(estimate), 37):
        window, flags = estimate[end - n : end], np.ones(n)
        singles = [predictor.predict(window, flags, h).probability_within(2.0) for h in horizons]
        best = predictor.best_within(window, flags, horizons, 2.0)
        assert best.valid and best.probability_within(2.0) == pytest.approx(max(singles))
        assert best.horizon_s == horizons[int(np.argmax(singles))]
        chosen.add(best.horizon_s)
    # the best moment moves with the deck: no one contact time wins everywhere
    assert len(chosen) >= 2
    # beyond the fit a contact time is skipped; with none left, or no history, it says why
    assert predictor.best_within(window, flags, (1.0, 99.0), 2.0).horizon_s == 1.0
    assert "outside" in predictor.best_within(window, flags, (99.0,), 2.0).reason
    assert not predictor.best_within(window, flags, (), 2.0).valid
    assert "valid" in predictor.best_within(window, np.zeros(n), horizons, 2.0).reason


def test_a_window_s_held_out_chances_are_the_best_of_its_contact_times_and_worth_more(predictor):
    window = (1.0, 1.2, 1.4)
    best = predictor.chances(window, 2.0)
    each = np.stack([predictor.chances(h, 2.0) for h in window])
    np.testing.assert_allclose(best, each.max(axis=0))
    one = predictor_stopping_values(predictor, 1.2, 2.0)
    several = predictor_stopping_values(predictor, window, 2.0)
    assert one is not None and several is not None
    assert several.value(0) > one.value(0) and several.value(10) >= one.value(10)
    assert predictor.chances((1.0, 99.0), 2.0).size == 0


def test_a_predictor_file_without_held_out_predictions_still_loads(predictor, tmp_path):
    path = predictor.save(tmp_path / "p.npz")
    with np.load(path) as data:
        kept = {k: data[k] for k in data.files if k != "heldout_means"}
    np.savez(tmp_path / "old.npz", **kept)
    old = LinearTiltPredictor.load(tmp_path / "old.npz")
    assert old.chances(1.0, 2.0).size == 0
    assert LinearTiltPredictor.load(path).chances(1.0, 2.0) == pytest.approx(
        predictor.chances(1.0, 2.0), abs=1e-3
    )


def test_a_file_that_is_not_a_predictor_is_refused_naming_it(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not numpy")
    with pytest.raises(ValueError, match=r"bad\.npz"):
        LinearTiltPredictor.load(bad)


def test_fitting_refuses_mismatched_shapes():
    histories, future, groups = _examples(range(2))
    with pytest.raises(ValueError, match="futures"):
        LinearTiltPredictor.fit(histories, future[:, :3], groups, HORIZONS_S, WINDOW_S, DT)
    with pytest.raises(ValueError, match="histories"):
        LinearTiltPredictor.fit(histories[:, :, :2], future, groups, HORIZONS_S, WINDOW_S, DT)
    with pytest.raises(ValueError, match="two episodes"):
        LinearTiltPredictor.fit(histories, future, np.zeros(len(groups)), HORIZONS_S, WINDOW_S, DT)


def test_futures_shift_within_an_episode_and_stop_at_its_end():
    truth = np.arange(10.0)[:, None].repeat(2, axis=1)
    episode = np.array([0] * 6 + [1] * 4)
    out = futures(truth, episode, np.array([0.0, 0.2]), 0.1)
    np.testing.assert_array_equal(out[:, 0, 0], truth[:, 0])
    assert out[0, 1, 0] == 2.0 and out[3, 1, 0] == 5.0
    assert np.isnan(out[4, 1, 0]) and np.isnan(out[5, 1, 0]) and out[6, 1, 0] == 8.0
    with pytest.raises(ValueError, match="multiples"):
        futures(truth, episode, np.array([0.15]), 0.1)


# ------------------------------------------------------------------ shipped predictors
@pytest.mark.parametrize("scenario", ["bench-ss3", "bench-ss4", "bench-ss5"])
def test_each_bench_scenario_ships_a_predictor_fitted_on_its_estimated_motion(scenario):
    predictor = LinearTiltPredictor.load(tilt_predictor_path(scenario))
    assert predictor.metadata["scenarios"] == [scenario]
    assert predictor.metadata["sensing"] == "realistic"
    assert predictor.metadata["estimator"] == "tight"
    assert predictor.window_s == 8.0 and predictor.dt_s == pytest.approx(0.05)
    assert predictor.channels == CHANNELS
    # the error a descent ahead is a fraction of the 5 deg limit, and larger at rougher seas
    k = int(np.argmin(abs(predictor.horizons_s - 1.3)))
    assert max(predictor.metadata["heldout_rms_deg"][k]) < 3.5


def test_the_bench_family_predictor_is_fitted_on_the_training_family_and_no_held_out_sea():
    predictor = LinearTiltPredictor.load(tilt_predictor_path("bench-broad"))
    members = training_family("bench-broad")
    assert predictor.metadata["seas"] == [m.name for m in members]
    assert predictor.metadata["scenarios"] == sorted({m.scenario for m in members})
    assert not set(predictor.metadata["scenarios"]) & set(HELD_OUT_SEAS)
    assert predictor.metadata["sensing"] == "realistic"
    assert predictor.metadata["estimator"] == "tight"
    assert predictor.window_s == 8.0 and predictor.channels == CHANNELS
    k = int(np.argmin(abs(predictor.horizons_s - 1.3)))
    assert max(predictor.metadata["heldout_rms_deg"][k]) < 3.5
    # the held-out bench sea reads the family's predictor, not one fitted to another sea
    assert load_config("bench-unseen").deck_predictor == "bench-broad"


def test_a_bare_name_is_a_shipped_predictor_and_a_path_is_itself(tmp_path):
    assert tilt_predictor_path("bench-ss4") == PREDICTOR_DIR / "deck_tilt_bench-ss4.npz"
    assert tilt_predictor_path(str(tmp_path / "x.npz")) == tmp_path / "x.npz"


# ------------------------------------------------------------------ the environment
def _env(**timing):
    from agents.training.sampler import make_timing_env

    return make_timing_env(
        "bench-ss4", "ideal", "truth", {f"timing.{k}": v for k, v in timing.items()}
    )


def test_the_model_wave_off_needs_a_history_as_long_as_its_window():
    with pytest.raises(ConfigError, match=r"timing\.history_s"):
        _env(wave_off_tilt_deg=5.0, wave_off_predictor="model")


def test_the_model_wave_off_needs_a_predictor():
    with pytest.raises(ConfigError, match=r"timing\.tilt_model"):
        _env(wave_off_tilt_deg=5.0, wave_off_predictor="model", tilt_model="", history_s=8.0)
    with pytest.raises(ConfigError, match=r"timing\.tilt_model"):
        _env(
            wave_off_tilt_deg=5.0,
            wave_off_predictor="model",
            tilt_model="no-such-sea",
            history_s=8.0,
        )


def test_a_certainty_demanding_model_wave_off_aborts_every_chosen_descent():
    # a deck within 0.5 deg, for certain: no prediction promises that
    env = _env(
        wave_off_tilt_deg=0.5,
        wave_off_predictor="model",
        wave_off_probability=1.0,
        history_s=8.0,
        wait_limit_s=6.0,
    )
    try:
        env.reset(seed=3)
        _, _, terminated, _, info = env.step(1)
        assert not terminated and info["wave_offs"] == 1 and not info["committed"]
        while not terminated:
            _, _, terminated, _, info = env.step(1)
        # only a commit at or past the wait limit is never waved off
        assert info["wait_s"] >= 6.0 and info["wave_offs"] >= 2
    finally:
        env.close()


def test_a_recorded_wave_off_step_holds_every_control_period_of_the_descent_and_the_climb():
    env = _env(
        wave_off_tilt_deg=0.5,
        wave_off_predictor="model",
        wave_off_probability=1.0,
        history_s=8.0,
        wait_limit_s=6.0,
    )
    try:
        env.reset(seed=3)
        base = env.unwrapped
        _, _, _, _, info = env.step(0)
        waited_s = info["wait_s"]
        assert waited_s > 0.0
        base.record_periods = True
        start_s = base.world.time
        _, reward, _, _, info = env.step(1)
        periods = base.periods_of_last_step
        times = np.array([p["time_s"] for p in periods])
        np.testing.assert_allclose(np.diff(times), base.env_dt, rtol=1e-9)
        assert times[0] == pytest.approx(start_s + base.env_dt) and times[-1] == base.world.time
        # the descent, then the climb back to the hold: within 5 cm of it, or for 1.5 s at most
        committed = [p["committed"] for p in periods]
        climb = committed.index(False)
        assert climb > 0 and committed == [True] * climb + [False] * (len(periods) - climb)
        climb_s = times[-1] - times[climb - 1]
        height_m = base.guidance.range_m(base._base_observation)
        # (here the hold is reached first: the climb stops there, before its 1.5 s)
        assert abs(height_m - base.timing.hold_height_m) < 0.05 and climb_s < 1.5
        # the whole go-around is waiting, added to the wait before it, and costs its time
        go_around_s = times[-1] - start_s
        assert info["wave_offs"] == 1 and info["wait_s"] == pytest.approx(waited_s + go_around_s)
        assert reward == pytest.approx(-base.config.reward.time_cost * go_around_s)
        # each record is the world at its period: the last one is the world now
        world, last = base.world, periods[-1]
        deck = world.deck_state()
        np.testing.assert_array_equal(last["drone_position_w"], world.drone_state().position_w)
        np.testing.assert_array_equal(last["deck_position_w"], deck.position_w)
        np.testing.assert_array_equal(last["deck_euler_w"], euler_zyx_from_matrix(deck.rotation_wp))
        r_cd, t_cd = world.true_deck_pose_c(deck)
        true_pose = np.concatenate([t_cd, euler_zyx_from_matrix(r_cd)])
        np.testing.assert_array_equal(last["deck_pose_true"], true_pose)
        observation = base._base_observation
        np.testing.assert_array_equal(last["deck_pose_observed"], observation["deck_pose"])
        assert last["deck_pose_valid"] is bool(observation["deck_pose_valid"][0])
        assert not np.array_equal(periods[0]["drone_position_w"], last["drone_position_w"])
        assert base.frames_of_last_step == []  # camera images only when rendering
        _, _, _, _, info = env.step(1)
        assert info["wave_offs"] == 2 and not info["committed"]
        # a new episode starts without them, its descent not yet planned, the records cleared
        base.record_periods = False
        _, info = env.reset(seed=4)
        assert info["wave_offs"] == 0 and info["wait_s"] == 0.0 and info["committed"] is False
        assert info["descent_s"] == 0.0
        assert info["planned_contact_s"] == base.timing.expected_contact_s
        assert base.periods_of_last_step == [] and base.frames_of_last_step == []
    finally:
        env.close()


def test_a_descent_past_its_timeout_ends_the_episode_as_a_timeout_of_that_length():
    env = _env(descent_timeout_s=0.5)
    try:
        env.reset(seed=3)
        start_s = env.unwrapped.world.time
        _, _, terminated, _, info = env.step(1)
        assert terminated and info["outcome"] == "timeout" and not info["is_success"]
        assert info["reward_time"] == 0.0  # a descent that was not waved off costs no wait
        # unasked, the control periods are not recorded
        assert env.unwrapped.record_periods is False
        assert env.unwrapped.periods_of_last_step == []
        assert info["descent_s"] == pytest.approx(0.5, abs=1e-9)
        assert env.unwrapped.world.time - start_s == pytest.approx(info["descent_s"], abs=1e-12)
    finally:
        env.close()


@pytest.mark.parametrize("level", [True, False])
def test_the_history_holds_the_deck_pose_levelled_by_the_drones_attitude_if_set(
    level: bool,
):
    env = _env(level_history=level)
    try:
        env.reset(seed=3)
        base = env.unwrapped
        pose = base._base_observation["deck_pose"].astype(float)
        levelled = levelled_deck_pose(pose, level_from_body(base.world.drone_state().rotation_wb))
        assert np.max(np.abs(levelled - pose)) > 1e-6  # the drone's tilt makes a difference
        newest = base.history.rows()[-1]
        np.testing.assert_allclose(newest[:6], levelled if level else pose, rtol=0.0, atol=1e-12)
    finally:
        env.close()


@pytest.mark.parametrize(("rate_window_s", "samples"), [(0.5, 10), (0.1, 2)])
def test_the_historys_rates_are_fitted_over_its_rate_window_of_at_least_two_samples(
    rate_window_s: float, samples: int
):
    # at 20 Hz: 0.5 s is ten samples, and the shortest window allowed, 0.1 s, two
    env = _env(rate_window_s=rate_window_s)
    try:
        env.reset(seed=3)
        rows = env.unwrapped.history.rows()
        times = np.arange(samples) * env.unwrapped.env_dt
        slopes = np.polyfit(times, rows[-samples:, 2:5], 1)[0]
        np.testing.assert_allclose(rows[-1, 6:9], slopes, rtol=1e-9, atol=1e-12)
    finally:
        env.close()


def test_a_timing_env_steps_only_after_a_reset_and_records_nothing_before():
    env = _env()
    try:
        base = env.unwrapped
        assert base.periods_of_last_step == [] and base.frames_of_last_step == []
        with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
            base.step(0)
    finally:
        env.close()


def test_a_rendered_recorded_step_keeps_the_camera_image_of_each_control_period():
    env = _env()
    try:
        env.reset(seed=3)
        base = env.unwrapped
        base.record_periods = True
        base.render_mode = "rgb_array"
        env.step(0)
        frames, periods = base.frames_of_last_step, base.periods_of_last_step
        assert len(frames) == len(periods) == base.timing.steps_per_decision
        np.testing.assert_array_equal(frames[-1], base.world.camera_image(base._sensing.frame))
    finally:
        env.close()


def test_the_descent_is_timed_on_the_environments_own_control_period():
    # at 40 Hz (0.025 s a period) the descent still meets the deck at its planned contact time
    from agents.training.sampler import make_timing_env

    env = make_timing_env("bench-ss4", "ideal", "truth", {"simulation.env_hz": 40})
    try:
        env.reset(seed=3)
        assert env.unwrapped.guidance.dt == env.unwrapped.env_dt == 0.025
        _, _, terminated, _, info = env.step(1)
        assert terminated and info["outcome"] == "success"
        assert abs(info["descent_s"] - info["planned_contact_s"]) < 0.1
    finally:
        env.close()


def test_the_value_wave_off_weighs_the_wait_so_far_during_a_descent():
    # the value rule's demanded chance reads the wait so far: each check of the descent passes it
    env = _env(
        wave_off_tilt_deg=5.0, wave_off_predictor="model", wave_off_rule="value", history_s=8.0
    )
    try:
        env.reset(seed=3)
        base = env.unwrapped
        asked = []
        chance = base.deck_prediction.wave_off_chance

        def asking(elapsed_s: float, wait_s: float) -> float:
            asked.append(wait_s)
            return chance(elapsed_s, wait_s)

        base.deck_prediction.wave_off_chance = asking
        env.step(0)
        waited_s = base._wait_s
        env.step(1)
        assert asked and all(wait_s == waited_s for wait_s in asked)
    finally:
        env.close()


def test_a_late_wave_offs_climb_back_stops_after_1_5_s_short_of_the_hold():
    # waved off 1.0-1.2 s into the descent, close to the deck: 1.5 s of climb do not regain
    # the 2 m hold to 5 cm, and the agent decides again then
    env = _env(
        wave_off_tilt_deg=0.5,
        wave_off_predictor="model",
        wave_off_probability=1.0,
        history_s=8.0,
        wait_limit_s=6.0,
        hold_height_m=2.0,
        wave_off_from_s=1.0,
        wave_off_until_s=1.2,
    )
    try:
        env.reset(seed=3)
        base = env.unwrapped
        base.record_periods = True
        _, _, terminated, _, info = env.step(1)
        assert not terminated and info["wave_offs"] == 1
        periods = base.periods_of_last_step
        climb = [p["committed"] for p in periods].index(False)
        climb_s = periods[-1]["time_s"] - periods[climb - 1]["time_s"]
        assert 1.5 - 1e-9 <= climb_s < 1.5 + base.env_dt
        height_m = base.guidance.range_m(base._base_observation)
        assert abs(height_m - 2.0) >= 0.05
    finally:
        env.close()


def test_a_model_wave_off_that_accepts_any_chance_never_aborts():
    env = _env(
        wave_off_tilt_deg=5.0, wave_off_predictor="model", wave_off_probability=0.0, history_s=8.0
    )
    try:
        env.reset(seed=3)
        _, _, terminated, _, info = env.step(1)
        assert terminated and info["wave_offs"] == 0
    finally:
        env.close()


def test_the_contact_window_is_a_grid_of_contact_times_and_empty_is_the_fixed_contact():
    from landing_env.guidance_gains import GuidanceGains
    from landing_env.timing_config import TimingConfig

    timed = GuidanceGains(descent_profile="timed")
    config = TimingConfig(guidance=timed, contact_window_s=[1.2, 1.5])
    assert config.contact_times_s == (1.2, 1.3, 1.4, 1.5)
    assert config.descent_time_for(1.5) == pytest.approx(1.4)
    assert TimingConfig(guidance=timed).contact_times_s == (1.3,)


@pytest.mark.parametrize(
    ("window", "extra", "key"),
    [
        ([1.5, 1.2], {}, "contact_window_s"),
        ([0.6, 1.2], {}, "contact_window_s"),
        ([1.2], {}, "contact_window_s"),
        ([1.2, math.nan], {}, "contact_window_s"),
        ([1.2, 1.5], {"guidance": {"descent_profile": "range"}}, "contact_window_s"),
        ([1.2, 1.5], {"contact_step_s": 0.0}, "contact_step_s"),
    ],
)
def test_a_bad_contact_window_is_refused_naming_the_key(window, extra, key):
    from landing_env.config_loading import build_dataclass
    from landing_env.timing_config import TimingConfig

    data = {"guidance": {"descent_profile": "timed"}, "contact_window_s": window}
    data.update(extra)
    with pytest.raises(ConfigError, match=key):
        build_dataclass(TimingConfig, data, "timing")


def test_a_contact_window_needs_a_predictor():
    with pytest.raises(ConfigError, match=r"timing\.tilt_model.*contact_window_s"):
        _env(contact_window_s=[1.2, 1.5], tilt_model="", history_s=8.0)
    with pytest.raises(ConfigError, match=r"timing\.history_s"):
        _env(contact_window_s=[1.2, 1.5])


def test_each_commit_times_its_descent_to_meet_the_deck_when_the_predictor_prefers():
    from agents.policies.registry import make_policy

    env = _env(contact_window_s=[1.2, 1.5], history_s=8.0)
    try:
        policy = make_policy("predictive", env)
        assert policy.contact_times_s == (1.2, 1.3, 1.4, 1.5)
        planned = []
        for seed in range(6):
            observation, _ = env.reset(seed=seed)
            for _ in range(seed * 7):
                observation, *_ = env.step(0)
            policy.act(observation)
            _, _, terminated, _, info = env.step(1)
            assert terminated and info["wave_offs"] == 0
            # the environment chose as the policy weighed it, and the feet met the deck then
            assert info["planned_contact_s"] == pytest.approx(policy.last.horizon_s)
            assert abs(info["descent_s"] - info["planned_contact_s"]) < 0.15
            planned.append(info["planned_contact_s"])
        assert len(set(planned)) >= 2
    finally:
        env.close()


# ------------------------------------------------------------------ the policy
def test_the_predictive_policy_needs_a_history_as_long_as_its_predictor_window():
    from agents.policies.registry import make_policy

    env = _env()
    try:
        with pytest.raises(ConfigError, match=r"timing\.history_s=8"):
            make_policy("predictive", env)
    finally:
        env.close()


def test_the_predictive_policy_decides_on_any_observation_inside_the_space():
    from agents.policies.registry import make_policy

    env = _env(history_s=8.0)
    try:
        policy = make_policy("predictive", env)
        space = env.observation_space
        space.seed(5)
        decisions = {policy.act(space.sample()) for _ in range(50)}
        assert decisions <= {0, 1}
        # the space's corners: all lows, all highs, all zeros
        for observation in (space.low, space.high, np.zeros_like(space.low)):
            assert policy.act(observation.astype(space.dtype)) in (0, 1)
            assert 0.0 <= policy.last_probability <= 1.0
    finally:
        env.close()


def test_the_predictive_policy_commits_over_a_level_deck_and_waits_over_a_tilted_one():
    from agents.policies.registry import make_policy
    from landing_env.anticipation.deck_history import HISTORY_FEATURES

    env = _env(history_s=8.0)
    try:
        policy = make_policy("predictive", env)
        layout = env.unwrapped.layout
        rows = np.zeros((layout.n_history, len(HISTORY_FEATURES)))
        rows[:, HISTORY_FEATURES.index("valid")] = 1.0
        rows[:, HISTORY_FEATURES.index("z")] = layout.hold_height_m
        tof = np.full(4, layout.hold_height_m)
        level, _ = layout.encode(rows, tof, np.ones(4, dtype=bool), 0.1)
        assert policy.act(level) == 1 and policy.last_probability > 0.98
        rows[:, HISTORY_FEATURES.index("roll")] = math.radians(8.0)
        tilted, _ = layout.encode(rows, tof, np.ones(4, dtype=bool), 0.1)
        assert policy.act(tilted) == 0 and policy.last_probability < 0.5
    finally:
        env.close()


def test_the_required_chance_falls_from_near_the_best_to_the_forced_commit_s_as_the_wait_runs_out():
    from agents.policies.registry import make_policy

    env = _env(history_s=8.0)
    try:
        policy = make_policy("predictive", env)
        thresholds = [policy.threshold(f) for f in np.linspace(0.0, 1.0, 31)]
        assert np.all(np.diff(thresholds) <= 1e-12)
        chances = policy.predictor.chances(1.3, 5.0)
        # 15 s of wait at bench sea state 4: nearly the best chance the sea offers
        assert thresholds[0] > np.quantile(chances, 0.75)
        # the last second: no better than the average chance, and nothing at the limit
        assert policy.threshold(0.95) <= chances.mean() + 0.2 and thresholds[-1] == 0.0
    finally:
        env.close()


def test_a_predictor_without_held_out_predictions_is_refused_by_the_policy_and_the_value_wave_off(
    tmp_path,
):
    from agents.policies.registry import make_policy

    bare = LinearTiltPredictor.load(tilt_predictor_path("bench-ss4"))
    bare.heldout_means = np.zeros((0, 0, 2))
    path = bare.save(tmp_path / "bare.npz")
    env = _env(history_s=8.0)
    try:
        with pytest.raises(ConfigError, match=r"timing\.tilt_model.*refit"):
            make_policy("predictive", env, model_path=path)
    finally:
        env.close()
    with pytest.raises(ConfigError, match=r"timing\.wave_off_rule.*refit"):
        _env(
            wave_off_tilt_deg=5.0,
            wave_off_predictor="model",
            wave_off_rule="value",
            tilt_model=str(path),
            history_s=8.0,
        )


def test_the_value_wave_off_needs_the_model_predictor():
    with pytest.raises(ConfigError, match="wave_off_rule"):
        _env(wave_off_tilt_deg=5.0, wave_off_rule="value")


def test_the_value_wave_off_demands_less_as_the_wait_runs_out_and_nothing_at_the_limit():
    env = _env(
        wave_off_tilt_deg=5.0, wave_off_predictor="model", wave_off_rule="value", history_s=8.0
    )
    try:
        base = env.unwrapped
        env.reset(seed=3)
        demanded = []
        for wait_s in (0.0, 5.0, 10.0, 13.0, 14.0):
            demanded.append(base.deck_prediction.wave_off_chance(0.5, wait_s))
        assert demanded == sorted(demanded, reverse=True) and demanded[0] > 0.95
        assert demanded[-1] == 0.0  # after the climb back nothing is left: never abort
    finally:
        env.close()


#: the settings of the bench timing ids up to v4, now settings of v6: v2 the wave-off below a
#: fixed chance, v3 below the value of waiting on, v4 with the contact window
_WAVE_OFF_VERSIONS = {
    2: {**PREDICTIVE, "timing.wave_off_rule": "fixed", "timing.contact_window_s": []},
    3: {**PREDICTIVE, "timing.contact_window_s": []},
    4: PREDICTIVE,
}


@pytest.mark.parametrize("version", [2, 3, 4])
def test_the_bench_id_with_the_predictive_settings_carries_the_history_and_wave_off_it_needs(
    version,
):
    import gymnasium as gym

    import landing_env  # noqa: F401
    from agents.policies.registry import make_policy

    env = gym.make("DeckLandingTiming-BenchSS4-v6", overrides=_WAVE_OFF_VERSIONS[version])
    try:
        base = env.unwrapped
        assert base.layout.n_history == 160 and base.deck_prediction.tilt_predictor is not None
        # the scenario's own predictor: bench-ss4.yaml's deck_predictor
        resolved = base.deck_prediction.resolved_tilt_model()
        assert base.timing.tilt_model == "scenario" and resolved == "bench-ss4"
        assert base.timing.wave_off_rule == ("fixed" if version == 2 else "value")
        assert (base.deck_prediction.wave_off_values is None) == (version == 2)
        assert len(base.timing.contact_times_s) == (4 if version == 4 else 1)
        policy = make_policy("predictive", env)
        assert policy.contact_times_s == base.timing.contact_times_s
        observation, _ = env.reset(seed=11)
        assert env.observation_space.contains(observation)
        assert policy.act(observation) in (0, 1) and policy.last.valid
    finally:
        env.close()


def test_a_model_card_records_the_predictor_a_model_wave_off_reads():
    from agents.common.cards import descent_signature
    from landing_env.guidance_gains import GuidanceGains

    gains = GuidanceGains(descent_profile="timed")
    signature = descent_signature(gains, 5.0, "model", "bench-ss4", 0.8)
    assert signature["tilt_model"] == "bench-ss4" and signature["wave_off_probability"] == 0.8
    valued = descent_signature(gains, 5.0, "model", "bench-ss4", 0.8, "value", 1.0)
    assert valued["wave_off_rule"] == "value" and valued["opportunity_s"] == 1.0
    assert "wave_off_probability" not in valued
    assert "tilt_model" not in descent_signature(gains, 5.0, "linear", "bench-ss4")
    chosen = descent_signature(gains, 5.0, "model", "bench-ss4", 0.8, "value", 1.0, (1.2, 1.3))
    assert chosen["contact_times_s"] == [1.2, 1.3]
    assert "contact_times_s" not in descent_signature(gains, 0.0, contact_times_s=(1.3,))
    ship = GuidanceGains(tracker_model="acceleration", deck_lead_s=0.2)
    assert descent_signature(ship) == {
        "profile": "range",
        "tracker_model": "acceleration",
        "deck_lead_s": 0.2,
    }
    assert descent_signature(GuidanceGains()) == {"profile": "range"}
    searching = GuidanceGains(tracker_model="acceleration", deck_lead_s=0.2, lost_deck="search")
    assert descent_signature(searching) == {**descent_signature(ship), "lost_deck": "search"}


def test_random_decisions_on_a_v4_id_under_realistic_sensing_never_leave_the_space():
    """A soak of the v4 timing task (the chosen contact time and the model wave-off in the
    loop, realistic sensing): random waits and commits, every observation inside the space,
    every reward finite, every contact time in the window."""
    import gymnasium as gym

    import landing_env  # noqa: F401

    env = gym.make(
        "DeckLandingTiming-BenchSS5-v6", overrides={"sensors": "realistic", **PREDICTIVE}
    )
    rng = np.random.default_rng(7)
    try:
        for episode in range(3):
            observation, _ = env.reset(seed=100 + episode)
            assert env.observation_space.contains(observation)
            done = False
            while not done:
                action = int(rng.random() < 0.15)
                observation, reward, terminated, truncated, info = env.step(action)
                assert env.observation_space.contains(observation)
                assert math.isfinite(reward)
                assert 1.2 - 1e-9 <= info["planned_contact_s"] <= 1.5 + 1e-9
                done = terminated or truncated
            assert info["outcome"] != "in_flight"
    finally:
        env.close()


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, -1e9])
def test_every_number_of_the_timing_settings_refuses_a_bad_value_naming_its_key(bad):
    from dataclasses import fields

    from landing_env.config_loading import build_dataclass
    from landing_env.timing_config import TimingConfig

    numeric = [
        f.name
        for f in fields(TimingConfig)
        if f.type in ("float", "int") and f.name != "level_history"
    ]
    assert {"wave_off_probability", "opportunity_s", "wait_limit_s"} <= set(numeric)
    for key in numeric:
        value = (
            int(bad)
            if isinstance(getattr(TimingConfig(), key), int) and math.isfinite(bad)
            else bad
        )
        with pytest.raises(ConfigError, match=key):
            build_dataclass(TimingConfig, {key: value}, "timing")


def test_the_evaluation_flies_the_predictive_policy_with_its_settings_and_set_overrides_win():
    from agents.policies.registry import make_env_and_policy

    env, policy = make_env_and_policy("predictive", "bench-ss4", "tight")
    try:
        base = env.unwrapped
        assert base.layout.n_history == 160 and base.timing.wave_off_rule == "value"
        assert policy.predictor.metadata["scenarios"] == ["bench-ss4"]
    finally:
        env.close()
    env, _ = make_env_and_policy(
        "predictive", "bench-ss4", "tight", extra_overrides={"timing.wave_off_rule": "fixed"}
    )
    try:
        assert env.unwrapped.timing.wave_off_rule == "fixed"
    finally:
        env.close()
    # the other policies fly the scenario as it is
    env, _ = make_env_and_policy("quiescent", "bench-ss4", "tight")
    try:
        base = env.unwrapped
        assert base.timing.history_s == 2.0 and base.deck_prediction.tilt_predictor is None
    finally:
        env.close()


def test_the_prediction_layout_round_trips_its_values_in_place_of_the_history():
    from landing_env.timing.layout import TimingObservationLayout

    layout = TimingObservationLayout(160, 0.7, n_prediction=6)
    assert not layout.history_observed and layout.size == 6 + 9
    prediction = np.array([0.9, 0.8, 0.7, 0.6, 0.85, 1.0])
    tof = np.array([0.7, 0.71, np.nan, 0.69])
    valid = np.array([True, True, False, True])
    flat, clipped = layout.encode(np.zeros((160, 10)), tof, valid, 0.25, prediction)
    parts = layout.decode(flat)
    assert not clipped and np.allclose(parts.prediction, prediction, atol=1e-6)
    assert parts.history.shape == (0, 10) and parts.wait_fraction == pytest.approx(0.25)
    assert np.allclose(parts.tof_range[valid], tof[valid], atol=1e-5)
    with pytest.raises(ValueError, match="prediction values"):
        layout.encode(np.zeros((160, 10)), tof, valid, 0.25, prediction[:4])


def test_the_v5_ids_observe_the_predictor_s_chances_and_the_value_of_waiting_on():
    """What a v5 observation holds is what the ``predictive`` rule computes from the same
    history: the chance at each contact time and the value of waiting over the wait left."""
    import gymnasium as gym

    import landing_env  # noqa: F401
    from landing_env.anticipation.deck_history import HISTORY_FEATURES

    env = gym.make(
        "DeckLandingTiming-BenchSS5-v6", overrides={"sensors": "realistic", **PREDICTION}
    )
    try:
        base = env.unwrapped
        assert env.observation_space.shape == (4 + 2 + 9,)
        observation, _ = env.reset(seed=21)
        for _ in range(30):
            observation, _, terminated, _, info = env.step(0)
            assert not terminated
        parts = base.layout.decode(observation)
        rows = base.history.rows()
        predictor = base.deck_prediction.tilt_predictor
        columns = [HISTORY_FEATURES.index(n) for n in predictor.channels]
        valid = rows[:, HISTORY_FEATURES.index("valid")] > 0.5
        expected = [
            predictor.predict(rows[:, columns], valid, h).probability_within(5.0)
            for h in base.timing.contact_times_s
        ]
        assert parts.prediction[5] == 1.0
        assert np.allclose(parts.prediction[:4], expected, atol=1e-6)
        left = base.timing.wait_limit_s - info["wait_s"]
        value = base.deck_prediction.observed_values.threshold(left, base.timing.opportunity_s)
        assert parts.prediction[4] == pytest.approx(value, abs=1e-6)
        assert 0.0 < value < 1.0
    finally:
        env.close()


def test_the_history_reading_policies_refuse_a_prediction_observation_naming_the_key():
    import gymnasium as gym

    import landing_env  # noqa: F401
    from agents.policies.registry import make_policy
    from landing_env.errors import ConfigError

    env = gym.make("DeckLandingTiming-BenchSS4-v6", overrides=PREDICTION)
    try:
        for name in ("quiescent", "predictive"):
            with pytest.raises(ConfigError, match=r"timing\.observation"):
                make_policy(name, env)
        assert make_policy("land-now", env).act(env.reset(seed=1)[0]) == 1
    finally:
        env.close()


def test_a_prediction_observation_needs_a_predictor_and_a_known_kind():
    import gymnasium as gym

    import landing_env  # noqa: F401
    from landing_env.errors import ConfigError
    from landing_env.timing_config import TimingConfig

    with pytest.raises(ConfigError, match="observation"):
        TimingConfig(observation="chances")
    with pytest.raises(ConfigError, match=r"timing\.tilt_model"):
        gym.make(
            "DeckLandingTiming-v0",
            config="bench-ss4",
            overrides={"timing.observation": "prediction"},
        )


def test_a_model_card_tells_the_prediction_observation_from_the_history():
    from agents.common.cards import observation_signature
    from landing_env.config_loading import build_dataclass
    from landing_env.scenarios import BENCH_TIMING, PREDICTIVE_TIMING
    from landing_env.timing_config import TimingConfig

    history = {**BENCH_TIMING, **PREDICTIVE_TIMING}
    prediction = {**history, "observation": "prediction"}
    v4 = observation_signature(build_dataclass(TimingConfig, history, "t"), 20)
    v5 = observation_signature(build_dataclass(TimingConfig, prediction, "t"), 20)
    assert "observation" not in v4 and v4["size"] == 160 * 10 + 9
    assert v5["observation"] == "prediction" and v5["tilt_model"] == "scenario"
    assert v5["contact_times_s"] == [1.2, 1.3, 1.4, 1.5] and v5["size"] == 15


def test_random_decisions_on_a_v5_id_under_realistic_sensing_never_leave_the_space():
    import gymnasium as gym

    import landing_env  # noqa: F401

    env = gym.make(
        "DeckLandingTiming-BenchSS4-v6", overrides={"sensors": "realistic", **PREDICTION}
    )
    rng = np.random.default_rng(8)
    try:
        for episode in range(2):
            observation, _ = env.reset(seed=300 + episode)
            done = False
            while not done:
                assert env.observation_space.contains(observation)
                assert np.all((observation[:6] >= 0.0) & (observation[:6] <= 1.0))
                observation, reward, terminated, truncated, info = env.step(int(rng.random() < 0.1))
                assert math.isfinite(reward)
                done = terminated or truncated
            assert info["outcome"] != "in_flight"
    finally:
        env.close()


def test_the_shipped_predictive_dqn_reads_the_prediction_and_refuses_the_history():
    """``timing-dqn-predictive`` was trained on DeckLandingTiming-BenchSS5-v5 (realistic,
    ``tight``), then over both bench sea states and the sensing profiles: its card records the
    prediction observation read from the scenario's own predictor; a history observation (the
    v4 settings) is refused naming the key; on held-out seeds it lands at least as often as
    ``land-now``, and it runs at sea state 4 and on ideal sensing without a flag."""
    from agents.common.cards import read_metadata
    from agents.evaluation.landing import evaluate_policy
    from agents.policies.registry import make_env_and_policy
    from agents.policies.timing import shipped_timing_model
    from landing_env.errors import ConfigError

    card = read_metadata(shipped_timing_model("dqn-predictive"))
    assert card is not None and card.observation["observation"] == "prediction"
    assert card.observation["tilt_model"] == "scenario" and card.estimator == "tight"
    # the second stage's card names its config and where it started from: the first stage's
    # final model, on the same task
    from agents.training.trainer import load_train_config

    train = ROOT / "configs" / "train"
    first = load_train_config(train / "timing_dqn_predictive.yaml")
    second = load_train_config(train / "timing_dqn_predictive_finetune.yaml")
    assert second.env_id == first.env_id == "DeckLandingTiming-BenchSS5-v6"
    assert second.settings.env_kwargs == first.settings.env_kwargs
    assert second.settings.init_model == f"{first.settings.out_dir}/timing_dqn_final.zip"
    # the third stage (2026-11-24, commit 62044bd) went on from the second's final weights,
    # randomised over both bench sea states (each its own predictor) and the sensing: one
    # card serves them all
    third = load_train_config(train / "timing_dqn_predictive_randomised.yaml")
    assert third.settings.init_model == f"{second.settings.out_dir}/timing_dqn_final.zip"
    assert card.training_config_source.endswith(
        "configs/train/timing_dqn_predictive_randomised.yaml"
    )
    assert card.training_config["deck_landing"]["init_model"].endswith(
        "timing_dqn_predictive_finetune/timing_dqn_final.zip"
    )
    assert set(card.sensing) == {"ideal", "realistic"}
    realistic = {"sensors": "realistic"}
    with pytest.raises(ConfigError, match=r"observation"):
        make_env_and_policy(
            "timing-dqn-predictive",
            "bench-ss5",
            "tight",
            extra_overrides={**realistic, "timing.observation": "history"},
        )
    episodes, first = 12, 2_000_000
    learned = evaluate_policy(
        "timing-dqn-predictive", "bench-ss5", episodes, first, "tight", extra_overrides=realistic
    )
    now = evaluate_policy(
        "land-now", "bench-ss5", episodes, first, "tight", extra_overrides=realistic
    )
    assert np.mean([r.success for r in learned]) >= np.mean([r.success for r in now])
    assert np.mean([r.success for r in learned]) >= 0.75
    # the card accepts bench-ss4 (its own predictor) under ideal sensing as it is
    env, policy = make_env_and_policy("timing-dqn-predictive", "bench-ss4", "tight")
    try:
        assert env.unwrapped.deck_prediction.resolved_tilt_model() == "bench-ss4"
        assert policy is not None
    finally:
        env.close()


def test_the_scenario_predictor_is_each_bench_scenarios_own_and_refused_where_none_is_fitted():
    """``timing.tilt_model: scenario`` reads the config's ``deck_predictor``; a scenario that
    names none (paper-stewart) is refused naming the key and what it reads."""
    from landing_env.envs.timing import DeckLandingTimingEnv

    loaded = {}
    for n in (3, 5):
        env = DeckLandingTimingEnv(
            f"bench-ss{n}",
            overrides=nested_to_dotted(
                {
                    "history_s": 8.0,
                    "observation": "prediction",
                    "tilt_model": "scenario",
                    "guidance": {"descent_profile": "timed"},
                },
                "timing",
            ),
        )
        try:
            assert env.deck_prediction.resolved_tilt_model() == f"bench-ss{n}"
            loaded[n] = env.deck_prediction.tilt_predictor
        finally:
            env.close()
    # two fitted predictors, not one file read twice
    assert loaded[3] is not None and loaded[5] is not None
    assert loaded[3].coefficients.shape != loaded[5].coefficients.shape or not np.allclose(
        loaded[3].coefficients, loaded[5].coefficients
    )
    with pytest.raises(ConfigError, match=r"timing\.tilt_model.*deck_predictor"):
        DeckLandingTimingEnv(
            "paper-stewart",
            overrides={
                "simulation.drone_fixed": False,
                **nested_to_dotted(
                    {"history_s": 8.0, "observation": "prediction", "tilt_model": "scenario"},
                    "timing",
                ),
            },
        )


def test_on_a_ship_the_hold_and_the_descent_fly_on_the_drones_own_state() -> None:
    """With the deck tracked (the ship ids), the guidance reads the drone's navigation state at
    the episode's first observation, in the hold and in the descent: without it the tracker
    stays empty and the set-points fall back to the camera's range."""
    import inspect

    import gymnasium as gym

    env = gym.make("DeckLandingTiming-ShipSS5-v8")
    try:
        guidance = env.unwrapped.guidance
        owns: dict[str, list] = {"observe": [], "hold": [], "descend": []}
        for name, calls in owns.items():
            flown = getattr(guidance, name)

            def spy(*args, _flown=flown, _calls=calls, **kwargs):
                bound = inspect.signature(_flown).bind(*args, **kwargs)
                _calls.append(bound.arguments.get("own"))
                return _flown(*args, **kwargs)

            setattr(guidance, name, spy)
        env.reset(seed=1)  # the first observation, then the warm-up's holds
        assert guidance.gains.track_deck and guidance.tracker.valid
        env.step(0)  # wait: a step of holds
        env.step(1)  # commit: the descent to its end
        assert owns["observe"] and owns["hold"] and owns["descend"]
        assert all(own is not None for calls in owns.values() for own in calls)
    finally:
        env.close()
