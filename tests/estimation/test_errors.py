"""The configuration checks (estimation.errors): what they let through, and the key, value and
allowed values that their refusals name."""

from __future__ import annotations

import math
import pickle

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.errors import ConfigError, require_choice, require_finite, require_range


def refusal(check, *args, **kwargs) -> ConfigError:
    """The error a check raises (the test fails when it lets the value through)."""
    with pytest.raises(ConfigError) as caught:
        check(*args, **kwargs)
    return caught.value


def test_a_config_error_holds_its_key_and_message_and_reads_key_colon_message() -> None:
    error = ConfigError("camera.mode", "'x' is not allowed")
    assert isinstance(error, ValueError)
    assert (error.key, error.detail, str(error)) == (
        "camera.mode",
        "'x' is not allowed",
        "camera.mode: 'x' is not allowed",
    )
    copied = pickle.loads(pickle.dumps(error))
    assert type(copied) is ConfigError
    assert (copied.key, copied.detail, str(copied)) == (error.key, error.detail, str(error))


def test_an_error_under_a_prefix_names_the_dotted_key_and_keeps_its_message() -> None:
    error = ConfigError("mode", "'x' is not allowed")
    nested = error.under("camera")
    assert type(nested) is ConfigError
    assert (nested.key, nested.detail, str(nested)) == (
        "camera.mode",
        "'x' is not allowed",
        "camera.mode: 'x' is not allowed",
    )
    assert error.under("sim").under("camera").key == "camera.sim.mode"
    # no prefix: the key as it was, without a leading dot
    same = error.under("")
    assert (same.key, same.detail, str(same)) == ("mode", "'x' is not allowed", str(error))


def test_a_choice_outside_the_allowed_ones_is_refused_naming_the_key_and_each_choice() -> None:
    # the choices may come from a generator: they are read once, for the test and the message
    require_choice("camera.mode", "render", (name for name in ("detections", "render")))
    error = refusal(require_choice, "camera.mode", "rendr", (n for n in ("detections", "render")))
    assert (error.key, error.detail) == (
        "camera.mode",
        "'rendr' is not allowed; choose one of 'detections', 'render'",
    )
    assert str(error) == "camera.mode: 'rendr' is not allowed; choose one of 'detections', 'render'"
    assert refusal(require_choice, "n", 3, [1, 2]).detail == "3 is not allowed; choose one of 1, 2"


@pytest.mark.parametrize("value", [0, -3, 2.5, 1e308, -1e-300, True])
def test_a_finite_number_passes_the_finite_check(value: float) -> None:
    require_finite("rate_hz", value)


@pytest.mark.parametrize(
    ("value", "detail"),
    [
        (math.nan, "nan is not allowed; give a finite number"),
        (math.inf, "inf is not allowed; give a finite number"),
        (-math.inf, "-inf is not allowed; give a finite number"),
        ("fast", "'fast' is not a number"),
        (None, "None is not a number"),
    ],
)
def test_a_value_that_is_not_a_finite_number_is_refused_naming_the_key_and_value(
    value: object, detail: str
) -> None:
    error = refusal(require_finite, "timing.rate_hz", value)
    assert (error.key, error.detail, str(error)) == (
        "timing.rate_hz",
        detail,
        f"timing.rate_hz: {detail}",
    )
    # not chained to the TypeError of a value that is not a number
    assert error.__suppress_context__ or error.__context__ is None


@pytest.mark.parametrize(
    ("args", "kwargs", "detail"),
    [
        ((5.0, 0.0, 1.0), {}, "5.0 is out of range; allowed [0.0, 1.0]"),
        ((-0.5, 0.0, 1.0), {}, "-0.5 is out of range; allowed [0.0, 1.0]"),
        ((-1, 0), {}, "-1 is out of range; allowed [0, inf]"),
        ((2.0, None, 1.5), {}, "2.0 is out of range; allowed [-inf, 1.5]"),
        ((0.0, 0.0, 1.0), {"low_inclusive": False}, "0.0 is out of range; allowed (0.0, 1.0]"),
        ((1.0, 0.0, 1.0), {"high_inclusive": False}, "1.0 is out of range; allowed [0.0, 1.0)"),
        (
            (0.0, 0.0),
            {"low_inclusive": False, "high_inclusive": False},
            "0.0 is out of range; allowed (0.0, inf)",
        ),
        (
            (16.0, 0.0, 15.0),
            {"bounds_from": "length_m = 15.0"},
            "16.0 is out of range; allowed [0.0, 15.0] (set by length_m = 15.0)",
        ),
        ((math.nan,), {}, "nan is out of range; allowed [-inf, inf]"),
        ((math.nan, 0.0, 1.0), {}, "nan is out of range; allowed [0.0, 1.0]"),
    ],
)
def test_a_value_out_of_range_is_refused_naming_the_key_value_and_allowed_interval(
    args: tuple, kwargs: dict, detail: str
) -> None:
    error = refusal(require_range, "deck.length_m", *args, **kwargs)
    assert (error.key, error.detail, str(error)) == (
        "deck.length_m",
        detail,
        f"deck.length_m: {detail}",
    )


bounds = st.none() | st.floats(-10.0, 10.0) | st.integers(-10, 10)


@settings(max_examples=300, deadline=None)
@given(
    value=st.floats(-12.0, 12.0) | st.integers(-12, 12) | st.just(math.nan),
    low=bounds,
    high=bounds,
    low_inclusive=st.booleans(),
    high_inclusive=st.booleans(),
)
def test_a_value_is_in_range_exactly_when_each_given_bound_holds_ends_as_told(
    value: float, low: float | None, high: float | None, low_inclusive: bool, high_inclusive: bool
) -> None:
    above = low is None or (value >= low if low_inclusive else value > low)
    below = high is None or (value <= high if high_inclusive else value < high)
    inside = not math.isnan(value) and above and below
    try:
        require_range(
            "k", value, low, high, low_inclusive=low_inclusive, high_inclusive=high_inclusive
        )
    except ConfigError:
        assert not inside
    else:
        assert inside


def test_both_ends_are_inclusive_by_default() -> None:
    require_range("k", 0.0, 0.0, 1.0)
    require_range("k", 1.0, 0.0, 1.0)
    require_range("k", 1.0, 1.0)
    require_range("k", 1.0, high=1.0)
