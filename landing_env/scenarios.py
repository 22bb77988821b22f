"""THE scenario table: every scenario the CLI names and every id it registers with Gymnasium.

A :class:`Scenario` (``bench-ss4``, ``ship-ss5``, ...) is a shipped config made a landing run:
the drone flying, the tag projected analytically, an estimator observed and, for the timing
task, the scenario's timing settings.  It registers one id per task it serves
(``DeckLanding-BenchSS4-v2``, ``DeckLandingTiming-BenchSS4-v6``), so that
``deck-landing evaluate landing --scenario bench-ss4`` and
``gym.make("DeckLandingTiming-BenchSS4-v6")`` build the same environment; a policy lays its own
settings (its estimator, its timing options) over the id's with the same dotted overrides
(:mod:`agents.policies.registry`).

Versions follow Gymnasium's rule: a version is the same task, fixed; variants (the observation,
the wave-off, the contact window) are settings of the config's ``timing`` section
(:class:`~landing_env.timing_config.TimingConfig`), set with ``overrides={"timing.<key>": ...}``.
Each id family's history is in :data:`VERSION_HISTORY`; an id no longer registered is refused by
Gymnasium with the latest version named.  To add a scenario, add a row to :data:`SCENARIOS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from types import SimpleNamespace
from typing import Any

from gymnasium.envs.registration import load_env_creator, register, registry

from landing_env.config import (
    DeckLandingConfig,
    SimulationConfig,
    episode_step_limit,
    read_config_data,
)
from landing_env.config_loading import (
    build_dataclass,
    deep_merge,
    dotted_to_nested,
    nested_to_dotted,
)
from landing_env.errors import ConfigError, require_choice
from landing_env.sea.heldout import HELD_OUT_SEAS
from landing_env.timing_config import SCENARIO_TILT_MODEL, TimingConfig

#: the top-level keys of the environment config (a keyword of ``gym.make`` for a section)
CONFIG_SECTIONS = frozenset(f.name for f in fields(DeckLandingConfig))

#: the task environments: id -> entry point
LANDING_TASK = "DeckLanding-v2"
TIMING_TASK = "DeckLandingTiming-v0"
TASKS: dict[str, str] = {
    LANDING_TASK: "landing_env.envs.deck_landing:DeckLandingEnv",
    TIMING_TASK: "landing_env.envs.timing:DeckLandingTimingEnv",
}

#: what turns a bench config (a pinned drone over the moving deck) into a landing run
FLYING_OVERRIDES: dict[str, Any] = {
    "simulation.drone_fixed": False,
    "simulation.max_episode_s": 40.0,
    "estimation.compare": [],
}
#: starts per task: the timing task starts at its hold height; align-descend far and off
START_OVERRIDES: dict[str, dict[str, Any]] = {
    TIMING_TASK: {"start.max_offset_m": 0.1, "start.max_yaw_deg": 10.0},
    LANDING_TASK: {
        "start.height_m": [1.5, 4.0],
        "start.max_offset_m": 1.0,
        "start.max_yaw_deg": 30.0,
    },
}


def landing_overrides(
    task: str, estimator: str = "ihrcf", camera_mode: str = "project"
) -> dict[str, Any]:
    """The dotted overrides that make a bench config a landing run of ``task``."""
    require_choice("task", task, tuple(TASKS))
    require_choice("mode", camera_mode, ("project", "render"))
    return {
        **FLYING_OVERRIDES,
        **START_OVERRIDES[task],
        "estimation.observed": estimator,
        "camera.mode": camera_mode,
    }


# ------------------------------------------------------------------------------ timing presets
#: the bench's timing task: the **timed** final descent (the height over the deck tracks a
#: 1.2 s reference, so the feet touch 1.30 +- 0.06 s after the commit) and the scenario's own
#: deck-tilt predictor for the options that read one (the wave-off by the predictor, the
#: contact window, the prediction observation)
BENCH_TIMING: dict[str, Any] = {
    "guidance": {"descent_profile": "timed"},
    "tilt_model": SCENARIO_TILT_MODEL,
}

#: the contact times a commit of the ``predictive`` timing chooses among, seconds after it
CONTACT_WINDOW_S = [1.2, 1.5]

#: the options the ``predictive`` timing flies with on the bench: an 8 s history (the window
#: of the scenario's deck-tilt predictor), the contact time chosen in ``CONTACT_WINDOW_S``, and
#: the wave-off by that predictor below the value of waiting on
PREDICTIVE_TIMING: dict[str, Any] = {
    "history_s": 8.0,
    "wave_off_tilt_deg": 5.0,
    "wave_off_predictor": "model",
    "wave_off_rule": "value",
    "contact_window_s": CONTACT_WINDOW_S,
}

#: what the lander's ids add to a bench scenario's timing settings: the ``predictive`` policy's
#: descent options (the deck-tilt predictor's wave-off and contact window) and the predictor's
#: chances and value of waiting in the observation
LANDER_TIMING: dict[str, Any] = {**PREDICTIVE_TIMING, "observation": "prediction"}

#: the ship's timing task: the drone holds 2 m over a helideck that heaves metres; the guidance
#: flies in the deck's frame (deck-velocity feed-forward led 0.2 s by a constant-acceleration
#: tracker, relative descent speed), descends blind on the track and the ToF below 0.8 m where
#: the 0.30 m tag leaves the view, goes around when the deck is lost, and gates the descent on
#: the camera's own field of view (:mod:`landing_env.timing.guidance`)
SHIP_TIMING: dict[str, Any] = {
    "hold_height_m": 2.0,
    "descent_timeout_s": 15.0,
    "guidance": {
        "track_deck": True,
        "k_xy": 1.5,
        "blind_range_m": 0.8,
        "view_half_tan": 0.558,
        "flare_range_m": 0.0,
        "tracker_model": "acceleration",
        "deck_lead_s": 0.2,
        "lost_deck": "search",
        "view_from_camera": True,
        "descent_rate_gain": 1.0,
    },
}

#: the ship's timing settings up to ``DeckLandingTiming-ShipSS<n>-v7`` (kept registered for the
#: model trained on them): the descent without the relative speed's feedback
SHIP_TIMING_V7: dict[str, Any] = {
    **SHIP_TIMING,
    "guidance": {k: v for k, v in SHIP_TIMING["guidance"].items() if k != "descent_rate_gain"},
}

#: the ship's touchdown: at the first contact a 0.15 s land sequence instead of cutting the
#: motors, the thrust falling to nothing along the deck's normal as the ToF ranges measure it
#: (``World.settle``; PX4's land detector: ground contact, thrust lowered, landed, disarm);
#: with the descent's relative speed held to its plan (``descent_rate_gain``), ``land-now``
#: at ``ship-ss6`` lands 77.5 % of 400 seeds against 63.0 % (docs/experiments/ship-timing.md)
SHIP_TOUCHDOWN: dict[str, Any] = {
    "touchdown.spool_down_s": 0.15,
    "touchdown.spool_down_final_thrust": 0.0,
}

#: the estimate observed over a ship deck: ``tight`` uses the ToF rays that hit the pad (1-3 of
#: 4 when the drone leans or drifts near its edge) and the tag alone without any, where IHRCF
#: and CRHF need all four
SHIP_ESTIMATOR = "tight"


# ------------------------------------------------------------------------------ the table
@dataclass(frozen=True)
class Scenario:
    """A named scenario: a shipped config made a landing run, and the ids it registers."""

    name: str
    config: str
    description: str
    #: registered id per task it serves (``DeckLanding-v2`` / ``DeckLandingTiming-v0``)
    ids: dict[str, str]
    #: the estimate in the observation
    estimator: str = "ihrcf"
    #: the timing task's settings (the config's ``timing`` section, nested); the lander's
    #: descent flies them too (with :data:`LANDER_TIMING` where a deck-tilt predictor is named)
    timing: dict[str, Any] = field(default_factory=dict)
    #: further dotted overrides of the config
    extra: dict[str, Any] = field(default_factory=dict)
    #: a held-out sea (:mod:`landing_env.sea.heldout`): it registers no id of its own but
    #: flies its sibling's ids on its own config (``gym.make(id, config=...)``)
    held_out: bool = False
    #: registers its own ids (False: it flies the ids it names on its own config, as the
    #: held-out seas do)
    own_id: bool = True

    def __post_init__(self) -> None:
        if self.held_out and self.own_id:
            object.__setattr__(self, "own_id", False)

    def overrides(
        self, task: str, estimator: str | None = None, camera_mode: str = "project"
    ) -> dict[str, Any]:
        """The dotted overrides of this scenario's ``task`` (the id's, or with another
        estimator or camera mode)."""
        require_choice("task", task, tuple(self.ids))
        result = {
            **landing_overrides(task, estimator or self.estimator, camera_mode),
            **self.extra,
        }
        if task == TIMING_TASK:
            result.update(nested_to_dotted(self.timing, "timing"))
        elif self.timing:
            predicted = LANDER_TIMING if "tilt_model" in self.timing else {}
            result.update(nested_to_dotted({**self.timing, **predicted}, "timing"))
        return result


_BENCH_SEAS = {
    3: "sea state 3 (Hs 0.88 m, Tp 7.5 s)",
    4: "sea state 4 (Hs 1.88 m, Tp 8.8 s)",
    5: "sea state 5 (Hs 3.25 m, Tp 9.7 s)",
}
_SHIP_SEAS = {**_BENCH_SEAS, 6: "sea state 6 (Hs 5.0 m, Tp 12.4 s)"}

#: THE scenario table: CLI name -> scenario
SCENARIOS: dict[str, Scenario] = {
    **{
        f"bench-ss{n}": Scenario(
            f"bench-ss{n}",
            f"bench-ss{n}",
            f"Stewart bench, {sea} scaled into the platform's workspace",
            {
                LANDING_TASK: f"DeckLanding-BenchSS{n}-v2",
                TIMING_TASK: f"DeckLandingTiming-BenchSS{n}-v6",
            },
            timing=BENCH_TIMING,
        )
        for n, sea in _BENCH_SEAS.items()
    },
    "paper-stewart": Scenario(
        "paper-stewart",
        "paper-stewart",
        "the papers' Stewart bench (sums of sinusoids)",
        {
            LANDING_TASK: "DeckLanding-PaperStewart-v2",
            TIMING_TASK: "DeckLandingTiming-PaperStewart-v0",
        },
    ),
    **{
        f"ship-ss{n}": Scenario(
            f"ship-ss{n}",
            f"ship-ss{n}",
            f"30 m vessel's helideck, {sea}, wind and gusts; the drone starts in trim",
            {
                LANDING_TASK: f"DeckLanding-ShipSS{n}-v6",
                TIMING_TASK: f"DeckLandingTiming-ShipSS{n}-v8",
            },
            estimator=SHIP_ESTIMATOR,
            timing=SHIP_TIMING,
            extra=SHIP_TOUCHDOWN,
        )
        for n, sea in _SHIP_SEAS.items()
    },
}

#: the held-out seas (never fitted, trained or tuned on): each flies the ids of the scenario
#: whose task it shares, on its own config
HELD_OUT_SCENARIOS: dict[str, Scenario] = {
    name: Scenario(
        name,
        name,
        f"held-out sea: {HELD_OUT_SEAS[name]}",
        SCENARIOS[sibling].ids,
        estimator=SCENARIOS[sibling].estimator,
        timing=SCENARIOS[sibling].timing,
        extra=SCENARIOS[sibling].extra,
        held_out=True,
    )
    for name, sibling in (
        ("bench-unseen", "bench-ss4"),
        ("ship-unseen-4", "ship-ss4"),
        ("ship-unseen-5", "ship-ss5"),
    )
}
SCENARIOS.update(HELD_OUT_SCENARIOS)

#: the approach from altitude's id, which its scenarios fly on their own configs
HIGH_APPROACH_ID = "DeckLanding-HighApproach-v2"

#: the scenarios of the approach from altitude (``DeckLanding-v2`` only)
APPROACH_SCENARIOS: dict[str, Scenario] = {
    "high-approach": Scenario(
        "high-approach",
        "high-approach",
        "from 20 m up and 5 m off, gusty wind, sea state 3",
        {LANDING_TASK: HIGH_APPROACH_ID},
    ),
    # the SVGS paper's flights from 100 m (its Tables 3-4) on a static pad: the high approach
    # on another config (``gym.make("DeckLanding-HighApproach-v2", config="svgs-100m")``)
    "svgs-100m": Scenario(
        "svgs-100m",
        "svgs-100m",
        "the SVGS paper's flights: from 101.7-106.7 m over a static pad, three landmarks",
        {LANDING_TASK: HIGH_APPROACH_ID},
        own_id=False,
    ),
    "svgs-100m-irlock": Scenario(
        "svgs-100m-irlock",
        "svgs-100m-irlock",
        "the SVGS paper's IR-LOCK flights: from 53.1-55.0 m over a static pad",
        {LANDING_TASK: HIGH_APPROACH_ID},
        own_id=False,
    ),
}

#: what each id family's versions were (the ids before the current ones are not registered,
#: but for a superseded one kept for a shipped model trained on it:
#: :attr:`ScenarioId.superseded_by`)
VERSION_HISTORY: dict[str, list[str]] = {
    "DeckLanding-<Scenario>": [
        "v0: the scenario's config made a landing run, IHRCF observed on the bench.",
        "v1: every observation key a float32 Box, the drone's velocity and attitude observed, "
        "a touchdown bonus.",
        "v2: DeckLanding-v2's land action (the timing task's descent in the step, obeyed in "
        "the hold band, forced after the wait limit in it), its observation and reward, the "
        "bench's timing settings (current).",
    ],
    "DeckLanding-ShipSS<n>": [
        "v0: the bench's settings over the ship deck.",
        "v1: ``tight`` observed, the ship configs' touchdown envelope, the standard lens.",
        "v2: the scenario's lens (wide at sea states 5 and 6).",
        "v3: started in trim with the mean wind, the autopilots' limits.",
        "v4: every observation key a float32 Box, the drone's velocity and attitude observed, "
        "a touchdown bonus.",
        "v5: DeckLanding-v2's land action, observation and reward, the ship's timing settings "
        "(a 2 m hold).",
        "v6: the touchdown control of the timing task's v8 (current).",
    ],
    "DeckLandingTiming-BenchSS<n>": [
        "v0: the range-scheduled final descent.",
        "v1: the timed final descent.",
        "v2-v4: v1 with an 8 s history and the deck-tilt predictor's wave-off (v3: below the "
        "value of waiting on; v4: and the contact window) fixed in the id.",
        "v5: v4 observing the predictor's chances instead of the history.",
        "v6: the timed descent with the scenario's deck-tilt predictor; the wave-off, the "
        "contact window and the observation are ``timing`` settings, not versions; v4 is v6 "
        "with the ``predictive`` policy's settings and v5 adds ``timing.observation: "
        "prediction`` (current).",
    ],
    "DeckLandingTiming-ShipSS<n>": [
        "v0: the bench's guidance over the ship deck.",
        "v1: the deck-frame guidance, ``tight`` observed.",
        "v2: the deck's acceleration tracked and led.",
        "v3: a go-around with the deck lost, no flare.",
        "v4: the scenario's lens, the view gate from the camera.",
        "v5: v4 observing the helideck forecast and the drone's own state.",
        "v6: v5 started in trim with the mean wind, the autopilots' limits.",
        "v7: v6 observing the deck-pose history by default; the forecast observation was the "
        "setting ``timing.observation: forecast`` until it left the package after 1.0.0; "
        "kept registered for ``timing_dqn_lookahead.zip``, which was trained on it.",
        "v8: the touchdown control: the descent holds its measured relative speed to the plan "
        "(``timing.guidance.descent_rate_gain``) and a 0.15 s land sequence along the "
        "measured deck normal follows the contact (``touchdown.spool_down_s``) (current).",
    ],
    "DeckLandingTiming-PaperStewart": ["v0: the range-scheduled descent (current)."],
    "DeckLanding-HighApproach": [
        "v0: from 20 m up and 5 m off.",
        "v1: every observation key a float32 Box, the drone's velocity and attitude observed, "
        "a touchdown bonus.",
        "v2: DeckLanding-v2's land action, observation and reward (current).",
    ],
}


@dataclass(frozen=True)
class ScenarioId:
    """A registered id: a task on a scenario's config, with its dotted overrides."""

    task: str
    config: str
    description: str
    overrides: dict[str, Any] = field(default_factory=dict)
    #: the scenario (:data:`SCENARIOS`) it belongs to
    scenario: str = ""
    #: the id that replaces it, where it is kept registered only for a shipped model
    superseded_by: str | None = None

    def make(self, overrides: dict[str, Any] | None = None, **kwargs: Any) -> Any:
        """The task's environment on this scenario; ``overrides`` (dotted keys) apply on top
        of the scenario's (``gym.make(id, overrides={...})``), other keywords go to the task."""
        task = load_env_creator(TASKS[self.task])
        config = kwargs.pop("config", self.config)
        # a config section given as a keyword (``timing={...}``, ``camera={...}``) is laid over
        # the scenario's settings like any override, never under them
        sections = {key: kwargs.pop(key) for key in list(kwargs) if key in CONFIG_SECTIONS}
        given = {
            **{
                k: v
                for key, value in sections.items()
                for k, v in (
                    nested_to_dotted(value, key) if isinstance(value, dict) else {key: value}
                ).items()
            },
            **(overrides or {}),
        }
        return task(config=config, overrides={**self.overrides, **given}, **kwargs)


def _task_phrase(task: str) -> str:
    return "timing task" if task == TIMING_TASK else "align and descend"


def _ids() -> dict[str, ScenarioId]:
    ids: dict[str, ScenarioId] = {}
    for scenario in (*SCENARIOS.values(), *APPROACH_SCENARIOS.values()):
        if not scenario.own_id:
            continue
        for task, env_id in scenario.ids.items():
            ids[env_id] = ScenarioId(
                task,
                scenario.config,
                f"{_task_phrase(task)}: {scenario.description}",
                scenario.overrides(task),
                scenario.name,
            )
    # the ship's timing ids before the touchdown control, kept for the model trained on them
    for n in _SHIP_SEAS:
        scenario = SCENARIOS[f"ship-ss{n}"]
        ids[f"DeckLandingTiming-ShipSS{n}-v7"] = ScenarioId(
            TIMING_TASK,
            scenario.config,
            f"{_task_phrase(TIMING_TASK)} without the touchdown control: {scenario.description}",
            {
                **landing_overrides(TIMING_TASK, scenario.estimator, "project"),
                **nested_to_dotted(SHIP_TIMING_V7, "timing"),
            },
            scenario.name,
            superseded_by=scenario.ids[TIMING_TASK],
        )
    # the high approach flies as its config says (from altitude, in gusts): no landing overrides
    approach = APPROACH_SCENARIOS["high-approach"]
    ids[approach.ids[LANDING_TASK]] = ScenarioId(
        LANDING_TASK, approach.config, approach.description, {}, approach.name
    )
    return ids


#: THE id -> scenario table (every registered id but the two bare tasks)
SCENARIO_IDS: dict[str, ScenarioId] = _ids()


def scenario_id(scenario: str, task: str) -> str:
    """The registered id of ``scenario``'s ``task``."""
    table = {**SCENARIOS, **APPROACH_SCENARIOS}
    require_choice("scenario", scenario, tuple(table))
    if task not in table[scenario].ids:
        raise ConfigError("scenario", f"{scenario!r} has no {task} id")
    return table[scenario].ids[task]


def make_scenario_env(scenario: str, **kwargs: Any) -> Any:
    """Gymnasium's entry point of every scenario id (``kwargs``: see :meth:`ScenarioId.make`)."""
    return SCENARIO_IDS[scenario].make(**kwargs)


make_scenario_env.metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 20}  # type: ignore[attr-defined]


def register_all() -> None:
    """Register the tasks and every scenario id with Gymnasium (idempotent)."""
    for env_id, entry_point in TASKS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, disable_env_checker=False)
    for env_id, scenario in SCENARIO_IDS.items():
        if env_id in registry:
            continue
        register(
            id=env_id,
            entry_point="landing_env.scenarios:make_scenario_env",
            kwargs={"scenario": env_id},
            max_episode_steps=_step_limit(scenario),
            disable_env_checker=False,
        )


def step_limit_on(env_id: str, config: str, overrides: dict[str, Any] | None = None) -> int:
    """The ``max_episode_steps`` of ``env_id`` flown on another ``config`` (a held-out sea, the
    SVGS flights on the high approach's id): ``gym.make(env_id, config=config,
    max_episode_steps=...)`` then truncates where that config's episode ends."""
    scenario = SCENARIO_IDS[env_id]
    return _step_limit(
        ScenarioId(
            scenario.task, config, scenario.description, {**scenario.overrides, **(overrides or {})}
        )
    )


def _step_limit(scenario: ScenarioId) -> int:
    """``episode_step_limit`` from the scenario's simulation and timing sections alone:
    registration reads no calibration file and builds no sensor (importing stays cheap)."""
    data = deep_merge(read_config_data(scenario.config), dotted_to_nested(scenario.overrides))
    sim = build_dataclass(SimulationConfig, data.get("simulation") or {}, "simulation")
    timing = None
    if scenario.task == TIMING_TASK:
        timing = build_dataclass(TimingConfig, data.get("timing") or {}, "timing")
    return episode_step_limit(SimpleNamespace(simulation=sim), timing)  # type: ignore[arg-type]


__all__ = [
    "APPROACH_SCENARIOS",
    "BENCH_TIMING",
    "CONTACT_WINDOW_S",
    "FLYING_OVERRIDES",
    "HELD_OUT_SCENARIOS",
    "LANDER_TIMING",
    "LANDING_TASK",
    "PREDICTIVE_TIMING",
    "SCENARIOS",
    "SCENARIO_IDS",
    "SHIP_ESTIMATOR",
    "SHIP_TIMING",
    "START_OVERRIDES",
    "TASKS",
    "TIMING_TASK",
    "VERSION_HISTORY",
    "Scenario",
    "ScenarioId",
    "landing_overrides",
    "register_all",
    "scenario_id",
    "step_limit_on",
]
