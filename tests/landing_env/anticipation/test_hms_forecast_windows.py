"""The helideck forecast's examples, by numbers: a forecast target at horizon h is the HMS
record h seconds after the window's last row."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from landing_env.anticipation.hms_forecast import (
    EXAMPLE_EVERY_S,
    HORIZONS_S,
    WINDOW_S,
    _examples,
)
from landing_env.sea.hms import HelideckMonitor, HelideckMonitorConfig

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
