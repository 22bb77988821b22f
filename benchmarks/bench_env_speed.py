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
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time

import gymnasium as gym
import numpy as np
from rich.console import Console
from rich.table import Table

import landing_env  # noqa: F401


def _run(
    mode: str, estimator: str, sim_seconds: float, seed: int, queue=None, sensors: str = "ideal"
) -> tuple[int, float, float, float]:
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
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset(seed=seed)
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    env.close()
    result = (steps, wall, steps * env_dt, cpu)
    if queue is not None:
        queue.put(result)
    return result


def _parallel(
    mode: str, estimator: str, sim_seconds: float, n: int, sensors: str = "ideal"
) -> tuple[int, float, float, float]:
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
    return steps, wall, sim, cpu


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
    args = parser.parse_args()
    console = Console(width=140)
    if not args.no_heights:
        height_table(console, args.height_steps, 10, args.renderers.split(","))
    if args.heights:
        return
    table = Table(title="DeckLanding-v2 speed (240 Hz physics, 20 Hz steps)")
    columns = ("sensors", "camera mode", "observed estimator", "envs", "steps/s")
    columns = (*columns, "real-time factor")
    # CPU time per step: what a shared machine inflates least (wall-clock figures need it idle)
    for column in (*columns, "CPU ms/step", "real-time factor by CPU"):
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
                steps, wall, sim, cpu = _run(mode, estimator, seconds, 0, None, sensors)
            else:
                steps, wall, sim, cpu = _parallel(mode, estimator, seconds, n, sensors)
            table.add_row(
                sensors,
                mode,
                estimator,
                str(n),
                f"{steps / wall:.0f}",
                f"{sim / wall:.1f}x",
                f"{1e3 * cpu / steps:.2f}",
                f"{sim / cpu:.1f}x",
            )
            console.print(f"{sensors} {mode}/{estimator} x{n}: {steps} steps in {wall:.1f} s")
    console.print(table)


if __name__ == "__main__":
    main()
