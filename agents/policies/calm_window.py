"""Calm windows: when the estimated deck has been, and is predicted to stay, calm enough to land.

The landing-period heuristic that ``quiescent`` commits by and ``align-descend`` flares for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.frames import tilt_deg
from estimation.limits import POSITIVE, Limit, Limited, limited
from landing_env.anticipation.deck_history import HISTORY_FEATURES

_Z, _ROLL, _PITCH = (HISTORY_FEATURES.index(n) for n in ("z", "roll", "pitch"))
_VALID = HISTORY_FEATURES.index("valid")


# ------------------------------------------------------------------------------ calm windows
@dataclass
class CalmConfig(Limited):
    """When the deck counts as calm enough to start the final descent."""

    #: sliding window of estimated deck motion that must have been calm, seconds (as long as
    #: the descent: the deck has been calm for a descent's length)
    window_s: float = limited(1.3, Limit(0.1, 10.0))
    #: duration of the final descent the calm must last for (the prediction horizon), seconds
    descent_s: float = limited(1.3, Limit(0.0, 10.0))
    #: fraction of the fitted trend extrapolated over the descent: 0 predicts that the calm
    #: persists, 1 extrapolates the straight line (which overshoots on an oscillating deck)
    trend_weight: float = limited(0.25, Limit(0.0, 1.0))
    #: largest deck tilt relative to the camera, now and predicted at touchdown, degrees
    max_tilt_deg: float = limited(4.0, Limit(0.0, 45.0, low_inclusive=False))
    #: also require every valid sample of the window to be within ``max_tilt_deg`` (the deck
    #: has been calm for a window, the landing-period heuristic); False judges by the fitted
    #: line alone
    require_calm_window: bool = True
    #: largest heave rate of the deck relative to the camera, m/s
    max_heave_rate: float = limited(0.15, POSITIVE)
    #: fewer valid estimates than this fraction of the window: not calm (nothing to judge by)
    min_valid_fraction: float = limited(0.8, Limit(0.0, 1.0))


@dataclass
class CalmPrediction:
    """The outcome of :func:`predict_calm`, with the figures it was decided on."""

    calm: bool
    #: largest tilt over the window (deg); NaN without valid samples
    window_max_tilt_deg: float
    #: tilt extrapolated to the end of the descent (deg)
    predicted_tilt_deg: float
    #: fitted heave rate of the deck relative to the camera (m/s)
    heave_rate: float
    reason: str = ""


def predict_calm(history: np.ndarray, dt: float, config: CalmConfig) -> CalmPrediction:
    """Is a calm window at least ``config.descent_s`` long ahead?

    ``history`` holds rows of :data:`~landing_env.anticipation.deck_history.HISTORY_FEATURES` (SI
    units), oldest first, one per ``dt``.  Over the last ``window_s`` the valid samples must all
    show a tilt below ``max_tilt_deg``; straight lines fitted to roll, pitch and z there give the
    rates, and the tilt extrapolated ``descent_s`` ahead (``trend_weight`` of the trend) and the
    heave rate must be within the limits too (the tilt is convex in (roll, pitch), so on a
    straight line its largest value is at one end: checking now and at the end of the descent
    covers the whole descent).
    """
    n = max(2, round(config.window_s / dt))
    window = np.asarray(history, dtype=float)[-n:]
    valid = window[:, _VALID] > 0.5
    nan = math.nan
    if valid.sum() < max(2, math.ceil(config.min_valid_fraction * n)):
        return CalmPrediction(False, nan, nan, nan, "too few valid estimates")
    t = np.arange(len(window))[valid] * dt
    values = window[valid][:, [_ROLL, _PITCH, _Z]]
    centred = t - t.mean()
    slopes = (centred @ (values - values.mean(axis=0))) / float(centred @ centred)
    now = values.mean(axis=0) + slopes * (t[-1] - t.mean())
    ahead = now + slopes * (config.trend_weight * config.descent_s)
    window_tilt = float(np.max(tilt_deg(values[:, 0], values[:, 1])))
    predicted = float(tilt_deg(ahead[0], ahead[1]))
    current = float(tilt_deg(now[0], now[1]))
    # the tag's z in the camera grows when the deck falls away: heave rate = -dz/dt
    heave_rate = -float(slopes[2])
    reason = ""
    if config.require_calm_window and window_tilt > config.max_tilt_deg:
        reason = "tilt in the window"
    elif max(predicted, current) > config.max_tilt_deg:
        reason = "tilt predicted"
    elif abs(heave_rate) > config.max_heave_rate:
        reason = "heave rate"
    return CalmPrediction(not reason, window_tilt, predicted, heave_rate, reason)
