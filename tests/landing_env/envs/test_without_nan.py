"""``info``'s NaN removal, IMU rows and the observation's NaN conversion against the code they
replace."""

from __future__ import annotations

import math
import pickle

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from estimation.types import ImuSample
from landing_env.envs.base import finite_or_nan_to_num, imu_sample_rows, without_nan


def reference(value):
    """The isinstance chain, as a match statement."""
    match value:
        case dict():
            return {key: reference(item) for key, item in value.items()}
        case list() | tuple():
            return type(value)(reference(item) for item in value)
        case np.ndarray() if value.dtype.kind == "f" and np.isnan(value).any():
            return np.nan_to_num(value, nan=0.0)
        case float() | np.floating() if math.isnan(value):
            return None
    return value


LEAVES = st.one_of(
    st.floats(allow_nan=True),
    st.floats(allow_nan=True).map(np.float64),
    st.floats(allow_nan=True, width=32).map(np.float32),
    st.booleans(),
    st.booleans().map(np.bool_),
    st.integers(),
    st.text(max_size=3),
    st.none(),
    hnp.arrays(np.float64, st.integers(0, 4), elements=st.floats(allow_nan=True)),
    hnp.arrays(np.int64, st.integers(0, 3)),
)
TREES = st.recursive(
    LEAVES,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3),
        st.lists(inner, max_size=3).map(tuple),
        st.dictionaries(st.text(max_size=2), inner, max_size=3),
    ),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(TREES)
def test_info_without_nan_is_the_isinstance_chain_s_result_for_any_nesting(tree) -> None:
    result, expected = without_nan(tree), reference(tree)
    assert pickle.dumps(result) == pickle.dumps(expected)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0.0, 1e4),
            hnp.arrays(
                st.sampled_from([np.float64, np.float32]),
                3,
                elements=st.floats(-1e3, 1e3, width=32),
            ),
            hnp.arrays(np.float64, 3, elements=st.floats(allow_nan=True)),
        ),
        max_size=14,
    )
)
def test_imu_rows_of_info_are_each_sample_unpacked_into_a_row(samples) -> None:
    imu = [ImuSample(t, accel, gyro) for t, accel, gyro in samples]
    expected = np.array([[s.timestamp, *s.accel, *s.gyro] for s in imu]).reshape(-1, 7)
    rows = imu_sample_rows(imu)
    assert rows.dtype == expected.dtype and rows.shape == expected.shape
    assert rows.tobytes() == expected.tobytes()


@settings(max_examples=300, deadline=None)
@given(
    hnp.arrays(
        st.sampled_from([np.float64, np.float32]),
        hnp.array_shapes(min_dims=1, max_dims=2, min_side=0, max_side=5),
        elements=st.floats(allow_nan=True, allow_infinity=True, width=32),
    )
)
def test_an_observation_s_nan_conversion_equals_nan_to_num_for_any_array(values) -> None:
    before = values.tobytes()
    result = finite_or_nan_to_num(values)
    expected = np.nan_to_num(values, nan=0.0)
    assert result.dtype == expected.dtype and result.shape == expected.shape
    assert result.tobytes() == expected.tobytes()
    assert values.tobytes() == before  # the input is never written
