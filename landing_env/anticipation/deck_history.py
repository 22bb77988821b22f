"""The deck-motion history the timing task observes and the calm-window heuristics judge."""

from __future__ import annotations

from collections import deque

import numpy as np

#: per-sample features of the history, in this order
HISTORY_FEATURES: tuple[str, ...] = (
    "x",
    "y",
    "z",
    "roll",
    "pitch",
    "yaw",
    "z_rate",
    "roll_rate",
    "pitch_rate",
    "valid",
)


class DeckMotionHistory:
    """A sliding window of estimated deck poses with least-squares rates (SI units).

    Each row holds :data:`HISTORY_FEATURES`; an invalid sample is a row of zeros with
    ``valid = 0``.  The rates of z, roll and pitch are the slope of a straight line fitted to
    the valid samples of the last ``rate_window`` samples (a finite difference of one step
    would amplify the estimator's noise twentyfold at 20 Hz).
    """

    def __init__(self, length: int, rate_window: int, dt: float) -> None:
        if length < 1 or rate_window < 2:
            raise ValueError("need length >= 1 and rate_window >= 2")
        self.length = length
        self.dt = dt
        self._rows: deque[np.ndarray] = deque(maxlen=length)
        self._recent: deque[tuple[float, np.ndarray | None]] = deque(maxlen=rate_window)
        self._t = 0.0
        #: the rate window's valid samples (centred times, poses, the times' sum of squares),
        #: stacked once per sample for every :meth:`slope` of it
        self._window: tuple[np.ndarray | None, np.ndarray | None, float] | None = None

    def reset(self) -> None:
        self._rows.clear()
        self._recent.clear()
        self._t = 0.0
        self._window = None

    def push(self, pose: np.ndarray | None) -> None:
        """Add the next sample: ``(x, y, z, roll, pitch, yaw)`` or None when invalid."""
        self._t += self.dt
        self._window = None
        row = np.zeros(len(HISTORY_FEATURES))
        if pose is not None and np.all(np.isfinite(pose)):
            pose = np.asarray(pose, dtype=float)
            self._recent.append((self._t, pose))
            row[:6] = pose
            row[6:9] = self.slope((2, 3, 4))
            row[9] = 1.0
        else:
            self._recent.append((self._t, None))
        self._rows.append(row)

    def slope(self, columns: tuple[int, ...]) -> np.ndarray:
        """The least-squares rate of the pose's ``columns`` (indices of x, y, z, roll, pitch,
        yaw) over the valid samples of the rate window, per second; zeros with fewer than two
        samples."""
        window = self._window
        if window is None:
            samples = [(t, p) for t, p in self._recent if p is not None]
            if len(samples) < 2:
                window = self._window = (None, None, 0.0)
            else:
                t = np.array([s[0] for s in samples])
                t = t - t.mean()
                poses = np.array([s[1] for s in samples])
                window = self._window = (t, poses, float(t @ t))
        t, poses, t_squares = window
        if t is None:
            return np.zeros(len(columns))
        values = poses[:, list(columns)]
        return (t @ (values - values.mean(axis=0))) / t_squares

    def newest(self) -> np.ndarray:
        """The newest row (an invalid row of zeros before the first sample)."""
        return self._rows[-1].copy() if self._rows else np.zeros(len(HISTORY_FEATURES))

    def rows(self) -> np.ndarray:
        """(length, features), oldest first; missing leading samples are invalid rows."""
        out = np.zeros((self.length, len(HISTORY_FEATURES)))
        if self._rows:
            out[self.length - len(self._rows) :] = np.array(self._rows)
        return out
