"""The policy classes of DeckLanding's recipes: the stopping rule's margin feature."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from hypothesis import given, settings
from hypothesis import strategies as st

import landing_env  # noqa: F401  (registers the ids)
from landing_env.anticipation.onboard_tilt_prediction import commit_by_prediction
from landing_env.privileged import ActorFeatures, DeckFeatures

SCALE = 0.005


@pytest.fixture(scope="module")
def space() -> gym.spaces.Dict:
    env = gym.make("DeckLanding-BenchSS4-v2", privileged=True)
    try:
        return env.observation_space
    finally:
        env.close()


def _margin(features: DeckFeatures, prediction: np.ndarray) -> float:
    return float(features.stopping_margin(th.as_tensor(prediction[None], dtype=th.float32))[0, 0])


@settings(max_examples=300, deadline=None)
@given(
    chances=st.lists(st.floats(0.0, 1.0, width=32), min_size=4, max_size=4),
    value=st.floats(0.0, 1.0, width=32),
    valid=st.booleans(),
)
def test_the_margin_feature_is_non_negative_exactly_where_predictive_commits(
    space: gym.spaces.Dict, chances: list[float], value: float, valid: bool
) -> None:
    features = DeckFeatures(space, stopping_rule_key="prediction", stopping_rule_scale=SCALE)
    prediction = np.array([*chances, value, float(valid)], np.float32)
    margin = _margin(features, prediction)
    assert (margin >= 0.0) == commit_by_prediction(prediction)
    assert -1.0 <= margin <= 1.0
    if valid:
        expected = np.clip((max(chances) - value) / SCALE, -1.0, 1.0)
        assert margin == pytest.approx(expected, abs=1e-3)
    else:
        assert margin == -1.0


def test_the_feature_widens_both_extractors_by_one_and_the_actor_still_drops_the_truth(
    space: gym.spaces.Dict,
) -> None:
    plain = DeckFeatures(space)
    ruled = DeckFeatures(space, stopping_rule_key="prediction")
    actor = ActorFeatures(space, stopping_rule_key="prediction")
    assert ruled.features_dim == plain.features_dim + 1
    assert "privileged" not in actor.extractors and "privileged" in ruled.extractors
    sample = {k: th.as_tensor(v[None]) for k, v in space.sample().items()}
    sample["prediction"] = th.tensor([[0.2, 0.9, 0.1, 0.3, 0.5, 1.0]])
    out = ruled(sample)
    assert out.shape == (1, ruled.features_dim)
    # the last feature is the rule's margin, saturated: 0.9 - 0.5 is far above the scale
    assert float(out[0, -1]) == 1.0
    # 0.01 below the value of waiting: twice the scale, saturated at -1
    sample["prediction"] = th.tensor([[0.2, 0.49, 0.1, 0.3, 0.5, 1.0]])
    assert float(ruled(sample)[0, -1]) == -1.0
    # within the scale: linear in the margin
    sample["prediction"] = th.tensor([[0.2, 0.4975, 0.1, 0.3, 0.5, 1.0]])
    assert float(ruled(sample)[0, -1]) == pytest.approx(-0.5, abs=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"stopping_rule_key": "chances"}, "'chances' is not an observation key"),
        ({"stopping_rule_key": "band_time"}, "shape (1,)"),
        ({"stopping_rule_key": "prediction", "stopping_rule_scale": 0.0}, "stopping_rule_scale"),
    ],
)
def test_a_bad_feature_setting_is_refused_naming_it(
    space: gym.spaces.Dict, kwargs: dict, named: str
) -> None:
    with pytest.raises(ValueError, match="features_extractor_kwargs") as error:
        DeckFeatures(space, **kwargs)
    assert named in str(error.value)
