"""Sign and phase of the vessel's heave, pitch and roll against the wave, in a regular wave.

Conventions (landing_env/waves/ship.py, estimation/frames.py): x forward (bow), y port, z up;
Euler ZYX, so roll is positive with the port side up and pitch positive with the BOW DOWN.  A
wave travelling towards mu (counter-clockwise from the bow; 180 = head seas) has the
elevation Re(E exp(i(w t - k (x cos mu + y sin mu)))).

What standard seakeeping says, and these tests check against the wave itself (elevations at
the bow, the stern and the sides, not the model's own slope formula):

* in waves much longer than the hull and far below its natural periods the vessel contours
  the surface: heave follows the elevation at the centre, the bow is up (pitch < 0) when the
  surface is higher at the bow than at the stern, e.g. once a crest has passed the bow in
  head seas, and the port side is up (roll > 0) when the surface is higher at port;
* at a natural period the response lags its excitation by a quarter period (90 degrees),
  heave behind the elevation and roll behind the slope across the hull.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from landing_env.stewart.motion import SeaStateConfig, SeaStateMotion
from landing_env.waves.ship import GRAVITY, ShipMotionConfig
from tests.landing_env.waves.regular import regular_ship


def surface(waves, times: np.ndarray, x_m: float, y_m: float) -> np.ndarray:
    """Elevation (m) of the seeded sea at a point of the hull's frame, from the wave field."""
    k = waves.omega**2 / GRAVITY
    phase = k * (x_m * np.cos(waves.directions) + y_m * np.sin(waves.directions))
    phasors = waves.elevation_phasors * np.exp(-1j * phase)
    return np.real(np.exp(1j * np.multiply.outer(times, waves.omega)) @ phasors)


def phase_lag_deg(response: np.ndarray, excitation: np.ndarray, omega: float, t: np.ndarray):
    """Phase of ``response`` minus that of ``excitation`` at ``omega`` (deg, in (-180, 180])."""
    carrier = np.exp(-1j * omega * t)
    ratio = np.sum(response * carrier) / np.sum(excitation * carrier)
    return math.degrees(np.angle(ratio))


def test_in_long_head_waves_the_bow_is_up_where_the_surface_is_higher_at_the_bow() -> None:
    ship = regular_ship(20.0, 180.0)  # a 624 m wave under a 30 m hull
    length = ship.config.length_m
    times = np.linspace(0.0, 60.0, 2401)
    vessel = ship.vessel_poses(times)
    bow = surface(ship.waves, times, 0.5 * length, 0.0)
    stern = surface(ship.waves, times, -0.5 * length, 0.0)
    slope_x = (bow - stern) / length  # the surface's rise towards the bow
    bow_up = -vessel[:, 4]  # pitch is positive bow down
    assert np.corrcoef(bow_up, slope_x)[0, 1] > 0.999
    assert np.std(bow_up) / np.std(slope_x) == pytest.approx(1.0, abs=0.05)
    # a crest that has passed the bow (now between the bow and midships) lifts the bow
    centre = surface(ship.waves, times, 0.0, 0.0)
    quarter = surface(ship.waves, times, 0.25 * length, 0.0)
    crest_forward = (quarter > 0.99 * np.max(quarter)) & (centre < quarter)
    assert crest_forward.any() and np.all(vessel[crest_forward, 4] < 0.0)
    # heave follows the elevation at the centre, in phase
    assert np.corrcoef(vessel[:, 2], centre)[0, 1] > 0.999
    omega = float(ship.waves.omega[0])
    assert abs(phase_lag_deg(vessel[:, 2], centre, omega, times)) < 3.0
    assert abs(phase_lag_deg(bow_up, slope_x, omega, times)) < 3.0


def test_in_long_following_waves_the_bow_is_up_where_the_surface_is_higher_at_the_bow() -> None:
    ship = regular_ship(20.0, 0.0)
    length = ship.config.length_m
    times = np.linspace(0.0, 60.0, 2401)
    slope_x = (
        surface(ship.waves, times, 0.5 * length, 0.0)
        - surface(ship.waves, times, -0.5 * length, 0.0)
    ) / length
    assert np.corrcoef(-ship.vessel_poses(times)[:, 4], slope_x)[0, 1] > 0.999


@pytest.mark.parametrize("direction_deg", [90.0, -90.0])
def test_in_long_beam_waves_the_port_side_is_up_where_the_surface_is_higher_at_port(
    direction_deg: float,
) -> None:
    ship = regular_ship(25.0, direction_deg)
    beam = ship.config.beam_m
    times = np.linspace(0.0, 75.0, 3001)
    slope_y = (
        surface(ship.waves, times, 0.0, 0.5 * beam) - surface(ship.waves, times, 0.0, -0.5 * beam)
    ) / beam
    roll = ship.vessel_poses(times)[:, 3]
    assert np.corrcoef(roll, slope_y)[0, 1] > 0.99
    omega = float(ship.waves.omega[0])
    assert abs(phase_lag_deg(roll, slope_y, omega, times)) < 10.0
    # the effective wave slope: a fraction (the roll_slope_factor, 0.7) of the surface's
    assert np.std(roll) / np.std(slope_y) == pytest.approx(0.7, rel=0.1)


def test_at_its_natural_periods_the_vessel_lags_the_wave_by_a_quarter_period() -> None:
    config = ShipMotionConfig()
    times = np.linspace(0.0, 400.0, 16001)
    # roll, in beam seas at the roll period: 90 degrees behind the slope across the hull
    ship = regular_ship(config.roll_period_in_use_s, 90.0)
    beam = config.beam_m
    slope_y = (
        surface(ship.waves, times, 0.0, 0.5 * beam) - surface(ship.waves, times, 0.0, -0.5 * beam)
    ) / beam
    omega = float(ship.waves.omega[0])
    lag = phase_lag_deg(ship.vessel_poses(times)[:, 3], slope_y, omega, times)
    assert lag == pytest.approx(-90.0, abs=3.0)
    # heave, in beam seas (no length filter) at the heave period: 90 degrees behind
    ship = regular_ship(config.heave_period_s, 90.0)
    centre = surface(ship.waves, times, 0.0, 0.0)
    omega = float(ship.waves.omega[0])
    lag = phase_lag_deg(ship.vessel_poses(times)[:, 2], centre, omega, times)
    assert lag == pytest.approx(-90.0, abs=3.0)
    # a lag, never a lead, either side of the resonance
    for factor in (0.8, 1.25):
        ship = regular_ship(factor * config.heave_period_s, 90.0)
        centre = surface(ship.waves, times, 0.0, 0.0)
        omega = float(ship.waves.omega[0])
        lag = phase_lag_deg(ship.vessel_poses(times)[:, 2], centre, omega, times)
        assert -180.0 < lag < 0.0


def test_the_bench_stand_in_uses_the_same_signs() -> None:
    config = SeaStateConfig(
        sea_state=None,
        significant_height_m=1.0,
        peak_period_s=25.0,
        n_components=1,
        band_low=0.999,
        band_high=1.001,
        wave_direction_deg=135.0,  # towards port, aft: the bow and starboard rise first
        direction_spread_deg=0.0,
    )
    source = SeaStateMotion(config, np.random.default_rng(1))
    times = np.linspace(0.0, 75.0, 3001)
    d = 5.0
    slope_x = (surface(source.waves, times, d, 0) - surface(source.waves, times, -d, 0)) / (2 * d)
    slope_y = (surface(source.waves, times, 0, d) - surface(source.waves, times, 0, -d)) / (2 * d)
    poses = source.poses(times)
    assert np.corrcoef(-poses[:, 4], slope_x)[0, 1] > 0.99
    assert np.corrcoef(poses[:, 3], slope_y)[0, 1] > 0.99
    assert np.corrcoef(poses[:, 2], surface(source.waves, times, 0, 0))[0, 1] > 0.99
