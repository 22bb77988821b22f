"""The timing task's observation: a flat ``Box`` laid out by :class:`TimingObservationLayout`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from gymnasium import spaces

from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.timing_config import TimingConfig

#: scale from SI units (m, rad, m/s, rad/s) to the observation: decimetres, tenths of a
#: radian, so that typical values are of order one
HISTORY_SCALES = np.array([10.0, 10.0, 10.0, 10.0, 10.0, 1.0, 10.0, 10.0, 10.0, 1.0])
TOF_SCALE = 10.0
#: bound of every scaled observation value; beyond it a value is clipped and flagged
OBSERVATION_LIMIT = 50.0


@dataclass
class TimingObservationParts:
    """The decoded observation of the timing task, in SI units."""

    #: (n, features) history, oldest first: m, rad, m/s, rad/s, validity
    history: np.ndarray
    #: the four ToF ranges (m; NaN where invalid)
    tof_range: np.ndarray
    tof_valid: np.ndarray
    #: waited time / wait limit
    wait_fraction: float
    #: the prediction layout's values (see :class:`TimingObservationLayout`); empty otherwise
    prediction: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class TimingObservationLayout:
    """Layout of the flat observation: ``n_history`` rows of :data:`HISTORY_FEATURES`
    (scaled by :data:`HISTORY_SCALES`, z and the ToF ranges relative to the hold height),
    then 4 ToF ranges, 4 ToF validities and the wait fraction.

    With ``n_prediction`` > 0 (``TimingConfig.observation = "prediction"``) the history rows
    are replaced by ``n_prediction`` values of the deck-tilt predictor, all in [0, 1]: the
    chance of a deck within the touchdown limit at each of the ``n_prediction - 2`` contact
    times, the value of waiting on (the chance a later commit is expected to get), and 1 when
    the prediction is valid (0: too little seen; the chances are then 0)."""

    n_history: int
    hold_height_m: float
    n_prediction: int = 0

    @property
    def history_observed(self) -> bool:
        """The observation holds the history rows (not the prediction)."""
        return self.n_prediction == 0

    @property
    def observed_rows(self) -> int:
        """How many of the newest history rows the observation holds."""
        return self.n_history if self.history_observed else 0

    @property
    def size(self) -> int:
        head = (
            self.observed_rows * len(HISTORY_FEATURES)
            if self.history_observed
            else self.n_prediction
        )
        return head + 9

    @property
    def space(self) -> spaces.Box:
        return spaces.Box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.size,), dtype=np.float32)

    def encode(
        self,
        history: np.ndarray,
        tof_range: np.ndarray,
        tof_valid: np.ndarray,
        wait_fraction: float,
        prediction: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool]:
        """The flat observation and whether any value had to be clipped to the bounds
        (``prediction``: the prediction layout's values, needed by it)."""
        if self.history_observed:
            rows = np.array(history, dtype=float)[-self.observed_rows :]
            valid = rows[:, 9] > 0.5
            rows[valid, 2] -= self.hold_height_m
            rows *= HISTORY_SCALES
            head = rows.ravel()
        else:
            head = np.nan_to_num(np.asarray(prediction, dtype=float).reshape(-1))
            if head.size != self.n_prediction:
                raise ValueError(
                    f"{head.size} prediction values; the layout needs {self.n_prediction}"
                )
        tof_valid = np.asarray(tof_valid, dtype=bool)
        tof = np.where(tof_valid, np.nan_to_num(tof_range) - self.hold_height_m, 0.0)
        flat = np.concatenate([head, tof * TOF_SCALE, tof_valid.astype(float), [wait_fraction]])
        clipped = bool(np.any(np.abs(flat) > OBSERVATION_LIMIT))
        flat = np.clip(flat, -OBSERVATION_LIMIT, OBSERVATION_LIMIT)
        return flat.astype(np.float32), clipped

    def decode(self, observation: np.ndarray) -> TimingObservationParts:
        """Undo :meth:`encode` (up to clipping and float32 rounding)."""
        flat = np.asarray(observation, dtype=float).reshape(-1)
        if flat.size != self.size:
            raise ValueError(f"observation has {flat.size} values; the layout needs {self.size}")
        prediction = np.zeros(0)
        if self.history_observed:
            n = self.observed_rows * len(HISTORY_FEATURES)
            rows = flat[:n].reshape(self.observed_rows, len(HISTORY_FEATURES)) / HISTORY_SCALES
            valid = rows[:, 9] > 0.5
            rows[valid, 2] += self.hold_height_m
        else:
            n = self.n_prediction
            rows = np.zeros((0, len(HISTORY_FEATURES)))
            prediction = flat[:n].copy()
        tof_valid = flat[n + 4 : n + 8] > 0.5
        tof = np.where(tof_valid, flat[n : n + 4] / TOF_SCALE + self.hold_height_m, np.nan)
        return TimingObservationParts(rows, tof, tof_valid, float(flat[n + 8]), prediction)


def observed_prediction_size(timing: TimingConfig) -> int:
    """How many prediction values the observation holds (0: the history instead)."""
    return len(timing.contact_times_s) + 2 if timing.observation == "prediction" else 0


def timing_layout(timing: TimingConfig, env_hz: float) -> TimingObservationLayout:
    """The observation layout of ``timing`` at ``env_hz`` decisions' control rate."""
    n_history = max(1, round(timing.history_s * env_hz))
    return TimingObservationLayout(
        n_history,
        timing.hold_height_m,
        observed_prediction_size(timing),
    )
