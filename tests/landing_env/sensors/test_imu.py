"""IMU: specific force convention, white-noise discretisation and bias random walk."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from estimation.frames import matrix_from_euler_zyx
from estimation.types import ImuSample
from landing_env.errors import ConfigError
from landing_env.sensors.imu import ImuConfig, ImuModel, mean_reading

QUIET = {"accel_bias_sigma": 0.0, "gyro_bias_sigma": 0.0}
NO_DRIFT = {"accel_bias_random_walk": 0.0, "gyro_bias_random_walk": 0.0}


def run(model: ImuModel, n: int, r_wb=None, accel_w=None, omega_b=None):
    r_wb = np.eye(3) if r_wb is None else r_wb
    accel_w = np.zeros(3) if accel_w is None else accel_w
    omega_b = np.zeros(3) if omega_b is None else omega_b
    samples = [model.sample(i / model.rate_hz, r_wb, accel_w, omega_b) for i in range(n)]
    return np.array([s.accel for s in samples]), np.array([s.gyro for s in samples])


def test_at_rest_reads_plus_g_on_body_z() -> None:
    model = ImuModel(ImuConfig(**QUIET, **NO_DRIFT), np.random.default_rng(0), rate_hz=200.0)
    accel, gyro = run(model, 2000)
    np.testing.assert_allclose(accel.mean(axis=0), [0.0, 0.0, 9.81], atol=3e-3)
    np.testing.assert_allclose(gyro.mean(axis=0), 0.0, atol=2e-4)


def test_noise_free_kinematics() -> None:
    zero = ImuConfig(accel_noise_density=0.0, gyro_noise_density=0.0, **QUIET, **NO_DRIFT)
    model = ImuModel(zero, np.random.default_rng(0), rate_hz=100.0)
    r_wb = matrix_from_euler_zyx(0.3, -0.2, 1.0)
    # tilted at rest: gravity's reaction seen in the body frame
    sample = model.sample(0.0, r_wb, np.zeros(3), np.array([0.1, -0.2, 0.3]))
    np.testing.assert_allclose(sample.accel, r_wb.T @ [0.0, 0.0, 9.81], atol=1e-12)
    np.testing.assert_allclose(sample.gyro, [0.1, -0.2, 0.3], atol=1e-12)
    # free fall reads zero specific force
    sample = model.sample(0.01, r_wb, np.array([0.0, 0.0, -9.81]), np.zeros(3))
    np.testing.assert_allclose(sample.accel, 0.0, atol=1e-12)
    # climbing at 2 m/s^2, level: 11.81 on body z
    sample = model.sample(0.02, np.eye(3), np.array([0.0, 0.0, 2.0]), np.zeros(3))
    np.testing.assert_allclose(sample.accel, [0.0, 0.0, 11.81], atol=1e-12)


@pytest.mark.parametrize("rate_hz", [100.0, 400.0])
def test_white_noise_std_is_density_times_sqrt_rate(rate_hz: float) -> None:
    config = ImuConfig(**QUIET, **NO_DRIFT)
    model = ImuModel(config, np.random.default_rng(1), rate_hz=rate_hz)
    accel, gyro = run(model, 6000)
    expected_a = config.accel_noise_density * np.sqrt(rate_hz)
    expected_g = config.gyro_noise_density * np.sqrt(rate_hz)
    np.testing.assert_allclose(accel.std(axis=0), expected_a, rtol=0.05)
    np.testing.assert_allclose(gyro.std(axis=0), expected_g, rtol=0.05)


def test_bias_random_walk_grows_like_sqrt_t() -> None:
    config = ImuConfig(accel_noise_density=0.0, gyro_noise_density=0.0, **QUIET)
    rng = np.random.default_rng(2)
    rate, runs = 50.0, 300
    times = (1.0, 4.0)
    biases = {t: [] for t in times}
    for _ in range(runs):
        model = ImuModel(config, rng, rate_hz=rate)
        for i in range(int(times[-1] * rate) + 1):
            sample = model.sample(i / rate, np.eye(3), np.zeros(3), np.zeros(3))
            if i / rate in biases:
                biases[i / rate].append(np.concatenate([sample.accel, sample.gyro]))
    for t in times:
        values = np.array(biases[t])
        values[:, 2] -= 9.81
        std_a = values[:, :3].std()
        std_g = values[:, 3:].std()
        # 900 values per estimate: ~5 % standard error on a standard deviation
        assert std_a == pytest.approx(config.accel_bias_random_walk * np.sqrt(t), rel=0.12)
        assert std_g == pytest.approx(config.gyro_bias_random_walk * np.sqrt(t), rel=0.12)


def test_reset_draws_initial_bias_and_is_seeded() -> None:
    config = ImuConfig(accel_bias_sigma=0.05, gyro_bias_sigma=0.002)
    rng = np.random.default_rng(3)
    model = ImuModel(config, rng, rate_hz=100.0)
    draws = []
    for _ in range(2000):
        model.reset()
        draws.append(np.concatenate([model.accel_bias, model.gyro_bias]))
    draws = np.array(draws)
    assert draws[:, :3].std() == pytest.approx(0.05, rel=0.05)
    assert draws[:, 3:].std() == pytest.approx(0.002, rel=0.05)
    first = ImuModel(config, np.random.default_rng(9), 100.0)
    second = ImuModel(config, np.random.default_rng(9), 100.0)
    np.testing.assert_array_equal(run(first, 20)[0], run(second, 20)[0])


def test_timestamps_must_not_go_backwards() -> None:
    model = ImuModel(ImuConfig(), np.random.default_rng(0), rate_hz=100.0)
    model.sample(1.0, np.eye(3), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="backwards"):
        model.sample(0.5, np.eye(3), np.zeros(3), np.zeros(3))


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError) as info:
        ImuConfig(gyro_noise_density=-1.0)
    assert info.value.key == "gyro_noise_density"


def test_sample_many_equals_consecutive_samples() -> None:
    """One batch draws the same random stream as sample() by sample(), value for value."""
    config = ImuConfig()
    one = ImuModel(config, np.random.default_rng(5), rate_hz=240.0)
    batch = ImuModel(config, np.random.default_rng(5), rate_hz=240.0)
    motion = np.random.default_rng(6)
    for block in range(3):
        times = [(12 * block + k + 1) / 240.0 for k in range(12)]
        rotations = [matrix_from_euler_zyx(*motion.normal(0.0, 0.3, 3)) for _ in times]
        accels = [motion.normal(0.0, 2.0, 3) for _ in times]
        omegas = [motion.normal(0.0, 1.0, 3) for _ in times]
        singles = [one.sample(*args) for args in zip(times, rotations, accels, omegas, strict=True)]
        # the batch takes plain floats too: R_WB row-major, vectors as tuples
        many = batch.sample_many(
            times,
            [r.ravel().tolist() for r in rotations],
            [tuple(a) for a in accels],
            [tuple(w) for w in omegas],
        )
        for a, b in zip(singles, many, strict=True):
            assert a.timestamp == b.timestamp
            np.testing.assert_array_equal(a.accel, b.accel)
            np.testing.assert_array_equal(a.gyro, b.gyro)
    np.testing.assert_array_equal(one.accel_bias, batch.accel_bias)
    np.testing.assert_array_equal(one.gyro_bias, batch.gyro_bias)
    assert batch.sample_many([], [], [], []) == []


def test_backwards_timestamp_in_a_batch_leaves_the_model_unchanged() -> None:
    model = ImuModel(ImuConfig(), np.random.default_rng(0), rate_hz=100.0)
    model.sample(1.0, np.eye(3), np.zeros(3), np.zeros(3))
    bias = model.accel_bias
    state = model.rng.bit_generator.state
    with pytest.raises(ValueError, match="backwards"):
        model.sample_many([1.01, 0.5], [np.eye(3)] * 2, [np.zeros(3)] * 2, [np.zeros(3)] * 2)
    np.testing.assert_array_equal(model.accel_bias, bias)
    assert model.rng.bit_generator.state == state


READINGS = hnp.arrays(
    st.sampled_from([np.float64, np.float64, np.float32]),
    3,
    elements=st.floats(-1e6, 1e6, width=32) | st.sampled_from([0.0, -0.0, 1e-300, -5e-324]),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(READINGS, READINGS), min_size=1, max_size=14))
def test_the_mean_reading_is_numpy_s_mean_of_the_stacked_samples_bit_for_bit(pairs) -> None:
    samples = [ImuSample(0.01 * i, accel, gyro) for i, (accel, gyro) in enumerate(pairs)]
    expected = np.zeros(6, dtype=np.float32)
    expected[:3] = np.mean([s.accel for s in samples], axis=0)
    expected[3:] = np.mean([s.gyro for s in samples], axis=0)
    mean = np.array(mean_reading(samples), dtype=np.float32)
    assert mean.tobytes() == expected.tobytes()
    float64 = [s for s in samples if s.accel.dtype == s.gyro.dtype == np.float64]
    if float64:
        accel = np.mean([s.accel for s in float64], axis=0)
        exact = np.concatenate([accel, np.mean([s.gyro for s in float64], axis=0)])
        assert np.array(mean_reading(float64)).tobytes() == exact.tobytes()


def test_the_mean_reading_of_the_world_s_samples_is_their_mean() -> None:
    model = ImuModel(ImuConfig(), np.random.default_rng(3), rate_hz=240.0)
    rotation = matrix_from_euler_zyx(0.1, -0.2, 0.3)
    samples = model.sample_many(
        [i / 240.0 for i in range(12)], [rotation] * 12, [np.ones(3)] * 12, [np.full(3, 0.5)] * 12
    )
    mean = mean_reading(samples)
    assert mean[:3] == tuple(np.mean([s.accel for s in samples], axis=0).tolist())
    assert mean[3:] == tuple(np.mean([s.gyro for s in samples], axis=0).tolist())
