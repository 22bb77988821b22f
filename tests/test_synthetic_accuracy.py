"""Issue 12's synthetic case: 0.5 px corners, ToF sigma = max(5 mm, 0.5 % of range)."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.noise import TofNoiseModel
from estimation.synthetic_accuracy import ISSUE_TOF_NOISE, synthetic_accuracy

HEIGHTS = (0.5, 1.0, 2.0, 3.0)


@pytest.fixture(scope="module")
def accuracy():
    return synthetic_accuracy(HEIGHTS, poses=300, seed=12)


def test_the_issue_tof_model_is_five_millimetres_or_half_a_percent() -> None:
    np.testing.assert_allclose(
        ISSUE_TOF_NOISE.sigma([0.5, 1.0, 2.0, 3.0]), [5e-3, 5e-3, 1e-2, 1.5e-2]
    )
    assert TofNoiseModel().sigma_min_m == 0.0  # the VL53L1X model has no floor
    with pytest.raises(ValueError, match="sigma_min_m"):
        TofNoiseModel(sigma_min_m=-1.0)


@pytest.mark.parametrize("height", HEIGHTS)
def test_tight_beats_atda_ihrcf_and_crhf_on_every_axis(accuracy, height: float) -> None:
    errors = accuracy.errors[height]
    assert all(np.isfinite(e).all() for e in errors.values()), "an estimate was invalid"
    mae = accuracy.mae(height)
    best = np.minimum.reduce([mae["atda"], mae["ihrcf"], mae["crhf"]])
    assert np.all(mae["tight"] <= 1.05 * best), (mae["tight"], best)
    assert np.all(mae["tight"][3:5] < best[3:5]), (mae["tight"], best)
