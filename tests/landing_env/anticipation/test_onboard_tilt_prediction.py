"""The timing task's deck prediction, unit by unit: what it loads and refuses, and what it
foresees from a history, with a hand-made predictor whose answers are known.

The predictor of these tests extrapolates the newest roll and pitch along their last step
(two samples at 20 Hz, block 1), with a fixed covariance: its prediction at any horizon is
known exactly, so each question's answer is too.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from estimation.anticipation.linear_predictors import LinearTiltPredictor
from estimation.anticipation.stopping import predictor_stopping_values
from landing_env.anticipation.deck_history import HISTORY_FEATURES, DeckMotionHistory
from landing_env.anticipation.onboard_tilt_prediction import DeckPrediction
from landing_env.config import load_config
from landing_env.errors import ConfigError

DT = 0.05
SIGMA_DEG = 2.0


def _extrapolating(
    dt_s: float = DT,
    channels: tuple[str, ...] = ("roll", "pitch"),
    heldout: bool = True,
) -> LinearTiltPredictor:
    """Roll and pitch ``h`` ahead: the newest sample plus ``h`` times its last step's rate,
    with a covariance of SIGMA_DEG on each axis; fitted horizons 0, 1 and 2 s."""
    horizons = np.array([0.0, 1.0, 2.0])
    coefficients = np.zeros((3, 5, 2))
    for k, h in enumerate(horizons):
        for axis in range(2):
            coefficients[k, axis, axis] = -h / dt_s  # the older sample
            coefficients[k, 2 + axis, axis] = 1.0 + h / dt_s  # the newer
    covariance = np.tile(math.radians(SIGMA_DEG) ** 2 * np.eye(2), (3, 1, 1))
    spread = np.radians(np.linspace(-8.0, 8.0, 40))
    means = np.stack([np.column_stack([spread, 0.5 * spread])] * 3) if heldout else np.zeros(0)
    return LinearTiltPredictor(
        2 * dt_s,
        dt_s,
        1,
        horizons,
        coefficients,
        covariance,
        channels=channels,
        heldout_means=means,
    )


def _saved(tmp_path: Path, predictor: LinearTiltPredictor | None = None) -> str:
    path = tmp_path / "deck_tilt_test.npz"
    (predictor or _extrapolating()).save(path)
    return str(path)


def _prediction(
    timing: dict, config: str = "bench-ss4", length: int = 20, env_dt: float = DT
) -> DeckPrediction:
    overrides = {"timing.guidance.descent_profile": "timed"}
    overrides.update({f"timing.{key}": value for key, value in timing.items()})
    history = DeckMotionHistory(length, 2, env_dt)
    return DeckPrediction(load_config(config, overrides), history, env_dt)


def _push_tilt(prediction: DeckPrediction, rolls_deg, pitches_deg=None) -> None:
    pitches_deg = pitches_deg if pitches_deg is not None else [0.0] * len(rolls_deg)
    for roll, pitch in zip(rolls_deg, pitches_deg, strict=True):
        prediction.history.push(
            np.array([0.0, 0.0, 0.5, math.radians(roll), math.radians(pitch), 0])
        )


# ------------------------------------------------------------------ loading and refusing
def test_no_predictor_is_loaded_unless_a_wave_off_a_contact_window_or_the_observation_reads_it(
    tmp_path,
) -> None:
    path = _saved(tmp_path)
    for timing in (
        {"tilt_model": path},
        {"tilt_model": path, "wave_off_tilt_deg": 0.0, "wave_off_predictor": "model"},
        {"tilt_model": path, "wave_off_tilt_deg": 5.0, "wave_off_predictor": "linear"},
    ):
        prediction = _prediction(timing)
        assert prediction.tilt_predictor is None
        assert prediction.wave_off_values is None and prediction.observed_values is None
    for timing in (
        {"wave_off_tilt_deg": 5.0, "wave_off_predictor": "model"},
        {"wave_off_tilt_deg": 0.5, "wave_off_predictor": "model"},
        {"contact_window_s": [1.2, 1.5]},
        {"observation": "prediction"},
    ):
        prediction = _prediction({"tilt_model": path, **timing})
        assert isinstance(prediction.tilt_predictor, LinearTiltPredictor)
        np.testing.assert_array_equal(prediction.tilt_predictor.horizons_s, [0.0, 1.0, 2.0])
    assert prediction.timing is prediction.config.timing


def test_the_scenario_tilt_model_is_the_configs_deck_predictor_and_any_other_name_itself() -> None:
    assert _prediction({"tilt_model": "scenario"}).resolved_tilt_model() == "bench-ss4"
    assert _prediction({"tilt_model": "bench-ss5"}).resolved_tilt_model() == "bench-ss5"
    assert _prediction({}).resolved_tilt_model() == ""
    assert _prediction({"tilt_model": "scenario"}, "default").resolved_tilt_model() == ""


@pytest.mark.parametrize(
    ("timing", "config", "message"),
    [
        (
            {"tilt_model": "", "wave_off_tilt_deg": 5.0, "wave_off_predictor": "model"},
            "bench-ss4",
            "timing.tilt_model: is empty; the model wave-off needs the scenario's deck-tilt "
            "predictor (e.g. bench-ss4, or a file written by "
            "`python -m agents.training.tilt_predictor_fit fit`)",
        ),
        (
            {"tilt_model": "", "contact_window_s": [1.2, 1.5]},
            "bench-ss4",
            "timing.tilt_model: is empty; timing.contact_window_s needs",
        ),
        (
            {"tilt_model": "", "observation": "prediction"},
            "bench-ss4",
            "timing.tilt_model: is empty; timing.observation = 'prediction' needs",
        ),
        (
            {"tilt_model": "scenario", "observation": "prediction"},
            "default",
            "timing.tilt_model: 'scenario' reads the scenario's deck_predictor, which this config "
            "does not name; timing.observation = 'prediction' needs",
        ),
        (
            {"tilt_model": "no-such-sea", "observation": "prediction"},
            "bench-ss4",
            "timing.tilt_model: 'no-such-sea': ",
        ),
    ],
)
def test_a_missing_tilt_model_is_refused_naming_the_key_and_the_setting_that_needs_it(
    timing: dict, config: str, message: str
) -> None:
    with pytest.raises(ConfigError) as error:
        _prediction(timing, config)
    assert str(error.value).startswith(message)
    if "no-such-sea" in message:
        assert str(error.value).endswith(
            "; give a shipped one (bench-broad, bench-ss3, bench-ss4, bench-ss5) or a file "
            "written by `python -m agents.training.tilt_predictor_fit fit`"
        )
        assert "deck_tilt_no-such-sea.npz" in str(error.value)


def test_a_predictor_that_does_not_fit_the_history_is_refused_saying_how(tmp_path) -> None:
    # a channel the history does not hold
    heave = _extrapolating(channels=("roll", "heave"))
    with pytest.raises(ConfigError) as error:
        _prediction({"tilt_model": _saved(tmp_path, heave), "observation": "prediction"})
    assert str(error.value) == (
        f"timing.tilt_model: deck_tilt_test.npz reads ['heave'], which the history does not "
        f"hold ({', '.join(HISTORY_FEATURES)})"
    )
    # fitted at another rate
    with pytest.raises(ConfigError) as error:
        _prediction(
            {"tilt_model": _saved(tmp_path, _extrapolating(0.1)), "contact_window_s": [1.2, 1.5]}
        )
    assert str(error.value) == (
        "timing.tilt_model: deck_tilt_test.npz was fitted at 10 Hz; simulation.env_hz is 20"
    )
    # a history shorter than its window (two samples)
    path = _saved(tmp_path)
    with pytest.raises(ConfigError) as error:
        _prediction({"tilt_model": path, "observation": "prediction"}, length=1)
    assert str(error.value).startswith(
        "timing.history_s: 2 s is shorter than the deck-tilt predictor's 0.1 s window: "
        "set timing.history_s=0.1"
    )
    assert _prediction({"tilt_model": path, "observation": "prediction"}, length=2).tilt_predictor


def test_the_value_wave_off_and_the_prediction_observation_need_held_out_chances(
    tmp_path,
) -> None:
    bare = _saved(tmp_path, _extrapolating(heldout=False))
    value = {
        "tilt_model": bare,
        "wave_off_tilt_deg": 5.0,
        "wave_off_predictor": "model",
        "wave_off_rule": "value",
        "contact_window_s": [1.2, 1.5],
    }
    with pytest.raises(ConfigError) as error:
        _prediction(value)
    assert str(error.value) == (
        f"timing.wave_off_rule: 'value' needs the chances the predictor {bare!r} gave held-out "
        "examples 1.2-1.5 s ahead, which it does not hold: refit it with "
        "`python -m agents.training.tilt_predictor_fit fit`"
    )
    with pytest.raises(ConfigError) as error:
        _prediction({"tilt_model": bare, "observation": "prediction"})
    assert str(error.value) == (
        f"timing.observation: 'prediction' needs the chances the predictor {bare!r} gave "
        "held-out examples 1.3-1.3 s ahead, which it does not hold: refit it with "
        "`python -m agents.training.tilt_predictor_fit fit`"
    )
    # the fixed rule reads no held-out chances
    fixed = _prediction({**value, "wave_off_rule": "fixed"})
    assert fixed.tilt_predictor is not None and fixed.wave_off_values is None


def test_the_values_of_waiting_on_are_the_predictors_at_the_contact_times_and_their_limits(
    tmp_path,
) -> None:
    path = _saved(tmp_path)
    predictor = LinearTiltPredictor.load(path)
    prediction = _prediction(
        {
            "tilt_model": path,
            "wave_off_tilt_deg": 3.0,
            "wave_off_predictor": "model",
            "wave_off_rule": "value",
            "contact_window_s": [1.2, 1.5],
            "observation": "prediction",
        }
    )
    times = (1.2, 1.3, 1.4, 1.5)
    # the wave-off's at its own tilt; the observation's at the touchdown limit (5 deg)
    for values, limit in ((prediction.wave_off_values, 3.0), (prediction.observed_values, 5.0)):
        expected = predictor_stopping_values(predictor, times, limit)
        assert values is not None and expected is not None
        for remaining_s in (0.5, 3.0, 20.0):
            assert values.threshold(remaining_s, 1.0) == pytest.approx(
                expected.threshold(remaining_s, 1.0)
            )
    assert prediction.wave_off_values.threshold(3.0, 1.0) != pytest.approx(
        prediction.observed_values.threshold(3.0, 1.0)
    )
    # a strict one (0.5 deg) has its own
    strict = _prediction(
        {
            "tilt_model": path,
            "wave_off_tilt_deg": 0.5,
            "wave_off_predictor": "model",
            "wave_off_rule": "value",
        }
    )
    expected = predictor_stopping_values(predictor, (1.3,), 0.5)
    assert strict.wave_off_values.threshold(3.0, 1.0) == pytest.approx(expected.threshold(3.0, 1.0))
    # a model wave-off off (0 deg) has no value to compare with
    off = _prediction(
        {
            "tilt_model": path,
            "wave_off_rule": "value",
            "wave_off_predictor": "model",
            "observation": "prediction",
        }
    )
    assert off.wave_off_values is None and off.observed_values is not None


# ------------------------------------------------------------------ what it foresees
def test_the_contact_is_the_window_time_of_the_best_chance_and_the_expected_one_without(
    tmp_path,
) -> None:
    path = _saved(tmp_path)
    window = _prediction({"tilt_model": path, "contact_window_s": [1.2, 1.5]})
    assert window.plan_contact() == 1.3  # nothing in the history: the expected contact
    # rolling back towards level at 4 deg/s from 8 deg: 3.2 deg at 1.2 s ... 2.0 deg at 1.5 s
    _push_tilt(window, [8.2, 8.0])
    assert window.plan_contact() == pytest.approx(1.5)
    # rolling away from level: the earliest
    _push_tilt(window, [8.0, 8.2])
    assert window.plan_contact() == pytest.approx(1.2)
    # the pitch column is read too: level in roll, pitching back to level
    _push_tilt(window, [0.0, 0.0], [8.2, 8.0])
    assert window.plan_contact() == pytest.approx(1.5)
    # without a window the expected contact, whatever the deck does
    fixed = _prediction(
        {"tilt_model": path, "observation": "prediction", "expected_contact_s": 1.4}
    )
    _push_tilt(fixed, [8.2, 8.0])
    assert fixed.plan_contact() == 1.4


def test_the_prediction_values_are_each_contact_times_chance_the_value_of_waiting_and_validity(
    tmp_path,
) -> None:
    path = _saved(tmp_path)
    prediction = _prediction(
        {
            "tilt_model": path,
            "contact_window_s": [1.2, 1.4],
            "observation": "prediction",
            "wait_limit_s": 6.0,
            "opportunity_s": 0.5,
        }
    )
    predictor = prediction.tilt_predictor
    empty = prediction.prediction_values(1.0)
    value = prediction.observed_values.threshold(5.0, 0.5)
    np.testing.assert_allclose(empty, [0.0, 0.0, 0.0, value, 0.0])
    _push_tilt(prediction, [8.2, 8.0], [1.0, 1.0])
    rows = prediction.history.rows()
    values = prediction.prediction_values(1.0)
    for k, horizon in enumerate((1.2, 1.3, 1.4)):
        expected = predictor.predict(rows[:, [3, 4]], rows[:, 9] > 0.5, horizon)
        assert values[k] == pytest.approx(expected.probability_within(5.0))
    assert values[0] < values[1] < values[2]
    assert values[3] == pytest.approx(value) and values[4] == 1.0
    # the wait run out: nothing to wait for
    assert prediction.prediction_values(6.0)[3] == 0.0
    assert prediction.prediction_values(9.0)[3] == 0.0
    # the newest sample lost: no prediction, the chances 0 and the row invalid
    prediction.history.push(None)
    np.testing.assert_allclose(prediction.prediction_values(1.0), [0.0, 0.0, 0.0, value, 0.0])


def _wave_off(tmp_path, length: int = 20, **timing) -> DeckPrediction:
    settings = {
        "wave_off_tilt_deg": 3.0,
        "wave_off_from_s": 0.4,
        "wave_off_until_s": 0.7,
        "steps_per_decision": 2,
    }
    settings.update(timing)
    return _prediction(settings, length=length)


def test_the_linear_wave_off_carries_the_newest_tilt_along_its_rate_to_the_contact(
    tmp_path,
) -> None:
    prediction = _wave_off(tmp_path)
    # rolling at 4 deg/s from 1 deg: 1 + 4 x (1.3 - 0.5) = 4.2 deg at the contact, 0.5 s in
    _push_tilt(prediction, [0.8, 1.0])
    assert prediction.history.rows()[-1, 7] == pytest.approx(math.radians(4.0))
    assert prediction.wave_off_due(0.5, 1.3, 0.0)
    # 0.4 + 2 x 0.8 = 2.0 deg: on
    on = _wave_off(tmp_path)
    _push_tilt(on, [0.3, 0.4])
    assert not on.wave_off_due(0.5, 1.3, 0.0)
    # a predictor loaded for the contact window does not replace the linear wave-off: 2 deg,
    # steady, is within 3 deg (the model gives it a chance below the required 0.8)
    windowed = _wave_off(tmp_path, tilt_model=_saved(tmp_path), contact_window_s=[1.2, 1.5])
    assert windowed.tilt_predictor is not None
    _push_tilt(windowed, [2.0, 2.0])
    assert not windowed.wave_off_due(0.5, 1.3, 0.0)
    # past the contact the tilt is the newest one (no extrapolation backwards)
    late = _wave_off(tmp_path, wave_off_until_s=2.0)
    _push_tilt(late, [3.6, 3.1])
    assert late.wave_off_due(1.5, 1.3, 0.0)
    assert not late.wave_off_due(1.0, 1.3, 0.0)  # 3.1 - 10 x 0.3 = 0.1 deg
    # the pitch carried along its rate as well: 4.2 deg of pitch
    pitched = _wave_off(tmp_path)
    _push_tilt(pitched, [0.0, 0.0], [0.8, 1.0])
    assert pitched.wave_off_due(0.5, 1.3, 0.0)
    late_pitch = _wave_off(tmp_path, wave_off_until_s=2.0)
    _push_tilt(late_pitch, [0.0, 0.0], [3.6, 3.1])
    assert late_pitch.wave_off_due(1.5, 1.3, 0.0) and not late_pitch.wave_off_due(1.0, 1.3, 0.0)
    # a strict limit: 0.8 deg, steady, is beyond 0.5 deg
    strict = _wave_off(tmp_path, wave_off_tilt_deg=0.5)
    _push_tilt(strict, [0.8, 0.8])
    assert strict.wave_off_due(0.5, 1.3, 0.0)


def test_the_wave_off_is_judged_only_in_its_window_and_with_a_valid_newest_row(tmp_path) -> None:
    prediction = _wave_off(tmp_path)
    _push_tilt(prediction, [8.0, 8.0])
    # from max(one decision = 0.1 s, wave_off_from_s = 0.4 s) to wave_off_until_s, ends included
    for elapsed_s, due in ((0.3, False), (0.4, True), (0.55, True), (0.7, True), (0.71, False)):
        assert prediction.wave_off_due(elapsed_s, 1.3, 0.0) is due
    # a decision longer than wave_off_from_s starts it later
    slow = _wave_off(tmp_path, steps_per_decision=10)
    _push_tilt(slow, [8.0, 8.0])
    assert not slow.wave_off_due(0.45, 1.3, 0.0) and slow.wave_off_due(0.5, 1.3, 0.0)
    # off at 0 deg
    off = _wave_off(tmp_path, wave_off_tilt_deg=0.0)
    _push_tilt(off, [8.0, 8.0])
    assert not off.wave_off_due(0.5, 1.3, 0.0)
    # the newest sample lost: the descent goes on
    prediction.history.push(None)
    assert not prediction.wave_off_due(0.5, 1.3, 0.0)


def test_the_quadratic_wave_off_fits_the_curve_of_its_window_once_five_samples_are_valid(
    tmp_path,
) -> None:
    # a roll curving back: r(t) = 4 - 40 t^2 deg (t in s, 0 now), over the last 0.5 s; the
    # last two samples' rate is +2 deg/s
    times = np.arange(-9, 1) * DT
    curve = [4.0 - 40.0 * t**2 for t in times]
    quadratic = _wave_off(tmp_path, wave_off_predictor="quadratic", wave_off_window_s=0.5)
    _push_tilt(quadratic, curve)
    # 0.5 s in, the contact 0.1 s ahead: 4 - 40 x 0.01 = 3.6 deg, beyond 3 deg
    assert quadratic.wave_off_due(0.5, 0.6, 0.0)
    # 0.2 s ahead: 4 - 1.6 = 2.4 deg, within (the line of the last two: 4.4 deg)
    assert not quadratic.wave_off_due(0.5, 0.7, 0.0)
    # the pitch fitted as well
    pitched = _wave_off(tmp_path, wave_off_predictor="quadratic", wave_off_window_s=0.5)
    _push_tilt(pitched, [0.0] * 10, curve)
    assert pitched.wave_off_due(0.5, 0.6, 0.0) and not pitched.wave_off_due(0.5, 0.7, 0.0)
    # in the window's 10 samples, 4 valid: the line, 4.4 deg; 5 valid: the curve. (The level
    # samples before the window are not fitted.)
    for valid, due in ((4, True), (5, False)):
        few = _wave_off(tmp_path, 30, wave_off_predictor="quadratic", wave_off_window_s=0.5)
        _push_tilt(few, [0.0] * 10)
        for _ in range(10 - valid):
            few.history.push(None)
        _push_tilt(few, curve[-valid:])
        assert few.wave_off_due(0.5, 0.7, 0.0) is due
    # a parabola, not every bend: of r(t) = 4 + 300 t^3 deg the fit's -2.4 deg 0.1 s ahead
    # (the line 4.1 deg, the cubic 4.3 deg)
    cubic = _wave_off(tmp_path, wave_off_predictor="quadratic", wave_off_window_s=0.5)
    _push_tilt(cubic, [4.0 + 300.0 * t**3 for t in times])
    assert not cubic.wave_off_due(0.5, 0.6, 0.0)


def test_the_model_wave_off_aborts_below_its_chance_or_the_value_of_waiting_on(tmp_path) -> None:
    path = _saved(tmp_path)
    model = {"tilt_model": path, "wave_off_predictor": "model", "wave_off_probability": 0.5}
    fixed = _wave_off(tmp_path, **model)
    predictor = fixed.tilt_predictor
    assert fixed.wave_off_chance(0.5, 2.0) == 0.5
    # no valid window: the descent goes on
    fixed.history.push(np.zeros(6))
    assert not fixed.wave_off_due(0.5, 1.3, 0.0)
    # 3 deg of roll, steady: the chance within 3 deg at the contact is about 0.4 (< 0.5)
    _push_tilt(fixed, [3.0, 3.0])
    rows = fixed.history.rows()
    chance = predictor.predict(rows[:, [3, 4]], rows[:, 9] > 0.5, 0.8).probability_within(3.0)
    assert 0.3 < chance < 0.5
    assert fixed.wave_off_due(0.5, 1.3, 0.0)
    _push_tilt(fixed, [2.0, 2.0])
    assert not fixed.wave_off_due(0.5, 1.3, 0.0)
    # a chance of 0 is not below a required 0: it never aborts
    never = _wave_off(tmp_path, **{**model, "wave_off_probability": 0.0})
    _push_tilt(never, [60.0, 60.0])
    assert never.wave_off_chance(0.5, 0.0) == 0.0
    assert not never.wave_off_due(0.5, 1.3, 0.0)
    # the value rule: the value of waiting on after the climb back, with the wait left
    value = _wave_off(tmp_path, **model, wave_off_rule="value", wait_limit_s=10.0)
    remaining_s = 10.0 - 2.0 - 0.5 - 1.5
    expected = value.wave_off_values.threshold(remaining_s, value.timing.opportunity_s)
    assert value.wave_off_chance(0.5, 2.0) == pytest.approx(expected)
    assert 0.0 < expected < 1.0
    assert value.wave_off_chance(0.5, 9.0) == 0.0  # no time left for another try


def test_the_value_wave_off_aborts_below_the_value_left_after_the_time_elapsed_and_waited(
    tmp_path,
) -> None:
    """With the value rule the model wave-off compares the chance at the contact with the
    value of waiting on for the time the descent (``elapsed_s``) and the wait (``wait_s``)
    leave: with no time left the value is 0 and it never aborts."""
    model = {"tilt_model": _saved(tmp_path), "wave_off_predictor": "model"}
    value = _wave_off(tmp_path, **model, wave_off_rule="value", wait_limit_s=10.0)
    _push_tilt(value, [3.0, 3.0])
    rows = value.history.rows()
    chance = value.tilt_predictor.predict(rows[:, [3, 4]], rows[:, 9] > 0.5, 0.8)
    chance = chance.probability_within(3.0)
    for elapsed_s, wait_s in ((0.5, 0.0), (0.5, 2.0), (0.6, 5.0), (0.5, 9.0)):
        threshold = value.wave_off_chance(elapsed_s, wait_s)
        due = value.wave_off_due(elapsed_s, 0.8 + elapsed_s, wait_s)
        assert due == (chance < threshold)
    assert not value.wave_off_due(0.5, 1.3, 9.0)
