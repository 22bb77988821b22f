"""The estimate every estimator returns (estimation.types.DeckPoseEstimate)."""

from __future__ import annotations

import numpy as np

from estimation.frames import matrix_from_euler_zyx
from estimation.types import DeckPoseEstimate


def test_an_invalid_estimate_says_who_when_and_why_and_holds_no_pose() -> None:
    estimate = DeckPoseEstimate.invalid("tight", 1.05, "out_of_view")
    assert estimate.method == "tight"
    assert estimate.timestamp == 1.05
    assert estimate.valid is False
    assert estimate.reason == "out_of_view"
    assert estimate.rotation.shape == (3, 3) and np.all(np.isnan(estimate.rotation))
    assert estimate.translation.shape == (3,) and np.all(np.isnan(estimate.translation))
    assert estimate.covariance is None and estimate.predicted is False and estimate.extras == {}
    vector = estimate.as_vector()
    assert vector.shape == (6,) and np.all(np.isnan(vector))


def test_a_valid_estimate_is_the_translation_then_roll_pitch_and_yaw() -> None:
    estimate = DeckPoseEstimate(
        method="ihrcf",
        timestamp=2.0,
        valid=True,
        rotation=matrix_from_euler_zyx(0.1, -0.2, 0.3),
        translation=np.array([0.4, -0.5, 2.0]),
    )
    np.testing.assert_allclose(estimate.as_vector(), [0.4, -0.5, 2.0, 0.1, -0.2, 0.3], atol=1e-12)
