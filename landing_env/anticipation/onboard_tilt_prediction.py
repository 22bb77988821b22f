"""The deck ahead: the timing task's use of the scenario's deck-tilt predictor.

:class:`DeckPrediction` loads the fitted predictor
(:class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor`) that the config's
``timing`` section asks for, checks it against the deck-motion history it will read
(:class:`~landing_env.anticipation.deck_history.DeckMotionHistory`), and answers the three questions
the task (:class:`~landing_env.envs.timing.DeckLandingTimingEnv`) puts to it: when a descent
starting now should meet the deck (the contact window), whether a descent under way should go around
(the wave-off, by the predictor or by extrapolating the history), and what the prediction
observation holds (the chance of a level deck at each contact time, the value of waiting on).
"""

from __future__ import annotations

import numpy as np

from estimation.anticipation.linear_predictors import LinearTiltPredictor
from estimation.anticipation.stopping import StoppingValues, predictor_stopping_values
from estimation.frames import tilt_deg
from landing_env.anticipation.deck_history import HISTORY_FEATURES, DeckMotionHistory
from landing_env.config import DeckLandingConfig
from landing_env.errors import ConfigError
from landing_env.resources import PREDICTOR_DIR, tilt_predictor_path
from landing_env.timing_config import SCENARIO_TILT_MODEL, WAVE_OFF_CLIMB_S, TimingConfig

_ROLL, _PITCH, _ROLL_RATE, _PITCH_RATE, _VALID = (
    HISTORY_FEATURES.index(n) for n in ("roll", "pitch", "roll_rate", "pitch_rate", "valid")
)


def commit_by_prediction(values: np.ndarray) -> bool:
    """The stopping rule over :meth:`DeckPrediction.prediction_values`: commit when the
    values are valid and the best contact time's chance of a level deck is at least the
    value of waiting on (``predictive``'s rule, read off the observation)."""
    values = np.asarray(values, dtype=float).reshape(-1)
    chances, value, valid = values[:-2], values[-2], values[-1]
    return bool(valid > 0.5 and chances.size > 0 and float(chances.max()) >= float(value))


class DeckPrediction:
    """The deck-tilt predictor of a timing task and what it foresees.

    ``config``: the task's config (its ``timing`` section is read as it stands at each call);
    ``history``: the task's deck-motion history, which the predictions read; ``env_dt``: the
    control period, seconds.  Bad settings raise :class:`~landing_env.errors.ConfigError`
    naming the key.
    """

    def __init__(
        self, config: DeckLandingConfig, history: DeckMotionHistory, env_dt: float
    ) -> None:
        self.config = config
        self.history = history
        self.env_dt = env_dt
        #: the scenario's deck-tilt predictor, read by the model wave-off, the contact
        #: window and the prediction observation (None when none is on)
        self.tilt_predictor = self._load_tilt_predictor()
        self.wave_off_values = self._wave_off_values()
        #: the value of waiting on that the prediction observation holds
        self.observed_values = self._observed_values()

    @property
    def timing(self) -> TimingConfig:
        """The config's ``timing`` section."""
        return self.config.timing

    def resolved_tilt_model(self) -> str:
        """``timing.tilt_model``, ``scenario`` resolved to the config's ``deck_predictor``
        (the predictor fitted to this scenario's deck; empty when it names none)."""
        name = self.timing.tilt_model
        return self.config.deck_predictor if name == SCENARIO_TILT_MODEL else name

    # ------------------------------------------------------------------ loading
    def _load_tilt_predictor(self) -> LinearTiltPredictor | None:
        """The fitted deck-tilt predictor (read by the ``model`` wave-off, the contact
        window and the prediction observation), checked against the history it will read."""
        t = self.timing
        wave_off = t.wave_off_predictor == "model" and t.wave_off_tilt_deg > 0.0
        observed = t.observation == "prediction"
        if not (wave_off or t.contact_window_s or observed):
            return None
        user = (
            "the model wave-off"
            if wave_off
            else "timing.contact_window_s"
            if t.contact_window_s
            else "timing.observation = 'prediction'"
        )
        name = self.resolved_tilt_model()
        if not name:
            what = (
                "'scenario' reads the scenario's deck_predictor, which this config does not name"
                if t.tilt_model == SCENARIO_TILT_MODEL
                else "is empty"
            )
            raise ConfigError(
                "timing.tilt_model",
                f"{what}; {user} needs the scenario's deck-tilt predictor "
                "(e.g. bench-ss4, or a file written by "
                "`python -m agents.training.tilt_predictor_fit fit`)",
            )
        path = tilt_predictor_path(name)
        try:
            model = LinearTiltPredictor.load(path)
        except (OSError, ValueError) as error:
            shipped = sorted(p.stem.removeprefix("deck_tilt_") for p in PREDICTOR_DIR.glob("*.npz"))
            raise ConfigError(
                "timing.tilt_model",
                f"{name!r}: {error}; give a shipped one ({', '.join(shipped)}) "
                "or a file written by `python -m agents.training.tilt_predictor_fit fit`",
            ) from None
        unknown = sorted(set(model.channels) - set(HISTORY_FEATURES))
        if unknown:
            raise ConfigError(
                "timing.tilt_model",
                f"{path.name} reads {unknown}, which the history does not hold "
                f"({', '.join(HISTORY_FEATURES)})",
            )
        if abs(model.dt_s - self.env_dt) > 1e-9:
            raise ConfigError(
                "timing.tilt_model",
                f"{path.name} was fitted at {1 / model.dt_s:g} Hz; simulation.env_hz is "
                f"{1 / self.env_dt:g}",
            )
        if self.history.length < model.n_window:
            raise ConfigError(
                "timing.history_s",
                f"{t.history_s:g} s is shorter than the deck-tilt predictor's {model.window_s:g} s "
                f"window: set timing.history_s={model.window_s:g}",
            )
        return model

    def _wave_off_values(self) -> StoppingValues | None:
        """The value of waiting on for the ``value`` wave-off: from the chances the
        predictor gave held-out examples at the contact."""
        t = self.timing
        if self.tilt_predictor is None or t.wave_off_rule != "value":
            return None
        if t.wave_off_predictor != "model" or t.wave_off_tilt_deg <= 0.0:
            return None
        values = predictor_stopping_values(
            self.tilt_predictor, t.contact_times_s, t.wave_off_tilt_deg
        )
        if values is None:
            raise ConfigError(
                "timing.wave_off_rule",
                f"'value' needs the chances the predictor {t.tilt_model!r} gave held-out "
                f"examples {t.contact_times_s[0]:g}-{t.contact_times_s[-1]:g} s ahead, which it "
                "does not hold: refit it "
                "with `python -m agents.training.tilt_predictor_fit fit`",
            )
        return values

    def _observed_values(self) -> StoppingValues | None:
        """The value of waiting on for the prediction observation: from the chances the
        predictor gave held-out examples at the contact times, within the touchdown limit."""
        t = self.timing
        if t.observation != "prediction" or self.tilt_predictor is None:
            return None
        limit = self.config.touchdown.max_deck_tilt_deg
        values = predictor_stopping_values(self.tilt_predictor, t.contact_times_s, limit)
        if values is None:
            raise ConfigError(
                "timing.observation",
                f"'prediction' needs the chances the predictor {t.tilt_model!r} gave held-out "
                f"examples {t.contact_times_s[0]:g}-{t.contact_times_s[-1]:g} s ahead, which it "
                "does not hold: refit it with `python -m agents.training.tilt_predictor_fit fit`",
            )
        return values

    def _predictor_columns(self) -> list[int]:
        """The history's columns the deck-tilt predictor reads."""
        assert self.tilt_predictor is not None
        return [HISTORY_FEATURES.index(name) for name in self.tilt_predictor.channels]

    # ------------------------------------------------------------------ what it foresees
    def plan_contact(self) -> float:
        """The contact time, seconds after now, of a descent starting now: with
        ``contact_window_s``, the one in the window where the predictor gives the best chance
        of a deck within the touchdown limit (``expected_contact_s`` when it cannot predict)."""
        t = self.timing
        contact_s = t.expected_contact_s
        if t.contact_window_s and self.tilt_predictor is not None:
            rows = self.history.rows()
            columns = self._predictor_columns()
            best = self.tilt_predictor.best_within(
                rows[:, columns],
                rows[:, _VALID] > 0.5,
                t.contact_times_s,
                self.config.touchdown.max_deck_tilt_deg,
            )
            if best.valid:
                contact_s = best.horizon_s
        return contact_s

    def wave_off_chance(self, elapsed_s: float, wait_s: float) -> float:
        """The chance of a deck within the limit below which the model wave-off aborts,
        ``elapsed_s`` into the descent after ``wait_s`` of waiting: ``wave_off_probability``,
        or with the ``value`` rule the value of waiting on after the climb back."""
        t = self.timing
        if self.wave_off_values is None:
            return t.wave_off_probability
        remaining_s = t.wait_limit_s - wait_s - elapsed_s - WAVE_OFF_CLIMB_S
        return self.wave_off_values.threshold(remaining_s, t.opportunity_s)

    def wave_off_due(self, elapsed_s: float, contact_s: float, wait_s: float) -> bool:
        """The deck tilt predicted at the contact (``contact_s`` after the commit, now
        ``elapsed_s`` ago, after ``wait_s`` of waiting) is beyond ``wave_off_tilt_deg`` while a
        wave-off is still possible (see :class:`~landing_env.timing_config.TimingConfig`)."""
        t = self.timing
        decision_s = t.steps_per_decision * self.env_dt
        first = max(decision_s, t.wave_off_from_s) - 1e-9
        if t.wave_off_tilt_deg <= 0.0 or not first <= elapsed_s <= t.wave_off_until_s:
            return False
        rows = self.history.rows()
        row = rows[-1]
        if row[_VALID] < 0.5:
            return False  # nothing to predict with: the descent goes on
        ahead = max(contact_s - elapsed_s, 0.0)
        if t.wave_off_predictor == "model" and self.tilt_predictor is not None:
            columns = self._predictor_columns()
            prediction = self.tilt_predictor.predict(rows[:, columns], rows[:, _VALID] > 0.5, ahead)
            if not prediction.valid:
                return False  # nothing to predict with: the descent goes on
            return prediction.probability_within(t.wave_off_tilt_deg) < self.wave_off_chance(
                elapsed_s, wait_s
            )
        roll = row[_ROLL] + row[_ROLL_RATE] * ahead
        pitch = row[_PITCH] + row[_PITCH_RATE] * ahead
        if t.wave_off_predictor == "quadratic":
            recent = rows[-max(3, round(t.wave_off_window_s / self.env_dt)) :]
            times = (np.arange(len(recent)) - (len(recent) - 1)) * self.env_dt
            valid = recent[:, _VALID] > 0.5
            if valid.sum() >= 5:
                fit = np.polyfit(times[valid], recent[valid][:, [_ROLL, _PITCH]], 2)
                roll, pitch = (float(np.polyval(fit[:, k], ahead)) for k in range(2))
        return float(tilt_deg(roll, pitch)) > t.wave_off_tilt_deg

    def prediction_values(self, wait_s: float) -> np.ndarray:
        """The prediction observation's values
        (:class:`~landing_env.timing.layout.TimingObservationLayout`) after ``wait_s`` of
        waiting: the chance at each contact time, the value of waiting on, the validity."""
        t = self.timing
        assert self.tilt_predictor is not None and self.observed_values is not None
        rows = self.history.rows()
        columns = self._predictor_columns()
        limit = self.config.touchdown.max_deck_tilt_deg
        chances = np.zeros(len(t.contact_times_s))
        valid = True
        for k, horizon in enumerate(t.contact_times_s):
            prediction = self.tilt_predictor.predict(
                rows[:, columns], rows[:, _VALID] > 0.5, horizon
            )
            if prediction.valid:
                chances[k] = prediction.probability_within(limit)
            else:
                valid = False
        if not valid:
            chances[:] = 0.0
        remaining_s = max(t.wait_limit_s - wait_s, 0.0)
        value = self.observed_values.threshold(remaining_s, t.opportunity_s)
        return np.concatenate([chances, [float(np.clip(value, 0.0, 1.0)), float(valid)]])
