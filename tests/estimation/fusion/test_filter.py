"""The drone–deck fusion EKF on synthetic data: consistency, delayed fusion, gating, resets."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from estimation.errors import ConfigError
from estimation.frames import (
    R_BC,
    R_PD,
    euler_zyx_from_matrix,
    matrix_from_euler_zyx,
    tof_positions_in_camera_frame,
)
from estimation.fusion import POSE_SOURCES, DeckFusion, FusionConfig, pose_measurement
from estimation.fusion.config import nis_gate
from estimation.fusion.model import (
    N_COLOURED,
    N_STATE,
    N_STATE_4,
    TH,
    P,
    TwoWaves,
    deck_normal,
    deck_spectrum_of,
    ekf_update,
    predict,
    rotation_zyx,
    tof_model,
    wrap_angle,
)
from estimation.types import DeckPoseEstimate, ImuSample, RangeReading

RATE = 240
DT = 1.0 / RATE
T_BC = np.array([0.0, 0.0, -0.03])
SIGMA = (0.003, 0.003, 0.008, 2.0, 2.0, 0.5)


@dataclass
class Frame:
    """One 50 ms step of synthetic data."""

    time: float
    r_wb: np.ndarray
    imu: list[ImuSample]
    truth: np.ndarray  # the 15-state truth at ``time``
    pose: DeckPoseEstimate | None


def synthetic_run(
    rng: np.random.Generator, config: FusionConfig, duration: float = 6.0, pose_every: int = 2
) -> list[Frame]:
    """Constant drone acceleration over a deck whose motion follows the filter's model.

    The drone (tilted, yawed, constant attitude) accelerates at a constant rate; the deck's
    position and Euler angles are random walks in velocity with the configured PSDs; the IMU
    has white noise and a random-walk bias; pose measurements carry the configured noise.
    """
    r_wb = matrix_from_euler_zyx(0.08, -0.05, 0.6)
    a_drone = np.array([0.3, -0.2, 0.15])
    g = np.array([0.0, 0.0, -9.81])
    p_rel = np.array([0.1, -0.2, -2.0]) + rng.normal(0.0, 0.01, 3)
    v_rel = rng.normal(0.0, config.initial_velocity_sigma, 3)
    th = np.array([0.03, -0.02, 0.4])
    w = rng.normal(0.0, config.initial_rate_sigma, 3)
    bias = rng.normal(0.0, config.initial_accel_bias_sigma, 3)
    sigma = np.array(SIGMA, dtype=float)
    sigma[3:] = np.deg2rad(sigma[3:])

    def block(q: float) -> np.ndarray:
        return q * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]])

    chol_a = np.linalg.cholesky(block(config.deck_accel_psd))
    chol_w = np.linalg.cholesky(block(config.deck_angular_accel_psd))
    frames: list[Frame] = []
    substeps = RATE // 20
    t = 0.0
    for k in range(round(duration * 20)):
        samples = []
        for _ in range(substeps):
            # deck noise (exact discretisation), drone: constant acceleration
            wa = chol_a @ rng.standard_normal((2, 3))
            ww = chol_w @ rng.standard_normal((2, 3))
            p_rel = p_rel + v_rel * DT - 0.5 * a_drone * DT**2 + wa[0]
            v_rel = v_rel - a_drone * DT + wa[1]
            th = th + w * DT + ww[0]
            w = w + ww[1]
            bias = bias + config.accel_bias_random_walk * math.sqrt(DT) * rng.standard_normal(3)
            t = round(t + DT, 12)
            noise = config.accel_noise_density * math.sqrt(RATE) * rng.standard_normal(3)
            accel = r_wb.T @ (a_drone - g) + bias + noise
            samples.append(ImuSample(t, accel, np.zeros(3)))
        truth = np.concatenate([p_rel, v_rel, th, w, bias])
        pose = None
        if k % pose_every == 0:
            r_wc = r_wb @ R_BC
            t_cd = r_wc.T @ (p_rel - r_wb @ T_BC) + sigma[:3] * rng.standard_normal(3)
            th_noisy = th + sigma[3:] * rng.standard_normal(3)
            r_cd = r_wc.T @ rotation_zyx(th_noisy) @ R_PD
            pose = DeckPoseEstimate("atda", t, True, r_cd, t_cd)
        frames.append(Frame(t, r_wb, samples, truth, pose))
    return frames


def make_config(**kwargs: object) -> FusionConfig:
    base: dict[str, object] = {
        "sources": ("atda",),
        "use_tof": False,
        "atda_sigma": SIGMA,
        "deck_accel_psd": 0.01,
        "deck_angular_accel_psd": 0.002,
        "initial_rate_sigma": 0.05,
        # these tests' data follow the given deck models with independent pose errors (the
        # identification and the coloured errors:
        # tests/estimation/fusion/test_filter_identification.py)
        "identify_deck_motion": False,
        "tilt_error_correlation_s": 0.0,
        "tilt_error_sigma_scale": 1.0,
    }
    base.update(kwargs)
    return FusionConfig(**base)  # type: ignore[arg-type]


def make_fusion(config: FusionConfig) -> DeckFusion:
    return DeckFusion(config, tof_positions_in_camera_frame(), T_BC)


def nees(fusion: DeckFusion, truth: np.ndarray) -> float:
    error = truth - fusion.state
    error[TH] = wrap_angle(error[TH])
    return float(error @ np.linalg.solve(fusion.covariance, error))


def test_nees_consistent_over_monte_carlo() -> None:
    """Average NEES over seeded runs inside the chi-square 95% band of the 15-state."""
    config = make_config(gate_probability=1.0 - 1e-12)
    runs = 25
    checkpoints = (40, 80, 119)  # 2 s, 4 s, 6 s
    values = {k: [] for k in checkpoints}
    rng = np.random.default_rng(7)
    for _ in range(runs):
        fusion = make_fusion(config)
        for k, frame in enumerate(synthetic_run(rng, config)):
            poses = [frame.pose] if frame.pose is not None else []
            fusion.step(frame.time, frame.r_wb, frame.imu, None, poses)
            if k in checkpoints:
                values[k].append(nees(fusion, frame.truth))
    low, high = chi2.ppf([0.025, 0.975], runs * N_STATE) / runs
    for k in checkpoints:
        mean = float(np.mean(values[k]))
        assert low <= mean <= high, (k, mean, low, high)
    # and it converged: the position error at the end is well below the measurement noise
    assert fusion.diagnostics().get("atda_rejected", 0) == 0


def test_converges_on_constant_acceleration() -> None:
    config = make_config()
    fusion = make_fusion(config)
    frames = synthetic_run(np.random.default_rng(3), config, duration=6.0)
    errors = []
    for frame in frames:
        estimate = fusion.step(
            frame.time, frame.r_wb, frame.imu, None, [frame.pose] if frame.pose else []
        )
        errors.append(np.abs(frame.truth - fusion.state))
    late = np.mean(errors[-40:], axis=0)
    assert estimate.valid and estimate.covariance is not None
    # below one measurement's noise (3, 3, 8 mm) and a tenth of the initial velocity sigma
    assert np.all(late[0:3] < np.array(SIGMA[:3]))
    assert np.all(late[3:6] < 0.2 * config.initial_velocity_sigma)


def _run_with_delay(delay_steps: int, frames: list[Frame], config: FusionConfig) -> DeckFusion:
    fusion = make_fusion(config)
    pending: list[tuple[int, DeckPoseEstimate]] = []
    for k, frame in enumerate(frames):
        if frame.pose is not None:
            pending.append((k + delay_steps, frame.pose))
        due = [pose for when, pose in pending if when <= k]
        pending = [(when, pose) for when, pose in pending if when > k]
        fusion.step(frame.time, frame.r_wb, frame.imu, None, due)
    return fusion


def test_delayed_measurement_equals_undelayed() -> None:
    """A pose delivered 200 ms late, fused at its timestamp, gives the on-time estimate."""
    config = make_config()
    frames = synthetic_run(np.random.default_rng(11), config, duration=3.0)
    # the last measurement lands inside both runs: compare after the delayed one arrives
    frames = frames[:-4] + [Frame(f.time, f.r_wb, f.imu, f.truth, None) for f in frames[-4:]]
    on_time = _run_with_delay(0, frames, config)
    late = _run_with_delay(4, frames, config)
    np.testing.assert_allclose(late.state, on_time.state, rtol=0, atol=1e-12)
    np.testing.assert_allclose(late.covariance, on_time.covariance, rtol=0, atol=1e-15)
    without = _run_with_delay(100, frames, config)  # never delivered: a different estimate
    assert np.max(np.abs(without.state - on_time.state)) > 1e-5


def test_too_old_measurement_is_rejected_and_counted() -> None:
    config = make_config(horizon_s=0.3)
    frames = synthetic_run(np.random.default_rng(5), config, duration=2.0)
    late = _run_with_delay(8, frames, config)  # 0.4 s late: beyond the 0.3 s horizon
    diag = late.diagnostics()
    assert diag["atda_too_old"] > 0
    assert diag.get("atda_accepted", 0) == 0


def test_outlier_is_gated_and_counted() -> None:
    config = make_config()
    fusion = make_fusion(config)
    frames = synthetic_run(np.random.default_rng(2), config, duration=3.0)
    for frame in frames[:-1]:
        fusion.step(frame.time, frame.r_wb, frame.imu, None, [frame.pose] if frame.pose else [])
    before = fusion.state
    last = frames[-1]
    r_wc = last.r_wb @ R_BC
    good_t = r_wc.T @ (last.truth[0:3] - last.r_wb @ T_BC)
    bad = DeckPoseEstimate(
        "atda",
        last.time,
        True,
        r_wc.T @ rotation_zyx(last.truth[TH]) @ R_PD,
        np.array([*good_t[:2], good_t[2] + 0.3]),
    )
    fusion.step(last.time, last.r_wb, last.imu, None, [bad])
    diag = fusion.diagnostics()
    assert diag["atda_rejected"] == 1
    assert diag["nis_atda"] > chi2.ppf(config.gate_probability, 6)
    # only the prediction moved the state: the outlier did not pull z
    assert abs(fusion.state[2] - before[2]) < 0.01


def test_reset_after_timeout_and_reinitialise() -> None:
    config = make_config(reset_timeout_s=0.5)
    fusion = make_fusion(config)
    frames = synthetic_run(np.random.default_rng(4), config, duration=3.0)
    for frame in frames[:20]:
        fusion.step(frame.time, frame.r_wb, frame.imu, None, [frame.pose] if frame.pose else [])
    assert fusion.initialised
    for frame in frames[20:40]:  # 1 s without vision
        estimate = fusion.step(frame.time, frame.r_wb, frame.imu, None, [])
    assert not estimate.valid and estimate.reason == "fusion_reset"
    assert fusion.diagnostics()["resets"] == 1
    frame = frames[40]
    assert frame.pose is not None
    estimate = fusion.step(frame.time, frame.r_wb, frame.imu, None, [frame.pose])
    assert estimate.valid
    assert fusion.diagnostics()["atda_initialised"] == 2


def test_tof_model_matches_geometry_and_jacobian() -> None:
    """A level drone 2 m above a level deck reads 2 m minus the sensor heights; H is right."""
    fusion = make_fusion(make_config(use_tof=True))
    x = np.zeros(N_STATE)
    x[2] = -2.0
    r_wb = np.eye(3)
    for origin in fusion.tof_origins_b:
        predicted, _ = tof_model(x, origin, r_wb)
        assert predicted == pytest.approx(2.0 + origin[2])
    rng = np.random.default_rng(0)
    x[0:3] += rng.normal(0, 0.05, 3)
    x[TH] = [0.1, -0.07, 0.5]
    r_wb = matrix_from_euler_zyx(0.05, 0.1, -0.3)
    origin = fusion.tof_origins_b[1]
    _, h = tof_model(x, origin, r_wb)
    numeric = np.zeros(N_STATE)
    for i in range(N_STATE):
        d = np.zeros(N_STATE)
        d[i] = 1e-7
        numeric[i] = (tof_model(x + d, origin, r_wb)[0] - tof_model(x - d, origin, r_wb)[0]) / 2e-7
    np.testing.assert_allclose(h, numeric, atol=1e-6)
    normal, _ = deck_normal(x[TH])
    np.testing.assert_allclose(normal, matrix_from_euler_zyx(*x[TH])[:, 2], atol=1e-12)


def test_a_tof_ray_reads_the_deck_from_any_height_above_it_but_not_grazing_or_from_on_it() -> None:
    """A ray reads the range along it to the deck plane however short (0.5 m: half a metre),
    and up to 78.5 degrees of incidence (cosine 0.2, exactly); a grazing ray, one pointing
    away and a sensor on the plane read nothing."""
    x = np.zeros(N_STATE)
    origin = np.zeros(3)
    x[2] = -0.5
    predicted, h = tof_model(x, origin, np.eye(3))
    assert predicted == pytest.approx(0.5, rel=1e-12)
    np.testing.assert_allclose(h[0:3], [0.0, 0.0, -1.0], atol=1e-12)
    x[2] = 0.0  # the sensor on the deck plane
    assert tof_model(x, origin, np.eye(3)) is None
    x[2] = -2.0
    for cosine, reads in ((0.2, True), (0.15, False), (-0.5, False)):
        sine = math.sqrt(1.0 - cosine * cosine)
        r_wb = np.array([[1.0, 0.0, 0.0], [0.0, cosine, -sine], [0.0, sine, cosine]])
        result = tof_model(x, origin, r_wb)
        assert (result is not None) == reads, cosine
        if reads:
            assert result[0] == pytest.approx(2.0 / cosine, rel=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    w1=st.floats(0.2, 1.5),
    ratio=st.floats(1.3, 4.0),
    zeta1=st.floats(0.05, 1.2),
    zeta2=st.floats(0.05, 1.2),
    sigma_rad=st.floats(0.005, 0.2),
    gain=st.floats(0.5, 4.0),
)
def test_the_two_component_model_has_its_factors_and_the_spread_asked_for_times_the_gain(
    w1: float, ratio: float, zeta1: float, zeta2: float, sigma_rad: float, gain: float
) -> None:
    """Each factor keeps its own frequency and damping in the polynomial, and the driving
    PSD gives the stationary spread asked for times the noise gain (default 1): the angle's,
    the angular acceleration's and the jerk's variance are the integrals of the spectrum
    ``q / |A(i w)|²`` times 1, ``w⁴`` and ``w⁶`` (against SciPy's quadrature, not the
    Lyapunov equation the model solves)."""
    w2 = ratio * w1
    polynomial, q, (accel_sigma, jerk_sigma) = deck_spectrum_of(
        w1, zeta1, w2, zeta2, sigma_rad, gain
    )
    product = np.polymul([1.0, 2.0 * zeta1 * w1, w1 * w1], [1.0, 2.0 * zeta2 * w2, w2 * w2])
    np.testing.assert_allclose(polynomial, product[:0:-1], rtol=1e-12)

    def variance(power: int) -> float:
        def spectrum(w: float) -> float:
            return q * w**power / abs(np.polyval(product, 1j * w)) ** 2

        return quad(spectrum, 0.0, np.inf, epsabs=0.0, epsrel=1e-10, limit=500)[0] / math.pi

    assert variance(0) == pytest.approx(gain * sigma_rad**2, rel=1e-6)
    assert accel_sigma == pytest.approx(math.sqrt(variance(4)), rel=1e-6)
    assert jerk_sigma == pytest.approx(math.sqrt(variance(6)), rel=1e-6)
    _, q_default, _ = deck_spectrum_of(w1, zeta1, w2, zeta2, sigma_rad)
    assert q_default == pytest.approx(q / gain, rel=1e-12)


def test_two_waves_matched_to_variances_hold_those_variances_when_stationary() -> None:
    """Each component, theta'' = -w² theta - 2 zeta w theta' + n with n of PSD q, settles at
    the variance asked for: the stationary covariance solves A P + P A^T + Q = 0."""
    from scipy.linalg import solve_continuous_lyapunov

    waves = TwoWaves.matched(0.9, 0.05, 1.7, 0.12, 0.02, 0.005)
    for w, zeta, q, variance in ((0.9, 0.05, waves.q1, 0.02), (1.7, 0.12, waves.q2, 0.005)):
        a = np.array([[0.0, 1.0], [-(w**2), -2.0 * zeta * w]])
        spread = solve_continuous_lyapunov(a, -np.diag([0.0, q]))
        assert spread[0, 0] == pytest.approx(variance, rel=1e-9)
        assert spread[1, 1] == pytest.approx(w**2 * variance, rel=1e-9)
    assert waves.second_sigmas == pytest.approx((math.sqrt(0.005), 1.7 * math.sqrt(0.005)))


@settings(max_examples=60, deadline=None)
@given(angles=st.tuples(*(st.floats(-4.0, 4.0),) * 3), turns=st.integers(-3, 3))
def test_rotation_zyx_is_yaw_then_pitch_then_roll_and_wrapping_keeps_the_angle(
    angles: tuple[float, float, float], turns: int
) -> None:
    """R_WP from (roll, pitch, yaw) is SciPy's intrinsic ZYX rotation (every entry, every
    angle), and wrapping an angle moves it into [-pi, pi) by whole turns."""
    roll, pitch, yaw = angles
    expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    np.testing.assert_allclose(rotation_zyx(np.array(angles)), expected, atol=1e-12)
    angle = roll + 2.0 * math.pi * turns
    wrapped = float(wrap_angle(angle))
    assert -math.pi <= wrapped < math.pi
    assert wrapped == pytest.approx(
        roll - 2.0 * math.pi * math.floor((roll + math.pi) / (2 * math.pi)), abs=1e-9
    )


_HOVER_B = np.array([0.0, 0.0, 9.81])


def _euler_step(
    x: np.ndarray,
    accel_b: np.ndarray,
    r_wb: np.ndarray,
    dt: float,
    deck4: tuple | None,
    tilt_correlation_s: float,
    deck_w0: float = 0.0,
    deck_zeta: float = 0.0,
) -> np.ndarray:
    """One explicit Euler step of the documented continuous models, written out: the relative
    position and velocity under the drone's acceleration, the Euler angles at their rates
    (yaw's constant), and roll and pitch as the two-oscillator sum (TwoWaves) or the
    fourth-order polynomial, or (deck4 None) the damped oscillator of ``deck_w0``; the
    coloured errors decay."""
    out = x.copy()
    a_rel = -(r_wb @ (accel_b - x[12:15])) - np.array([0.0, 0.0, -9.81])
    out[0:3] = x[0:3] + x[3:6] * dt + 0.5 * dt * dt * a_rel
    out[3:6] = x[3:6] + a_rel * dt
    out[6:9] = x[6:9] + x[9:12] * dt
    for i in range(2 if deck4 is not None else 0):
        th, w, third, fourth = x[6 + i], x[9 + i], x[15 + i], x[17 + i]
        if isinstance(deck4[i], TwoWaves):
            m = deck4[i]
            accel2 = -(m.w2**2) * third - 2.0 * m.zeta2 * m.w2 * fourth
            accel1 = -(m.w1**2) * (th - third) - 2.0 * m.zeta1 * m.w1 * (w - fourth)
            out[9 + i] = w + (accel1 + accel2) * dt
            out[15 + i] = third + fourth * dt
            out[17 + i] = fourth + accel2 * dt
        else:
            a0, a1, a2, a3 = deck4[i][0]
            out[9 + i] = w + third * dt
            out[15 + i] = third + fourth * dt
            out[17 + i] = fourth - (a0 * th + a1 * w + a2 * third + a3 * fourth) * dt
    if deck4 is None:
        out[9:11] = x[9:11] - (deck_w0**2 * x[6:8] + 2.0 * deck_zeta * deck_w0 * x[9:11]) * dt
    if tilt_correlation_s > 0.0:
        out[-N_COLOURED:] = x[-N_COLOURED:] * math.exp(-dt / tilt_correlation_s)
    return out


@pytest.mark.parametrize("model", ["two-waves", "fourth-order", "oscillator", "constant-rates"])
@pytest.mark.parametrize("tilt_correlation_s", [0.0, 0.3])
def test_a_prediction_is_one_euler_step_and_its_covariance_goes_through_the_same_map(
    model: str, tilt_correlation_s: float
) -> None:
    """From a state with every entry set (a tilted, accelerating drone; a deck rolling and
    pitching through both components), one step of 20 ms is the Euler step of the models,
    entry by entry; and the covariance is carried by that same linear map, F P Fᵀ plus the
    noise of a zero covariance (each axis driven by its own components' PSDs), for each deck
    model (the two-oscillator sum, the fourth-order model, the oscillator, constant rates),
    with and without the coloured tilt errors."""
    if model == "two-waves":
        deck4 = (
            TwoWaves.matched(0.6, 0.1, 1.4, 0.3, 2e-3, 5e-4),
            TwoWaves.matched(0.5, 0.2, 1.7, 0.15, 1e-3, 8e-4),
        )
    elif model == "fourth-order":
        deck4 = (
            (deck_spectrum_of(0.6, 0.1, 1.4, 0.3, 0.04)),
            (deck_spectrum_of(0.5, 0.2, 1.7, 0.15, 0.03)),
        )
    else:
        deck4 = None
    oscillator = (0.7, 0.2) if model == "oscillator" else (0.0, 0.0)
    n = (N_STATE if deck4 is None else N_STATE_4) + (N_COLOURED if tilt_correlation_s > 0.0 else 0)
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 0.3, n)
    r_wb = matrix_from_euler_zyx(0.2, -0.15, 0.7)
    accel_b = np.array([0.8, -0.5, 11.0])
    dt = 0.02
    args = (accel_b, r_wb, dt, 0.01, 0.002, 1e-3, 4e-4)
    extra = {
        "deck_w0": oscillator[0],
        "deck_zeta": oscillator[1],
        "deck4": deck4,
        "tilt_correlation_s": tilt_correlation_s,
    }
    stepped, _ = predict(x, np.zeros((n, n)), *args, **extra)
    expected = _euler_step(x, accel_b, r_wb, dt, deck4, tilt_correlation_s, *oscillator)
    np.testing.assert_allclose(stepped, expected, rtol=1e-12, atol=1e-14)
    # the map is affine in the state: its columns by differences of unit steps
    jacobian = np.column_stack(
        [predict(x + np.eye(n)[i], np.zeros((n, n)), *args, **extra)[0] - stepped for i in range(n)]
    )
    _, noise = predict(x, np.zeros((n, n)), *args, **extra)
    d1, d2, d3 = dt, dt * dt / 2.0, dt**3 / 3.0
    white = np.array([[d3, d2], [d2, d1]])
    for i in range(2 if deck4 is not None else 0):
        # each axis' own driving noise: roll's and pitch's PSDs, integrated over the step
        block = noise[np.ix_([6 + i, 9 + i, 15 + i, 17 + i], [6 + i, 9 + i, 15 + i, 17 + i])]
        if model == "two-waves":
            expected_block = deck4[i].q1 * np.kron([[1.0, 0.0], [0.0, 0.0]], white)
            expected_block += deck4[i].q2 * np.kron(np.ones((2, 2)), white)
        else:
            expected_block = np.zeros((4, 4))
            expected_block[3, 3] = deck4[i][1] * dt
        np.testing.assert_allclose(block, expected_block, rtol=1e-12, atol=1e-20)
    root = rng.normal(0.0, 1.0, (n, n))
    cov = root @ root.T
    _, carried = predict(x, cov, *args, **extra)
    np.testing.assert_allclose(carried - noise, jacobian @ cov @ jacobian.T, rtol=1e-9, atol=1e-12)


def test_without_a_deck_model_the_rates_stay_and_an_oscillator_alone_is_undamped() -> None:
    """Without deck_w0 the Euler rates stay as they are (constant rates); given deck_w0
    alone, roll and pitch swing undamped: half a period later they are reversed."""
    x = np.zeros(N_STATE)
    x[TH] = [0.05, -0.04, 0.3]
    x[9:12] = [0.01, -0.02, 0.03]
    cov = np.zeros((N_STATE, N_STATE))
    steady, _ = predict(x, cov, _HOVER_B, np.eye(3), 0.5, 0.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(steady[9:12], x[9:12], rtol=0, atol=0)
    np.testing.assert_allclose(steady[TH], x[TH] + 0.5 * x[9:12], rtol=1e-12)
    period, dt = 9.0, 1.0 / 240.0
    swing = x.copy()
    swing[9:12] = [0.0, 0.0, 0.0]
    for _ in range(round(period / 2.0 / dt)):
        swing, _ = predict(
            swing, cov, _HOVER_B, np.eye(3), dt, 0.0, 0.0, 0.0, 0.0, deck_w0=2.0 * math.pi / period
        )
    np.testing.assert_allclose(swing[TH][:2], [-0.05, 0.04], rtol=0.02)


def test_an_update_at_exactly_the_gate_is_fused_and_one_beyond_it_or_nan_is_not() -> None:
    """The gate is the largest NIS accepted: an innovation of exactly 3 sigma passes a gate
    of 9 (3 SD) and moves the state by the Kalman gain; a bit more, or a NaN, leaves it."""
    x = np.array([1.0, 2.0])
    cov = np.diag([3.0, 1.0])
    h = np.array([[1.0, 0.0]])
    noise = np.array([[1.0]])  # S = 4, so an innovation of 6 is 3 sigma
    updated, new_cov, nis, accepted = ekf_update(x, cov, np.array([6.0]), h, noise, 9.0)
    assert accepted and nis == 9.0
    np.testing.assert_allclose(updated, [1.0 + 0.75 * 6.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(new_cov, np.diag([0.75, 1.0]), rtol=1e-12)
    for innovation in (6.000001, math.nan):
        kept, kept_cov, _, accepted = ekf_update(x, cov, np.array([innovation]), h, noise, 9.0)
        assert not accepted and kept is x and kept_cov is cov


def test_tof_ranges_refine_height_and_tilt() -> None:
    """With the ToF ranges, z and the deck tilt are estimated better than from poses alone."""
    config = make_config(use_tof=True, tof_sigma_m=0.002, tof_sigma_per_m=0.0)
    errors = {}
    for use_tof in (False, True):
        cfg = make_config(use_tof=use_tof, tof_sigma_m=0.002, tof_sigma_per_m=0.0)
        fusion = make_fusion(cfg)
        rng = np.random.default_rng(9)
        frames = synthetic_run(rng, config, duration=4.0)
        err = []
        for frame in frames:
            x = frame.truth
            ranges = np.array([tof_model(x, o, frame.r_wb)[0] for o in fusion.tof_origins_b])
            ranges += 0.002 * rng.standard_normal(4)
            reading = RangeReading(frame.time, ranges, np.ones(4, dtype=bool))
            poses = [frame.pose] if frame.pose else []
            fusion.step(frame.time, frame.r_wb, frame.imu, reading, poses)
            err.append(np.abs(wrap_angle(fusion.state - x))[[2, 6, 7]])
        errors[use_tof] = np.mean(err[20:], axis=0)
        if use_tof:
            assert fusion.diagnostics()["tof_accepted"] > 0
    assert np.all(errors[True] < errors[False])


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError, match="sources"):
        FusionConfig(sources=("truth",))
    with pytest.raises(ConfigError, match="gate_probability"):
        FusionConfig(gate_probability=1.0)
    with pytest.raises(ConfigError, match="atda_sigma"):
        FusionConfig(atda_sigma=(0.1, 0.1))
    assert FusionConfig(ihrcf_sigma=(0.002, 0.002, math.inf, math.inf, math.inf, 0.3)).sources


_WAVES = {"deck_roll_periods_s": (10.0, 4.0), "deck_pitch_periods_s": (9.0, 4.0)}
_PERIODS = ": two periods in 0.5-1000 s, or [] for none"
_RMS = "two values in (0, 90]: roll, pitch (deg)"
_NOT_A_SOURCE = "'truth' is not allowed; choose one of " + ", ".join(map(repr, POSE_SOURCES))


@pytest.mark.parametrize(
    ("overrides", "key", "detail"),
    [
        ({"sources": ("truth",)}, "sources", _NOT_A_SOURCE),
        ({"covariance_sources": ("truth",)}, "covariance_sources", _NOT_A_SOURCE),
        (
            {"atda_sigma": (0.1, 0.1)},
            "atda_sigma",
            "(0.1, 0.1) needs 6 values: x, y, z (m), roll, pitch, yaw (deg)",
        ),
        (
            {"crhf_sigma": (0.1,) * 5 + (0.0,)},
            "crhf_sigma",
            "(0.1, 0.1, 0.1, 0.1, 0.1, 0.0): every sigma must be > 0 (or .inf: unused)",
        ),
        (
            {"tight_sigma": (-0.1,) + (0.1,) * 5},
            "tight_sigma",
            "(-0.1, 0.1, 0.1, 0.1, 0.1, 0.1): every sigma must be > 0 (or .inf: unused)",
        ),
        (
            {"deck_roll_periods_s": (10.0,), "deck_pitch_periods_s": (9.0, 4.0)},
            "deck_roll_periods_s",
            "(10.0,)" + _PERIODS,
        ),
        (
            {"deck_roll_periods_s": (10.0, 4.0, 3.0), "deck_pitch_periods_s": (9.0, 4.0)},
            "deck_roll_periods_s",
            "(10.0, 4.0, 3.0)" + _PERIODS,
        ),
        (
            {"deck_roll_periods_s": (10.0, 4.0), "deck_pitch_periods_s": (9.0, 0.49)},
            "deck_pitch_periods_s",
            "(9.0, 0.49)" + _PERIODS,
        ),
        (
            {"deck_roll_periods_s": (1000.5, 4.0), "deck_pitch_periods_s": (9.0, 4.0)},
            "deck_roll_periods_s",
            "(1000.5, 4.0)" + _PERIODS,
        ),
        (
            {"deck_roll_periods_s": (10.0, 4.0)},
            "deck_pitch_periods_s",
            "set with deck_roll_periods_s, or neither",
        ),
        ({"deck_attitude_rms_deg": (3.0,)}, "deck_attitude_rms_deg", _RMS),
        ({"deck_attitude_rms_deg": (3.0,) * 3}, "deck_attitude_rms_deg", _RMS),
        ({"deck_attitude_rms_deg": (0.0, 3.0)}, "deck_attitude_rms_deg", _RMS),
        ({"deck_attitude_rms_deg": (3.0, 90.5)}, "deck_attitude_rms_deg", _RMS),
        (
            {**_WAVES, "deck_damping_ratio": 0.004},
            "deck_damping_ratio",
            "must be >= 0.005 with the wave periods",
        ),
    ],
)
def test_a_bad_fusion_setting_is_refused_naming_its_key_and_what_it_needs(
    overrides: dict[str, object], key: str, detail: str
) -> None:
    with pytest.raises(ConfigError) as caught:
        FusionConfig(**overrides)  # type: ignore[arg-type]
    assert (caught.value.key, caught.value.detail) == (key, detail)


def test_fusion_settings_at_the_ends_of_their_ranges_are_taken_as_tuples_of_floats() -> None:
    """Lists and integers are taken as tuples of floats; periods of 0.5 s and 1000 s, an RMS
    of 90 deg or half a degree and a damping ratio of 0.005 with the wave periods are
    allowed, and so is no damping at all without them."""
    config = FusionConfig(
        sources=["atda", "tight"],  # type: ignore[arg-type]
        covariance_sources=["tight"],  # type: ignore[arg-type]
        deck_roll_periods_s=[0.5, 1000],  # type: ignore[arg-type]
        deck_pitch_periods_s=(1000, 0.5),
        deck_attitude_rms_deg=[90, 0.5],  # type: ignore[arg-type]
        deck_damping_ratio=0.005,
        atda_sigma=[1, 2, 3, 4, 5, math.inf],  # type: ignore[arg-type]
    )
    assert config.sources == ("atda", "tight") and config.covariance_sources == ("tight",)
    for value, expected in (
        (config.deck_roll_periods_s, (0.5, 1000.0)),
        (config.deck_pitch_periods_s, (1000.0, 0.5)),
        (config.deck_attitude_rms_deg, (90.0, 0.5)),
        (config.atda_sigma, (1.0, 2.0, 3.0, 4.0, 5.0, math.inf)),
    ):
        assert type(value) is tuple and value == expected
        assert all(type(v) is float for v in value)
    assert config.pose_sigma("atda") == (1.0, 2.0, 3.0, 4.0, 5.0, math.inf)
    assert config.pose_sigma("crhf") == config.crhf_sigma
    assert FusionConfig(deck_damping_ratio=0.0).deck_damping_ratio == 0.0


@pytest.mark.parametrize(
    ("overrides", "key", "detail"),
    [
        ({"identify_ar_order": 5}, "identify_ar_order", "5: 4, 6, ..., 16"),
        ({"identify_ar_order": 18}, "identify_ar_order", "18: 4, 6, ..., 16"),
        (
            {"identify_window_s": 15.0, "identify_min_window_s": 20.0},
            "identify_min_window_s",
            "must be <= identify_window_s",
        ),
        (
            {"identify_min_window_s": 11.9},
            "identify_min_window_s",
            "needs 3 * identify_ar_order samples (identify_sample_s apart) or more",
        ),
        (
            {"identify_period_range_s": (2.0, 1000.5)},
            "identify_period_range_s",
            "(2.0, 1000.5): two values in [0.5, 1000]",
        ),
        (
            {"identify_initial_periods_s": (10.0, 1000.5)},
            "identify_initial_periods_s",
            "(10.0, 1000.5): two values in [0.5, 1000]",
        ),
        (
            {"identify_damping_range": (0.05, 10.5)},
            "identify_damping_range",
            "(0.05, 10.5): two values in [0.005, 10]",
        ),
        (
            {"identify_period_range_s": (2.0, 2.0)},
            "identify_period_range_s",
            "(2.0, 2.0): the low end first, below the high end",
        ),
        (
            {"identify_damping_range": (0.5, 0.5)},
            "identify_damping_range",
            "(0.5, 0.5): the low end first, below the high end",
        ),
    ],
)
def test_bad_identification_settings_are_refused_saying_what_they_need(
    overrides: dict[str, object], key: str, detail: str
) -> None:
    """The AR order is even, 4 to 16; the shortest window fits in the window and holds three
    samples per AR coefficient; the bands are two values, the low end first."""
    with pytest.raises(ConfigError) as caught:
        FusionConfig(**overrides)  # type: ignore[arg-type]
    assert (caught.value.key, caught.value.detail) == (key, detail)


def test_identification_settings_at_the_ends_of_their_ranges_are_taken_as_floats() -> None:
    """Orders 4 and 16; a shortest window equal to the window, or to exactly three samples
    per AR coefficient (8 x 3 x 0.5 s = 12 s); bands from 0.5 s to 1000 s and damping from
    0.005 to 10, given as lists of integers or floats; the initial periods in either order."""
    assert FusionConfig(identify_ar_order=4).identify_ar_order == 4
    assert FusionConfig(identify_ar_order=16, identify_min_window_s=24.0).identify_ar_order == 16
    assert FusionConfig(identify_window_s=15.0, identify_min_window_s=15.0).identifies
    assert FusionConfig(identify_min_window_s=12.0).identify_min_window_s == 12.0
    config = FusionConfig(
        identify_period_range_s=[1, 1000],  # type: ignore[arg-type]
        identify_initial_periods_s=[0.5, 1000],  # type: ignore[arg-type]
        identify_damping_range=[0.005, 10],  # type: ignore[arg-type]
    )
    for value, expected in (
        (config.identify_period_range_s, (1.0, 1000.0)),
        (config.identify_initial_periods_s, (0.5, 1000.0)),
        (config.identify_damping_range, (0.005, 10.0)),
    ):
        assert type(value) is tuple and value == expected
        assert all(type(v) is float for v in value)
    assert FusionConfig(identify_period_range_s=(0.5, 30.0)).identify_period_range_s[0] == 0.5


def test_the_gate_is_gate_sd_squared_when_set_else_the_chi_square_quantile() -> None:
    paper = FusionConfig(gate_sd=10.0, gate_probability=0.99)
    assert [paper.gate(dof) for dof in range(1, 7)] == [100.0] * 6
    chi_square = FusionConfig(gate_probability=0.99)
    for dof in range(1, 7):
        assert chi_square.gate(dof) == pytest.approx(chi2.ppf(0.99, dof), rel=1e-12)


@given(
    dof=st.integers(1, 12),
    probability=st.floats(1e-6, 1.0 - 1e-9, allow_nan=False),
)
@settings(max_examples=60, deadline=None)
def test_the_chi_square_gate_is_scipys_chi_square_quantile(dof: int, probability: float) -> None:
    assert nis_gate(dof, probability, None) == pytest.approx(chi2.ppf(probability, dof), rel=1e-12)
    assert nis_gate(dof, probability, 3.0) == 9.0


def _as_tight(frame: Frame, rng: np.random.Generator, sigma_cd: np.ndarray) -> DeckPoseEstimate:
    """The frame's true T_CD with noise of covariance diag(sigma_cd²) on its (x, y, z, roll,
    pitch, yaw), carried as the estimate's own covariance (as tight gives it)."""
    r_wb = frame.r_wb
    r_wc = r_wb @ R_BC
    truth = frame.truth
    t_cd = r_wc.T @ (truth[0:3] - r_wb @ T_BC)
    euler = euler_zyx_from_matrix(r_wc.T @ rotation_zyx(truth[TH]) @ R_PD)
    noisy = np.concatenate([t_cd, euler]) + sigma_cd * rng.standard_normal(6)
    return DeckPoseEstimate(
        "tight",
        frame.time,
        True,
        matrix_from_euler_zyx(*noisy[3:]),
        noisy[:3],
        covariance=np.diag(sigma_cd**2),
        extras={"ranges_used": 4},
    )


def test_a_source_with_its_own_covariance_is_fused_consistently_nees_and_nis() -> None:
    """Poses whose noise is given in T_CD's axes (tight's covariance) are carried into the
    state's axes through the measurement Jacobian: NEES and NIS stay in their chi² bands."""
    config = make_config(sources=("tight",), gate_probability=1.0 - 1e-12)
    sigma_cd = np.array([0.002, 0.002, 0.004, *np.radians([1.5, 1.5, 0.3])])
    runs = 25
    nees_end, nis_values = [], []
    rng = np.random.default_rng(11)
    for _ in range(runs):
        fusion = make_fusion(config)
        for frame in synthetic_run(rng, config):
            poses = [_as_tight(frame, rng, sigma_cd)] if frame.pose is not None else []
            fusion.step(frame.time, frame.r_wb, frame.imu, None, poses)
            if poses and fusion.diagnostics().get("tight_accepted", 0) > 0:
                nis_values.append(fusion.diagnostics()["nis_tight"])
        nees_end.append(nees(fusion, frame.truth))
    low, high = chi2.ppf([0.025, 0.975], runs * N_STATE) / runs
    assert low <= float(np.mean(nees_end)) <= high
    n = len(nis_values)
    low, high = chi2.ppf([0.025, 0.975], 6 * n) / n
    assert low <= float(np.mean(nis_values)) <= high, np.mean(nis_values)


def test_a_pose_that_holds_its_frames_ranges_supersedes_their_tof_update() -> None:
    """Each ToF reading is used once: through tight's pose when it arrives (even late),
    directly otherwise."""
    config = make_config(sources=("tight",), use_tof=True)
    sigma_cd = np.array([0.002, 0.002, 0.004, *np.radians([1.5, 1.5, 0.3])])
    rng = np.random.default_rng(3)
    frames = synthetic_run(rng, config, duration=2.0, pose_every=1)
    fusion = make_fusion(config)
    reading = RangeReading(0.0, np.full(4, 2.0), np.ones(4, bool))
    for k, frame in enumerate(frames):
        ranges = RangeReading(frame.time, reading.ranges, reading.valid)
        pose = _as_tight(frame, rng, sigma_cd)
        # every other pose arrives one step late: its frame's ranges were fused by then
        if k % 2 == 0:
            fusion.step(frame.time, frame.r_wb, frame.imu, ranges, [])
            late = pose
        else:
            fusion.step(frame.time, frame.r_wb, frame.imu, ranges, [late, pose])
    counts = fusion.diagnostics()
    assert counts.get("tof_superseded", 0) >= len(frames) - 4
    assert counts.get("tof_accepted", 0) + counts.get("tof_rejected", 0) <= 4 * 2


@pytest.mark.parametrize("source", ["ihrcf", "crhf"])
def test_a_pose_without_depth_is_fused_along_the_cameras_x_and_y_on_a_tilted_drone(
    source: str,
) -> None:
    """IHRCF and CRHF give x and y along the camera's axes and no depth. On a drone tilted
    10 degrees, a depth 0.3 m off moves nothing (the camera's x and y agree with the state),
    and each pose narrows the deck's position along the camera's x and y to its own 2 mm:
    the depth it does not give lends its stand-in sigma to neither."""
    config = make_config(sources=("atda", source))
    r_wb = matrix_from_euler_zyx(math.radians(10.0), math.radians(-4.0), 0.7)
    r_wc = r_wb @ R_BC
    fusion = make_fusion(config)
    fusion.step(0.0, r_wb, (), None, [_pose("atda", 0.0)])
    wrong_depth = _pose(source, 0.0)
    wrong_depth = dataclasses.replace(wrong_depth, translation=np.array([0.1, -0.2, 2.1]))
    for k in range(1, 11):
        pose = dataclasses.replace(wrong_depth, timestamp=0.05 * k)
        fusion.step(0.05 * k, r_wb, (), None, [pose])
    assert fusion.diagnostics()[f"{source}_accepted"] == 10
    in_camera = r_wc.T @ (fusion.state[P] - r_wb @ T_BC)
    np.testing.assert_allclose(in_camera, [0.1, -0.2, 1.8], rtol=0, atol=1e-9)
    spread = r_wc.T @ fusion.covariance[P, P] @ r_wc
    # ten 2-mm measurements of x and y: their variance is a tenth of 2 mm squared or less
    assert spread[0, 0] <= 0.002**2 / 10 and spread[1, 1] <= 0.002**2 / 10
    # the depth is ATDA's alone: its 8 mm, spread over the 10 steps' velocity prior
    assert spread[2, 2] >= 0.008**2


def test_the_drones_own_rotation_does_not_enter_the_deck_attitude() -> None:
    """A hovering drone that rolls and yaws by several degrees over a deck at rest: the camera
    sees the deck tilt and turn, the filter (drone attitude from the autopilot and the gyro)
    keeps the deck level and still, and averages its poses over the frames."""
    config = make_config(sources=("tight",), gate_probability=1.0 - 1e-12)
    sigma_cd = np.array([0.002, 0.002, 0.004, *np.radians([1.5, 1.5, 0.3])])
    rng = np.random.default_rng(5)
    fusion = make_fusion(config)
    th_deck = np.array([0.0, 0.0, 0.3])
    p_deck_w = np.array([0.0, 0.0, -2.0])
    g = np.array([0.0, 0.0, -9.81])
    t = 0.0
    errors = []
    for k in range(200):  # 10 s
        samples = []
        for _ in range(RATE // 20):
            t = round(t + DT, 12)
            angles = np.array([0.1 * math.sin(1.3 * t), 0.06 * math.sin(0.7 * t), 0.4 * t])
            rates = np.array([0.13 * math.cos(1.3 * t), 0.042 * math.cos(0.7 * t), 0.4])
            r_wb = matrix_from_euler_zyx(*angles)
            # body rates of this Euler motion, by differencing the attitude
            r_next = matrix_from_euler_zyx(*(angles + rates * 1e-6))
            omega = Rotation.from_matrix(r_wb.T @ r_next).as_rotvec() / 1e-6
            samples.append(ImuSample(t, r_wb.T @ (-g), omega))
        truth = np.concatenate([p_deck_w, np.zeros(3), th_deck, np.zeros(3), np.zeros(3)])
        frame = Frame(t, r_wb, samples, truth, None)
        fusion.step(t, r_wb, samples, None, [_as_tight(frame, rng, sigma_cd)])
        if k >= 100:
            error = fusion.state[TH] - th_deck
            errors.append(np.degrees(np.abs(wrap_angle(error))))
    mean = np.array(errors).mean(axis=0)
    # the drone rolled 5.7° and turned 230°; the deck estimate stays level and still, with
    # its mean error over the last 5 s well below a single frame's (0.8 sigma: 1.2° in roll
    # and pitch, 0.24° in yaw)
    single = 0.8 * np.degrees(sigma_cd[3:])
    assert np.all(mean[:2] < 0.4 * single[:2]) and mean[2] < 0.8 * single[2], (mean, single)


def test_the_deck_oscillator_swings_roll_and_pitch_about_level_with_the_stationary_spread() -> None:
    """With a deck period set, roll and pitch follow a damped oscillator about level (yaw keeps
    its rate), and with no measurement their variance settles at the second-order model's
    q / (4 zeta w0^3) instead of growing without bound as under constant rates."""
    from estimation.fusion.model import W, predict

    period, psd, dt = 9.0, 0.002, 1.0 / 240.0
    w0 = 2.0 * math.pi / period
    hover = np.array([0.0, 0.0, 9.81])  # level drone at rest: no relative acceleration
    x = np.zeros(N_STATE)
    x[TH] = [0.05, -0.04, 0.3]
    x[W] = [0.0, 0.0, 0.01]
    cov = np.eye(N_STATE) * 1e-8
    swing = x.copy()
    for _ in range(round(period / 2.0 / dt)):  # half a period, undamped
        swing, _ = predict(swing, cov, hover, np.eye(3), dt, 0.0, 0.0, 0.0, 0.0, w0, 0.0)
    np.testing.assert_allclose(swing[TH][:2], [-0.05, 0.04], rtol=0.02)
    assert swing[TH][2] == pytest.approx(0.3 + 0.01 * period / 2.0, rel=1e-9)
    zeta = 0.3
    for _ in range(round(60.0 / dt)):
        x, cov = predict(x, cov, hover, np.eye(3), dt, 0.0, psd, 0.0, 0.0, w0, zeta)
    stationary = psd / (4.0 * zeta * w0**3)
    assert cov[6, 6] == pytest.approx(stationary, rel=0.1)
    assert cov[7, 7] == pytest.approx(stationary, rel=0.1)
    assert cov[8, 8] > 10.0 * stationary  # yaw: constant rate, its variance keeps growing
    assert np.all(np.abs(x[TH][:2]) < 1e-3)  # damped back to level
    with pytest.raises(ConfigError, match="deck_period_s"):
        FusionConfig(deck_period_s=-1.0)


def test_the_two_component_deck_model_settles_at_the_seas_spread_and_rings_at_its_periods() -> None:
    """With the sea's two wave periods per axis, roll and pitch are fourth-order: the model's
    poles sit at those periods, and with no measurement its variance settles at the
    configured RMS (the driving noise is derived from it), roll and pitch each their own."""
    from estimation.fusion.model import N_STATE_4, deck_polynomial, predict

    config = FusionConfig(
        deck_roll_periods_s=(11.0, 4.4),
        deck_pitch_periods_s=(9.0, 4.0),
        deck_attitude_rms_deg=(3.7, 2.0),
        deck_damping_ratio=0.3,
    )
    roots = np.roots([1.0, *reversed(deck_polynomial(2 * math.pi / 11.0, 2 * math.pi / 4.4, 0.3))])
    undamped = np.sort(np.abs(roots))  # |root| of each factor is its natural frequency
    np.testing.assert_allclose(undamped[::2], [2 * math.pi / 11.0, 2 * math.pi / 4.4], rtol=1e-9)
    deck4 = config.deck4
    # the config builds each axis' model from its own periods
    assert deck4 is not None and len(deck4) == 2
    np.testing.assert_allclose(
        deck4[0][0], deck_polynomial(2 * math.pi / 11.0, 2 * math.pi / 4.4, 0.3), rtol=1e-12
    )
    np.testing.assert_allclose(
        deck4[1][0], deck_polynomial(2 * math.pi / 9.0, 2 * math.pi / 4.0, 0.3), rtol=1e-12
    )
    dt = 1.0 / 240.0
    hover = np.array([0.0, 0.0, 9.81])
    x = np.zeros(N_STATE_4)
    cov = np.eye(N_STATE_4) * 1e-10
    for _ in range(round(80.0 / dt)):
        x, cov = predict(x, cov, hover, np.eye(3), dt, 0.0, 0.001, 0.0, 0.0, deck4=deck4)
    assert math.degrees(math.sqrt(cov[6, 6])) == pytest.approx(3.7, rel=0.05)
    assert math.degrees(math.sqrt(cov[7, 7])) == pytest.approx(2.0, rel=0.05)
    assert math.sqrt(cov[15, 15]) == pytest.approx(deck4[0][2][0], rel=0.05)
    with pytest.raises(ConfigError, match="deck_pitch_periods_s"):
        FusionConfig(deck_roll_periods_s=(10.0, 4.0))
    with pytest.raises(ConfigError, match="deck_roll_periods_s"):
        FusionConfig(deck_roll_periods_s=(10.0,), deck_pitch_periods_s=(9.0, 4.0))


def _two_component_run(
    rng: np.random.Generator, config: FusionConfig, duration: float, latency_steps: int
) -> tuple[list[tuple[float, np.ndarray, list, list]], list[np.ndarray]]:
    """A hovering drone over a deck whose roll and pitch follow the fourth-order model (its
    own discretisation, driving noise and priors), seen by tight-like poses every other 50 ms
    step that arrive ``latency_steps`` steps late.  Returns the steps' inputs and truths."""
    deck4 = config.deck4
    r_wb = np.eye(3)
    g = np.array([0.0, 0.0, -9.81])
    sigma_cd = np.array([0.002, 0.002, 0.004, *np.radians([1.0, 1.0, 0.3])])
    state = np.zeros(19)
    state[0:3] = [0.05, -0.03, -2.0]
    state[6:9] = np.radians([2.0, -1.5, 20.0])
    state[9:12] = rng.normal(0.0, config.initial_rate_sigma, 3)
    state[11] = 0.0
    for i in range(2):
        state[15 + i] = rng.normal(0.0, deck4[i][2][0])
        state[17 + i] = rng.normal(0.0, deck4[i][2][1])
    steps, truths, pending = [], [], []
    t = 0.0
    for k in range(round(duration * 20)):
        samples = []
        for _ in range(RATE // 20):
            for i in range(2):
                a0, a1, a2, a3 = deck4[i][0]
                th, w, a, j = state[6 + i], state[9 + i], state[15 + i], state[17 + i]
                state[6 + i] += w * DT
                state[9 + i] += a * DT
                state[15 + i] += j * DT
                state[17 + i] += -(a0 * th + a1 * w + a2 * a + a3 * j) * DT
                state[17 + i] += math.sqrt(deck4[i][1] * DT) * rng.standard_normal()
            t = round(t + DT, 12)
            samples.append(ImuSample(t, r_wb.T @ (-g), np.zeros(3)))
        truths.append(state.copy())
        frame = Frame(t, r_wb, samples, state[:15].copy(), None)
        if k % 2 == 0:
            pending.append((k + latency_steps, _as_tight(frame, rng, sigma_cd)))
        due = [pose for when, pose in pending if when <= k]
        pending = [(when, pose) for when, pose in pending if when > k]
        steps.append((t, r_wb, samples, due))
    return steps, truths


def test_the_two_component_deck_model_is_consistent_and_carries_late_poses_forward() -> None:
    """On a deck whose roll and pitch move as the fourth-order model says, with poses 200 ms
    late, the NEES of those eight states (angles, rates, accelerations, jerks) stays in its
    chi² band, and the present roll/pitch error is well below what constant Euler rates give
    on the same data."""
    deck = np.array([6, 7, 9, 10, 15, 16, 17, 18])
    base = {"gate_probability": 1.0 - 1e-12, "initial_rate_sigma": 0.05}
    config = make_config(
        sources=("tight",),
        deck_roll_periods_s=(11.0, 4.4),
        deck_pitch_periods_s=(9.0, 4.0),
        deck_attitude_rms_deg=(3.7, 3.7),
        deck_damping_ratio=0.1,
        **base,
    )
    flat = make_config(sources=("tight",), deck_angular_accel_psd=0.004, **base)
    runs = 20
    nees_end, errors, errors_flat = [], [], []
    rng = np.random.default_rng(21)
    for _ in range(runs):
        steps, truths = _two_component_run(rng, config, duration=8.0, latency_steps=4)
        fusion, other = make_fusion(config), make_fusion(flat)
        for k, (t, r_wb, samples, due) in enumerate(steps):
            fusion.step(t, r_wb, samples, None, due)
            other.step(t, r_wb, samples, None, due)
            if k >= 60:
                errors.append(np.abs(wrap_angle(fusion.state[TH][:2] - truths[k][6:8])))
                errors_flat.append(np.abs(wrap_angle(other.state[TH][:2] - truths[k][6:8])))
        error = truths[-1] - fusion.state
        error[TH] = wrap_angle(error[TH])
        block = fusion.covariance[np.ix_(deck, deck)]
        nees_end.append(float(error[deck] @ np.linalg.solve(block, error[deck])))
    low, high = chi2.ppf([0.025, 0.975], runs * len(deck)) / runs
    assert low <= float(np.mean(nees_end)) <= high, np.mean(nees_end)
    assert np.mean(errors) < 0.8 * np.mean(errors_flat), (np.mean(errors), np.mean(errors_flat))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    periods=st.lists(st.floats(-1.0, 2e3) | st.just(math.nan), min_size=0, max_size=3),
    zeta=st.floats(0.0, 10.0),
    rms=st.floats(-1.0, 200.0) | st.just(math.nan),
)
def test_fuzzed_wave_components_are_refused_naming_their_key_or_never_raise(
    periods: list[float], zeta: float, rms: float
) -> None:
    """Any wave periods, damping and RMS: a ConfigError naming the key, or a filter that steps
    through delayed poses without raising and gives finite or invalid estimates."""
    try:
        config = make_config(
            sources=("tight",),
            deck_roll_periods_s=tuple(periods),
            deck_pitch_periods_s=tuple(reversed(periods)),
            deck_attitude_rms_deg=(rms, 3.0),
            deck_damping_ratio=zeta,
        )
    except ConfigError as error:
        assert error.key in {
            "deck_roll_periods_s",
            "deck_pitch_periods_s",
            "deck_attitude_rms_deg",
            "deck_damping_ratio",
        }, error
        return
    fusion = make_fusion(config)
    rng = np.random.default_rng(0)
    sigma_cd = np.array([0.002, 0.002, 0.004, *np.radians([1.0, 1.0, 0.3])])
    late = []
    for frame in synthetic_run(rng, config, duration=1.0, pose_every=1):
        estimate = fusion.step(frame.time, frame.r_wb, frame.imu, None, late)
        late = [_as_tight(frame, rng, sigma_cd)]
        if estimate.valid:
            assert np.all(np.isfinite(estimate.translation))


def test_the_tof_sensors_sit_at_the_camera_plus_their_mounts_turned_into_the_body() -> None:
    mounts_c = np.array([[0.02, 0.01, 0.0], [-0.03, 0.015, 0.005]])
    fusion = DeckFusion(make_config(use_tof=True), mounts_c.ravel().tolist(), [0.01, 0.0, -0.03])
    expected = np.array([[0.01, 0.0, -0.03] + R_BC @ mount for mount in mounts_c])
    np.testing.assert_allclose(fusion.tof_origins_b, expected, rtol=0, atol=1e-15)


def test_the_filters_identifier_and_states_follow_the_identification_and_tilt_settings() -> None:
    """The identifier takes each identification setting (and there is none without the
    identification, or with wave periods given); the coloured tilt errors add two states
    only with both a correlation time and a share."""
    config = make_config(
        identify_deck_motion=True,
        identify_window_s=60.0,
        identify_sample_s=0.25,
        identify_min_window_s=12.0,
        identify_refit_s=3.0,
        identify_period_range_s=(3.0, 25.0),
        identify_damping_range=(0.04, 1.5),
        identify_noise_gain=1.5,
        identify_ar_order=6,
    )
    identifier = make_fusion(config).identifier
    assert identifier is not None
    assert (
        identifier.window_s,
        identifier.sample_s,
        identifier.min_window_s,
        identifier.refit_s,
        identifier.period_range_s,
        identifier.damping_range,
        identifier.noise_gain,
        identifier.order,
    ) == (60.0, 0.25, 12.0, 3.0, (3.0, 25.0), (0.04, 1.5), 1.5, 6)
    # no identifier when the motion is not identified, or when wave periods are given
    assert make_fusion(make_config(identify_deck_motion=False)).identifier is None
    prior = make_config(
        identify_deck_motion=True, deck_roll_periods_s=(11.0, 4.4), deck_pitch_periods_s=(9.0, 4.0)
    )
    assert make_fusion(prior).identifier is None
    for correlation_s, share, n in ((0.3, 0.0, N_STATE), (0.0, 0.5, N_STATE), (0.3, 0.5, 17)):
        config = make_config(
            tilt_error_correlation_s=correlation_s, tilt_error_coloured_share=share
        )
        assert make_fusion(config).state.shape == (n,)


def test_a_new_filter_is_not_initialised_and_knows_only_the_accelerometer_bias_prior() -> None:
    config = make_config(initial_accel_bias_sigma=0.07)
    fusion = make_fusion(config)
    expected = np.zeros((N_STATE, N_STATE))
    expected[12:15, 12:15] = 0.07**2 * np.eye(3)
    np.testing.assert_array_equal(fusion.state, np.zeros(N_STATE))
    np.testing.assert_allclose(fusion.covariance, expected, rtol=1e-15, atol=0)
    estimate = fusion.step(0.2, np.eye(3))
    assert estimate.valid is False and estimate.reason == "fusion_not_initialised"
    assert estimate.method == "fused" and estimate.timestamp == 0.2
    assert estimate.extras == {"resets": 0, "initialised": False, "since_pose_s": math.inf}


def _pose(method: str, time: float, **extra: object) -> DeckPoseEstimate:
    """A pose of a deck 1.8 m below a camera, a little off centre, turned and tilted."""
    return DeckPoseEstimate(
        method,
        time,
        True,
        matrix_from_euler_zyx(0.05, -0.03, 0.4),
        np.array([0.1, -0.2, 1.8]),
        **extra,  # type: ignore[arg-type]
    )


@pytest.mark.parametrize(
    ("stamp", "nearest"),
    [(-0.05, 0), (0.04, 0), (0.06, 1), (0.1, 1), (0.149, 1), (0.151, 2), (0.3, 3), (0.32, 3)],
)
def test_a_pose_is_taken_with_the_drones_attitude_nearest_its_stamp(
    stamp: float, nearest: int
) -> None:
    """The drone turns between steps 0.1 s apart; a pose delivered late (or stamped a little
    after the latest step) is placed with the attitude of the step nearest its stamp."""
    fusion = make_fusion(make_config(horizon_s=1.0))
    attitudes = [matrix_from_euler_zyx(0.1 * k, -0.05 * k, 0.3 * k) for k in range(4)]
    for k, r_wb in enumerate(attitudes):
        pose = _pose("atda", stamp)
        fusion.step(0.1 * k, r_wb, (), None, [pose] if k == 3 else [])
    z, _ = pose_measurement(pose, attitudes[nearest], T_BC)
    np.testing.assert_allclose(fusion.state[[0, 1, 2, 6, 7, 8]], z, rtol=0, atol=1e-12)


def test_the_last_attitude_before_the_horizon_is_kept_while_it_is_the_nearest_to_a_pose() -> None:
    """Steps at 0, 0.1, 0.7, 0.98 and 1 s, a horizon of 0.25 s: a pose stamped 0.78 s
    (inside the horizon) is nearer the attitude of 0.7 s (outside it) than that of 0.98 s."""
    fusion = make_fusion(make_config(horizon_s=0.25))
    times = (0.0, 0.1, 0.7, 0.98, 1.0)
    attitudes = [matrix_from_euler_zyx(0.1 * k, -0.05 * k, 0.3 * k) for k in range(5)]
    pose = _pose("atda", 0.78)
    for k, (time, r_wb) in enumerate(zip(times, attitudes, strict=True)):
        fusion.step(time, r_wb, (), None, [pose] if k == 4 else [])
    z, _ = pose_measurement(pose, attitudes[2], T_BC)
    np.testing.assert_allclose(fusion.state[[0, 1, 2, 6, 7, 8]], z, rtol=0, atol=1e-12)


def _jacobian_of_the_pose(estimate: DeckPoseEstimate, r_wb: np.ndarray) -> np.ndarray:
    """d(p, th)/d(x, y, z, roll, pitch, yaw of T_CD) by central differences of 1e-5."""
    base = np.concatenate([estimate.translation, euler_zyx_from_matrix(estimate.rotation)])
    columns = []
    for k in range(6):
        delta = np.zeros(6)
        delta[k] = 1e-5
        values = []
        for sign in (1.0, -1.0):
            moved = base + sign * delta
            changed = DeckPoseEstimate(
                "tight", 0.0, True, matrix_from_euler_zyx(*moved[3:]), moved[:3]
            )
            values.append(pose_measurement(changed, r_wb, T_BC)[0])
        columns.append(wrap_angle(values[0] - values[1]) / 2e-5)
    return np.column_stack(columns)


@pytest.mark.parametrize("coloured", [False, True], ids=["white", "coloured"])
@pytest.mark.parametrize("source", ["atda", "ihrcf", "tight"])
def test_the_first_pose_starts_the_state_at_its_measurement_with_its_noise_and_the_priors(
    source: str, coloured: bool
) -> None:
    """The first pose sets the relative position and the deck's angles to what it measures,
    with its noise (fixed sigmas in the camera frame turned into W, or the source's own
    covariance through the measurement's Jacobian; roll and pitch times
    tilt_error_sigma_scale), and a component the source does not give wide open (1 m along
    the camera's z, 0.5 rad); velocity, rates and the accelerometer bias start at their
    priors; the coloured errors at unit variance, anticorrelated with the tilt they were
    measured in."""
    tilt = {"tilt_error_correlation_s": 0.3, "tilt_error_coloured_share": 0.6} if coloured else {}
    config = make_config(
        sources=(source,),
        tilt_error_sigma_scale=2.0,
        initial_velocity_sigma=0.4,
        initial_rate_sigma=0.1,
        initial_accel_bias_sigma=0.03,
        **tilt,
    )
    r_wb = matrix_from_euler_zyx(0.1, -0.2, 0.7)  # tilted: the camera's z is not W's
    root = np.random.default_rng(4).normal(0.0, 0.01, (6, 6))
    own = root @ root.T + np.diag([1e-6, 1e-6, 4e-6, 1e-4, 1e-4, 1e-5])
    extra = {"covariance": own} if source == "tight" else {}
    pose = _pose(source, 0.0, **extra)
    fusion = make_fusion(config)
    fusion.step(0.0, r_wb, (), None, [pose])
    z, r_wc = pose_measurement(pose, r_wb, T_BC)
    n = N_STATE + (N_COLOURED if coloured else 0)
    expected_x = np.zeros(n)
    expected_x[[0, 1, 2, 6, 7, 8]] = z
    np.testing.assert_allclose(fusion.state, expected_x, rtol=0, atol=1e-15)
    if source == "tight":
        jac = _jacobian_of_the_pose(pose, r_wb)
        noise = jac @ own @ jac.T
    else:
        sigma = np.array(config.pose_sigma(source))
        given = np.isfinite(sigma)
        sigma = np.where(given, sigma, 1.0)
        noise = np.zeros((6, 6))
        noise[:3, :3] = r_wc @ np.diag(sigma[:3] ** 2) @ r_wc.T
        noise[3:, 3:] = np.diag(np.radians(sigma[3:]) ** 2)
    scale = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 1.0])
    noise = noise * np.outer(scale, scale)
    expected = np.zeros((n, n))
    expected[0:3, 0:3] = noise[:3, :3]
    expected[6:9, 6:9] = noise[3:, 3:]
    if source == "ihrcf":  # z (1 m along the camera's z, above), roll and pitch not given
        for i, wide in ((6, 0.25), (7, 0.25)):
            expected[i, :] = expected[:, i] = 0.0
            expected[i, i] = wide
    expected[3:6, 3:6] = 0.4**2 * np.eye(3)
    expected[9:12, 9:12] = 0.1**2 * np.eye(3)
    expected[12:15, 12:15] = 0.03**2 * np.eye(3)
    if coloured:
        expected[15:, 15:] = np.eye(2)
        if source != "ihrcf":
            gain = math.sqrt(0.6) * np.linalg.cholesky(noise[3:5, 3:5])
            expected[6:8, 15:] = -gain
            expected[15:, 6:8] = -gain.T
    np.testing.assert_allclose(fusion.covariance, expected, rtol=1e-6, atol=1e-14)
    diagnostics = fusion.diagnostics()
    assert diagnostics[f"{source}_initialised"] == 1
    # nothing was innovated: no NIS
    assert not any(key.startswith("nis") for key in diagnostics)


@pytest.mark.parametrize(
    "overrides",
    [
        {},
        {
            "deck_period_s": 9.0,
            "deck_damping_ratio": 0.2,
            "tilt_error_correlation_s": 0.3,
            "tilt_error_coloured_share": 0.6,
        },
        {
            "deck_roll_periods_s": (11.0, 4.4),
            "deck_pitch_periods_s": (9.0, 4.0),
            "deck_damping_ratio": 0.3,
        },
        {"tilt_error_correlation_s": 0.3, "tilt_error_coloured_share": 0.0},
    ],
    ids=["constant-rates", "oscillator-and-coloured-errors", "wave-periods", "no-coloured-share"],
)
def test_between_poses_each_imu_sample_is_predicted_with_the_attitude_the_gyro_turns_it_to(
    overrides: dict[str, object],
) -> None:
    """After the first pose, each IMU sample is one prediction of the model over the time
    since the sample (or event) before it, with its specific force and the drone's attitude
    at the sample: the attitude given at the previous step turned by each gyro sample over
    its interval (the attitude given with the samples is where the next step starts)."""
    config = make_config(**overrides)
    fusion = make_fusion(config)
    start = matrix_from_euler_zyx(0.1, -0.05, 0.6)
    fusion.step(0.0, start, (), None, [_pose("atda", 0.0)])
    x, cov = fusion.state, fusion.covariance
    r_wb, previous = start, 0.0
    rng = np.random.default_rng(8)
    for step, (t_end, ends) in enumerate(
        ((0.05, matrix_from_euler_zyx(0.12, -0.04, 0.62)), (0.08, np.eye(3)))
    ):
        times = [0.01, 0.02, 0.03, 0.04, 0.05] if step == 0 else [0.065, 0.08]
        samples = [
            ImuSample(
                t, np.array([0.3, -0.2, 9.9]) + rng.normal(0.0, 0.2, 3), rng.normal(0, 0.5, 3)
            )
            for t in times
        ]
        for sample in samples:
            dt = sample.timestamp - previous
            r_wb = r_wb @ Rotation.from_rotvec(sample.gyro * dt).as_matrix()
            x, cov = predict(
                x,
                cov,
                sample.accel,
                r_wb,
                dt,
                config.deck_accel_psd,
                config.deck_angular_accel_psd,
                config.accel_noise_density,
                config.accel_bias_random_walk,
                config.deck_w0,
                config.deck_damping_ratio,
                config.deck4,
                # no coloured states without a share: nothing decays as one
                config.tilt_error_correlation_s if config.tilt_error_coloured_share else 0.0,
            )
            previous = sample.timestamp
        estimate = fusion.step(t_end, ends, samples)
        r_wb = ends
        np.testing.assert_allclose(fusion.state, x, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(fusion.covariance, cov, rtol=1e-12, atol=1e-18)
    assert estimate.valid and not estimate.predicted


def _pose_noise(config: FusionConfig, source: str, r_wc: np.ndarray) -> np.ndarray:
    """A fixed-sigma source's pose noise in the state's axes (a component not given: 1)."""
    sigma = np.array(config.pose_sigma(source))
    sigma = np.where(np.isfinite(sigma), sigma, 1.0)  # a component not given: unused
    noise = np.zeros((6, 6))
    noise[:3, :3] = r_wc @ np.diag(sigma[:3] ** 2) @ r_wc.T
    noise[3:, 3:] = np.diag(np.radians(sigma[3:]) ** 2)
    scale = np.array([1.0, 1.0, 1.0, *(config.tilt_error_sigma_scale,) * 2, 1.0])
    return noise * np.outer(scale, scale)


@pytest.mark.parametrize("coloured", [False, True], ids=["white", "coloured"])
def test_a_pose_update_is_the_textbook_kalman_update_of_the_pose_and_its_coloured_tilt(
    coloured: bool,
) -> None:
    """A second pose at the first one's time: the Kalman update of H = [I on (p, th)] (plus,
    with coloured errors, the unit coloured states through the Cholesky factor of the tilt
    noise times the square root of their share, the white rest of the noise scaled by the
    square root of one less the share), its NIS and its roll/pitch NIS; with white errors
    and equal noise it lands half way between the two poses with half their variance."""
    tilt = {"tilt_error_correlation_s": 0.3, "tilt_error_coloured_share": 0.6} if coloured else {}
    config = make_config(tilt_error_sigma_scale=1.3, **tilt)
    fusion = make_fusion(config)
    r_wb = matrix_from_euler_zyx(0.1, -0.2, 0.7)
    first = _pose("atda", 0.0)
    second = DeckPoseEstimate(
        "atda",
        0.0,
        True,
        matrix_from_euler_zyx(0.07, -0.04, 0.403),
        first.translation + np.array([0.002, -0.001, 0.004]),
    )
    fusion.step(0.0, r_wb, (), None, [first])
    x, cov = fusion.state, fusion.covariance
    fusion.step(0.0, r_wb, (), None, [second])
    z1, r_wc = pose_measurement(first, r_wb, T_BC)
    z2, _ = pose_measurement(second, r_wb, T_BC)
    noise = _pose_noise(config, "atda", r_wc)
    n = x.shape[0]
    h = np.zeros((6, n))
    h[0:3, 0:3] = np.eye(3)
    h[3:6, 6:9] = np.eye(3)
    if coloured:
        gain = math.sqrt(0.6) * np.linalg.cholesky(noise[3:5, 3:5])
        h[3:5, 15:17] = gain
        white = np.array([1.0, 1.0, 1.0, math.sqrt(0.4), math.sqrt(0.4), 1.0])
        noise = noise * np.outer(white, white)
    innovation = z2 - h @ x
    s = h @ cov @ h.T + noise
    k = cov @ h.T @ np.linalg.inv(s)
    np.testing.assert_allclose(fusion.state, x + k @ innovation, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(fusion.covariance, cov - k @ s @ k.T, rtol=1e-9, atol=1e-15)
    diagnostics = fusion.diagnostics()
    assert diagnostics["atda_initialised"] == 1 and diagnostics["atda_accepted"] == 1
    nis = innovation @ np.linalg.solve(s, innovation)
    nis_tilt = innovation[3:5] @ np.linalg.solve(s[3:5, 3:5], innovation[3:5])
    assert diagnostics["nis_atda"] == pytest.approx(nis, rel=1e-9)
    assert diagnostics["nis_tilt_atda"] == pytest.approx(nis_tilt, rel=1e-9)
    if not coloured:
        np.testing.assert_allclose(fusion.state[[0, 1, 2, 6, 7, 8]], 0.5 * (z1 + z2), atol=1e-12)
        block = fusion.covariance[np.ix_([0, 1, 2, 6, 7, 8], [0, 1, 2, 6, 7, 8])]
        np.testing.assert_allclose(block, 0.5 * noise, rtol=1e-9, atol=1e-18)


def test_the_estimate_is_the_state_as_the_pose_of_the_deck_in_the_camera_and_says_its_age() -> None:
    """Estimated at the attitude of the first pose, the fused T_CD is that pose, and its
    covariance that pose's own (translation and angles; carried into the state and back
    through the two Jacobians); beyond horizon_s since the last pose it is predicted, and
    beyond reset_timeout_s it is no estimate (fusion_timed_out)."""
    config = make_config(sources=("tight",), horizon_s=0.5, reset_timeout_s=1.0)
    fusion = make_fusion(config)
    r_wb = matrix_from_euler_zyx(0.1, -0.2, 0.7)
    root = np.random.default_rng(6).normal(0.0, 0.01, (6, 6))
    own = root @ root.T + np.diag([1e-6, 1e-6, 4e-6, 1e-4, 1e-4, 1e-5])
    pose = _pose("tight", 0.25, covariance=own)
    fusion.step(0.25, r_wb, (), None, [pose])
    estimate = fusion.estimate(0.25, r_wb)
    assert estimate.valid is True and estimate.method == "fused" and estimate.timestamp == 0.25
    np.testing.assert_allclose(estimate.translation, pose.translation, rtol=0, atol=1e-12)
    np.testing.assert_allclose(estimate.rotation, pose.rotation, rtol=0, atol=1e-12)
    assert estimate.covariance is not None and estimate.covariance.shape == (6, 6)
    for block in (slice(0, 3), slice(3, 6)):
        np.testing.assert_allclose(
            estimate.covariance[block, block], own[block, block], rtol=1e-6, atol=1e-13
        )
    assert estimate.extras["initialised"] is True and estimate.extras["since_pose_s"] == 0.0
    for time, predicted in ((0.75, False), (0.7500001, True), (1.25, True)):
        later = fusion.estimate(time, r_wb)
        assert later.valid is True and later.predicted is predicted and later.timestamp == time
    late = fusion.estimate(1.2500001, r_wb)
    assert late.valid is False and late.reason == "fusion_timed_out"
    assert late.method == "fused" and late.timestamp == 1.2500001 and late.extras["initialised"]


def _imu(times: list[float]) -> list[ImuSample]:
    """Hovering samples (level drone at rest) at these times."""
    return [ImuSample(t, np.array([0.0, 0.0, 9.81]), np.zeros(3)) for t in times]


def test_the_filter_resets_after_more_than_reset_timeout_s_and_restarts_keeping_the_bias() -> None:
    """At exactly reset_timeout_s after the last pose the filter still runs; after it, it
    resets (counted once, fusion_reset); the next pose starts it afresh with the velocity's
    prior but the accelerometer bias' estimate and covariance as they were."""
    config = make_config(reset_timeout_s=0.375, horizon_s=0.2)
    fusion = make_fusion(config)
    level = np.eye(3)
    fusion.step(0.0, level, (), None, [_pose("atda", 0.0)])
    moved = DeckPoseEstimate(
        "atda", 0.125, True, _pose("atda", 0.0).rotation, np.array([0.104, -0.197, 1.805])
    )
    fusion.step(0.125, level, _imu([0.0625, 0.125]), None, [moved])
    estimate = fusion.step(0.5, level, _imu([0.25, 0.5]))
    assert estimate.valid and fusion.initialised
    bias, bias_cov = fusion.state[12:15], fusion.covariance[12:15, 12:15]
    assert np.all(bias != 0.0)
    estimate = fusion.step(0.5625, level, _imu([0.5625]))
    assert not estimate.valid and estimate.reason == "fusion_reset"
    assert fusion.diagnostics()["resets"] == 1 and fusion.diagnostics()["initialised"] is False
    estimate = fusion.step(0.625, level, _imu([0.625]), None, [_pose("atda", 0.625)])
    assert estimate.valid and fusion.diagnostics()["atda_initialised"] == 2
    np.testing.assert_array_equal(fusion.state[12:15], bias)
    np.testing.assert_array_equal(fusion.covariance[12:15, 12:15], bias_cov)
    np.testing.assert_array_equal(fusion.state[3:6], np.zeros(3))
    np.testing.assert_allclose(fusion.covariance[3:6, 3:6], 0.3**2 * np.eye(3), rtol=1e-15)
    assert fusion.diagnostics()["resets"] == 1


def test_tof_ranges_are_fused_one_sensor_at_a_time_each_gated_alone() -> None:
    """Each valid range is one scalar update through the ray's model, with the range's own
    sigma and the one-dimensional gate: an invalid one is skipped, one with an NIS of 13.5
    (beyond the gate of one degree of freedom, 12.1, not of two) rejected alone; the NIS is
    the mean over the sensors.  Without use_tof, or with no valid range, a reading changes
    nothing."""
    config = make_config(use_tof=True, tof_sigma_m=0.003, tof_sigma_per_m=0.0)
    r_wb = matrix_from_euler_zyx(0.05, -0.03, 0.2)
    fusion = make_fusion(config)
    fusion.step(0.0, r_wb, (), None, [_pose("atda", 0.0)])
    x, cov = fusion.state, fusion.covariance
    origins = fusion.tof_origins_b
    predicted = [tof_model(x, origin, r_wb)[0] for origin in origins]
    measured = [predicted[0] + 0.004, math.nan, predicted[2] - 0.003, math.nan]
    gate = chi2.ppf(config.gate_probability, 1)
    sigma = config.tof_noise.sigma_scalar(2.0)  # the same at every range here
    nis_values, accepted = [], []
    for k, origin in enumerate(origins):
        model, h = tof_model(x, origin, r_wb)
        if k == 3:  # the outlier: an NIS of 13.5
            measured[3] = model + math.sqrt(13.5 * (h @ cov @ h + sigma**2))
        if not math.isfinite(measured[k]):
            continue
        innovation = np.array([measured[k] - model])
        x, cov, nis, ok = ekf_update(x, cov, innovation, h[None, :], np.array([[sigma**2]]), gate)
        nis_values.append(nis)
        accepted.append(ok)
    reading = RangeReading(0.0625, np.array(measured), np.array([True, False, True, True]))
    fusion.step(0.0625, r_wb, (), reading)
    assert nis_values[2] == pytest.approx(13.5, rel=1e-9)
    assert accepted == [True, True, False]
    np.testing.assert_allclose(fusion.state, x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fusion.covariance, cov, rtol=1e-12, atol=1e-18)
    diagnostics = fusion.diagnostics()
    assert (diagnostics["tof_accepted"], diagnostics["tof_rejected"]) == (2, 1)
    assert diagnostics["nis_tof"] == pytest.approx(np.mean(nis_values), rel=1e-12)
    for use_tof, valid in ((False, [True] * 4), (True, [False] * 4)):
        other = make_fusion(make_config(use_tof=use_tof))
        other.step(0.0, r_wb, (), None, [_pose("atda", 0.0)])
        before = other.state
        other.step(0.0625, r_wb, (), RangeReading(0.0625, np.array(predicted), np.array(valid)))
        np.testing.assert_array_equal(other.state, before)
        assert not any(key.startswith(("tof", "nis_tof")) for key in other.diagnostics())


def test_a_pose_holding_its_frames_ranges_supersedes_that_frames_reading_alone() -> None:
    """A tight pose stamped at one frame, arriving a frame late, supersedes the ToF reading
    of its own frame (its ranges are in it), not the frames before or after it."""
    config = make_config(sources=("atda", "tight"), use_tof=True)
    r_wb = np.eye(3)
    fusion = make_fusion(config)
    fusion.step(0.0, r_wb, (), None, [_pose("atda", 0.0)])
    ranges = np.array([tof_model(fusion.state, o, r_wb)[0] for o in fusion.tof_origins_b])
    for time in (0.0625, 0.125, 0.1875):
        # a pose without the ranges (atda) at a reading's time leaves the reading fused
        poses = [_pose("atda", time)] if time == 0.0625 else []
        if time == 0.1875:
            poses = [_pose("tight", 0.125, extras={"ranges_used": 4})]
        fusion.step(time, r_wb, (), RangeReading(time, ranges, np.ones(4, bool)), poses)
    diagnostics = fusion.diagnostics()
    assert diagnostics["tof_superseded"] == 1
    assert diagnostics.get("tof_accepted", 0) + diagnostics.get("tof_rejected", 0) == 8
    # on time, the latest event, after an IMU sample of the same stamp: its own frame's
    # reading is superseded too
    pose = _pose("tight", 0.25, extras={"ranges_used": 4})
    fusion.step(0.25, r_wb, _imu([0.25]), RangeReading(0.25, ranges, np.ones(4, bool)), [pose])
    assert fusion.diagnostics()["tof_superseded"] == 2


class _Identifier:
    """A stand-in for the filter's identifier: keeps what it is fed and, from the second
    estimate on, hands out its own model."""

    def __init__(self, deck4: tuple) -> None:
        self.deck4, self.fed, self.resets = deck4, [], 0

    def add(self, time: float, roll: float, pitch: float) -> bool:
        self.fed.append((time, roll, pitch))
        return len(self.fed) >= 2

    def reset(self) -> None:
        self.resets += 1


def test_poses_leaving_the_buffer_feed_the_identifier_and_its_model_drives_the_prediction() -> None:
    """Each pose update, once older than the horizon (final), gives the identifier its time
    and the deck's roll and pitch after it; a refitted model drives the predictions that
    follow; a reset restarts the identifier and the initial model."""
    config = make_config(identify_deck_motion=True, horizon_s=0.25)
    fusion = make_fusion(config)
    model = (
        TwoWaves.matched(0.6, 0.1, 1.4, 0.3, 2e-3, 5e-4),
        TwoWaves.matched(0.5, 0.2, 1.7, 0.15, 1e-3, 8e-4),
    )
    stand_in = _Identifier(model)
    fusion.identifier = stand_in  # type: ignore[assignment]
    r_wb = np.eye(3)
    after = []
    for k in range(5):
        time = 0.125 * k
        pose = DeckPoseEstimate(
            "atda",
            time,
            True,
            matrix_from_euler_zyx(0.05 + 0.01 * k, -0.03 - 0.005 * k, 0.4),
            np.array([0.1, -0.2, 1.8]),
        )
        fusion.step(time, r_wb, _imu([time]) if k else (), None, [pose])
        after.append((time, *fusion.state[6:8]))
    # at 0.5 s the poses before 0.25 s have left the buffer
    np.testing.assert_allclose(np.array(stand_in.fed), np.array(after[:2]), rtol=1e-12)
    assert all(type(v) is float for v in stand_in.fed[0])
    for deck4, restart in ((model, False), (config.deck4_initial, True)):
        if restart:
            fusion.reset()
            fusion.step(0.5, r_wb, (), None, [_pose("atda", 0.5)])
        x, cov = fusion.state, fusion.covariance
        sample = ImuSample(0.5625, np.array([0.1, -0.1, 9.9]), np.zeros(3))
        fusion.step(0.5625, r_wb, [sample])
        expected = predict(
            x, cov, sample.accel, r_wb, 0.0625, config.deck_accel_psd,
            config.deck_angular_accel_psd, config.accel_noise_density,
            config.accel_bias_random_walk, deck4=deck4,
            tilt_correlation_s=config.tilt_error_correlation_s,
        )  # fmt: skip
        np.testing.assert_allclose(fusion.state, expected[0], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(fusion.covariance, expected[1], rtol=1e-12, atol=1e-18)
    assert stand_in.resets == 1


@pytest.mark.parametrize("model", ["identified", "wave-periods"])
def test_with_a_deck_model_its_extra_states_start_at_the_seas_stationary_spread(
    model: str,
) -> None:
    """The first pose starts the second wave component's angle and rate (the identified
    two-oscillator model) or the deck's angular acceleration and jerk (the fourth-order
    model of given wave periods) at their stationary sigmas, roll's and pitch's each."""
    if model == "identified":
        config = make_config(identify_deck_motion=True, deck_attitude_rms_deg=(3.0, 2.0))
        deck4 = config.deck4_initial
        sigmas = [waves.second_sigmas for waves in deck4]
    else:
        config = make_config(
            deck_roll_periods_s=(11.0, 4.4),
            deck_pitch_periods_s=(9.0, 4.0),
            deck_attitude_rms_deg=(3.0, 2.0),
        )
        sigmas = [axis[2] for axis in config.deck4]
    fusion = make_fusion(config)
    fusion.step(0.0, np.eye(3), (), None, [_pose("atda", 0.0)])
    cov = fusion.covariance
    assert cov.shape == (N_STATE_4, N_STATE_4)
    np.testing.assert_allclose(np.diag(cov)[15:19], [s[i] ** 2 for i in (0, 1) for s in sigmas])
    np.testing.assert_array_equal(cov[15:19, :15], np.zeros((4, 15)))
    np.testing.assert_array_equal(cov[15:19, 15:19], np.diag(np.diag(cov)[15:19]))


def test_the_gyro_turns_the_attitude_from_the_latest_event_in_the_buffer() -> None:
    """A step's first IMU sample is turned by the gyro over the time since the latest event
    in the buffer: here the previous step's ToF reading, after that step's last sample."""
    config = make_config(use_tof=True)
    fusion = make_fusion(config)
    level = np.eye(3)
    fusion.step(0.0, level, (), None, [_pose("atda", 0.0)])
    ranges = np.array([tof_model(fusion.state, o, level)[0] for o in fusion.tof_origins_b])
    fusion.step(0.05, level, _imu([0.02, 0.04]), RangeReading(0.05, ranges, np.ones(4, bool)))
    x, cov = fusion.state, fusion.covariance
    gyro = np.array([0.5, -0.3, 0.8])
    sample = ImuSample(0.07, np.array([0.2, 0.1, 9.6]), gyro)
    fusion.step(0.07, level, [sample])
    r_wb = Rotation.from_rotvec(gyro * 0.02).as_matrix()
    # the prediction itself runs from the last prediction (the sample at 0.04 s)
    expected = predict(
        x, cov, sample.accel, r_wb, 0.07 - 0.04, config.deck_accel_psd,
        config.deck_angular_accel_psd, config.accel_noise_density,
        config.accel_bias_random_walk,
    )  # fmt: skip
    np.testing.assert_allclose(fusion.state, expected[0], rtol=1e-12, atol=1e-15)


def test_poses_not_fused_are_dropped_and_those_older_than_the_horizon_counted() -> None:
    """A pose of a source the filter does not fuse, or an invalid one, is dropped; one older
    than horizon_s is counted as too old (each one), even before anything has left the
    buffer; one exactly horizon_s old is fused."""
    fusion = make_fusion(make_config(horizon_s=0.5))
    attitudes = [matrix_from_euler_zyx(0.0, 0.0, 0.2 * k) for k in range(3)]
    for k in range(2):
        fusion.step(0.5 * k, attitudes[k])
    poses = [
        _pose("crhf", 1.0),
        DeckPoseEstimate.invalid("atda", 1.0, "no tag"),
        _pose("atda", 0.49),
        _pose("atda", 0.3),
    ]
    fusion.step(1.0, attitudes[2], (), None, poses)
    assert fusion.diagnostics() == {
        "atda_too_old": 2,
        "resets": 0,
        "initialised": False,
        "since_pose_s": math.inf,
    }
    fusion.step(1.0, attitudes[2], (), None, [_pose("atda", 0.5)])
    assert fusion.initialised and fusion.diagnostics()["atda_too_old"] == 2
    z, _ = pose_measurement(_pose("atda", 0.5), attitudes[1], T_BC)
    np.testing.assert_allclose(fusion.state[[0, 1, 2, 6, 7, 8]], z, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "covariance",
    [np.eye(3) * 1e-4, np.full((6, 6), np.nan), None],
    ids=["not-6x6", "not-finite", "none"],
)
def test_a_covariance_source_without_a_finite_6x6_covariance_is_fused_with_its_sigmas(
    covariance: np.ndarray | None,
) -> None:
    config = make_config(sources=("tight",))
    r_wb = matrix_from_euler_zyx(0.1, -0.2, 0.7)
    fusion = make_fusion(config)
    fusion.step(0.0, r_wb, (), None, [_pose("tight", 0.0, covariance=covariance)])
    _, r_wc = pose_measurement(_pose("tight", 0.0), r_wb, T_BC)
    noise = _pose_noise(config, "tight", r_wc)
    np.testing.assert_allclose(fusion.covariance[0:3, 0:3], noise[:3, :3], rtol=1e-12)
    np.testing.assert_allclose(fusion.covariance[6:9, 6:9], noise[3:, 3:], rtol=1e-12)


def test_a_late_pose_within_the_horizon_is_fused_before_the_newer_events() -> None:
    """Only the events older than now - horizon_s leave the buffer: a pose delivered late,
    stamped inside the horizon but before newer IMU samples, is fused at its time."""
    fusion = make_fusion(make_config(horizon_s=0.15))
    level = np.eye(3)
    fusion.step(0.0, level, (), None, [_pose("atda", 0.0)])
    for time in (0.1, 0.2, 0.3, 0.4):
        fusion.step(time, level, _imu([time]))
    late = DeckPoseEstimate(
        "atda", 0.27, True, _pose("atda", 0.0).rotation, np.array([0.1, -0.2, 1.8])
    )
    fusion.step(0.41, level, _imu([0.41]), None, [late])
    diagnostics = fusion.diagnostics()
    assert diagnostics.get("atda_too_old", 0) == 0 and diagnostics["atda_accepted"] == 1


def test_the_first_steps_samples_turn_from_its_own_attitude_the_first_by_nothing() -> None:
    """A filter's first step brings a pose and IMU samples after it: the attitude starts at
    the one given with the step, the first sample turns it by nothing (no event before it),
    and each sample after the pose is a prediction."""
    config = make_config()
    start = matrix_from_euler_zyx(0.1, -0.05, 0.6)
    gyro = np.array([0.4, -0.2, 0.6])
    samples = [ImuSample(t, np.array([0.3, -0.2, 9.9]), gyro) for t in (0.01, 0.02)]
    fusion = make_fusion(config)
    fusion.step(0.02, start, samples, None, [_pose("atda", 0.0)])
    twin = make_fusion(config)
    twin.step(0.0, start, (), None, [_pose("atda", 0.0)])
    x, cov = twin.state, twin.covariance
    for sample, r_wb in (
        (samples[0], start),
        (samples[1], start @ Rotation.from_rotvec(gyro * 0.01).as_matrix()),
    ):
        x, cov = predict(
            x, cov, sample.accel, r_wb, 0.01, config.deck_accel_psd,
            config.deck_angular_accel_psd, config.accel_noise_density,
            config.accel_bias_random_walk,
        )  # fmt: skip
    np.testing.assert_allclose(fusion.state, x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fusion.covariance, cov, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize(
    "sigma",
    [
        (0.003, 0.003, 0.008, 2.0, 2.0, 0.5),
        (0.003, 0.003, 0.008, 2.0, 2.0, math.inf),
        (0.003, 0.003, 0.008, math.inf, 2.0, 0.5),
        (0.003, 0.003, 0.008, 2.0, math.inf, 0.5),
    ],
    ids=["all-given", "no-yaw", "no-roll", "no-pitch"],
)
def test_the_coloured_tilt_errors_enter_with_a_poses_roll_and_pitch_both_and_carry_over(
    sigma: tuple[float, ...],
) -> None:
    """Only a pose giving both roll and pitch starts the coloured errors anticorrelated with
    its tilt and sees them in its update (and has a roll/pitch NIS); each later update, after
    a prediction, is the textbook one of the components given, the coloured states as the
    updates before left them."""
    config = make_config(
        atda_sigma=sigma,
        tilt_error_sigma_scale=1.3,
        tilt_error_correlation_s=0.3,
        tilt_error_coloured_share=0.6,
    )
    mask = np.isfinite(np.array(sigma))
    both = bool(mask[3] and mask[4])
    fusion = make_fusion(config)
    r_wb = matrix_from_euler_zyx(0.1, -0.2, 0.7)
    fusion.step(0.0, r_wb, (), None, [_pose("atda", 0.0)])
    _, r_wc = pose_measurement(_pose("atda", 0.0), r_wb, T_BC)
    noise = _pose_noise(config, "atda", r_wc)
    gain = math.sqrt(0.6) * np.linalg.cholesky(noise[3:5, 3:5])
    np.testing.assert_allclose(
        fusion.covariance[6:8, 15:17], -gain if both else np.zeros((2, 2)), rtol=1e-12
    )
    h = np.zeros((6, 17))
    h[0:3, 0:3] = np.eye(3)
    h[3:6, 6:9] = np.eye(3)
    white = noise
    if both:
        h[3:5, 15:17] = gain
        scale = np.array([1.0, 1.0, 1.0, math.sqrt(0.4), math.sqrt(0.4), 1.0])
        white = noise * np.outer(scale, scale)
    h, white = h[mask], white[np.ix_(mask, mask)]
    for k, (tilt, shift) in enumerate(((0.02, 0.002), (-0.015, -0.001))):
        time = 0.05 * (k + 1)
        pose = DeckPoseEstimate(
            "atda",
            time,
            True,
            matrix_from_euler_zyx(0.05 + tilt, -0.03 - tilt, 0.4 + 0.1 * tilt),
            np.array([0.1 + shift, -0.2 - shift, 1.8 + shift]),
        )
        # predicted to the pose's time first: the coloured errors decay, their gain grows
        fusion.step(time, r_wb, [ImuSample(time, r_wb.T @ np.array([0, 0, 9.81]), np.zeros(3))])
        x, cov = fusion.state, fusion.covariance
        fusion.step(time, r_wb, (), None, [pose])
        z, _ = pose_measurement(pose, r_wb, T_BC)
        innovation = z[mask] - h @ x
        s = h @ cov @ h.T + white
        gain_k = cov @ h.T @ np.linalg.inv(s)
        np.testing.assert_allclose(fusion.state, x + gain_k @ innovation, rtol=1e-9, atol=1e-13)
        np.testing.assert_allclose(
            fusion.covariance, cov - gain_k @ s @ gain_k.T, rtol=1e-9, atol=1e-15
        )
        assert fusion.diagnostics()["atda_accepted"] == k + 1
        assert ("nis_tilt_atda" in fusion.diagnostics()) is both
    assert bool(np.all(fusion.state[15:17] != 0.0)) is both


def test_a_pose_giving_no_component_starts_every_one_wide_open() -> None:
    """1 m on each axis of the position, 0.5 rad of roll and pitch, pi of yaw."""
    fusion = make_fusion(make_config(atda_sigma=(math.inf,) * 6))
    fusion.step(0.0, np.eye(3), (), None, [_pose("atda", 0.0)])
    np.testing.assert_array_equal(
        np.diag(fusion.covariance)[[0, 1, 2, 6, 7, 8]], [1.0, 1.0, 1.0, 0.25, 0.25, math.pi**2]
    )


def test_a_tilt_noise_not_positive_definite_couples_the_coloured_errors_by_its_sigmas() -> None:
    """A source covariance whose roll/pitch block is not positive definite (a variance
    rounded below 0) has no Cholesky factor: the coloured errors then enter through the
    square roots of its roll and pitch variances, a negative one taken as 0."""
    config = make_config(
        sources=("tight",), tilt_error_correlation_s=0.3, tilt_error_coloured_share=0.6
    )
    own = np.diag([1e-6, 1e-6, 4e-6, -1e-8, 1e-4, 1e-5])
    r_wb = matrix_from_euler_zyx(0.0, 0.0, 0.7)
    fusion = make_fusion(config)
    fusion.step(0.0, r_wb, (), None, [_pose("tight", 0.0, covariance=own)])
    tilt = fusion.covariance[6:8, 6:8]  # the pose's tilt noise, as it starts
    assert np.min(np.linalg.eigvalsh(tilt)) < 0.0
    gain = math.sqrt(0.6) * np.diag(np.sqrt(np.clip(np.diag(tilt), 0.0, None)))
    np.testing.assert_allclose(fusion.covariance[6:8, 15:17], -gain, rtol=1e-9, atol=1e-15)


def test_of_two_poses_stamped_alike_the_one_delivered_first_is_fused_first() -> None:
    """The first initialises the filter; an outlier delivered after it is gated out, not
    the other way round."""
    fusion = make_fusion(make_config())
    good = _pose("atda", 0.0)
    outlier = DeckPoseEstimate(
        "atda", 0.0, True, good.rotation, good.translation + np.array([0.0, 0.0, 0.3])
    )
    fusion.step(0.0, np.eye(3), (), None, [good, outlier])
    z, _ = pose_measurement(good, np.eye(3), T_BC)
    np.testing.assert_allclose(fusion.state[[0, 1, 2, 6, 7, 8]], z, rtol=0, atol=1e-12)
    assert fusion.diagnostics()["atda_rejected"] == 1


def test_each_ray_that_misses_the_deck_is_counted_rejected() -> None:
    """Rolled 80 degrees, every ray grazes the deck plane (beyond 78.5 degrees of incidence):
    no update, and each of the four readings counted as rejected."""
    fusion = make_fusion(make_config(use_tof=True))
    fusion.step(0.0, np.eye(3), (), None, [_pose("atda", 0.0)])
    before = fusion.state
    rolled = matrix_from_euler_zyx(math.radians(80.0), 0.0, 0.0)
    reading = RangeReading(0.0625, np.full(4, 2.0), np.ones(4, bool))
    fusion.step(0.0625, rolled, (), reading)
    np.testing.assert_allclose(fusion.state, before, rtol=0, atol=1e-15)  # angles re-wrapped
    diagnostics = fusion.diagnostics()
    assert diagnostics["tof_rejected"] == 4 and "tof_accepted" not in diagnostics
