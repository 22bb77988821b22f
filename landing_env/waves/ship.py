"""A small vessel's 6-DOF motion in a JONSWAP sea, and the helideck motion it carries.

The vessel: a 10-40 m monohull (defaults: a 30 m patrol or crew-transfer vessel, 7 m beam,
1.8 m draught, block coefficient 0.45, metacentric height 1.2 m), hove-to (zero speed) in a
short-crested JONSWAP sea (:class:`~landing_env.waves.spectrum.WaveComponents`, gamma by the
DNV-RP-C205 rule).  Its response amplitude operators (RAOs), per wave component of
frequency w, wave number k = w^2/g (deep water) and direction mu (the direction the waves
travel towards, counter-clockwise from the bow: 0 following, 180 head seas):

* **Heave and pitch**: the closed-form transfer functions of Jensen, Mansour & Olsen (2004),
  *Estimation of ship motions using closed-form expressions*, Ocean Eng. 31:61-85, for a
  homogeneously loaded box of length L, breadth B = Cb * B0 and draught T, at zero speed.
  With ``k_e = |k cos mu|``, x = k_e L / 2, kappa = exp(-k_e T),
  A = 2 sin(k B / 2) exp(-k T), f = sqrt((1 - k T)^2 + (A^2 / (k B))^2) and the dynamic
  factor eta = 1 / ((1 - 2 k T) + i A^2 / (k B)) (its modulus is the paper's eta; the phase
  is that of the same second-order form):
  heave / elevation = eta kappa f sin(x) / x, and pitch / (-slope along x) =
  eta kappa f 3 (sin x - x cos x) / x^3.  The sin(x)/x and 3 (sin x - x cos x)/x^3 factors
  are the **hull-length filtering**: waves shorter than the hull average out along it
  (both tend to 1 for long waves, where the vessel follows the surface).  The resonance of
  eta (k = 1/(2T)) sets the vessel's own heave and pitch period, 2 pi sqrt(2 T / g).
* **Roll**: a single-degree-of-freedom oscillator driven by the effective wave slope across
  the hull, roll / (slope along y) = r exp(-k T / 2) (sin x / x) / (1 - (w/wr)^2 + 2 i zeta
  w/wr), with the natural period by the IMO 2008 IS Code (Part A, 2.3.4) formula
  Tr = 2 C B0 / sqrt(GM), C = 0.373 + 0.023 B0/T - 0.043 L/100, a damping ratio of 0.1
  (typical with bilge keels, e.g. Himeno 1981, *Prediction of ship roll damping*, Univ.
  Michigan NAME 239) and the effective-wave-slope factor r exp(-kT/2) (pressure at half
  draught; r = 0.7 is the IMO weather criterion's order of magnitude for small ships,
  IS Code 2.3.4).  This is this project's simplification; the 2004 paper's roll expression
  is not used.
* **Surge and sway**: the Froude-Krylov response of a free mass, the horizontal orbital
  displacement of the surface (as large as the elevation, 90 degrees ahead) averaged along
  the hull: surge = kappa (sin x / x) cos mu * orbital, sway = kappa (sin x / x) sin mu *
  orbital.  **Yaw** is held by the autopilot (zero).

The helideck: the deck frame P sits at ``helideck_position_m`` from the vessel's centre of
rotation (its centre of gravity; x forward, y port, z up).  Its pose relative to home is the
vessel's rotation R(roll, pitch, yaw) and the translation (surge, sway, heave) + R r - r, so
its vertical velocity is the heave rate plus the lever arm times the roll and pitch rates.

Sea, vessel, deck: all of it is one complex amplitude per (DOF, component), computed once per
episode from the seeded generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from estimation.limits import Limit, limited, require_limits
from landing_env.errors import ConfigError, require_range
from landing_env.waves.generator import make_sea
from landing_env.waves.sea_config import SeaConfig

GRAVITY = 9.80665


@dataclass(frozen=True)
class ShipMotionConfig(SeaConfig):
    """A sea (:class:`~landing_env.waves.sea_config.SeaConfig`), a 10-40 m vessel in it, and
    where its helideck is (see the module)."""

    HS_RANGE_M: ClassVar[tuple[float, float]] = (0.0, 16.0)
    TP_RANGE_S: ClassVar[tuple[float, float]] = (2.0, 25.0)

    n_components: int = 200
    band_high: float = 4.0
    #: 150 = bow seas 30 deg off the starboard bow, a usual heading for deck landings
    wave_direction_deg: float = limited(
        150.0, physical=Limit(-360.0, 360.0, note="from the bow, degrees")
    )
    #: hull: length, moulded breadth, draught (m), block coefficient, metacentric height (m)
    length_m: float = limited(30.0, Limit(10.0, 40.0))
    beam_m: float = 7.0
    draught_m: float = 1.8
    block_coefficient: float = limited(0.45, Limit(0.3, 1.0))
    metacentric_height_m: float = limited(1.2, Limit(0.2, 5.0))
    #: roll natural period (s); None: the IMO 2008 IS Code formula from the hull
    roll_period_s: float | None = limited(None, Limit(2.0, 30.0))
    roll_damping_ratio: float = limited(0.1, Limit(0.01, 1.0))
    #: effective wave-slope factor of roll (IMO weather criterion's r, order 0.7)
    roll_slope_factor: float = limited(0.7, Limit(0.0, 1.5))
    #: helideck centre from the centre of rotation (x forward, y port, z up), metres: aft
    #: helideck 10 m behind the CoG, 3 m above it
    helideck_position_m: tuple[float, float, float] = (-10.0, 0.0, 3.0)

    def __post_init__(self) -> None:
        self.check_sea()
        # a 10-40 m class, with proportions a monohull can have
        require_limits(self)
        require_range(
            "beam_m",
            self.beam_m,
            0.1 * self.length_m,
            0.5 * self.length_m,
            bounds_from=f"length_m = {self.length_m}",
        )
        require_range(
            "draught_m",
            self.draught_m,
            0.2,
            0.6 * self.beam_m,
            bounds_from=f"beam_m = {self.beam_m}",
        )
        position = tuple(float(v) for v in self.helideck_position_m)
        if len(position) != 3:
            raise ConfigError("helideck_position_m", f"needs 3 values, got {len(position)}")
        half = (0.5 * self.length_m, 0.5 * self.beam_m, 20.0)
        for axis, value, limit in zip("xyz", position, half, strict=True):
            require_range(
                f"helideck_position_m[{axis}]",
                value,
                -limit,
                limit,
                bounds_from=f"half of length_m = {self.length_m} and of beam_m = {self.beam_m}",
            )
        object.__setattr__(self, "helideck_position_m", position)

    @property
    def roll_period_in_use_s(self) -> float:
        """``roll_period_s`` or the IMO 2008 IS Code (Part A 2.3.4) estimate 2 C B / sqrt(GM)."""
        if self.roll_period_s is not None:
            return self.roll_period_s
        c = 0.373 + 0.023 * self.beam_m / self.draught_m - 0.043 * self.length_m / 100.0
        return 2.0 * c * self.beam_m / math.sqrt(self.metacentric_height_m)

    @property
    def heave_period_s(self) -> float:
        """The vessel's own heave (and pitch) period, 2 pi sqrt(2 T / g) (the resonance of eta)."""
        return 2.0 * math.pi * math.sqrt(2.0 * self.draught_m / GRAVITY)


def _sinc(x: np.ndarray) -> np.ndarray:
    """sin(x)/x with the limit 1 at 0."""
    return np.sinc(x / math.pi)


def _pitch_filter(x: np.ndarray) -> np.ndarray:
    """3 (sin x - x cos x) / x^3, the length filter of pitch (1 at x = 0)."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    value = 3.0 * (np.sin(safe) - safe * np.cos(safe)) / safe**3
    return np.where(small, 1.0 - x**2 / 10.0, value)


def vessel_raos(
    config: ShipMotionConfig,
    omega: np.ndarray,
    direction: np.ndarray,
    encounter_omega: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Complex RAOs per component: heave and surge/sway per metre of elevation; roll and
    pitch per unit wave slope along y and (minus) along x (see the module docstring).

    ``encounter_omega`` (rad/s, signed; None: ``omega``, a ship at rest): the frequency the
    moving ship meets each component at.  The excitation keeps the wave's geometry (its
    wave number k = w^2/g: the Smith factor, the length filters, f); the oscillators (the
    dynamic factor eta and the roll response) take the encounter frequency, their damping
    odd in it (a negative w_e is the same oscillation seen with time reversed).  This
    speed dependence is this project's extension of the zero-speed expressions."""
    k = omega**2 / GRAVITY
    length, draught = config.length_m, config.draught_m
    breadth = config.block_coefficient * config.beam_m
    cos_mu, sin_mu = np.cos(direction), np.sin(direction)
    x = 0.5 * np.abs(k * cos_mu) * length
    kappa = np.exp(-np.abs(k * cos_mu) * draught)
    a = 2.0 * np.sin(0.5 * k * breadth) * np.exp(-k * draught)
    damping = a**2 / (k * breadth)
    f = np.sqrt((1.0 - k * draught) ** 2 + damping**2)
    if encounter_omega is None:
        eta = 1.0 / ((1.0 - 2.0 * k * draught) + 1j * damping)
        oscillation = omega
    else:
        oscillation = np.asarray(encounter_omega, dtype=float)
        ke = np.maximum(oscillation**2 / GRAVITY, 1e-12)
        ae = 2.0 * np.sin(0.5 * ke * breadth) * np.exp(-ke * draught)
        damping_e = np.sign(oscillation) * ae**2 / (ke * breadth)
        eta = 1.0 / ((1.0 - 2.0 * ke * draught) + 1j * damping_e)
    length_filter = _sinc(x)
    heave = eta * kappa * f * length_filter
    pitch = eta * kappa * f * _pitch_filter(x)
    wr = 2.0 * math.pi / config.roll_period_in_use_s
    ratio = oscillation / wr
    roll_dynamics = 1.0 / (1.0 - ratio**2 + 2j * config.roll_damping_ratio * ratio)
    roll = config.roll_slope_factor * np.exp(-0.5 * k * draught) * length_filter * roll_dynamics
    planar = kappa * length_filter
    return {
        "heave": heave,
        "pitch": pitch,
        "roll": roll,
        "surge": planar * cos_mu,
        "sway": planar * sin_mu,
    }


def _rotations_zyx(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        -2,
    )


def helideck_poses(vessel: np.ndarray, lever_arm: np.ndarray) -> np.ndarray:
    """Helideck poses (N, 6) from the vessel's (surge, sway, heave, roll, pitch, yaw) (N, 6)
    at its centre of motion: the deck at ``lever_arm`` (x forward, y port, z up; m) moves
    with the hull as a rigid body, by the rotation R(roll, pitch, yaw) and the translation
    (surge, sway, heave) + R r - r; its attitude is the vessel's."""
    vessel = np.asarray(vessel, dtype=float).reshape(-1, 6)
    arm = np.asarray(lever_arm, dtype=float).reshape(3)
    rotations = _rotations_zyx(vessel[:, 3], vessel[:, 4], vessel[:, 5])
    moved = rotations @ arm - arm
    return np.concatenate([vessel[:, :3] + moved, vessel[:, 3:]], axis=1)


class ShipMotion:
    """Helideck pose relative to its home (6,): m and rad (Euler ZYX), as every motion source.

    ``vessel_poses`` gives the vessel's own (surge, sway, heave, roll, pitch, yaw) at its
    centre of rotation; ``elevation`` the sea surface there.
    """

    def __init__(self, config: ShipMotionConfig, rng: np.random.Generator) -> None:
        self.config = config
        waves = make_sea(config, rng)
        self.waves = waves
        omega = waves.omega
        self._omega = waves.encounter_omega
        # a changing sea: per unit amplitude, the amplitudes applied in time (see _phasors)
        elevation = waves.elevation_phasors if waves.steady else waves.unit_phasors
        k = omega**2 / GRAVITY
        direction = waves.directions
        slope_x = -1j * k * np.cos(direction) * elevation
        slope_y = -1j * k * np.sin(direction) * elevation
        orbital = -1j * elevation
        moving = config.generator.speed_m_s != 0.0
        rao = vessel_raos(config, omega, direction, waves.encounter_omega if moving else None)
        self._coefficients = np.array(
            [
                rao["surge"] * orbital,
                rao["sway"] * orbital,
                rao["heave"] * elevation,
                rao["roll"] * slope_y,
                -rao["pitch"] * slope_x,
                np.zeros_like(elevation),
            ]
        )
        # the motion oscillates at the encounter frequency (the wave's own at rest)
        self._rate_coefficients = self._coefficients * (1j * self._omega)
        self.lever_arm = np.asarray(config.helideck_position_m, dtype=float)
        # the deck's vertical displacement, linearised (heave + y roll - x pitch), and tilt
        lx, ly, lz = self.lever_arm
        peak = 1.0 if waves.steady else waves.peak_amplitudes_m
        largest = self._coefficients * peak
        vertical = largest[2] + ly * largest[3] - lx * largest[4]
        tilt = np.abs(largest[3]) + np.abs(largest[4])

        def reach(amplitudes: np.ndarray) -> float:
            # six standard deviations, or the sum of amplitudes when that is smaller
            six_sigma = 6.0 * math.sqrt(float(np.sum(np.abs(amplitudes) ** 2)) / 2.0)
            return min(float(np.sum(np.abs(amplitudes))), six_sigma)

        #: the deck's tilt stays below this (rad; six standard deviations)
        self.tilt_reach_rad = reach(tilt)
        #: ``|deck vertical displacement|`` stays below this (m; six standard deviations plus the
        #: lever arm's second-order drop)
        self.vertical_reach_m = reach(vertical) + abs(lz) * (
            1.0 - math.cos(min(self.tilt_reach_rad, 1.5))
        )

    def elevation(self, t: float | np.ndarray) -> np.ndarray:
        return self.waves.elevation(t)

    def vessel_poses(self, times: np.ndarray) -> np.ndarray:
        """Vessel (surge, sway, heave, roll, pitch, yaw) at its centre of rotation, (N, 6)."""
        times = np.asarray(times, dtype=float)
        if not self.waves.steady:
            return np.real(self.waves.phasors(times) @ self._coefficients.T)
        phasors = np.exp(1j * np.multiply.outer(times, self._omega))
        return np.real(phasors @ self._coefficients.T)

    def vessel_rates(self, times: np.ndarray) -> np.ndarray:
        """Time derivative of :meth:`vessel_poses`, (N, 6)."""
        times = np.asarray(times, dtype=float)
        if not self.waves.steady:
            return np.real(self.waves.phasor_rates(times) @ self._coefficients.T)
        phasors = np.exp(1j * np.multiply.outer(times, self._omega))
        return np.real(phasors @ self._rate_coefficients.T)

    def poses(self, times: np.ndarray) -> np.ndarray:
        return helideck_poses(
            self.vessel_poses(np.asarray(times, dtype=float).reshape(-1)), self.lever_arm
        )

    def pose(self, t: float) -> np.ndarray:
        return self.poses(np.array([t]))[0]

    def velocities(self, times: np.ndarray) -> np.ndarray:
        """Helideck velocity (m/s) and Euler rates (rad/s), (N, 6)."""
        times = np.asarray(times, dtype=float).reshape(-1)
        vessel = self.vessel_poses(times)
        rates = self.vessel_rates(times)
        roll, pitch, yaw = vessel[:, 3], vessel[:, 4], vessel[:, 5]
        droll, dpitch, dyaw = rates[:, 3], rates[:, 4], rates[:, 5]
        # world angular velocity of Rz(yaw) Ry(pitch) Rx(roll) from the Euler rates
        omega_w = np.stack(
            [
                np.cos(yaw) * np.cos(pitch) * droll - np.sin(yaw) * dpitch,
                np.sin(yaw) * np.cos(pitch) * droll + np.cos(yaw) * dpitch,
                -np.sin(pitch) * droll + dyaw,
            ],
            -1,
        )
        arm_w = _rotations_zyx(roll, pitch, yaw) @ self.lever_arm
        linear = rates[:, :3] + np.cross(omega_w, arm_w)
        return np.concatenate([linear, rates[:, 3:]], axis=1)

    def velocity(self, t: float) -> np.ndarray:
        return self.velocities(np.array([t]))[0]
