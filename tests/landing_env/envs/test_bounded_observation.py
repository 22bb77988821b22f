"""The observation's one-pass bounding against the per-key reference it replaces."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from landing_env.envs.base import BoundedObservation

SPACE = spaces.Dict(
    {
        "pose": spaces.Box(np.float32(-2.5), np.float32(2.5), shape=(6,), dtype=np.float32),
        "flag": spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32),
        "open": spaces.Box(-np.inf, np.inf, shape=(2, 2), dtype=np.float32),
        "ranges": spaces.Box(0.0, 4.0, shape=(4,), dtype=np.float32),
    }
)

#: any float64 value: NaN, infinities, subnormals, beyond float32's range
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=64)


def reference(values: dict, space: spaces.Dict) -> dict[str, np.ndarray]:
    """Each key on its own: NaN as 0 (infinities as the largest floats), clipped, float32."""
    return {
        key: np.clip(
            np.nan_to_num(np.asarray(values[key], dtype=np.float64), nan=0.0), box.low, box.high
        ).astype(np.float32)
        for key, box in space.spaces.items()
    }


@st.composite
def observation_values(draw) -> dict:
    return {
        key: draw(hnp.arrays(np.float64, box.shape, elements=ANY_FLOAT))
        for key, box in SPACE.spaces.items()
    }


@pytest.mark.filterwarnings("ignore:overflow encountered in cast")
@settings(max_examples=200, deadline=None)
@given(observation_values())
def test_bounding_all_keys_at_once_matches_each_key_bounded_alone_bit_for_bit(values) -> None:
    bounded = BoundedObservation().observation(values, SPACE)
    expected = reference(values, SPACE)
    assert list(bounded) == list(expected)
    for key, array in expected.items():
        assert bounded[key].dtype == np.float32 and bounded[key].shape == array.shape
        assert bounded[key].tobytes() == array.tobytes(), key
        assert SPACE[key].contains(bounded[key])


def test_a_value_of_another_size_is_bounded_as_its_key_alone() -> None:
    values = {"pose": [0.5] * 6, "flag": 3.0, "open": np.full((2, 2), np.nan), "ranges": [9.0]}
    bounded = BoundedObservation().observation(values, SPACE)
    np.testing.assert_array_equal(bounded["flag"], [1.0])
    np.testing.assert_array_equal(bounded["ranges"], [4.0] * 4)  # broadcast as np.clip does
    np.testing.assert_array_equal(bounded["open"], np.zeros((2, 2)))
    assert bounded["pose"].tobytes() == reference(values, SPACE)["pose"].tobytes()
