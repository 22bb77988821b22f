"""Steps per second and real-time factor of DeckLanding-v2 (prints figures; not a test).

    .venv/bin/python benchmarks/bench_env_speed.py [--seconds 60]

Measures the `project` and `render` camera modes, one environment in this process and two
environments in parallel (one process each, as SubprocVecEnv runs them; ``--envs``).  The deck moves
(sum of sinusoids), the four ToF rays are cast and the IMU is sampled at 240 Hz in every case;
`truth` rows measure the simulation alone, `ihrcf` rows add the default estimator, `tight`
the tightly coupled one; `realistic` rows run with ``sensors: realistic`` (the OV9281-class
camera's blur and noise, lens distortion, ToF noise; ``--sensors`` picks the rows).  The
CPU-time columns (this process's, or the sum over the processes) are what a shared machine
inflates least.  The drone
hovers at the default start height (about 2 m), where `render` mode renders the tag's window.

The second table is `render` mode by height: the drone pinned (``simulation.drone_fixed``)
over the moving deck at 4, 2, 1, 0.6 and 0.3 m, one environment, for each renderer
(``camera.renderer``: ``planar``, the default, and ``bullet``, PyBullet's TinyRenderer; and
``planar+realistic``: ``sensors: realistic``, the OV9281-class camera's blur and noise), with
the time of a step and of a full-frame ``render()`` (``rgb_array``), each as CPU time of this
process (``time.process_time``, what the run costs when the machine is shared) and wall time.
Only ``--heights`` runs that table alone.

Each row of the first table is set against the physics ceiling of the same run: the CPU time
of the bare ``stepSimulation`` calls of the env's own world during the row's steps (the same
sub-steps, the same states), over the row's CPU time per step (1 would be a step that costs
its physics alone).  The timing task (``DeckLandingTiming-BenchSS4-v6``, ``step(0)`` in a loop,
reset at each end) is a row of its own: its steps are wait decisions, each some two control
periods of the hold, its CPU time is per decision, and its ceiling is its own physics.  When
gym-pybullet-drones or PyFlyt is installed,
their hover tasks run beside the rows; otherwise the output says they are not installed.

``--profile`` prints, instead of the tables, the top functions by cumulative and by own CPU
time of ``--seconds`` simulated seconds of `project` mode with the truth observed, with
`tight`, and with `tight` under realistic sensing (cProfile; ``--profile-top`` rows each),
and the CPU time of a step of each case without the profiler and under it (cProfile's own
cost, with CPU time as its clock, is several times the step's)::

    .venv/bin/python -m benchmarks.bench_env_speed --profile --seconds 20

``--tight-starts`` prints what each start of ``tight`` costs and gains instead: over
``--seconds`` of a slow descent in `project` mode (ideal and realistic sensing), every frame
is estimated by ``tight`` as configured (``previous_start: fallback``: IPPE and ToF-plane
starts) and with ``previous_start: first``, each timed by CPU, with the Levenberg–Marquardt
iterations of every start refined, and each compared with the true pose.
"""

from __future__ import annotations

import argparse
import copy
import cProfile
import dataclasses
import importlib.util
import multiprocessing as mp
import pstats
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pybullet as p
from rich.console import Console
from rich.table import Table

import landing_env  # noqa: F401


def _run(
    mode: str, estimator: str, sim_seconds: float, seed: int, queue=None, sensors: str = "ideal"
) -> tuple[int, float, float, float, float]:
    """Steps, wall s, simulated s, CPU s and the CPU s of its ``stepSimulation`` calls."""
    overrides = {
        "camera.mode": mode,
        "estimation.observed": estimator,
        "simulation.max_episode_s": 1e4,
        "sensors": sensors,
    }
    env = gym.make("DeckLanding-v2", overrides=overrides)
    env.reset(seed=seed)
    env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
    steps = int(sim_seconds / env_dt)
    # hover: the drone stays in the air, so every step runs the full pipeline
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(action)
    start = time.perf_counter()
    cpu_start = time.process_time()
    with PhysicsClock() as physics:
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=seed)
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    env.close()
    result = (steps, wall, steps * env_dt, cpu, physics.cpu_s)
    if queue is not None:
        queue.put(result)
    return result


def _parallel(
    mode: str, estimator: str, sim_seconds: float, n: int, sensors: str = "ideal"
) -> tuple[int, float, float, float, float]:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [
        ctx.Process(target=_run, args=(mode, estimator, sim_seconds, i, queue, sensors))
        for i in range(n)
    ]
    for proc in procs:
        proc.start()
    results = [queue.get() for _ in procs]
    for proc in procs:
        proc.join()
    steps = sum(r[0] for r in results)
    wall = max(r[1] for r in results)
    sim = sum(r[2] for r in results)
    cpu = sum(r[3] for r in results)
    physics = sum(r[4] for r in results)
    return steps, wall, sim, cpu, physics


class PhysicsClock:
    """Times every ``pybullet.stepSimulation`` call of this process (CPU seconds).

    The world calls ``pybullet.stepSimulation`` once per physics sub-step; while the clock is
    installed each call is timed, so a row's physics is measured in the row's own run: the
    same world, the same sub-steps, the same states.  Its total over the row's steps is the
    physics ceiling: what a step would cost if nothing but the physics ran.
    """

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self._step = p.stepSimulation

    def __enter__(self) -> PhysicsClock:
        step, clock = self._step, time.process_time

        def timed(*args, **kwargs):
            start = clock()
            try:
                return step(*args, **kwargs)
            finally:
                self.cpu_s += clock() - start

        p.stepSimulation = timed
        return self

    def __exit__(self, *exc: object) -> None:
        p.stepSimulation = self._step


#: the peers' hover tasks: (package to import, label, env id, module whose import registers it)
PEERS = (
    ("gym_pybullet_drones", "gym-pybullet-drones HoverAviary", "hover-aviary-v0", None),
    ("PyFlyt", "PyFlyt QuadX-Hover-v4", "PyFlyt/QuadX-Hover-v4", "PyFlyt.gym_envs"),
)


def _peer_env(package: str, env_id: str, module: str | None) -> gym.Env:
    if package == "gym_pybullet_drones":
        from gym_pybullet_drones.envs.HoverAviary import HoverAviary

        return HoverAviary()
    if module is not None:
        importlib.import_module(module)
    return gym.make(env_id)


def peer_rows(sim_seconds: float) -> tuple[list[tuple[str, int, float, float, float]], list[str]]:
    """The installed peers' rows (label, steps, wall s, simulated s, CPU s) and the names of
    those not installed."""
    rows, missing = [], []
    for package, label, env_id, module in PEERS:
        if importlib.util.find_spec(package) is None:
            missing.append(label)
            continue
        env = _peer_env(package, env_id, module)
        env.reset(seed=0)
        fps = float(env.metadata.get("render_fps") or getattr(env, "CTRL_FREQ", 30))
        steps = max(1, int(sim_seconds * fps))
        action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        if np.issubdtype(env.action_space.dtype, np.floating):
            action = 0.5 * (env.action_space.low + env.action_space.high)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=0)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        env.close()
        rows.append((label, steps, wall, steps / fps, cpu))
    return rows, missing


#: the timing task measured beside the table: ``step(0)`` (wait) in a loop, reset at each end
TIMING_IDS = ("DeckLandingTiming-BenchSS4-v6",)


def wait_decisions(env_id: str, cpu_seconds: float) -> tuple[int, float, float, float]:
    """Wait decisions of the timing task ``env_id`` (default observation, ``step(0)``) over
    about ``cpu_seconds`` of CPU: (decisions, CPU s, physics CPU s, wall s)."""
    env = gym.make(env_id)
    env.reset(seed=0)
    decisions, episodes = 0, 0
    with PhysicsClock() as physics:
        wall = time.perf_counter()
        start = time.process_time()
        while time.process_time() - start < cpu_seconds:
            _, _, terminated, truncated, _ = env.step(0)
            decisions += 1
            if terminated or truncated:
                episodes += 1
                env.reset(seed=episodes)
        cpu = time.process_time() - start
        wall = time.perf_counter() - wall
    env.close()
    return decisions, cpu, physics.cpu_s, wall


#: the profiled cases: (label, observed estimator, sensors), all in `project` mode
PROFILE_CASES = (
    ("project mode, truth observed", "truth", "ideal"),
    ("project mode, tight", "tight", "ideal"),
    ("project mode, tight, realistic sensing", "tight", "realistic"),
)


def profile(console: Console, sim_seconds: float, top: int) -> None:
    """Print the top functions by cumulative CPU time of each profiled case."""
    root = str(Path(__file__).resolve().parents[1]) + "/"
    for label, estimator, sensors in PROFILE_CASES:
        overrides = {
            "camera.mode": "project",
            "estimation.observed": estimator,
            "simulation.max_episode_s": 1e4,
            "sensors": sensors,
        }
        env = gym.make("DeckLanding-v2", overrides=overrides)
        env.reset(seed=0)
        env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
        steps = max(1, int(sim_seconds / env_dt))
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        env.step(action)
        # the same steps without the profiler first: what a step costs unobserved
        unobserved = time.process_time()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=0)
        unobserved = time.process_time() - unobserved
        env.reset(seed=0)
        env.step(action)
        profiler = cProfile.Profile(time.process_time)
        profiler.enable()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset(seed=0)
        profiler.disable()
        env.close()
        stats = pstats.Stats(profiler)
        # the outermost call's cumulative time: the whole of the steps
        total = max(max(entry[3] for entry in stats.stats.values()), 1e-12)
        console.print(
            f"{label}: {1e3 * unobserved / steps:.3f} CPU ms/step without the profiler, "
            f"{1e3 * total / steps:.3f} under it"
        )
        # by cumulative time (where the step's time goes) and by own time (what to rewrite)
        for order, column in (("cumulative", 3), ("own", 2)):
            table = Table(title=f"{label}: {steps} steps, top {top} by {order} CPU time")
            for heading in ("function", "calls/step", "cumulative %", "own %"):
                table.add_column(heading, justify="left" if heading == "function" else "right")
            entries = sorted(stats.stats.items(), key=lambda item: item[1][column], reverse=True)
            for (path, line, name), (_, calls, own, cumulative, _) in entries[:top]:
                where = path.removeprefix(root) if path.startswith(root) else path
                if "site-packages/" in where:
                    where = where.split("site-packages/", 1)[1]
                site = f"{where}:{line}({name})" if line else name
                table.add_row(
                    site, f"{calls / steps:.1f}", f"{100 * cumulative / total:.1f}",
                    f"{100 * own / total:.1f}",
                )  # fmt: skip
            console.print(table)


def tight_starts(console: Console, sim_seconds: float) -> None:
    """Per frame: CPU, iterations (all starts) and error of ``tight`` by its start rule."""
    from estimation.tight_problem import TightProblem

    counts = {"solves": 0, "iterations": 0}
    solve = TightProblem.solve

    def counted(self, *args, **kwargs):
        solution = solve(self, *args, **kwargs)
        counts["solves"] += 1
        counts["iterations"] += solution.iterations if solution is not None else 0
        return solution

    table = Table(title=f"tight by start rule, {sim_seconds:g} s of a slow descent per row")
    for column in (
        "sensors", "previous_start", "valid", "CPU µs median / mean", "starts", "LM iterations",
        "kept previous", "position error mm median / p95", "tilt error deg median / p95",
        "gap to fallback mm / deg",
    ):  # fmt: skip
        table.add_column(column, justify="right")
    TightProblem.solve = counted
    try:
        for sensors in ("ideal", "realistic"):
            overrides = {
                "camera.mode": "project",
                "estimation.observed": "tight",
                "simulation.max_episode_s": 1e4,
                "sensors": sensors,
            }
            env = gym.make("DeckLanding-v2", overrides=overrides)
            env.reset(seed=0)
            env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
            own = env.unwrapped.bank.estimators["tight"]
            variants = {"fallback": copy.deepcopy(own), "first": copy.deepcopy(own)}
            variants["first"].config = dataclasses.replace(own.config, previous_start="first")
            rows = {name: [] for name in variants}
            action = np.zeros(env.action_space.shape, dtype=np.float32)
            action[2] = -0.1  # a slow descent: every height from the start's down to the deck
            for _ in range(max(1, int(sim_seconds / env_dt))):
                _, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    env.reset(seed=0)
                    for estimator in variants.values():
                        estimator.reset()
                    continue
                sensing = env.unwrapped._sensing
                truth = np.asarray(info["deck_pose_true"], dtype=float)
                for name, estimator in variants.items():
                    counts["solves"] = counts["iterations"] = 0
                    cpu = time.process_time()
                    estimate = estimator.estimate(sensing.frame, sensing.ranges)
                    cpu = time.process_time() - cpu
                    pose = estimate.as_vector() if estimate.valid else np.full(6, np.nan)
                    rows[name].append(
                        (cpu, counts["solves"], counts["iterations"],
                         estimate.extras.get("start") == "previous", *pose, *truth)
                    )  # fmt: skip
            env.close()
            fallback = np.array(rows["fallback"])
            for name, data in ((n, np.array(r)) for n, r in rows.items()):
                # the frames with an estimate (those without one cost no refinement)
                valid = np.isfinite(data[:, 4])
                used, pose, truth = data[valid], data[valid, 4:10], data[valid, 10:16]
                position = 1e3 * np.linalg.norm(pose[:, :3] - truth[:, :3], axis=1)
                tilt = np.degrees(np.max(np.abs(pose[:, 3:5] - truth[:, 3:5]), axis=1))
                both = valid & np.isfinite(fallback[:, 4])
                gap_m = np.abs(data[both, 4:7] - fallback[both, 4:7]).max(initial=0.0)
                gap_rad = np.abs(data[both, 7:10] - fallback[both, 7:10]).max(initial=0.0)
                table.add_row(
                    sensors, name, f"{int(valid.sum())}/{len(data)}",
                    f"{1e6 * np.median(used[:, 0]):.0f} / {1e6 * np.mean(used[:, 0]):.0f}",
                    f"{np.mean(used[:, 1]):.2f}", f"{np.mean(used[:, 2]):.1f}",
                    f"{np.mean(used[:, 3]):.0%}",
                    f"{np.median(position):.2f} / {np.percentile(position, 95):.2f}",
                    f"{np.median(tilt):.3f} / {np.percentile(tilt, 95):.3f}",
                    f"{1e3 * gap_m:.3f} / {np.degrees(gap_rad):.4f}",
                )  # fmt: skip
    finally:
        TightProblem.solve = solve
    console.print(table)


HEIGHTS_M = (4.0, 2.0, 1.0, 0.6, 0.3)


def _by_height(case: str, height: float, steps: int, renders: int) -> dict[str, float]:
    """Per-step and per-render CPU and wall times (ms) with the drone pinned at a height.

    ``case`` is a renderer, optionally with ``+realistic`` (``sensors: realistic``).
    """
    renderer, _, extra = case.partition("+")
    overrides = {
        "camera.mode": "render",
        "camera.renderer": renderer,
        "estimation.observed": "ihrcf",
        "simulation.drone_fixed": True,
        "simulation.max_episode_s": 1e4,
        "start.height_m": (height, height),
        "start.max_offset_m": 0.0,
        "start.max_yaw_deg": 0.0,
    }
    if extra:
        overrides["sensors"] = extra
    env = gym.make("DeckLanding-v2", render_mode="rgb_array", overrides=overrides)
    env.reset(seed=0)
    env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(action)
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(steps):
        env.step(action)
    step_cpu, step_wall = (time.process_time() - cpu) / steps, (time.perf_counter() - wall) / steps
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(renders):
        env.render()
    render_cpu = (time.process_time() - cpu) / renders
    render_wall = (time.perf_counter() - wall) / renders
    env.close()
    return {
        "step_cpu_ms": 1e3 * step_cpu,
        "step_wall_ms": 1e3 * step_wall,
        "rtf_cpu": env_dt / step_cpu,
        "rtf_wall": env_dt / step_wall,
        "render_cpu_ms": 1e3 * render_cpu,
        "render_wall_ms": 1e3 * render_wall,
    }


def height_table(console: Console, steps: int, renders: int, renderers: list[str]) -> None:
    table = Table(title="render mode by height (drone pinned, one env, 20 Hz steps)")
    for column in (
        "renderer",
        "height m",
        "step ms cpu / wall",
        "real-time factor cpu / wall",
        "rgb_array render ms cpu / wall",
    ):
        table.add_column(column, justify="right")
    for renderer in renderers:
        for height in HEIGHTS_M:
            r = _by_height(renderer, height, steps, renders)
            table.add_row(
                renderer,
                f"{height:g}",
                f"{r['step_cpu_ms']:.1f} / {r['step_wall_ms']:.1f}",
                f"{r['rtf_cpu']:.1f}x / {r['rtf_wall']:.1f}x",
                f"{r['render_cpu_ms']:.1f} / {r['render_wall_ms']:.1f}",
            )
            console.print(f"{renderer} {height} m: {r}")
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per env")
    parser.add_argument("--render-seconds", type=float, default=20.0)
    parser.add_argument("--heights", action="store_true", help="only the table by height")
    parser.add_argument("--height-steps", type=int, default=100, help="steps per height")
    parser.add_argument(
        "--renderers",
        default="planar,planar+realistic,bullet",
        help="comma-separated renderers (planar, bullet), +realistic for sensors: realistic",
    )
    parser.add_argument("--no-heights", action="store_true", help="skip the table by height")
    parser.add_argument(
        "--sensors",
        default="ideal,realistic",
        help="comma-separated sensor sets of the first table's rows (ideal, realistic)",
    )
    parser.add_argument(
        "--envs", default="1,2", help="comma-separated environment counts of the first table"
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="print the profile of a step (by cumulative and by own time) instead of the tables",
    )
    parser.add_argument("--profile-top", type=int, default=25, help="functions per profile")
    parser.add_argument(
        "--tight-starts", action="store_true", help="print what each start of tight costs"
    )
    args = parser.parse_args()
    console = Console(width=180)
    if args.tight_starts:
        tight_starts(console, args.seconds)
        return
    if args.profile:
        profile(console, args.seconds, args.profile_top)
        return
    if not args.no_heights:
        height_table(console, args.height_steps, 10, args.renderers.split(","))
    if args.heights:
        return
    table = Table(title="DeckLanding-v2 speed (240 Hz physics, 20 Hz steps)")
    columns = ("sensors", "camera mode", "observed estimator", "envs", "steps/s")
    columns = (*columns, "real-time factor")
    # CPU time per step: what a shared machine inflates least (wall-clock figures need it idle)
    for column in (*columns, "CPU ms/step", "real-time factor by CPU", "of physics ceiling"):
        table.add_column(column, justify="right")
    cases = (
        ("ideal", "project", "truth", args.seconds),
        ("ideal", "project", "ihrcf", args.seconds),
        ("ideal", "project", "tight", args.seconds),
        ("ideal", "render", "ihrcf", args.render_seconds),
        # the realistic camera (blur, noise, lens), ToF noise and their calibrations
        ("realistic", "project", "tight", args.seconds),
        ("realistic", "render", "ihrcf", args.render_seconds),
        ("realistic", "render", "tight", args.render_seconds),
    )
    chosen = set(args.sensors.split(","))
    for sensors, mode, estimator, seconds in cases:
        if sensors not in chosen:
            continue
        for n in (int(count) for count in args.envs.split(",")):
            if n == 1:
                steps, wall, sim, cpu, physics = _run(mode, estimator, seconds, 0, None, sensors)
            else:
                steps, wall, sim, cpu, physics = _parallel(mode, estimator, seconds, n, sensors)
            table.add_row(
                sensors,
                mode,
                estimator,
                str(n),
                f"{steps / wall:.0f}",
                f"{sim / wall:.1f}x",
                f"{1e3 * cpu / steps:.2f}",
                f"{sim / cpu:.1f}x",
                f"{physics / cpu:.2f}",
            )
            console.print(
                f"{sensors} {mode}/{estimator} x{n}: {steps} steps in {wall:.1f} s, "
                f"{1e3 * cpu / steps:.3f} CPU ms/step, physics {1e3 * physics / steps:.3f} "
                f"CPU ms/step: {physics / cpu:.2f} of the physics ceiling"
            )
    for env_id in TIMING_IDS:
        decisions, cpu, physics, wall = wait_decisions(env_id, min(args.seconds, 15.0))
        console.print(
            f"{env_id}: {decisions / cpu:.0f} wait decisions/s by CPU ({decisions} in "
            f"{cpu:.1f} CPU s), {physics / cpu:.2f} of the physics ceiling"
        )
        # a row of its own: a step is a wait decision (its control periods inside it), so
        # its steps/s are decisions/s and its CPU time is per decision; no real-time factor
        table.add_row(
            "ideal", env_id, "default (wait decisions)", "1", f"{decisions / wall:.0f}", "",
            f"{1e3 * cpu / decisions:.2f}", "", f"{physics / cpu:.2f}",
        )  # fmt: skip
    peers, missing = peer_rows(args.seconds)
    for label, steps, wall, sim, cpu in peers:
        table.add_row(
            "peer", label, "", "1", f"{steps / wall:.0f}", f"{sim / wall:.1f}x",
            f"{1e3 * cpu / steps:.2f}", f"{sim / cpu:.1f}x", "",
        )  # fmt: skip
    console.print(table)
    if missing:
        console.print(f"peers not installed (no rows): {', '.join(missing)}")


if __name__ == "__main__":
    main()
