"""A predictor's error measured online: it scales the fitted covariance up by what the sea at
hand shows, never down, and never raises on data."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.prediction_error import PredictionErrorScale
from landing_env.errors import ConfigError
from landing_env.timing.config import TimingConfig

SIGMA = math.radians(1.5)
COV = np.diag([SIGMA**2, SIGMA**2])
NOISE = np.diag([math.radians(0.1) ** 2] * 2)


def _run(scale_of_error: float, n: int = 4000, seed: int = 0) -> PredictionErrorScale:
    """Predict ``horizon_s`` ahead every 0.1 s with errors ``scale_of_error`` times the
    fitted spread, the deck estimated exactly."""
    rng = np.random.default_rng(seed)
    check = PredictionErrorScale(1.3, COV, NOISE)
    truth = rng.normal(0.0, math.radians(3.0), (n + 20, 2))
    for k in range(n):
        t = 0.1 * k
        due = k + 13
        predicted = truth[due] + rng.normal(0.0, scale_of_error * SIGMA, 2)
        check.update(t, predicted, truth[k])
    return check


def test_errors_as_fitted_leave_the_covariance_as_it_is() -> None:
    check = _run(1.0)
    assert check.count > 3900
    assert check.scale == pytest.approx(1.0, abs=0.1)


def test_errors_twice_the_fitted_spread_scale_the_covariance_four_times() -> None:
    check = _run(2.0)
    assert check.scale == pytest.approx(4.0, rel=0.1)


def test_a_predictor_better_than_its_fit_is_never_trusted_more() -> None:
    assert _run(0.3).scale == 1.0


def test_few_checks_are_shrunk_toward_the_fit_and_reset_forgets() -> None:
    check = PredictionErrorScale(1.3, COV, NOISE, prior_count=20.0)
    for k in range(14):
        check.update(0.1 * k, np.array([0.0, 0.0]), np.array([3 * SIGMA, 0.0]))
    # one check of a 3-sigma error (9 against the 2 expected): (20*2 + 9) / 21 / 2
    assert check.count == 1
    assert check.scale == pytest.approx((40.0 + 9.0 * (SIGMA**2 / (SIGMA**2 + NOISE[0, 0]))) / 42.0)
    check.reset()
    assert check.count == 0 and check.scale == 1.0


def test_a_prediction_whose_time_passes_without_an_estimate_is_dropped() -> None:
    check = PredictionErrorScale(1.0, COV, NOISE)
    check.update(0.0, np.array([0.1, 0.1]), None)
    check.update(1.0, None, None)  # due now, but nothing to check it against
    check.update(5.0, None, np.array([0.0, 0.0]))
    assert check.count == 0 and check.scale == 1.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"horizon_s": 0.0}, "horizon_s"),
        ({"prior_count": -1.0}, "prior_count"),
        ({"tolerance_s": math.nan}, "tolerance_s"),
        ({"covariance": np.eye(3)}, "covariances"),
    ],
)
def test_bad_settings_are_refused_naming_them(kwargs, match) -> None:
    args = {"horizon_s": 1.3, "covariance": COV, "noise_covariance": NOISE, **kwargs}
    with pytest.raises(ValueError, match=match):
        PredictionErrorScale(**args)


def test_the_timing_key_takes_fit_or_online_only() -> None:
    assert TimingConfig().tilt_error == "fit"
    with pytest.raises(ConfigError, match="tilt_error"):
        TimingConfig(tilt_error="adaptive")


values = st.one_of(
    st.none(),
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=2, max_size=2).map(
        np.array
    ),
)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True), values, values), max_size=40)
)
def test_update_never_raises_and_the_scale_stays_finite_and_at_least_one(steps) -> None:
    check = PredictionErrorScale(1.3, COV, NOISE)
    for t, predicted, estimated in steps:
        check.update(t, predicted, estimated)
    assert math.isfinite(check.scale)
    assert check.scale >= 1.0
