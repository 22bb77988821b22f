"""The stopping rule read off the prediction observation: what ``align-predictive`` commits on."""

from __future__ import annotations

import numpy as np
import pytest

from landing_env.anticipation.onboard_tilt_prediction import commit_by_prediction


@pytest.mark.parametrize(
    ("values", "commit"),
    [
        # chances at three contact times, the value of waiting on, the validity
        ([0.2, 0.8, 0.5, 0.7, 1.0], True),  # the best chance (0.8) beats waiting (0.7)
        ([0.2, 0.6, 0.5, 0.7, 1.0], False),  # every chance below the value of waiting
        ([0.7, 0.1, 0.1, 0.7, 1.0], True),  # equal: waiting is worth no more
        ([0.9, 0.9, 0.9, 0.7, 0.0], False),  # an invalid prediction never commits
        ([0.0, 0.0, 0.0, 0.0, 1.0], True),  # nothing left to wait for (the forced end)
    ],
)
def test_a_commit_needs_a_valid_best_chance_at_least_the_value_of_waiting(
    values: list[float], commit: bool
) -> None:
    assert commit_by_prediction(np.array(values, dtype=np.float32)) is commit


def test_the_best_contact_time_decides_not_the_first() -> None:
    values = np.array([0.1, 0.1, 0.95, 0.9, 1.0])
    assert commit_by_prediction(values)
    assert not commit_by_prediction(np.array([0.95, 0.1, 0.1, 0.96, 1.0]))
