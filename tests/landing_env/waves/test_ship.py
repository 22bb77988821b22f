"""The full-scale ship deck: JONSWAP sea, vessel RAOs, helideck lever arm, the deck mount."""

from __future__ import annotations

import math
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar
from scipy.signal import welch
from scipy.spatial.transform import Rotation

import landing_env  # noqa: F401  (registers the environments)
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.waves.generator import SeaGeneratorConfig
from landing_env.waves.ship import ShipMotion, ShipMotionConfig, helideck_poses, vessel_raos
from landing_env.waves.spectrum import WaveComponents, dnv_gamma, jonswap_shape
from tests.landing_env.waves.regular import regular_ship


def test_dnv_gamma_follows_the_rule_of_dnv_rp_c205() -> None:
    # Tp / sqrt(Hs) >= 5: Pierson-Moskowitz; the tabled sea states 3-6 all are
    for hs, tp in ((0.88, 7.5), (1.88, 8.8), (3.25, 9.7), (5.0, 12.4)):
        assert dnv_gamma(hs, tp) == 1.0
    assert dnv_gamma(4.0, 8.0) == pytest.approx(math.exp(5.75 - 1.15 * 4.0))
    assert dnv_gamma(4.0, 6.0) == 5.0


@pytest.mark.parametrize(("hs", "tp", "gamma", "seed"), [(1.88, 8.8, 1.0, 0), (3.0, 7.0, 3.3, 1)])
def test_synthesised_spectrum_matches_the_target_jonswap(
    hs: float, tp: float, gamma: float, seed: int
) -> None:
    waves = WaveComponents(hs, tp, gamma, 200, (0.5, 4.0), 0.0, 0.5, np.random.default_rng(seed))
    fs = 2.0
    elevation = waves.elevation(np.arange(0.0, 3 * 3600.0, 1.0 / fs))
    f, psd = welch(elevation, fs=fs, nperseg=2048)
    m0 = float(np.sum(psd) * (f[1] - f[0]))
    assert abs(4.0 * math.sqrt(m0) / hs - 1.0) < 0.03
    # Tp: the JONSWAP shape (of this gamma, scaled to the measured m0) that fits best
    band = (f > 0.5 / tp) & (f < 4.0 / tp)

    def misfit(period: float) -> float:
        shape = jonswap_shape(f[band], period, gamma)
        shape *= m0 / float(np.sum(shape) * (f[1] - f[0]))
        return float(np.sum((shape - psd[band]) ** 2))

    fitted = minimize_scalar(misfit, bounds=(0.5 * tp, 2.0 * tp), method="bounded").x
    assert abs(fitted / tp - 1.0) < 0.05


def test_helideck_vertical_velocity_is_heave_rate_plus_lever_arm_rates() -> None:
    config = ShipMotionConfig(sea_state=4, helideck_position_m=(-10.0, 1.5, 3.0))
    source = ShipMotion(config, np.random.default_rng(3))
    times = np.arange(0.0, 600.0, 0.25)
    deck = source.velocities(times)
    vessel = source.vessel_rates(times)
    x, y, _ = config.helideck_position_m
    # pitch is nose-down positive (Euler ZYX, z up): an aft deck rises as the bow dips
    linear = vessel[:, 2] + y * vessel[:, 3] - x * vessel[:, 4]
    assert np.sqrt(np.mean((deck[:, 2] - linear) ** 2)) < 0.03 * np.std(deck[:, 2])
    # and the lever arm matters: the aft deck moves more than the centre of gravity
    assert np.std(deck[:, 2]) > 1.05 * np.std(vessel[:, 2])
    # velocities are the derivative of the poses
    h = 1e-4
    numeric = (source.poses(times + h) - source.poses(times - h)) / (2 * h)
    np.testing.assert_allclose(deck, numeric, atol=1e-6)


def test_hull_length_filters_short_waves_and_long_waves_pass() -> None:
    config = ShipMotionConfig()
    omega = np.array([0.3, 2.0 * math.pi / (0.5 * config.length_m / 1.56) ** 0.5])
    rao = vessel_raos(config, omega, np.full(2, math.pi))
    # a 685 m swell: the vessel follows the surface; a wave half its length: mostly filtered
    assert abs(rao["heave"][0]) == pytest.approx(1.0, abs=0.02)
    assert abs(rao["pitch"][0]) == pytest.approx(1.0, abs=0.02)
    assert abs(rao["heave"][1]) < 0.15
    assert abs(rao["pitch"][1]) < 0.15
    # its own periods: heave from the draught, roll from the IMO formula
    assert 3.0 < config.heave_period_s < 5.0
    assert 4.0 < config.roll_period_in_use_s < 8.0


def test_ship_deck_rms_grows_with_the_sea_state() -> None:
    times = np.arange(0.0, 1200.0, 0.2)
    rms = []
    for state in (3, 4, 5, 6):
        source = ShipMotion(ShipMotionConfig(sea_state=state), np.random.default_rng(state))
        rms.append(np.std(source.velocities(times)[:, 2]))
    assert np.all(np.diff(rms) > 0)
    # metres per second, not the bench's centimetres: STANAG 4154's 1 m/s RMS is approached
    assert 0.15 < rms[0] < 0.4 and 0.6 < rms[3] < 1.3


def test_ship_motion_needs_the_ship_mount_and_a_small_vessel() -> None:
    with pytest.raises(ConfigError, match="deck_mount"):
        load_config("default", overrides={"motion.kind": "ship"})
    with pytest.raises(ConfigError, match=r"motion\.ship\.length_m"):
        load_config("ship-ss4", overrides={"motion.ship.length_m": 80.0})
    with pytest.raises(ConfigError, match="deck_mount"):
        load_config("ship-ss4", overrides={"deck_mount": "raft"})


def test_ship_deck_moves_metres_without_legs_and_the_drone_starts_above_it() -> None:
    env = gym.make("DeckLanding-v2", config="ship-ss6")
    try:
        world = env.unwrapped.world
        assert world.stewart.cylinder_body_ids == [] and world.stewart.base_body_id == -1
        heights = []
        for seed in range(6):
            env.reset(seed=seed)
            deck = world.deck_state().position_w
            drone = world.drone_state().position_w
            # 1.8-2.2 m above where the deck is, not where it would be at rest
            assert 1.8 <= drone[2] - deck[2] <= 2.2
            assert math.hypot(*(drone[:2] - deck[:2])) <= 0.3 + 1e-9
            heights.append(deck[2] - world.deck_home_w[2])
        assert np.ptp(heights) > 0.3
        zero = np.zeros(env.action_space.shape)
        start = world.deck_state().position_w[2]
        travel = 0.0
        for _ in range(40):
            env.step(zero)
            travel = max(travel, abs(world.deck_state().position_w[2] - start))
        assert travel > 0.2  # a full-scale deck, tracked as commanded (never clamped)
        motion = world.stewart.motion
        np.testing.assert_allclose(
            world.deck_state().position_w - world.deck_home_w,
            motion.pose(world.time)[:3],
            atol=1e-6,
        )
    finally:
        env.close()


@pytest.mark.parametrize(
    "name", ["bench-ss3", "bench-ss4", "bench-ss5", "ship-ss3", "ship-ss4", "ship-ss5", "ship-ss6"]
)
def test_landing_scenarios_fly_the_drone_and_use_the_dnv_gamma(name: str) -> None:
    config = load_config(name)
    assert config.simulation.drone_fixed is False  # paper-stewart pins it; these must not
    sea = config.motion.ship if config.motion.kind == "ship" else config.motion.sea_state
    assert sea.gamma is None and sea.gamma_in_use == 1.0
    assert (config.deck_mount == "ship") == name.startswith("ship")


@settings(max_examples=25, deadline=None)
@given(
    length=st.floats(10.0, 40.0),
    beam_ratio=st.floats(0.12, 0.45),
    draught_ratio=st.floats(0.1, 0.55),
    cb=st.floats(0.3, 1.0),
    gm=st.floats(0.2, 5.0),
    direction=st.floats(-360.0, 360.0),
    state=st.sampled_from([0, 1, 2, 3, 4, 5, 6]),
    arm=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-20.0, 20.0)),
    seed=st.integers(0, 2**32 - 1),
)
def test_any_valid_vessel_moves_finitely(
    length, beam_ratio, draught_ratio, cb, gm, direction, state, arm, seed
) -> None:
    beam = beam_ratio * length
    config = ShipMotionConfig(
        sea_state=state,
        length_m=length,
        beam_m=beam,
        draught_m=max(0.2, draught_ratio * beam),
        block_coefficient=cb,
        metacentric_height_m=gm,
        wave_direction_deg=direction,
        helideck_position_m=(arm[0] * 0.5 * length, arm[1] * 0.5 * beam, arm[2]),
        n_components=40,
    )
    source = ShipMotion(config, np.random.default_rng(seed))
    times = np.linspace(0.0, 120.0, 61)
    poses, rates = source.poses(times), source.velocities(times)
    assert np.all(np.isfinite(poses)) and np.all(np.isfinite(rates))
    assert np.all(np.abs(poses[:, 2]) <= source.vertical_reach_m + 1e-9)


def test_dnv_gamma_is_5_up_to_3_6_the_exponential_between_and_1_from_5_and_for_a_calm_sea() -> None:
    # Tp / sqrt(Hs) = 3.6 and 5 exactly: each bound belongs to the constant beside it
    assert dnv_gamma(1.0, 3.6) == 5.0
    assert dnv_gamma(1.0, 5.0) == pytest.approx(1.0, abs=1e-12)
    assert dnv_gamma(4.0, 10.0) == 1.0
    # just inside the exponential branch, on both sides
    assert dnv_gamma(1.0, 3.7) == pytest.approx(math.exp(5.75 - 1.15 * 3.7), rel=1e-12)
    assert dnv_gamma(1.0, 4.9) == pytest.approx(math.exp(5.75 - 1.15 * 4.9), rel=1e-12)
    # a calm sea, Hs = 0, has no ratio: 1
    assert dnv_gamma(0.0, 3.0) == 1.0


@settings(max_examples=50, deadline=None)
@given(hs=st.floats(0.05, 16.0), phi=st.floats(3.61, 4.99))
def test_dnv_gamma_between_the_bounds_is_the_rules_exponential_of_tp_over_root_hs(
    hs: float, phi: float
) -> None:
    tp = phi * math.sqrt(hs)
    assert dnv_gamma(hs, tp) == pytest.approx(math.exp(5.75 - 1.15 * tp / math.sqrt(hs)))
    # (the rule jumps at 3.6: its exponential is 5.003 there)
    assert 1.0 < dnv_gamma(hs, tp) < 5.01


def test_a_sea_takes_the_tabled_hs_and_tp_of_its_state_unless_given_and_gamma_by_the_rule() -> None:
    tabled = ShipMotionConfig(sea_state=5)
    assert (tabled.hs, tabled.tp) == (3.25, 9.7)
    assert tabled.gamma_in_use == 1.0
    given_sea = ShipMotionConfig(sea_state=5, significant_height_m=2.0, peak_period_s=6.0)
    assert (given_sea.hs, given_sea.tp) == (2.0, 6.0)
    assert given_sea.gamma_in_use == pytest.approx(math.exp(5.75 - 1.15 * 6.0 / math.sqrt(2.0)))
    chosen = ShipMotionConfig(sea_state=None, significant_height_m=2.0, peak_period_s=6.0, gamma=3)
    assert chosen.gamma_in_use == 3.0 and isinstance(chosen.gamma_in_use, float)


def test_the_jonswap_shape_is_pierson_moskowitz_times_the_peak_factor_of_its_two_widths() -> None:
    tp = 8.0
    fp = 1.0 / tp
    # at the peak: fp^-5 exp(-5/4) times the whole gamma
    assert jonswap_shape(np.array([fp]), tp, 3.3)[0] == pytest.approx(
        fp**-5 * math.exp(-1.25) * 3.3
    )
    # Pierson-Moskowitz (gamma 1): f^-5 exp(-5/4 (fp/f)^4)
    f = np.array([0.5 * fp, 2.0 * fp, 3.0 * fp])
    np.testing.assert_allclose(
        jonswap_shape(f, tp, 1.0), f**-5 * np.exp(-1.25 * (fp / f) ** 4), rtol=1e-12
    )
    # one width below the peak (sigma 0.07) and one above (0.09): gamma^exp(-1/2)
    for f_hz in (fp * (1.0 - 0.07), fp * (1.0 + 0.09)):
        ratio = (
            jonswap_shape(np.array([f_hz]), tp, 3.3)[0]
            / jonswap_shape(np.array([f_hz]), tp, 1.0)[0]
        )
        assert ratio == pytest.approx(3.3 ** math.exp(-0.5), rel=1e-12)
    # a list is taken as an array, of integers too
    assert jonswap_shape([fp], tp, 2.0)[0] == pytest.approx(fp**-5 * math.exp(-1.25) * 2.0)
    np.testing.assert_allclose(jonswap_shape([1, 2], 1, 2), jonswap_shape([1.0, 2.0], 1.0, 2.0))


def test_wave_components_draw_one_frequency_in_each_bin_a_phase_and_a_direction_in_the_spread() -> (
    None
):
    hs, tp, gamma, n = 2.0, 8.0, 3.3, 2000
    band, direction, spread = (0.5, 4.0), 0.4, 0.3
    waves = WaveComponents(hs, tp, gamma, n, band, direction, spread, np.random.default_rng(5))
    edges = np.linspace(band[0] / tp, band[1] / tp, n + 1)
    np.testing.assert_allclose(waves.bin_widths_hz, np.diff(edges), rtol=1e-12)
    position = (waves.frequencies_hz - edges[:-1]) / waves.bin_widths_hz
    assert np.all((position >= 0.0) & (position < 1.0))
    assert position.min() < 0.01 and position.max() > 0.99 and abs(position.mean() - 0.5) < 0.03
    np.testing.assert_allclose(waves.omega, 2.0 * math.pi * waves.frequencies_hz, rtol=1e-15)
    # phases uniform over the circle
    phase = np.mod(np.angle(waves.elevation_phasors), 2.0 * math.pi)
    assert phase.min() < 0.05 and phase.max() > 2.0 * math.pi - 0.05
    assert np.mean(phase < math.pi) == pytest.approx(0.5, abs=0.04)
    # directions uniform within the spread of the mean direction
    offset = waves.directions - direction
    assert np.all(np.abs(offset) <= spread) and offset.min() < -0.99 * spread
    assert offset.max() > 0.99 * spread and abs(offset.mean()) < 0.02
    # amplitudes: sqrt(2 S(f) df), scaled so that m0 is Hs^2 / 16 exactly
    density = jonswap_shape(waves.frequencies_hz, tp, gamma) * waves.bin_widths_hz
    np.testing.assert_allclose(
        waves.amplitudes_m, np.sqrt(2.0 * density * hs**2 / 16.0 / np.sum(density)), rtol=1e-12
    )
    np.testing.assert_allclose(np.abs(waves.elevation_phasors), waves.amplitudes_m, rtol=1e-12)
    assert waves.m0 == pytest.approx(hs**2 / 16.0, rel=1e-12)
    # a sea at rest: met at its own frequencies
    assert waves.steady is True and waves.encounter_omega is waves.omega


def test_the_elevation_is_the_sum_of_the_components_cosines_at_a_time_or_times() -> None:
    # (a count given as a float is taken as the whole number it is)
    waves = WaveComponents(1.0, 6.0, 1.0, 5.0, (0.5, 4.0), 0.0, 0.5, np.random.default_rng(2))
    assert len(waves.omega) == 5
    times = np.array([0.0, 1.3, 7.25])
    expected = [
        float(
            np.sum(
                np.abs(waves.elevation_phasors)
                * np.cos(waves.omega * t + np.angle(waves.elevation_phasors))
            )
        )
        for t in times
    ]
    np.testing.assert_allclose(waves.elevation(times), expected, atol=1e-12)
    assert waves.elevation(1.3) == pytest.approx(expected[1], abs=1e-12)
    assert waves.elevation(2) == pytest.approx(waves.elevation(2.0))


def test_a_vessel_of_impossible_proportions_is_refused_naming_the_key_and_its_bounds() -> None:
    cases = {
        "beam_m": ({"beam_m": 15.1}, "allowed [3.0, 15.0] (set by length_m = 30.0)"),
        "draught_m": ({"draught_m": 4.3}, "allowed [0.2, 4.2] (set by beam_m = 7.0)"),
        "helideck_position_m": ({"helideck_position_m": (1.0, 2.0)}, "needs 3 values, got 2"),
        "helideck_position_m[x]": (
            {"helideck_position_m": (-15.1, 0.0, 3.0)},
            "allowed [-15.0, 15.0] (set by half of length_m = 30.0 and of beam_m = 7.0)",
        ),
        "helideck_position_m[y]": (
            {"helideck_position_m": (0.0, 3.6, 3.0)},
            "allowed [-3.5, 3.5] (set by half of length_m = 30.0 and of beam_m = 7.0)",
        ),
        "helideck_position_m[z]": ({"helideck_position_m": (0.0, 0.0, 20.5)}, "[-20.0, 20.0]"),
    }
    for key, (fields, text) in cases.items():
        with pytest.raises(ConfigError) as info:
            ShipMotionConfig(**fields)
        assert info.value.key == key and text in str(info.value), (key, str(info.value))
    # the bounds themselves are proportions a hull can have
    ShipMotionConfig(beam_m=15.0, draught_m=0.2)
    ShipMotionConfig(beam_m=3.0, draught_m=1.5, helideck_position_m=(15.0, -1.5, -20.0))
    deck = ShipMotionConfig(helideck_position_m=[-15, 3.5, 20]).helideck_position_m
    assert deck == (-15.0, 3.5, 20.0) and all(isinstance(v, float) for v in deck)


def test_a_sea_outside_what_it_can_be_is_refused_naming_the_key_and_its_bounds() -> None:
    codes = "choose one of 0, 1, 2, 3, 4, 5, 6"
    needs = f"None needs both significant_height_m and peak_period_s; or {codes}"
    cases = [
        ("sea_state", {"sea_state": 7}, f"7 is not allowed; {codes}"),
        ("sea_state", {"sea_state": None, "peak_period_s": 7.0}, needs),
        ("sea_state", {"sea_state": None, "significant_height_m": 2.0}, needs),
        ("significant_height_m", {"significant_height_m": 16.5}, "allowed [0.0, 16.0]"),
        ("significant_height_m", {"significant_height_m": -0.1}, "allowed [0.0, 16.0]"),
        ("peak_period_s", {"peak_period_s": 1.9}, "allowed [2.0, 25.0]"),
        ("peak_period_s", {"peak_period_s": 25.5}, "allowed [2.0, 25.0]"),
        ("gamma", {"gamma": 0.9}, "allowed [1.0, 10.0]"),
        ("gamma", {"gamma": 10.5}, "allowed [1.0, 10.0]"),
        ("n_components", {"n_components": 0}, "allowed [1, 10000]"),
        ("n_components", {"n_components": 10_001}, "allowed [1, 10000]"),
        ("band_low", {"band_low": 0.0}, "0.0 is out of range; allowed (0.0, 1.0]"),
        ("band_low", {"band_low": 1.5}, "allowed (0.0, 1.0]"),
        ("band_high", {"band_high": 1.0}, "1.0 is out of range; allowed (1.0, 20.0]"),
        ("band_high", {"band_high": 20.5}, "allowed (1.0, 20.0]"),
        ("direction_spread_deg", {"direction_spread_deg": 180.5}, "allowed [0.0, 180.0]"),
        ("generator.spectrum", {"generator": {"spectrum": "pm"}}, "'pm' is not allowed"),
        # the sea state 4 (1.88 m, 8.8 s) is swell-dominated; a ramp to Tp 4 s is not
        (
            "generator.tp_end_s",
            {"generator": {"spectrum": "torsethaugen", "tp_end_s": 4.0}},
            "the ramp from Hs 1.88 m, Tp 8.8 s to Hs 1.88 m, Tp 4 s crosses",
        ),
    ]
    for key, fields, text in cases:
        with pytest.raises(ConfigError) as info:
            ShipMotionConfig(**fields)
        assert info.value.key == key and text in str(info.value), (key, str(info.value))
    # the bounds are seas it can be; a generator given as a mapping becomes its config
    ShipMotionConfig(
        sea_state=None,
        significant_height_m=0.0,
        peak_period_s=2.0,
        gamma=1.0,
        n_components=1,
        band_low=1.0,
        band_high=20.0,
        direction_spread_deg=0.0,
    )
    widest = ShipMotionConfig(
        significant_height_m=16.0,
        peak_period_s=25.0,
        gamma=10.0,
        n_components=10_000,
        band_low=1e-3,
        band_high=1.001,
        direction_spread_deg=180.0,
        generator={"speed_m_s": 3.0},
    )
    assert widest.generator == SeaGeneratorConfig(speed_m_s=3.0)
    assert ShipMotionConfig(sea_state=0).hs == 0.0


def test_the_vessels_own_periods_are_the_imo_roll_formula_and_the_draughts_heave() -> None:
    config = ShipMotionConfig(length_m=20.0, beam_m=6.0, draught_m=1.5, metacentric_height_m=0.8)
    c = 0.373 + 0.023 * 6.0 / 1.5 - 0.043 * 20.0 / 100.0
    assert config.roll_period_in_use_s == pytest.approx(2.0 * c * 6.0 / math.sqrt(0.8), rel=1e-12)
    assert ShipMotionConfig(roll_period_s=9.0).roll_period_in_use_s == 9.0
    assert config.heave_period_s == pytest.approx(2.0 * math.pi * math.sqrt(3.0 / 9.80665))


def test_the_helideck_moves_with_the_hull_as_a_rigid_body_for_any_attitude() -> None:
    rng = np.random.default_rng(8)
    vessel = np.column_stack([rng.normal(0.0, 1.0, (20, 3)), rng.uniform(-0.6, 0.6, (20, 3))])
    arm = np.array([-10.0, 1.5, 3.0])
    poses = helideck_poses(vessel, arm)
    rotation = Rotation.from_euler("ZYX", vessel[:, [5, 4, 3]])
    np.testing.assert_allclose(poses[:, :3], vessel[:, :3] + rotation.apply(arm) - arm, atol=1e-12)
    np.testing.assert_array_equal(poses[:, 3:], vessel[:, 3:])
    # one pose as a flat row, the arm as a list
    np.testing.assert_allclose(helideck_poses(vessel[0], list(arm)), poses[:1], atol=1e-12)


def test_the_length_filters_are_smooth_through_zero_and_long_waves_pass() -> None:
    config = ShipMotionConfig()
    omega = np.full(4, 0.5)
    k = 0.25 / 9.80665
    # x = k |cos mu| L / 2 either side of 1e-3 and at 0 (beam seas)
    cosines = np.array([0.0, 0.9e-3, 1.1e-3, 0.02]) / (0.5 * k * config.length_m)
    cosines[3] = 0.999  # x = 0.19: the series 1 - x^2/10 would be off by 5e-5 there
    rao = vessel_raos(config, omega, np.arccos(cosines))
    x = 0.5 * k * cosines * config.length_m
    pitch_filter = rao["pitch"] / (rao["heave"] / np.sinc(x / math.pi))
    expected = 3.0 * (np.sin(x[1:]) - x[1:] * np.cos(x[1:])) / x[1:] ** 3
    np.testing.assert_allclose(pitch_filter[1:], expected, rtol=1e-6)
    assert pitch_filter[0] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(pitch_filter[:3], 1.0 - x[:3] ** 2 / 10.0, atol=1e-9)
    # surge and sway: the orbital motion of the surface along and across the hull
    mu = np.arccos(cosines)
    np.testing.assert_allclose(
        rao["surge"],
        np.exp(-k * cosines * config.draught_m) * np.sinc(x / math.pi) * np.cos(mu),
        atol=1e-15,
    )
    np.testing.assert_allclose(
        rao["sway"], np.exp(-k * cosines * config.draught_m) * np.sinc(x / math.pi) * np.sin(mu)
    )


def test_the_oscillators_take_the_encounter_frequency_with_damping_odd_in_it() -> None:
    config = ShipMotionConfig()
    omega = np.array([0.6, 1.0, 1.6, 2.2])
    direction = np.radians([180.0, 150.0, 120.0, 90.0])
    at_rest = vessel_raos(config, omega, direction)
    met_as_at_rest = vessel_raos(config, omega, direction, omega)
    for name in ("heave", "pitch", "roll", "surge", "sway"):
        np.testing.assert_allclose(met_as_at_rest[name], at_rest[name], rtol=1e-12)
    # a negative encounter frequency: the same oscillation with time reversed
    encounter = np.array([0.3, 0.9, 1.4, 2.5])
    ahead = vessel_raos(config, omega, direction, encounter)
    behind = vessel_raos(config, omega, direction, -encounter)
    for name in ("heave", "pitch", "roll"):
        np.testing.assert_allclose(behind[name], np.conj(ahead[name]), rtol=1e-12)
    # the oscillators at their own frequency; the excitation keeps the wave's geometry
    k = omega**2 / 9.80665
    ke = encounter**2 / 9.80665
    breadth = config.block_coefficient * config.beam_m
    a = 2.0 * np.sin(0.5 * k * breadth) * np.exp(-k * config.draught_m)
    ae = 2.0 * np.sin(0.5 * ke * breadth) * np.exp(-ke * config.draught_m)
    eta_e = 1.0 / ((1.0 - 2.0 * ke * config.draught_m) + 1j * ae**2 / (ke * breadth))
    eta = 1.0 / ((1.0 - 2.0 * k * config.draught_m) + 1j * a**2 / (k * breadth))
    np.testing.assert_allclose(ahead["heave"] / at_rest["heave"], eta_e / eta, rtol=1e-10)
    ratio_e = encounter * config.roll_period_in_use_s / (2.0 * math.pi)
    ratio = omega * config.roll_period_in_use_s / (2.0 * math.pi)
    np.testing.assert_allclose(
        ahead["roll"] / at_rest["roll"],
        (1.0 - ratio**2 + 0.2j * ratio) / (1.0 - ratio_e**2 + 0.2j * ratio_e),
        rtol=1e-10,
    )
    # met at zero frequency (the ship keeping pace with the wave): a static response
    still = vessel_raos(config, omega, direction, np.zeros(4))
    np.testing.assert_allclose(still["heave"] / at_rest["heave"], 1.0 / eta, rtol=1e-9)
    np.testing.assert_allclose(still["roll"] / at_rest["roll"], 1.0 - ratio**2 + 0.2j * ratio)


def test_the_decks_reach_is_its_amplitude_in_a_regular_wave_and_six_sigma_in_a_sea() -> None:
    times = np.linspace(0.0, 200.0, 20001)
    # one component in head seas: no roll; the deck's tilt is the pitch
    config = ShipMotionConfig(
        sea_state=None,
        significant_height_m=2.0,
        peak_period_s=8.0,
        n_components=1,
        wave_direction_deg=180.0,
        direction_spread_deg=0.0,
    )
    ship = ShipMotion(config, np.random.default_rng(0))
    poses = ship.poses(times)
    assert np.max(np.abs(poses[:, 4])) == pytest.approx(ship.tilt_reach_rad, rel=1e-3)
    drop = 3.0 * (1.0 - math.cos(ship.tilt_reach_rad))
    assert np.max(np.abs(poses[:, 2])) == pytest.approx(ship.vertical_reach_m - drop, rel=2e-3)
    assert 0.0 < drop < 0.01 * ship.vertical_reach_m
    # seas off the bow, the deck off the centre line: its heave adds the roll's and pitch's arms
    bow = ShipMotion(
        replace(config, wave_direction_deg=120.0, helideck_position_m=(-10.0, 3.0, 0.0)),
        np.random.default_rng(0),
    )
    vessel = bow.vessel_poses(times)
    roll, pitch = np.max(np.abs(vessel[:, 3])), np.max(np.abs(vessel[:, 4]))
    assert roll > 0.1 * pitch and bow.tilt_reach_rad == pytest.approx(roll + pitch, rel=1e-3)
    linear = vessel[:, 2] + 3.0 * vessel[:, 3] + 10.0 * vessel[:, 4]
    assert bow.vertical_reach_m == pytest.approx(np.max(np.abs(linear)), rel=1e-3)
    # a short-crested sea of 200 components: six standard deviations
    sea = ShipMotion(ShipMotionConfig(sea_state=5), np.random.default_rng(1))
    long = np.arange(0.0, 7200.0, 0.5)
    poses = sea.poses(long)
    drop = 3.0 * (1.0 - math.cos(min(sea.tilt_reach_rad, 1.5)))
    assert (sea.vertical_reach_m - drop) / np.std(poses[:, 2]) == pytest.approx(6.0, rel=0.05)
    tilt = np.abs(sea.vessel_poses(long)[:, 3]) + np.abs(sea.vessel_poses(long)[:, 4])
    assert sea.tilt_reach_rad > np.max(tilt)


def test_the_decks_reach_adds_the_lever_arms_drop_at_the_tilt_reach_up_to_1_5_rad() -> None:
    # the deck's height above the centre of rotation changes only that drop, not the sea
    for sea, capped in (({"sea_state": 4}, False), ({"significant_height_m": 16.0}, True)):
        fields = dict(sea, peak_period_s=3.0) if capped else sea
        hull = {"length_m": 10.0, "beam_m": 4.0, "draught_m": 1.0}
        level = ShipMotion(
            ShipMotionConfig(**fields, **hull, helideck_position_m=(-4.0, 1.0, 0.0)),
            np.random.default_rng(3),
        )
        assert (level.tilt_reach_rad > 1.5) == capped
        drop = 1.0 - math.cos(min(level.tilt_reach_rad, 1.5))
        for height_m in (12.0, -12.0):
            high = ShipMotion(
                ShipMotionConfig(**fields, **hull, helideck_position_m=(-4.0, 1.0, height_m)),
                np.random.default_rng(3),
            )
            assert high.tilt_reach_rad == level.tilt_reach_rad
            assert high.vertical_reach_m - level.vertical_reach_m == pytest.approx(12.0 * drop)


@pytest.mark.parametrize("speed_m_s", [0.0, 6.0])
def test_a_ship_under_way_in_a_steady_sea_moves_at_the_derivative_of_its_poses(
    speed_m_s: float,
) -> None:
    generator = SeaGeneratorConfig(speed_m_s=speed_m_s, swell_direction_deg=120.0)
    config = ShipMotionConfig(wave_direction_deg=180.0, generator=generator)
    ship = ShipMotion(config, np.random.default_rng(1))
    assert ship.waves.steady
    times = np.linspace(0.0, 40.0, 81)
    h = 1e-4
    numeric = (ship.poses(times + h) - ship.poses(times - h)) / (2 * h)
    np.testing.assert_allclose(ship.velocities(times), numeric, atol=2e-5)
    vessel = (ship.vessel_poses(times + h) - ship.vessel_poses(times - h)) / (2 * h)
    np.testing.assert_allclose(ship.vessel_rates(times), vessel, atol=2e-5)
    np.testing.assert_allclose(ship.velocity(times[7]), ship.velocities(times)[7], atol=1e-12)
    np.testing.assert_allclose(ship.elevation(times), ship.waves.elevation(times), atol=0.0)


@pytest.mark.parametrize("speed_m_s", [1.0, 6.0])
def test_a_ship_under_way_heaves_by_the_rao_of_its_encounter_frequency(speed_m_s: float) -> None:
    ship = regular_ship(6.0, 180.0, generator=SeaGeneratorConfig(speed_m_s=speed_m_s))
    waves = ship.waves
    omega_e = float(waves.encounter_omega[0])
    assert omega_e > float(waves.omega[0])  # head seas: met more often
    # the complex heave of the one component: its real part now, a quarter period earlier
    heave = ship.vessel_poses(np.array([0.0, -0.5 * math.pi / omega_e]))[:, 2]
    response = (heave[0] + 1j * heave[1]) / waves.elevation_phasors[0]
    under_way = vessel_raos(ship.config, waves.omega, waves.directions, waves.encounter_omega)
    at_rest = vessel_raos(ship.config, waves.omega, waves.directions)
    assert response == pytest.approx(complex(under_way["heave"][0]), rel=1e-9)
    assert abs(response - at_rest["heave"][0]) > 1e-3 * abs(response)


def test_at_rest_the_raos_are_jensen_mansour_olsens_closed_forms_and_the_roll_oscillator() -> None:
    config = ShipMotionConfig(roll_period_s=6.0, roll_damping_ratio=0.2, roll_slope_factor=0.6)
    omega = np.array([0.4, 0.9, 1.3, 1.8, 2.6, 1.1])
    direction = np.radians([180.0, 160.0, 100.0, 30.0, 0.0, -120.0])
    rao = vessel_raos(config, omega, direction)
    length, breadth, draught = config.length_m, 0.45 * config.beam_m, config.draught_m
    k = omega**2 / 9.80665
    ke = np.abs(k * np.cos(direction))
    x = 0.5 * ke * length
    kappa = np.exp(-ke * draught)
    a = 2.0 * np.sin(0.5 * k * breadth) * np.exp(-k * draught)
    f = np.sqrt((1.0 - k * draught) ** 2 + (a**2 / (k * breadth)) ** 2)
    eta = 1.0 / ((1.0 - 2.0 * k * draught) + 1j * a**2 / (k * breadth))
    np.testing.assert_allclose(rao["heave"], eta * kappa * f * np.sin(x) / x, rtol=1e-10)
    pitch_filter = 3.0 * (np.sin(x) - x * np.cos(x)) / x**3
    np.testing.assert_allclose(rao["pitch"], eta * kappa * f * pitch_filter, rtol=1e-8)
    ratio = omega / (2.0 * math.pi / 6.0)
    roll = 0.6 * np.exp(-0.5 * k * draught) * np.sin(x) / x / (1.0 - ratio**2 + 0.4j * ratio)
    np.testing.assert_allclose(rao["roll"], roll, rtol=1e-10)
    # surge and sway: the surface's orbital motion, with the same length filter and depth decay
    np.testing.assert_allclose(rao["surge"], kappa * np.sin(x) / x * np.cos(direction), rtol=1e-10)
    np.testing.assert_allclose(rao["sway"], kappa * np.sin(x) / x * np.sin(direction), rtol=1e-10)


def test_in_a_long_wave_the_hull_surges_and_sways_with_the_surfaces_orbital_velocity() -> None:
    # u = w * elevation along the direction the wave travels (in phase with it: forward under
    # a crest), as the water particles at the surface of a deep-water wave
    times = np.linspace(0.0, 100.0, 4001)
    for direction_deg, column, sign in ((0.0, 0, 1.0), (180.0, 0, -1.0), (90.0, 1, 1.0)):
        ship = regular_ship(25.0, direction_deg)
        rate = ship.vessel_rates(times)[:, column]
        orbital = sign * ship.waves.omega[0] * ship.elevation(times)
        assert np.corrcoef(rate, orbital)[0, 1] > 0.999, direction_deg
        assert np.std(rate) / np.std(orbital) == pytest.approx(1.0, abs=0.02)


def test_near_zero_the_pitch_filter_is_its_series_to_the_series_own_error() -> None:
    # x below 1e-3 (components within a milliradian-order angle of beam seas): 1 - x^2/10, whose
    # next term x^4/280 is below 3e-15 there
    config = ShipMotionConfig()
    omega = np.full(3, 0.5)
    k = 0.25 / 9.80665
    direction = np.arccos(np.array([0.3e-3, 0.6e-3, 0.9e-3]) / (0.5 * k * config.length_m))
    rao = vessel_raos(config, omega, direction)
    x = 0.5 * k * np.abs(np.cos(direction)) * config.length_m
    assert np.all(x < 1e-3)
    pitch_filter = rao["pitch"] / (rao["heave"] / np.sinc(x / math.pi))
    np.testing.assert_allclose(pitch_filter, 1.0 - x**2 / 10.0, rtol=0.0, atol=1e-13)


def test_encounter_frequencies_in_single_precision_give_the_raos_of_their_value() -> None:
    config = ShipMotionConfig()
    omega = np.array([0.6, 1.0, 1.6])
    direction = np.radians([180.0, 150.0, 120.0])
    encounter = np.array([0.7, 1.3, -0.4], dtype=np.float32)
    single = vessel_raos(config, omega, direction, encounter)
    double = vessel_raos(config, omega, direction, encounter.astype(float))
    for name, value in double.items():
        np.testing.assert_array_equal(single[name], value, err_msg=name)


def test_the_helideck_takes_single_precision_poses_at_their_value_and_an_arm_of_any_shape() -> None:
    rng = np.random.default_rng(8)
    vessel = np.column_stack([rng.normal(0.0, 1.0, (5, 3)), rng.uniform(-0.6, 0.6, (5, 3))])
    vessel = vessel.astype(np.float32)
    arm = np.array([-10.0, 1.5, 3.0])
    poses = helideck_poses(vessel.astype(float), arm)
    np.testing.assert_array_equal(helideck_poses(vessel, arm), poses)
    for shape in ((1, 3), (3, 1)):
        np.testing.assert_array_equal(helideck_poses(vessel, arm.reshape(shape)), poses)


def test_the_decks_poses_and_velocities_take_a_time_or_times_of_any_shape_one_row_each() -> None:
    for generator in (SeaGeneratorConfig(), SeaGeneratorConfig(hs_end_m=3.0, ramp_duration_s=20.0)):
        ship = ShipMotion(
            ShipMotionConfig(n_components=20, generator=generator), np.random.default_rng(0)
        )
        times = np.array([3.0, 12.5])
        for method in (ship.poses, ship.velocities):
            rows = method(times)
            assert rows.shape == (2, 6)
            # (to the rounding of a product over one row or two)
            np.testing.assert_allclose(method(3.0), rows[:1], rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(method(times.reshape(2, 1)), rows, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(method(times.reshape(1, 2)), rows, rtol=1e-12, atol=1e-15)


def test_in_a_changing_sea_the_hull_follows_the_sea_of_the_moment_and_reaches_its_largest() -> None:
    # one component in head seas, its height doubling from 100 s to 150 s
    ramp = SeaGeneratorConfig(hs_end_m=2.0, ramp_start_s=100.0, ramp_duration_s=50.0)
    ship = regular_ship(6.0, 180.0, generator=ramp)
    waves = ship.waves
    assert not waves.steady
    omega = float(waves.omega[0])
    quarter_s = 0.5 * math.pi / omega
    heave_rao = complex(vessel_raos(ship.config, waves.omega, waves.directions)["heave"][0])
    # the complex heave over the complex elevation, before the ramp and after it
    for t, hs in ((0.0, 1.0), (300.0, 2.0)):
        heave = ship.vessel_poses(np.array([t, t - quarter_s]))[:, 2]
        amplitude = hs / (2.0 * math.sqrt(2.0))
        elevation = amplitude * waves.unit_phasors[0] * np.exp(1j * omega * t)
        assert (heave[0] + 1j * heave[1]) / elevation == pytest.approx(heave_rao, rel=1e-9)
    # the reach is that of the largest sea, the one after the ramp: twice the first one's
    before = ship.poses(np.linspace(0.0, 100.0, 10001))
    after = ship.poses(np.linspace(150.0, 350.0, 20001))
    assert np.max(np.abs(after[:, 4])) == pytest.approx(ship.tilt_reach_rad, rel=1e-3)
    assert np.max(np.abs(before[:, 4])) == pytest.approx(0.5 * ship.tilt_reach_rad, rel=1e-3)
    # the deck 10 m aft and 3 m up: its linearised height, heave + 10 pitch, and the arm's drop
    vessel = ship.vessel_poses(np.linspace(150.0, 350.0, 20001))
    linear = vessel[:, 2] + 10.0 * vessel[:, 4]
    drop = 3.0 * (1.0 - math.cos(ship.tilt_reach_rad))
    assert np.max(np.abs(linear)) == pytest.approx(ship.vertical_reach_m - drop, rel=1e-3)
