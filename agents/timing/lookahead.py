"""The onboard look-ahead as an observation: a learned timing that weighs what it foresees.

``deck-forecast-onboard`` (:mod:`agents.timing.deck_forecast`) tries a commit now in a handful of
futures its onboard model draws (the ship's helideck forecast, its own deck-pose estimate
and wind estimate with their errors, its airframe's uncertain drag and thrust) and commits
by a fixed rule: all of them land with 15 % slack, the standard falling over the last 5 s.
Whether a look-ahead's verdict is worth acting on now or worth waiting for a better one
is what a learned policy can weigh instead, as ``timing-dqn-predictive`` weighs the
deck-tilt predictor's chances.

:class:`LookaheadTimingWrapper` turns the timing task into that decision.  Every
``check_every_s`` of the wait the agent sees :data:`LOOKAHEAD_FEATURES` of the look-ahead
(``draws`` tried commits, all of them run: no early stop) for this check and the one before,
and the wait used; between checks the drone holds (a wait of ``check_every_s`` is one step
of the wrapped task, its rewards summed).  The same features reach a trained model at
evaluation through :class:`LookaheadTimingPolicy`, which acts on the bare task and waits
between its checks: the features of a given episode and check are the same in both (the
look-ahead's draws are seeded by the episode and the decision).

The look-ahead is the onboard model's (:class:`~agents.timing.deck_forecast.OnboardModelConfig`):
what the drone knows of the present, the HMS forecast of the deck; the drone's own code
(guidance, controller, estimators) flies it.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.policy_registry import make_env_and_policy
from agents.timing.cards import check_compatible, env_signature, sensing_profile
from agents.timing.deck_forecast import (
    DeckForecastTimingPolicy,
    OnboardModelConfig,
    episode_monitor,
)
from agents.timing.oracle import TriedCommit
from agents.timing.policies import TrainedTimingPolicy
from agents.timing.sampler import SENSING_PROFILES
from landing_env.config_loading import build_dataclass
from landing_env.envs.actions import validate_action
from landing_env.envs.snapshot import restore_snapshot, save_snapshot
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.scenarios import SCENARIOS
from landing_env.sea.hms import REPORT_FIELDS
from landing_env.touchdown import Outcome

#: per check, in order: whether a look-ahead was made (a deck-pose estimate and a forecast
#: were there), the share of draws that land with the slack, the share that succeed at all,
#: and the mean and the least of each draw's score (its margin, clipped to [-1, 1]; -1 for a
#: draw that failed)
LOOKAHEAD_FEATURES: tuple[str, ...] = ("valid", "chance", "success", "mean_score", "min_score")

#: the score of a tried commit that did not succeed
FAILED_SCORE = -1.0

#: the ship's HMS report the observation may carry (``hms_report_s``), each field by the value
#: that reads 1 (the observation clips it there): the peak inclination of the deck over the
#: window by 20 deg, its total heave by 15 m (the 5 m sea of ship-ss6 reports 11-15 deg and
#: 7-9 m over ten minutes; :data:`landing_env.sea.hms.REPORT_FIELDS`)
HMS_REPORT_FEATURES: dict[str, float] = {
    "peak_inclination": math.radians(20.0),
    "total_heave": 15.0,
}


@dataclass(frozen=True)
class LookaheadSettings:
    """The look-ahead behind the observation (``deck_landing.lookahead`` of a training YAML).

    * ``draws``: futures tried per check (each is a full descent and touchdown: ~0.17 s of
      this machine's CPU at ``ship-ss5``);
    * ``check_every_s``: the wait between checks (a multiple of the task's decision);
    * ``min_margin``: the slack a draw needs to count in ``chance``
      (:func:`agents.timing.oracle.touchdown_margin`);
    * ``checks``: how many checks the observation holds (this one first);
    * ``seed``: the look-ahead's own streams (with the episode's seed and the decision);
    * ``hms_report_s``: with a window (CAP 437's is 600 s), the observation also carries the
      ship's HMS report over it (:data:`HMS_REPORT_FEATURES`, before the wait used): how
      hard the sea moves the deck, which the look-ahead's draws do not say; 0: no report.
    * ``airframe_in_trim``: the onboard model's drawn airframes start in their own trim
      (:attr:`~agents.timing.deck_forecast.OnboardModelConfig.airframe_in_trim`); False: the
      shipped look-ahead's draws.
    """

    draws: int = 4
    check_every_s: float = 0.5
    min_margin: float = 0.15
    checks: int = 2
    seed: int = 0
    hms_report_s: float = 0.0
    airframe_in_trim: bool = False

    def __post_init__(self) -> None:
        require_range("draws", self.draws, 1, 64)
        require_range("check_every_s", self.check_every_s, 0.0, 10.0, low_inclusive=False)
        require_range("min_margin", self.min_margin, 0.0, 1.0)
        require_range("checks", self.checks, 1, 16)
        require_range("hms_report_s", self.hms_report_s, 0.0, 3600.0)
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
        """The observation's length: the features of each check, the HMS report's (if any),
        then the wait fraction."""
        return self.checks * len(LOOKAHEAD_FEATURES) + self.report_size + 1

    @property
    def report_size(self) -> int:
        """How many of the observation's values are the HMS report's."""
        return len(HMS_REPORT_FEATURES) if self.hms_report_s > 0 else 0

    def signature(self) -> dict[str, Any]:
        """What the observation's values mean, for a model's card."""

        fields = asdict(self)
        if not self.hms_report_s:
            # a look-ahead without the report signs as before the report existed
            del fields["hms_report_s"]
        else:
            fields["hms_report"] = {k: round(v, 6) for k, v in HMS_REPORT_FEATURES.items()}
        if not self.airframe_in_trim:
            del fields["airframe_in_trim"]  # likewise
        return {
            **fields,
            "features": list(LOOKAHEAD_FEATURES),
            "failed_score": FAILED_SCORE,
            "onboard": self.onboard().signature(),
        }

    def onboard(self) -> Any:
        """The onboard model the look-ahead plays (:class:`OnboardModelConfig`)."""

        return OnboardModelConfig(airframe_in_trim=self.airframe_in_trim)


def hms_report_features(monitor: Any, t_s: float, window_s: float) -> np.ndarray:
    """:data:`HMS_REPORT_FEATURES` of ``monitor``'s standard report over ``window_s`` up to
    ``t_s``, each scaled to its reading of 1 and clipped to [0, 1]."""

    report = monitor.standard_report(t_s, window_s)
    values = [report[REPORT_FIELDS.index(k)] / scale for k, scale in HMS_REPORT_FEATURES.items()]
    return np.clip(np.nan_to_num(np.asarray(values, float), nan=1.0), 0.0, 1.0)


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
            raise ConfigError("env", "the look-ahead acts in DeckLandingTiming-v0")
        self.env = base
        s = self.settings
        self.planner = DeckForecastTimingPolicy(
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
        report = self.report(float(env.world.time))
        return np.concatenate([*checks, report, [wait]]).astype(np.float32)

    def report(self, t_s: float) -> np.ndarray:
        """The HMS report's features at ``t_s`` (none without ``hms_report_s``)."""
        if not self.settings.hms_report_s:
            return np.zeros(0)
        return hms_report_features(self.planner.monitor(), t_s, self.settings.hms_report_s)

    @property
    def observation_space(self) -> gym.spaces.Box:
        return gym.spaces.Box(-1.0, 1.0, (self.settings.size,), dtype=np.float32)


class LookaheadTimingWrapper(gym.Wrapper):
    """The timing task decided every ``check_every_s`` on the look-ahead's features.

    Action 0 holds for ``check_every_s`` (the task's waits, their rewards summed; it ends
    early if the episode does: the wait limit forces the commit); 1 commits.  The reward
    terms of the last step are in ``info`` as the task gives them.  ``settings`` are
    :class:`LookaheadSettings`' keys; ``forecast``: the helideck forecast to use (default: the
    scenario's, fitted once per process).
    """

    def __init__(self, env: gym.Env, forecast: Any = None, **settings: Any) -> None:
        super().__init__(env)

        self.settings = build_dataclass(LookaheadSettings, settings, "lookahead")
        #: what a model card records of this observation (:func:`agents.timing.cards.env_signature`)
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


class LookaheadTimingPolicy:
    """A model trained on :class:`LookaheadTimingWrapper`, acting in the bare timing task.

    Every ``check_every_s`` (its card's) it looks ahead and asks the model; between checks it
    waits.  The card is checked as :class:`~agents.timing.policies.TrainedTimingPolicy` checks
    one, the look-ahead's settings included.
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
        fields = {k: card[k] for k in LookaheadSettings.__dataclass_fields__ if k in card}
        self.settings = LookaheadSettings(**fields)
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

    def __call__(self, observation: np.ndarray) -> int:
        return self.act(observation)


def find_lookahead(env: Any) -> LookaheadTimingWrapper | None:
    """The look-ahead wrapper in ``env``'s wrapper chain, if any."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, LookaheadTimingWrapper):
            return env
        env = env.env
    return None


# ------------------------------------------------------------------------------ offline data
#: the arrays of a transitions file (:func:`collect_transitions`)
TRANSITION_KEYS = (
    "observation",
    "commit_reward",
    "commit_success",
    "commit_terminal",
    "wait_reward",
    "next_observation",
    "wait_terminal",
    "wait_success",
    "episode",
)
#: the check an observation was made at (:func:`collect_transitions`): whether commits were
#: tried (records,), and each draw's verdict (records, draws).  With them a file
#: recorded with many draws gives the observations of fewer (:func:`with_draws`): a draw's
#: future is seeded by the episode, the decision and its index, not by how many are drawn.
DRAW_KEYS = ("check_tried", "draw_lands", "draw_success", "draw_margin")


def collect_transitions(
    scenario: str,
    seeds: list[int],
    out: str | Path,
    settings: LookaheadSettings | None = None,
    estimator: str | None = None,
    progress: bool = True,
    forecast: Any = None,
    sensing: str | None = None,
) -> Path:
    """Both actions' outcomes at every check of whole episodes: the data of an offline DQN.

    Each episode holds to its wait limit; at every check the look-ahead's observation is
    recorded with the reward of a commit now, tried with the episode's own future in a saved
    copy (as :class:`agents.timing.oracle.OracleTimingPolicy` tries it), and with the wait's reward
    and the next check's observation.  The episode then goes on as if it waited, so any policy
    of the wrapper can be replayed exactly on the file (:func:`replay_success`): the states on
    its path and their observations are the ones recorded.  Each check's draws are kept
    (:data:`DRAW_KEYS`), so the file also serves a look-ahead of fewer draws.  The file is
    rewritten after every episode (an interrupted run keeps what it has).

    ``sensing`` names a profile of :data:`agents.timing.sampler.SENSING_PROFILES`
    (``realistic-2x``: twice the realistic noise); the file records that name (with the
    scenario's lens where it is not the standard one: ``realistic-2x,lens=wide``).  Without it
    the ``sensors`` default applies (``DECK_LANDING_SENSORS``); the file records
    :func:`agents.timing.cards.sensing_profile` either way.
    """
    from tqdm import tqdm

    settings = settings or LookaheadSettings()
    overrides: dict[str, Any] = {}
    if sensing is not None:
        require_choice("sensing", sensing, tuple(SENSING_PROFILES))
        # a profile without a ``sensors`` bundle is ideal sensing plus its overrides, whatever
        # DECK_LANDING_SENSORS says
        overrides = {"sensors": "ideal", **SENSING_PROFILES[sensing]}
    env, _ = make_env_and_policy(
        "land-now",
        scenario,
        estimator or SCENARIOS[scenario].estimator,
        extra_overrides=overrides,
    )
    wrapper = LookaheadTimingWrapper(env, forecast=forecast, **asdict(settings))
    base = wrapper.unwrapped
    rows: dict[str, list[Any]] = {key: [] for key in TRANSITION_KEYS + DRAW_KEYS}
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        for seed in tqdm(seeds, desc=f"look-ahead transitions @ {scenario}", disable=not progress):
            observation, _ = wrapper.reset(seed=seed)
            while True:
                for key, value in zip(
                    DRAW_KEYS,
                    _draw_arrays(wrapper.observer.last_tries, settings.draws),
                    strict=True,
                ):
                    rows[key].append(value)
                commit = (0.0, False, True)
                if in_flight(base):
                    here = save_snapshot(base)
                    try:
                        _, reward, terminated, _, info = base.step(1)
                    finally:
                        restore_snapshot(base, here, keep=False)
                    commit = (float(reward), info["outcome"] == "success", bool(terminated))
                next_observation, reward, terminated, truncated, info = wrapper.step(0)
                for key, value in zip(
                    TRANSITION_KEYS,
                    (
                        observation,
                        *commit,
                        float(reward),
                        next_observation,
                        bool(terminated or truncated),
                        info["outcome"] == "success",
                        seed,
                    ),
                    strict=True,
                ):
                    rows[key].append(value)
                observation = next_observation
                if terminated or truncated:
                    break
            np.savez_compressed(
                path,
                settings=json.dumps(settings.signature()),
                scenario=scenario,
                estimator=base.config.estimation.observed,
                sensing=sensing_profile(base.config, sensing),
                **{key: np.asarray(value) for key, value in rows.items()},
            )
    finally:
        wrapper.close()
    return path


def _draw_arrays(
    tries: list[TriedCommit] | None, draws: int
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray]:
    """One check's tried commits as :data:`DRAW_KEYS`' rows."""
    lands = np.zeros(draws, bool)
    success = np.zeros(draws, bool)
    margin = np.full(draws, np.nan)
    for k, tried in enumerate((tries or [])[:draws]):
        lands[k], success[k], margin[k] = tried.lands, tried.success, tried.margin
    return bool(tries), lands, success, margin


def recorded_tries(data: dict[str, np.ndarray], row: int, draws: int) -> list[TriedCommit] | None:
    """The first ``draws`` tried commits of record ``row``'s check (None: nothing tried)."""
    if not data["check_tried"][row]:
        return None
    lands, success, margin = (data[key][row][:draws] for key in DRAW_KEYS[1:])
    return [
        TriedCommit(bool(a), bool(b), float(m))
        for a, b, m in zip(lands, success, margin, strict=True)
    ]


def with_draws(data: dict[str, np.ndarray], settings: LookaheadSettings) -> dict[str, np.ndarray]:
    """The records as a look-ahead of ``settings`` (the file's, with fewer draws) sees them:
    every observation rebuilt from the first ``settings.draws`` draws of its checks."""
    if any(key not in data for key in DRAW_KEYS):
        raise ConfigError("data", "the transitions hold no draws of their own: record them anew")
    if settings.draws > data["draw_lands"].shape[1]:
        raise ConfigError(
            "lookahead.draws",
            f"{settings.draws} draws asked; the transitions hold {data['draw_lands'].shape[1]}",
        )
    checks = settings.checks
    features = np.array(
        [
            check_features(recorded_tries(data, i, settings.draws))
            for i in range(len(data["episode"]))
        ]
    )
    invalid = check_features(None)
    episodes = data["episode"]
    # what follows the checks (the HMS report, if recorded, and the wait used) is kept
    tail_from = checks * len(LOOKAHEAD_FEATURES)

    def stack(row: int, newest: np.ndarray | None, tail: np.ndarray) -> np.ndarray:
        """The observation whose newest check is ``newest`` (or row's), the earlier ones the
        rows before it in its episode."""
        parts = [] if newest is None else [newest]
        k = row
        while len(parts) < checks and k >= 0 and episodes[k] == episodes[row]:
            parts.append(features[k])
            k -= 1
        parts += [invalid] * (checks - len(parts))
        return np.concatenate([*parts, tail]).astype(np.float32)

    out = dict(data)
    n = len(episodes)
    out["observation"] = np.array(
        [stack(i, None, data["observation"][i][tail_from:]) for i in range(n)], np.float32
    )
    out["next_observation"] = np.array(
        [
            stack(i + 1, None, data["next_observation"][i][tail_from:])
            if i + 1 < n and episodes[i + 1] == episodes[i] and not data["wait_terminal"][i]
            else stack(i, invalid, data["next_observation"][i][tail_from:])
            for i in range(n)
        ],
        np.float32,
    )
    return out


def with_hms_report(
    data: dict[str, np.ndarray], settings: LookaheadSettings, progress: bool = False
) -> dict[str, np.ndarray]:
    """The records as a look-ahead of ``settings`` (with ``hms_report_s``) sees them when they
    were recorded without the HMS report: each observation gets the report its check would
    have read, before its wait used.  The report is the ship's record, a fixed function of the
    episode's seed and the time, whatever the drone does: each episode of each ``scenario`` is
    reset again and its k-th check read at the reset's time plus k checks (a warm-up that ended
    the episode gives its one check the report at the time the warm-up ended)."""
    from tqdm import tqdm

    if not settings.hms_report_s:
        raise ConfigError("lookahead.hms_report_s", "no report asked: 0 s")
    tail_from = settings.checks * len(LOOKAHEAD_FEATURES)
    if data["observation"].shape[1] != tail_from + 1:
        raise ConfigError("data", "the transitions hold an HMS report already or another layout")
    episodes, scenarios = data["episode"], data["scenario"]
    reports = np.zeros((len(episodes), settings.report_size))
    next_reports = np.zeros_like(reports)
    for scenario in np.unique(scenarios).tolist():
        if scenario not in SCENARIOS:
            raise ConfigError(
                "data", f"records of scenario {scenario!r}: the report needs a known scenario"
            )
        env, _ = make_env_and_policy("land-now", scenario, SCENARIOS[scenario].estimator)
        base = env.unwrapped
        try:
            seeds = np.unique(episodes[scenarios == scenario]).tolist()
            for seed in tqdm(seeds, desc=f"HMS reports @ {scenario}", disable=not progress):
                base.reset(seed=int(seed))
                monitor = episode_monitor(base, settings.seed)
                t0 = float(base.world.time)
                rows = np.flatnonzero((episodes == seed) & (scenarios == scenario))
                for k, row in enumerate(rows):
                    t = t0 + k * settings.check_every_s
                    reports[row] = hms_report_features(monitor, t, settings.hms_report_s)
                    next_reports[row] = hms_report_features(
                        monitor, t + settings.check_every_s, settings.hms_report_s
                    )
        finally:
            env.close()
    out = dict(data)
    for key, values in (("observation", reports), ("next_observation", next_reports)):
        observed = data[key]
        out[key] = np.concatenate(
            [observed[:, :tail_from], values, observed[:, tail_from:]], axis=1
        ).astype(np.float32)
    return out


def load_transitions(
    paths: list[str | Path], settings: LookaheadSettings | None = None, progress: bool = False
) -> dict[str, np.ndarray]:
    """The transitions of several files, concatenated; they must share their look-ahead, and
    an episode (its seed) may be in one file only, whatever its scenario.  Each record also
    gets its file's ``scenario``, the ``estimator`` observed (a file without one: the
    scenario's own) and the ``sensing`` profile (:func:`agents.timing.cards.sensing_profile`;
    a file without one: ``unknown``).  ``settings``: the look-ahead to see them with, the
    files' or the same with fewer draws (:func:`with_draws`), or with the HMS report where
    the files have none (:func:`with_hms_report`)."""

    parts: list[dict[str, np.ndarray]] = []
    signature = None
    seen: dict[int, str] = {}
    for path in paths:
        with np.load(path) as data:
            if signature is None:
                signature = str(data["settings"])
            elif str(data["settings"]) != signature:
                raise ConfigError("data", f"{path} was collected with another look-ahead")
            keys = TRANSITION_KEYS + tuple(k for k in DRAW_KEYS if k in data)
            part = {key: data[key] for key in keys}
            scenario = str(data["scenario"]) if "scenario" in data else "unknown"
            estimator = (
                str(data["estimator"])
                if "estimator" in data
                else SCENARIOS[scenario].estimator
                if scenario in SCENARIOS
                else "unknown"
            )
            sensing = str(data["sensing"]) if "sensing" in data else "unknown"
        for seed in np.unique(part["episode"]).tolist():
            if seed in seen:
                raise ConfigError(
                    "data",
                    f"episode seed {seed} is in both {seen[seed]} and {path}: an episode "
                    "is one file's (record another scenario with other seeds)",
                )
            seen[seed] = str(path)
        part["scenario"] = np.full(len(part["episode"]), scenario)
        part["estimator"] = np.full(len(part["episode"]), estimator)
        part["sensing"] = np.full(len(part["episode"]), sensing)
        parts.append(part)
    if not parts or signature is None:
        raise ConfigError("data", "no transitions files given")
    keys = tuple(k for k in parts[0] if all(k in p for p in parts))
    merged = {key: np.concatenate([p[key] for p in parts]) for key in keys}
    if settings is None:
        return merged
    recorded = json.loads(signature)
    wanted = json.loads(json.dumps(settings.signature()))
    if recorded == wanted:
        return merged
    report_keys = ("hms_report_s", "hms_report")
    recorded_report = {k: recorded.pop(k) for k in report_keys if k in recorded}
    wanted_report = {k: wanted.pop(k) for k in report_keys if k in wanted}
    if (
        {**recorded, "draws": settings.draws} != wanted
        or settings.draws > recorded["draws"]
        or (recorded_report and recorded_report != wanted_report)
    ):
        raise ConfigError(
            "data",
            "the transitions were collected with another look-ahead than the one asked "
            f"(recorded {recorded['draws']} draws; only fewer draws can be taken from them, "
            "and an HMS report added to records without one)",
        )
    if settings.draws != recorded["draws"]:
        merged = with_draws(merged, settings)
    if wanted_report and not recorded_report:
        merged = with_hms_report(merged, settings, progress=progress)
    return merged


def replay_success(data: dict[str, np.ndarray], decide: Any) -> tuple[float, np.ndarray]:
    """The success of a policy replayed on recorded episodes, exactly: ``decide(observations)``
    gives 1 (commit) or 0 for each check; an episode ends at its first commit (its recorded
    outcome) or, waiting throughout, as the wait limit ended it.  Returns the success rate
    and each episode's check of commit (-1: never)."""
    actions = np.asarray(decide(data["observation"])).reshape(-1)
    episodes = data["episode"]
    successes, chosen = [], []
    for seed in np.unique(episodes):
        index = np.flatnonzero(episodes == seed)
        commits = index[(actions[index] == 1) & data["commit_terminal"][index]]
        if len(commits):
            successes.append(bool(data["commit_success"][commits[0]]))
            chosen.append(int(np.searchsorted(index, commits[0])))
        else:
            successes.append(bool(data["wait_success"][index[-1]]))
            chosen.append(-1)
    return float(np.mean(successes)), np.asarray(chosen)


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.timing.lookahead collect``: record transitions
    (:func:`collect_transitions`); ``train``: fit a DQN on them offline
    (:func:`agents.timing.lookahead_training.train_offline`)."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m agents.timing.lookahead", description=main.__doc__
    )
    sub = parser.add_subparsers(dest="command", required=True)
    collect = sub.add_parser("collect", help="both actions' outcomes at every check")
    collect.add_argument("--scenario", default="ship-ss5")
    collect.add_argument("--seed", type=int, default=10_000, help="first episode seed")
    collect.add_argument("--episodes", type=int, default=60)
    collect.add_argument("--draws", type=int, default=LookaheadSettings.draws)
    collect.add_argument("--check-every-s", type=float, default=LookaheadSettings.check_every_s)
    collect.add_argument(
        "--airframe-in-trim",
        action="store_true",
        help="the onboard model's drawn airframes start in their own trim",
    )
    collect.add_argument(
        "--estimator",
        default=None,
        help="the estimate observed (default: the scenario's; the bench's policies observe tight)",
    )
    collect.add_argument(
        "--sensors",
        default=None,
        help="a sensing profile by name (ideal, realistic, realistic-2x, ...; default: the "
        "sensors default, DECK_LANDING_SENSORS)",
    )
    collect.add_argument("--out", required=True, help="the .npz to write")
    args = parser.parse_args(argv)
    if args.command == "collect":
        require_range("episodes", args.episodes, 1)
        settings = LookaheadSettings(
            draws=args.draws,
            check_every_s=args.check_every_s,
            airframe_in_trim=args.airframe_in_trim,
        )
        seeds = list(range(args.seed, args.seed + args.episodes))
        path = collect_transitions(
            args.scenario, seeds, args.out, settings, args.estimator, sensing=args.sensors
        )
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def build_lookahead_policy(
    env: Any, model_path: str | None, allow: tuple[str, ...]
) -> LookaheadTimingPolicy:
    """``timing-dqn-lookahead`` for ``env`` (:mod:`agents.policy_registry`'s builder)."""
    if model_path is None:
        raise ConfigError(
            "model", "timing-dqn-lookahead needs a model (the shipped one by default)"
        )
    return LookaheadTimingPolicy(model_path, env, tuple(allow))
