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
``fused`` (or ``--routine-estimator``), ``beacon-range`` with ``beacon`` (bearing + range).
Episodes run over ``--workers`` processes.

The landing error is the SVGS paper's (003, Sec. 3, Figure 16): the commanded landing point
minus the actual one, in the deck plate's frame P (x, y), at the first touchdown.  The
commanded point is the policy's ``landing_point_d`` (x, y in the deck frame D; the origin of
D, the landing point, where the policy has none).

``--scenario svgs-100m`` (``svgs-100m-irlock``: the IR-LOCK flights' starts) flies the paper's
100 m approach onto a static pad (``configs/svgs-100m.yaml``).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.pipeline import (
    HELD_OUT_SEED,
    Evaluated,
    PolicyEvaluation,
    Watch,
    evaluate,
    held_out_seeds,
    make_episode,
)
from agents.evaluation.plots import pyplot
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.runner import EpisodeTask
from agents.evaluation.summary import columns
from agents.policies.registry import POLICIES
from agents.policies.svgs_routine import RoutineConfig, make_svgs_routine
from estimation.frames import R_PD, matrix_from_euler_zyx
from estimation.registry import ESTIMATOR_NAMES
from landing_env.errors import require_choice

#: the policies of this evaluation and the estimator each reads by default
APPROACH_POLICIES: dict[str, str] = {
    name: str(POLICIES[name].estimator) for name in ("svgs-routine", "beacon-range")
}
#: a trajectory point every this many control periods (plots only)
TRAJECTORY_STRIDE = 5
#: trajectories kept per policy for the figure
PLOTTED_EPISODES = 12
#: how svgs-routine chooses the moment of the final descent
ROUTINE_TIMINGS = ("model", "quiescent")


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


def _count(transitions: list[tuple[float, str, str]], states: tuple[str, ...]) -> int:
    return sum(1 for _, state, _ in transitions if state in states)


class ApproachWatch(Watch):
    """The approach's own columns: the start, the trajectory, the landing error at the first
    touchdown and the policy's relocations and searches (truth for the record, never for the
    policy)."""

    def __init__(self, estimator: str) -> None:
        self.estimator = estimator
        self.started_s = time.perf_counter()

    def start(self, env: Any, policy: Any, observation: Any, info: dict[str, Any]) -> None:
        self.policy = policy
        self.home = np.asarray(env.unwrapped.world.deck_home_w, dtype=float)
        self.start_w = np.asarray(info["drone"]["position_w"], dtype=float) - self.home
        self.trajectory = [(0.0, *(float(v) for v in self.start_w))]
        self.commanded_d = np.asarray(getattr(policy, "landing_point_d", (0.0, 0.0)), float)
        self.error = np.full(2, math.nan)
        self.steps = 0

    def step(self, observation: Any, reward: float, done: bool, info: dict[str, Any]) -> None:
        self.steps += 1
        if "touchdown" in info and not np.isfinite(self.error).all():
            self.error = landing_error_p(
                self.commanded_d,
                info["drone"]["position_w"],
                info["deck"]["position_w"],
                info["deck"]["euler_w"],
            )
        if self.steps % TRAJECTORY_STRIDE == 0 or done:
            rel = np.asarray(info["drone"]["position_w"], dtype=float) - self.home
            self.trajectory.append((float(info["time_s"]), *(float(v) for v in rel)))

    def finish(self, record: EpisodeRecord) -> None:
        transitions = getattr(self.policy, "transitions", [])
        record.estimator = self.estimator
        record.start_height_m = float(self.start_w[2])
        record.start_offset_m = float(math.hypot(self.start_w[0], self.start_w[1]))
        record.final_state = str(getattr(getattr(self.policy, "state", ""), "value", ""))
        record.relocations = _count(transitions, ("relocate_xy",))
        # the baseline counts its PX4 searches; the routine's re-entered scans are transitions
        record.searches = int(getattr(self.policy, "searches", _count(transitions, ("scan",))))
        record.trajectory = self.trajectory
        record.landing_error_x_m = float(self.error[0])
        record.landing_error_y_m = float(self.error[1])
        record.landing_error_m = float(np.hypot(*self.error))
        record.wall_time_s = time.perf_counter() - self.started_s


def plot_trajectories(results: dict[str, list[EpisodeRecord]], path: Path, title: str) -> None:
    """Top view (x, y from the deck's home) and height against time of the first episodes."""
    plt = pyplot()

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


class _ApproachEvaluation(PolicyEvaluation):
    """The approach: the options are the estimator, the overrides and ``routine_timing``."""

    def validate(self, task: EpisodeTask) -> None:
        require_choice("policy", task.policy, tuple(APPROACH_POLICIES))
        require_choice("routine_timing", task.options["routine_timing"], ROUTINE_TIMINGS)
        super().validate(task)

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        o = task.options
        env, policy = make_episode(
            task.policy,
            task.scenario,
            estimator=o["estimator"],
            extra_overrides=o["extra_overrides"],
        )
        if task.policy == "svgs-routine" and o["routine_timing"] == "quiescent":
            # the registry's routine commits through the timing model; this one without it
            policy = make_svgs_routine(env, RoutineConfig(use_timing_model=False))
        return env, policy


#: the runner's handle on this evaluation (``EVALUATIONS["approach"]``)
APPROACH_EVALUATION = _ApproachEvaluation(
    name="approach",
    heading="Approach",
    columns=columns(
        "policy", "estimator", "episodes", "success (95% CI)", "offset mean / p95 (m)",
        "landing error mean / p95 (m)", "time to land mean / p95 (s)", "v_n mean (m/s)",
        "deck tilt mean (deg)", "relocations / searches", "outcomes",
    ),
    plot=lambda evaluated, path, title: plot_trajectories(evaluated.results, path, title),
    watch=lambda task: ApproachWatch(task.options["estimator"]),
)  # fmt: skip


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
) -> Evaluated:
    """Evaluate ``policies`` on ``scenario``; write the table, CSV, JSON and figure.
    ``routine_estimator_name``: svgs-routine's estimator (None: its own, ``fused``)."""
    seeds = held_out_seeds(first_seed, episodes)
    estimators = dict(APPROACH_POLICIES)
    if routine_estimator_name:
        require_choice("routine_estimator", routine_estimator_name, ESTIMATOR_NAMES)
        estimators["svgs-routine"] = routine_estimator_name
    # the other estimators are not run
    options = {"extra_overrides": {"estimation.compare": [], **(overrides or {})}}
    tasks = [
        EpisodeTask(
            "approach",
            name,
            scenario,
            {**options, "estimator": estimators.get(name), "routine_timing": routine_timing},
        )
        for name in policies
    ]
    evaluated = evaluate(
        APPROACH_EVALUATION, tasks, seeds, out_dir, workers, progress, address, resume
    )
    if out_dir is not None:
        title = (
            f"{scenario}: {episodes} episodes per policy (seeds {first_seed}–"
            f"{first_seed + episodes - 1})"
        )
        if "svgs-routine" in evaluated.results:
            title += f"; svgs-routine commits through the {routine_timing} timing"
        wall = sum(e.wall_time_s for r in evaluated.results.values() for e in r)
        settings = {
            "scenario": scenario,
            "first_seed": first_seed,
            "overrides": overrides or {},
            "routine_timing": routine_timing,
        }
        notes = f"Simulation wall time over all episodes: {wall:.0f} s (summed over workers)"
        evaluated.write(out_dir, title, settings, command, notes)
    return evaluated
