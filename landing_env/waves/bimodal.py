"""Two-peak wave spectra, swell plus wind sea: Torsethaugen and Ochi-Hubble (DNV-RP-C205).

Both are written as a list of :class:`SpectralPart`, one per wave system (the wind sea and
the swell), each with its own significant height and peak period, so that the sea generator
(:mod:`landing_env.waves.generator`) can give each system its own direction.  Densities are
one-sided, per hertz: S(f) in m^2/Hz, with m0 = integral S(f) df = Hs^2 / 16.

References::

    * DNV-RP-C205 (2010), *Environmental conditions and environmental loads*, Sec. 3.5.7
      (two-peak spectra): the Ochi-Hubble spectrum and the Torsethaugen spectrum.
    * Ochi & Hubble (1976), *Six-parameter wave spectra*, Proc. 15th Coastal Eng. Conf.:
      S(w) = 1/4 sum_j ((4 l_j + 1)/4 w_pj^4)^l_j / Gamma(l_j) Hs_j^2 / w^(4 l_j + 1)
      exp(-(4 l_j + 1)/4 (w_pj / w)^4), each part integrating exactly to Hs_j^2 / 16 and
      peaking at w_pj.  l_j is the shape: 1 is Pierson-Moskowitz's, larger is narrower.
    * Torsethaugen (1996), *Model for a doubly peaked wave spectrum*, SINTEF STF22 A96204, as
      DNV-RP-C205 gives it.  With Tf = 6.6 Hs^(1/3) (the peak period of a fully developed sea):
      - wind dominated (Tp <= Tf): the wind sea (primary) has Hs1 = r Hs, Tp1 = Tp with
        r = 0.7 + 0.3 exp(-(2 (Tf - Tp) / (Tf - 2 sqrt(Hs)))^2) and
        gamma = 35 (1 + 3.5 exp(-Hs)) (2 pi Hs1 / (g Tp^2))^0.857; the swell (secondary) has
        Hs2 = sqrt(1 - r^2) Hs, Tp2 = Tf + 2 s, gamma 1;
      - swell dominated (Tp > Tf): with eps = (Tp - Tf) / (25 - Tf), the swell (primary) has
        Hs1 = r Hs, Tp1 = Tp, r = 0.6 + 0.4 exp(-(eps / 0.3)^2),
        gamma = 35 (1 + 3.5 exp(-Hs)) (2 pi Hs / (g Tf^2))^0.857 (1 + 6 eps); the wind sea
        (secondary) has Hs2 = sqrt(1 - r^2) Hs, gamma 1, M = 4 (1 - 0.7 exp(-Hs / 3)) and
        Tp2 = max(2.5, (16 s4 0.4^N / (G0 Hs2^2))^(-1/(N - 1))), s4 = max(0.01, 0.08 (1 -
        exp(-Hs / 3)));
      - each part S_j(f) = Hs_j^2 Tp_j / 16 * G0 A_gamma fn^-N exp(-(N/M) fn^-M)
        gamma^exp(-(fn - 1)^2 / (2 sigma^2)), fn = f Tp_j, N = 0.5 sqrt(Hs) + 3.2, M = 4
        unless stated, sigma 0.07 below and 0.09 above the peak,
        G0 = [M^-1 (N/M)^(-(N-1)/M) Gamma((N-1)/M)]^-1 (which makes the gamma = 1 shape
        integrate to one) and A_gamma = (1 + f1 (ln gamma)^f2) / gamma with
        f1 = 4.1 (N - 2 M^0.28 + 5.3)^(0.96 - 1.45 M^0.1),
        f2 = (2.2 M^-3.3 + 0.57) N^(0.53 - 0.58 M^0.37) + 0.94 - 1.04 M^-1.9
        (a fit: the parts integrate to Hs_j^2 / 16 within 5 %; the generator normalises its
        discrete components exactly).
      A peak factor below 1 from these fits is taken as 1 (this project's guard).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.special import gamma as gamma_function

GRAVITY = 9.80665


@dataclass(frozen=True)
class SpectralPart:
    """One wave system of a spectrum: a generalised JONSWAP (``form`` "torsethaugen") or an
    Ochi-Hubble part (``form`` "ochi_hubble"), or a plain JONSWAP (``form`` "jonswap")."""

    system: str
    form: str
    significant_height_m: float
    peak_period_s: float
    #: peak enhancement factor (torsethaugen, jonswap)
    gamma: float = 1.0
    #: spectral exponents N and M (torsethaugen)
    n_exponent: float = 5.0
    m_exponent: float = 4.0
    #: Ochi-Hubble shape lambda
    shape: float = 1.0

    def density(self, frequency_hz: np.ndarray) -> np.ndarray:
        """S(f) of this part, m^2/Hz (zero at f <= 0)."""
        f = np.asarray(frequency_hz, dtype=float)
        out = np.zeros(np.shape(f))
        positive = f > 0.0
        if self.significant_height_m <= 0.0 or not positive.any():
            return out
        fp = f[positive]
        hs, tp = self.significant_height_m, self.peak_period_s
        if self.form == "ochi_hubble":
            lam = self.shape
            wp = 2.0 * math.pi / tp
            w = 2.0 * math.pi * fp
            c = (4.0 * lam + 1.0) / 4.0
            s_w = (
                0.25
                * (c * wp**4) ** lam
                / gamma_function(lam)
                * hs**2
                / w ** (4.0 * lam + 1.0)
                * np.exp(-c * (wp / w) ** 4)
            )
            out[positive] = 2.0 * math.pi * s_w
            return out
        n, m = self.n_exponent, self.m_exponent
        fn = fp * tp
        sigma = np.where(fn < 1.0, 0.07, 0.09)
        peak = self.gamma ** np.exp(-((fn - 1.0) ** 2) / (2.0 * sigma**2))
        shape = fn**-n * np.exp(-(n / m) * fn**-m) * peak
        if self.form == "jonswap":
            out[positive] = hs**2 / 16.0 * tp * shape / _shape_integral(n, m, self.gamma)
            return out
        out[positive] = hs**2 * tp / 16.0 * _g0(n, m) * _a_gamma(n, m, self.gamma) * shape
        return out


@lru_cache(maxsize=64)
def _shape_integral(n: float, m: float, gamma: float) -> float:
    """Integral over fn of the peak-enhanced shape (numerical: JONSWAP's has no closed form)."""
    grid = np.linspace(0.05, 20.0, 40_001)
    sigma = np.where(grid < 1.0, 0.07, 0.09)
    shape = grid**-n * np.exp(-(n / m) * grid**-m)
    shape = shape * gamma ** np.exp(-((grid - 1.0) ** 2) / (2.0 * sigma**2))
    return float(np.trapezoid(shape, grid))


def _g0(n: float, m: float) -> float:
    """Normaliser of fn^-N exp(-(N/M) fn^-M): one over its integral."""
    return 1.0 / ((1.0 / m) * (n / m) ** (-(n - 1.0) / m) * gamma_function((n - 1.0) / m))


def _a_gamma(n: float, m: float, gamma: float) -> float:
    """Torsethaugen's fit of the normaliser of the peak enhancement (1 at gamma = 1)."""
    if gamma <= 1.0:
        return 1.0
    f1 = 4.1 * (n - 2.0 * m**0.28 + 5.3) ** (0.96 - 1.45 * m**0.1)
    f2 = (2.2 * m**-3.3 + 0.57) * n ** (0.53 - 0.58 * m**0.37) + 0.94 - 1.04 * m**-1.9
    return (1.0 + f1 * math.log(gamma) ** f2) / gamma


def fully_developed_period_s(significant_height_m: float) -> float:
    """Tf = 6.6 Hs^(1/3): Torsethaugen's boundary between wind- and swell-dominated seas."""
    return 6.6 * significant_height_m ** (1.0 / 3.0)


def torsethaugen_parts(significant_height_m: float, peak_period_s: float) -> list[SpectralPart]:
    """The wind-sea and swell parts (in that order) of the Torsethaugen spectrum."""
    hs, tp = float(significant_height_m), float(peak_period_s)
    if hs <= 0.0:
        return [
            SpectralPart("wind", "torsethaugen", 0.0, tp),
            SpectralPart("swell", "torsethaugen", 0.0, tp),
        ]
    tf = fully_developed_period_s(hs)
    n = 0.5 * math.sqrt(hs) + 3.2
    lift = 35.0 * (1.0 + 3.5 * math.exp(-hs))
    if tp <= tf:
        r = 0.7 + 0.3 * math.exp(-((2.0 * (tf - tp) / (tf - 2.0 * math.sqrt(hs))) ** 2))
        h1 = r * hs
        gamma = max(1.0, lift * (2.0 * math.pi * h1 / (GRAVITY * tp**2)) ** 0.857)
        wind = SpectralPart("wind", "torsethaugen", h1, tp, gamma, n, 4.0)
        h2 = math.sqrt(max(0.0, 1.0 - r**2)) * hs
        swell = SpectralPart("swell", "torsethaugen", h2, tf + 2.0, 1.0, n, 4.0)
        return [wind, swell]
    eps = (tp - tf) / (25.0 - tf)
    r = 0.6 + 0.4 * math.exp(-((eps / 0.3) ** 2))
    gamma = max(1.0, lift * (2.0 * math.pi * hs / (GRAVITY * tf**2)) ** 0.857 * (1.0 + 6.0 * eps))
    swell = SpectralPart("swell", "torsethaugen", r * hs, tp, gamma, n, 4.0)
    h2 = math.sqrt(max(0.0, 1.0 - r**2)) * hs
    m2 = 4.0 * (1.0 - 0.7 * math.exp(-hs / 3.0))
    s4 = max(0.01, 0.08 * (1.0 - math.exp(-hs / 3.0)))
    tp2 = 2.5
    if h2 > 0.0:
        tp2 = max(2.5, (16.0 * s4 * 0.4**n / (_g0(n, m2) * h2**2)) ** (-1.0 / (n - 1.0)))
    wind = SpectralPart("wind", "torsethaugen", h2, float(tp2), 1.0, n, m2)
    return [wind, swell]


def ochi_hubble_parts(
    significant_height_m: float,
    wind_peak_period_s: float,
    swell_peak_period_s: float,
    swell_energy_fraction: float,
    wind_shape: float = 1.0,
    swell_shape: float = 3.0,
) -> list[SpectralPart]:
    """The wind-sea and swell parts of an Ochi-Hubble spectrum of total ``Hs``, the swell
    holding ``swell_energy_fraction`` of m0 (Hs_swell^2 = fraction Hs^2)."""
    hs = float(significant_height_m)
    swell_h = math.sqrt(swell_energy_fraction) * hs
    wind_h = math.sqrt(1.0 - swell_energy_fraction) * hs
    return [
        SpectralPart("wind", "ochi_hubble", wind_h, wind_peak_period_s, shape=wind_shape),
        SpectralPart("swell", "ochi_hubble", swell_h, swell_peak_period_s, shape=swell_shape),
    ]


def total_density(parts: list[SpectralPart], frequency_hz: np.ndarray) -> np.ndarray:
    """The sum of the parts' densities, m^2/Hz."""
    return np.sum([part.density(frequency_hz) for part in parts], axis=0)
