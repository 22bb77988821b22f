"""Motion sources for the Stewart platform: static, sums of sinusoids, a JONSWAP sea, CSV replay.

The replay of recordings (CSV or .npy, deck or vessel frame, random start per seeded episode)
lives in :mod:`landing_env.waves.recording`; its names are re-exported here.

Every source gives the commanded top-plate pose relative to the home frame as the 6-vector
``(x, y, z, roll, pitch, yaw)`` in metres and radians (Euler ZYX, see
:mod:`estimation.frames`) and its time derivative (m/s and Euler rates in rad/s).  Sources are
deterministic: all randomness is drawn once, at construction, from the ``numpy.random.Generator``
given to :func:`make_motion_source`.

Unit convention of the *configs* and of CSV files: translations in metres, angles in DEGREES
(they are written by people); the sources themselves work in radians.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from estimation.limits import Limit, limited
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.waves.generator import make_sea
from landing_env.waves.recording import CsvMotion as CsvMotion
from landing_env.waves.recording import CsvMotionConfig as CsvMotionConfig
from landing_env.waves.recording import CsvMotionError as CsvMotionError
from landing_env.waves.recording import csv_motion_from_config
from landing_env.waves.recording import write_motion_csv as write_motion_csv
from landing_env.waves.sea_config import SeaConfig
from landing_env.waves.ship import ShipMotion, ShipMotionConfig

MOTION_KINDS: tuple[str, ...] = ("static", "sinusoids", "sea_state", "ship", "csv")
AXES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")
GRAVITY = 9.80665


@runtime_checkable
class MotionSource(Protocol):
    """Commanded top-plate motion relative to the home pose."""

    def pose(self, t: float) -> np.ndarray:
        """(x, y, z, roll, pitch, yaw) at time ``t`` (s): metres and radians, shape (6,)."""
        ...

    def velocity(self, t: float) -> np.ndarray:
        """Time derivative of :meth:`pose`: m/s and Euler rates rad/s, shape (6,)."""
        ...


@runtime_checkable
class BatchMotionSource(MotionSource, Protocol):
    """A motion source that is a pure function of time and evaluates many times at once.

    The platform evaluates such a source a few physics steps ahead in one call.
    """

    def poses(self, times: np.ndarray) -> np.ndarray:
        """Poses (N, 6) at the times (N,): equal to ``pose`` at each time (to rounding)."""
        ...


def sample_poses(source: MotionSource, times: Sequence[float] | np.ndarray) -> np.ndarray:
    """Poses (N, 6) of ``source`` at ``times`` (a convenience for plots and tests)."""
    times = np.asarray(times, dtype=float).reshape(-1)
    if isinstance(source, BatchMotionSource):
        return source.poses(times)
    return np.array([source.pose(float(t)) for t in times]).reshape(-1, 6)


def _pose_from_config(values: Sequence[float]) -> np.ndarray:
    """(x, y, z [m], roll, pitch, yaw [deg]) -> SI pose."""
    pose = np.asarray(values, dtype=float).copy()
    pose[3:] = np.deg2rad(pose[3:])
    return pose


# ------------------------------------------------------------------------------- static
@dataclass(frozen=True)
class StaticMotionConfig:
    """A constant pose (e.g. the papers' static test)."""

    #: (x, y, z) in metres relative to home
    position_m: tuple[float, float, float] = limited(
        (0.0, 0.0, 0.0), physical=Limit.symmetric(100.0)
    )
    #: (roll, pitch, yaw) in degrees
    attitude_deg: tuple[float, float, float] = limited(
        (0.0, 0.0, 0.0), physical=Limit.symmetric(90.0)
    )

    def __post_init__(self) -> None:
        for name in ("position_m", "attitude_deg"):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 3:
                raise ConfigError(name, f"needs 3 values, got {len(value)}")
            object.__setattr__(self, name, value)


class StaticMotion:
    """A pose that never changes."""

    def __init__(self, pose: np.ndarray) -> None:
        self._pose = np.asarray(pose, dtype=float).reshape(6).copy()

    def pose(self, t: float) -> np.ndarray:
        return self._pose.copy()

    def poses(self, times: np.ndarray) -> np.ndarray:
        return np.tile(self._pose, (len(times), 1))

    def velocity(self, t: float) -> np.ndarray:
        return np.zeros(6)


# ------------------------------------------------------------------------------- sinusoids
def _default_amplitudes() -> tuple[tuple[float, ...], ...]:
    # Centimetres and a few degrees, like the papers' bench; peaks stay inside the default
    # workspace so the default run is never clamped.
    return ((0.03, 0.01), (0.03, 0.01), (0.05, 0.02), (5.0, 1.5), (5.0, 1.5), (3.0, 1.0))


def _default_frequencies() -> tuple[tuple[float, ...], ...]:
    # Periods of several seconds, incommensurate between axes so the motion does not repeat.
    return (
        (0.083, 0.21),
        (0.071, 0.19),
        (0.10, 0.27),
        (0.091, 0.23),
        (0.11, 0.25),
        (0.053, 0.17),
    )


@dataclass(frozen=True)
class SinusoidConfig:
    """Per axis a sum of sinusoids ``sum_k A_k sin(2 pi f_k t + phi_k)``.

    Each field holds six rows (x, y, z, roll, pitch, yaw); a row may hold any number of
    components (possibly none), the same number in every field.
    """

    #: amplitudes: metres for x, y, z; degrees for roll, pitch, yaw
    amplitudes: tuple[tuple[float, ...], ...] = limited(
        default_factory=_default_amplitudes,
        physical=Limit.non_negative(100.0, "metres and degrees"),
    )
    #: frequencies in Hz
    frequencies_hz: tuple[tuple[float, ...], ...] = limited(
        default_factory=_default_frequencies, physical=Limit.non_negative(100.0)
    )
    #: phases in degrees; None: drawn uniformly from the seed
    phases_deg: tuple[tuple[float, ...], ...] | None = limited(
        None, physical=Limit.symmetric(3600.0)
    )

    def __post_init__(self) -> None:
        amplitudes = _six_rows("amplitudes", self.amplitudes)
        frequencies = _six_rows("frequencies_hz", self.frequencies_hz)
        _same_shape("frequencies_hz", frequencies, amplitudes)
        for axis, row in zip(AXES, amplitudes, strict=True):
            for value in row:
                require_range(f"amplitudes[{axis}]", value, 0.0)
        for axis, row in zip(AXES, frequencies, strict=True):
            for value in row:
                require_range(f"frequencies_hz[{axis}]", value, 0.0, low_inclusive=False)
        object.__setattr__(self, "amplitudes", amplitudes)
        object.__setattr__(self, "frequencies_hz", frequencies)
        if self.phases_deg is not None:
            phases = _six_rows("phases_deg", self.phases_deg)
            _same_shape("phases_deg", phases, amplitudes)
            object.__setattr__(self, "phases_deg", phases)


def _six_rows(name: str, rows: Sequence[Sequence[float]]) -> tuple[tuple[float, ...], ...]:
    try:
        result = tuple(tuple(float(v) for v in row) for row in rows)
    except (TypeError, ValueError) as exc:
        raise ConfigError(name, f"needs six lists of numbers ({', '.join(AXES)})") from exc
    if len(result) != 6:
        raise ConfigError(name, f"needs six rows ({', '.join(AXES)}), got {len(result)}")
    return result


def _same_shape(name: str, rows: tuple[tuple[float, ...], ...], reference: tuple) -> None:
    for axis, row, ref in zip(AXES, rows, reference, strict=True):
        if len(row) != len(ref):
            raise ConfigError(
                name, f"row {axis} has {len(row)} values but amplitudes has {len(ref)}"
            )


class SinusoidMotion:
    """Independent sums of sinusoids on the six axes (SI units: m, rad, Hz, rad)."""

    def __init__(
        self,
        amplitudes: Sequence[Sequence[float]],
        frequencies_hz: Sequence[Sequence[float]],
        phases: Sequence[Sequence[float]],
    ) -> None:
        # Flatten to one component list with an axis index, so one call evaluates all axes.
        axis, amp, omega, phase = [], [], [], []
        for k in range(6):
            n = len(amplitudes[k])
            axis += [k] * n
            amp += list(amplitudes[k])
            omega += [2.0 * math.pi * f for f in frequencies_hz[k]]
            phase += list(phases[k])
        self._omega = np.array(omega, dtype=float)
        self._phase = np.array(phase, dtype=float)
        # Selection matrix (6, n_components) scaled by the amplitudes: pose = M @ sin(...)
        self._mix = np.zeros((6, len(amp)))
        self._mix[axis, np.arange(len(amp))] = amp

    @classmethod
    def from_config(cls, config: SinusoidConfig, rng: np.random.Generator) -> SinusoidMotion:
        """Convert the config's degrees to radians; draw missing phases from ``rng``."""
        amplitudes = [list(row) for row in config.amplitudes]
        for k in range(3, 6):
            amplitudes[k] = [math.radians(a) for a in amplitudes[k]]
        if config.phases_deg is None:
            phases = [list(rng.uniform(0.0, 2.0 * math.pi, len(row))) for row in amplitudes]
        else:
            phases = [[math.radians(p) for p in row] for row in config.phases_deg]
        return cls(amplitudes, config.frequencies_hz, phases)

    def pose(self, t: float) -> np.ndarray:
        return self._mix @ np.sin(self._omega * t + self._phase)

    def poses(self, times: np.ndarray) -> np.ndarray:
        return np.sin(np.multiply.outer(times, self._omega) + self._phase) @ self._mix.T

    def velocity(self, t: float) -> np.ndarray:
        return self._mix @ (self._omega * np.cos(self._omega * t + self._phase))


# ------------------------------------------------------------------------------- sea state
#: the physical range of a motion's period, and of its damping ratio
MOTION_PERIOD_S = Limit.positive(1e3, "ship-motion periods are seconds to a minute")
DAMPING_RATIO = Limit.non_negative(10.0, "damping ratio")


@dataclass(frozen=True)
class SeaStateConfig(SeaConfig):
    """A sea (:class:`~landing_env.waves.sea_config.SeaConfig`), a small vessel's response to it
    and its scaling onto the platform."""

    #: vessel natural periods (s) and damping ratios of its second-order responses
    heave_period_s: float = limited(3.0, physical=MOTION_PERIOD_S)
    heave_damping: float = limited(0.3, physical=DAMPING_RATIO)
    roll_period_s: float = limited(5.0, physical=MOTION_PERIOD_S)
    roll_damping: float = limited(0.1, physical=DAMPING_RATIO)
    pitch_period_s: float = limited(3.5, physical=MOTION_PERIOD_S)
    pitch_damping: float = limited(0.25, physical=DAMPING_RATIO)
    surge_sway_period_s: float = limited(10.0, physical=MOTION_PERIOD_S)
    surge_sway_damping: float = limited(0.7, physical=DAMPING_RATIO)
    yaw_period_s: float = limited(8.0, physical=MOTION_PERIOD_S)
    yaw_damping: float = limited(0.5, physical=DAMPING_RATIO)
    #: platform motion = scale * vessel motion, per axis (x, y, z, roll, pitch, yaw); the
    #: defaults make sea state 4 use most of the default workspace (occasional clamping)
    scale: tuple[float, float, float, float, float, float] = limited(
        (0.1, 0.1, 0.06, 0.7, 1.0, 3.5), physical=Limit.non_negative(100.0)
    )

    def __post_init__(self) -> None:
        self.check_sea()
        for name in ("heave", "roll", "pitch", "surge_sway", "yaw"):
            for suffix in ("period_s", "damping"):
                key = f"{name}_{suffix}"
                require_range(key, getattr(self, key), 0.0, low_inclusive=False)
        scale = tuple(float(v) for v in self.scale)
        if len(scale) != 6:
            raise ConfigError("scale", f"needs 6 values ({', '.join(AXES)}), got {len(scale)}")
        for axis, value in zip(AXES, scale, strict=True):
            require_range(f"scale[{axis}]", value, 0.0)
        object.__setattr__(self, "scale", scale)


def second_order_response(omega: np.ndarray, period_s: float, damping: float) -> np.ndarray:
    """Complex gain of 1 / (1 - (w/wn)^2 + 2 i zeta w/wn): unit gain at low frequency."""
    ratio = np.asarray(omega) * period_s / (2.0 * math.pi)
    return 1.0 / (1.0 - ratio**2 + 2j * damping * ratio)


class SeaStateMotion:
    """Platform motion that imitates a small vessel's deck in a JONSWAP sea.

    The sea is a sum of ``n`` cosines, one per frequency bin of the band, each at a frequency
    drawn uniformly inside its bin (so the record does not repeat), with a random phase and a
    random direction around the mean wave direction.  Amplitudes follow the spectrum and are
    normalised so the spectral m0 is exactly Hs^2 / 16.  The vessel (at the origin) responds
    with second-order transfer functions of unit static gain:

    * heave to the surface elevation; surge and sway to the horizontal orbital displacement
      of the surface (deep water: as large as the elevation, 90 degrees ahead, along the
      component's direction); roll to the surface slope along y and pitch to minus the slope
      along x (a raft on the surface would take exactly the slope angles); yaw to a crude
      proxy of the wave yaw moment, slope * sin(2 beta) / 2, beta the component direction.

    The platform pose is ``scale * vessel motion`` per axis.  All of it is precomputed as one
    complex amplitude per (axis, component), so a pose costs one complex exponential of n
    frequencies and a (6, n) product.
    """

    def __init__(self, config: SeaStateConfig, rng: np.random.Generator) -> None:
        self.config = config
        waves = make_sea(config, rng)
        self.waves = waves
        self.frequencies_hz = waves.frequencies_hz
        self.amplitudes_m = waves.amplitudes_m
        self.directions = direction = waves.directions
        self.m0 = waves.m0
        wavenumber = waves.omega**2 / GRAVITY  # deep-water dispersion
        # the responses oscillate at the frequency met (the vessel's speed, generator)
        omega = waves.encounter_omega
        self._omega = omega
        # a changing sea: per unit amplitude, the amplitudes applied in time (see poses)
        elevation = waves.elevation_phasors if waves.steady else waves.unit_phasors
        self._elevation = elevation
        slope = -1j * wavenumber * elevation  # d/dx of the travelling wave at the origin
        orbital = -1j * elevation  # horizontal surface displacement along the direction
        c = config
        cos_b, sin_b = np.cos(direction), np.sin(direction)
        heave = second_order_response(omega, c.heave_period_s, c.heave_damping)
        roll = second_order_response(omega, c.roll_period_s, c.roll_damping)
        pitch = second_order_response(omega, c.pitch_period_s, c.pitch_damping)
        planar = second_order_response(omega, c.surge_sway_period_s, c.surge_sway_damping)
        yaw = second_order_response(omega, c.yaw_period_s, c.yaw_damping)
        vessel = np.array(
            [
                planar * orbital * cos_b,
                planar * orbital * sin_b,
                heave * elevation,
                roll * slope * sin_b,
                -pitch * slope * cos_b,
                yaw * slope * 0.5 * np.sin(2.0 * direction),
            ]
        )
        self._coefficients = np.asarray(c.scale)[:, None] * vessel  # (6, n)
        self._rate_coefficients = self._coefficients * (1j * omega)

    @property
    def significant_height(self) -> float:
        """4 sqrt(m0) of the synthesised (unscaled) elevation spectrum, metres."""
        return 4.0 * math.sqrt(self.m0)

    def elevation(self, t: float | np.ndarray) -> np.ndarray:
        """Unscaled sea-surface elevation (m) at the vessel for a time or an array of times."""
        if not self.waves.steady:
            return self.waves.elevation(t)
        t = np.asarray(t, dtype=float)
        return np.real(np.exp(1j * np.multiply.outer(t, self._omega)) @ self._elevation)

    def pose(self, t: float) -> np.ndarray:
        if not self.waves.steady:
            return self.poses(np.array([t]))[0]
        return np.real(self._coefficients @ np.exp(1j * self._omega * t))

    def poses(self, times: np.ndarray) -> np.ndarray:
        if not self.waves.steady:
            return np.real(self.waves.phasors(times) @ self._coefficients.T)
        phasors = np.exp(1j * np.multiply.outer(times, self._omega))
        return np.real(phasors @ self._coefficients.T)

    def velocity(self, t: float) -> np.ndarray:
        if not self.waves.steady:
            return np.real(self.waves.phasor_rates(np.array([t])) @ self._coefficients.T)[0]
        return np.real(self._rate_coefficients @ np.exp(1j * self._omega * t))


# ------------------------------------------------------------------------------- forecast
class ForecastMotion:
    """The deck's motion as a forecast has it: ``truth`` up to ``t0_s`` (the past happened),
    then a cubic spline through the forecast poses ``poses`` (H, 6) at ``t0_s + horizons_s``
    (``horizons_s[0]`` = 0), held at the last one beyond.

    A look-ahead plays it in place of the episode's own motion
    (:mod:`agents.policies.deck_forecast`).  The spline starts at the true pose and velocity of
    ``t0_s`` so that the servoed deck does not jump: the forecast's own error at horizon 0
    (the HMS's noise, a few cm) is added back with a ``fade_s`` time constant, and the
    spline's second derivative is zero at its end.
    """

    def __init__(
        self,
        truth: MotionSource,
        t0_s: float,
        horizons_s: np.ndarray,
        poses: np.ndarray,
        fade_s: float = 1.0,
    ) -> None:
        from scipy.interpolate import CubicSpline

        horizons = np.asarray(horizons_s, dtype=float).reshape(-1)
        poses = np.asarray(poses, dtype=float)
        if poses.shape != (len(horizons), 6) or len(horizons) < 2:
            raise ValueError(
                f"poses must be (H, 6) at H >= 2 horizons, got {poses.shape} at {len(horizons)}"
            )
        if abs(horizons[0]) > 1e-9 or np.any(np.diff(horizons) <= 0):
            raise ValueError("horizons_s must start at 0 and increase")
        if not (np.all(np.isfinite(poses)) and math.isfinite(t0_s)):
            raise ValueError("poses and t0_s must be finite")
        require_range("fade_s", fade_s, 0.0, low_inclusive=False)
        self.truth = truth
        self.t0_s = float(t0_s)
        self.end_s = self.t0_s + float(horizons[-1])
        now = np.asarray(truth.pose(self.t0_s), dtype=float)
        joined = poses + np.outer(np.exp(-horizons / fade_s), now - poses[0])
        start_rate = np.asarray(truth.velocity(self.t0_s), dtype=float)
        self._spline = CubicSpline(
            self.t0_s + horizons, joined, axis=0, bc_type=((1, start_rate), (2, np.zeros(6)))
        )
        self._rate = self._spline.derivative()
        self._last = joined[-1]

    def poses(self, times: np.ndarray) -> np.ndarray:
        times = np.asarray(times, dtype=float).reshape(-1)
        out = np.empty((len(times), 6))
        past = times <= self.t0_s
        if past.any():
            out[past] = sample_poses(self.truth, times[past])
        ahead = ~past
        if ahead.any():
            out[ahead] = self._spline(np.minimum(times[ahead], self.end_s))
        return out

    def pose(self, t: float) -> np.ndarray:
        return self.poses(np.array([t]))[0]

    def velocity(self, t: float) -> np.ndarray:
        if t <= self.t0_s:
            return np.asarray(self.truth.velocity(t), dtype=float)
        if t >= self.end_s:
            return np.zeros(6)
        return np.asarray(self._rate(t), dtype=float)


# ------------------------------------------------------------------------------- factory
_NESTED: dict[str, type] = {
    "static": StaticMotionConfig,
    "sinusoids": SinusoidConfig,
    "sea_state": SeaStateConfig,
    "ship": ShipMotionConfig,
    "csv": CsvMotionConfig,
}


@dataclass(frozen=True)
class MotionConfig:
    """Which motion source drives the platform, with one nested config per kind."""

    kind: Literal["static", "sinusoids", "sea_state", "ship", "csv"] = "sinusoids"
    static: StaticMotionConfig = field(default_factory=StaticMotionConfig)
    sinusoids: SinusoidConfig = field(default_factory=SinusoidConfig)
    sea_state: SeaStateConfig = field(default_factory=SeaStateConfig)
    #: a full-scale vessel's helideck motion (landing_env/waves/ship.py; needs deck_mount: ship)
    ship: ShipMotionConfig = field(default_factory=ShipMotionConfig)
    csv: CsvMotionConfig = field(default_factory=CsvMotionConfig)

    def __post_init__(self) -> None:
        require_choice("kind", self.kind, MOTION_KINDS)
        # Accept plain mappings (from YAML) for the nested configs.
        for item in fields(self):
            if item.name == "kind":
                continue
            value = getattr(self, item.name)
            if isinstance(value, dict):
                try:
                    value = _NESTED[item.name](**value)
                except ConfigError as exc:
                    raise exc.under(item.name) from exc
                except TypeError as exc:
                    raise ConfigError(item.name, str(exc)) from exc
                object.__setattr__(self, item.name, value)
        if self.kind == "csv" and not self.csv.path:
            raise ConfigError("csv.path", "is required when kind is 'csv'")
        if self.kind == "csv" and not Path(self.csv.path).expanduser().is_file():
            raise ConfigError("csv.path", f"{self.csv.path!r} is not a file (motion.kind: csv)")


def make_motion_source(config: MotionConfig, rng: np.random.Generator) -> MotionSource:
    """Build the source chosen by ``config.kind``; all its randomness comes from ``rng``."""
    if config.kind == "static":
        static = config.static
        return StaticMotion(_pose_from_config((*static.position_m, *static.attitude_deg)))
    if config.kind == "sinusoids":
        return SinusoidMotion.from_config(config.sinusoids, rng)
    if config.kind == "sea_state":
        return SeaStateMotion(config.sea_state, rng)
    if config.kind == "ship":
        return ShipMotion(config.ship, rng)
    return csv_motion_from_config(config.csv, rng)
