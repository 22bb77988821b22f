"""One seeded episode of DeckLanding-v2 under the align-descend policy: summary, video, plot."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import imageio.v2 as imageio
import numpy as np
from rich.console import Console
from rich.table import Table
from tqdm import tqdm

import landing_env  # noqa: F401  (registers the environments)
from agents.evaluation.pipeline import (
    HELD_OUT_SEED,
    Watch,
    make_episode,
    run_episode,
)
from agents.evaluation.plots import pyplot, save_figure
from agents.evaluation.records import EpisodeRecord
from agents.policies.registry import default_policy
from landing_env.errors import ConfigError, require_choice
from landing_env.scenarios import LANDING_TASK
from landing_env.sensors.camera_config import CAMERA_MODES


@dataclass
class EpisodeLog(Watch):
    """Per-step record of an episode, for plots and summaries (a :class:`Watch` of
    :func:`agents.evaluation.pipeline.run_episode`); rendered frames go to ``frames``."""

    frames: list[np.ndarray] | None = field(default=None, repr=False)
    time: list[float] = field(default_factory=list)
    drone: list[np.ndarray] = field(default_factory=list)
    deck: list[np.ndarray] = field(default_factory=list)
    pose_true: list[np.ndarray] = field(default_factory=list)
    pose_observed: list[np.ndarray] = field(default_factory=list)
    pose_valid: list[bool] = field(default_factory=list)
    #: every estimator's pose per step (NaN when invalid), for the error summary
    estimates: dict[str, list[np.ndarray]] = field(default_factory=dict)
    total_reward: float = 0.0
    final_info: dict[str, Any] = field(default_factory=dict)

    def start(self, env: Any, policy: Any, observation: Any, info: dict[str, Any]) -> None:
        self.env = env
        self.bar = tqdm(total=env.unwrapped.max_steps, desc="episode", unit="step", leave=False)
        self.record(observation, info)

    def step(self, observation: Any, reward: float, done: bool, info: dict[str, Any]) -> None:
        self.total_reward += reward
        self.record(observation, info)
        self.bar.update()
        self.final_info = info

    def finish(self, record: EpisodeRecord) -> None:
        self.bar.close()

    def record(self, observation: dict, info: dict) -> None:
        self.time.append(info["time_s"])
        self.drone.append(info["drone"]["position_w"])
        self.deck.append(info["deck"]["position_w"])
        self.pose_true.append(info["deck_pose_true"])
        self.pose_observed.append(observation["deck_pose"].astype(float))
        self.pose_valid.append(bool(observation["deck_pose_valid"][0]))
        for name, estimate in info["estimates"].items():
            pose = np.asarray(estimate["pose"], dtype=float)
            if not estimate["valid"]:
                pose = np.full(6, np.nan)  # info holds zeros for an invalid estimate
            self.estimates.setdefault(name, []).append(pose)
        if self.frames is not None:
            self.frames.append(self.env.render())


def plot_trajectory(log: EpisodeLog, path: Path) -> None:
    """Drone and deck heights against time, and the drone's track over the deck."""
    t = np.asarray(log.time)
    drone = np.asarray(log.drone)
    deck = np.asarray(log.deck)
    fig, axes = pyplot().subplots(1, 3, figsize=(14, 4))
    axes[0].plot(t, drone[:, 2], label="drone centre")
    axes[0].plot(t, deck[:, 2], label="deck surface")
    axes[0].set(xlabel="time (s)", ylabel="z (m)", title="Height")
    axes[0].legend()
    rel = drone - deck
    axes[1].plot(t, rel[:, 0], label="x")
    axes[1].plot(t, rel[:, 1], label="y")
    axes[1].set(xlabel="time (s)", ylabel="drone - deck (m)", title="Horizontal offset")
    axes[1].legend()
    true = np.asarray(log.pose_true)
    observed = np.asarray(log.pose_observed)
    valid = np.asarray(log.pose_valid)
    axes[2].plot(t, true[:, 2], "k-", label="true tag z in camera")
    axes[2].plot(t[valid], observed[valid, 2], ".", ms=3, label="observed")
    axes[2].set(xlabel="time (s)", ylabel="z_C (m)", title="Deck pose seen by the policy")
    axes[2].legend()
    save_figure(fig, path)


def summarise(log: EpisodeLog, console: Console) -> None:
    info = log.final_info
    table = Table(title=f"{LANDING_TASK} episode")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("outcome", info["outcome"])
    table.add_row("episode time (s)", f"{info['time_s']:.2f}")
    table.add_row("return", f"{log.total_reward:.2f}")
    touchdown = info.get("touchdown")
    if touchdown:
        table.add_row("relative normal speed (m/s)", f"{touchdown['relative_normal_speed']:.3f}")
        table.add_row(
            "relative tangential speed (m/s)", f"{touchdown['relative_tangential_speed']:.3f}"
        )
        table.add_row("deck tilt (deg)", f"{touchdown['deck_tilt_deg']:.2f}")
        table.add_row("drone-to-deck attitude (deg)", f"{touchdown['relative_attitude_deg']:.2f}")
        table.add_row("lateral offset (m)", f"{touchdown['lateral_offset_m']:.3f}")
        table.add_row("all feet on deck", str(touchdown["all_feet_touched"]))
        table.add_row("on deck 1 s later", str(touchdown["on_deck_after_settle"]))
        failed = ", ".join(touchdown["failed_checks"]) or "none"
        table.add_row("failed checks", failed)
    if "crash_contact" in info:
        table.add_row("crash contact", info["crash_contact"])
    valid = np.asarray(log.pose_valid)
    table.add_row("steps with a valid deck estimate", f"{valid.sum()}/{valid.size}")
    console.print(table)
    errors = Table(title="Deck-pose estimates against the truth over the episode")
    for column in ("estimator", "valid steps", "MAE x, y, z (mm)", "MAE roll, pitch, yaw (deg)"):
        errors.add_column(column, justify="right")
    truth = np.asarray(log.pose_true)
    for name, poses in log.estimates.items():
        poses = np.asarray(poses)
        ok = np.all(np.isfinite(poses), axis=1)
        if not ok.any():
            errors.add_row(name, f"0/{ok.size}", "-", "-")
            continue
        err = np.abs(poses[ok] - truth[ok])
        err[:, 3:] = np.degrees(
            np.abs((poses[ok, 3:] - truth[ok, 3:] + np.pi) % (2 * np.pi) - np.pi)
        )
        mae = err.mean(axis=0)
        errors.add_row(
            name,
            f"{ok.sum()}/{ok.size}",
            ", ".join(f"{1000 * v:.1f}" for v in mae[:3]),
            ", ".join(f"{v:.2f}" for v in mae[3:]),
        )
    console.print(errors)


def run_demo(
    config: str = "default",
    seed: int = 0,
    out_dir: Path = Path("results/demo"),
    timing: bool = True,
    timing_seed: int = 4,
    episodes: int = 1,
    camera_mode: str = "render",
    record: Path | None = None,
    overrides: dict[str, Any] | None = None,
) -> EpisodeLog:
    """The `make demo` job: ``episodes`` seeded episodes (seeds ``seed``, ``seed + 1``, ...)
    with the camera rendered and the tag detected (``camera_mode="project"`` projects it,
    faster), then (``timing``) the trained timing policy landing on a sea-state deck.  The
    video and plot show the first episode; returns its log.

    ``timing_seed`` 4 (held-out seed 1 000 004) is an episode on which committing at once meets
    a 6.7° deck tilt (a hard landing): the one that shows the policy waiting.
    ``record``: an MCAP file for the first episode (:class:`agents.io.record.McapRecorder`);
    ``overrides``: dotted config overrides.
    """
    if episodes < 1:
        raise ConfigError("episodes", f"{episodes} is out of range; allowed [1, inf]")
    require_choice("mode", camera_mode, CAMERA_MODES)
    console = Console()
    out_dir.mkdir(parents=True, exist_ok=True)
    # the demo renders the camera and detects the tag for real (training uses `project`)
    overrides = dict(overrides or {})
    overrides.setdefault("camera.mode", camera_mode)
    # run the other estimators beside the observed one, for the record in info["estimates"]
    overrides.setdefault("estimation.compare", ["atda", "crhf"])
    env, policy = make_episode(
        "align-descend", config, render_mode="rgb_array", extra_overrides=overrides
    )
    if record is not None:
        # mcap and rosbags: the optional extra ``io``
        from agents.io.record import McapRecorder

        env = McapRecorder(env, record)
    frames: list[np.ndarray] = []
    logs = [EpisodeLog(frames)] + [EpisodeLog() for _ in range(1, episodes)]
    try:
        for offset, log in enumerate(logs):
            run_episode(env, policy, seed + offset, "align-descend", config, log)
    finally:
        env.close()
    for offset, log in enumerate(logs):
        if episodes > 1:
            console.print(f"[bold]seed {seed + offset}[/bold]")
        summarise(log, console)
    first = logs[0]
    video = out_dir / "camera.mp4"
    imageio.mimsave(video, frames, fps=env.unwrapped.config.simulation.env_hz, macro_block_size=1)
    plot = out_dir / "trajectory.png"
    plot_trajectory(first, plot)
    console.print(f"camera video (seed {seed}): {video}\ntrajectory plot: {plot}")
    if timing:
        run_timing_demo(seed=timing_seed, out_dir=out_dir)
    return first


# ---------------------------------------------------------------------------------------------
# Part 2: the trained landing-timing policy on a sea-state deck (see agents/policies/timing.py)
@dataclass
class TimingDemoLog(Watch):
    """Every control period of a DeckLandingTiming-v0 episode, and its end (a :class:`Watch`
    of the environment's per-period records, ``record_periods``)."""

    periods: list[dict[str, Any]] = field(default_factory=list)
    commit_time_s: float = float("nan")
    final_info: dict[str, Any] = field(default_factory=dict)
    frames: list[np.ndarray] = field(default_factory=list, repr=False)

    def start(self, env: Any, policy: Any, observation: Any, info: dict[str, Any]) -> None:
        self.base = env.unwrapped
        self.periods += self.base.periods_of_last_step
        self.frames += self.base.frames_of_last_step

    def step(self, observation: Any, reward: float, done: bool, info: dict[str, Any]) -> None:
        base = self.base
        if info["committed"] and np.isnan(self.commit_time_s):
            first = next(p for p in base.periods_of_last_step if p["committed"])
            self.commit_time_s = first["time_s"] - base.env_dt
        self.periods += base.periods_of_last_step
        self.frames += base.frames_of_last_step
        self.final_info = info


def plot_timing(log: TimingDemoLog, path: Path, limit_deg: float) -> None:
    """Deck tilt (true and as estimated) and the drone's height over the deck, with the commit."""
    t = np.array([p["time_s"] for p in log.periods])
    deck = np.array([p["deck_euler_w"] for p in log.periods])
    true_tilt = np.degrees(np.arccos(np.cos(deck[:, 0]) * np.cos(deck[:, 1])))
    observed = np.array([p["deck_pose_observed"] for p in log.periods])
    valid = np.array([p["deck_pose_valid"] for p in log.periods])
    seen_tilt = np.degrees(np.arccos(np.cos(observed[:, 3]) * np.cos(observed[:, 4])))
    height = np.array([p["drone_position_w"][2] - p["deck_position_w"][2] for p in log.periods])
    fig, (ax_tilt, ax_height) = pyplot().subplots(2, 1, figsize=(10, 6), sharex=True)
    ax_tilt.plot(t, true_tilt, "k-", label="deck tilt (truth)")
    ax_tilt.plot(t[valid], seen_tilt[valid], ".", ms=3, label="deck relative to camera (observed)")
    ax_tilt.axhline(limit_deg, color="r", linestyle="--", linewidth=1, label="touchdown limit")
    ax_height.plot(t, height, label="drone centre above deck centre")
    touchdown = log.final_info.get("touchdown")
    for ax in (ax_tilt, ax_height):
        ax.axvline(log.commit_time_s, color="g", linewidth=1.2, label="commit")
        if touchdown:
            ax.axvline(touchdown["time_s"], color="m", linewidth=1.2, label="touchdown")
    ax_tilt.set(ylabel="tilt (deg)", title="Waiting for a calm deck, then the final descent")
    ax_height.set(xlabel="time (s)", ylabel="height (m)")
    ax_tilt.legend(fontsize=8)
    ax_height.legend(fontsize=8)
    save_figure(fig, path)


def run_timing_demo(
    seed: int = 0,
    out_dir: Path = Path("results/demo"),
    scenario: str = "bench-ss4",
    policy_name: str | None = None,
) -> TimingDemoLog | None:
    """`make demo`, part 2: the scenario's recommended timing policy waits over a sea-state
    deck and lands.

    The camera is rendered and the tag detected for real.  ``policy_name`` None picks the
    scenario's recommended policy (:func:`agents.policies.registry.default_policy`: ``predictive``
    on the bench) with its own estimator and settings; ``deck-landing demo --sensors
    realistic`` flies it under realistic sensing.  Writes ``timing_camera.mp4`` and
    ``timing_trajectory.png``.  The seed is offset into the held-out range, so that the
    episode is not one a policy was fitted on.
    """

    console = Console()
    out_dir.mkdir(parents=True, exist_ok=True)
    if policy_name is None:
        policy_name = default_policy(scenario)
    env, policy = make_episode(policy_name, scenario, camera_mode="render", render_mode="rgb_array")
    base = env.unwrapped
    base.record_periods = True
    log = TimingDemoLog()
    try:
        run_episode(env, policy, HELD_OUT_SEED + seed, policy_name, scenario, log)
    finally:
        env.close()
    info = log.final_info
    table = Table(title=f"{env.spec.id if env.spec else scenario}: {policy_name}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("outcome", info["outcome"])
    table.add_row("waited before committing (s)", f"{info['wait_s']:.2f}")
    table.add_row("forced by the wait limit", str(info["forced_commit"]))
    table.add_row("final descent (s)", f"{info['descent_s']:.2f}")
    touchdown = info.get("touchdown")
    if touchdown:
        table.add_row("time to land (s)", f"{touchdown['time_s']:.2f}")
        table.add_row("relative normal speed (m/s)", f"{touchdown['relative_normal_speed']:.3f}")
        table.add_row("deck tilt (deg)", f"{touchdown['deck_tilt_deg']:.2f}")
        table.add_row("lateral offset (m)", f"{touchdown['lateral_offset_m']:.3f}")
        table.add_row("failed checks", ", ".join(touchdown["failed_checks"]) or "none")
    console.print(table)
    video = out_dir / "timing_camera.mp4"
    imageio.mimsave(video, log.frames, fps=base.config.simulation.env_hz, macro_block_size=1)
    plot = out_dir / "timing_trajectory.png"
    plot_timing(log, plot, base.config.touchdown.max_deck_tilt_deg)
    console.print(f"timing camera video: {video}\ntiming plot: {plot}")
    return log
