"""A deck-tilt predictor's error on the sea at hand, measured online.

A predictor fitted on some seas (:class:`~estimation.deck_prediction.LinearTiltPredictor`)
carries the covariance of its errors on *those* seas.  On a sea it was not fitted to its
errors can be larger, and a chance computed with the fitted covariance is then overconfident.
:class:`PredictionErrorScale` checks the predictor against what happens: each prediction
``horizon_s`` ahead is kept until that time comes, then compared with the deck's estimated
tilt at that time, and the squared error normalised by the fitted covariance (plus the
estimate's own noise) is averaged, a normalised innovation squared (Bar-Shalom, Li &
Kirubarajan 2001, Sec. 5.4).  Its mean is 2 (two angles) when the fitted covariance is
right; the scale is that mean over 2, shrunk toward 1 by ``prior_count`` pseudo-samples,
and never below 1: the sea at hand can make the predictor less certain than its fit, never
more.  Pure NumPy; :meth:`PredictionErrorScale.update` never raises on data.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np


class PredictionErrorScale:
    """The factor by which a predictor's fitted covariance ``horizon_s`` ahead understates its
    error on the sea at hand (see the module docstring).

    ``covariance``: the fitted (2, 2) covariance of (roll, pitch) at ``horizon_s``, rad²;
    ``noise_covariance``: the estimate's own (2, 2) noise, rad², added because the check is
    against the estimated tilt, not the truth; ``prior_count``: pseudo-samples at scale 1;
    ``tolerance_s``: how close to ``horizon_s`` after a prediction an estimate must come to
    check it (half a decision period).
    """

    def __init__(
        self,
        horizon_s: float,
        covariance: np.ndarray,
        noise_covariance: np.ndarray,
        prior_count: float = 20.0,
        tolerance_s: float = 0.05,
    ) -> None:
        if not (math.isfinite(horizon_s) and horizon_s > 0.0):
            raise ValueError(f"horizon_s must be positive, got {horizon_s}")
        if not (math.isfinite(prior_count) and prior_count > 0.0):
            raise ValueError(f"prior_count must be positive, got {prior_count}")
        if not (math.isfinite(tolerance_s) and tolerance_s > 0.0):
            raise ValueError(f"tolerance_s must be positive, got {tolerance_s}")
        covariance = np.asarray(covariance, dtype=float)
        noise_covariance = np.asarray(noise_covariance, dtype=float)
        if covariance.shape != (2, 2) or noise_covariance.shape != (2, 2):
            raise ValueError("the covariances must be (2, 2) arrays of roll and pitch")
        total = covariance + noise_covariance
        if not np.all(np.isfinite(total)):
            raise ValueError("the covariances must be finite")
        self.horizon_s = float(horizon_s)
        self.prior_count = float(prior_count)
        self.tolerance_s = float(tolerance_s)
        self._information = np.linalg.inv(total + 1e-12 * np.eye(2))
        self._pending: deque[tuple[float, np.ndarray]] = deque()
        self.reset()

    def reset(self) -> None:
        """Forget the episode: the scale is 1 again."""
        self._pending.clear()
        self.count = 0
        self._sum = 0.0

    @property
    def scale(self) -> float:
        """The factor (>= 1) for the fitted covariance."""
        mean = (self.prior_count * 2.0 + self._sum) / (self.prior_count + self.count) / 2.0
        return max(1.0, mean)

    def update(
        self, t_s: float, predicted: np.ndarray | None, estimated: np.ndarray | None
    ) -> None:
        """At time ``t_s`` (seconds, increasing): check the predictions that have come due
        against ``estimated`` (roll, pitch; None when there is no estimate), then keep
        ``predicted`` (roll, pitch ``horizon_s`` after ``t_s``; None when none was made)."""
        if not math.isfinite(t_s):
            return
        due = t_s - self.horizon_s
        while self._pending and self._pending[0][0] < due - self.tolerance_s:
            self._pending.popleft()  # its time passed without an estimate to check it
        if self._pending and abs(self._pending[0][0] - due) <= self.tolerance_s:
            _, mean = self._pending.popleft()
            if estimated is not None and np.all(np.isfinite(estimated)):
                error = np.asarray(estimated, dtype=float)[:2] - mean
                with np.errstate(over="ignore", invalid="ignore"):
                    squared = float(error @ self._information @ error)
                if math.isfinite(squared):
                    self._sum += squared
                    self.count += 1
        if predicted is not None and np.all(np.isfinite(predicted)):
            self._pending.append((float(t_s), np.asarray(predicted, dtype=float)[:2].copy()))
