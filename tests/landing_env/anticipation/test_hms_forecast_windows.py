"""The helideck forecast's examples, by numbers: a forecast target at horizon h is the HMS
record h seconds after the window's last row."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from landing_env.anticipation import hms_forecast
from landing_env.anticipation.hms_forecast import (
    EXAMPLE_EVERY_S,
    HORIZONS_S,
    WINDOW_S,
    _examples,
)
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.scenarios import SCENARIOS
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.sea.training_seas import TRAINING_FAMILIES, member_config
from landing_env.stewart.motion import MotionConfig, make_motion_source, sample_poses

DT_S = 0.1  # the HMS at 10 Hz
CHANNELS = 5


def ramp(rows: int) -> np.ndarray:
    """A record whose every channel counts its rows: row i holds i (and 1000 + i, ...)."""
    return np.arange(rows, dtype=float)[:, None] + 1000.0 * np.arange(CHANNELS)[None, :]


# ------------------------------------------------------------------ the forecast's examples
def test_a_forecast_target_lies_its_horizon_after_the_windows_last_row() -> None:
    record = ramp(600)
    windows, targets = _examples(record, record, DT_S)
    n_window = round(WINDOW_S / DT_S)
    assert windows.shape[1:] == (n_window, CHANNELS + 1)  # the five and the valid column
    assert targets.shape[1:] == (len(HORIZONS_S), CHANNELS)
    for window, target in zip(windows, targets, strict=True):
        last = window[-1, :CHANNELS]
        # horizon 0 is the window's last row; horizon h is h / dt rows after it
        np.testing.assert_array_equal(target[0], last)
        np.testing.assert_array_equal(target - last, np.outer(HORIZONS_S / DT_S, np.ones(5)))
        # the window is the n rows up to its last, oldest first, all valid
        np.testing.assert_array_equal(window[:, 0], last[0] - np.arange(n_window)[::-1])
        assert np.all(window[:, CHANNELS] == 1.0)


@settings(max_examples=60, deadline=None)
@given(
    extra_rows=st.integers(0, 400),
    dt_s=st.sampled_from([0.05, 0.1, 0.25, 0.5]),
)
def test_every_example_reads_the_past_and_targets_the_future_inside_the_record(
    extra_rows: int, dt_s: float
) -> None:
    n_window = round(WINDOW_S / dt_s)
    steps = np.round(HORIZONS_S / dt_s).astype(int)
    rows = n_window + steps[-1] + extra_rows
    record = ramp(rows)
    windows, targets = _examples(record, record, dt_s)
    ends = windows[:, -1, 0].astype(int)
    # one example every EXAMPLE_EVERY_S from the first full window, up to the last whose
    # furthest target is still recorded
    stride = max(1, round(EXAMPLE_EVERY_S / dt_s))
    np.testing.assert_array_equal(ends, np.arange(n_window - 1, rows - steps[-1], stride))
    np.testing.assert_array_equal(targets[:, :, 0], ends[:, None] + steps[None, :])
    np.testing.assert_array_equal(windows[:, 0, 0], ends - n_window + 1)
    np.testing.assert_array_equal(targets[:, :, 4] - 4000.0, targets[:, :, 0])


# ------------------------------------------------------------------ the HMS record's windows
class RampMotion:
    """A deck moving at constant rates: (x, y, z, roll, pitch, yaw) = t (1, 2, 3, 0.1, 0.2, 0)."""

    RATES = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.0])

    def pose(self, t: float) -> np.ndarray:
        return t * self.RATES

    def velocity(self, t: float) -> np.ndarray:
        return self.RATES.copy()

    def poses(self, times: np.ndarray) -> np.ndarray:
        return np.asarray(times, dtype=float)[:, None] * self.RATES[None, :]


@pytest.fixture(scope="module")
def exact_hms() -> HelideckMonitor:
    """The HMS of the ramp without errors."""
    config = HelideckMonitorConfig(
        angle_noise_deg=0.0, position_noise_m=0.0, position_noise_fraction=0.0
    )
    return HelideckMonitor(RampMotion(), config, seed=1, spread_record_s=10.0)


@pytest.fixture(scope="module")
def noisy_hms() -> HelideckMonitor:
    return HelideckMonitor(RampMotion(), HelideckMonitorConfig(), seed=7, spread_record_s=10.0)


@settings(max_examples=100, deadline=None)
@given(t_end_s=st.floats(0.0, 2000.0), window_s=st.floats(0.05, 60.0))
def test_an_hms_window_holds_the_samples_up_to_its_end_oldest_first(
    exact_hms: HelideckMonitor, t_end_s: float, window_s: float
) -> None:
    dt_s = exact_hms.dt_s
    times, values = exact_hms.window(t_end_s, window_s)
    assert len(times) == max(1, round(window_s / dt_s)) == len(values)
    # on the record's grid, evenly spaced, the newest the last sample at or before the end
    assert t_end_s - dt_s - 1e-9 < times[-1] <= t_end_s + 1e-9
    np.testing.assert_allclose(np.diff(times), dt_s, atol=1e-9)
    np.testing.assert_allclose(times / dt_s, np.round(times / dt_s), atol=1e-6)
    # each row is the deck at its time: surge, sway, heave, roll, pitch
    np.testing.assert_allclose(values, times[:, None] * RampMotion.RATES[None, :5], atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(t_end_s=st.floats(0.0, 2000.0), shift=st.integers(-300, 300), window_s=st.floats(1.0, 40.0))
def test_overlapping_hms_windows_agree_on_the_samples_they_share(
    noisy_hms: HelideckMonitor, t_end_s: float, shift: int, window_s: float
) -> None:
    # the record's errors are a fixed function of each sample, however it is read
    first_t, first = noisy_hms.window(t_end_s, window_s)
    second_t, second = noisy_hms.window(t_end_s + shift * noisy_hms.dt_s, window_s)
    common, i, j = np.intersect1d(
        np.round(first_t / noisy_hms.dt_s), np.round(second_t / noisy_hms.dt_s), return_indices=True
    )
    np.testing.assert_array_equal(first[i], second[j])
    assert len(common) == max(0, len(first_t) - abs(shift))


class StillMotion(RampMotion):
    """A deck at rest."""

    RATES = np.zeros(6)


def test_the_hms_samples_at_its_rate() -> None:
    assert HelideckMonitorConfig(rate_hz=4.0).dt_s == 0.25
    hms = HelideckMonitor(StillMotion(), HelideckMonitorConfig(rate_hz=4.0), spread_record_s=10.0)
    times, _ = hms.window(10.0, 1.0)
    np.testing.assert_allclose(times, [9.25, 9.5, 9.75, 10.0])
    # a window ending on a sample's time holds it, though 0.3 / 0.1 falls short of 3
    tenth = HelideckMonitor(StillMotion(), spread_record_s=1.0)
    np.testing.assert_allclose(tenth.window(0.3, 0.3)[0], [0.1, 0.2, 0.3])


def test_the_hms_errors_are_5_cm_or_5_percent_of_the_channels_spread_and_a_tenth_of_a_degree(
    noisy_hms: HelideckMonitor,
) -> None:
    # the ramp's spread over the 10 s before the start: that of a uniform ramp, times each rate
    spread = np.std(np.arange(-100, 0) * 0.1) * RampMotion.RATES[:3]
    angle = np.radians(0.1)
    np.testing.assert_allclose(noisy_hms.noise_std, [*(0.05 * spread), angle, angle])
    # by default over the 600 s before the start
    long_spread = np.std(np.arange(-6000, 0) * 0.1) * RampMotion.RATES[:3]
    np.testing.assert_allclose(HelideckMonitor(RampMotion()).noise_std[:3], 0.05 * long_spread)
    still = HelideckMonitor(StillMotion(), seed=7, spread_record_s=10.0)  # the default config
    np.testing.assert_allclose(still.noise_std, [0.05, 0.05, 0.05, angle, angle])
    # the errors drawn have those deviations (10 000 samples, across chunks of the record)
    _, values = still.window(1000.0, 1000.0)
    errors = values / still.noise_std
    np.testing.assert_allclose(errors.std(axis=0), 1.0, atol=0.03)
    np.testing.assert_allclose(errors.mean(axis=0), 0.0, atol=0.03)


def test_the_hms_errors_are_its_seeds_draws_and_any_integer_seeds_it() -> None:
    def errors(**seed: int) -> np.ndarray:
        return HelideckMonitor(StillMotion(), spread_record_s=1.0, **seed).window(5.0, 5.0)[1]

    # sample i's errors: row i of the seed's stream for the record's first 4096 samples
    hms = HelideckMonitor(StillMotion(), seed=7, spread_record_s=1.0)
    draws = np.random.default_rng([7, 2**32]).standard_normal((4096, 5))
    np.testing.assert_array_equal(errors(seed=7), draws[1:51] * hms.noise_std)
    np.testing.assert_array_equal(errors(), errors(seed=0))
    for other in (8, 9):
        assert not np.array_equal(errors(seed=7), errors(seed=other))
    np.testing.assert_array_equal(errors(seed=-1), errors(seed=2**63 - 1))


# ------------------------------------------------------------- the fits' records, by numbers
def ship_motion(sea_state: int = 4) -> MotionConfig:
    return load_config(SCENARIOS[f"ship-ss{sea_state}"].config).motion


def spy(monkeypatch: pytest.MonkeyPatch, name: str) -> list[tuple]:
    """Replace ``hms_forecast.<name>`` by one that records its arguments and returns a new
    object each call."""
    calls: list[tuple] = []

    def record(*args, **kwargs):
        calls.append((args, kwargs))
        return object()

    monkeypatch.setattr(hms_forecast, name, record)
    return calls


def test_each_fitting_record_is_its_seeds_hms_record_of_the_seas_in_turn_with_the_truth(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls = spy(monkeypatch, "_fit")
    motions = [ship_motion(4), ship_motion(5)]
    record_s = 2 * (WINDOW_S + HORIZONS_S[-1])  # the shortest record taken
    hms = HelideckMonitorConfig(rate_hz=5.0)
    hms_forecast.fit_deck_forecast(motions, hms, realizations=3, record_s=record_s, seed=40)
    (records, dt_s, metadata), _ = calls[0]
    assert dt_s == 0.2
    assert metadata == {"realizations": 3, "record_s": record_s, "seed": 40, "seas": 2}
    assert len(records) == 3
    for k, (measured, truth) in enumerate(records):
        source = make_motion_source(motions[k % 2], np.random.default_rng([40 + k]))
        times, expected = HelideckMonitor(source, hms, seed=40 + k).window(0.0, record_s)
        np.testing.assert_array_equal(measured, expected)
        np.testing.assert_array_equal(truth, sample_poses(source, times)[:, :5])


def test_a_fit_is_refused_naming_the_setting_out_of_its_range(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    spy(monkeypatch, "_fit")
    # records of one sample: only the checks are under test
    monkeypatch.setattr(hms_forecast, "make_motion_source", lambda motion, rng: None)
    monkeypatch.setattr(hms_forecast, "sample_poses", lambda source, times: np.zeros((1, 6)))

    class OneSample:
        def __init__(self, source, hms, seed) -> None:
            pass

        def window(self, t_end_s: float, window_s: float) -> tuple[np.ndarray, np.ndarray]:
            return np.zeros(1), np.zeros((1, 5))

    monkeypatch.setattr(hms_forecast, "HelideckMonitor", OneSample)
    fit = hms_forecast.fit_deck_forecast
    shortest = 2 * (WINDOW_S + HORIZONS_S[-1])
    with pytest.raises(ConfigError, match=r"^motion: no sea to fit the deck forecast on$"):
        fit([])
    with pytest.raises(ConfigError) as error:
        fit([ship_motion(), MotionConfig(kind="sinusoids")])
    assert str(error.value) == (
        "motion.kind: is 'sinusoids'; the deck forecast needs a sea (ship, sea_state)"
    )
    for realizations in (1, 1001):
        with pytest.raises(ConfigError, match=r"^realizations: "):
            fit(ship_motion(), realizations=realizations, record_s=shortest)
    for record_s in (shortest - 0.1, 1e6 + 1.0):
        with pytest.raises(ConfigError, match=r"^record_s: "):
            fit(ship_motion(), realizations=2, record_s=record_s)
    for realizations, record_s in ((2, shortest), (1000, 1e6)):
        fit((ship_motion(),), realizations=realizations, record_s=record_s)


def test_at_one_hms_sample_a_second_every_sample_ends_an_example() -> None:
    windows, _ = _examples(ramp(60), ramp(60), 1.0)
    np.testing.assert_array_equal(windows[:, -1, 0], np.arange(19, 60 - 8))


def test_the_fit_takes_every_records_examples_as_one_group_at_the_forecasts_sizes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls: list[tuple] = []

    class Fit:
        @staticmethod
        def fit(*args, **kwargs):
            calls.append((args, kwargs))
            return "fitted"

    monkeypatch.setattr(hms_forecast, "LinearMotionPredictor", Fit)
    records = [(ramp(300), ramp(300) + 0.5), (ramp(290), ramp(290) - 0.5)]
    assert hms_forecast._fit(records, DT_S, {"seed": 1}) == "fitted"
    (windows, futures, groups, horizons, window_s, dt_s), kwargs = calls[0]
    first, second = (_examples(m, t, DT_S) for m, t in records)
    np.testing.assert_array_equal(windows, np.concatenate([first[0], second[0]]))
    np.testing.assert_array_equal(futures, np.concatenate([first[1], second[1]]))
    np.testing.assert_array_equal(groups, [0] * len(first[0]) + [1] * len(second[0]))
    np.testing.assert_array_equal(horizons, HORIZONS_S)
    assert (window_s, dt_s) == (WINDOW_S, DT_S)
    assert kwargs == {
        "block": hms_forecast.BLOCK,
        "channels": HMS_CHANNELS,
        "targets": HMS_CHANNELS,
        "metadata": {"seed": 1},
    }


class RecordedHms:
    """An HMS whose record counts its rows, and which remembers the windows asked of it."""

    dt_s = DT_S

    def __init__(self) -> None:
        self.asked: list[tuple[float, float]] = []

    def window(self, t_end_s: float, window_s: float) -> tuple[np.ndarray, np.ndarray]:
        self.asked.append((t_end_s, window_s))
        rows = round(window_s / self.dt_s)
        return np.arange(rows) * self.dt_s, ramp(rows)


class OneRow(RecordedHms):
    """An HMS whose every window is one row."""

    def window(self, t_end_s: float, window_s: float) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(1), np.zeros((1, 5))


def test_the_online_forecast_is_fitted_on_eight_consecutive_parts_of_the_last_record(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls = spy(monkeypatch, "_fit")
    hms = RecordedHms()
    shortest = hms_forecast.ONLINE_PARTS * (WINDOW_S + HORIZONS_S[-1])
    hms_forecast.fit_online_forecast(hms, 500.0, record_s=shortest + 0.3)
    (records, dt_s, metadata), _ = calls[0]
    assert hms.asked == [(500.0, shortest + 0.3)] and dt_s == DT_S
    assert metadata == {"online_record_s": shortest + 0.3, "t_end_s": 500.0}
    part = round((shortest + 0.3) / DT_S) // 8
    assert len(records) == 8
    for k, (measured, targets) in enumerate(records):
        assert measured is targets  # the HMS's measurements are the targets too
        np.testing.assert_array_equal(measured, ramp(8 * part + 3)[k * part : (k + 1) * part])
    # by default over the last 1200 s; a shorter record than eight examples is refused
    hms_forecast.fit_online_forecast(hms, 700.0)
    assert hms.asked[-1] == (700.0, 1200.0)
    with pytest.raises(ConfigError) as error:
        hms_forecast.fit_online_forecast(hms, 700.0, record_s=shortest - 0.1)
    assert error.value.key == "record_s"
    with pytest.raises(ConfigError, match=r"^record_s: "):
        hms_forecast.fit_online_forecast(OneRow(), 700.0, record_s=1e6 + 1.0)


def test_an_episode_refits_its_online_forecast_once_it_is_old_or_the_clock_went_back(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls = spy(monkeypatch, "fit_online_forecast")
    hms = RecordedHms()
    episode = hms_forecast.EpisodeForecast(None, hms)
    first = episode.at(-5.0)
    assert calls == [((hms, -5.0), {})]
    assert episode.at(-5.0) is first and episode.at(-4.5) is first
    assert episode.at(-5.0 + hms_forecast.ONLINE_REFIT_S - 0.01) is first
    later = episode.at(-5.0 + hms_forecast.ONLINE_REFIT_S)
    assert later is not first and calls[-1][0][1] == -5.0 + hms_forecast.ONLINE_REFIT_S
    assert episode.at(20.0) is not later and calls[-1][0][1] == 20.0  # the clock went back
    assert episode.at(math.nan) is None and len(calls) == 3
    fitted = object()
    assert hms_forecast.EpisodeForecast(fitted, hms).at(0.0) is fitted and len(calls) == 3


class Hold:
    """A forecast that holds the window's last row at every horizon, and remembers the
    windows it was given; it cannot forecast a window whose last heave is negative."""

    window_s = WINDOW_S
    horizons_s = tuple(HORIZONS_S)

    def __init__(self) -> None:
        self.windows: list[np.ndarray] = []

    def predict_targets(self, window: np.ndarray, valid: np.ndarray) -> np.ndarray | str:
        assert valid.dtype == bool and valid.all() and len(valid) == len(window)
        self.windows.append(window)
        if window[-1, 2] < 0.0:
            return "no forecast"
        return np.repeat(window[-1:], len(HORIZONS_S), axis=0)


def test_the_forecasts_rms_error_is_over_its_windows_every_second_of_an_unseen_seeds_record() -> (
    None
):
    motion, record_s = ship_motion(), 60.5
    forecast = Hold()
    rms = hms_forecast.forecast_rms(forecast, motion, record_s=record_s)
    seed = hms_forecast.FIT_SEED - 1
    source = make_motion_source(motion, np.random.default_rng([seed]))
    times, measured = HelideckMonitor(source, HelideckMonitorConfig(), seed=seed).window(
        0.0, record_s
    )
    truth = sample_poses(source, times)[:, :5]
    n_window, steps = round(WINDOW_S / DT_S), np.round(HORIZONS_S / DT_S).astype(int)
    ends = np.arange(n_window - 1, len(times) - steps[-1], round(EXAMPLE_EVERY_S / DT_S))
    assert len(forecast.windows) == len(ends)
    errors = []
    for end, window in zip(ends, forecast.windows, strict=True):
        np.testing.assert_array_equal(window, measured[end - n_window + 1 : end + 1])
        if measured[end, 2] >= 0.0:
            errors.append(measured[end] - truth[end + steps])
    assert 0 < len(errors) < len(ends)  # the windows it could not forecast are left out
    np.testing.assert_allclose(rms, np.sqrt(np.mean(np.square(errors), axis=0)), rtol=1e-12)
    # at 1 Hz, an example every sample, each of 20 samples and its futures 1 to 8 s on
    slow = Hold()
    hms_forecast.forecast_rms(slow, motion, HelideckMonitorConfig(rate_hz=1.0), record_s=60.0)
    assert [len(window) for window in slow.windows] == [20] * len(range(19, 60 - 8))
    with pytest.raises(ConfigError, match=r"^record_s: 20 s holds no forecast window") as error:
        hms_forecast.forecast_rms(Hold(), motion, record_s=20.0)
    assert error.value.key == "record_s"


def test_a_scenarios_forecast_is_fitted_once_on_its_own_sea_or_on_its_training_family(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls = spy(monkeypatch, "cached_deck_forecast")
    monkeypatch.setattr(hms_forecast, "_FITTED", {})
    config, hms = load_config(SCENARIOS["ship-ss4"].config), HelideckMonitorConfig()
    own = hms_forecast.deck_forecast_for(config, hms)
    assert calls == [(((config.motion,), hms), {})]
    assert hms_forecast.deck_forecast_for(config, hms) is own and len(calls) == 1
    config.deck_forecast = "ship-broad"
    family = hms_forecast.deck_forecast_for(config, hms)
    members = tuple(member_config(m).motion for m in TRAINING_FAMILIES["ship-broad"])
    assert family is not own and calls[-1] == ((members, hms), {})
    assert hms_forecast.held_out_sea(config.motion) == ""
    held_out = load_config("ship-unseen-5")
    held_out.deck_forecast = ""
    with pytest.raises(ConfigError) as error:
        hms_forecast.deck_forecast_for(held_out, hms)
    assert str(error.value) == (
        "deck_forecast: is empty, and the sea is the held-out 'ship-unseen-5', which nothing is "
        "fitted on (landing_env/sea/heldout.py): use 'online' or a training family of seas "
        f"({', '.join(TRAINING_FAMILIES)})"
    )
    held_out.deck_forecast = "ship-everything"
    with pytest.raises(ConfigError, match=r"^deck_forecast: ") as error:
        hms_forecast.deck_forecast_for(held_out, hms)
    assert len(calls) == 2
