"""The onboard look-ahead as an observation: a learned timing that weighs what it foresees.

The onboard look-ahead (:mod:`agents.policies.deck_forecast`) tries a commit now in a handful
of futures its onboard model draws (the ship's helideck forecast, its own deck-pose estimate
and wind estimate with their errors, its airframe's uncertain drag and thrust).  Whether a
look-ahead's verdict is worth acting on now or worth waiting for a better one is what a
learned policy weighs here, as ``timing-dqn-predictive`` weighs the
deck-tilt predictor's chances.

:class:`LookaheadTimingWrapper` turns the timing task into that decision.  Every
``check_every_s`` of the wait the agent sees :data:`LOOKAHEAD_FEATURES` of the look-ahead
(``draws`` tried commits, all of them run: no early stop) for this check and the one before,
and the wait used; between checks the drone holds (a wait of ``check_every_s`` is one step
of the wrapped task, its rewards summed).  The same features reach a trained model at
evaluation through :class:`LookaheadTimingPolicy`, which acts on the bare task and waits
between its checks: the features of a given episode and check are the same in both (the
look-ahead's draws are seeded by the episode and the decision).

The look-ahead is the onboard model's (:class:`~agents.policies.deck_forecast.OnboardModelConfig`):
what the drone knows of the present, the HMS forecast of the deck; the drone's own code
(guidance, controller, estimators) flies it.  Both actions' outcomes at every check, recorded
for an offline DQN, are :mod:`agents.training.lookahead_data`'s.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.common.cards import check_compatible, env_signature
from agents.policies.base import Policy
from agents.policies.deck_forecast import DeckForecastTimingPolicy, OnboardModelConfig
from agents.policies.oracle import TriedCommit
from agents.policies.reduced_descent import ReducedLookahead
from agents.policies.timing import TrainedTimingPolicy
from estimation.limits import Limit, limited, require_limits
from landing_env.config_loading import build_dataclass
from landing_env.envs.actions import validate_action
from landing_env.errors import ConfigError, require_choice
from landing_env.scenarios import TIMING_TASK
from landing_env.touchdown import Outcome

#: per check, in order: whether a look-ahead was made (a deck-pose estimate and a forecast
#: were there), the share of draws that land with the slack, the share that succeed at all,
#: and the mean and the least of each draw's score (its margin, clipped to [-1, 1]; -1 for a
#: draw that failed)
LOOKAHEAD_FEATURES: tuple[str, ...] = ("valid", "chance", "success", "mean_score", "min_score")

#: the score of a tried commit that did not succeed
FAILED_SCORE = -1.0

#: the onboard models that fly the look-ahead's futures (``LookaheadSettings.model``):
#: ``replay`` restores a copy of the whole simulation for each draw
#: (:class:`~agents.policies.deck_forecast.DeckForecastTimingPolicy`), ``reduced`` flies all of
#: a check's draws at once through a point-mass model of the drone's own closed loop
#: (:class:`~agents.policies.reduced_descent.ReducedLookahead`)
ONBOARD_MODELS: tuple[str, ...] = ("replay", "reduced")


@dataclass(frozen=True)
class LookaheadSettings:
    """The look-ahead behind the observation (``deck_landing.lookahead`` of a training YAML).

    * ``draws``: futures tried per check (each is a full descent and touchdown: ~0.17 s of
      this machine's CPU at ``ship-ss5``);
    * ``check_every_s``: the wait between checks (a multiple of the task's decision);
    * ``min_margin``: the slack a draw needs to count in ``chance``
      (:func:`agents.policies.oracle.touchdown_margin`);
    * ``checks``: how many checks the observation holds (this one first);
    * ``seed``: the look-ahead's own streams (with the episode's seed and the decision);
    * ``airframe_in_trim``: the onboard model's drawn airframes start in their own trim
      (:attr:`~agents.policies.deck_forecast.OnboardModelConfig.airframe_in_trim`); False: the
      shipped look-ahead's draws.
    * ``model``: what flies the futures (:data:`ONBOARD_MODELS`): ``replay`` (~0.17 s a draw)
      or ``reduced`` (a check's draws in one vectorised flight of a few tens of ms).
    """

    draws: int = limited(4, Limit(1, 64))
    check_every_s: float = limited(0.5, Limit(0.0, 10.0, low_inclusive=False))
    min_margin: float = limited(0.15, Limit(0.0, 1.0))
    checks: int = limited(2, Limit(1, 16))
    seed: int = 0
    airframe_in_trim: bool = False
    model: str = "replay"

    def __post_init__(self) -> None:
        require_limits(self)
        require_choice("lookahead.model", self.model, ONBOARD_MODELS)
        if not isinstance(self.airframe_in_trim, bool):
            raise ConfigError(
                "airframe_in_trim", f"must be true or false, got {self.airframe_in_trim!r}"
            )
        for key in ("draws", "checks", "seed"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ConfigError(key, f"must be an integer, got {value!r}")

    @property
    def size(self) -> int:
        """The observation's length: the features of each check, then the wait fraction."""
        return self.checks * len(LOOKAHEAD_FEATURES) + 1

    def signature(self) -> dict[str, Any]:
        """What the observation's values mean, for a model's card."""

        fields = asdict(self)
        if not self.airframe_in_trim:
            # a look-ahead without it signs as before it existed
            del fields["airframe_in_trim"]
        if self.model == "replay":
            # the replay signs as before the reduced model existed
            del fields["model"]
        return {
            **fields,
            "features": list(LOOKAHEAD_FEATURES),
            "failed_score": FAILED_SCORE,
            "onboard": self.onboard().signature(),
        }

    @classmethod
    def from_signature(cls, signed: dict[str, Any]) -> LookaheadSettings:
        """The settings a card's ``observation.lookahead`` (:meth:`signature`) was made by."""

        return cls(**{k: signed[k] for k in cls.__dataclass_fields__ if k in signed})

    def onboard(self) -> Any:
        """The onboard model the look-ahead plays (:class:`OnboardModelConfig`)."""

        return OnboardModelConfig(airframe_in_trim=self.airframe_in_trim)


def in_flight(env: Any) -> bool:
    """Whether a commit can be tried now: the episode goes on and its warm-up hold did not
    end it (``env``: the unwrapped timing task)."""

    return not getattr(env, "_hold_failed", False) and env._outcome is Outcome.IN_FLIGHT


def check_features(tries: list[TriedCommit] | None) -> np.ndarray:
    """:data:`LOOKAHEAD_FEATURES` of one check's tried commits (None: no look-ahead made)."""
    if not tries:
        return np.array([0.0, 0.0, 0.0, FAILED_SCORE, FAILED_SCORE])
    scores = np.array(
        [
            float(np.clip(t.margin, -1.0, 1.0))
            if t.success and math.isfinite(t.margin)
            else FAILED_SCORE
            for t in tries
        ]
    )
    return np.array(
        [
            1.0,
            float(np.mean([t.lands for t in tries])),
            float(np.mean([t.success for t in tries])),
            float(np.mean(scores)),
            float(np.min(scores)),
        ]
    )


class LookaheadObserver:
    """The look-ahead of one ``DeckLandingTiming`` environment, as features.

    ``observe(decision)`` tries the commits (the environment is left as found) and returns
    the observation: this check's features, the earlier checks', the wait used.
    """

    def __init__(
        self, env: Any, settings: LookaheadSettings | None = None, forecast: Any = None
    ) -> None:

        self.settings = settings or LookaheadSettings()
        base = env.unwrapped
        if not hasattr(base, "layout") or not hasattr(base, "timing"):
            raise ConfigError("env", f"the look-ahead acts in {TIMING_TASK}")
        self.env = base
        s = self.settings
        planner = ReducedLookahead if s.model == "reduced" else DeckForecastTimingPolicy
        self.planner = planner(
            base,
            draws=s.draws,
            min_chance=1.0,
            check_every_s=s.check_every_s,
            seed=s.seed,
            min_margin=s.min_margin,
            onboard=s.onboard(),
            forecast=forecast,
        )
        decision_s = base.env_dt * base.timing.steps_per_decision
        stride = s.check_every_s / decision_s
        if abs(stride - round(stride)) > 1e-6:
            raise ConfigError(
                "lookahead.check_every_s",
                f"{s.check_every_s:g} s is not a multiple of the task's decision, {decision_s:g} s",
            )
        #: the task's decisions between two checks
        self.stride = round(stride)
        self._history: list[np.ndarray] = []
        #: the tried commits of the latest check (None: none were tried)
        self.last_tries: list[TriedCommit] | None = None

    def reset(self) -> None:
        self.planner.reset()
        self._history = []
        self.last_tries = None

    def observe(self, decision: int) -> np.ndarray:
        """Look ahead at ``decision`` (the task's steps since the reset) and build the
        observation; an ended episode or a warm-up that failed gives an invalid check."""
        env = self.env
        tries: list[TriedCommit] | None = None
        if in_flight(env):
            tries = self.planner.try_commits(decision, needed=0.0)
        self.last_tries = tries
        self._history.insert(0, check_features(tries))
        del self._history[self.settings.checks :]
        invalid = check_features(None)
        checks = self._history + [invalid] * (self.settings.checks - len(self._history))
        wait = min(max(float(env._wait_s) / float(env.timing.wait_limit_s), 0.0), 1.0)
        return np.concatenate([*checks, [wait]]).astype(np.float32)

    @property
    def observation_space(self) -> gym.spaces.Box:
        return gym.spaces.Box(-1.0, 1.0, (self.settings.size,), dtype=np.float32)


class LookaheadTimingWrapper(gym.Wrapper):
    """The timing task decided every ``check_every_s`` on the look-ahead's features.

    Action 0 holds for ``check_every_s`` (the task's waits, their rewards summed; it ends
    early if the episode does: the wait limit forces the commit); 1 commits.  The reward
    terms of the last step are in ``info`` as the task gives them.  ``settings`` are
    :class:`LookaheadSettings`' keys; ``forecast``: the helideck forecast to use (default: the
    scenario's, fitted once per machine).
    """

    def __init__(self, env: gym.Env, forecast: Any = None, **settings: Any) -> None:
        super().__init__(env)

        self.settings = build_dataclass(LookaheadSettings, settings, "lookahead")
        #: what a model card records of this observation (:func:`agents.common.cards.env_signature`)
        self.lookahead_settings = self.settings
        self.observer = LookaheadObserver(env, self.settings, forecast)
        self.observation_space = self.observer.observation_space
        self.action_space = gym.spaces.Discrete(2)
        self._decisions = 0

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        _, info = self.env.reset(**kwargs)
        self.observer.reset()
        self._decisions = 0
        return self.observer.observe(0), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:

        choice = validate_action(action, self.action_space, "0 = wait, 1 = commit")
        total = 0.0
        repeats = 1 if choice == 1 else self.observer.stride
        terminated = truncated = False
        info: dict[str, Any] = {}
        for _ in range(repeats):
            _, reward, terminated, truncated, info = self.env.step(choice)
            self._decisions += 1
            total += float(reward)
            if terminated or truncated:
                break
        # an ended episode gives an invalid check (nothing is tried)
        return self.observer.observe(self._decisions), total, terminated, truncated, info


class LookaheadTimingPolicy(Policy):
    """A model trained on :class:`LookaheadTimingWrapper`, acting in the bare timing task.

    Every ``check_every_s`` (its card's) it looks ahead and asks the model; between checks it
    waits.  The card is checked as :class:`~agents.policies.timing.TrainedTimingPolicy` checks
    one, the look-ahead's settings included (its onboard model among them).
    """

    def __init__(
        self,
        path: str | Path,
        env: Any,
        allow_mismatch: tuple[str, ...] = (),
        forecast: Any = None,
    ) -> None:

        self.trained = TrainedTimingPolicy(path)
        card = self.trained.metadata.observation.get("lookahead")
        if not isinstance(card, dict):
            raise ConfigError(
                "model",
                f"{Path(path).name} was not trained on the look-ahead's features "
                "(its card has no observation.lookahead): use timing-dqn with it",
            )
        self.settings = LookaheadSettings.from_signature(card)
        self.observer = LookaheadObserver(env, self.settings, forecast)
        self.trained.check_layout(self.settings.size)

        check_compatible(
            self.trained.metadata,
            env_signature(env, self.settings),
            self.trained.path.name,
            allow_mismatch,
        )
        self.name = "timing-dqn-lookahead"
        self._decisions = 0
        #: (decision, observation, action) of each check of the episode
        self.checks: list[tuple[int, np.ndarray, int]] = []

    def reset(self) -> None:
        self.observer.reset()
        self.trained.reset()
        self._decisions = 0
        self.checks = []

    def act(self, observation: np.ndarray) -> int:
        del observation  # the task's own observation: the look-ahead reads the environment
        decision = self._decisions
        self._decisions += 1
        if decision % self.observer.stride:
            return 0
        features = self.observer.observe(decision)
        action = self.trained.act(features)
        self.checks.append((decision, features, action))
        return action


def find_lookahead(env: Any) -> LookaheadTimingWrapper | None:
    """The look-ahead wrapper in ``env``'s wrapper chain, if any."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, LookaheadTimingWrapper):
            return env
        env = env.env
    return None


def build_lookahead_policy(
    env: Any, model_path: str | None, allow: tuple[str, ...]
) -> LookaheadTimingPolicy:
    """``timing-dqn-lookahead`` for ``env`` (:mod:`agents.policies.registry`'s builder)."""
    if model_path is None:
        raise ConfigError(
            "model", "timing-dqn-lookahead needs a model (the shipped one by default)"
        )
    return LookaheadTimingPolicy(model_path, env, tuple(allow))
