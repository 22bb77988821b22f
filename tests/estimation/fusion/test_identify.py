"""The identification's parts, each on its own: the AR model's peaks (the two highest inside
the band of periods, an unstable pole taken as its reflection), the oscillator's
autocorrelation, the split of the variance and its refinement (stand-ins for SciPy's fits
see what they are given)."""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm, solve_continuous_lyapunov

from estimation.fusion import identify
from estimation.fusion.identify import (
    ORDER,
    AxisModel,
    DeckMotionIdentifier,
    component_variances,
    factors_from_ar,
    fit_ar,
    oscillator_correlation,
    refine_components,
)
from estimation.fusion.model import TwoWaves

SAMPLE_S = 0.5
PERIOD_RANGE_S = (2.0, 30.0)
DAMPING_RANGE = (0.05, 2.0)


def pole_pair(period_s: float, radius: float) -> list[complex]:
    """A discrete pole pair of the given period and radius (1: undamped)."""
    turn = 2.0 * math.pi * SAMPLE_S / period_s
    return [
        radius * complex(math.cos(turn), math.sin(turn)),
        radius * complex(math.cos(turn), -math.sin(turn)),
    ]


def ar_coefficients(poles: list[complex]) -> np.ndarray:
    """``c`` of ``y[n] = sum_k c[k] y[n-1-k]`` whose characteristic roots are ``poles``."""
    return -np.real(np.poly(poles))[1:]


def test_the_strong_pole_pair_is_the_wind_sea_not_a_weak_one_beside_it() -> None:
    # a 12 s swell and a 5 s wind sea, both sharp; a weak broad pair at 5.8 s (within the
    # 25 % that makes one component) and two real poles: the noise floor of an order-8 fit
    poles = [
        *pole_pair(12.0, 0.98),
        *pole_pair(5.0, 0.98),
        *pole_pair(5.8, 0.7),
        0.3,
        -0.2,
    ]
    coefficients = ar_coefficients(poles)
    assert len(coefficients) == ORDER
    (swell_w, swell_zeta), (wind_w, wind_zeta) = factors_from_ar(
        coefficients, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE
    )
    assert 2.0 * math.pi / swell_w == pytest.approx(12.0, rel=0.01)
    assert 2.0 * math.pi / wind_w == pytest.approx(5.0, rel=0.01)
    # the sharp pair's damping, not the broad one's (about 0.55)
    assert swell_zeta < 0.1 and wind_zeta < 0.1


def oscillator_in_state_space(w: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """The damped oscillator ``x'' + 2 zeta w x' + w² x = noise`` as ``(A, P)``: its state
    matrix and its stationary covariance (Lyapunov: ``A P + P Aᵀ + Q = 0``)."""
    a = np.array([[0.0, 1.0], [-w * w, -2.0 * zeta * w]])
    return a, solve_continuous_lyapunov(a, -np.diag([0.0, 1.0]))


@settings(max_examples=30, deadline=None)
@given(
    w=st.floats(0.2, 3.0),
    zeta=st.floats(0.01, 0.95),
    lags_s=st.lists(st.floats(-20.0, 20.0), min_size=1, max_size=5),
)
def test_the_oscillators_correlation_is_its_state_space_models_at_every_lag(
    w: float, zeta: float, lags_s: list[float]
) -> None:
    a, p = oscillator_in_state_space(w, zeta)
    expected = [(expm(a * abs(lag)) @ p)[0, 0] / p[0, 0] for lag in lags_s]
    found = oscillator_correlation(np.array(lags_s), w, zeta)
    assert found == pytest.approx(expected, abs=1e-9)


def test_an_overdamped_oscillators_correlation_takes_the_shape_of_damping_0_99() -> None:
    lags_s = np.linspace(0.0, 10.0, 21)
    a, p = oscillator_in_state_space(0.8, 0.99)
    expected = [(expm(a * lag) @ p)[0, 0] / p[0, 0] for lag in lags_s]
    for zeta in (0.99, 1.0, 1.7):
        assert oscillator_correlation(lags_s, 0.8, zeta) == pytest.approx(expected, abs=1e-9)


def test_an_unstable_pole_pair_is_taken_as_its_reflection_inside_the_unit_circle() -> None:
    unstable = ar_coefficients([*pole_pair(12.0, 1.05), *pole_pair(5.0, 0.9)])
    reflected = ar_coefficients([*pole_pair(12.0, 1.0 / 1.05), *pole_pair(5.0, 0.9)])
    found = factors_from_ar(unstable, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    assert np.array(found) == pytest.approx(
        np.array(factors_from_ar(reflected, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)), rel=1e-9
    )
    # the swell's factor is the reflected pole's s = ln(z) / T: damped, not held at the floor
    s = cmath.log(pole_pair(12.0, 1.0 / 1.05)[0]) / SAMPLE_S
    assert found[0] == pytest.approx((abs(s), -s.real / abs(s)), rel=1e-9)


def test_poles_outside_the_band_of_periods_are_not_the_decks_components() -> None:
    # the sharpest pairs are at 40 s and 1.6 s, outside 2-30 s: the components are the
    # broader pairs inside it, at the periods and damping of s = ln(z) / T
    inside = [pole_pair(25.0, 0.95)[0], pole_pair(3.0, 0.95)[0]]
    coefficients = ar_coefficients(
        [
            *pole_pair(40.0, 0.99),
            *pole_pair(1.6, 0.995),
            *pole_pair(25.0, 0.95),
            *pole_pair(3.0, 0.95),
        ]
    )
    found = factors_from_ar(coefficients, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    expected = []
    for z in inside:
        s = cmath.log(z) / SAMPLE_S
        expected.append((abs(s), max(-s.real / abs(s), DAMPING_RANGE[0])))
    assert np.array(found) == pytest.approx(np.array(expected), rel=1e-6)


def test_real_poles_alone_give_a_factor_held_at_the_longest_period_and_one_an_octave_up() -> None:
    # two real poles near 1: an overdamped factor far below the band, held at its edge
    (slow_w, slow_zeta), (other_w, other_zeta) = factors_from_ar(
        ar_coefficients([0.999, 0.998]), SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE
    )
    a, b = math.log(0.999) / SAMPLE_S, math.log(0.998) / SAMPLE_S
    assert slow_w == pytest.approx(2.0 * math.pi / PERIOD_RANGE_S[1], rel=1e-12)
    assert slow_zeta == pytest.approx(-(a + b) / (2.0 * math.sqrt(a * b)), rel=1e-9)
    assert (other_w, other_zeta) == pytest.approx((2.0 * slow_w, 0.3), rel=1e-12)


def two_tones(n: int) -> np.ndarray:
    """A 12 s swell of amplitude 2 and a 5 s wind sea of amplitude 1, sampled every 0.5 s:
    80 % and 20 % of the variance."""
    t = np.arange(n) * SAMPLE_S
    return 2.0 * np.cos(2.0 * math.pi * t / 12.0) + np.cos(2.0 * math.pi * t / 5.0 + 1.0)


SWELL = (2.0 * math.pi / 12.0, 0.02)
WIND_SEA = (2.0 * math.pi / 5.0, 0.02)


def test_the_variance_splits_between_the_components_as_the_window_holds_them() -> None:
    y = two_tones(600)
    swell, wind_sea = component_variances(y, SAMPLE_S, SWELL, WIND_SEA)
    assert swell + wind_sea == pytest.approx(float(np.mean(y * y)), rel=1e-12)
    assert (swell, wind_sea) == pytest.approx((0.8 * 2.5, 0.2 * 2.5), abs=0.1)


@pytest.mark.parametrize(
    ("n", "lags"),
    [(600, int(1.5 * 12.0 / SAMPLE_S) + 1), (61, 61 // 3 + 1)],
    ids=["one-and-a-half-periods", "a-third-of-the-window"],
)
def test_the_split_fits_the_autocovariance_up_to_one_and_a_half_longer_periods(
    monkeypatch: pytest.MonkeyPatch, n: int, lags: int
) -> None:
    """The non-negative fit is of the sample autocovariance by the two oscillators'
    autocorrelations, over lags up to 1.5 of the longer period, at most a third of the
    window (a stand-in for SciPy's ``nnls`` sees what it is given)."""
    seen = {}

    def fit(basis: np.ndarray, covariance: np.ndarray) -> tuple[np.ndarray, float]:
        seen.update(basis=basis, covariance=covariance)
        return np.array([3.0, 1.0]), 0.0

    monkeypatch.setattr(identify, "nnls", fit)
    y = two_tones(n)
    total = float(np.mean(y * y))
    assert component_variances(y, SAMPLE_S, SWELL, WIND_SEA) == pytest.approx(
        (0.75 * total, 0.25 * total), rel=1e-12
    )
    tau = np.arange(lags) * SAMPLE_S
    assert seen["covariance"] == pytest.approx([np.mean(y[: n - k] * y[k:]) for k in range(lags)])
    assert seen["basis"] == pytest.approx(
        np.column_stack(
            [oscillator_correlation(tau, *SWELL), oscillator_correlation(tau, *WIND_SEA)]
        )
    )


@pytest.mark.parametrize(
    ("split", "shares"),
    [
        ((0.3, 0.2), (0.6, 0.4)),
        ((1.0, 0.0), (1.0 / 1.02, 0.02 / 1.02)),
        ((10.0, 0.1), (10.0 / 10.1 / (10.0 / 10.1 + 0.02), 0.02 / (10.0 / 10.1 + 0.02))),
        ((0.0, 0.0), (0.5, 0.5)),
        ((math.nan, 1.0), (0.5, 0.5)),
        (ValueError, (0.5, 0.5)),
    ],
    ids=[
        "as-fitted",
        "at-least-2-percent",
        "2-percent-of-the-fitted-sum",
        "none-fitted",
        "not-finite",
        "fit-failed",
    ],
)
def test_each_component_keeps_its_fitted_share_and_at_least_2_percent(
    monkeypatch: pytest.MonkeyPatch, split: object, shares: tuple[float, float]
) -> None:
    def fit(basis: np.ndarray, covariance: np.ndarray) -> tuple[np.ndarray, float]:
        if split is ValueError:
            raise ValueError("no fit")
        return np.array(split), 0.0

    monkeypatch.setattr(identify, "nnls", fit)
    y = two_tones(600)
    total = float(np.mean(y * y))
    found = component_variances(y, SAMPLE_S, SWELL, WIND_SEA)
    assert found == pytest.approx((shares[0] * total, shares[1] * total), rel=1e-12)


class LeastSquares:
    """A stand-in for SciPy's ``least_squares``: keeps what it is given and returns ``x``
    (or raises ``error``)."""

    def __init__(self, x: list[float] | None = None, error: type | None = None) -> None:
        self.x, self.error, self.call = x, error, {}

    def __call__(
        self, fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, bounds: tuple, max_nfev: int
    ) -> object:
        self.call = {"fun": fun, "x0": np.array(x0), "bounds": bounds, "max_nfev": max_nfev}
        if self.error is not None:
            raise self.error("no fit")
        return type("Result", (), {"x": np.array(self.x)})()


BAND_S = (4.0, 20.0)
W_LOW, W_HIGH = 2.0 * math.pi / BAND_S[1], 2.0 * math.pi / BAND_S[0]


def refine(
    monkeypatch: pytest.MonkeyPatch,
    fit: LeastSquares,
    y: np.ndarray,
    first: tuple[float, float],
    second: tuple[float, float],
) -> tuple:
    monkeypatch.setattr(identify, "least_squares", fit)
    return refine_components(y, SAMPLE_S, first, second, BAND_S, (0.05, 1.5))


def test_the_refinement_starts_from_the_peaks_and_split_held_in_the_bands(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The start is the AR's peaks held inside the bands of frequency and damping (below
    0.99, where the oscillator's correlation has its shape) and the split as shares of the
    window's variance; the bounds are the bands and shares up to 2; 200 evaluations."""
    y = two_tones(600)
    first, second = (0.2, 1.2), (2.0, 0.01)  # below and above the band of periods
    fit = LeastSquares([0.5, 0.1, 1.0, 0.2, 0.5, 0.5])
    refine(monkeypatch, fit, y, first, second)
    var1, var2 = component_variances(y, SAMPLE_S, first, second)
    total = float(np.mean(y * y))
    assert fit.call["x0"] == pytest.approx([W_LOW, 0.99, W_HIGH, 0.05, var1 / total, var2 / total])
    assert fit.call["bounds"] == (
        [W_LOW, 0.05, W_LOW, 0.05, 0.0, 0.0],
        [W_HIGH, 0.99, W_HIGH, 0.99, 2.0, 2.0],
    )
    assert fit.call["max_nfev"] == 200


@pytest.mark.parametrize(
    ("n", "lags"),
    [(600, int(2.0 * 12.0 / SAMPLE_S) + 1), (61, 61 // 3 + 1)],
    ids=["two-periods", "a-third-of-the-window"],
)
def test_the_refinement_fits_the_autocovariance_up_to_two_longer_periods(
    monkeypatch: pytest.MonkeyPatch, n: int, lags: int
) -> None:
    """The residual is the two oscillators' autocovariance less the window's, relative to
    the window's variance, over lags up to twice the longer period (at most a third of the
    window)."""
    y = two_tones(n)
    fit = LeastSquares([0.5, 0.1, 1.0, 0.2, 0.5, 0.5])
    refine(monkeypatch, fit, y, SWELL, WIND_SEA)
    p = np.array([0.6, 0.1, 1.3, 0.3, 0.7, 0.4])
    tau = np.arange(lags) * SAMPLE_S
    covariance = np.array([np.mean(y[: n - k] * y[k:]) for k in range(lags)])
    expected = (
        0.7 * oscillator_correlation(tau, 0.6, 0.1)
        + 0.4 * oscillator_correlation(tau, 1.3, 0.3)
        - covariance / np.mean(y * y)
    )
    assert fit.call["fun"](p) == pytest.approx(expected)


def test_the_refined_components_come_slowest_first_with_their_shares_of_the_variance(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    y = two_tones(600)
    total = float(np.mean(y * y))
    # the faster component first, shares 0.9 and 0.005 (held at 2 %), not summing to 1
    fit = LeastSquares([1.3, 0.3, 0.6, 0.1, 0.9, 0.005])
    slow, fast = refine(monkeypatch, fit, y, SWELL, WIND_SEA)
    shares = np.array([0.9 / 0.905, 0.02])
    shares = shares / shares.sum() * total
    assert slow == pytest.approx((0.6, 0.1, shares[1]))
    assert fast == pytest.approx((1.3, 0.3, shares[0]))


@pytest.mark.parametrize(
    "fit",
    [
        LeastSquares([0.5, 0.1, 0.625, 0.2, 0.5, 0.5]),
        LeastSquares([0.625, 0.1, 0.5, 0.2, 0.5, 0.5]),
        LeastSquares([math.nan, 0.1, 1.0, 0.2, 0.5, 0.5]),
        LeastSquares(error=ValueError),
        LeastSquares(error=np.linalg.LinAlgError),
    ],
    ids=["merged", "merged-faster-first", "not-finite", "refused", "singular"],
)
def test_a_refinement_that_merges_the_components_or_fails_keeps_the_start(
    monkeypatch: pytest.MonkeyPatch, fit: LeastSquares
) -> None:
    """Two frequencies within a ratio of 1.25 (here exactly 1.25) are one component: the
    AR's distinct peaks are kept, as when the fit fails."""
    y = two_tones(600)
    (w1, z1, v1), (w2, z2, v2) = refine(monkeypatch, fit, y, SWELL, WIND_SEA)
    var1, var2 = component_variances(y, SAMPLE_S, SWELL, WIND_SEA)
    # the start: the peaks with their damping held at the band's floor
    assert (w1, z1, w2, z2) == pytest.approx((SWELL[0], 0.05, WIND_SEA[0], 0.05))
    assert (v1, v2) == pytest.approx((var1, var2))


def test_a_pole_at_zero_is_taken_at_a_millionth() -> None:
    # y[n] = 0.999 y[n-1]: poles 0.999 and 0 (the order-2 fit's second lag unused); the two
    # real poles pair into one overdamped factor, the pole at 0 taken at 1e-6
    (w, zeta), _ = factors_from_ar(np.array([0.999, 0.0]), SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    a, b = math.log(0.999) / SAMPLE_S, math.log(1e-6) / SAMPLE_S
    assert w == pytest.approx(math.sqrt(a * b), rel=1e-9)
    assert zeta == DAMPING_RANGE[1]  # -(a + b) / 2w is far above the band


def peak(period_s: float, radius: float) -> tuple[float, float]:
    """The factor ``(w, zeta)`` of a discrete pole pair: ``s = ln(z) / T``."""
    s = cmath.log(pole_pair(period_s, radius)[0]) / SAMPLE_S
    return abs(s), -s.real / abs(s)


def real_pair(one: float, two: float) -> tuple[float, float]:
    """The overdamped factor ``(w, zeta)`` of two real discrete poles."""
    a, b = math.log(one) / SAMPLE_S, math.log(two) / SAMPLE_S
    w = math.sqrt(a * b)
    return w, -(a + b) / (2.0 * w)


def test_of_three_distinct_peaks_the_two_highest_are_the_components() -> None:
    coefficients = ar_coefficients(
        [*pole_pair(20.0, 0.99), *pole_pair(8.0, 0.97), *pole_pair(3.0, 0.6)]
    )
    found = factors_from_ar(coefficients, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    assert np.array(found) == pytest.approx(np.array([peak(20.0, 0.99), peak(8.0, 0.97)]))


def test_one_peak_takes_the_slowest_two_real_poles_as_its_second_factor() -> None:
    # a 12 s pair and four real poles: the second factor is the two slowest (nearest 1), not
    # the fastest, and the complex pair's own real parts are not real poles
    coefficients = ar_coefficients([*pole_pair(12.0, 0.95), 0.9, 0.8, 0.3, 0.2])
    found = factors_from_ar(coefficients, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    assert np.array(found) == pytest.approx(np.array([real_pair(0.9, 0.8), peak(12.0, 0.95)]))


def test_real_poles_alone_pair_up_slowest_first_into_two_overdamped_factors() -> None:
    coefficients = ar_coefficients([0.9, 0.8, 0.3, 0.2])
    found = factors_from_ar(coefficients, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    assert np.array(found) == pytest.approx(np.array([real_pair(0.9, 0.8), real_pair(0.3, 0.2)]))


def test_no_peak_in_the_band_and_no_real_pole_give_the_longest_period_and_an_octave_up() -> None:
    # one sharp pair at 1.5 s, outside the band: a critically damped factor at 30 s, and the
    # second component an octave up with damping 0.3
    found = factors_from_ar(
        ar_coefficients(pole_pair(1.5, 0.9)), SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE
    )
    w_low = 2.0 * math.pi / PERIOD_RANGE_S[1]
    assert np.array(found) == pytest.approx(np.array([(w_low, 1.0), (2.0 * w_low, 0.3)]), rel=1e-12)


@pytest.mark.parametrize(
    ("period_s", "octave"),
    [(5.0, 2.0), (3.0, 0.5)],
    ids=["up-inside-the-band", "down-when-up-leaves-it"],
)
def test_a_single_peaks_second_component_starts_an_octave_away_inside_the_band(
    period_s: float, octave: float
) -> None:
    w, zeta = peak(period_s, 0.9)
    found = factors_from_ar(
        ar_coefficients(pole_pair(period_s, 0.9)), SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE
    )
    expected = sorted([(w, zeta), (octave * w, 0.3)])
    assert np.array(found) == pytest.approx(np.array(expected), rel=1e-12)


def test_an_octave_up_at_exactly_the_bands_top_is_inside_it() -> None:
    # the band 2-4 s is one octave: real poles give a factor held at 4 s, the second one
    # exactly at 2 s
    (slow_w, _), (other_w, other_zeta) = factors_from_ar(
        ar_coefficients([0.999, 0.998]), SAMPLE_S, (2.0, 4.0), DAMPING_RANGE
    )
    assert (slow_w, other_w, other_zeta) == (math.pi / 2.0, math.pi, 0.3)


def ar_samples(coefficients: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """``n`` samples that follow ``y[n] = sum_k c[k] y[n-1-k]`` exactly, from random values."""
    y = list(np.random.default_rng(seed).standard_normal(len(coefficients)))
    while len(y) < n:
        y.append(float(np.dot(coefficients, y[-1 : -len(coefficients) - 1 : -1])))
    return np.array(y[:n])


def test_the_ar_fit_gives_the_coefficients_that_samples_follow_from_three_per_coefficient() -> None:
    """Samples that follow an AR model exactly give its coefficients back, from three samples
    per coefficient on; fewer, a table of samples, or a constant window give none."""
    coefficients = ar_coefficients([*pole_pair(12.0, 0.98), *pole_pair(5.0, 0.95)])
    for n in (12, 200):
        assert fit_ar(ar_samples(coefficients, n), 4) == pytest.approx(coefficients, rel=1e-6)
    assert fit_ar([int(v) for v in 100 * ar_samples(coefficients, 40)], 4) is not None
    assert fit_ar(ar_samples(coefficients, 11), 4) is None
    # a window without motion, or holding a constant, determines nothing
    assert fit_ar(np.zeros(40), 4) is None
    assert fit_ar(np.full(40, 0.1), 4) is None
    table = np.random.default_rng(1).standard_normal((60, 2))
    assert fit_ar(table, 4) is None


class Recorder:
    """Stand-ins for the identifier's three fits: they keep what they are given and return
    fixed results (``fit_ar`` None when ``coefficients`` is None)."""

    def __init__(self, coefficients: np.ndarray | None) -> None:
        self.coefficients = coefficients
        self.fits: list[tuple[np.ndarray, int]] = []
        self.factors: list[tuple] = []
        self.refinements: list[tuple] = []
        self.first, self.second = (0.5, 0.1), (1.2, 0.2)
        self.refined = ((0.6, 0.15, 0.004), (1.3, 0.25, 0.001))

    def fit_ar(self, y: np.ndarray, order: int) -> np.ndarray | None:
        self.fits.append((np.array(y), order))
        return self.coefficients

    def factors_from_ar(self, *args: object) -> list[tuple[float, float]]:
        self.factors.append(args)
        return [self.first, self.second]

    def refine_components(self, *args: object) -> tuple:
        self.refinements.append(args)
        return self.refined

    def install(self, monkeypatch: pytest.MonkeyPatch) -> None:
        for name in ("fit_ar", "factors_from_ar", "refine_components"):
            monkeypatch.setattr(identify, name, getattr(self, name))


BANDS = ((2.0, 30.0), (0.05, 2.0))


def feed(identifier: DeckMotionIdentifier, times: np.ndarray) -> list[bool]:
    """Roll ``sin(t)`` and pitch ``0.5 cos(t)`` at each time; each call's result."""
    return [identifier.add(float(t), math.sin(t), 0.5 * math.cos(t)) for t in times]


def block_means(times: np.ndarray, sample_s: float) -> np.ndarray:
    """The roll and pitch of ``feed`` averaged over each whole block of ``sample_s``."""
    values = np.column_stack([np.sin(times), 0.5 * np.cos(times)])
    blocks = np.floor(times / sample_s)
    return np.array([values[blocks == b].mean(axis=0) for b in np.unique(blocks)])


def test_the_identifier_fits_block_means_once_the_shortest_window_is_full_then_every_refit_s(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Estimates every 0.125 s are averaged over blocks of 0.5 s; the first fit comes as
    the tenth block (5 s, the shortest window) closes, on the block means of each axis with
    the AR order; the next exactly refit_s (2 s) later, and none in between."""
    recorder = Recorder(np.zeros(4))
    recorder.install(monkeypatch)
    identifier = DeckMotionIdentifier(10.0, 0.5, 5.0, 2.0, *BANDS, order=4)
    assert identifier.models is None
    times = np.arange(0, 73) * 0.125  # 0 to 9 s
    fitted = feed(identifier, times)
    # block k closes at the first estimate of block k + 1: ten blocks at t = 5 s
    assert [float(t) for t, f in zip(times, fitted, strict=True) if f] == [5.0, 7.0, 9.0]
    means = block_means(times[times < 5.0], 0.5)
    (roll, order), (pitch, _) = recorder.fits[:2]
    assert order == 4
    np.testing.assert_allclose(roll, means[:, 0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(pitch, means[:, 1], rtol=1e-12, atol=1e-15)
    assert identifier.span_s == 9.0


def test_the_identifier_keeps_the_last_window_s_of_blocks_or_three_per_ar_coefficient(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    recorder = Recorder(np.zeros(4))
    recorder.install(monkeypatch)
    times = np.arange(0, 241) * 0.125  # 30 s
    identifier = DeckMotionIdentifier(10.0, 0.5, 5.0, 1.0, *BANDS, order=4)
    feed(identifier, times)
    # 20 blocks of 0.5 s: the last closed at 30 s, so blocks 40 to 59
    np.testing.assert_allclose(
        recorder.fits[-2][0], block_means(times[times < 30.0], 0.5)[-20:, 0], rtol=1e-12
    )
    # a 2 s window holds three samples per coefficient of an order-4 AR: 12 blocks
    identifier = DeckMotionIdentifier(2.0, 0.5, 1.0, 2.0, *BANDS, order=4)
    feed(identifier, times)
    assert len(recorder.fits[-1][0]) == 12 and identifier.span_s == 6.0


def test_the_identified_model_is_the_refined_components_with_their_variances_times_the_gain(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each axis: the AR's peaks from its coefficients at the sample spacing in the bands,
    refined on its block means; the model holds the refined periods, damping and the
    axis' RMS, its deck4 the two oscillators with the refined variances times the noise
    gain (1 unless given)."""
    times = np.arange(0, 41) * 0.125
    for gain in (None, 3.0):
        recorder = Recorder(np.array([0.1, 0.2, 0.3, 0.4]))
        recorder.install(monkeypatch)
        extra = {} if gain is None else {"noise_gain": gain}
        identifier = DeckMotionIdentifier(10.0, 0.5, 5.0, 2.0, *BANDS, order=4, **extra)
        assert feed(identifier, times)[-1]
        means = block_means(times[times < 5.0], 0.5)
        (w1, z1, v1), (w2, z2, v2) = recorder.refined
        expected = []
        for axis in range(2):
            coefficients, sample_s, *bands = recorder.factors[axis]
            assert list(coefficients) == [0.1, 0.2, 0.3, 0.4]
            assert (sample_s, *bands) == (0.5, *BANDS)
            y, sample_s, first, second, *bands = recorder.refinements[axis]
            np.testing.assert_allclose(y, means[:, axis], rtol=1e-12, atol=1e-15)
            assert (sample_s, first, second, *bands) == (0.5, (0.5, 0.1), (1.2, 0.2), *BANDS)
            rms = math.sqrt(np.mean(means[:, axis] ** 2))
            g = 1.0 if gain is None else gain
            waves = TwoWaves.matched(w1, z1, w2, z2, g * v1, g * v2)
            expected.append(
                AxisModel((2.0 * math.pi / w1, 2.0 * math.pi / w2), (z1, z2), rms, waves)
            )
        assert identifier.models is not None
        for found, model in zip(identifier.models, expected, strict=True):
            assert found.periods_s == pytest.approx(model.periods_s, rel=1e-12)
            assert found.damping == model.damping and found.deck4 == model.deck4
            assert found.rms_rad == pytest.approx(model.rms_rad, rel=1e-12)
        assert identifier.deck4 == (expected[0].deck4, expected[1].deck4)


def test_a_window_without_an_ar_fit_or_without_motion_gives_no_model(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    times = np.arange(0, 41) * 0.125
    for coefficients, scale in ((None, 1.0), (np.zeros(4), 0.0)):
        recorder = Recorder(coefficients)
        recorder.install(monkeypatch)
        identifier = DeckMotionIdentifier(10.0, 0.5, 5.0, 2.0, *BANDS, order=4)
        results = [identifier.add(float(t), scale * math.sin(t), 0.0 * t) for t in times]
        assert recorder.fits and not any(results)
        assert identifier.models is None and identifier.deck4 is None


def test_estimates_that_are_not_angles_are_skipped_and_angles_up_to_pi_are_taken(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A roll or pitch beyond pi, or a time not finite, is not an estimate: it is skipped
    (False, nothing raised); pi itself is an angle."""
    recorder = Recorder(np.zeros(4))
    recorder.install(monkeypatch)
    identifier = DeckMotionIdentifier(10.0, 0.5, 5.0, 2.0, *BANDS, order=4)
    for k in range(41):
        t = 0.125 * k
        assert identifier.add(t, 3.5, 0.0) is False
        assert identifier.add(t, 0.0, -3.5) is False
        assert identifier.add(math.nan, 0.0, 0.0) is False
        assert identifier.add(math.inf, 0.0, 0.0) is False
        identifier.add(t, math.pi if k % 2 else 0.0, -math.pi if k % 2 else 0.0)
    roll, _ = recorder.fits[0]
    pitch, _ = recorder.fits[1]
    # each block holds two estimates at pi and two at 0
    np.testing.assert_allclose(roll, np.full(10, 0.5 * math.pi), rtol=1e-12)
    np.testing.assert_allclose(pitch, np.full(10, -0.5 * math.pi), rtol=1e-12)


def test_a_gap_of_two_blocks_joins_on_and_one_of_three_restarts_the_window(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    recorder = Recorder(np.zeros(4))
    recorder.install(monkeypatch)
    identifier = DeckMotionIdentifier(10.0, 0.5, 5.0, 100.0, *BANDS, order=4)
    for t in (0.0, 0.5, 1.0):
        identifier.add(t, 0.1, 0.1)
    assert identifier.span_s == 1.0  # blocks 0 and 1 closed
    identifier.add(2.0, 0.1, 0.1)  # block 4 after block 2: block 3 empty
    assert identifier.span_s == 1.5
    identifier.add(3.5, 0.1, 0.1)  # block 7 after block 4: two empty blocks
    assert identifier.span_s == 0.5
    identifier.reset()
    assert identifier.span_s == 0.0 and identifier.models is None


def test_fast_real_poles_give_a_factor_held_at_the_shortest_period_and_one_an_octave_down() -> None:
    # two real poles far from 1: an overdamped factor at 5.2 rad/s, above the band's top
    # (pi rad/s, 2 s), held there; the second component an octave below it
    (other_w, other_zeta), (fast_w, fast_zeta) = factors_from_ar(
        ar_coefficients([0.1, 0.05]), SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE
    )
    a, b = math.log(0.1) / SAMPLE_S, math.log(0.05) / SAMPLE_S
    assert fast_w == pytest.approx(math.pi, rel=1e-12)
    assert fast_zeta == pytest.approx(-(a + b) / (2.0 * math.sqrt(a * b)), rel=1e-9)
    assert (other_w, other_zeta) == pytest.approx((0.5 * math.pi, 0.3), rel=1e-12)


def test_a_refinement_of_two_distinct_components_is_kept_slowest_first(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    y = two_tones(600)
    total = float(np.mean(y * y))
    fit = LeastSquares([0.5, 0.1, 1.0, 0.2, 0.6, 0.4])
    slow, fast = refine(monkeypatch, fit, y, SWELL, WIND_SEA)
    assert slow == pytest.approx((0.5, 0.1, 0.6 * total))
    assert fast == pytest.approx((1.0, 0.2, 0.4 * total))


def test_the_refinements_residual_is_relative_to_a_windows_variance_below_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A deck's roll in radians has a variance far below 1: the residual is still the
    autocovariance relative to it (the two oscillators' shares of it)."""
    y = 0.05 * two_tones(600)
    fit = LeastSquares([0.5, 0.1, 1.0, 0.2, 0.5, 0.5])
    refine(monkeypatch, fit, y, SWELL, WIND_SEA)
    tau = np.arange(int(2.0 * 12.0 / SAMPLE_S) + 1) * SAMPLE_S
    covariance = np.array([np.mean(y[: 600 - k] * y[k:]) for k in range(len(tau))])
    expected = (
        0.7 * oscillator_correlation(tau, 0.6, 0.1)
        + 0.3 * oscillator_correlation(tau, 1.3, 0.3)
        - covariance / np.mean(y * y)
    )
    assert fit.call["fun"](np.array([0.6, 0.1, 1.3, 0.3, 0.7, 0.3])) == pytest.approx(expected)


def test_the_components_are_the_sharp_peaks_not_a_broad_pair_beside_them() -> None:
    # the AR spectrum 1 / |A(e^{iwT})|² is highest at the two sharp pairs (20 s and 12 s),
    # far above the broad pair at 8 s
    coefficients = ar_coefficients(
        [*pole_pair(20.0, 0.98), *pole_pair(12.0, 0.98), *pole_pair(8.0, 0.5)]
    )
    found = factors_from_ar(coefficients, SAMPLE_S, PERIOD_RANGE_S, DAMPING_RANGE)
    assert np.array(found) == pytest.approx(np.array([peak(20.0, 0.98), peak(12.0, 0.98)]))
