"""The timing task's scripted policies and the trained timing model's loader.

``land-now`` (commit at once), ``quiescent`` (the landing-period heuristic,
:mod:`agents.policies.calm_window`), ``predictive`` (the deck-tilt predictor weighed by optimal
stopping) and :class:`TrainedTimingPolicy` (an SB3 model, checked against its card).  Which to
use where, and every other policy, is in :mod:`agents.policies.registry`; the ``build_*``
functions here are its builders.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from agents.common.cards import (
    METADATA_NAME,
    check_compatible,
    env_signature,
    model_class,
    read_metadata,
)
from agents.policies.base import Policy
from agents.policies.calm_window import CalmConfig, CalmPrediction, predict_calm
from agents.policies.deck_forecast import episode_monitor
from agents.policies.registry import MODEL_DIR, find_model
from estimation.anticipation.linear_predictors import LinearMotionPredictor, LinearTiltPredictor
from estimation.anticipation.stopping import (
    StoppingValues,
    predictor_stopping_values,
    value_before_forced,
)
from landing_env.anticipation.deck_history import HISTORY_FEATURES
from landing_env.anticipation.hms_forecast import EpisodeForecast, deck_forecast_for
from landing_env.errors import ConfigError, require_range
from landing_env.resources import tilt_predictor_path
from landing_env.sea.hms import HelideckMonitorConfig
from landing_env.timing.layout import TimingObservationLayout
from landing_env.timing_config import TimingConfig


def shipped_timing_model(algo: str) -> Path:
    """Where the trained timing policy of ``algo`` (``dqn``, ``ppo``, or a variant such as
    ``dqn-predictive``) is installed: ``agents/models/timing_<algo, - as _>.zip``."""
    return MODEL_DIR / f"timing_{algo.replace('-', '_')}.zip"


#: the trained timing policy shipped with the package
SHIPPED_TIMING_MODEL = shipped_timing_model("dqn")

_Z, _ROLL, _PITCH = (HISTORY_FEATURES.index(n) for n in ("z", "roll", "pitch"))
_VALID = HISTORY_FEATURES.index("valid")


# ------------------------------------------------------------------------------ timing policies
class LandNowPolicy(Policy):
    """Commit at the first decision: the lower bar."""

    name = "land-now"

    def reset(self) -> None:
        """Stateless."""

    def act(self, observation: np.ndarray) -> int:
        return 1


class QuiescentPolicy(Policy):
    """Commit when :func:`predict_calm` predicts a calm window as long as the descent."""

    name = "quiescent"

    def __init__(
        self, layout: TimingObservationLayout, dt: float, config: CalmConfig | None = None
    ) -> None:
        self.layout = layout
        self.dt = dt
        self.config = config or CalmConfig()
        self.last: CalmPrediction | None = None

    def reset(self) -> None:
        self.last = None

    def act(self, observation: np.ndarray) -> int:
        parts = self.layout.decode(observation)
        self.last = predict_calm(parts.history, self.dt, self.config)
        return int(self.last.calm)


class PredictivePolicy(Policy):
    """Commit when the chance of a good contact is worth more than waiting for a better one.

    The chance: that the deck's tilt at the contact is within the limit, by a
    :class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor` (the Wiener predictor
    fitted to the estimated deck motion, :mod:`agents.training.tilt_predictor_fit`) on the
    observation's history, with the Gaussian error measured on held-out episodes; the contact comes
    at one of
    ``contact_times_s`` after the commit (``timing.contact_times_s``: the timed descent's
    1.3 s, or a window the environment's descent chooses the best of, the same way), and the
    chance is that of the best.  What
    waiting is worth: the optimal-stopping value
    (:class:`~estimation.anticipation.stopping.StoppingValues`) of the chances the predictor gave
    held-out examples, over the wait left (``wait_limit_s`` less the wait so far), one
    independent opportunity per ``opportunity_s`` (``timing.opportunity_s``).  Needs a
    history at least as long as the predictor's window (``timing.history_s``)."""

    name = "predictive"

    def __init__(
        self,
        layout: TimingObservationLayout,
        dt: float,
        predictor: Any,
        max_tilt_deg: float,
        wait_limit_s: float,
        opportunity_s: float,
        contact_times_s: tuple[float, ...] | None = None,
    ) -> None:

        if not isinstance(predictor, LinearTiltPredictor):
            predictor = LinearTiltPredictor.load(predictor)
        if abs(predictor.dt_s - dt) > 1e-9:
            raise ConfigError(
                "simulation.env_hz",
                f"the deck-tilt predictor was fitted at {1.0 / predictor.dt_s:g} Hz, the "
                f"environment runs at {1.0 / dt:g} Hz",
            )
        if layout.n_history < predictor.n_window:
            raise ConfigError(
                "timing.history_s",
                f"{layout.n_history * dt:g} s is shorter than the deck-tilt predictor's "
                f"{predictor.window_s:g} s window: set timing.history_s={predictor.window_s:g}",
            )
        unknown = sorted(set(predictor.channels) - set(HISTORY_FEATURES))
        if unknown:
            raise ConfigError(
                "timing.tilt_model", f"the predictor reads {unknown}, not in the history"
            )
        require_range("wait_limit_s", wait_limit_s, 0.0, low_inclusive=False)
        require_range("opportunity_s", opportunity_s, 0.0, low_inclusive=False)
        if contact_times_s is None:
            # the timing task's default: the timed descent's one contact time
            contact_times_s = TimingConfig().contact_times_s
        self.contact_times_s = tuple(float(c) for c in contact_times_s)
        if not self.contact_times_s:
            raise ConfigError("timing.contact_window_s", "gives no contact time")
        values = predictor_stopping_values(predictor, self.contact_times_s, max_tilt_deg)
        if values is None:
            raise ConfigError(
                "timing.tilt_model",
                "the predictor holds no held-out predictions to weigh a chance against "
                f"(or none {self.contact_times_s[0]:g}-{self.contact_times_s[-1]:g} s ahead): "
                "refit it with `python -m agents.training.tilt_predictor_fit fit`",
            )
        self.values = values
        self.columns = [HISTORY_FEATURES.index(name) for name in predictor.channels]
        self.layout = layout
        self.dt = dt
        self.predictor = predictor
        self.max_tilt_deg = max_tilt_deg
        self.wait_limit_s = wait_limit_s
        self.opportunity_s = opportunity_s
        self.last: Any = None
        self.last_probability = 0.0

    def reset(self) -> None:
        self.last = None
        self.last_probability = 0.0

    def threshold(self, wait_fraction: float) -> float:
        """The chance a commit needs after ``wait_fraction`` of the wait limit: the value of
        waiting on."""
        remaining_s = (1.0 - wait_fraction) * self.wait_limit_s
        return self.values.threshold(remaining_s, self.opportunity_s)

    def _chance(self, rows: np.ndarray) -> float:
        self.last = self.predictor.best_within(
            rows[:, self.columns], rows[:, _VALID] > 0.5, self.contact_times_s, self.max_tilt_deg
        )
        self.last_probability = self.last.probability_within(self.max_tilt_deg)
        return self.last_probability

    def act(self, observation: np.ndarray) -> int:
        parts = self.layout.decode(observation)
        chance = self._chance(parts.history)
        return int(self.last.valid and chance >= self.threshold(parts.wait_fraction))


#: when the ship's contact comes after a commit, seconds: the deck-frame descent from the 2 m
#: hold (``land-now`` on the ``-v8`` ids, realistic sensing, 200 seeds from 1 000 000: at
#: ``ship-ss6`` 10, 30, 50, 70 and 90 % of the contacts by 2.69, 2.95, 3.15, 3.50 and 4.55 s;
#: at ``ship-ss5`` by 2.77, 2.97, 3.09, 3.30 and 3.68 s, the time to land less the 1.95 s
#: warm-up); the chance is their mean
SHIP_CONTACT_TIMES_S = (2.75, 3.0, 3.25, 3.5, 4.5)


class HelideckPredictivePolicy(Policy):
    """``predictive`` at sea: the same optimal stopping, on the ship's helideck forecast.

    The chance: that the deck's tilt at the contact is within the limit, by the helideck
    forecast (:mod:`landing_env.anticipation.hms_forecast`: the direct multi-horizon linear
    predictor of the ship's HMS record, the helideck's surge, sway, heave, roll and pitch a few
    seconds ahead), its Gaussian error the forecast's held-out residuals at each horizon.  The
    ship's descent is not timed: its contact comes 2.7-4.5 s after the commit, spread by the
    wind, so the chance is the mean over ``contact_times_s`` (:data:`SHIP_CONTACT_TIMES_S`).
    What waiting is worth: the optimal-stopping value of the chances the forecast gave its
    held-out examples, over the wait left, one opportunity per ``opportunity_s``; once the
    forced commit at the wait limit is within the forecast's reach (its contact no more than
    the last horizon ahead), that value is built on the chance the forecast gives the forced
    commit itself rather than on the long-run mean
    (:func:`~estimation.anticipation.stopping.value_before_forced`), so a rough spell that
    will still be rough at the limit is not waited out.

    ``forecast``: the fitted forecast (the config's ``deck_forecast``: a training family such
    as ``ship-broad``, or the scenario's own sea); None: each episode identifies its own
    online from the HMS's record (``deck_forecast: online``), and the value of waiting is that
    forecast's.  The HMS is the ship's (CAP 437), its errors drawn per episode."""

    name = "predictive"

    def __init__(
        self,
        env: Any,
        forecast: Any,
        hms: Any,
        max_tilt_deg: float,
        wait_limit_s: float,
        opportunity_s: float,
        contact_times_s: tuple[float, ...] = SHIP_CONTACT_TIMES_S,
        seed: int = 0,
    ) -> None:
        require_range("wait_limit_s", wait_limit_s, 0.0, low_inclusive=False)
        require_range("opportunity_s", opportunity_s, 0.0, low_inclusive=False)
        self.contact_times_s = tuple(float(c) for c in contact_times_s)
        if not self.contact_times_s:
            raise ConfigError("contact_times_s", "gives no contact time")
        if forecast is not None:
            horizons = forecast.horizons_s
            if min(self.contact_times_s) < horizons[0] or max(self.contact_times_s) > horizons[-1]:
                raise ConfigError(
                    "contact_times_s",
                    f"{self.contact_times_s} lie outside the forecast's "
                    f"{horizons[0]:g}-{horizons[-1]:g} s",
                )
        self.env = env.unwrapped
        self.layout = self.env.layout
        self.forecast = forecast
        self.hms = hms
        self.max_tilt_deg = max_tilt_deg
        self.wait_limit_s = wait_limit_s
        self.opportunity_s = opportunity_s
        self.seed = seed
        self._values: dict[int, Any] = {}
        self._episode_forecast: Any = None
        self.last: list[Any] = []
        self.last_probability = 0.0
        self.last_threshold = 0.0

    def reset(self) -> None:
        self._episode_forecast = None
        self.last = []
        self.last_probability = 0.0
        self.last_threshold = 0.0

    def _stopping_values(self, forecast: Any) -> Any:
        """The value of waiting on for the chances ``forecast`` gives (kept per forecast: an
        online one changes every refit)."""
        key = id(forecast)
        if key not in self._values:
            if len(self._values) > 8:
                self._values.clear()
            chances = forecast.chances(self.contact_times_s, self.max_tilt_deg, combine="mean")
            self._values[key] = (forecast, StoppingValues.from_samples(chances), chances)
        return self._values[key][1]

    def chance(self, wait_fraction: float) -> float:
        """The chance a commit now meets a deck within the tilt limit (0 without a
        forecast), and the chance it needs after ``wait_fraction`` of the wait limit
        (``last_threshold``)."""
        t_s = float(self.env.world.time)
        if self._episode_forecast is None:
            monitor = episode_monitor(self.env, self.seed, self.hms)
            self._episode_forecast = EpisodeForecast(self.forecast, monitor)
        forecast = self._episode_forecast.at(t_s)
        if forecast is None:
            self.last, self.last_probability = [], 0.0
            return 0.0
        _, measured = self._episode_forecast.monitor.window(t_s, forecast.window_s)
        chance, self.last = forecast.mean_within(
            measured,
            np.ones(len(measured), dtype=bool),
            self.contact_times_s,
            self.max_tilt_deg,
        )
        self.last_probability = chance
        remaining_s = (1.0 - wait_fraction) * self.wait_limit_s
        self.last_threshold = self._stopping_values(forecast).threshold(
            remaining_s, self.opportunity_s
        )
        forced_times = [remaining_s + c for c in self.contact_times_s]
        if remaining_s > 0.0 and max(forced_times) <= float(forecast.horizons_s[-1]):
            # the forced commit is within the forecast's reach: the value of waiting is
            # built on the chance the forecast gives it, not on the long-run mean
            forced, predictions = forecast.mean_within(
                measured,
                np.ones(len(measured), dtype=bool),
                forced_times,
                self.max_tilt_deg,
            )
            if all(p.valid for p in predictions):
                samples = self._values[id(forecast)][2]
                self.last_threshold = value_before_forced(
                    samples, forced, remaining_s, self.opportunity_s
                )
        return chance

    def act(self, observation: np.ndarray) -> int:
        chance = self.chance(self.layout.decode(observation).wait_fraction)
        valid = bool(self.last) and all(p.valid for p in self.last)
        return int(valid and chance >= self.last_threshold)


class TrainedTimingPolicy(Policy):
    """A trained SB3 model (PPO or DQN) of the timing task, acting deterministically.

    The model's card (:mod:`agents.common.cards`: env id and version, observation layout,
    estimator, sensing profiles, training config) is read on load; a model without one is
    refused.  :meth:`check_env` refuses an environment that differs from the card.
    """

    def __init__(self, path: str | Path = SHIPPED_TIMING_MODEL, device: str = "cpu") -> None:
        self.path = find_model(path)
        if not self.path.is_file():
            algo = "ppo" if "ppo" in self.path.name else "dqn"
            raise FileNotFoundError(
                f"no trained timing model at {self.path}; train one with `deck-landing train "
                f"timing --config configs/train/timing_{algo}.yaml --install`"
            )
        metadata = read_metadata(self.path)
        if metadata is None:
            raise ConfigError(
                "model",
                f"{self.path.name} has no card ({METADATA_NAME}: what it was trained on); add "
                "it by training it with `deck-landing train timing`",
            )
        self.metadata = metadata
        self.model = model_class(self.path).load(self.path, device=device)
        self.name = f"timing-{type(self.model).__name__.lower()}"
        #: a recurrent policy's memory (RecurrentPPO), cleared by :meth:`reset`
        self.recurrent = self.name == "timing-recurrentppo"
        self._state: Any = None
        self._episode_start = True

    def check_env(self, env: Any, allow_mismatch: tuple[str, ...] = ()) -> None:
        """Refuse ``env`` unless it is what the model was trained on (see the card); the
        fields in ``allow_mismatch`` (``sensing``, ``estimator``, ...) may differ."""
        base = env.unwrapped
        if "lookahead" in self.metadata.observation:
            raise ConfigError(
                "policy",
                f"{self.path.name} decides on the onboard look-ahead's features: evaluate it "
                "with --policy timing-dqn-lookahead",
            )
        # the card first: it names the setting that differs, where a shape would not
        check_compatible(self.metadata, env_signature(base), self.path.name, allow_mismatch)
        self.check_layout(base.layout.size)

    def check_observation(self, signature: dict[str, Any]) -> None:
        """Refuse an observation whose meaning (``observation_signature``) differs."""
        check_compatible(self.metadata, {"observation": signature}, self.path.name)
        self.check_layout(int(signature["size"]))

    def check_layout(self, observation_size: int) -> None:
        """Refuse an environment whose observation does not match the model's."""
        expected = self.model.observation_space.shape
        if expected != (observation_size,):
            raise ConfigError(
                "timing",
                f"the model {self.path.name} expects observations of shape {expected}, the "
                f"environment gives ({observation_size},): use the timing settings it was "
                "trained with (history_s, env_hz)",
            )

    def reset(self) -> None:
        """Forget a recurrent policy's memory (a feed-forward one has none)."""
        self._state = None
        self._episode_start = True

    def act(self, observation: np.ndarray) -> int:
        if self.recurrent:
            action, self._state = self.model.predict(
                observation,
                state=self._state,
                episode_start=np.array([self._episode_start]),
                deterministic=True,
            )
            self._episode_start = False
        else:
            action, _ = self.model.predict(observation, deterministic=True)
        return int(np.asarray(action).reshape(-1)[0])


# ------------------------------------------------------------------------------ builders
def _tilt_model(model_path: str | Path | None, scenario_model: str) -> Any:
    """The deck-tilt predictor of the predictive policy: ``--model``, else the scenario's
    (``timing.tilt_model``), loaded; a missing or malformed one names the key."""

    if model_path is None and not scenario_model:
        raise ConfigError(
            "timing.tilt_model",
            "is empty: the predictive policy needs the scenario's deck-tilt predictor (set "
            "timing.tilt_model=NAME or pass --model FILE; fit one with "
            "`python -m agents.training.tilt_predictor_fit fit`)",
        )
    path = Path(model_path) if model_path is not None else tilt_predictor_path(scenario_model)
    try:
        return LinearTiltPredictor.load(path)
    except (OSError, ValueError) as error:
        raise ConfigError("timing.tilt_model", f"{path}: {error}") from None


def _require_timing(env: Any, name: str) -> Any:
    base = env.unwrapped
    if not hasattr(base, "layout"):
        raise ConfigError("policy", f"{name} acts in the timing task (DeckLandingTiming)")
    return base


def _require_history(base: Any, name: str) -> None:
    if base.layout.observed_rows != base.layout.n_history:
        raise ConfigError(
            "timing.observation",
            f"is {base.timing.observation!r}; {name} reads the deck-pose history: use 'history'",
        )


def build_land_now(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """``land-now``: commit at once."""
    _require_timing(env, "land-now")
    return LandNowPolicy()


def build_quiescent(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """``quiescent`` for ``env`` (a timing environment observing the history)."""
    base = _require_timing(env, "quiescent")
    _require_history(base, "quiescent")
    return QuiescentPolicy(base.layout, base.env_dt)


def build_predictive(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """``predictive``: ``model_path`` is a deck-tilt predictor (else the scenario's); over a
    ship's helideck, the ship's helideck forecast (:class:`HelideckPredictivePolicy`)."""
    base = _require_timing(env, "predictive")
    if base.config.motion.kind == "ship":
        return _build_helideck_predictive(base, model_path)
    _require_history(base, "predictive")
    return PredictivePolicy(
        base.layout,
        base.env_dt,
        _tilt_model(model_path, base.deck_prediction.resolved_tilt_model()),
        base.config.touchdown.max_deck_tilt_deg,
        base.timing.wait_limit_s,
        base.timing.opportunity_s,
        base.timing.contact_times_s,
    )


def _build_helideck_predictive(base: Any, model_path: str | None) -> Any:
    """``predictive`` over a ship's helideck: its forecast is the config's ``deck_forecast``
    (``model_path``: a forecast file of :class:`LinearMotionPredictor`)."""
    hms = HelideckMonitorConfig()
    forecast: LinearMotionPredictor | None
    if model_path is not None:
        try:
            forecast = LinearMotionPredictor.load(model_path)
        except (OSError, ValueError) as error:
            raise ConfigError("model", f"{model_path}: {error}") from None
    else:
        forecast = deck_forecast_for(base.config, hms)
    return HelideckPredictivePolicy(
        base,
        forecast,
        hms,
        base.config.touchdown.max_deck_tilt_deg,
        base.timing.wait_limit_s,
        base.timing.opportunity_s,
    )


def build_trained(env: Any, model_path: str | None, allow: tuple[str, ...]) -> Any:
    """A trained SB3 timing model at ``model_path``, checked against ``env`` (its card)."""
    _require_timing(env, "a trained timing model")
    if model_path is None:
        raise ConfigError("model", "a trained timing policy needs --model PATH (an SB3 zip)")
    policy = TrainedTimingPolicy(model_path)
    policy.check_env(env, allow)
    return policy
