"""When to take a chance: the optimal-stopping value of waiting for a better one.

A timing policy sees, every decision, the chance ``x`` that a descent committed now meets the
deck within its limit; it may take it or wait, and at the wait limit it must commit whatever
the chance.  With ``m`` independent opportunities left, drawn from the chance's distribution
``F``, this is the full-information best-choice ("house-selling") problem (Moser 1956, *On a
problem of Cayley*, Scripta Math. 22; Chow, Robbins & Siegmund 1971, *Great Expectations:
The Theory of Optimal Stopping*, ch. 3): the value of going on is

    V_0 = E[X]                      (the forced commit takes whatever comes)
    V_m = E[max(X, V_{m-1})]        (take the next draw if it beats going on after it)

and the optimal rule takes a chance ``x`` with ``m`` opportunities left after it when
``x >= V_m``.  The deck's chance is not drawn afresh every decision: it decorrelates over a
fraction of a roll period, so the wait left counts one opportunity per ``opportunity_s``
(the one tuned number).  Early in a wait the value is near the best chance the sea offers;
near the limit it falls to what a forced commit would get, so the rule becomes lenient
exactly when waiting stops paying, and it means the same at every sea state: a calm sea's
chances are high and so is its value, a rough sea's are lower and so is its.

Pure NumPy; never raises on data (no samples: a value of 0, which takes any chance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: the most opportunities tabulated (the value converges to the best chance long before)
MAX_OPPORTUNITIES = 400


@dataclass(frozen=True)
class StoppingValues:
    """``values[m]``: the value of going on with ``m`` independent opportunities left."""

    values: np.ndarray

    @classmethod
    def from_samples(
        cls, samples: np.ndarray, max_opportunities: int = MAX_OPPORTUNITIES
    ) -> StoppingValues:
        """The values for chances distributed as ``samples`` (their empirical distribution;
        non-finite samples are dropped, and none at all give values of 0)."""
        x = np.asarray(samples, dtype=float).reshape(-1)
        x = np.sort(x[np.isfinite(x)])
        if x.size == 0:
            return cls(np.zeros(1))
        values = np.empty(max(int(max_opportunities), 0) + 1)
        values[0] = float(np.mean(x))
        for m in range(1, len(values)):
            values[m] = float(np.mean(np.maximum(x, values[m - 1])))
        return cls(values)

    def value(self, opportunities: float) -> float:
        """The value of going on with ``opportunities`` left (interpolated between whole
        numbers; none or fewer: ``values[0]``, the forced commit's; non-finite: 0)."""
        if not math.isfinite(opportunities):
            return 0.0
        m = min(max(float(opportunities), 0.0), float(len(self.values) - 1))
        low = math.floor(m)
        high = min(low + 1, len(self.values) - 1)
        w = m - low
        return float((1.0 - w) * self.values[low] + w * self.values[high])

    def threshold(self, remaining_s: float, opportunity_s: float) -> float:
        """The chance worth taking with ``remaining_s`` of wait left, one independent
        opportunity per ``opportunity_s``: 0 once nothing is left (the commit is forced)."""
        if not (math.isfinite(remaining_s) and opportunity_s > 0.0) or remaining_s <= 0.0:
            return 0.0
        return self.value(remaining_s / opportunity_s)


def value_before_forced(
    samples: np.ndarray, forced_chance: float, remaining_s: float, opportunity_s: float
) -> float:
    """The value of going on when the forced commit's own chance is known: the recursion
    above from ``V_0 = forced_chance`` (a forecast that reaches past the wait limit predicts
    the deck the forced commit will meet) instead of the long-run mean, with the chances
    between distributed as ``samples``, one per ``opportunity_s`` of the ``remaining_s``
    (interpolated between whole numbers); 0 once nothing is left, and ``forced_chance``
    when it is not finite is taken as the long-run mean."""
    if not (math.isfinite(remaining_s) and opportunity_s > 0.0) or remaining_s <= 0.0:
        return 0.0
    x = np.asarray(samples, dtype=float).reshape(-1)
    x = x[np.isfinite(x)]
    if not math.isfinite(forced_chance):
        forced_chance = float(np.mean(x)) if x.size else 0.0
    m = min(remaining_s / opportunity_s, float(MAX_OPPORTUNITIES))
    values = [float(forced_chance)]
    for _ in range(math.ceil(m)):
        values.append(float(np.mean(np.maximum(x, values[-1]))) if x.size else values[-1])
    low = math.floor(m)
    high = min(low + 1, len(values) - 1)
    w = m - low
    return (1.0 - w) * values[low] + w * values[high]


def predictor_stopping_values(
    predictor: Any, horizons_s: float | Sequence[float], limit_deg: float
) -> StoppingValues | None:
    """The value of waiting for a better chance when the chances are distributed as the
    deck-tilt ``predictor`` gave them to held-out examples
    (:meth:`~estimation.anticipation.linear_predictors.LinearTiltPredictor.chances`); None when none
    were recorded."""
    chances = predictor.chances(horizons_s, limit_deg)
    return StoppingValues.from_samples(chances) if chances.size else None
