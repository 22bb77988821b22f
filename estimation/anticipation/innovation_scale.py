"""How wide a deck-tilt prediction's error is on the deck it is flying over, from its own record.

A :class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor` claims the error it
made on the held-out episodes of the seas it was fitted to: at the bench's training seas about
1.8 deg of roll and 1.2 deg of pitch at the 1.3 s contact.  On a calm deck that claim caps the
chance of a deck within a 5 deg limit near 0.99, so a deck that is plainly level cannot clear a
value of waiting computed from the same seas.  The remedy of adaptive filtering is to measure
the error where the predictor is used: each prediction, once the estimates reach the time it
was made for, leaves an *innovation* ``e`` (the estimated roll and pitch then, less the
prediction), and ``q = e' P^-1 e`` against the claimed covariance ``P`` has mean 2 when the
claim is right (covariance matching, Mehra 1972, *Approaches to adaptive filtering*, IEEE Trans.
Autom. Control 17(5); Mohamed & Schwarz 1999, *Adaptive Kalman filtering for INS/GPS*, J.
Geodesy 73).  :class:`InnovationScale` turns them into one factor on the claimed covariance:
the posterior mean of a variance scale with an inverse-gamma prior worth ``prior_weight``
innovations at 1 (the fitted claim), over the innovations of the last ``memory_s``,

    scale = (prior_weight + sum(q_i) / 2) / (prior_weight + n),

kept in ``[min_scale, max_scale]``.  An innovation holds the estimate's own noise too, so the
scale is an upper bound on the prediction's: it errs towards the claim.

The innovations show a *bias* as well.  The predictor is fitted on windows of oscillating
motion; nothing in the fit ties its response to a steady input, and the bench's predictors
answer one with several times its size (at the bench's training seas, a steady 1 deg of roll
in the window predicts -7 deg 1.3 s on; a drone holding 1 cm to the side of the deck's centre,
-4 deg).  On a rough sea the oscillation drowns that; over a calm deck with a list, or a
drone holding off the centre, it is a phantom tilt no chance clears.  When the mean innovation
is significant (its chi-square over the independent innovations, one per ``correlation_s``,
above ``bias_chi2``: the innovation mean test of Mehra & Peschon 1971, *An innovations approach
to fault detection and diagnosis in dynamic systems*, Automatica 7), it is the predictor's
steady error on this deck: :attr:`InnovationScale.bias` is added to the prediction, and the
scale is measured about it.

Times are the caller's clock (seconds, any origin, non-decreasing); the estimates come as the
newest rows of a history sampled every ``dt_s``.  Pure NumPy; never raises on data: a
non-finite or singular input is ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: the fitted claim is worth this many innovations (2 s of decisions every 0.1 s)
PRIOR_WEIGHT = 20.0
#: innovations older than this (by the time they were made for) are forgotten, seconds
MEMORY_S = 10.0
#: the narrowest error allowed, as a factor on the claimed variance (about a fifth of its
#: standard deviation)
MIN_SCALE = 0.05
#: innovations this far apart count as independent in the bias test, seconds
CORRELATION_S = 1.0
#: the mean innovation is a bias above this chi-square of 2 degrees of freedom (1 % false)
BIAS_CHI2 = 9.21
#: the widest, as a factor on the claimed variance: 1 keeps the claim as the ceiling (the value
#: of waiting is computed at the claimed error)
MAX_SCALE = 1.0


def _finite(value: object) -> bool:
    """A real, finite number."""
    try:
        return math.isfinite(float(value))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


@dataclass
class InnovationScale:
    """The bias and the factor on a tilt predictor's claimed covariance, measured from its
    innovations."""

    prior_weight: float = PRIOR_WEIGHT
    memory_s: float = MEMORY_S
    min_scale: float = MIN_SCALE
    max_scale: float = MAX_SCALE
    #: innovations this far apart are independent (the deck's chance decorrelates over about
    #: a second), seconds: the bias test counts one independent innovation per this long
    correlation_s: float = CORRELATION_S
    #: the chi-square (2 degrees of freedom) the mean innovation must exceed to be a bias
    bias_chi2: float = BIAS_CHI2
    #: predictions waiting for their estimate: (target time, roll, pitch, inverse covariance)
    _pending: list[tuple[float, float, float, np.ndarray]] = field(default_factory=list)
    #: scored innovations: (target time, innovation (2,), inverse claimed covariance (2, 2))
    _scored: list[tuple[float, np.ndarray, np.ndarray]] = field(default_factory=list)

    def __post_init__(self) -> None:
        for name in (
            "prior_weight",
            "memory_s",
            "min_scale",
            "max_scale",
            "correlation_s",
            "bias_chi2",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        if self.min_scale > self.max_scale:
            raise ValueError(
                f"min_scale ({self.min_scale}) must not exceed max_scale ({self.max_scale})"
            )

    def reset(self) -> None:
        """Forget every prediction and innovation (a new episode)."""
        self._pending.clear()
        self._scored.clear()

    @property
    def innovations(self) -> int:
        """How many innovations the scale now rests on."""
        return len(self._scored)

    @property
    def bias(self) -> np.ndarray:
        """The predictor's steady error (roll, pitch; rad) to add to its predictions: the mean
        innovation where it is significant (its chi-square over the independent innovations,
        one per ``correlation_s`` of their span, above ``bias_chi2``), else zero."""
        if not self._scored:
            return np.zeros(2)
        errors = np.array([e for _, e, _ in self._scored])
        mean = errors.mean(axis=0)
        inverse = np.mean([w for _, _, w in self._scored], axis=0)
        times = [t for t, _, _ in self._scored]
        independent = 1.0 + (max(times) - min(times)) / self.correlation_s
        with np.errstate(all="ignore"):
            chi2 = float(mean @ inverse @ mean) * independent
        return mean if math.isfinite(chi2) and chi2 > self.bias_chi2 else np.zeros(2)

    @property
    def scale(self) -> float:
        """The factor on the claimed covariance of the predictions corrected by :attr:`bias`
        (1 with no innovations when ``max_scale`` allows it)."""
        bias = self.bias
        with np.errstate(all="ignore"):
            total = sum(float((e - bias) @ w @ (e - bias)) for _, e, w in self._scored)
        value = (self.prior_weight + 0.5 * total) / (self.prior_weight + len(self._scored))
        if not math.isfinite(value):
            return float(self.max_scale)
        return float(min(max(value, self.min_scale), self.max_scale))

    def record(
        self, time_s: float, horizon_s: float, roll: float, pitch: float, covariance: np.ndarray
    ) -> None:
        """A prediction made at ``time_s`` of the roll and pitch (rad) ``horizon_s`` later,
        with its claimed (2, 2) ``covariance`` (rad^2); ignored when any of it is not usable."""
        if not all(_finite(v) for v in (time_s, horizon_s, roll, pitch)):
            return
        if horizon_s < 0.0:
            return
        try:
            cov = np.asarray(covariance, dtype=float)
            if cov.shape != (2, 2) or not np.all(np.isfinite(cov)):
                return
            np.linalg.cholesky(cov)  # positive definite, else no honest q
            inverse = np.linalg.inv(cov)
        except (TypeError, ValueError, np.linalg.LinAlgError):
            return
        self._pending.append((float(time_s) + float(horizon_s), float(roll), float(pitch), inverse))

    def update(self, time_s: float, estimates: np.ndarray, valid: np.ndarray, dt_s: float) -> None:
        """Score every pending prediction whose time the history reaches: ``estimates`` (n, 2)
        roll and pitch (rad), oldest first, the newest at ``time_s``, one every ``dt_s``, with
        ``valid`` flags; a prediction whose row is invalid is dropped unscored.  Then forget
        innovations older than ``memory_s``."""
        if not (_finite(time_s) and _finite(dt_s) and dt_s > 0.0):
            return
        try:
            rows = np.asarray(estimates, dtype=float)
            flags = np.asarray(valid, dtype=bool).reshape(-1)
        except (TypeError, ValueError):
            return
        if rows.ndim != 2 or rows.shape[1] != 2 or len(flags) != len(rows):
            return
        n = len(rows)
        oldest_s = time_s - (n - 1) * dt_s - 0.5 * dt_s
        waiting = []
        for item in self._pending:
            target_s, roll, pitch, inverse = item
            if target_s > time_s + 0.5 * dt_s:
                waiting.append(item)  # not yet estimated
                continue
            if target_s < oldest_s:
                continue  # the history no longer holds it
            index = n - 1 - round((time_s - target_s) / dt_s)
            if not (0 <= index < n) or not flags[index] or not np.all(np.isfinite(rows[index])):
                continue
            error = rows[index] - (roll, pitch)
            with np.errstate(all="ignore"):
                q = float(error @ inverse @ error)
            if math.isfinite(q):
                self._scored.append((target_s, error, inverse))
        self._pending = waiting
        self._scored = [item for item in self._scored if item[0] >= time_s - self.memory_s]
