"""The timing task's observation: a flat ``Box`` laid out by :class:`TimingObservationLayout`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from gymnasium import spaces

from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.anticipation.hms_forecast import HORIZONS_S
from landing_env.timing_config import TimingConfig

#: scale from SI units (m, rad, m/s, rad/s) to the observation: decimetres, tenths of a
#: radian, so that typical values are of order one
HISTORY_SCALES = np.array([10.0, 10.0, 10.0, 10.0, 10.0, 1.0, 10.0, 10.0, 10.0, 1.0])
TOF_SCALE = 10.0
#: bound of every scaled observation value; beyond it a value is clipped and flagged
OBSERVATION_LIMIT = 50.0
#: scale of the ``forecast`` observation's helideck forecast (surge, sway, heave in m, from
#: the forecast's present; roll and pitch in rad): decimetres and tenths of a radian
FORECAST_SCALES = np.array([10.0, 10.0, 10.0, 10.0, 10.0])
#: the drone's own state in the ``forecast`` observation: its velocity in its heading frame
#: (m/s) and its roll and pitch (rad), scaled to order one
OWN_STATE_FEATURES: tuple[str, ...] = ("vx_h", "vy_h", "vz_h", "roll", "pitch")
OWN_STATE_SCALES = np.array([10.0, 10.0, 10.0, 10.0, 10.0])


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
    #: the forecast layout's helideck forecast, (horizons, 5) of surge, sway, heave (m, from
    #: the forecast's present) and roll, pitch (rad); empty otherwise
    forecast: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    #: the forecast was made (False: no HMS record yet; its values are then 0)
    forecast_valid: bool = False
    #: the forecast layout's own state (:data:`OWN_STATE_FEATURES`, SI); empty otherwise
    own_state: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class TimingObservationLayout:
    """Layout of the flat observation: ``n_history`` rows of :data:`HISTORY_FEATURES`
    (scaled by :data:`HISTORY_SCALES`, z and the ToF ranges relative to the hold height),
    then 4 ToF ranges, 4 ToF validities and the wait fraction.

    With ``n_prediction`` > 0 (``TimingConfig.observation = "prediction"``) the history rows
    are replaced by ``n_prediction`` values of the deck-tilt predictor, all in [0, 1]: the
    chance of a deck within the touchdown limit at each of the ``n_prediction - 2`` contact
    times, the value of waiting on (the chance a later commit is expected to get), and 1 when
    the prediction is valid (0: too little seen; the chances are then 0).

    With ``n_forecast`` > 0 (``TimingConfig.observation = "forecast"``) only the newest
    history row is observed (the deck's motion is in the forecast) and ``n_forecast * 5 + 1 +
    5`` values follow the wait fraction: the ship's helideck forecast
    (:mod:`landing_env.anticipation.hms_forecast`) at its ``n_forecast`` horizons (surge, sway and
    heave from the forecast's present, roll and pitch; :data:`FORECAST_SCALES`), 1 when it
    was made, and the drone's own state (:data:`OWN_STATE_FEATURES`)."""

    n_history: int
    hold_height_m: float
    n_prediction: int = 0
    n_forecast: int = 0

    @property
    def history_observed(self) -> bool:
        """The observation holds the history rows (not the prediction)."""
        return self.n_prediction == 0

    @property
    def observed_rows(self) -> int:
        """How many of the newest history rows the observation holds."""
        if not self.history_observed:
            return 0
        return 1 if self.n_forecast else self.n_history

    @property
    def size(self) -> int:
        head = (
            self.observed_rows * len(HISTORY_FEATURES)
            if self.history_observed
            else self.n_prediction
        )
        tail = self.n_forecast * len(FORECAST_SCALES) + 1 + len(OWN_STATE_SCALES)
        return head + 9 + (tail if self.n_forecast else 0)

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
        forecast: np.ndarray | None = None,
        own_state: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool]:
        """The flat observation and whether any value had to be clipped to the bounds
        (``prediction``: the prediction layout's values, needed by it; ``forecast``: the
        forecast layout's (n_forecast, 5) forecast, None when none was made, and
        ``own_state``, needed by it)."""
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
        parts = [head, tof * TOF_SCALE, tof_valid.astype(float), [wait_fraction]]
        if self.n_forecast:
            parts.extend(self._forecast_values(forecast, own_state))
        flat = np.concatenate(parts)
        clipped = bool(np.any(np.abs(flat) > OBSERVATION_LIMIT))
        flat = np.clip(flat, -OBSERVATION_LIMIT, OBSERVATION_LIMIT)
        return flat.astype(np.float32), clipped

    def _forecast_values(
        self, forecast: np.ndarray | None, own_state: np.ndarray | None
    ) -> list[np.ndarray]:
        shape = (self.n_forecast, len(FORECAST_SCALES))
        valid = forecast is not None
        values = np.zeros(shape) if forecast is None else np.asarray(forecast, dtype=float)
        if values.shape != shape:
            raise ValueError(f"forecast has shape {values.shape}; the layout needs {shape}")
        own = np.asarray(own_state if own_state is not None else [], dtype=float).reshape(-1)
        if own.size != len(OWN_STATE_SCALES):
            raise ValueError(
                f"own_state has {own.size} values; the layout needs {len(OWN_STATE_FEATURES)} "
                f"({', '.join(OWN_STATE_FEATURES)})"
            )
        scaled = np.nan_to_num(values * FORECAST_SCALES).ravel()
        return [scaled, [float(valid)], np.nan_to_num(own * OWN_STATE_SCALES)]

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
        parts = TimingObservationParts(rows, tof, tof_valid, float(flat[n + 8]), prediction)
        if self.n_forecast:
            start = n + 9
            size = self.n_forecast * len(FORECAST_SCALES)
            block = flat[start : start + size].reshape(self.n_forecast, len(FORECAST_SCALES))
            parts.forecast = block / FORECAST_SCALES
            parts.forecast_valid = bool(flat[start + size] > 0.5)
            parts.own_state = flat[start + size + 1 :] / OWN_STATE_SCALES
        return parts


def observed_prediction_size(timing: TimingConfig) -> int:
    """How many prediction values the observation holds (0: the history instead)."""
    return len(timing.contact_times_s) + 2 if timing.observation == "prediction" else 0


def observed_forecast_size(timing: TimingConfig) -> int:
    """How many horizons of the helideck forecast the observation holds (0: none)."""
    return len(HORIZONS_S) if timing.observation == "forecast" else 0


def timing_layout(timing: TimingConfig, env_hz: float) -> TimingObservationLayout:
    """The observation layout of ``timing`` at ``env_hz`` decisions' control rate."""
    n_history = max(1, round(timing.history_s * env_hz))
    return TimingObservationLayout(
        n_history,
        timing.hold_height_m,
        observed_prediction_size(timing),
        observed_forecast_size(timing),
    )
