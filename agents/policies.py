"""Landing policies that read only the observation (the estimated deck pose and the ToF).

* ``align-descend`` (``DeckLanding-v0``, Box actions): visual servoing on the estimated deck
  pose: centre over the tag while descending to a hold height, flare there until a calm
  window is predicted, then the final descent to touchdown.
* ``quiescent`` (``DeckLandingTiming-v0``): commit when a calm window at least as long as the
  descent is predicted from the recent deck motion (the classic landing-period heuristic).
* ``land-now`` (``DeckLandingTiming-v0``): commit at once; the lower bar.
* ``oracle`` (``DeckLandingTiming-v0``): the best timing of all, found by trying every commit
  in a saved copy of the episode (privileged: it knows the future, :mod:`agents.oracle`);
  the upper bar.
* ``deck-oracle`` (``DeckLandingTiming-v0``): the timing that knows the deck's future and
  nothing else to come (the gusts and the sensors' noise drawn anew in its look-ahead,
  :class:`agents.oracle.DeckOracleTimingPolicy`): the bar for timing by deck prediction.
* ``deck-forecast`` (``DeckLandingTiming-v0``): the deck oracle with the deck's future
  replaced by a forecast from the ship's helideck monitoring system
  (:mod:`agents.deck_forecast`; its look-ahead still flies a copy of the simulation).
* ``deck-forecast-onboard`` (``DeckLandingTiming-v0``): the same look-ahead as a model the
  drone carries: started from its own deck-pose estimate and wind estimate, with its drag
  and thrust uncertain (:class:`agents.deck_forecast.OnboardModelConfig`), and its standard
  falling to half the look-aheads over the last 5 s of the wait.
* ``timing-dqn`` / ``timing-ppo`` (``DeckLandingTiming-v0``): a trained SB3 policy,
  ``agents/models/timing_dqn.zip`` (shipped) or ``timing_ppo.zip``, or any model file trained
  by :mod:`agents.training`.
* ``timing-dqn-realistic`` (``DeckLandingTiming-v0``): the DQN trained for realistic sensing
  with the ``tight`` estimate observed, ``agents/models/timing_dqn_realistic.zip`` (its card
  says so; ``configs/train/timing_dqn_realistic.yaml``).
* ``timing-dqn-randomised`` (``DeckLandingTiming-v0``): that DQN trained on from its weights
  over bench sea states 4 and 5 and ideal, realistic and twice-realistic sensing,
  ``agents/models/timing_dqn_randomised.zip`` (``configs/train/timing_dqn_randomised.yaml``).
  These three were trained on the range-scheduled final descent (the bench scenarios of
  ``deck-landing evaluate landing`` fly the timed one: run them with
  ``--set timing.guidance.descent_profile=range``).
* ``timing-dqn-timed`` (``DeckLandingTiming-v0``): the DQN trained for realistic sensing with
  ``tight`` observed on the **timed** final descent (``DeckLandingTiming-BenchSS4-v1``; the
  contact a fixed 1.3 s after the commit), ``agents/models/timing_dqn_timed.zip``
  (``configs/train/timing_dqn_timed.yaml``).
* ``timing-dqn-waveoff`` (``DeckLandingTiming-v0``): the same on the timed descent with the
  wave-off (``timing.wave_off_tilt_deg`` 4.5: a descent whose deck is predicted too tilted at
  the contact is aborted 0.4-0.7 s in), ``agents/models/timing_dqn_waveoff.zip``
  (``configs/train/timing_dqn_waveoff.yaml``).
* ``predictive`` (``DeckLandingTiming-v0``): commit when the scenario's deck-tilt predictor
  (:mod:`estimation.deck_prediction`, a Wiener predictor fitted on the estimated motion,
  ``timing.tilt_model``) gives a chance that the deck is within the touchdown limit at the
  contact worth more than waiting on (the optimal-stopping value of the chances it gives,
  :mod:`estimation.optimal_stopping`; :class:`PredictivePolicy`); it reads an 8 s history
  (``DeckLandingTiming-BenchSS{3,4,5}-v3``, which also wave off by the same predictor and
  the same value).
* ``timing-dqn-waveoff30`` (``DeckLandingTiming-v0``): the same with a 30 s wait limit
  (``--set timing.wave_off_tilt_deg=4.5 timing.wait_limit_s=30``),
  ``agents/models/timing_dqn_waveoff30.zip`` (``configs/train/timing_dqn_waveoff30.yaml``).
* ``timing-dqn-predictive`` (``DeckLandingTiming-v0``): a DQN that weighs what ``predictive``
  weighs: it observes, in place of the history, the deck-tilt predictor's chance at each
  contact time and the value of waiting on (``timing.observation: prediction``,
  ``DeckLandingTiming-BenchSS{3,4,5}-v5``), ``agents/models/timing_dqn_predictive.zip``
  (``configs/train/timing_dqn_predictive.yaml``, then trained on by
  ``configs/train/timing_dqn_predictive_finetune.yaml``).
* ``timing-dqn-lookahead`` (``DeckLandingTiming-v0``, sea scenarios): a DQN that weighs what
  ``deck-forecast-onboard``'s look-ahead foresees: every 0.5 s it reads 16 commits tried in
  the onboard model's futures and decides (:mod:`agents.lookahead`; fitted offline on
  recorded episodes by ``configs/train/timing_dqn_lookahead_offline.yaml``),
  ``agents/models/timing_dqn_lookahead.zip``.
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from estimation.frames import camera_to_heading_xy, tilt_deg
from landing_env.config import ActionConfig
from landing_env.envs.actions import action_from_setpoint
from landing_env.envs.guidance import DeckGuidance, GuidanceGains
from landing_env.envs.history import HISTORY_FEATURES, DeckMotionHistory
from landing_env.envs.timing import TimingConfig, TimingObservationLayout
from landing_env.errors import ConfigError, require_range
from landing_env.physics.controller import VelocitySetpoint
from landing_env.sensors.tof import TofConfig

MODEL_DIR = Path(__file__).resolve().parent / "models"


def shipped_timing_model(algo: str) -> Path:
    """Where the trained timing policy of ``algo`` (``dqn``, ``ppo``, or a variant such as
    ``dqn-realistic``) is installed: ``agents/models/timing_<algo, - as _>.zip``."""
    return MODEL_DIR / f"timing_{algo.replace('-', '_')}.zip"


#: the trained timing policy shipped with the package
SHIPPED_TIMING_MODEL = shipped_timing_model("dqn")

_Z, _ROLL, _PITCH = (HISTORY_FEATURES.index(n) for n in ("z", "roll", "pitch"))
_VALID = HISTORY_FEATURES.index("valid")


# ------------------------------------------------------------------------------ calm windows
@dataclass
class CalmConfig:
    """When the deck counts as calm enough to start the final descent."""

    #: sliding window of estimated deck motion that must have been calm, seconds (as long as
    #: the descent: the deck has been calm for a descent's length)
    window_s: float = 1.3
    #: duration of the final descent the calm must last for (the prediction horizon), seconds
    descent_s: float = 1.3
    #: fraction of the fitted trend extrapolated over the descent: 0 predicts that the calm
    #: persists, 1 extrapolates the straight line (which overshoots on an oscillating deck)
    trend_weight: float = 0.25
    #: largest deck tilt relative to the camera, now and predicted at touchdown, degrees
    max_tilt_deg: float = 4.0
    #: also require every valid sample of the window to be within ``max_tilt_deg`` (the deck
    #: has been calm for a window, the landing-period heuristic); False judges by the fitted
    #: line alone
    require_calm_window: bool = True
    #: largest heave rate of the deck relative to the camera, m/s
    max_heave_rate: float = 0.15
    #: fewer valid estimates than this fraction of the window: not calm (nothing to judge by)
    min_valid_fraction: float = 0.8

    def __post_init__(self) -> None:
        require_range("window_s", self.window_s, 0.1, 10.0)
        require_range("descent_s", self.descent_s, 0.0, 10.0)
        require_range("trend_weight", self.trend_weight, 0.0, 1.0)
        require_range("max_tilt_deg", self.max_tilt_deg, 0.0, 45.0, low_inclusive=False)
        require_range("max_heave_rate", self.max_heave_rate, 0.0, low_inclusive=False)
        require_range("min_valid_fraction", self.min_valid_fraction, 0.0, 1.0)


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

    ``history`` holds rows of :data:`~landing_env.envs.history.HISTORY_FEATURES` (SI units),
    oldest first, one per ``dt``.  Over the last ``window_s`` the valid samples must all show
    a tilt below ``max_tilt_deg``; straight lines fitted to roll, pitch and z there give the
    rates, and the tilt extrapolated ``descent_s`` ahead (``trend_weight`` of the trend) and
    the heave rate must be within the limits too (the tilt is convex in (roll, pitch), so on a
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


# ------------------------------------------------------------------------------ timing policies
class TimingPolicy(Protocol):
    """A policy of the timing task: 0 = wait, 1 = commit."""

    name: str

    def reset(self) -> None: ...

    def act(self, observation: np.ndarray) -> int: ...


class LandNowPolicy:
    """Commit at the first decision: the lower bar."""

    name = "land-now"

    def reset(self) -> None:
        """Stateless."""

    def act(self, observation: np.ndarray) -> int:
        return 1

    def __call__(self, observation: np.ndarray) -> int:
        return self.act(observation)


class QuiescentPolicy:
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

    def __call__(self, observation: np.ndarray) -> int:
        return self.act(observation)


class PredictivePolicy:
    """Commit when the chance of a good contact is worth more than waiting for a better one.

    The chance: that the deck's tilt at the contact is within the limit, by a
    :class:`~estimation.deck_prediction.LinearTiltPredictor` (the Wiener predictor fitted to
    the estimated deck motion, :mod:`agents.deck_predictor`) on the observation's history,
    with the Gaussian error measured on held-out episodes; the contact comes at one of
    ``contact_times_s`` after the commit (``timing.contact_times_s``: the timed descent's
    1.3 s, or a window the environment's descent chooses the best of, the same way), and the
    chance is that of the best.  What
    waiting is worth: the optimal-stopping value
    (:class:`~estimation.optimal_stopping.StoppingValues`) of the chances the predictor gave
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
        from estimation.deck_prediction import LinearTiltPredictor

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
        values = predictor.stopping_values(self.contact_times_s, max_tilt_deg)
        if values is None:
            raise ConfigError(
                "timing.tilt_model",
                "the predictor holds no held-out predictions to weigh a chance against "
                f"(or none {self.contact_times_s[0]:g}-{self.contact_times_s[-1]:g} s ahead): "
                "refit it with `python -m agents.deck_predictor fit`",
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

    def probability(self, observation: np.ndarray) -> float:
        """The predicted chance that a commit now meets a deck within the tilt limit."""
        return self._chance(self.layout.decode(observation).history)

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

    def __call__(self, observation: np.ndarray) -> int:
        return self.act(observation)


def _model_class(path: Path) -> Any:
    """PPO, DQN or RecurrentPPO, read from the saved model's data (no trial loading)."""
    from stable_baselines3 import DQN, PPO

    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    module = str(data.get("policy_class", {}).get("__module__", ""))
    if "recurrent" in module:
        from sb3_contrib import RecurrentPPO

        return RecurrentPPO
    return DQN if ".dqn." in module else PPO


class TrainedTimingPolicy:
    """A trained SB3 model (PPO or DQN) of the timing task, acting deterministically.

    The model's card (:mod:`agents.model_metadata`: env id and version, observation layout,
    estimator, sensing profiles, training config) is read on load; a model without one is
    refused.  :meth:`check_env` refuses an environment that differs from the card.
    """

    def __init__(self, path: str | Path = SHIPPED_TIMING_MODEL, device: str = "cpu") -> None:
        from agents.model_metadata import METADATA_NAME, read_metadata

        self.path = Path(path)
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
                "it with `python -m agents.model_metadata stamp MODEL --config TRAINING_YAML`",
            )
        self.metadata = metadata
        self.model = _model_class(self.path).load(self.path, device=device)
        self.name = f"timing-{type(self.model).__name__.lower()}"
        #: a recurrent policy's memory (RecurrentPPO), cleared by :meth:`reset`
        self.recurrent = self.name == "timing-recurrentppo"
        self._state: Any = None
        self._episode_start = True

    def check_env(self, env: Any, allow_mismatch: tuple[str, ...] = ()) -> None:
        """Refuse ``env`` unless it is what the model was trained on (see the card); the
        fields in ``allow_mismatch`` (``sensing``, ``estimator``, ...) may differ."""
        from agents.model_metadata import check_compatible, env_signature

        base = env.unwrapped
        if "lookahead" in self.metadata.observation:
            raise ConfigError(
                "policy",
                f"{self.path.name} decides on the onboard look-ahead's features: evaluate it "
                "with --policy timing-dqn-lookahead",
            )
        self.check_layout(base.layout.size)
        check_compatible(self.metadata, env_signature(base), self.path.name, allow_mismatch)

    def check_observation(self, signature: dict[str, Any]) -> None:
        """Refuse an observation whose meaning (``observation_signature``) differs."""
        from agents.model_metadata import check_compatible

        self.check_layout(int(signature["size"]))
        check_compatible(self.metadata, {"observation": signature}, self.path.name)

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

    def __call__(self, observation: np.ndarray) -> int:
        return self.act(observation)


# ------------------------------------------------------------------------------ align-descend
class Phase(str, Enum):
    """Phases of :class:`AlignDescendPolicy`."""

    APPROACH = "approach"
    FLARE = "flare"
    DESCENT = "descent"


def _flare_calm() -> CalmConfig:
    # low over the deck the descent is short (about 1 s), so a straight-line extrapolation of
    # the last half second predicts the tilt at touchdown well, even on the papers' slow bench
    return CalmConfig(
        window_s=0.5,
        descent_s=1.0,
        trend_weight=1.0,
        max_tilt_deg=3.5,
        require_calm_window=False,
    )


@dataclass
class AlignDescendConfig:
    """Settings of the align-descend policy (heights are camera ranges above the deck)."""

    #: height of the flare, where the policy waits for a calm window, metres (low, so that
    #: the final descent is short and the calm prediction short-range; the tag still fits
    #: the image)
    hold_height_m: float = 0.4
    #: the flare starts when the range is within this of the hold height, metres
    hold_tolerance_m: float = 0.1
    #: the final descent starts regardless after this long in the flare, seconds
    max_flare_s: float = 25.0
    #: search speed without an estimate: climb (to widen the view) while a ToF sees a
    #: surface, descend while none does (every surface is beyond the ToF range), m/s
    search_climb_speed: float = 0.3
    #: horizontal speed towards the deck when the ToF ranges show its edge, m/s
    edge_seek_speed: float = 0.3
    #: ToF ranges shorter than the longest by more than this are taken as on the deck, metres
    edge_step_m: float = 0.1
    #: back to the approach after this long without a tag in the flare, seconds
    lost_tag_s: float = 1.0
    #: length of the motion history kept for the calm prediction, seconds
    history_s: float = 2.0
    rate_window_s: float = 0.5
    calm: CalmConfig = field(default_factory=_flare_calm)
    guidance: GuidanceGains = field(default_factory=GuidanceGains)

    def __post_init__(self) -> None:
        require_range("hold_height_m", self.hold_height_m, 0.3, 3.0)
        require_range("hold_tolerance_m", self.hold_tolerance_m, 0.0, low_inclusive=False)
        require_range("max_flare_s", self.max_flare_s, 0.0)
        require_range("search_climb_speed", self.search_climb_speed, 0.0)
        require_range("edge_seek_speed", self.edge_seek_speed, 0.0)
        require_range("edge_step_m", self.edge_step_m, 0.0, low_inclusive=False)
        require_range("lost_tag_s", self.lost_tag_s, 0.0)
        require_range(
            "history_s",
            self.history_s,
            self.calm.window_s,
            10.0,
            bounds_from=f"calm.window_s = {self.calm.window_s}",
        )
        require_range(
            "rate_window_s",
            self.rate_window_s,
            0.1,
            self.history_s,
            bounds_from=f"history_s = {self.history_s}",
        )


class AlignDescendPolicy:
    """Visual servoing for ``DeckLanding-v0`` on the estimated deck pose.

    Approach: centre over the tag and descend while aligned to the hold height; without a
    valid estimate, move towards the deck when the ToF ranges show its edge (IHRCF and CRHF
    need every ToF spot on the deck), else climb to bring the tag into view (or descend when
    no ToF sees anything: every surface is then beyond its range).  Flare: hold
    there, aligned, until :func:`predict_calm` predicts a calm window as long as the descent
    (or ``max_flare_s`` has passed).  Descent: the final descent of
    :class:`~landing_env.envs.guidance.DeckGuidance` down to touchdown.  Output: the Box(4)
    action, normalised by :class:`ActionConfig`.
    """

    name = "align-descend"

    def __init__(
        self,
        action: ActionConfig | None = None,
        config: AlignDescendConfig | None = None,
        dt: float = 0.05,
        tof_mounts_c: np.ndarray | None = None,
    ) -> None:
        self.action = action or ActionConfig()
        self.config = config or AlignDescendConfig()
        self.dt = dt
        mounts = np.asarray(
            tof_mounts_c if tof_mounts_c is not None else TofConfig().mount_offsets_c, dtype=float
        )
        # each sensor's direction from the camera in the heading frame, for seeking the deck
        # with the ranges
        directions = camera_to_heading_xy(mounts[:, :2])
        norms = np.linalg.norm(directions, axis=1, keepdims=True)
        self._tof_directions = directions / np.where(norms > 0.0, norms, 1.0)
        self.guidance = DeckGuidance(self.config.guidance)
        self.history = DeckMotionHistory(
            max(1, round(self.config.history_s / dt)),
            max(2, round(self.config.rate_window_s / dt)),
            dt,
        )
        self.reset()

    def reset(self) -> None:
        self.phase = Phase.APPROACH
        self.guidance.reset()
        self.history.reset()
        self._flare_s = 0.0
        self._unseen_s = 0.0
        self.last: CalmPrediction | None = None

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return self.act(observation)

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        c = self.config
        seen = bool(observation["deck_pose_valid"][0])
        self._unseen_s = 0.0 if seen else self._unseen_s + self.dt
        self.history.push(observation["deck_pose"].astype(float) if seen else None)
        height = self.guidance.range_m(observation)

        if self.phase is Phase.FLARE and self._unseen_s > c.lost_tag_s:
            self.phase = Phase.APPROACH
        if self.phase is Phase.APPROACH and self.guidance.aligned(observation):
            if abs(height - c.hold_height_m) < c.hold_tolerance_m:
                self.phase, self._flare_s = Phase.FLARE, 0.0
        if self.phase is Phase.FLARE:
            self._flare_s += self.dt
            if self._flare_s >= c.calm.window_s:
                self.last = predict_calm(self.history.rows(), self.dt, c.calm)
                if self.last.calm or self._flare_s >= c.max_flare_s:
                    self.phase = Phase.DESCENT

        if self.phase is Phase.DESCENT:
            setpoint = self.guidance.descend(observation)
        elif self.phase is Phase.FLARE:
            setpoint = self.guidance.hold(observation, c.hold_height_m)
        elif seen:
            setpoint = self.guidance.hold(observation, c.hold_height_m)
            if not self.guidance.aligned(observation):
                # centre first, then descend: the tag stays in view on the way down
                setpoint = VelocitySetpoint(
                    np.array([*setpoint.velocity_h[:2], max(setpoint.velocity_h[2], 0.0)]),
                    setpoint.yaw_rate,
                )
        else:
            towards = self._deck_direction(observation)
            if towards is not None:
                setpoint = VelocitySetpoint(np.array([*(c.edge_seek_speed * towards), 0.0]), 0.0)
            elif observation["tof_valid"].any():
                setpoint = VelocitySetpoint(np.array([0.0, 0.0, c.search_climb_speed]), 0.0)
            else:
                # nothing within the ToF range below: high above the sea, safe to come down
                setpoint = VelocitySetpoint(np.array([0.0, 0.0, -c.search_climb_speed]), 0.0)
        return normalise_setpoint(setpoint, self.action)

    def _deck_direction(self, observation: dict[str, np.ndarray]) -> np.ndarray | None:
        """Unit heading-frame direction towards the deck when the ToF ranges straddle its edge.

        The deck stands above the sea: sensors whose ranges are clearly shorter than the
        longest (a sensor without a return counts as longest) are over the deck.
        """
        valid = observation["tof_valid"].astype(bool)
        ranges = np.where(valid, observation["tof_range"].astype(float), np.inf)
        on_deck = ranges < np.max(ranges) - self.config.edge_step_m
        if not on_deck.any():
            return None
        vector = self._tof_directions[on_deck].sum(axis=0)
        norm = float(np.linalg.norm(vector))
        return vector / norm if norm > 0.0 else None


#: the Box(4) encoding of a set-point lives with the actions (kept here under its old name)
normalise_setpoint = action_from_setpoint


# ------------------------------------------------------------------------------ registry
#: policy name -> the environment it acts in
POLICY_ENVS: dict[str, str] = {
    "align-descend": "DeckLanding-v0",
    "quiescent": "DeckLandingTiming-v0",
    "land-now": "DeckLandingTiming-v0",
    "oracle": "DeckLandingTiming-v0",
    "deck-oracle": "DeckLandingTiming-v0",
    "deck-forecast": "DeckLandingTiming-v0",
    "deck-forecast-onboard": "DeckLandingTiming-v0",
    "timing-dqn": "DeckLandingTiming-v0",
    "timing-ppo": "DeckLandingTiming-v0",
    "timing-dqn-realistic": "DeckLandingTiming-v0",
    "timing-dqn-randomised": "DeckLandingTiming-v0",
    "timing-dqn-timed": "DeckLandingTiming-v0",
    "timing-dqn-waveoff": "DeckLandingTiming-v0",
    "timing-dqn-waveoff30": "DeckLandingTiming-v0",
    "predictive": "DeckLandingTiming-v0",
    "timing-dqn-predictive": "DeckLandingTiming-v0",
    "timing-dqn-lookahead": "DeckLandingTiming-v0",
}
POLICY_NAMES: tuple[str, ...] = tuple(POLICY_ENVS)


def _tilt_model(model_path: str | Path | None, scenario_model: str) -> Any:
    """The deck-tilt predictor of the predictive policy: ``--model``, else the scenario's
    (``timing.tilt_model``), loaded; a missing or malformed one names the key."""
    from estimation.deck_prediction import LinearTiltPredictor
    from landing_env.resources import tilt_predictor_path

    if model_path is None and not scenario_model:
        raise ConfigError(
            "timing.tilt_model",
            "is empty: the predictive policy needs the scenario's deck-tilt predictor (set "
            "timing.tilt_model=NAME or pass --model FILE; fit one with "
            "`python -m agents.deck_predictor fit`)",
        )
    path = Path(model_path) if model_path is not None else tilt_predictor_path(scenario_model)
    try:
        return LinearTiltPredictor.load(path)
    except (OSError, ValueError) as error:
        raise ConfigError("timing.tilt_model", f"{path}: {error}") from None


def make_policy(
    name: str,
    env: Any,
    model_path: str | Path | None = None,
    allow_mismatch: tuple[str, ...] = (),
) -> Any:
    """Build the policy ``name`` for ``env`` (an environment of ``POLICY_ENVS[name]``).

    A trained model is checked against ``env`` (:meth:`TrainedTimingPolicy.check_env`);
    ``allow_mismatch`` names the card's fields that may differ on purpose."""
    if name not in POLICY_ENVS:
        raise ConfigError("policy", f"{name!r} is not allowed; choose one of {POLICY_NAMES}")
    base = env.unwrapped
    dt = base.env_dt
    if name == "align-descend":
        return AlignDescendPolicy(
            base.config.action, dt=dt, tof_mounts_c=base.config.tof.mount_offsets_c
        )
    if name == "land-now":
        return LandNowPolicy()
    if name in ("quiescent", "predictive") and base.layout.observed_rows != base.layout.n_history:
        raise ConfigError(
            "timing.observation",
            f"is {base.timing.observation!r}; {name} reads the deck-pose history: use 'history'",
        )
    if name == "quiescent":
        return QuiescentPolicy(base.layout, dt)
    if name == "predictive":
        return PredictivePolicy(
            base.layout,
            dt,
            _tilt_model(model_path, base.resolved_tilt_model()),
            base.config.touchdown.max_deck_tilt_deg,
            base.timing.wait_limit_s,
            base.timing.opportunity_s,
            base.timing.contact_times_s,
        )
    if name == "oracle":
        from agents.oracle import OracleTimingPolicy

        return OracleTimingPolicy(env)
    if name == "deck-oracle":
        from agents.oracle import DeckOracleTimingPolicy

        return DeckOracleTimingPolicy(env)
    if name == "deck-forecast":
        from agents.deck_forecast import DeckForecastTimingPolicy

        return DeckForecastTimingPolicy(env)
    if name == "deck-forecast-onboard":
        from agents.deck_forecast import DeckForecastTimingPolicy, OnboardModelConfig

        return DeckForecastTimingPolicy(env, onboard=OnboardModelConfig(), deadline_chance=0.5)
    default = shipped_timing_model(name.removeprefix("timing-"))
    if name == "timing-dqn-lookahead":
        from agents.lookahead import LookaheadTimingPolicy

        return LookaheadTimingPolicy(model_path or default, env, tuple(allow_mismatch))
    policy = TrainedTimingPolicy(model_path or default)
    policy.check_env(env, allow_mismatch)
    return policy
