"""The landing-target filter: a constant-velocity Kalman filter per axis with a gate."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.landing_target import (
    ACCEPTED,
    INITIALISED,
    INVALID_INPUT,
    REJECTED,
    LandingTargetConfig,
    LandingTargetFilter,
)


def _initialised(x_m: float = 1.0, y_m: float = -2.0, **config: float) -> LandingTargetFilter:
    f = LandingTargetFilter(LandingTargetConfig(**config))
    assert f.update(np.array([x_m, y_m]), 3.0) == INITIALISED
    return f


def test_config_defaults_are_px4s_and_the_papers_gate() -> None:
    c = LandingTargetConfig()
    assert c.gate_sd == 10.0
    assert c.accel_sigma == pytest.approx(math.sqrt(10.0))
    assert c.measurement_sigma_m == 0.02
    assert c.measurement_sigma_per_m == pytest.approx(math.sqrt(0.005))
    assert c.initial_position_sigma_m == pytest.approx(math.sqrt(0.1))
    assert c.initial_velocity_sigma == pytest.approx(math.sqrt(0.1))
    assert c.timeout_s == 2.0


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("gate_sd", 0.0),
        ("accel_sigma", 0.0),
        ("measurement_sigma_m", 0.0),
        ("measurement_sigma_per_m", -0.1),
        ("initial_position_sigma_m", 0.0),
        ("initial_velocity_sigma", 0.0),
        ("timeout_s", 0.0),
    ],
)
def test_config_rejects_values_outside_the_limits_naming_the_field(
    field: str, value: float
) -> None:
    with pytest.raises(ValueError, match=field):
        LandingTargetConfig(**{field: value})


def test_a_new_filter_is_invalid_and_empty() -> None:
    f = LandingTargetFilter()
    assert not f.valid and not f.initialised
    assert f.rejections == 0 and math.isnan(f.last_innovation_sd)
    assert f.since_fix_s == math.inf
    np.testing.assert_array_equal(f.position_xy, [0.0, 0.0])
    np.testing.assert_array_equal(f.velocity_xy, [0.0, 0.0])


def test_first_fix_initialises_at_the_fix_with_zero_velocity_and_initial_covariance() -> None:
    f = _initialised(1.0, -2.0)
    assert f.valid and f.initialised and f.since_fix_s == 0.0 and f.last_innovation_sd == 0.0
    np.testing.assert_array_equal(f.position_xy, [1.0, -2.0])
    np.testing.assert_array_equal(f.velocity_xy, [0.0, 0.0])
    for axis in range(2):
        np.testing.assert_allclose(f.covariance[axis], np.diag([0.1, 0.1]))


def test_position_and_velocity_are_copies() -> None:
    f = _initialised(1.0, -2.0)
    f.position_xy[0] = 99.0
    f.velocity_xy[0] = 99.0
    np.testing.assert_array_equal(f.state, [[1.0, 0.0], [-2.0, 0.0]])


def test_predict_moves_the_target_against_the_vehicle_acceleration() -> None:
    f = _initialised(1.0, -2.0)
    f.state[:, 1] = [0.5, -0.25]
    assert f.predict(np.array([2.0, -4.0]), 0.5)
    # p' = p + v dt - a dt^2 / 2, v' = v - a dt
    np.testing.assert_allclose(f.position_xy, [1.0 + 0.25 - 0.25, -2.0 - 0.125 + 0.5])
    np.testing.assert_allclose(f.velocity_xy, [0.5 - 1.0, -0.25 + 2.0])
    assert f.since_fix_s == 0.5


def test_predict_grows_the_covariance_by_the_transition_and_acceleration_noise() -> None:
    f = _initialised(accel_sigma=3.0)
    p0 = f.covariance[0].copy()
    dt = 0.2
    f.predict(np.zeros(2), dt)
    tr = np.array([[1.0, dt], [0.0, 1.0]])
    b = np.array([-0.5 * dt * dt, -dt])
    expected = tr @ p0 @ tr.T + 9.0 * np.outer(b, b)
    for axis in range(2):
        np.testing.assert_allclose(f.covariance[axis], expected, rtol=1e-12)


def test_predict_with_a_non_finite_acceleration_coasts_and_says_so() -> None:
    f = _initialised(1.0, -2.0)
    f.state[:, 1] = [1.0, 2.0]
    assert not f.predict(np.array([np.nan, 1.0]), 0.5)
    np.testing.assert_allclose(f.position_xy, [1.5, -1.0])
    np.testing.assert_allclose(f.velocity_xy, [1.0, 2.0])


@pytest.mark.parametrize("dt", [-0.1, math.nan, math.inf])
def test_predict_ignores_a_negative_or_non_finite_step(dt: float) -> None:
    f = _initialised(1.0, -2.0)
    before = f.state.copy(), f.covariance.copy()
    assert not f.predict(np.array([1.0, 1.0]), dt)
    np.testing.assert_array_equal(f.state, before[0])
    np.testing.assert_array_equal(f.covariance, before[1])
    assert f.since_fix_s == 0.0


def test_predict_before_the_first_fix_only_counts_time() -> None:
    f = LandingTargetFilter()
    f.since_fix_s = 0.0
    assert f.predict(np.array([1.0, 1.0]), 0.5)
    assert f.since_fix_s == 0.5 and not f.initialised
    np.testing.assert_array_equal(f.state, np.zeros((2, 2)))


def test_estimate_stays_valid_up_to_the_timeout_then_the_next_fix_reinitialises() -> None:
    f = _initialised(1.0, -2.0, timeout_s=1.0)
    f.predict(np.zeros(2), 0.5)
    f.predict(np.zeros(2), 0.5)
    assert f.valid and f.initialised  # exactly at the timeout
    f.predict(np.zeros(2), 0.01)
    assert not f.valid and not f.initialised
    # far from the old estimate, yet not gated: the filter starts again
    assert f.update(np.array([50.0, 50.0]), 3.0) == INITIALISED
    np.testing.assert_array_equal(f.position_xy, [50.0, 50.0])
    assert f.valid


def test_measurement_sigma_grows_with_distance_and_is_floored_at_zero_distance() -> None:
    f = LandingTargetFilter(
        LandingTargetConfig(measurement_sigma_m=0.1, measurement_sigma_per_m=0.05)
    )
    assert f.measurement_sigma_m(4.0) == pytest.approx(0.3)
    assert f.measurement_sigma_m(0.0) == pytest.approx(0.1)
    assert f.measurement_sigma_m(-5.0) == pytest.approx(0.1)


def test_innovation_sd_is_each_axis_offset_over_its_innovation_sd() -> None:
    f = _initialised(1.0, -2.0, measurement_sigma_m=0.3, measurement_sigma_per_m=0.0)
    # S = 0.1 + 0.09 = 0.19 on both axes
    np.testing.assert_allclose(
        f.innovation_sd(np.array([1.5, -3.0]), 7.0), [0.5 / math.sqrt(0.19), 1.0 / math.sqrt(0.19)]
    )


def test_update_fuses_a_fix_with_the_kalman_gain() -> None:
    f = _initialised(1.0, -2.0, measurement_sigma_m=0.3, measurement_sigma_per_m=0.0)
    f.predict(np.zeros(2), 0.1)
    p = f.covariance[0].copy()
    f.since_fix_s = 0.7
    assert f.update(np.array([1.2, -2.0]), 2.0) == ACCEPTED
    s = p[0, 0] + 0.09
    gain = p[:, 0] / s
    np.testing.assert_allclose(f.state[0], [1.0 + gain[0] * 0.2, gain[1] * 0.2], rtol=1e-12)
    np.testing.assert_allclose(f.state[1], [-2.0, 0.0], atol=1e-15)
    joseph = np.eye(2) - np.outer(gain, [1.0, 0.0])
    expected = joseph @ p @ joseph.T + 0.09 * np.outer(gain, gain)
    np.testing.assert_allclose(f.covariance[0], expected, rtol=1e-12)
    np.testing.assert_allclose(f.covariance[1], expected, rtol=1e-12)
    assert f.since_fix_s == 0.0
    assert f.last_innovation_sd == pytest.approx(0.2 / math.sqrt(s))


def test_update_gates_out_a_fix_beyond_gate_sd_on_either_axis() -> None:
    f = _initialised(0.0, 0.0, gate_sd=3.0, measurement_sigma_m=0.3, measurement_sigma_per_m=0.0)
    sd = math.sqrt(0.19)
    f.since_fix_s = 0.4
    assert f.update(np.array([0.0, 3.01 * sd]), 1.0) == REJECTED
    assert f.rejections == 1 and f.last_innovation_sd == pytest.approx(3.01)
    np.testing.assert_array_equal(f.position_xy, [0.0, 0.0])
    assert f.since_fix_s == 0.4
    assert f.update(np.array([-3.01 * sd, 0.0]), 1.0) == REJECTED
    assert f.rejections == 2
    # just inside the gate: fused
    assert f.update(np.array([2.99 * sd, 0.0]), 1.0) == ACCEPTED
    assert f.rejections == 2 and f.position_xy[0] > 0.0


@pytest.mark.parametrize(
    ("position", "distance_m"),
    [([1.0, np.nan], 1.0), ([1.0, 2.0], math.inf), ([1.0, 2.0, 3.0], 1.0), ([1.0], 1.0)],
)
def test_update_ignores_a_non_finite_or_ill_shaped_fix(position: list, distance_m: float) -> None:
    f = LandingTargetFilter()
    assert f.update(np.array(position), distance_m) == INVALID_INPUT
    assert not f.initialised
    g = _initialised(1.0, -2.0)
    assert g.update(np.array(position), distance_m) == INVALID_INPUT
    np.testing.assert_array_equal(g.position_xy, [1.0, -2.0])


def test_reset_forgets_everything() -> None:
    f = _initialised(0.0, 0.0, gate_sd=1.0)
    f.update(np.array([100.0, 0.0]), 1.0)
    f.reset()
    assert not f.valid and not f.initialised and f.rejections == 0
    assert math.isnan(f.last_innovation_sd) and f.since_fix_s == math.inf
    np.testing.assert_array_equal(f.state, np.zeros((2, 2)))
    np.testing.assert_array_equal(f.covariance, np.zeros((2, 2, 2)))


@settings(max_examples=30, deadline=None)
@given(
    x=st.floats(-5.0, 5.0),
    v=st.floats(-2.0, 2.0),
    a=st.floats(-3.0, 3.0),
)
def test_filter_tracks_a_target_moving_with_constant_relative_acceleration(
    x: float, v: float, a: float
) -> None:
    """Fed exact fixes of a relative motion driven by the vehicle's acceleration, it converges."""
    f = LandingTargetFilter(
        LandingTargetConfig(measurement_sigma_m=0.01, measurement_sigma_per_m=0.0)
    )
    dt = 0.05
    t = 0.0
    f.update(np.array([x, -x]), 1.0)
    for _ in range(200):
        f.predict(np.array([a, -a]), dt)
        t += dt
        pos = x + v * t - 0.5 * a * t * t
        assert f.update(np.array([pos, -pos]), 1.0) == ACCEPTED
    np.testing.assert_allclose(f.position_xy, [pos, -pos], atol=1e-3)
    np.testing.assert_allclose(f.velocity_xy, [v - a * t, -(v - a * t)], atol=2e-2)


def test_validity_and_initialisation_are_booleans_before_and_after_the_timeout() -> None:
    f = LandingTargetFilter(LandingTargetConfig(timeout_s=0.5))
    assert f.valid is False and f.initialised is False
    f.update(np.array([1.0, 2.0]), 1.0)
    assert f.valid is True
    f.predict(np.zeros(2), 1.0)
    assert f.valid is False and f.initialised is False


def test_predict_by_zero_seconds_is_a_usable_step_that_changes_nothing() -> None:
    f = _initialised(1.0, -2.0)
    before = f.state.copy(), f.covariance.copy()
    assert f.predict(np.array([1.0, 1.0]), 0.0)
    np.testing.assert_array_equal(f.state, before[0])
    np.testing.assert_array_equal(f.covariance, before[1])


def test_a_missing_time_step_or_distance_is_ignored_without_raising() -> None:
    f = _initialised(1.0, -2.0)
    assert not f.predict(np.zeros(2), None)
    assert f.update(np.array([1.0, -2.0]), None) == INVALID_INPUT
    assert LandingTargetFilter().update(np.array([1.0, -2.0]), None) == INVALID_INPUT


def test_row_or_column_shaped_inputs_are_taken_as_x_y() -> None:
    f = LandingTargetFilter()
    assert f.update(np.array([[1.0], [-2.0]]), 3.0) == INITIALISED
    np.testing.assert_array_equal(f.position_xy, [1.0, -2.0])
    f.predict(np.array([[2.0, -4.0]]), 0.5)
    np.testing.assert_allclose(f.position_xy, [0.75, -1.5])
    np.testing.assert_allclose(f.velocity_xy, [-1.0, 2.0])
    ratio = f.innovation_sd(np.array([[0.75], [-1.5]]), 3.0)
    assert ratio.shape == (2,)
    np.testing.assert_array_equal(ratio, [0.0, 0.0])
    g = LandingTargetFilter()
    assert g.update(np.array([[1.0, -2.0]]), 3.0) == INITIALISED
    np.testing.assert_array_equal(g.position_xy, [1.0, -2.0])


def test_a_fix_exactly_at_the_gate_is_accepted() -> None:
    # S = 0.75^2 + 1^2 = 1.25^2: an offset of 2.5 m is exactly 2 standard deviations
    f = _initialised(
        0.0,
        0.0,
        gate_sd=2.0,
        initial_position_sigma_m=0.75,
        measurement_sigma_m=1.0,
        measurement_sigma_per_m=0.0,
    )
    assert f.update(np.array([2.5, 0.0]), 1.0) == ACCEPTED
    assert f.last_innovation_sd == 2.0 and f.rejections == 0
