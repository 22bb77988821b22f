"""A generator of seas the project has not fitted to: bimodal, at speed, changing in time.

``motion.ship.generator`` and ``motion.sea_state.generator`` (:class:`SeaGeneratorConfig`)
turn the single JONSWAP sea of a scenario into a family of other seas:

* **Bimodal spectra, swell plus wind sea** (``spectrum``): Torsethaugen's from the
  scenario's Hs and Tp, or an Ochi-Hubble of the scenario's Hs with its wind sea peaking at
  Tp and a swell of ``swell_peak_period_s`` holding ``swell_energy_fraction`` of the
  variance (formulas and references: :mod:`landing_env.waves.bimodal`, DNV-RP-C205 Sec.
  3.5.7).  The wind sea travels towards ``wave_direction_deg`` with the scenario's spread,
  the swell towards ``swell_direction_deg`` with its own, narrower, ``swell_spread_deg``.
* **Other headings and ship speeds**: the heading is ``wave_direction_deg`` (and the
  swell's); ``speed_m_s`` moves the ship ahead (along its bow, x) through the sea, so it
  meets a component of frequency w, wave number k = w^2/g and direction mu at the
  encounter frequency w_e = w - k U cos(mu) (head seas: faster; following seas: slower,
  possibly negative, i.e. the ship overtakes the waves).  The motion is the same
  superposition with w_e in time; the vessel's own oscillators (its heave, pitch and roll
  resonances and their damping) respond at w_e while the excitation keeps the wave's
  geometry (wave number k): :func:`landing_env.waves.ship.vessel_raos`.
* **A sea state that changes during the episode**: from ``ramp_start_s`` the significant
  height and peak period go from the scenario's to ``hs_end_m`` and ``tp_end_s`` over
  ``ramp_duration_s`` along a raised cosine (smooth at both ends).  The sea is then an
  evolutionary spectrum (Priestley 1965, *J. R. Stat. Soc. B* 27:204): fixed components
  whose amplitudes follow the spectrum of the moment, a_j(t) = sqrt(2 S(f_j; Hs(t), Tp(t))
  df_j), so that at every instant the variance is Hs(t)^2 / 16.  The band covers the
  spectrum's peaks over the whole ramp.  The vessel's response to a component is its RAO
  times the slowly changing amplitude (the ramp lasts many wave periods).

Each wave system is realised as in :class:`~landing_env.waves.spectrum.WaveComponents`: one
component per frequency bin, its frequency drawn inside the bin, a random phase and a
direction within the spread, all from the seeded generator, its amplitudes normalised so the
discrete variance of the system is exactly its Hs_j^2 / 16.  A generator left at its
defaults (one JONSWAP, zero speed, no ramp) builds exactly the scenario's usual sea.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from estimation.limits import Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice
from landing_env.waves.bimodal import (
    SpectralPart,
    fully_developed_period_s,
    ochi_hubble_parts,
    torsethaugen_parts,
)
from landing_env.waves.spectrum import WaveComponents, underflowed_amplitudes

GRAVITY = 9.80665
SPECTRA: tuple[str, ...] = ("jonswap", "torsethaugen", "ochi_hubble")
#: instants of the ramp at which the band and the peak amplitudes are taken
_RAMP_GRID = 17


@dataclass(frozen=True)
class SeaGeneratorConfig:
    """Which sea the scenario's Hs, Tp and heading stand for (see the module docstring).

    Units: heights m, periods s, directions degrees (the direction the waves travel
    towards, counter-clockwise from the bow: 180 head seas), speed m/s, times s from reset.
    """

    #: "jonswap" (the scenario's), "torsethaugen" or "ochi_hubble" (two systems)
    spectrum: Literal["jonswap", "torsethaugen", "ochi_hubble"] = "jonswap"
    #: direction the swell travels towards, deg; None: with the wind sea
    swell_direction_deg: float | None = limited(None, Limit(-360.0, 360.0))
    #: half-width of the uniform spread of the swell's directions, deg
    swell_spread_deg: float = limited(10.0, Limit(0.0, 180.0))
    #: ochi_hubble: share of the variance (m0) in the swell, 0-1
    swell_energy_fraction: float = limited(0.5, Limit(0.0, 1.0))
    #: ochi_hubble: the swell's peak period, s (the wind sea peaks at the scenario's Tp)
    swell_peak_period_s: float = limited(14.0, Limit(2.0, 30.0))
    #: ochi_hubble: shape lambda of the wind sea and of the swell (1: Pierson-Moskowitz's
    #: width; larger: narrower)
    wind_shape: float = limited(1.0, Limit(0.5, 20.0))
    swell_shape: float = limited(3.0, Limit(0.5, 20.0))
    #: the ship's speed ahead through the water, m/s (the bench's stand-in vessel as well)
    speed_m_s: float = limited(0.0, Limit(0.0, 20.0))
    #: the sea state at the end of the ramp: Hs (m) and Tp (s); None: unchanged
    hs_end_m: float | None = limited(None, Limit(0.0, 16.0))
    tp_end_s: float | None = limited(None, Limit(2.0, 25.0))
    #: when the ramp starts (s after the reset) and how long it lasts (s)
    ramp_start_s: float = limited(0.0, Limit(0.0, 1e5))
    ramp_duration_s: float = limited(60.0, Limit(0.0, 1e5, low_inclusive=False))

    def __post_init__(self) -> None:
        require_choice("spectrum", self.spectrum, SPECTRA)
        require_limits(self)

    @property
    def ramped(self) -> bool:
        return self.hs_end_m is not None or self.tp_end_s is not None

    @property
    def is_plain(self) -> bool:
        """Left at its defaults: the scenario's own JONSWAP sea (WaveComponents)."""
        return (
            self.spectrum == "jonswap"
            and self.speed_m_s == 0.0
            and not self.ramped
            and self.swell_direction_deg is None
        )

    def ramp_weight(self, times: np.ndarray) -> np.ndarray:
        """0 before the ramp, 1 after it, a raised cosine between."""
        elapsed = np.asarray(times, dtype=float) - self.ramp_start_s
        return 0.5 - 0.5 * np.cos(math.pi * np.clip(elapsed / self.ramp_duration_s, 0.0, 1.0))

    def sea_parameters(
        self, hs_m: float, tp_s: float, times: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Hs (m) and Tp (s) at ``times`` for a sea that starts at ``hs_m``, ``tp_s``."""
        w = self.ramp_weight(times)
        hs_end = hs_m if self.hs_end_m is None else self.hs_end_m
        tp_end = tp_s if self.tp_end_s is None else self.tp_end_s
        return hs_m + w * (hs_end - hs_m), tp_s + w * (tp_end - tp_s)

    def parts(self, hs_m: float, tp_s: float, gamma: float) -> list[SpectralPart]:
        """The wave systems of the sea of this Hs and Tp."""
        if self.spectrum == "torsethaugen":
            return torsethaugen_parts(hs_m, tp_s)
        if self.spectrum == "ochi_hubble":
            return ochi_hubble_parts(
                hs_m,
                tp_s,
                self.swell_peak_period_s,
                self.swell_energy_fraction,
                self.wind_shape,
                self.swell_shape,
            )
        return [SpectralPart("wind", "jonswap", hs_m, tp_s, gamma, 5.0, 4.0)]

    def check_sea(self, hs_m: float, tp_s: float) -> None:
        """Refuse (by key) a Torsethaugen ramp that crosses from a wind- to a swell-dominated
        sea: its systems would swap directions at once."""
        if self.spectrum != "torsethaugen" or not self.ramped:
            return
        hs, tp = self.sea_parameters(hs_m, tp_s, self._ramp_instants())
        swell = [t > fully_developed_period_s(h) for h, t in zip(hs, tp, strict=True) if h > 0]
        if len(set(swell)) > 1:
            raise ConfigError(
                "generator.tp_end_s",
                f"the ramp from Hs {hs_m} m, Tp {tp_s} s to Hs {hs[-1]:g} m, Tp {tp[-1]:g} s "
                "crosses Tp = 6.6 Hs^(1/3) (wind- to swell-dominated Torsethaugen sea); keep "
                "the ramp on one side, or use spectrum: ochi_hubble",
            )

    def _ramp_instants(self) -> np.ndarray:
        return self.ramp_start_s + self.ramp_duration_s * np.linspace(0.0, 1.0, _RAMP_GRID)


def require_generator(value: SeaGeneratorConfig | dict) -> SeaGeneratorConfig:
    """A generator config from a config or a plain mapping (YAML), errors under its key."""
    if isinstance(value, SeaGeneratorConfig):
        return value
    if not isinstance(value, dict):
        raise ConfigError("generator", f"expected a mapping of generator keys, got {value!r}")
    try:
        return SeaGeneratorConfig(**value)
    except ConfigError as exc:
        raise exc.under("generator") from exc
    except TypeError as exc:
        raise ConfigError("generator", str(exc)) from exc


class GeneratedSea:
    """A seeded sea of one or two wave systems, possibly changing, met at a ship speed.

    The interface of :class:`~landing_env.waves.spectrum.WaveComponents` (``omega``,
    ``directions``, ``elevation_phasors`` at t = 0, ``m0``, ``elevation``) plus
    ``encounter_omega`` (the frequencies met by the moving ship, rad/s), ``steady``, and for
    a changing sea ``unit_phasors`` and the amplitudes in time (``amplitudes``,
    ``amplitude_rates``, ``peak_amplitudes_m``).
    """

    def __init__(
        self,
        significant_height_m: float,
        peak_period_s: float,
        gamma: float,
        n_components: int,
        band: tuple[float, float],
        direction_rad: float,
        spread_rad: float,
        generator: SeaGeneratorConfig,
        rng: np.random.Generator,
    ) -> None:
        self.generator = generator
        self.hs_m, self.tp_s, self.gamma = float(significant_height_m), float(peak_period_s), gamma
        self.steady = not generator.ramped
        instants = generator._ramp_instants() if generator.ramped else np.zeros(1)
        hs, tp = generator.sea_parameters(self.hs_m, self.tp_s, instants)
        systems = [generator.parts(h, t, gamma) for h, t in zip(hs, tp, strict=True)]
        swell_direction = (
            direction_rad
            if generator.swell_direction_deg is None
            else math.radians(generator.swell_direction_deg)
        )
        n = int(n_components)
        freq, width, phase, direction, index = [], [], [], [], []
        for p in range(len(systems[0])):
            periods = [parts[p].peak_period_s for parts in systems]
            edges = np.linspace(band[0] / max(periods), band[1] / min(periods), n + 1)
            bins = np.diff(edges)
            freq.append(edges[:-1] + bins * rng.uniform(0.0, 1.0, n))
            width.append(bins)
            phase.append(rng.uniform(0.0, 2.0 * math.pi, n))
            swell = systems[0][p].system == "swell"
            centre = swell_direction if swell else direction_rad
            half = math.radians(generator.swell_spread_deg) if swell else spread_rad
            direction.append(centre + rng.uniform(-half, half, n))
            index.append(np.full(n, p))
        self.frequencies_hz = np.concatenate(freq)
        self.bin_widths_hz = np.concatenate(width)
        self.directions = np.concatenate(direction)
        self.part_index = np.concatenate(index)
        self.omega = 2.0 * math.pi * self.frequencies_hz
        wavenumber = self.omega**2 / GRAVITY
        self.encounter_omega = self.omega - wavenumber * generator.speed_m_s * np.cos(
            self.directions
        )
        self.unit_phasors = np.exp(1j * np.concatenate(phase))
        grid_amplitudes = np.array([self._amplitudes_of(parts) for parts in systems])
        self.peak_amplitudes_m = grid_amplitudes.max(axis=0)
        self.amplitudes_m = grid_amplitudes[0]  # the ramp has not started at t = 0
        self.elevation_phasors = self.amplitudes_m * self.unit_phasors
        self.m0 = float(np.sum(self.amplitudes_m**2) / 2.0)

    def _amplitudes_of(self, parts: list[SpectralPart]) -> np.ndarray:
        """Component amplitudes (m) for the systems ``parts``, each normalised to its m0."""
        amplitudes = np.zeros(len(self.frequencies_hz))
        for p, part in enumerate(parts):
            mask = self.part_index == p
            density = part.density(self.frequencies_hz[mask]) * self.bin_widths_hz[mask]
            total = float(np.sum(density))
            if part.significant_height_m <= 0.0:
                continue
            target = part.significant_height_m**2 / 16.0
            if total > 0.0:
                amplitudes[mask] = np.sqrt(2.0 * density * target / total)
            else:
                amplitudes[mask] = underflowed_amplitudes(self.frequencies_hz[mask], target)
        return amplitudes

    def amplitudes(self, times: np.ndarray) -> np.ndarray:
        """Component amplitudes (N, n) at ``times`` (s), metres."""
        times = np.asarray(times, dtype=float).reshape(-1)
        if self.steady:
            return np.broadcast_to(self.amplitudes_m, (len(times), len(self.amplitudes_m)))
        hs, tp = self.generator.sea_parameters(self.hs_m, self.tp_s, times)
        out = np.empty((len(times), len(self.frequencies_hz)))
        cache: dict[tuple[float, float], np.ndarray] = {}
        for i, key in enumerate(zip(hs.tolist(), tp.tolist(), strict=True)):
            row = cache.get(key)
            if row is None:
                row = self._amplitudes_of(self.generator.parts(key[0], key[1], self.gamma))
                cache[key] = row
            out[i] = row
        return out

    def amplitude_rates(self, times: np.ndarray) -> np.ndarray:
        """Time derivative of :meth:`amplitudes` (central difference, 1 ms), m/s."""
        times = np.asarray(times, dtype=float).reshape(-1)
        if self.steady:
            return np.zeros((len(times), len(self.frequencies_hz)))
        h = 1e-3
        return (self.amplitudes(times + h) - self.amplitudes(times - h)) / (2.0 * h)

    def phasors(self, times: np.ndarray) -> np.ndarray:
        """a_j(t) exp(i w_e,j t) (N, n), per unit of each component's complex unit phase."""
        times = np.asarray(times, dtype=float).reshape(-1)
        carrier = np.exp(1j * np.multiply.outer(times, self.encounter_omega))
        return carrier * self.amplitudes(times)

    def phasor_rates(self, times: np.ndarray) -> np.ndarray:
        """Time derivative of :meth:`phasors`."""
        times = np.asarray(times, dtype=float).reshape(-1)
        carrier = np.exp(1j * np.multiply.outer(times, self.encounter_omega))
        amplitudes = self.amplitudes(times)
        return carrier * (self.amplitude_rates(times) + 1j * self.encounter_omega * amplitudes)

    def elevation(self, t: float | np.ndarray) -> np.ndarray:
        """Sea-surface elevation (m) met by the ship (at its centre) at a time or times."""
        t = np.asarray(t, dtype=float)
        return np.real(self.phasors(t.reshape(-1)) @ self.unit_phasors).reshape(t.shape)


def make_sea(config, rng: np.random.Generator) -> WaveComponents | GeneratedSea:
    """The sea of a ship or bench sea config (its Hs/Tp/gamma, band, heading, generator)."""
    args = (
        config.hs,
        config.tp,
        config.gamma_in_use,
        config.n_components,
        (config.band_low, config.band_high),
        math.radians(config.wave_direction_deg),
        math.radians(config.direction_spread_deg),
    )
    if config.generator.is_plain:
        return WaveComponents(*args, rng)
    return GeneratedSea(*args, config.generator, rng)
