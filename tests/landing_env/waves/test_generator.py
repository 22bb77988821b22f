"""The generator of held-out seas: bimodal spectra (DNV-RP-C205), ship speed, a changing sea."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.signal import argrelmax, welch

from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.stewart.motion import SeaStateConfig, SeaStateMotion
from landing_env.waves.bimodal import ochi_hubble_parts, torsethaugen_parts, total_density
from landing_env.waves.generator import GeneratedSea, SeaGeneratorConfig
from landing_env.waves.ship import GRAVITY, ShipMotion, ShipMotionConfig


def m0_of(parts) -> float:
    return sum(
        quad(lambda f, p=p: float(p.density(np.array([f]))[0]), 0.0, 5.0, limit=400)[0]
        for p in parts
    )


@pytest.mark.parametrize(
    ("hs", "tp"), [(1.0, 4.0), (2.5, 6.0), (1.88, 8.8), (3.25, 9.7), (2.0, 14.0), (4.0, 18.0)]
)
def test_torsethaugen_integrates_to_hs_and_peaks_at_tp(hs: float, tp: float) -> None:
    parts = torsethaugen_parts(hs, tp)
    # the DNV-RP-C205 form's normaliser A_gamma is a fit: within 5 % of Hs^2 / 16
    assert m0_of(parts) == pytest.approx(hs**2 / 16.0, rel=0.05)
    # the two systems share the variance: Hs1^2 + Hs2^2 = Hs^2
    assert sum(p.significant_height_m**2 for p in parts) == pytest.approx(hs**2)
    f = np.linspace(0.02, 1.0, 50_000)
    assert 1.0 / f[np.argmax(total_density(parts, f))] == pytest.approx(tp, rel=0.005)
    tf = 6.6 * hs ** (1.0 / 3.0)
    # the primary peak (at Tp) is the wind sea's below Tf, the swell's above
    (primary,) = [p for p in parts if p.peak_period_s == tp]
    assert primary.system == ("wind" if tp <= tf else "swell")


def test_a_swell_dominated_torsethaugen_sea_has_its_wind_sea_peak_too() -> None:
    parts = torsethaugen_parts(2.0, 14.0)
    wind = next(p for p in parts if p.system == "wind")
    f = np.linspace(0.03, 0.5, 20_000)
    density = total_density(parts, f)
    peaks = 1.0 / f[argrelmax(density)[0]]
    # two peaks: the swell's at Tp, and the wind sea's (its own maximum at its Tp2, moved a
    # little by the swell's tail under it)
    assert len(peaks) == 2 and max(peaks) == pytest.approx(14.0, rel=0.005)
    assert 1.0 / f[np.argmax(wind.density(f))] == pytest.approx(wind.peak_period_s, rel=1e-3)
    assert wind.peak_period_s < min(peaks) < 0.85 * 14.0


def test_ochi_hubble_parts_integrate_exactly_and_peak_at_their_periods() -> None:
    parts = ochi_hubble_parts(2.5, 6.0, 15.0, 0.4, wind_shape=1.5, swell_shape=4.0)
    assert m0_of(parts) == pytest.approx(2.5**2 / 16.0, rel=1e-5)
    assert m0_of(parts[1:]) == pytest.approx(0.4 * 2.5**2 / 16.0, rel=1e-5)
    f = np.linspace(0.02, 1.0, 100_000)
    for part, tp in zip(parts, (6.0, 15.0), strict=True):
        assert 1.0 / f[np.argmax(part.density(f))] == pytest.approx(tp, rel=1e-3)
    peaks = 1.0 / f[argrelmax(total_density(parts, f))[0]]
    assert sorted(peaks) == pytest.approx([6.0, 15.0], rel=0.02)


def generated(generator: SeaGeneratorConfig, hs=2.0, tp=8.0, n=200, seed=0) -> GeneratedSea:
    return GeneratedSea(
        hs,
        tp,
        1.0,
        n,
        (0.5, 4.0),
        math.radians(150.0),
        math.radians(30.0),
        generator,
        np.random.default_rng(seed),
    )


@pytest.mark.parametrize("spectrum", ["torsethaugen", "ochi_hubble"])
def test_a_generated_bimodal_sea_has_the_requested_hs_and_peaks(spectrum: str) -> None:
    generator = SeaGeneratorConfig(
        spectrum=spectrum, swell_direction_deg=200.0, swell_peak_period_s=15.0
    )
    sea = generated(generator, hs=2.0, tp=6.0 if spectrum == "ochi_hubble" else 14.0)
    assert 4.0 * math.sqrt(sea.m0) == pytest.approx(2.0, rel=1e-12)
    fs = 2.0
    elevation = sea.elevation(np.arange(0.0, 3 * 3600.0, 1.0 / fs))
    f, psd = welch(elevation, fs=fs, nperseg=4096)
    m0 = float(np.sum(psd) * (f[1] - f[0]))
    assert 4.0 * math.sqrt(m0) == pytest.approx(2.0, rel=0.04)
    # the record's spectrum has the target's primary peak and its split between the systems
    parts = generator.parts(2.0, 6.0 if spectrum == "ochi_hubble" else 14.0, 1.0)
    fine = np.linspace(0.02, 1.0, 20_000)
    target = total_density(parts, fine)
    smooth = np.convolve(psd, np.ones(5) / 5, mode="same")
    primary = 1.0 / fine[np.argmax(target)]
    assert 1.0 / f[np.argmax(smooth)] == pytest.approx(primary, rel=0.08)
    split = math.sqrt(1.0 / parts[0].peak_period_s / parts[1].peak_period_s)
    share = np.sum(target[fine < split]) / np.sum(target)
    assert np.sum(psd[f < split]) / np.sum(psd) == pytest.approx(share, abs=0.05)
    assert 0.1 < share < 0.9
    # each system travels its own way: the swell towards 200 deg, the wind sea 150 +- 30
    swell = sea.part_index == 1
    assert np.all(np.abs(np.degrees(sea.directions[swell]) - 200.0) <= 10.0 + 1e-9)
    assert np.all(np.abs(np.degrees(sea.directions[~swell]) - 150.0) <= 30.0 + 1e-9)


def test_a_changing_sea_has_at_every_instant_the_variance_of_its_ramp() -> None:
    generator = SeaGeneratorConfig(
        hs_end_m=3.25, tp_end_s=9.7, ramp_start_s=600, ramp_duration_s=1200
    )
    sea = generated(generator, hs=1.88, tp=8.8, n=300)
    times = np.array([0.0, 600.0, 900.0, 1200.0, 1500.0, 1800.0, 5000.0])
    hs, tp = generator.sea_parameters(1.88, 8.8, times)
    assert hs[0] == 1.88 and hs[-1] == 3.25 and tp[-1] == 9.7
    assert np.all(np.diff(hs) >= 0.0) and hs[3] == pytest.approx(0.5 * (1.88 + 3.25))
    amplitudes = sea.amplitudes(times)
    np.testing.assert_allclose(4.0 * np.sqrt(np.sum(amplitudes**2, axis=1) / 2.0), hs, rtol=1e-12)
    # the peak moves with Tp
    for row, period in ((0, 8.8), (-1, 9.7)):
        density = amplitudes[row] ** 2 / 2.0 / sea.bin_widths_hz
        assert 1.0 / sea.frequencies_hz[np.argmax(density)] == pytest.approx(period, rel=0.06)
    # and the record shows it: RMS before and after the ramp in the ratio of the heights
    before = sea.elevation(np.arange(0.0, 600.0, 0.5))
    after = sea.elevation(np.arange(1800.0, 5400.0, 0.5))
    assert np.std(after) / np.std(before) == pytest.approx(3.25 / 1.88, rel=0.2)


def test_a_torsethaugen_ramp_across_the_fully_developed_period_is_refused_by_key() -> None:
    with pytest.raises(ConfigError) as info:
        load_config(
            "ship-ss4",
            overrides={
                "motion.ship.generator.spectrum": "torsethaugen",
                "motion.ship.generator.tp_end_s": 6.0,
            },
        )
    assert info.value.key == "motion.ship.generator.tp_end_s"
    for key, value in (
        ("spectrum", "bretschneider"),
        ("speed_m_s", -1.0),
        ("swell_energy_fraction", 1.5),
        ("ramp_duration_s", 0.0),
        ("swel_spread_deg", 5.0),
    ):
        with pytest.raises(ConfigError) as info:
            load_config("ship-ss4", overrides={f"motion.ship.generator.{key}": value})
        assert f"motion.ship.generator.{key}" in str(info.value)


def test_head_seas_at_speed_are_met_more_often_and_following_seas_less() -> None:
    times = np.arange(0.0, 1800.0, 0.25)
    peaks = {}
    for name, direction, speed in (
        ("rest", 180.0, 0.0),
        ("head", 180.0, 6.0),
        ("follow", 0.0, 3.0),
    ):
        config = ShipMotionConfig(
            wave_direction_deg=direction,
            direction_spread_deg=0.0,
            generator=SeaGeneratorConfig(speed_m_s=speed) if speed else SeaGeneratorConfig(),
        )
        ship = ShipMotion(config, np.random.default_rng(2))
        f, psd = welch(ship.vessel_poses(times)[:, 2], fs=4.0, nperseg=2048)
        peaks[name] = f[np.argmax(psd)]
        omega = ship.waves.omega
        k = omega**2 / GRAVITY
        np.testing.assert_allclose(
            ship.waves.encounter_omega, omega - k * speed * np.cos(ship.waves.directions)
        )
    assert peaks["head"] > 1.15 * peaks["rest"]
    assert peaks["follow"] < 0.9 * peaks["rest"]


@pytest.mark.parametrize("source", ["ship", "bench"])
def test_velocities_are_the_derivative_of_the_poses_in_a_changing_sea_at_speed(source) -> None:
    generator = SeaGeneratorConfig(
        spectrum="ochi_hubble",
        speed_m_s=4.0,
        swell_direction_deg=90.0,
        hs_end_m=3.0,
        tp_end_s=10.0,
        ramp_start_s=5.0,
        ramp_duration_s=20.0,
    )
    if source == "ship":
        motion = ShipMotion(ShipMotionConfig(generator=generator), np.random.default_rng(1))
        rates = lambda t: motion.velocities(t)  # noqa: E731
    else:
        motion = SeaStateMotion(SeaStateConfig(generator=generator), np.random.default_rng(1))
        rates = lambda t: np.array([motion.velocity(x) for x in t])  # noqa: E731
    times = np.linspace(0.0, 40.0, 81)
    h = 1e-4
    numeric = (motion.poses(times + h) - motion.poses(times - h)) / (2 * h)
    np.testing.assert_allclose(rates(times), numeric, atol=2e-5)
    single = np.array([motion.pose(float(t)) for t in times])
    np.testing.assert_allclose(single, motion.poses(times), atol=1e-12)
