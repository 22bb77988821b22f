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
    component_variances,
    factors_from_ar,
    oscillator_correlation,
    refine_components,
)

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
