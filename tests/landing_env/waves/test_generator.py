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
from landing_env.waves.bimodal import (
    SpectralPart,
    ochi_hubble_parts,
    torsethaugen_parts,
    total_density,
)
from landing_env.waves.generator import (
    GeneratedSea,
    SeaGeneratorConfig,
    make_sea,
    require_generator,
)
from landing_env.waves.ship import GRAVITY, ShipMotion, ShipMotionConfig
from landing_env.waves.spectrum import WaveComponents, jonswap_shape, underflowed_amplitudes


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


@pytest.mark.parametrize("form", ["jonswap", "torsethaugen", "ochi_hubble"])
def test_a_spectral_part_has_no_energy_at_or_below_zero_frequency_nor_when_calm(form: str) -> None:
    part = SpectralPart("wind", form, 2.0, 8.0, gamma=3.3, shape=2.0)
    density = part.density(np.array([-0.1, 0.0, 0.125]))
    assert density[0] == 0.0 and density[1] == 0.0 and density[2] > 0.0
    assert np.all(part.density(np.array([-1.0, 0.0])) == 0.0)
    calm = SpectralPart("wind", form, 0.0, 8.0, gamma=3.3, shape=2.0)
    np.testing.assert_array_equal(calm.density(np.array([0.05, 0.125, 0.3])), np.zeros(3))
    # a list of frequencies is taken as an array
    assert part.density([0.125])[0] == pytest.approx(density[2])


@pytest.mark.parametrize("gamma", [1.0, 3.3, 7.0])
def test_a_plain_jonswap_part_is_the_jonswap_shape_holding_exactly_its_hs(gamma: float) -> None:
    part = SpectralPart("wind", "jonswap", 1.5, 8.0, gamma, 5.0, 4.0)
    assert m0_of([part]) == pytest.approx(1.5**2 / 16.0, rel=1e-4)
    f = np.linspace(0.05, 0.6, 200)
    ratio = part.density(f) / jonswap_shape(f, 8.0, gamma)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-10)


def test_a_torsethaugen_part_without_peak_factor_holds_exactly_its_hs_whatever_its_exponents() -> (
    None
):
    for n, m in ((3.7, 4.0), (4.2, 2.5), (5.0, 4.0)):
        part = SpectralPart("wind", "torsethaugen", 1.5, 7.0, 1.0, n, m)
        assert m0_of([part]) == pytest.approx(1.5**2 / 16.0, rel=1e-4)


def test_a_peaked_torsethaugen_part_is_normalised_by_the_dnv_fit_a_gamma() -> None:
    hs, tp, gamma, n, m = 2.0, 8.0, 3.3, 3.9, 4.0
    part = SpectralPart("wind", "torsethaugen", hs, tp, gamma, n, m)
    flat = SpectralPart("wind", "torsethaugen", hs, tp, 1.0, n, m)
    f1 = 4.1 * (n - 2.0 * m**0.28 + 5.3) ** (0.96 - 1.45 * m**0.1)
    f2 = (2.2 * m**-3.3 + 0.57) * n ** (0.53 - 0.58 * m**0.37) + 0.94 - 1.04 * m**-1.9
    a_gamma = (1.0 + f1 * math.log(gamma) ** f2) / gamma
    # at the peak (fn = 1) the peak factor is the whole gamma; below and above by its widths
    fp = 1.0 / tp
    assert part.density(np.array([fp]))[0] == pytest.approx(
        flat.density(np.array([fp]))[0] * a_gamma * gamma, rel=1e-12
    )
    for fn in (1.0 - 0.07, 1.0 + 0.09):
        ratio = part.density(np.array([fn * fp]))[0] / flat.density(np.array([fn * fp]))[0]
        assert ratio == pytest.approx(a_gamma * gamma ** math.exp(-0.5), rel=1e-12)
    # the fit is close to the exact normaliser
    assert m0_of([part]) == pytest.approx(hs**2 / 16.0, rel=0.05)


def torsethaugen_reference(hs: float, tp: float) -> dict[str, tuple[float, float, float, float]]:
    """(Hs, Tp, gamma, M) of each system by DNV-RP-C205 Sec. 3.5.7.6, as the module states it."""
    tf = 6.6 * hs ** (1.0 / 3.0)
    n = 0.5 * math.sqrt(hs) + 3.2
    lift = 35.0 * (1.0 + 3.5 * math.exp(-hs))
    if tp <= tf:
        r = 0.7 + 0.3 * math.exp(-((2.0 * (tf - tp) / (tf - 2.0 * math.sqrt(hs))) ** 2))
        gamma = lift * (2.0 * math.pi * r * hs / (GRAVITY * tp**2)) ** 0.857
        return {
            "wind": (r * hs, tp, max(1.0, gamma), 4.0),
            "swell": (math.sqrt(1.0 - r**2) * hs, tf + 2.0, 1.0, 4.0),
        }
    eps = (tp - tf) / (25.0 - tf)
    r = 0.6 + 0.4 * math.exp(-((eps / 0.3) ** 2))
    gamma = lift * (2.0 * math.pi * hs / (GRAVITY * tf**2)) ** 0.857 * (1.0 + 6.0 * eps)
    h2 = math.sqrt(1.0 - r**2) * hs
    m2 = 4.0 * (1.0 - 0.7 * math.exp(-hs / 3.0))
    s4 = max(0.01, 0.08 * (1.0 - math.exp(-hs / 3.0)))
    g0 = 1.0 / ((1.0 / m2) * (n / m2) ** (-(n - 1.0) / m2) * math.gamma((n - 1.0) / m2))
    tp2 = max(2.5, (16.0 * s4 * 0.4**n / (g0 * h2**2)) ** (-1.0 / (n - 1.0)))
    return {"wind": (h2, tp2, 1.0, m2), "swell": (r * hs, tp, max(1.0, gamma), 4.0)}


@pytest.mark.parametrize(
    ("hs", "tp"),
    [
        (1.0, 4.0),
        (2.5, 6.0),
        (3.25, 9.7),
        (1.0, 6.6),  # Tp = Tf (6.6 Hs^(1/3)): wind-dominated
        (1.88, 8.8),
        (4.0, 11.0),  # just above Tf: a swell peak factor below 2
        (1.5, 12.0),  # a wind sea below 1 m, its period above the 2.5 s floor
        (2.0, 14.0),
        (4.0, 18.0),
    ],
)
def test_torsethaugen_parts_follow_the_dnv_formulas_of_their_regime(hs: float, tp: float) -> None:
    parts = torsethaugen_parts(hs, tp)
    assert [p.system for p in parts] == ["wind", "swell"]
    reference = torsethaugen_reference(hs, tp)
    for part in parts:
        assert part.form == "torsethaugen"
        h, t, gamma, m = reference[part.system]
        assert part.significant_height_m == pytest.approx(h, rel=1e-12)
        assert part.peak_period_s == pytest.approx(t, rel=1e-12)
        assert part.gamma == pytest.approx(gamma, rel=1e-12)
        assert part.n_exponent == pytest.approx(0.5 * math.sqrt(hs) + 3.2, rel=1e-12)
        assert part.m_exponent == pytest.approx(m, rel=1e-12)


def test_a_calm_torsethaugen_sea_has_two_empty_systems_at_its_period() -> None:
    parts = torsethaugen_parts(0.0, 5.0)
    assert [(p.system, p.form, p.significant_height_m, p.peak_period_s) for p in parts] == [
        ("wind", "torsethaugen", 0.0, 5.0),
        ("swell", "torsethaugen", 0.0, 5.0),
    ]
    np.testing.assert_array_equal(total_density(parts, np.array([0.1, 0.2])), np.zeros(2))


def test_ochi_hubble_parts_split_hs_by_the_swells_energy_fraction_with_their_shapes() -> None:
    wind, swell = ochi_hubble_parts(2.0, 6.0, 15.0, 0.36, wind_shape=1.5, swell_shape=4.0)
    assert (wind.system, wind.form, swell.system, swell.form) == (
        "wind",
        "ochi_hubble",
        "swell",
        "ochi_hubble",
    )
    assert wind.significant_height_m == pytest.approx(1.6) and wind.peak_period_s == 6.0
    assert swell.significant_height_m == pytest.approx(1.2) and swell.peak_period_s == 15.0
    assert (wind.shape, swell.shape) == (1.5, 4.0)
    default_wind, default_swell = ochi_hubble_parts(2.0, 6.0, 15.0, 0.36)
    assert (default_wind.shape, default_swell.shape) == (1.0, 3.0)


def test_a_generator_at_its_defaults_is_plain_and_builds_exactly_the_usual_jonswap_sea() -> None:
    assert SeaGeneratorConfig().is_plain and not SeaGeneratorConfig().ramped
    for changed in (
        {"spectrum": "ochi_hubble"},
        {"speed_m_s": 2.0},
        {"hs_end_m": 3.0},
        {"tp_end_s": 9.0},
        {"swell_direction_deg": 90.0},
    ):
        assert not SeaGeneratorConfig(**changed).is_plain, changed
    assert SeaGeneratorConfig(hs_end_m=3.0).ramped and SeaGeneratorConfig(tp_end_s=9.0).ramped
    # the same seed, the same sea, whichever class realises it
    args = (2.0, 8.0, 3.3, 50, (0.5, 4.0), 0.3, 0.5)
    plain = WaveComponents(*args, np.random.default_rng(4))
    general = GeneratedSea(*args, SeaGeneratorConfig(), np.random.default_rng(4))
    for name in ("frequencies_hz", "bin_widths_hz", "directions", "omega", "encounter_omega"):
        np.testing.assert_allclose(getattr(general, name), getattr(plain, name), rtol=1e-12)
    np.testing.assert_allclose(general.elevation_phasors, plain.elevation_phasors, rtol=1e-12)
    assert general.m0 == pytest.approx(plain.m0, rel=1e-12) and general.steady
    times = np.array([0.0, 3.3, 40.0])
    np.testing.assert_allclose(general.elevation(times), plain.elevation(times), atol=1e-12)
    # and the factory picks the plain one for a plain generator
    assert isinstance(make_sea(ShipMotionConfig(), np.random.default_rng(0)), WaveComponents)
    moving = ShipMotionConfig(generator=SeaGeneratorConfig(speed_m_s=1.0))
    assert isinstance(make_sea(moving, np.random.default_rng(0)), GeneratedSea)


def test_make_sea_realises_the_configs_hs_tp_gamma_band_heading_and_spread() -> None:
    config = ShipMotionConfig(
        sea_state=None,
        significant_height_m=1.5,
        peak_period_s=7.0,
        gamma=2.5,
        n_components=400,
        band_low=0.6,
        band_high=3.0,
        wave_direction_deg=120.0,
        direction_spread_deg=20.0,
        generator=SeaGeneratorConfig(speed_m_s=1.0),
    )
    sea = make_sea(config, np.random.default_rng(1))
    assert 4.0 * math.sqrt(sea.m0) == pytest.approx(1.5, rel=1e-12)
    assert sea.gamma == 2.5 and len(sea.frequencies_hz) == 400
    assert sea.frequencies_hz.min() >= 0.6 / 7.0 and sea.frequencies_hz.max() <= 3.0 / 7.0
    edges = np.linspace(0.6 / 7.0, 3.0 / 7.0, 401)
    np.testing.assert_allclose(sea.bin_widths_hz, np.diff(edges), rtol=1e-12)
    offset = np.degrees(sea.directions) - 120.0
    assert np.all(np.abs(offset) <= 20.0 + 1e-9) and offset.min() < -19.0 and offset.max() > 19.0


def test_a_ramp_follows_a_raised_cosine_from_its_start_over_its_duration() -> None:
    generator = SeaGeneratorConfig(hs_end_m=3.0, ramp_start_s=100.0, ramp_duration_s=40.0)
    times = np.array([0.0, 100.0, 110.0, 120.0, 130.0, 140.0, 1e4])
    expected = 0.5 - 0.5 * np.cos(math.pi * np.array([0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0]))
    np.testing.assert_allclose(generator.ramp_weight(times), expected, atol=1e-15)
    hs, tp = generator.sea_parameters(1.0, 8.0, times)
    np.testing.assert_allclose(hs, 1.0 + 2.0 * expected, atol=1e-15)
    np.testing.assert_array_equal(tp, np.full(7, 8.0))  # no tp_end_s: the period stays
    hs, tp = SeaGeneratorConfig(tp_end_s=10.0).sea_parameters(1.0, 8.0, np.array([0.0, 60.0]))
    np.testing.assert_array_equal(hs, [1.0, 1.0])
    np.testing.assert_allclose(tp, [8.0, 10.0])
    # the instants the band and the peak amplitudes are taken at span the ramp
    instants = generator._ramp_instants()
    assert instants[0] == 100.0 and instants[-1] == 140.0 and len(instants) >= 9


def test_the_generators_systems_are_its_spectrums_parts_of_the_sea() -> None:
    (jonswap,) = SeaGeneratorConfig().parts(2.0, 8.0, 3.3)
    assert jonswap == SpectralPart("wind", "jonswap", 2.0, 8.0, 3.3, 5.0, 4.0)
    assert SeaGeneratorConfig(spectrum="torsethaugen").parts(2.0, 8.0, 3.3) == torsethaugen_parts(
        2.0, 8.0
    )
    ochi = SeaGeneratorConfig(
        spectrum="ochi_hubble",
        swell_peak_period_s=16.0,
        swell_energy_fraction=0.3,
        wind_shape=2.0,
        swell_shape=5.0,
    )
    assert ochi.parts(2.0, 8.0, 3.3) == ochi_hubble_parts(2.0, 8.0, 16.0, 0.3, 2.0, 5.0)


def test_a_torsethaugen_ramp_on_one_side_of_the_fully_developed_period_is_taken() -> None:
    # wind-dominated throughout (Tp <= 6.6 Hs^(1/3) at every instant)
    SeaGeneratorConfig(spectrum="torsethaugen", hs_end_m=3.0).check_sea(2.0, 6.0)
    # and from calm: a calm instant has no side (the next one is wind-dominated already)
    SeaGeneratorConfig(spectrum="torsethaugen", hs_end_m=16.0).check_sea(0.0, 2.5)
    # Tp = Tf is wind-dominated, as torsethaugen_parts takes it (Tf = 6.6 s at Hs 1 m)
    SeaGeneratorConfig(spectrum="torsethaugen", tp_end_s=5.0).check_sea(1.0, 6.6)
    # another spectrum may cross it; an unramped Torsethaugen sea has nothing to cross
    SeaGeneratorConfig(spectrum="ochi_hubble", tp_end_s=14.0).check_sea(2.0, 6.0)
    SeaGeneratorConfig(spectrum="torsethaugen").check_sea(2.0, 14.0)
    with pytest.raises(ConfigError) as info:
        SeaGeneratorConfig(spectrum="torsethaugen", tp_end_s=14.0).check_sea(2.0, 6.0)
    assert info.value.key == "generator.tp_end_s"
    assert "Hs 2.0 m, Tp 6.0 s to Hs 2 m, Tp 14 s" in str(info.value)
    assert "6.6 Hs^(1/3)" in str(info.value) and "ochi_hubble" in str(info.value)


def test_a_small_seas_torsethaugen_ramp_across_the_fully_developed_period_is_refused() -> None:
    # Hs 0.5 m: Tf = 6.6 * 0.5^(1/3) = 5.24 s, so Tp 3 s is a wind sea and 8 s a swell
    with pytest.raises(ConfigError) as info:
        SeaGeneratorConfig(spectrum="torsethaugen", tp_end_s=8.0).check_sea(0.5, 3.0)
    assert info.value.key == "generator.tp_end_s"
    assert "Hs 0.5 m, Tp 3.0 s to Hs 0.5 m, Tp 8 s" in str(info.value)
    with pytest.raises(ConfigError):
        SeaGeneratorConfig(spectrum="torsethaugen", hs_end_m=0.9, tp_end_s=3.0).check_sea(0.3, 8.0)


@pytest.mark.parametrize("spectrum", ["jonswap", "torsethaugen", "ochi_hubble"])
def test_a_generated_sea_below_a_metre_holds_its_variance_in_each_system(spectrum: str) -> None:
    generator = SeaGeneratorConfig(spectrum=spectrum, speed_m_s=1.0)
    sea = generated(generator, hs=0.8, tp=5.0, n=100)
    assert 4.0 * math.sqrt(sea.m0) == pytest.approx(0.8, rel=1e-12)
    for p, part in enumerate(generator.parts(0.8, 5.0, 1.0)):
        in_part = sea.amplitudes_m[sea.part_index == p]
        assert part.significant_height_m < 1.0
        assert np.sum(in_part**2) / 2.0 == pytest.approx(part.significant_height_m**2 / 16.0)


def test_a_generator_is_taken_from_a_mapping_and_refused_under_its_key() -> None:
    config = SeaGeneratorConfig(speed_m_s=3.0)
    assert require_generator(config) is config
    assert require_generator({"speed_m_s": 3.0}) == config
    with pytest.raises(ConfigError) as info:
        require_generator(["speed_m_s"])
    assert info.value.key == "generator"
    assert "expected a mapping of generator keys, got ['speed_m_s']" in str(info.value)
    with pytest.raises(ConfigError) as info:
        require_generator({"speed_m_s": -1.0})
    assert info.value.key == "generator.speed_m_s"
    with pytest.raises(ConfigError) as info:
        require_generator({"spectrum": "bretschneider"})
    assert info.value.key == "generator.spectrum" and "'bretschneider'" in str(info.value)
    with pytest.raises(ConfigError) as info:
        require_generator({"sped_m_s": 3.0})
    assert info.value.key == "generator" and "sped_m_s" in str(info.value)


def test_a_changing_seas_components_cover_the_band_of_every_instant_of_its_ramp() -> None:
    generator = SeaGeneratorConfig(
        spectrum="ochi_hubble", swell_peak_period_s=15.0, hs_end_m=3.0, tp_end_s=10.0
    )
    sea = generated(generator, hs=2.0, tp=6.0, n=100)
    assert not sea.steady
    wind = sea.part_index == 0
    np.testing.assert_array_equal(sea.part_index, np.repeat([0, 1], 100))
    # the wind sea's period goes from 6 s to 10 s: its band from 0.5/10 Hz to 4/6 Hz
    edges = np.linspace(0.5 / 10.0, 4.0 / 6.0, 101)
    np.testing.assert_allclose(sea.bin_widths_hz[wind], np.diff(edges), rtol=1e-12)
    position = (sea.frequencies_hz[wind] - edges[:-1]) / np.diff(edges)
    assert np.all((position >= 0.0) & (position < 1.0))
    assert position.min() < 0.05 and position.max() > 0.95
    # the swell's stays at 15 s
    np.testing.assert_allclose(sea.bin_widths_hz[~wind], np.full(100, 3.5 / 15.0 / 100), rtol=1e-12)
    np.testing.assert_allclose(sea.omega, 2.0 * math.pi * sea.frequencies_hz, rtol=1e-15)
    phase = np.mod(np.angle(sea.unit_phasors), 2.0 * math.pi)
    np.testing.assert_allclose(np.abs(sea.unit_phasors), 1.0, rtol=1e-12)
    assert phase.min() < 0.1 and phase.max() > 2.0 * math.pi - 0.1
    assert np.mean(phase < math.pi) == pytest.approx(0.5, abs=0.1)
    # each system's directions fill its own spread: the wind sea 150 +- 30, the swell with it
    # (no swell_direction_deg) +- 10 deg
    for system, half in ((wind, 30.0), (~wind, 10.0)):
        offset = np.degrees(sea.directions[system]) - 150.0
        assert np.all(np.abs(offset) <= half + 1e-9)
        assert offset.min() < -0.9 * half and offset.max() > 0.9 * half
    # amplitudes at t = 0 (before the ramp) and the largest over the ramp
    instants = generator._ramp_instants()
    grid = sea.amplitudes(instants)
    np.testing.assert_allclose(sea.peak_amplitudes_m, grid.max(axis=0), rtol=1e-12)
    np.testing.assert_allclose(sea.amplitudes_m, sea.amplitudes(np.array([0.0]))[0], rtol=1e-12)
    np.testing.assert_allclose(sea.elevation_phasors, sea.amplitudes_m * sea.unit_phasors)
    assert sea.m0 == pytest.approx(2.0**2 / 16.0, rel=1e-12)
    # each system holds its share of the variance at every instant
    for row, hs in zip(grid, generator.sea_parameters(2.0, 6.0, instants)[0], strict=True):
        assert np.sum(row[~wind] ** 2) / 2.0 == pytest.approx(0.5 * hs**2 / 16.0, rel=1e-12)
        assert np.sum(row[wind] ** 2) / 2.0 == pytest.approx(0.5 * hs**2 / 16.0, rel=1e-12)


def test_a_steady_seas_amplitudes_stay_and_a_changing_seas_rates_are_their_derivative() -> None:
    steady = generated(SeaGeneratorConfig(speed_m_s=2.0), n=20)
    times = np.array([0.0, 10.0, 500.0])
    np.testing.assert_array_equal(steady.amplitudes(times), np.tile(steady.amplitudes_m, (3, 1)))
    np.testing.assert_array_equal(steady.amplitude_rates(times), np.zeros((3, 20)))
    changing = generated(
        SeaGeneratorConfig(hs_end_m=3.0, ramp_start_s=10.0, ramp_duration_s=20.0), n=20
    )
    times = np.array([5.0, 12.0, 20.0, 27.5, 40.0])
    h = 1e-2
    numeric = (changing.amplitudes(times + h) - changing.amplitudes(times - h)) / (2.0 * h)
    np.testing.assert_allclose(changing.amplitude_rates(times), numeric, rtol=1e-3, atol=1e-9)
    assert np.all(changing.amplitude_rates(np.array([20.0])) > 0.0)
    # the phasors and their rates, of the encounter frequency
    t = np.array([3.0, 21.0])
    carrier = np.exp(1j * np.multiply.outer(t, changing.encounter_omega))
    np.testing.assert_allclose(changing.phasors(t), carrier * changing.amplitudes(t))
    numeric = (changing.phasors(t + 1e-5) - changing.phasors(t - 1e-5)) / 2e-5
    np.testing.assert_allclose(changing.phasor_rates(t), numeric, rtol=1e-5, atol=1e-8)
    assert changing.elevation(3.0).shape == ()
    assert changing.elevation(np.array([[3.0, 21.0]])).shape == (1, 2)
    np.testing.assert_allclose(
        changing.elevation(t), np.real(changing.phasors(t) @ changing.unit_phasors)
    )


def test_an_ochi_hubble_part_is_the_six_parameter_form_of_its_shape() -> None:
    hs, tp = 1.5, 9.0
    f = np.array([0.05, 0.09, 1.0 / tp, 0.14, 0.3])
    w, wp = 2.0 * math.pi * f, 2.0 * math.pi / tp
    for lam in (1.0, 2.5, 6.0):
        c = (4.0 * lam + 1.0) / 4.0
        s_w = (c * wp**4) ** lam / math.gamma(lam) * hs**2 / 4.0 / w ** (4.0 * lam + 1.0)
        s_w *= np.exp(-c * (wp / w) ** 4)
        part = SpectralPart("swell", "ochi_hubble", hs, tp, shape=lam)
        np.testing.assert_allclose(part.density(f), 2.0 * math.pi * s_w, rtol=1e-12)


def test_a_part_of_whole_number_settings_takes_whole_number_frequencies() -> None:
    for form in ("jonswap", "torsethaugen", "ochi_hubble"):
        whole = SpectralPart("wind", form, 2, 8, 3, 5, 4, 2).density([0, 1, 2])
        real = SpectralPart("wind", form, 2.0, 8.0, 3.0, 5.0, 4.0, 2.0).density([0.0, 1.0, 2.0])
        np.testing.assert_allclose(whole, real, rtol=1e-12)


def test_a_refused_torsethaugen_ramp_names_the_sea_at_its_end_and_the_way_out() -> None:
    # Hs 0.3 m, Tp 8 s (swell-dominated) to Hs 0.9 m, Tp 3 s (wind-dominated): Hs changes too
    with pytest.raises(ConfigError) as info:
        SeaGeneratorConfig(spectrum="torsethaugen", hs_end_m=0.9, tp_end_s=3.0).check_sea(0.3, 8.0)
    assert str(info.value) == (
        "generator.tp_end_s: the ramp from Hs 0.3 m, Tp 8.0 s to Hs 0.9 m, Tp 3 s crosses "
        "Tp = 6.6 Hs^(1/3) (wind- to swell-dominated Torsethaugen sea); keep the ramp on one "
        "side, or use spectrum: ochi_hubble"
    )


def test_the_amplitudes_and_phasors_take_a_time_or_times_of_any_shape_one_row_each() -> None:
    steady = generated(SeaGeneratorConfig(speed_m_s=2.0), n=20)
    changing = generated(
        SeaGeneratorConfig(hs_end_m=3.0, ramp_start_s=10.0, ramp_duration_s=20.0), n=20
    )
    times = np.array([12.0, 21.0])
    for sea in (steady, changing):
        for method in (sea.amplitudes, sea.amplitude_rates, sea.phasors, sea.phasor_rates):
            rows = method(times)
            assert rows.shape == (2, 20)
            np.testing.assert_array_equal(method(12.0), rows[:1])
            np.testing.assert_array_equal(method(times.reshape(2, 1)), rows)
            np.testing.assert_array_equal(method(times.reshape(1, 2)), rows)


def test_times_in_single_precision_are_taken_at_their_value() -> None:
    generator = SeaGeneratorConfig(hs_end_m=3.0, ramp_start_s=600.0, ramp_duration_s=40.0)
    times = np.array([610.3, 620.7, 633.1], dtype=np.float32)
    exact = times.astype(float)
    weight = generator.ramp_weight(times)
    assert weight.dtype == np.float64
    np.testing.assert_array_equal(weight, generator.ramp_weight(exact))
    # the rates' central difference is 2 ms wide whatever the times' precision
    sea = generated(generator, n=20)
    np.testing.assert_array_equal(sea.amplitude_rates(times), sea.amplitude_rates(exact))


@pytest.mark.parametrize("generated", [False, True])
def test_a_system_whose_components_all_lie_where_its_density_underflows_keeps_its_energy(
    generated: bool,
) -> None:
    # one component drawn at 0.18 of the peak frequency, where exp(-1.25 (fp/f)^4) is 0 in
    # double precision: the sea still holds Hs^2 / 16, in that component (the limit of
    # vanishing densities), at rest or met by a ship under way
    config = ShipMotionConfig(
        sea_state=None,
        significant_height_m=2.0,
        peak_period_s=8.0,
        n_components=1,
        band_low=0.1,
        band_high=1.001,
        generator=SeaGeneratorConfig(speed_m_s=1.0) if generated else SeaGeneratorConfig(),
    )
    sea = make_sea(config, np.random.default_rng(3))
    assert isinstance(sea, GeneratedSea) == generated
    assert sea.frequencies_hz[0] * 8.0 < 0.2
    assert sea.m0 == pytest.approx(2.0**2 / 16.0, rel=1e-12)
    np.testing.assert_allclose(sea.amplitudes_m, [math.sqrt(2.0 * 0.25)], rtol=1e-12)
    assert np.all(np.isfinite(sea.elevation(np.array([0.0, 5.0]))))


def test_of_components_all_in_the_underflow_the_one_nearest_the_peak_takes_the_energy() -> None:
    amplitudes = underflowed_amplitudes(np.array([0.010, 0.014, 0.012]), 0.5)
    np.testing.assert_array_equal(amplitudes, [0.0, 1.0, 0.0])
    assert underflowed_amplitudes(np.array([]), 0.5).shape == (0,)


def test_a_short_sea_whose_densities_sum_below_one_keeps_the_shape_of_its_spectrum() -> None:
    # a 1 s peak period: the densities times their bins sum to about 0.3 (in Hz^-5 units)
    sea = WaveComponents(0.2, 1.0, 3.3, 200, (0.5, 3.0), 0.0, 0.0, np.random.default_rng(0))
    density = jonswap_shape(sea.frequencies_hz, 1.0, 3.3) * sea.bin_widths_hz
    assert float(np.sum(density)) < 1.0
    np.testing.assert_allclose(
        sea.amplitudes_m**2, 2.0 * (0.2**2 / 16.0) * density / np.sum(density), rtol=1e-9
    )


def test_an_ochi_hubble_sea_all_swell_or_all_wind_sea_holds_its_height_in_that_system() -> None:
    for fraction in (1.0, 0.0):
        generator = SeaGeneratorConfig(
            spectrum="ochi_hubble", swell_energy_fraction=fraction, speed_m_s=1.0
        )
        config = ShipMotionConfig(
            sea_state=None, significant_height_m=2.0, peak_period_s=8.0, generator=generator
        )
        sea = make_sea(config, np.random.default_rng(0))
        held = {p: float(np.sum(sea.amplitudes_m[sea.part_index == p] ** 2) / 2.0) for p in (0, 1)}
        swell, wind = held[1], held[0]  # the parts: the wind sea, then the swell
        assert sea.m0 == pytest.approx(0.25, rel=1e-9)
        assert (swell, wind) == (
            pytest.approx(0.25 * fraction),
            pytest.approx(0.25 * (1 - fraction)),
        )
