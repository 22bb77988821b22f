"""The deck's two wave components are the AR model's two highest spectral peaks: a weak pole
pair beside a strong one (the estimates' noise floor) does not take the strong one's place."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimation.fusion.identify import ORDER, factors_from_ar

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
