"""The high-approach evaluation: ``deck-landing evaluate approach``.

``deck-landing evaluate approach --policy svgs-routine beacon-range --scenario high-approach
--episodes N`` flies each policy for N episodes (seeds ``--seed``, ``--seed + 1``, ...) from
the scenario's start (``configs/high-approach.yaml``: 20 m up, 5 m off, sea state 3, gusty
wind) and writes to ``--out`` (``results/approach/``): a Markdown table per policy (success
rate with its 95% Wilson interval, offset from the deck centre at touchdown mean and 95th
percentile, the SVGS paper's landing error, time to land, touchdown speed, outcomes), a CSV
of the episodes, a JSON summary and a PNG of trajectories (top view and height against time,
truth, for the reader only).

Each policy flies with its own estimator in the observation: ``svgs-routine`` with
``fused`` when the environment offers it (else ``atda``; ``--routine-estimator``),
``beacon-range`` with ``beacon`` (bearing + range).  Episodes run over ``--workers``
processes.

The landing error is the SVGS paper's (003, Sec. 3, Figure 16): the commanded landing point
minus the actual one, in the deck plate's frame P (x, y), at the first touchdown.  The
commanded point is the policy's ``landing_point_d`` (x, y in the deck frame D; the origin of
D, the landing point, where the policy has none).

``--scenario svgs-100m`` (``svgs-100m-irlock``: the IR-LOCK flights' starts) flies the paper's
100 m approach onto a static pad (``configs/svgs-100m.yaml``).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import landing_env  # noqa: F401  (registers the environments)
from agents.beacon_range import make_beacon_range
from agents.evaluation.landing import HELD_OUT_SEED
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.runner import (
    EpisodeTask,
    RunResult,
    SeedFailure,
    batch_session,
    for_each_seed,
    run_episodes,
    split_runs,
)
from agents.evaluation.summary import (
    Column,
    counts_cell,
    finite_mean,
    finite_p95,
    success_cell,
    success_fields,
    write_summary_files,
)
from agents.evaluation.summary import markdown_table as summary_table
from agents.policy_registry import POLICIES
from agents.svgs_routine import RoutineConfig, make_svgs_routine
from estimation.frames import R_PD, matrix_from_euler_zyx
from estimation.registry import ESTIMATOR_NAMES
from landing_env.config import load_config
from landing_env.errors import ConfigError, require_choice
from landing_env.scenarios import APPROACH_SCENARIOS, LANDING_TASK, scenario_id, step_limit_on

#: the policies of this evaluation and the estimator each reads by default
APPROACH_POLICIES: dict[str, str] = {
    name: str(POLICIES[name].estimator) for name in ("svgs-routine", "beacon-range")
}
#: the routine's estimator when ``fused`` is not (yet) available
ROUTINE_FALLBACK_ESTIMATOR = "atda"
#: a trajectory point every this many control periods (plots only)
TRAJECTORY_STRIDE = 5
#: trajectories kept per policy for the figure
PLOTTED_EPISODES = 12


#: how svgs-routine chooses the moment of the final descent
ROUTINE_TIMINGS = ("model", "quiescent")


def routine_estimator(requested: str | None = None) -> str:
    """The estimator the SVGS routine flies with: ``requested``, else ``fused`` if the
    environment knows it, else ``atda``."""

    if requested:
        require_choice("routine_estimator", requested, ESTIMATOR_NAMES)
        return requested
    return "fused" if "fused" in ESTIMATOR_NAMES else ROUTINE_FALLBACK_ESTIMATOR


@dataclass
class ApproachEpisode(EpisodeRecord):
    """One approach episode: the shared record (:mod:`agents.evaluation.records`; the
    touchdown offset is ``lateral_offset_m``) and the approach's own columns."""

    estimator: str = ""
    #: start: height above the deck's home surface and horizontal offset, metres
    start_height_m: float = math.nan
    start_offset_m: float = math.nan
    #: the policy's last state; relocations (svgs-routine's Algorithm 4); searches
    #: (beacon-range: PX4 searches flown; svgs-routine: scans re-entered after a relocation)
    final_state: str = ""
    relocations: int = 0
    searches: int = 0
    wall_time_s: float = math.nan
    #: the SVGS paper's landing error: commanded minus actual landing point at the first
    #: touchdown, x and y in the deck plate's frame P and its length, metres
    landing_error_x_m: float = math.nan
    landing_error_y_m: float = math.nan
    landing_error_m: float = math.nan
    #: (t, x, y, z) of the drone relative to the deck's home, every TRAJECTORY_STRIDE periods
    trajectory: list[tuple[float, float, float, float]] = field(default_factory=list, repr=False)


def approach_id(scenario: str) -> str:
    """The registered id a scenario of the approach flies: its own (``high-approach``), the
    one it shares (``svgs-100m``: the high approach on the paper's config), or the bare task
    for a config given by path."""
    if scenario in APPROACH_SCENARIOS:
        return scenario_id(scenario, LANDING_TASK)
    return LANDING_TASK


def make_env_and_policy(
    policy_name: str,
    scenario: str,
    estimator: str,
    overrides: dict[str, Any] | None = None,
    routine_timing: str = "model",
) -> tuple[Any, Any]:
    """``DeckLanding-v2`` on ``scenario`` with ``estimator`` observed, and the policy.

    ``routine_timing`` (svgs-routine only): ``"model"`` commits through the shipped timing
    policy where it is installed, ``"quiescent"`` through the calm-window heuristic.
    """
    import gymnasium as gym

    require_choice("policy", policy_name, tuple(APPROACH_POLICIES))
    require_choice("routine_timing", routine_timing, ROUTINE_TIMINGS)
    settings = {
        "estimation.observed": estimator,
        "estimation.compare": [],
        **(overrides or {}),
    }
    env_id = approach_id(scenario)
    limit = step_limit_on(env_id, scenario, settings) if env_id != LANDING_TASK else None
    env = gym.make(env_id, config=scenario, overrides=settings, max_episode_steps=limit)
    try:
        if policy_name == "svgs-routine":
            config = RoutineConfig(use_timing_model=routine_timing == "model")
            policy = make_svgs_routine(env, config)
        else:
            policy = make_beacon_range(env)
    except Exception:
        env.close()
        raise
    return env, policy


def _count(transitions: list[tuple[float, str, str]], states: tuple[str, ...]) -> int:
    return sum(1 for _, state, _ in transitions if state in states)


def landing_error_p(
    commanded_d: np.ndarray,
    drone_position_w: np.ndarray,
    deck_position_w: np.ndarray,
    deck_euler_w: np.ndarray,
) -> np.ndarray:
    """The SVGS paper's landing error: the commanded landing point (x, y in the deck frame D)
    minus the drone's position, as x, y in the deck plate's frame P (metres)."""
    r_wp = matrix_from_euler_zyx(*(float(v) for v in deck_euler_w))
    commanded = np.array([float(commanded_d[0]), float(commanded_d[1]), 0.0])
    commanded_p = R_PD @ commanded
    actual_p = r_wp.T @ (np.asarray(drone_position_w, float) - np.asarray(deck_position_w, float))
    return (commanded_p - actual_p)[:2]


def run_episode(
    env: Any, policy: Any, seed: int, policy_name: str, estimator: str, scenario: str
) -> ApproachEpisode:
    """One episode to its end; truth from ``info`` only for the record, never to the policy."""
    import time

    start_wall = time.perf_counter()
    observation, info = env.reset(seed=seed)
    policy.reset()
    home = np.asarray(env.unwrapped.world.deck_home_w, dtype=float)
    start = np.asarray(info["drone"]["position_w"], dtype=float) - home
    trajectory = [(0.0, *(float(v) for v in start))]
    commanded_d = np.asarray(getattr(policy, "landing_point_d", (0.0, 0.0)), dtype=float)
    error = np.full(2, math.nan)
    step = 0
    while True:
        observation, _, terminated, truncated, info = env.step(policy(observation))
        step += 1
        if "touchdown" in info and not np.isfinite(error).all():
            error = landing_error_p(
                commanded_d,
                info["drone"]["position_w"],
                info["deck"]["position_w"],
                info["deck"]["euler_w"],
            )
        if step % TRAJECTORY_STRIDE == 0 or terminated or truncated:
            rel = np.asarray(info["drone"]["position_w"], dtype=float) - home
            trajectory.append((float(info["time_s"]), *(float(v) for v in rel)))
        if terminated or truncated:
            break
    transitions = getattr(policy, "transitions", [])
    episode = ApproachEpisode(
        policy=policy_name,
        estimator=estimator,
        scenario=scenario,
        seed=seed,
        outcome=info["outcome"],
        success=info["outcome"] == "success",
        start_height_m=float(start[2]),
        start_offset_m=float(math.hypot(start[0], start[1])),
        final_state=str(getattr(getattr(policy, "state", ""), "value", "")),
        relocations=_count(transitions, ("relocate_xy",)),
        # the baseline counts its PX4 searches; the routine's re-entered scans are transitions
        searches=int(getattr(policy, "searches", _count(transitions, ("scan",)))),
        trajectory=trajectory,
        landing_error_x_m=float(error[0]),
        landing_error_y_m=float(error[1]),
        landing_error_m=float(np.hypot(*error)),
    )
    episode.record_end(info)
    episode.wall_time_s = time.perf_counter() - start_wall
    return episode


class _ApproachEvaluation:
    """``evaluate approach`` for the runner (:mod:`agents.evaluation.runner`)."""

    record_type = ApproachEpisode

    def validate(self, task: EpisodeTask) -> None:

        o = task.options
        require_choice("policy", task.policy, tuple(APPROACH_POLICIES))
        require_choice("routine_timing", o.get("routine_timing", "model"), ROUTINE_TIMINGS)
        load_config(
            task.scenario,
            {
                "estimation.observed": o["estimator"],
                "estimation.compare": [],
                **(o.get("overrides") or {}),
            },
        )

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        o = task.options
        return make_env_and_policy(
            task.policy,
            task.scenario,
            o["estimator"],
            o.get("overrides"),
            o.get("routine_timing", "model"),
        )

    def run_episode(self, env: Any, policy: Any, seed: int, task: EpisodeTask) -> ApproachEpisode:
        return run_episode(env, policy, seed, task.policy, task.options["estimator"], task.scenario)


#: the runner's handle on this evaluation (``EVALUATIONS["approach"]``)
APPROACH_EVALUATION = _ApproachEvaluation()


def evaluate_policy(
    policy_name: str,
    scenario: str,
    estimator: str,
    episodes: int,
    first_seed: int = HELD_OUT_SEED,
    workers: int = 2,
    progress: bool = True,
    overrides: dict[str, Any] | None = None,
    routine_timing: str = "model",
    address: str | None = None,
    results_path: Path | None = None,
    resume: bool = False,
) -> RunResult:
    """``episodes`` episodes of one policy over ``workers`` workers (Ray beyond one)."""
    task = EpisodeTask(
        "approach",
        policy_name,
        scenario,
        {"estimator": estimator, "overrides": overrides, "routine_timing": routine_timing},
    )
    return run_episodes(
        task,
        for_each_seed(first_seed, episodes),
        workers=workers,
        address=address,
        results_path=results_path,
        resume=resume,
        progress=progress,
        desc=f"{policy_name} ({estimator})",
    )


# ------------------------------------------------------------------------------ summaries
@dataclass
class ApproachSummary:
    """One policy's figures over its episodes (touchdown metrics over those that touched down)."""

    policy: str
    estimator: str
    episodes: int
    successes: int
    success_rate: float
    success_ci_low: float
    success_ci_high: float
    offset_mean_m: float
    offset_p95_m: float
    landing_error_mean_m: float
    landing_error_p95_m: float
    time_to_land_mean_s: float
    time_to_land_p95_s: float
    normal_speed_mean: float
    deck_tilt_mean_deg: float
    relocations: int
    searches: int
    outcomes: dict[str, int] = field(default_factory=dict)


def summarise(episodes: list[ApproachEpisode]) -> ApproachSummary:
    """The table's figures for one policy's episodes."""

    def column(name: str) -> list[float]:
        return [getattr(e, name) for e in episodes]

    return ApproachSummary(
        policy=episodes[0].policy if episodes else "",
        estimator=episodes[0].estimator if episodes else "",
        **success_fields(episodes),
        offset_mean_m=finite_mean(column("lateral_offset_m")),
        offset_p95_m=finite_p95(column("lateral_offset_m")),
        landing_error_mean_m=finite_mean(column("landing_error_m")),
        landing_error_p95_m=finite_p95(column("landing_error_m")),
        time_to_land_mean_s=finite_mean(column("time_to_land_s")),
        time_to_land_p95_s=finite_p95(column("time_to_land_s")),
        normal_speed_mean=finite_mean(column("relative_normal_speed")),
        deck_tilt_mean_deg=finite_mean(column("deck_tilt_deg")),
        relocations=sum(e.relocations for e in episodes),
        searches=sum(e.searches for e in episodes),
        outcomes=dict(Counter(e.outcome for e in episodes)),
    )


#: the columns of the approach table (:func:`agents.evaluation.summary.markdown_table`)
COLUMNS: tuple[Column, ...] = (
    Column("policy", lambda s: s.policy),
    Column("estimator", lambda s: s.estimator),
    Column("episodes", lambda s: str(s.episodes)),
    Column("success (95% CI)", success_cell),
    Column("offset mean / p95 (m)", lambda s: f"{s.offset_mean_m:.3f} / {s.offset_p95_m:.3f}"),
    Column(
        "landing error mean / p95 (m)",
        lambda s: f"{s.landing_error_mean_m:.3f} / {s.landing_error_p95_m:.3f}",
    ),
    Column(
        "time to land mean / p95 (s)",
        lambda s: f"{s.time_to_land_mean_s:.1f} / {s.time_to_land_p95_s:.1f}",
    ),
    Column("v_n mean (m/s)", lambda s: f"{s.normal_speed_mean:.3f}"),
    Column("deck tilt mean (deg)", lambda s: f"{s.deck_tilt_mean_deg:.2f}"),
    Column("relocations / searches", lambda s: f"{s.relocations} / {s.searches}"),
    Column("outcomes", lambda s: counts_cell(s.outcomes)),
)
TABLE_HEADER = tuple(c.header for c in COLUMNS)


def markdown_table(summaries: list[ApproachSummary]) -> str:
    """One row per policy."""
    return summary_table(summaries, COLUMNS)


def plot_trajectories(results: dict[str, list[ApproachEpisode]], path: Path, title: str) -> None:
    """Top view (x, y from the deck's home) and height against time of the first episodes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_top, ax_h) = plt.subplots(1, 2, figsize=(13, 5.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for index, (name, episodes) in enumerate(results.items()):
        colour = colours[index % len(colours)]
        for k, episode in enumerate(episodes[:PLOTTED_EPISODES]):
            track = np.asarray(episode.trajectory, dtype=float)
            if track.size == 0:
                continue
            label = name if k == 0 else None
            ax_top.plot(track[:, 1], track[:, 2], color=colour, alpha=0.6, lw=1, label=label)
            ax_top.plot(track[0, 1], track[0, 2], "o", color=colour, ms=4)
            marker = "x" if episode.success else "s"
            ax_top.plot(track[-1, 1], track[-1, 2], marker, color=colour, ms=6)
            ax_h.plot(track[:, 0], track[:, 3], color=colour, alpha=0.6, lw=1, label=label)
    ax_top.plot(0.0, 0.0, "k+", ms=14, mew=2, label="deck centre")
    ax_top.set(xlabel="x (m)", ylabel="y (m)", title="Top view (o start, x success, s other)")
    ax_top.set_aspect("equal", adjustable="datalim")
    ax_top.legend(loc="best", fontsize=8)
    ax_h.set(xlabel="time (s)", ylabel="height above the deck's home (m)", title="Height")
    ax_h.legend(loc="best", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


@dataclass
class ApproachEvaluation:
    """Every policy on the scenario, and the files written."""

    scenario: str
    summaries: list[ApproachSummary]
    results: dict[str, list[ApproachEpisode]]
    files: list[Path]
    #: seeds whose worker crashed, per policy (the other seeds' results are kept)
    failures: dict[str, list[SeedFailure]] = field(default_factory=dict)


def evaluate_approach(
    policies: list[str],
    scenario: str = "high-approach",
    episodes: int = 20,
    out_dir: Path | None = Path("results/approach"),
    first_seed: int = HELD_OUT_SEED,
    routine_estimator_name: str | None = None,
    workers: int = 2,
    progress: bool = True,
    overrides: dict[str, Any] | None = None,
    command: str = "",
    routine_timing: str = "model",
    address: str | None = None,
    resume: bool = False,
) -> ApproachEvaluation:
    """Evaluate ``policies`` on ``scenario``; write the table, CSV, JSON and figure."""
    if episodes < 1:
        raise ConfigError("episodes", f"{episodes} is out of range; allowed [1, inf]")
    for name in policies:
        require_choice("policy", name, tuple(APPROACH_POLICIES))
    runs: dict[str, RunResult] = {}
    stem = f"approach_{Path(scenario).stem}"
    estimators = {
        name: routine_estimator(routine_estimator_name)
        if name == "svgs-routine"
        else APPROACH_POLICIES[name]
        for name in policies
    }
    for name, estimator in estimators.items():  # a bad config fails before Ray starts
        APPROACH_EVALUATION.validate(
            EpisodeTask(
                "approach",
                name,
                scenario,
                {"estimator": estimator, "overrides": overrides, "routine_timing": routine_timing},
            )
        )
    with batch_session(workers, address):
        for name in policies:
            estimator = estimators[name]
            run = evaluate_policy(
                name,
                scenario,
                estimator,
                episodes,
                first_seed,
                workers,
                progress,
                overrides,
                routine_timing,
                address,
                out_dir / f"{stem}_{name}.jsonl" if out_dir is not None else None,
                resume,
            )
            runs[name] = run
    results, failures = split_runs(runs)
    summaries = [summarise(r) for r in results.values()]
    files: list[Path] = []
    if out_dir is not None:
        title = (
            f"{scenario}: {episodes} episodes per policy (seeds {first_seed}–"
            f"{first_seed + episodes - 1})"
        )
        if "svgs-routine" in results:
            title += f"; svgs-routine commits through the {routine_timing} timing"
        wall = sum(e.wall_time_s for r in results.values() for e in r)
        files = write_summary_files(
            out_dir,
            stem,
            heading=f"Approach: {scenario}",
            title=title,
            table=markdown_table(summaries),
            summaries=summaries,
            results=results,
            failures=failures,
            settings={
                "scenario": scenario,
                "first_seed": first_seed,
                "overrides": overrides or {},
                "routine_timing": routine_timing,
            },
            command=command,
            notes=f"Simulation wall time over all episodes: {wall:.0f} s (summed over workers)",
            csv_exclude=("trajectory",),
        )
        figure = out_dir / f"{stem}.png"
        plot_trajectories(results, figure, title)
        files.append(figure)
    return ApproachEvaluation(scenario, summaries, results, files, failures)
