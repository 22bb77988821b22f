"""The timed final descent's reference: the height over the deck that meets it on time.

With ``GuidanceGains.descent_profile = "timed"``
(:class:`~landing_env.guidance_gains.GuidanceGains`) the guidance
(:class:`~landing_env.timing.guidance.DeckGuidance`) makes the height over the deck track
:func:`timed_descent_reference`, which reaches the deck ``descent_time_s`` after the commit at
the touchdown speed: the feet touch a fixed time after the commit, the time a timing policy
must predict.
"""

from __future__ import annotations

import numpy as np


def timed_descent_reference(
    t_s: float, start_m: float, duration_s: float, end_speed: float, end_m: float = 0.0
) -> tuple[float, float]:
    """The timed descent's reference height over the deck and its rate at ``t_s`` after the
    commit: a cubic from ``start_m`` at rest to ``end_m`` at ``-end_speed`` after
    ``duration_s`` (Hermite end conditions: the drone leaves the hold without a jerk in its
    velocity set-point and meets the deck at the touchdown speed), then on down at that speed.
    """
    if t_s >= duration_s:
        return end_m - end_speed * (t_s - duration_s), -end_speed
    s = max(t_s, 0.0) / duration_s
    drop = start_m - end_m
    # Hermite basis: h00 = 2s^3 - 3s^2 + 1 (start height), h11 = s^3 - s^2 (end slope)
    height = end_m + drop * (2 * s**3 - 3 * s**2 + 1) - end_speed * duration_s * (s**3 - s**2)
    rate = (drop * (6 * s**2 - 6 * s) - end_speed * duration_s * (3 * s**2 - 2 * s)) / duration_s
    return height, rate


def timed_descent_references(
    t_s: np.ndarray, start_m: np.ndarray, duration_s: float, end_speed: float, end_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`timed_descent_reference` of many descents at once (``t_s`` and ``start_m`` arrays
    of one shape): the same heights and rates, element by element."""
    t = np.asarray(t_s, dtype=float)
    drop = np.asarray(start_m, dtype=float) - end_m
    s = np.clip(t, 0.0, None) / duration_s
    height = end_m + drop * (2 * s**3 - 3 * s**2 + 1) - end_speed * duration_s * (s**3 - s**2)
    rate = (drop * (6 * s**2 - 6 * s) - end_speed * duration_s * (3 * s**2 - 2 * s)) / duration_s
    after = t >= duration_s
    height = np.where(after, end_m - end_speed * (t - duration_s), height)
    rate = np.where(after, -end_speed, rate)
    return height, rate
