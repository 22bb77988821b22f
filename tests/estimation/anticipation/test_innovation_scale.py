"""The deck-tilt prediction's error measured from its own innovations
(estimation.anticipation.innovation_scale)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from estimation.anticipation.innovation_scale import InnovationScale

DT = 0.05
#: a claimed error of 1.8 deg of roll and 1.2 deg of pitch (the bench's training seas at 1.3 s)
CLAIM = np.diag(np.radians([1.8, 1.2]) ** 2)


def _fly(scale: InnovationScale, error_sd: np.ndarray, seconds: float, seed: int = 0) -> None:
    """Predictions 1.3 s ahead every 0.1 s, each wrong by a draw of ``error_sd`` (rad), scored
    against a history of estimates as the seconds run."""
    rng = np.random.default_rng(seed)
    truth: dict[int, np.ndarray] = {}
    n = round(8.0 / DT)
    for k in range(round(seconds / 0.1)):
        now = k * 0.1
        newest = round(now / DT)
        rows = np.array([truth.get(i, np.zeros(2)) for i in range(newest - n + 1, newest + 1)])
        scale.update(now, rows, np.ones(n, dtype=bool), DT)
        target = round((now + 1.3) / DT)
        truth[target] = rng.normal(0.0, 0.02, 2)
        predicted = truth[target] + rng.normal(0.0, 1.0, 2) * error_sd
        scale.record(now, 1.3, predicted[0], predicted[1], CLAIM)


def test_with_no_innovation_yet_the_claimed_error_stands():
    scale = InnovationScale()
    scale.record(0.0, 1.3, 0.01, 0.0, CLAIM)
    assert scale.scale == 1.0 and scale.innovations == 0


def test_predictions_as_wrong_as_claimed_keep_the_claim():
    scale = InnovationScale()
    _fly(scale, np.radians([1.8, 1.2]), 30.0)
    assert scale.innovations > 50
    assert scale.scale > 0.8


def test_predictions_far_better_than_claimed_narrow_the_error_to_their_own():
    scale = InnovationScale()
    _fly(scale, np.radians([0.45, 0.3]), 30.0)  # a quarter of the claimed deviation
    # (prior + n/16) / (prior + n) with n = 100 innovations in the 10 s memory
    assert scale.scale == pytest.approx((20 + 100 / 16) / 120, rel=0.25)
    assert scale.scale < 0.3


def test_predictions_worse_than_claimed_never_widen_the_claim_past_the_ceiling():
    scale = InnovationScale()
    _fly(scale, np.radians([5.0, 4.0]), 20.0)
    assert scale.scale == 1.0
    wider = InnovationScale(max_scale=10.0)
    _fly(wider, np.radians([5.0, 4.0]), 20.0)
    assert wider.scale > 4.0


def test_the_prior_is_worth_its_weight_in_innovations():
    scale = InnovationScale(prior_weight=4.0)
    for k in range(4):
        scale.record(0.1 * k, 1.0, 0.0, 0.0, CLAIM)
    rows = np.zeros((200, 2))
    scale.update(1.3, rows, np.ones(200, dtype=bool), DT)
    # four perfect predictions against a prior of four at 1: half the claim
    assert scale.innovations == 4 and scale.scale == pytest.approx(0.5)


def test_a_prediction_is_scored_against_the_row_of_its_own_time_once_the_history_reaches_it():
    scale = InnovationScale(prior_weight=1.0, min_scale=1e-6)
    error = math.radians(1.8)
    scale.record(0.0, 1.0, 0.0, 0.0, CLAIM)
    rows = np.zeros((200, 2))
    valid = np.ones(200, dtype=bool)
    scale.update(0.95, rows, valid, DT)
    assert scale.innovations == 0  # its time has not come
    rows[-1 - 4] = (error, 0.0)  # 1.0 s is four rows before the newest at 1.2 s
    scale.update(1.2, rows, valid, DT)
    # q = 1: (1 + 1/2) / (1 + 1)
    assert scale.innovations == 1 and scale.scale == pytest.approx(0.75)


def test_an_invalid_estimate_or_one_the_history_no_longer_holds_scores_nothing():
    scale = InnovationScale()
    scale.record(0.0, 1.0, 0.0, 0.0, CLAIM)
    valid = np.ones(200, dtype=bool)
    valid[-1 - 4] = False
    scale.update(1.2, np.zeros((200, 2)), valid, DT)
    assert scale.innovations == 0
    scale.record(1.2, 0.5, 0.0, 0.0, CLAIM)
    scale.update(30.0, np.zeros((200, 2)), np.ones(200, dtype=bool), DT)  # 10 s history
    assert scale.innovations == 0 and scale.scale == 1.0


def test_innovations_older_than_the_memory_are_forgotten_and_reset_forgets_all():
    scale = InnovationScale(memory_s=5.0)
    _fly(scale, np.radians([0.2, 0.2]), 10.0)
    assert scale.scale < 0.6
    scale.update(20.0, np.zeros((160, 2)), np.ones(160, dtype=bool), DT)
    assert scale.innovations == 0 and scale.scale == 1.0
    _fly(scale, np.radians([0.2, 0.2]), 10.0)
    scale.reset()
    assert scale.innovations == 0 and scale.scale == 1.0


@pytest.mark.parametrize(
    ("settings_", "name"),
    [
        ({"prior_weight": 0.0}, "prior_weight"),
        ({"memory_s": math.nan}, "memory_s"),
        ({"min_scale": -1.0}, "min_scale"),
        ({"max_scale": math.inf}, "max_scale"),
        ({"min_scale": 2.0, "max_scale": 1.0}, "min_scale"),
    ],
)
def test_a_bad_setting_is_refused_naming_it(settings_, name):
    with pytest.raises(ValueError, match=name):
        InnovationScale(**settings_)


_ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=60, deadline=None)
@given(
    records=st.lists(
        st.tuples(
            _ANY_FLOAT,
            _ANY_FLOAT,
            _ANY_FLOAT,
            _ANY_FLOAT,
            arrays(float, (2, 2), elements=_ANY_FLOAT),
        ),
        max_size=6,
    ),
    time_s=_ANY_FLOAT,
    dt_s=_ANY_FLOAT,
    rows=arrays(
        float, st.tuples(st.integers(0, 12), st.sampled_from([1, 2, 3])), elements=_ANY_FLOAT
    ),
    flags=arrays(bool, st.integers(0, 12)),
)
def test_any_input_leaves_the_scale_inside_its_bounds_without_raising(
    records, time_s, dt_s, rows, flags
):
    scale = InnovationScale()
    for record in records:
        scale.record(*record)
    scale.record(0.0, 1.0, 0.0, 0.0, "not a covariance")  # type: ignore[arg-type]
    scale.update(time_s, rows, flags, dt_s)
    scale.update("later", rows, flags, DT)  # type: ignore[arg-type]
    assert scale.min_scale <= scale.scale <= scale.max_scale
    assert math.isfinite(scale.scale)


def _steady(scale: InnovationScale, offset_rad: np.ndarray, seconds: float) -> None:
    """Predictions every 0.1 s that miss a level deck by ``offset_rad`` every time."""
    n = round(8.0 / DT)
    for k in range(round(seconds / 0.1)):
        now = k * 0.1
        scale.update(now, np.zeros((n, 2)), np.ones(n, dtype=bool), DT)
        scale.record(now, 1.3, -offset_rad[0], -offset_rad[1], CLAIM)


def test_a_steady_miss_is_found_as_the_predictor_s_bias_and_the_error_narrows_about_it():
    scale = InnovationScale()
    _steady(scale, np.radians([3.0, -1.0]), 4.0)
    assert np.degrees(scale.bias) == pytest.approx([3.0, -1.0])
    # exact about it: only the prior holds the claim up
    assert scale.scale == pytest.approx(20.0 / (20.0 + scale.innovations))


def test_an_error_that_averages_out_is_no_bias():
    scale = InnovationScale()
    _fly(scale, np.radians([1.8, 1.2]), 30.0)
    assert np.all(scale.bias == 0.0)
    # one innovation a claimed deviation off is no evidence of a bias either
    one = InnovationScale()
    one.record(0.0, 1.0, 0.0, 0.0, CLAIM)
    rows = np.zeros((40, 2))
    rows[-1, 0] = math.radians(1.8)
    one.update(1.0, rows, np.ones(40, dtype=bool), DT)
    assert one.innovations == 1 and np.all(one.bias == 0.0)
