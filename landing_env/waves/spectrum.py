"""Wave spectra: the JONSWAP shape, DNV's rule for its peak factor, and typical sea states.

References
----------
* Hasselmann et al. (1973), *Measurements of wind-wave growth and swell decay during the
  Joint North Sea Wave Project (JONSWAP)*, Dtsch. Hydrogr. Z. A8(12): the spectral form,
  with the peak widths sigma = 0.07 below and 0.09 above the peak.
* DNV-RP-C205 (2010), *Environmental conditions and environmental loads*, Sec. 3.5.5.5:
  without a site-specific value, the peak enhancement factor is
  gamma = 5 for Tp/sqrt(Hs) <= 3.6, exp(5.75 - 1.15 Tp/sqrt(Hs)) for 3.6 < Tp/sqrt(Hs) < 5,
  and 1 (Pierson-Moskowitz) for Tp/sqrt(Hs) >= 5 (Tp in s, Hs in m).
* Bales, Lee & Voelker (1981), DTNSRDC/SPD-0919-01, open-ocean North Atlantic table: the
  typical (Hs, Tp) of :data:`SEA_STATE_TABLE`.
"""

from __future__ import annotations

import math

import numpy as np

#: Typical (significant height m, peak period s) per WMO sea-state code.  Heights are the
#: means of the open-ocean North Atlantic table of Bales, Lee & Voelker (DTNSRDC 1981), which
#: fall inside the WMO/Douglas code bands; periods are that table's most probable modal
#: periods.  Codes 0 and 1 (calm) have no tabulated period: 3 s is this project's choice.
SEA_STATE_TABLE: dict[int, tuple[float, float]] = {
    0: (0.0, 3.0),
    1: (0.05, 3.0),
    2: (0.3, 7.5),
    3: (0.88, 7.5),
    4: (1.88, 8.8),
    5: (3.25, 9.7),
    6: (5.0, 12.4),
}


def dnv_gamma(significant_height_m: float, peak_period_s: float) -> float:
    """JONSWAP peak enhancement factor by the DNV-RP-C205 (Sec. 3.5.5.5) rule.

    A calm sea (Hs = 0) gets 1: its shape does not matter.
    """
    if significant_height_m <= 0.0:
        return 1.0
    phi = peak_period_s / math.sqrt(significant_height_m)
    if phi <= 3.6:
        return 5.0
    if phi < 5.0:
        return math.exp(5.75 - 1.15 * phi)
    return 1.0


class JonswapSeaFields:
    """Mixin of a config with ``sea_state``, ``significant_height_m``, ``peak_period_s`` and
    ``gamma`` fields: the Hs, Tp and gamma in use (the WMO table's when not given, gamma by
    :func:`dnv_gamma` when None)."""

    sea_state: int | None
    significant_height_m: float | None
    peak_period_s: float | None
    gamma: float | None

    @property
    def hs(self) -> float:
        """Significant wave height in use (m)."""
        if self.significant_height_m is not None:
            return self.significant_height_m
        return SEA_STATE_TABLE[int(self.sea_state)][0]  # type: ignore[arg-type]

    @property
    def tp(self) -> float:
        """Peak period in use (s)."""
        if self.peak_period_s is not None:
            return self.peak_period_s
        return SEA_STATE_TABLE[int(self.sea_state)][1]  # type: ignore[arg-type]

    @property
    def gamma_in_use(self) -> float:
        """JONSWAP peak factor in use: ``gamma`` or, when None, the DNV-RP-C205 rule's."""
        return dnv_gamma(self.hs, self.tp) if self.gamma is None else float(self.gamma)


def jonswap_shape(frequency_hz: np.ndarray, peak_period_s: float, gamma: float) -> np.ndarray:
    """Unnormalised JONSWAP spectral shape S(f) (arbitrary scale; normalised by Hs later).

    Pierson-Moskowitz f^-5 exp(-5/4 (fp/f)^4) times the peak enhancement
    gamma^exp(-(f - fp)^2 / (2 sigma^2 fp^2)), sigma 0.07 below and 0.09 above the peak.
    """
    f = np.asarray(frequency_hz, dtype=float)
    fp = 1.0 / peak_period_s
    sigma = np.where(f <= fp, 0.07, 0.09)
    peak = gamma ** np.exp(-((f - fp) ** 2) / (2.0 * sigma**2 * fp**2))
    return f**-5 * np.exp(-1.25 * (fp / f) ** 4) * peak


def underflowed_amplitudes(frequency_hz: np.ndarray, m0_m2: float) -> np.ndarray:
    """The amplitudes (m) of components whose spectral densities all underflow to 0, so that
    their m0 (the sum of a^2 / 2) is ``m0_m2``.

    The density of a spectrum with the Pierson-Moskowitz factor exp(-5/4 (fp/f)^4) is below
    the smallest double under about 0.2 fp, so a system of a few components can draw them all
    there (one component in a band from 0.1 fp: one seed in nine).  Their shares are then the
    limit of vanishing densities: the component nearest the peak (the highest frequency; 1 %
    lower in frequency is some 30 e-folds weaker there) takes the whole energy, as it does
    while the densities are still representable."""
    frequency_hz = np.asarray(frequency_hz, dtype=float)
    amplitudes = np.zeros(len(frequency_hz))
    if len(frequency_hz):
        amplitudes[int(np.argmax(frequency_hz))] = math.sqrt(2.0 * m0_m2)
    return amplitudes


class WaveComponents:
    """A seeded discrete JONSWAP sea: one cosine per frequency bin of the band.

    Each frequency is drawn uniformly inside its bin (so the record does not repeat), with a
    random phase and a direction drawn uniformly within ``spread`` of the mean direction.
    Amplitudes follow the spectrum and are normalised so that the spectral m0 is exactly
    Hs^2 / 16.  ``elevation_phasors`` are the complex amplitudes at t = 0 at the origin:
    elevation(t) = Re(sum E_j exp(i w_j t)).
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
        rng: np.random.Generator,
    ) -> None:
        n = int(n_components)
        fp = 1.0 / peak_period_s
        edges = np.linspace(band[0] * fp, band[1] * fp, n + 1)
        width = np.diff(edges)
        frequency = edges[:-1] + width * rng.uniform(0.0, 1.0, n)
        phase = rng.uniform(0.0, 2.0 * math.pi, n)
        direction = direction_rad + rng.uniform(-spread_rad, spread_rad, n)
        density = jonswap_shape(frequency, peak_period_s, gamma) * width
        m0_target = significant_height_m**2 / 16.0
        total = float(np.sum(density))
        if total > 0.0:
            amplitude = np.sqrt(2.0 * density * (m0_target / total))
        else:
            amplitude = underflowed_amplitudes(frequency, m0_target)
        self.frequencies_hz = frequency
        self.bin_widths_hz = width
        self.amplitudes_m = amplitude
        self.directions = direction
        self.omega = 2.0 * math.pi * frequency
        self.m0 = float(np.sum(amplitude**2) / 2.0)
        self.elevation_phasors = amplitude * np.exp(1j * phase)
        #: a stationary sea met by a ship at rest (see landing_env.waves.generator for others)
        self.steady = True
        self.encounter_omega = self.omega

    def elevation(self, t: float | np.ndarray) -> np.ndarray:
        """Sea-surface elevation (m) at the origin for a time or an array of times."""
        t = np.asarray(t, dtype=float)
        return np.real(np.exp(1j * np.multiply.outer(t, self.omega)) @ self.elevation_phasors)
