"""THE policy registry: every landing policy by name, what it is, where it runs, what to use.

Each :class:`PolicySpec` names the policy's kind (``baseline``, ``heuristic``, ``trained`` or
``bound``: privileged, it knows the future), its status (``recommended``, ``supported``,
``legacy`` or ``research``), the task it acts in, the estimator and the sensing it runs with
unless told otherwise, the settings it lays over the scenario's (``overrides``: dotted keys of
the config, e.g. the timing task's wave-off), its shipped model, and its builder as a
``module:function`` entry point, loaded only when the policy is built (as Gymnasium's
registry loads environments), so that this registry imports no policy module.

:data:`RECOMMENDED` says which policy to use in each setting and names the committed result
summary that measures it (``configs/results/<name>.json``, read by
:mod:`agents.evaluation.results`: the registry holds no figure); :func:`default_policy` is
what ``deck-landing evaluate landing --scenario S`` runs without ``--policy``.
:func:`make_env_and_policy` builds a scenario's registered id (:mod:`landing_env.scenarios`)
with the policy's settings, and the policy in it.
"""

from __future__ import annotations

import importlib
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

import landing_env  # noqa: F401  (registers the environments)
from landing_env.config import SENSORS_ENV
from landing_env.config_loading import nested_to_dotted
from landing_env.errors import ConfigError, require_choice
from landing_env.scenarios import (
    APPROACH_SCENARIOS,
    LANDING_TASK,
    PREDICTIVE_TIMING,
    SCENARIOS,
    TIMING_TASK,
    scenario_id,
    step_limit_on,
)

#: where the shipped models are installed (package data of ``agents``)
MODEL_DIR = Path(__file__).resolve().parents[1] / "models"


def find_model(text: str | Path) -> Path:
    """A trained model by path, or by the name ``deck-landing list models`` prints (a shipped
    model in :data:`MODEL_DIR`, ``.zip`` optional).  A missing file is returned as given (its
    reader names it); a file that is not a model zip is refused naming it."""
    path = Path(text)
    if not path.exists() and path.name == str(text):
        for candidate in (MODEL_DIR / path.name, MODEL_DIR / f"{path.name}.zip"):
            if candidate.is_file():
                return candidate
    if path.is_file() and not zipfile.is_zipfile(path):
        raise ConfigError(
            "model",
            f"{text} is not a model (an SB3 .zip; `deck-landing list models` names the "
            "shipped ones)",
        )
    return path


def require_model(name: str, model_path: str | None) -> str | None:
    """The model the policy ``name`` flies: ``model_path`` (a path or a shipped model's
    name), else its shipped one; a trained policy without either is refused naming
    ``--model``.  Checked before any episode runs, in this process."""
    spec = policy_spec(name)
    if model_path is None and spec.model is not None:
        return str(MODEL_DIR / spec.model)
    if spec.kind != "trained":
        return model_path  # a heuristic's own file (predictive: a deck-tilt predictor)
    if model_path is None:
        raise ConfigError(
            "--model",
            f"{name} runs a trained model: give --model PATH, or a name `deck-landing list "
            "models` prints",
        )
    path = find_model(model_path)
    if not path.is_file():
        raise ConfigError("--model", f"{model_path}: no such file, nor a shipped model's name")
    return str(path)


KINDS = ("baseline", "heuristic", "trained", "bound")

#: ``predictive`` over a ship's helideck: the helideck forecast identified online from the
#: ship's own HMS record of the last 20 min (nothing fitted beforehand; ``--set
#: deck_forecast=ship-broad`` flies the forecast fitted offline on the training family of
#: seas), and one independent opportunity every 2 s of the wait (the ship's deck decorrelates
#: more slowly than the bench's: at ``ship-ss6`` 91.0 % of the 200 selection seeds from
#: 1 000 000 against 89.0 % with the bench's 1 s, docs/experiments/ship-timing.md)
SHIP_PREDICTIVE_OVERRIDES: dict[str, dict[str, Any]] = {
    name: {"deck_forecast": "online", "timing.opportunity_s": 2.0}
    for name in ("ship-ss3", "ship-ss4", "ship-ss5", "ship-ss6", "ship-unseen-4", "ship-unseen-5")
}
STATUSES = ("recommended", "supported", "legacy", "research")


@dataclass(frozen=True)
class PolicySpec:
    """One registered policy (see the module docstring)."""

    name: str
    kind: str
    status: str
    task: str
    #: ``module:function`` building it: ``function(env, model_path, allow_mismatch)``
    builder: str
    summary: str
    #: the estimate it observes unless ``--estimator`` says otherwise (None: the scenario's)
    estimator: str | None = None
    #: the sensing it runs under unless ``--sensors`` says otherwise (None: the scenario's)
    sensing: str | None = None
    #: dotted config overrides it flies with, laid over the scenario's
    overrides: dict[str, Any] = field(default_factory=dict)
    #: its shipped model (``agents/models/<model>``), if any
    model: str | None = None
    #: the scenarios it is made for (empty: every scenario of its task)
    scenarios: tuple[str, ...] = ()
    #: scenario -> the superseded id it flies there instead of the scenario's current one:
    #: the version its shipped model was trained on, kept registered for it
    env_ids: dict[str, str] = field(default_factory=dict)
    #: scenario -> the dotted overrides it flies there instead of ``overrides``
    scenario_overrides: dict[str, dict[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        require_choice(f"{self.name}.kind", self.kind, KINDS)
        require_choice(f"{self.name}.status", self.status, STATUSES)
        require_choice(f"{self.name}.task", self.task, (LANDING_TASK, TIMING_TASK))

    @property
    def tasks(self) -> tuple[str, ...]:
        return (self.task,)


def _timing(name: str, **kwargs: Any) -> PolicySpec:
    return PolicySpec(name=name, task=TIMING_TASK, **kwargs)


#: THE registry: name -> policy
POLICIES: dict[str, PolicySpec] = {
    spec.name: spec
    for spec in (
        PolicySpec(
            "align-descend",
            "heuristic",
            "supported",
            LANDING_TASK,
            "agents.policies.align_descend:build_align_descend",
            "visual servoing on the estimated deck pose: centre, descend, flare for a calm "
            "window, land",
        ),
        PolicySpec(
            "align-predictive",
            "heuristic",
            "supported",
            LANDING_TASK,
            "agents.policies.align_descend:build_align_predictive",
            "align-descend's approach to the hold band, then `land` when predictive's "
            "stopping rule holds on the observed chances: the lander's imitation teacher",
            estimator="tight",
            scenarios=("bench-ss3", "bench-ss4", "bench-ss5"),
        ),
        PolicySpec(
            "svgs-routine",
            "heuristic",
            "supported",
            LANDING_TASK,
            "agents.policies.svgs_routine:build_svgs_routine",
            "the SVGS paper's landing routine from altitude (search, align, descend, relocate, "
            "land) on the fused estimate, committing through the timing model",
            estimator="fused",
            scenarios=("high-approach", "svgs-100m"),
        ),
        PolicySpec(
            "beacon-range",
            "baseline",
            "supported",
            LANDING_TASK,
            "agents.policies.beacon_range:build_beacon_range",
            "the IR-LOCK-style baseline: a beacon's bearing and the rangefinder through a "
            "landing-target filter, PX4's precision-landing search",
            estimator="beacon",
            scenarios=("high-approach", "svgs-100m-irlock"),
        ),
        _timing(
            "land-now",
            kind="baseline",
            status="supported",
            builder="agents.policies.timing:build_land_now",
            summary="commit at once: the lower bar of the timing task",
        ),
        _timing(
            "quiescent",
            kind="heuristic",
            status="recommended",
            builder="agents.policies.timing:build_quiescent",
            summary="commit when a calm window as long as the descent is predicted from the "
            "recent deck motion (the landing-period heuristic)",
        ),
        _timing(
            "predictive",
            kind="heuristic",
            status="recommended",
            builder="agents.policies.timing:build_predictive",
            summary="commit when the scenario's deck-tilt predictor gives a chance of a level "
            "deck at the contact worth more than waiting on (optimal stopping); chooses the "
            "contact time and waves off by the same predictor; over a ship's helideck the "
            "predictor is the helideck forecast identified online from the ship's HMS record",
            estimator="tight",
            overrides=nested_to_dotted(PREDICTIVE_TIMING, "timing"),
            scenarios=(
                "bench-ss3",
                "bench-ss4",
                "bench-ss5",
                "bench-unseen",
                *SHIP_PREDICTIVE_OVERRIDES,
            ),
            scenario_overrides=SHIP_PREDICTIVE_OVERRIDES,
        ),
        _timing(
            "timing-dqn-predictive",
            kind="trained",
            status="recommended",
            builder="agents.policies.timing:build_trained",
            summary="a DQN observing what `predictive` weighs (the predictor's chances and "
            "the value of waiting on)",
            estimator="tight",
            overrides=nested_to_dotted(
                {**PREDICTIVE_TIMING, "observation": "prediction"}, "timing"
            ),
            model="timing_dqn_predictive.zip",
            scenarios=("bench-ss3", "bench-ss4", "bench-ss5"),
        ),
        _timing(
            "timing-dqn-lookahead",
            kind="trained",
            status="supported",
            builder="agents.policies.lookahead:build_lookahead_policy",
            summary="a DQN deciding every 0.5 s on 16 commits tried in an onboard model's "
            "futures of the ship deck",
            estimator="tight",
            sensing="realistic",
            model="timing_dqn_lookahead.zip",
            scenarios=("ship-ss3", "ship-ss4", "ship-ss5", "ship-ss6"),
            env_ids={
                **{f"ship-ss{n}": f"DeckLandingTiming-ShipSS{n}-v7" for n in (3, 4, 5, 6)},
                **{f"ship-unseen-{n}": f"DeckLandingTiming-ShipSS{n}-v7" for n in (4, 5)},
            },
        ),
        PolicySpec(
            "lander",
            "trained",
            "supported",
            LANDING_TASK,
            "agents.policies.lander:build_lander",
            "the shipped SB3 lander of DeckLanding-v2: the PPO recipe's policy taught by "
            "DAgger from align-predictive; flies the approach, the hold and the land trigger",
            estimator="tight",
            sensing="realistic",
            model="lander_ppo.zip",
            scenarios=("bench-ss4",),
        ),
        PolicySpec(
            "lander-model",
            "trained",
            "research",
            LANDING_TASK,
            "agents.policies.lander:build_lander",
            "your own SB3 lander of DeckLanding-v2 (--model PATH; deck-landing train "
            "landing), checked against its card",
        ),
        _timing(
            "timing-model",
            kind="trained",
            status="supported",
            builder="agents.policies.timing:build_trained",
            summary="your own SB3 timing model (--model PATH), checked against its card",
        ),
        _timing(
            "oracle",
            kind="bound",
            status="supported",
            builder="agents.policies.oracle:build_oracle",
            summary="the best timing of all, found by trying every commit in saved copies of "
            "the episode: the upper bar",
        ),
        _timing(
            "deck-oracle",
            kind="bound",
            status="supported",
            builder="agents.policies.oracle:build_deck_oracle",
            summary="the timing that knows the deck's future and nothing else (gusts and noise "
            "drawn anew): the bar for timing by deck prediction",
        ),
    )
}
POLICY_NAMES: tuple[str, ...] = tuple(POLICIES)


@dataclass(frozen=True)
class Recommendation:
    """The policy to use in one setting, and the committed summary that measures it
    (``configs/results/<summary>.json``: the figure on seeds held out from the choice, the
    seeds, commit, command and what chose it; :mod:`agents.evaluation.results` reads it)."""

    setting: str
    scenario: str
    sensing: str
    policy: str
    summary: str


#: what to use, setting by setting; each figure is in its summary
RECOMMENDED: tuple[Recommendation, ...] = (
    Recommendation(
        "bench, sea state 4, ideal",
        "bench-ss4",
        "ideal",
        "predictive",
        "bench-ss4-ideal-heldout",
    ),
    Recommendation(
        "bench, sea state 4, realistic",
        "bench-ss4",
        "realistic",
        "predictive",
        "bench-ss4-realistic-heldout",
    ),
    Recommendation(
        "bench, sea state 5, realistic",
        "bench-ss5",
        "realistic",
        "timing-dqn-predictive",
        "bench-ss5-realistic-heldout",
    ),
    Recommendation(
        "ship, sea state 3, realistic",
        "ship-ss3",
        "realistic",
        "predictive",
        "ship-ss3-realistic-heldout",
    ),
    Recommendation(
        "ship, sea state 4, realistic",
        "ship-ss4",
        "realistic",
        "predictive",
        "ship-ss4-realistic-heldout",
    ),
    Recommendation(
        "ship, sea state 5, realistic",
        "ship-ss5",
        "realistic",
        "predictive",
        "ship-ss5-realistic-heldout",
    ),
    Recommendation(
        "ship, sea state 6, realistic",
        "ship-ss6",
        "realistic",
        "predictive",
        "ship-ss6-realistic-heldout",
    ),
)

#: the policy ``evaluate landing --scenario S`` runs without ``--policy``
DEFAULT_POLICY: dict[str, str] = {
    "bench-ss3": "predictive",
    "bench-ss4": "predictive",
    "bench-ss5": "timing-dqn-predictive",
    "paper-stewart": "quiescent",
    "ship-ss3": "predictive",
    "ship-ss4": "predictive",
    "ship-ss5": "predictive",
    "ship-ss6": "predictive",
    "bench-unseen": "predictive",
    "ship-unseen-4": "predictive",
    "ship-unseen-5": "predictive",
}


def default_policy(scenario: str) -> str:
    """The recommended policy of ``scenario``."""
    require_choice("scenario", scenario, tuple(DEFAULT_POLICY))
    return DEFAULT_POLICY[scenario]


def policy_spec(name: str) -> PolicySpec:
    """The registered policy ``name`` (a clear error naming the allowed ones)."""
    require_choice("policy", name, POLICY_NAMES)
    return POLICIES[name]


def make_policy(
    name: str, env: Any, model_path: str | None = None, allow_mismatch: tuple[str, ...] = ()
) -> Any:
    """Build the policy ``name`` for ``env`` (an environment of its task); a trained model is
    checked against ``env`` (its card), ``allow_mismatch`` naming fields that may differ."""
    spec = policy_spec(name)
    module, function = spec.builder.split(":")
    builder = getattr(importlib.import_module(module), function)
    if model_path is not None or spec.model is not None:
        model_path = require_model(name, model_path)
    return builder(env, model_path, tuple(allow_mismatch))


def env_settings(
    policy: str,
    scenario: str,
    estimator: str | None = None,
    camera_mode: str = "project",
    sensing: str | None = None,
    extra_overrides: dict[str, Any] | None = None,
) -> tuple[str, dict[str, Any]]:
    """The registered id ``policy`` flies on ``scenario`` and the overrides it lays over the
    id's: its own settings, its estimator and sensing (unless given), then ``extra_overrides``
    (the scenario's config is :func:`scenario_config`'s)."""
    spec = policy_spec(policy)
    table = {**SCENARIOS, **APPROACH_SCENARIOS}
    require_choice("scenario", scenario, tuple(table))
    env_id = spec.env_ids.get(scenario) or scenario_id(scenario, spec.task)
    overrides: dict[str, Any] = {}
    chosen = estimator or spec.estimator
    if chosen is not None:
        overrides["estimation.observed"] = chosen
    if camera_mode != "project":
        require_choice("mode", camera_mode, ("project", "render"))
        overrides["camera.mode"] = camera_mode
    if sensing:
        overrides["sensors"] = sensing
    elif spec.sensing and not os.environ.get(SENSORS_ENV):
        # the sensing it was made for, unless the run says otherwise (``--sensors``)
        overrides["sensors"] = spec.sensing
    overrides.update(spec.scenario_overrides.get(scenario, spec.overrides))
    overrides.update(extra_overrides or {})
    return env_id, overrides


def scenario_config(scenario: str) -> str:
    """The config ``scenario`` flies: its id's, or a held-out sea's own on its sibling's id."""
    table = {**SCENARIOS, **APPROACH_SCENARIOS}
    require_choice("scenario", scenario, tuple(table))
    return table[scenario].config


def make_env_and_policy(
    policy_name: str,
    scenario: str,
    estimator: str | None = None,
    camera_mode: str = "project",
    model_path: str | None = None,
    render_mode: str | None = None,
    extra_overrides: dict[str, Any] | None = None,
    allow_mismatch: tuple[str, ...] = (),
    sensing: str | None = None,
) -> tuple[Any, Any]:
    """The scenario's registered id for the policy's task, with the policy's settings
    (:func:`env_settings`), and the policy built in it."""
    env_id, overrides = env_settings(
        policy_name, scenario, estimator, camera_mode, sensing, extra_overrides
    )
    config = scenario_config(scenario)
    env = gym.make(
        env_id,
        config=config,
        overrides=overrides,
        render_mode=render_mode,
        # a scenario flying another's id on its own config ends where its own config says
        max_episode_steps=step_limit_on(env_id, config, overrides),
    )
    try:
        policy = make_policy(policy_name, env, model_path, tuple(allow_mismatch))
    except Exception:
        env.close()
        raise
    return env, policy


def check_registry() -> None:
    """Refuse a registry whose entries contradict each other (a test runs it)."""
    for scenario, name in DEFAULT_POLICY.items():
        spec = policy_spec(name)
        if spec.scenarios and scenario not in spec.scenarios:
            raise ConfigError("DEFAULT_POLICY", f"{name} is not made for {scenario}")
    for rec in RECOMMENDED:
        if POLICIES[rec.policy].status != "recommended":
            raise ConfigError("RECOMMENDED", f"{rec.policy} is recommended but not so marked")


__all__ = [
    "DEFAULT_POLICY",
    "POLICIES",
    "POLICY_NAMES",
    "RECOMMENDED",
    "PolicySpec",
    "Recommendation",
    "default_policy",
    "env_settings",
    "find_model",
    "make_env_and_policy",
    "make_policy",
    "policy_spec",
    "require_model",
    "scenario_config",
]
