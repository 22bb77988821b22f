"""Registered environment ids with their scenario built in: ONE table, ``SCENARIO_IDS``.

``gym.make("DeckLandingTiming-BenchSS4-v0")`` is ``DeckLandingTiming-v0`` on the
``bench-ss4`` config made a landing run (the drone flying, the tag projected, IHRCF in the
observation): what the README trains and evaluates on, reproducible by id alone (rl-zoo3
included).  To add or rename a scenario, edit the table; the ids follow
``<task>-<Scenario>-v<version>`` and the version goes up when what the id builds changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from landing_env.errors import require_choice
from landing_env.physics.controller import ControllerGains

#: the task environments: id -> entry point
TASKS: dict[str, str] = {
    "DeckLanding-v0": "landing_env.envs.deck_landing:DeckLandingEnv",
    "DeckLandingTiming-v0": "landing_env.envs.timing:DeckLandingTimingEnv",
}

#: what turns a bench config (a pinned drone over the moving deck) into a landing run
FLYING_OVERRIDES: dict[str, Any] = {
    "simulation.drone_fixed": False,
    "simulation.max_episode_s": 40.0,
    "estimation.compare": [],
}
#: starts per task: the timing task starts at its hold height; align-descend far and off
START_OVERRIDES: dict[str, dict[str, Any]] = {
    "DeckLandingTiming-v0": {"start.max_offset_m": 0.1, "start.max_yaw_deg": 10.0},
    "DeckLanding-v0": {
        "start.height_m": [1.5, 4.0],
        "start.max_offset_m": 1.0,
        "start.max_yaw_deg": 30.0,
    },
}


def landing_overrides(
    task: str, estimator: str = "ihrcf", camera_mode: str = "project"
) -> dict[str, Any]:
    """The dotted overrides that make a bench config a landing run of ``task``."""
    return {
        **FLYING_OVERRIDES,
        **START_OVERRIDES[task],
        "estimation.observed": estimator,
        "camera.mode": camera_mode,
    }


@dataclass(frozen=True)
class ScenarioId:
    """A registered id: a task on a config, with overrides (dotted keys)."""

    task: str
    config: str
    description: str
    overrides: dict[str, Any] = field(default_factory=dict)
    #: keyword arguments of the task itself (e.g. the timing task's ``timing`` settings)
    task_kwargs: dict[str, Any] = field(default_factory=dict)

    def make(self, overrides: dict[str, Any] | None = None, **kwargs: Any) -> Any:
        """The task's environment on this scenario; ``overrides`` apply on top of the
        scenario's (``gym.make(id, overrides={...})``), other keywords go to the task."""
        from gymnasium.envs.registration import load_env_creator

        task = load_env_creator(TASKS[self.task])
        config = kwargs.pop("config", self.config)
        kwargs = {**self.task_kwargs, **kwargs}
        return task(config=config, overrides={**self.overrides, **(overrides or {})}, **kwargs)


def _landing(
    task: str, config: str, description: str, task_kwargs: dict[str, Any] | None = None
) -> ScenarioId:
    return ScenarioId(task, config, description, landing_overrides(task), task_kwargs or {})


#: the timing task over a ship deck holds higher: the helideck heaves metres at up to
#: 2-4 m/s (the bench: centimetres), and 0.7 m over it ends in a touchdown during the warm-up;
#: the guidance flies in the deck's frame (deck-velocity feed-forward, relative descent speed,
#: the camera aimed at the tag and the descent held while the tag nears the image edge;
#: landing_env/envs/guidance.py); below 0.8 m, where the 0.30 m tag no longer fits the view
#: of a camera leaning 10-25 deg in wind, it descends on the track and the ToF; below 0.5 m
#: it waits out gusts that lean the drone more than 18 deg; the descent may pause to find the
#: tag again or for a lull, so it gets 15 s (the ``-v1`` ship ids)
SHIP_TIMING_V1: dict[str, Any] = {
    "hold_height_m": 2.0,
    "descent_timeout_s": 15.0,
    "guidance": {
        "track_deck": True,
        "k_xy": 1.5,
        "blind_range_m": 0.8,
        # 256 px / 458.5 px: half the image over the focal length of the default camera
        "view_half_tan": 0.558,
        "flare_range_m": 0.5,
    },
}

#: the ship's timing task from ``-v2`` on: the deck tracker models the deck's acceleration
#: (constant-acceleration Kalman filter) and the set-point carries the deck's velocity 0.2 s
#: ahead, the velocity loop's lag, so that the drone meets a heaving deck on time: at
#: ship-ss4 the touchdown speed's 95th percentile fell from 0.44 to 0.32 m/s (README
#: "Landing on the ship")
SHIP_TIMING_V2: dict[str, Any] = {
    **SHIP_TIMING_V1,
    "guidance": {
        **SHIP_TIMING_V1["guidance"],
        "tracker_model": "acceleration",
        "deck_lead_s": 0.2,
    },
}

#: the ship's timing task from ``-v3`` on: with the deck lost (neither the tag nor a ToF range
#: for the tracker's 1.5 s coast, the drone above the blind range: a gust leans it 20-30 deg
#: and its view and rays leave the 2 m pad) the guidance goes around (``lost_deck: search``:
#: climbs over the deck's last height, re-centred on its horizontal track) where v2 flew on
#: down blind, past the pad's edge: at ship-ss4 the timeouts of ``land-now`` fell from 9 to
#: 1 in 200; and no flare (``flare_range_m: 0``): with the rotor drag fading after the motor
#: cut (quadrotor.yaml ``drag.airframe_fraction``) a leaning touchdown seldom tips over, and
#: waiting low over the deck for a lean below 18 deg (which sea state 5's wind never gives)
#: only let the drone drift off the pad (README "Landing on the ship")
SHIP_TIMING_V3: dict[str, Any] = {
    **SHIP_TIMING_V2,
    "guidance": {**SHIP_TIMING_V2["guidance"], "lost_deck": "search", "flare_range_m": 0.0},
}

#: the ship's timing task from ``-v4`` on: the scenario's own lens (``ship-ss5`` and
#: ``ship-ss6`` fit the wide one, ``lens: wide``, configs/lenses/wide.yaml: 80 deg across
#: where the standard lens sees 58 deg; the ids up to v3 keep the standard lens everywhere)
#: and the view gate's half field of view taken from the camera's calibration
#: (``view_from_camera``) instead of the standard lens's 0.558: a drone leaning 20-30 deg
#: into the wind of sea states 5 and 6 keeps the tag in view (README "A wider lens for the
#: ship")
SHIP_TIMING: dict[str, Any] = {
    **SHIP_TIMING_V3,
    "guidance": {**SHIP_TIMING_V3["guidance"], "view_from_camera": True},
}

#: the ship timing ids' v5: v4 observing, after the history, the ship's helideck forecast (its
#: HMS record 0-8 s ahead) and the drone's own velocity and lean (``timing.observation``)
SHIP_TIMING_FORECAST: dict[str, Any] = {**SHIP_TIMING, "observation": "forecast"}

#: the first ship id of each task whose drone starts in trim with the mean wind (leaning into
#: it, the rotors carrying its drag: ``start.trim_to_wind``) and flies with the autopilots'
#: stock limits (a 10 m/s^2 velocity integrator, 45 deg of tilt: the ship configs'
#: ``controller``), where the earlier ids start level and at rest with the bench's limits and
#: the wind blows the drone off the deck during the hold: at ship-ss6 the deck was 1.86 m off
#: the camera's axis at the first decision in 82 of 100 episodes (README "Starting in trim,
#: with the autopilot's limits")
SHIP_TRIM_VERSION = {"DeckLandingTiming-v0": 6, "DeckLanding-v0": 3}

#: ``timing.tilt_model`` that stands for the scenario's own deck-tilt predictor (its config's
#: ``deck_predictor``): one model card then fits every scenario it was trained over
SCENARIO_TILT_MODEL = "scenario"

#: the ids made before the ship scenarios' wide lens keep the standard one
STANDARD_LENS = {"lens": "standard"}


#: the bench's timing task from v1 on: the **timed** final descent (GuidanceGains.descent_profile;
#: the height over the deck tracks a 1.2 s reference, so the feet touch 1.30 +- 0.06 s after the
#: commit, where v0's range-scheduled descent, cushioned by the ground effect in its last
#: centimetres, took 1.85 +- 0.35 s): a timing policy predicts the deck a fixed, shorter time
#: ahead (README "Timing with a timed descent")
BENCH_TIMING: dict[str, Any] = {"guidance": {"descent_profile": "timed"}}

#: the contact times a commit of the ``predictive`` timing chooses among, seconds after it
#: (``timing.contact_window_s``: the timed descent lasts 1.1-1.4 s, meeting the deck where the
#: predictor gives the best chance; a wider window, to 1.8 s, did worse at bench sea state 5,
#: README "Predicting the deck a descent ahead")
CONTACT_WINDOW_S = [1.2, 1.5]

#: what the ``predictive`` timing flies with (v4 of the bench ids): an 8 s history, the window
#: of the scenario's deck-tilt predictor (``tilt_model``, landing_env/assets/predictors), the
#: contact time chosen in ``CONTACT_WINDOW_S``, and the wave-off by that predictor: 0.4-0.7 s
#: into a chosen descent, a chance that the deck is within 5 deg at the contact below the
#: value of waiting on (the optimal-stopping value over the wait left) aborts it (README
#: "Predicting the deck a descent ahead")
PREDICTIVE_TIMING: dict[str, Any] = {
    "history_s": 8.0,
    "wave_off_tilt_deg": 5.0,
    "wave_off_predictor": "model",
    "wave_off_rule": "value",
    "contact_window_s": CONTACT_WINDOW_S,
}


#: what each version of the predictive bench ids flies (``bench_predictive_timing``)
PREDICTIVE_VERSIONS: dict[int, str] = {
    2: "the timed descent, an 8 s history and the deck-tilt predictor's wave-off below a "
    "fixed chance",
    3: "the timed descent, an 8 s history and the deck-tilt predictor's wave-off below the "
    "value of waiting on",
    4: "the timed descent whose contact time each commit chooses by the deck-tilt predictor, "
    "an 8 s history and the predictor's wave-off below the value of waiting on",
    5: "v4's descent and wave-off, observing instead of the history the deck-tilt predictor's "
    "chance at each contact time and the value of waiting on (for a learned policy)",
}


def bench_predictive_timing(version: int = 4) -> dict[str, Any]:
    """The timing settings of ``DeckLandingTiming-BenchSS<n>-v<version>``, whatever the sea
    state (each reads its scenario's own deck-tilt predictor; v2: the model
    wave-off below a fixed chance of 0.8; v3: below the value of waiting on; v4: and the
    contact time chosen in ``CONTACT_WINDOW_S``; v2 and v3 have the fixed 1.3 s contact; v5:
    v4 observing the predictor's chances and the value of waiting instead of the history)."""
    require_choice("version", version, tuple(PREDICTIVE_VERSIONS))
    rule: dict[str, Any] = {} if version >= 4 else {"contact_window_s": []}
    if version == 5:
        rule["observation"] = "prediction"
    if version == 2:
        rule.update({"wave_off_rule": "fixed", "wave_off_probability": 0.8})
    return {
        **BENCH_TIMING,
        **PREDICTIVE_TIMING,
        **rule,
        # the scenario's own predictor (bench-ss<n>.yaml's deck_predictor)
        "tilt_model": SCENARIO_TILT_MODEL,
    }


#: the estimate observed over a ship deck: ``tight`` uses the ToF rays that hit the pad (1-3 of
#: 4 when the drone leans or drifts near its edge, where a missed ray finds the sea 12 m below,
#: beyond its range) and the tag alone without any, where IHRCF and CRHF need all four
SHIP_ESTIMATOR = "tight"


def ship_flight_overrides(task: str, version: int) -> dict[str, Any]:
    """The start and the controller's limits of the ship id ``task``-``version``: the ship
    configs' (in trim, the autopilots' limits) from ``SHIP_TRIM_VERSION`` on, level and at
    rest with the bench's limits (``ControllerGains``' defaults) before."""
    require_choice("task", task, tuple(SHIP_TRIM_VERSION))
    if version >= SHIP_TRIM_VERSION[task]:
        return {"start.trim_to_wind": True}
    bench = ControllerGains()
    return {
        "start.trim_to_wind": False,
        "controller.vel_i_limit_xy": bench.vel_i_limit_xy,
        "controller.max_tilt": bench.max_tilt,
    }


def _ship_ids() -> dict[str, ScenarioId]:
    """v1: the deck-frame guidance (``SHIP_TIMING_V1``), ``tight`` observed and the ship
    configs' touchdown envelope (v0: the bench's guidance, IHRCF, 10 deg drone-to-deck
    attitude); the timing task's v2: the deck's acceleration tracked and led
    (``SHIP_TIMING_V2``); v3: and a go-around with the deck lost (``SHIP_TIMING_V3``); v4:
    the scenario's lens (wide at sea states 5 and 6), the view gate from the camera
    (``SHIP_TIMING``); v5: v4 observing the helideck forecast and the drone's own state
    (``SHIP_TIMING_FORECAST``); v6: v5 started in trim with the mean wind, flying with the
    autopilots' limits (``SHIP_TRIM_VERSION``).  The landing task's v1 has the standard
    lens, its v2 the scenario's, its v3 that lens, the start in trim and those limits."""
    ids: dict[str, ScenarioId] = {}
    timing_task = "DeckLandingTiming-v0"
    for n in (3, 4, 5, 6):
        for version, timing, what in (
            (1, SHIP_TIMING_V1, ""),
            (2, SHIP_TIMING_V2, ", the deck's acceleration tracked and led"),
            (
                3,
                SHIP_TIMING_V3,
                ", the deck's acceleration led, a go-around with the deck lost, no flare",
            ),
            (4, SHIP_TIMING, ", v3's guidance through the scenario's lens (wide from ss5)"),
            (
                5,
                SHIP_TIMING_FORECAST,
                ", v4 observing the ship's helideck forecast and its own state",
            ),
            (
                6,
                SHIP_TIMING_FORECAST,
                ", v5 started in trim with the mean wind, the autopilots' limits",
            ),
        ):
            lens = STANDARD_LENS if version < 4 else {}
            ids[f"DeckLandingTiming-ShipSS{n}-v{version}"] = ScenarioId(
                timing_task,
                f"ship-ss{n}",
                f"timing task over a 30 m vessel's helideck at sea state {n}{what}",
                {
                    **landing_overrides(timing_task, SHIP_ESTIMATOR),
                    **lens,
                    **ship_flight_overrides(timing_task, version),
                },
                {"timing": timing},
            )
        for version, lens, what in (
            (1, STANDARD_LENS, ""),
            (2, {}, " through the scenario's lens (wide from ss5)"),
            (3, {}, " through the scenario's lens, started in trim, the autopilots' limits"),
        ):
            ids[f"DeckLanding-ShipSS{n}-v{version}"] = ScenarioId(
                "DeckLanding-v0",
                f"ship-ss{n}",
                f"align and descend onto a 30 m vessel's helideck at sea state {n}{what}",
                {
                    **landing_overrides("DeckLanding-v0", SHIP_ESTIMATOR),
                    **lens,
                    **ship_flight_overrides("DeckLanding-v0", version),
                },
            )
    return ids


#: THE id -> scenario table (landing runs of the shipped benches, and the high approach)
SCENARIO_IDS: dict[str, ScenarioId] = {
    "DeckLandingTiming-BenchSS3-v0": _landing(
        "DeckLandingTiming-v0", "bench-ss3", "timing task over a bench-ss3 deck"
    ),
    "DeckLandingTiming-BenchSS4-v0": _landing(
        "DeckLandingTiming-v0", "bench-ss4", "timing task over a bench-ss4 deck (trained)"
    ),
    "DeckLandingTiming-BenchSS5-v0": _landing(
        "DeckLandingTiming-v0", "bench-ss5", "timing task over a bench-ss5 deck"
    ),
    **{
        f"DeckLandingTiming-BenchSS{n}-v1": _landing(
            "DeckLandingTiming-v0",
            f"bench-ss{n}",
            f"timing task over a bench-ss{n} deck, the timed final descent",
            {"timing": BENCH_TIMING},
        )
        for n in (3, 4, 5)
    },
    **{
        f"DeckLandingTiming-BenchSS{n}-v{version}": _landing(
            "DeckLandingTiming-v0",
            f"bench-ss{n}",
            f"timing task over a bench-ss{n} deck, {what}",
            {"timing": bench_predictive_timing(version)},
        )
        for version, what in PREDICTIVE_VERSIONS.items()
        for n in (3, 4, 5)
    },
    "DeckLandingTiming-PaperStewart-v0": _landing(
        "DeckLandingTiming-v0", "paper-stewart", "timing task over the papers' Stewart bench"
    ),
    "DeckLanding-BenchSS3-v0": _landing(
        "DeckLanding-v0", "bench-ss3", "align and descend onto a bench-ss3 deck"
    ),
    "DeckLanding-BenchSS4-v0": _landing(
        "DeckLanding-v0", "bench-ss4", "align and descend onto a bench-ss4 deck"
    ),
    "DeckLanding-BenchSS5-v0": _landing(
        "DeckLanding-v0", "bench-ss5", "align and descend onto a bench-ss5 deck"
    ),
    "DeckLanding-PaperStewart-v0": _landing(
        "DeckLanding-v0", "paper-stewart", "align and descend onto the papers' Stewart bench"
    ),
    "DeckLanding-HighApproach-v0": ScenarioId(
        "DeckLanding-v0", "high-approach", "from 20 m up and 5 m off, gusty wind, sea state 3"
    ),
    **_ship_ids(),
}


def episode_step_limit(config: Any, timing: Any = None) -> int:
    """The most steps an episode of this config can take (``max_episode_steps``).

    ``DeckLanding-v0`` truncates at ``simulation.max_episode_s``; the timing task decides every
    ``steps_per_decision`` control periods until ``wait_limit_s`` forces the commit (one step).
    """
    sim = config.simulation
    if timing is None:
        return round(sim.max_episode_s * sim.env_hz)
    decision_s = timing.steps_per_decision / sim.env_hz
    return math.ceil(timing.wait_limit_s / decision_s - 1e-9) + 1


def make_scenario_env(scenario: str, **kwargs: Any) -> Any:
    """Gymnasium's entry point of every scenario id (``kwargs``: see :meth:`ScenarioId.make`)."""
    return SCENARIO_IDS[scenario].make(**kwargs)


make_scenario_env.metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 20}  # type: ignore[attr-defined]


def register_all() -> None:
    """Register the tasks and every scenario id with Gymnasium (idempotent)."""
    from gymnasium.envs.registration import register, registry

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


def _step_limit(scenario: ScenarioId) -> int:
    """``episode_step_limit`` from the scenario's simulation section alone: registration reads
    no calibration file and builds no sensor (importing the package stays cheap and safe)."""
    from types import SimpleNamespace

    from landing_env.config import SimulationConfig, read_config_data
    from landing_env.config_loading import build_dataclass, deep_merge, dotted_to_nested

    data = deep_merge(read_config_data(scenario.config), dotted_to_nested(scenario.overrides))
    sim = build_dataclass(SimulationConfig, data.get("simulation") or {}, "simulation")
    timing = None
    if scenario.task == "DeckLandingTiming-v0":
        from landing_env.envs.timing import TimingConfig

        timing = build_dataclass(TimingConfig, scenario.task_kwargs.get("timing", {}), "timing")
    return episode_step_limit(SimpleNamespace(simulation=sim), timing)


__all__ = [
    "BENCH_TIMING",
    "CONTACT_WINDOW_S",
    "FLYING_OVERRIDES",
    "PREDICTIVE_TIMING",
    "SCENARIO_IDS",
    "SCENARIO_TILT_MODEL",
    "SHIP_TIMING",
    "SHIP_TIMING_V1",
    "SHIP_TIMING_V2",
    "SHIP_TIMING_V3",
    "SHIP_TRIM_VERSION",
    "STANDARD_LENS",
    "START_OVERRIDES",
    "TASKS",
    "ScenarioId",
    "bench_predictive_timing",
    "episode_step_limit",
    "landing_overrides",
    "register_all",
    "ship_flight_overrides",
]
