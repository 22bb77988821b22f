"""Online identification of the deck's roll and pitch motion (the fusion's deck model).

Without a prior (given wave periods), the filter models roll and pitch each as the sum of
two damped oscillators driven by white noise (:class:`~estimation.fusion.model.TwoWaves`):
the two wave components a deck shows, a swell and a wind sea.  Rather than being told the
sea's periods and RMS, the filter fits them to its own recent roll and pitch estimates:

1. the estimates are block-averaged into samples ``sample_s`` apart over a sliding window
   of ``window_s`` (the latest seconds of the deck's motion);
2. an autoregressive model of order eight, ``y[n] = sum_k c_k y[n-k] + e[n]``, is fitted by
   least squares (the covariance method) to each axis: four pole pairs, room for the two
   components and for the estimates' noise floor, which biases a fit of order four;
3. its discrete poles ``z`` map to continuous ones ``s = ln(z) / sample_s`` (the
   impulse-invariant correspondence); the two pairs whose AR spectrum peaks highest are the
   components, each a second-order factor ``s² + 2 zeta w s + w²`` kept inside the
   physically plausible band of periods and damping ratios;
4. the axis is modelled as the SUM of the two components, each a damped oscillator driven
   by its own white noise (:class:`~estimation.fusion.model.TwoWaves`): from the AR's
   peaks, the two oscillators' frequencies, damping ratios and variances are fitted to the
   window's sample autocovariance by least squares (:func:`refine_components`; the AR
   spectrum alone smooths its peaks), and each driving noise is set so that its component
   has that variance: a swell and a wind sea of any relative size.

An AR fit is the maximum-entropy (Burg's sense) spectrum of its poles: it puts them at the
window's spectral peaks, whose widths give the damping (Box, Jenkins &
Reinsel, *Time Series Analysis*, Ch. 3; ship-motion identification by AR models: e.g.
Fossen, *Handbook of Marine Craft Hydrodynamics and Motion Control*, Sec. 10.2.2 and
Triantafyllou, Bodson & Athans, 1983).  The fit is refreshed every ``refit_s``.
"""

from __future__ import annotations

import cmath
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, nnls

from estimation.fusion.model import TwoWaves

#: the AR order of the fit: the two components and room for the noise floor
ORDER = 8
#: the frequency ratio above which two AR peaks are two components (below: one broad one)
DISTINCT = 1.25


@dataclass(frozen=True)
class AxisModel:
    """One axis' identified model: the two components' periods (s) and damping ratios, the
    RMS (rad) and the filter's model of the axis (the two components' sum)."""

    periods_s: tuple[float, float]
    damping: tuple[float, float]
    rms_rad: float
    deck4: TwoWaves


def fit_ar(samples: np.ndarray, order: int) -> np.ndarray | None:
    """Least-squares AR coefficients ``c`` (``y[n] = sum_k c[k] y[n-1-k]``), or None when the
    samples cannot determine them (too few, or not finite, or degenerate)."""
    y = np.asarray(samples, dtype=float)
    if y.ndim != 1 or len(y) < 3 * order or not np.all(np.isfinite(y)):
        return None
    rows = np.column_stack([y[order - 1 - k : len(y) - 1 - k] for k in range(order)])
    target = y[order:]
    coefficients, _, rank, _ = np.linalg.lstsq(rows, target, rcond=None)
    if rank < order or not np.all(np.isfinite(coefficients)):
        return None
    return coefficients


def _factor(
    w: float, zeta: float, period_range_s: tuple[float, float], damping_range: tuple
) -> tuple[float, float]:
    w_low, w_high = 2.0 * math.pi / period_range_s[1], 2.0 * math.pi / period_range_s[0]
    return min(max(w, w_low), w_high), min(max(zeta, damping_range[0]), damping_range[1])


def factors_from_ar(
    coefficients: np.ndarray,
    sample_s: float,
    period_range_s: tuple[float, float],
    damping_range: tuple[float, float],
) -> list[tuple[float, float]]:
    """The AR model's two dominant spectral peaks as second-order factors ``(w rad/s,
    zeta)``, slowest first, each held inside the given bands.

    Every complex pole pair inside the band of periods is a peak; the two whose AR spectrum
    is highest at their own frequency, and whose frequencies differ by more than
    :data:`DISTINCT`, are the deck's components (the other poles shape the noise floor or
    the same broad peak).  Real
    poles pair up into overdamped factors, used only when fewer than two peaks exist.  An
    unstable pole is reflected into the stable side (the same spectrum)."""
    c = np.asarray(coefficients, dtype=float)
    z = np.roots(np.concatenate([[1.0], -c]))
    s = []
    for root in z:
        if abs(root) == 0.0:
            root = 1e-6
        if abs(root) > 1.0:
            root = 1.0 / np.conj(root)
        s.append(cmath.log(root) / sample_s)
    lags = np.arange(1, len(c) + 1)
    peaks = []
    w_low, w_high = 2.0 * math.pi / period_range_s[1], 2.0 * math.pi / period_range_s[0]
    for r in (r for r in s if r.imag > 1e-9):
        w = abs(r)
        if not w_low <= w <= w_high:
            continue  # a pole outside the deck's band shapes the noise, not the deck
        # the AR spectrum 1/|A(e^{i omega T})|^2 at the pole's damped frequency
        a = 1.0 - np.sum(c * np.exp(-1j * r.imag * sample_s * lags))
        peaks.append((1.0 / max(abs(a) ** 2, 1e-300), w, -r.real / w))
    factors: list[tuple[float, float]] = []
    for _, w, zeta in sorted(peaks, reverse=True):
        # two poles within 25 % in frequency are one broad component, not two
        if all(max(w, other) / min(w, other) > DISTINCT for other, _ in factors):
            factors.append((w, zeta))
        if len(factors) == 2:
            break
    reals = sorted((r.real for r in s if abs(r.imag) <= 1e-9), reverse=True)
    for a, b in zip(reals[0::2], reals[1::2], strict=False):
        if len(factors) >= 2:
            break
        w = math.sqrt(max(a * b, 1e-12))
        factors.append((w, -(a + b) / (2.0 * w)))
    factors = [_factor(w, zeta, period_range_s, damping_range) for w, zeta in factors]
    if not factors:
        factors.append(_factor(0.0, 1.0, period_range_s, damping_range))
    if len(factors) < 2:
        # one peak: the second component starts an octave away, inside the band, broad
        w = factors[0][0]
        other = 2.0 * w if 2.0 * w <= w_high else 0.5 * w
        factors.append(_factor(other, 0.3, period_range_s, damping_range))
    return sorted(factors)


def oscillator_correlation(lags_s: np.ndarray, w: float, zeta: float) -> np.ndarray:
    """The autocorrelation of a damped oscillator driven by white noise at these lags
    (an overdamped factor is taken at the critical damping's shape, zeta held below 1)."""
    zeta = min(zeta, 0.99)
    damped = w * math.sqrt(1.0 - zeta * zeta)
    tau = np.abs(lags_s)
    return np.exp(-zeta * w * tau) * (
        np.cos(damped * tau) + zeta / math.sqrt(1.0 - zeta * zeta) * np.sin(damped * tau)
    )


def component_variances(
    samples: np.ndarray, sample_s: float, first: tuple[float, float], second: tuple[float, float]
) -> tuple[float, float]:
    """How the window's variance splits between the two components: a non-negative least-
    squares fit of the sample autocovariance, over lags up to 1.5 of the longer period (at
    most a third of the window), by the two oscillators' autocorrelations.  Each keeps at
    least 2 % of the total (no component is ruled out by one window)."""
    y = np.asarray(samples, dtype=float)
    total = float(np.mean(y * y))
    longest = 2.0 * math.pi / min(first[0], second[0])
    n_lags = int(min(1.5 * longest / sample_s, len(y) // 3)) + 1
    lags = np.arange(n_lags)
    covariance = np.array([np.mean(y[: len(y) - k] * y[k:]) for k in lags])
    basis = np.column_stack(
        [oscillator_correlation(lags * sample_s, w, zeta) for w, zeta in (first, second)]
    )
    try:
        split, _ = nnls(basis, covariance)
    except (ValueError, RuntimeError):
        split = np.zeros(2)
    if not (np.all(np.isfinite(split)) and split.sum() > 0.0):
        split = np.ones(2)
    split = np.maximum(split / split.sum(), 0.02)
    split = split / split.sum() * total
    return float(split[0]), float(split[1])


def refine_components(
    samples: np.ndarray,
    sample_s: float,
    first: tuple[float, float],
    second: tuple[float, float],
    period_range_s: tuple[float, float],
    damping_range: tuple[float, float],
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The two components ``(w, zeta, variance)`` fitted to the window's sample
    autocovariance (lags up to twice the longer period, at most a third of the window) by
    non-linear least squares, from the AR's peaks and the non-negative split as the start.

    The AR spectrum smooths its peaks (a low-order fit overstates the damping and shifts
    the periods); the autocovariance of the sum of two oscillators is exactly the model the
    filter runs, so fitting it directly gives that model's own parameters."""
    y = np.asarray(samples, dtype=float)
    var1, var2 = component_variances(y, sample_s, first, second)
    w_low, w_high = 2.0 * math.pi / period_range_s[1], 2.0 * math.pi / period_range_s[0]
    z_low, z_high = damping_range[0], min(damping_range[1], 0.99)
    longest = 2.0 * math.pi / min(first[0], second[0])
    n_lags = int(min(2.0 * longest / sample_s, len(y) // 3)) + 1
    lags = np.arange(n_lags)
    covariance = np.array([np.mean(y[: len(y) - k] * y[k:]) for k in lags])
    scale = max(float(covariance[0]), 1e-300)
    tau = lags * sample_s

    def residual(p: np.ndarray) -> np.ndarray:
        return (
            p[4] * oscillator_correlation(tau, p[0], p[1])
            + p[5] * oscillator_correlation(tau, p[2], p[3])
            - covariance / scale
        )

    def clip(value: float, low: float, high: float) -> float:
        return min(max(value, low), high)

    start = np.array(
        [
            clip(first[0], w_low, w_high),
            clip(first[1], z_low, z_high),
            clip(second[0], w_low, w_high),
            clip(second[1], z_low, z_high),
            var1 / scale,
            var2 / scale,
        ]
    )
    bounds = ([w_low, z_low, w_low, z_low, 0.0, 0.0], [w_high, z_high, w_high, z_high, 2.0, 2.0])
    try:
        p = least_squares(residual, start, bounds=bounds, max_nfev=200).x
    except (ValueError, np.linalg.LinAlgError):
        p = start
    if not np.all(np.isfinite(p)) or max(p[0], p[2]) / min(p[0], p[2]) <= DISTINCT:
        p = start  # the fit merged the two components: keep the AR's distinct peaks
    total = float(np.mean(y * y))
    shares = np.maximum(p[4:] / max(p[4] + p[5], 1e-12), 0.02)
    shares = shares / shares.sum() * total
    one = (float(p[0]), float(p[1]), float(shares[0]))
    two = (float(p[2]), float(p[3]), float(shares[1]))
    return (one, two) if one[0] <= two[0] else (two, one)


class DeckMotionIdentifier:
    """Sliding-window AR identification of the deck's roll and pitch (module docstring)."""

    def __init__(
        self,
        window_s: float,
        sample_s: float,
        min_window_s: float,
        refit_s: float,
        period_range_s: tuple[float, float],
        damping_range: tuple[float, float],
        noise_gain: float = 1.0,
        order: int = ORDER,
    ) -> None:
        self.order = int(order)
        self.window_s = float(window_s)
        self.sample_s = float(sample_s)
        self.min_window_s = float(min_window_s)
        self.refit_s = float(refit_s)
        self.period_range_s = period_range_s
        self.damping_range = damping_range
        self.noise_gain = float(noise_gain)
        self.reset()

    def reset(self) -> None:
        self._samples: deque[tuple[float, float]] = deque(
            maxlen=max(round(self.window_s / self.sample_s), 3 * self.order)
        )
        self._bin: int | None = None
        self._sum = np.zeros(2)
        self._count = 0
        self._last_fit = -math.inf
        self.models: tuple[AxisModel, AxisModel] | None = None

    @property
    def span_s(self) -> float:
        """Seconds of motion in the window."""
        return len(self._samples) * self.sample_s

    def add(self, time: float, roll: float, pitch: float) -> bool:
        """One estimate of the deck's roll and pitch (rad) at ``time``; True when the model
        was refitted.  Estimates arrive in time order; a gap longer than two samples restarts
        the window (the motion before it no longer joins on); the model fitted before the gap
        stays until the new window is long enough to refit."""
        if not (math.isfinite(time) and abs(roll) <= math.pi and abs(pitch) <= math.pi):
            return False  # not an angle (also NaN)
        index = math.floor(time / self.sample_s)
        if self._bin is not None and index != self._bin:
            if self._count:
                if index > self._bin + 2:
                    self._samples.clear()
                self._samples.append(tuple(self._sum / self._count))
            self._sum[:] = 0.0
            self._count = 0
        self._bin = index
        self._sum += (roll, pitch)
        self._count += 1
        if self.span_s < self.min_window_s or time - self._last_fit < self.refit_s:
            return False
        self._last_fit = time
        return self._fit()

    def _fit(self) -> bool:
        data = np.asarray(self._samples)
        models = []
        for axis in range(2):
            y = data[:, axis]
            coefficients = fit_ar(y, self.order)
            rms = float(np.sqrt(np.mean(y * y)))
            if coefficients is None or not 0.0 < rms < math.inf:
                return False
            first, second = factors_from_ar(
                coefficients, self.sample_s, self.period_range_s, self.damping_range
            )
            (w1, z1, var1), (w2, z2, var2) = refine_components(
                y, self.sample_s, first, second, self.period_range_s, self.damping_range
            )
            gain = self.noise_gain
            model = TwoWaves.matched(w1, z1, w2, z2, gain * var1, gain * var2)
            models.append(AxisModel((2.0 * math.pi / w1, 2.0 * math.pi / w2), (z1, z2), rms, model))
        self.models = (models[0], models[1])
        return True

    @property
    def deck4(self) -> tuple | None:
        """The identified model in the filter's form (None before the first fit)."""
        return None if self.models is None else tuple(m.deck4 for m in self.models)
