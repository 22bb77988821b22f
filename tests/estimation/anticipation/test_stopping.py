"""The optimal-stopping value of waiting for a better chance (estimation.anticipation.stopping)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.anticipation.stopping import StoppingValues, value_before_forced

#: a uniform distribution on [0, 1], as evenly spaced quantiles
UNIFORM = (np.arange(20000) + 0.5) / 20000


def test_with_no_opportunity_left_the_value_is_the_mean_chance_of_a_forced_commit():
    values = StoppingValues.from_samples(np.array([0.2, 0.4, 0.9]))
    assert values.value(0) == pytest.approx(0.5)


def test_uniform_chances_give_moser_s_recursion():
    # the house-selling problem with uniform offers: V_m = (1 + V_{m-1}^2) / 2 (Moser 1956)
    values = StoppingValues.from_samples(UNIFORM)
    expected = 0.5
    for m in range(1, 30):
        expected = (1.0 + expected**2) / 2.0
        assert values.value(m) == pytest.approx(expected, abs=1e-4)


def test_the_value_rises_with_the_wait_left_towards_the_best_chance():
    rng = np.random.default_rng(3)
    samples = rng.beta(2.0, 3.0, 5000)
    values = StoppingValues.from_samples(samples)
    assert np.all(np.diff(values.values) >= 0.0)
    assert values.values[-1] <= samples.max() + 1e-12
    assert values.threshold(30.0, 1.0) > values.threshold(3.0, 1.0) > values.threshold(0.5, 1.0)
    # one opportunity per 2 s: 10 s left are worth what 5 opportunities are
    assert values.threshold(10.0, 2.0) == pytest.approx(values.value(5))


def test_nothing_left_or_nothing_known_takes_any_chance():
    values = StoppingValues.from_samples(UNIFORM)
    assert values.threshold(0.0, 1.0) == 0.0 and values.threshold(-3.0, 1.0) == 0.0
    assert values.threshold(math.nan, 1.0) == 0.0 and values.value(math.inf) == 0.0
    assert StoppingValues.from_samples(np.array([])).threshold(10.0, 1.0) == 0.0
    nan_only = StoppingValues.from_samples(np.array([math.nan, math.inf]))
    assert nan_only.threshold(10.0, 1.0) == 0.0


def _play(rule, draws: np.ndarray) -> float:
    """The mean chance taken by ``rule(x, left)`` over rows of independent draws (the last
    draw of a row is taken if none was before it)."""
    taken = []
    for row in draws:
        for index, x in enumerate(row):
            left = len(row) - 1 - index
            if left == 0 or rule(x, left):
                taken.append(x)
                break
    return float(np.mean(taken))


def test_the_value_rule_takes_better_chances_than_any_fixed_threshold():
    rng = np.random.default_rng(11)
    samples = rng.beta(2.0, 3.0, 20000)
    values = StoppingValues.from_samples(samples)
    draws = rng.beta(2.0, 3.0, (4000, 8))
    best = _play(lambda x, left: x >= values.value(left), draws)
    for fixed in (0.3, 0.5, 0.6, 0.7, 0.8):
        assert best > _play(lambda x, left, f=fixed: x >= f, draws)
    # and it earns what the value promised
    assert best == pytest.approx(values.value(7), abs=0.01)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=50),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(allow_nan=True, allow_infinity=True),
)
def test_the_values_never_raise_on_any_input(samples, remaining, opportunity):
    values = StoppingValues.from_samples(np.array(samples, dtype=float))
    assert isinstance(values.threshold(remaining, opportunity), float)


# ------------------------------------------------------------- a forced commit foreseen
def test_a_forced_commit_foreseen_at_the_long_run_mean_is_the_value_as_before():
    rng = np.random.default_rng(5)
    samples = rng.beta(3.0, 2.0, 4000)
    values = StoppingValues.from_samples(samples)
    for remaining_s in (0.3, 1.0, 2.0, 3.3, 7.0):
        assert value_before_forced(
            samples, float(np.mean(samples)), remaining_s, 2.0
        ) == pytest.approx(values.threshold(remaining_s, 2.0), rel=1e-12)


def test_a_forced_commit_foreseen_bad_lowers_the_bar_and_one_foreseen_good_raises_it():
    samples = UNIFORM
    # no whole opportunity left: the bar runs from the forced commit's own chance (nothing
    # left before it) to E[max(X, forced)] (one chance drawn before it)
    assert value_before_forced(samples, 0.1, 1e-9, 2.0) == pytest.approx(0.1, abs=1e-6)
    one = (1.0 + 0.1**2) / 2.0  # E[max(U, 0.1)]
    assert value_before_forced(samples, 0.1, 2.0, 2.0) == pytest.approx(one, abs=1e-4)
    assert value_before_forced(samples, 0.1, 1.0, 2.0) == pytest.approx((0.1 + one) / 2, abs=1e-4)
    long_run = StoppingValues.from_samples(samples).threshold(1.0, 2.0)
    assert value_before_forced(samples, 0.1, 1.0, 2.0) < long_run
    assert value_before_forced(samples, 0.95, 1.0, 2.0) > long_run
    # the foreseen chance matters less the more opportunities come before it
    near = value_before_forced(samples, 0.9, 2.0, 2.0) - value_before_forced(samples, 0.1, 2.0, 2.0)
    far = value_before_forced(samples, 0.9, 8.0, 2.0) - value_before_forced(samples, 0.1, 8.0, 2.0)
    assert 0.0 < far < near


def test_a_forced_commit_foreseen_with_nothing_left_or_known_is_handled():
    assert value_before_forced(UNIFORM, 0.3, 0.0, 2.0) == 0.0
    assert value_before_forced(UNIFORM, 0.3, math.nan, 2.0) == 0.0
    assert value_before_forced(UNIFORM, 0.3, 1.0, 0.0) == 0.0
    # a forced chance not known: the long-run mean's
    assert value_before_forced(UNIFORM, math.nan, 1e-9, 2.0) == pytest.approx(0.5, abs=1e-6)
    # no samples: the forced chance alone
    assert value_before_forced(np.array([]), 0.4, 5.0, 2.0) == pytest.approx(0.4)


def test_the_values_stop_at_their_cap_of_opportunities_and_interpolate_between_whole_ones():
    samples = np.array([0.1, 0.5, 0.7])
    expected = [np.mean(samples)]
    for _ in range(3):
        expected.append(np.mean(np.maximum(samples, expected[-1])))
    values = StoppingValues.from_samples(samples, max_opportunities=3)
    assert values.values == pytest.approx(expected, rel=1e-12) and len(values.values) == 4
    # beyond the cap, the cap's value; between the last two, the straight line between them
    assert values.value(3) == values.value(50.0) == pytest.approx(expected[3], rel=1e-12)
    assert values.value(2.25) == pytest.approx(0.75 * expected[2] + 0.25 * expected[3])
    none_left = StoppingValues.from_samples(samples, max_opportunities=0)
    assert len(none_left.values) == 1 and none_left.value(7.0) == pytest.approx(expected[0])


def test_an_opportunity_period_that_is_not_positive_gives_no_value_to_wait_for():
    values = StoppingValues.from_samples(UNIFORM)
    for period in (0.0, -1.0):
        assert values.threshold(10.0, period) == 0.0
        assert value_before_forced(UNIFORM, 0.3, 10.0, period) == 0.0


def test_a_forced_commit_foreseen_counts_one_opportunity_per_period_below_a_second_too():
    samples = np.array([0.2, 0.6, 0.8])
    expected = [0.3]
    for _ in range(3):
        expected.append(np.mean(np.maximum(samples, expected[-1])))
    # 1.5 s left at one opportunity per 0.5 s: three opportunities before the forced commit
    assert value_before_forced(samples, 0.3, 1.5, 0.5) == pytest.approx(expected[3], rel=1e-12)
    # 1.25 s: between two and three
    assert value_before_forced(samples, 0.3, 1.25, 0.5) == pytest.approx(
        0.5 * expected[2] + 0.5 * expected[3], rel=1e-12
    )


def test_with_no_chance_known_and_the_forced_commit_unknown_the_value_is_zero():
    for samples in (np.array([]), np.array([math.nan, math.inf])):
        assert value_before_forced(samples, math.nan, 5.0, 2.0) == 0.0
