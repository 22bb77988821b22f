"""Steps per second and real-time factor of DeckLanding-v0 (prints figures; not a test).

    .venv/bin/python benchmarks/bench_env_speed.py [--seconds 60]

Measures the `project` and `render` camera modes, one environment in this process and two
environments in parallel (one process each, as SubprocVecEnv runs them).  The deck moves
(sum of sinusoids), the four ToF rays are cast and the IMU is sampled at 240 Hz in every case;
`truth` rows measure the simulation alone, `ihrcf` rows add the default estimator, `tight`
the tightly coupled one.  The CPU-time columns (this process's, or the sum over the
processes) are what a shared machine inflates least.  The drone
hovers at the default start height (about 2 m), where `render` mode renders the tag's window.
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
    mode: str, estimator: str, sim_seconds: float, seed: int, queue=None
) -> tuple[int, float, float, float]:
    overrides = {
        "camera.mode": mode,
        "estimation.observed": estimator,
        "simulation.max_episode_s": 1e4,
    }
    env = gym.make("DeckLanding-v0", overrides=overrides)
    env.reset(seed=seed)
    env_dt = 1.0 / env.unwrapped.config.simulation.env_hz
    steps = int(sim_seconds / env_dt)
    # hover: the drone stays in the air, so every step runs the full pipeline
    action = np.zeros(4, dtype=np.float32)
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
    mode: str, estimator: str, sim_seconds: float, n: int
) -> tuple[int, float, float, float]:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [
        ctx.Process(target=_run, args=(mode, estimator, sim_seconds, i, queue)) for i in range(n)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per env")
    parser.add_argument("--render-seconds", type=float, default=20.0)
    args = parser.parse_args()
    console = Console()
    table = Table(title="DeckLanding-v0 speed (240 Hz physics, 20 Hz steps)")
    columns = ("camera mode", "observed estimator", "envs", "steps/s", "real-time factor")
    # CPU time per step: what a shared machine inflates least (wall-clock figures need it idle)
    for column in (*columns, "CPU ms/step", "real-time factor by CPU"):
        table.add_column(column, justify="right")
    cases = (
        ("project", "truth", args.seconds),
        ("project", "ihrcf", args.seconds),
        ("project", "tight", args.seconds),
        ("render", "ihrcf", args.render_seconds),
    )
    for mode, estimator, seconds in cases:
        for n in (1, 2):
            if n == 1:
                steps, wall, sim, cpu = _run(mode, estimator, seconds, 0)
            else:
                steps, wall, sim, cpu = _parallel(mode, estimator, seconds, n)
            table.add_row(
                mode,
                estimator,
                str(n),
                f"{steps / wall:.0f}",
                f"{sim / wall:.1f}x",
                f"{1e3 * cpu / steps:.2f}",
                f"{sim / cpu:.1f}x",
            )
            console.print(f"{mode}/{estimator} x{n}: {steps} steps in {wall:.1f} s")
    console.print(table)


if __name__ == "__main__":
    main()
