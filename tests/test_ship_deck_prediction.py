"""The ship deck-prediction benchmark's rules read the true deck motion as its docstring says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.bench_ship_deck_prediction import _window, commits, true_history, true_tilt_deg
from landing_env.errors import ConfigError


class RollingDeck:
    """Roll of ``amplitude`` rad with ``period_s``, heaving ``heave_m`` in phase."""

    def __init__(self, amplitude: float, period_s: float = 8.0, heave_m: float = 0.0) -> None:
        self.amplitude, self.omega, self.heave_m = amplitude, 2 * math.pi / period_s, heave_m

    def pose(self, t: float) -> np.ndarray:
        s = math.sin(self.omega * t)
        return np.array([0.0, 0.0, self.heave_m * s, self.amplitude * s, 0.0, 0.0])


def settings(rule: str, **kwargs: float) -> dict:
    base = {"rule": rule, "max_tilt_deg": 4.5, "max_heave_rate": 0.15, "window_s": (2.5, 5.0)}
    return {**base, "min_wait_s": 0.0, **kwargs}


def test_the_true_tilt_is_the_angle_of_the_decks_normal() -> None:
    pose = np.array([0, 0, 0, math.radians(3.0), math.radians(4.0), 0.3])
    expected = math.degrees(math.acos(math.cos(math.radians(3.0)) * math.cos(math.radians(4.0))))
    assert true_tilt_deg(pose) == pytest.approx(expected)
    assert 4.9 < expected < 5.1  # about the hypotenuse for small angles


def test_the_true_history_has_the_camera_sign_of_heave_and_the_newest_row_last() -> None:
    deck = RollingDeck(0.1, heave_m=1.0)
    rows = true_history(deck, 2.0, 0.05, 40)
    assert rows.shape[0] == 40 and np.all(rows[:, -1] == 1.0)
    assert rows[-1, 3] == pytest.approx(deck.pose(2.0)[3])
    assert rows[-1, 2] == pytest.approx(-deck.pose(2.0)[2])  # the deck rising: z shrinking
    assert rows[0, 3] == pytest.approx(deck.pose(2.0 - 39 * 0.05)[3])


def test_the_tilt_window_rule_commits_on_a_level_deck_and_waits_on_a_rolling_one() -> None:
    level, rolling = RollingDeck(0.0), RollingDeck(math.radians(10.0))
    assert commits(settings("tilt-window"), level, 0.0, 0.05, 0.0)
    assert not commits(settings("tilt-window"), rolling, 0.0, 0.05, 0.0)  # 10 deg within 5 s
    # the hold it asks for first
    assert not commits(settings("tilt-window", min_wait_s=3.0), level, 0.0, 0.05, 2.0)
    assert commits(settings("tilt-window", min_wait_s=3.0), level, 0.0, 0.05, 3.0)


def test_the_calm_rule_reads_the_true_roll_and_heave() -> None:
    assert commits(settings("calm", max_tilt_deg=4.0), RollingDeck(0.0), 5.0, 0.05, 0.0)
    assert not commits(settings("calm", max_tilt_deg=4.0), RollingDeck(0.2), 2.0, 0.05, 0.0)
    # level but heaving 1 m at 8 s: 0.79 m/s at the mid-stroke, over the 0.15 m/s limit
    assert not commits(
        settings("calm", max_tilt_deg=4.0), RollingDeck(0.0, heave_m=1.0), 8.0, 0.05, 0.0
    )


def test_a_bad_window_names_the_argument() -> None:
    assert _window("2.5,5") == (2.5, 5.0)
    for text in ("2.5", "5,2.5", "a,b"):
        with pytest.raises(ConfigError, match="window"):
            _window(text)
