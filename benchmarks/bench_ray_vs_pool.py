"""Episodes per second of ``evaluate landing`` on Ray against the old multiprocessing pool,
and Ray's fixed start-up and shut-down cost (prints figures; not a test).

    python benchmarks/bench_ray_vs_pool.py [--episodes 6 24] [--policy land-now]

For 1 and 2 workers: the previous ``agents/evaluation/parallel.py`` (a spawned
``multiprocessing.Pool`` over chunks of seeds, reproduced below for the comparison; its
process start-up is inside its time, as it was in every evaluation), and the Ray runner
(``agents/evaluation/runner.py``, one actor per worker, seeds one at a time) timed from the
first submission to the last record, with ``ray.init`` and ``ray.shutdown`` timed apart.
Each runs N1 and N2 episodes; the per-episode throughput is (N2 - N1) / (t2 - t1), so that
fixed costs (worker start-up, environment construction) cancel, and the fixed cost is what
remains of t1.  Both paths must return the serial records seed by seed; the script checks
it.  Wall-clock times: on a shared machine compare rows of one run only.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rich.console import Console
from rich.table import Table

from agents.evaluation.landing import (
    HELD_OUT_SEED,
    landing_task,
    make_env_and_policy,
    run_episode,
)
from agents.evaluation.runner import ensure_ray, run_episodes


# ------------------------------------------------------------------ the old pool, for reference
def _pool_chunk(job: tuple) -> list:
    policy, scenario, seeds = job
    env, pol = make_env_and_policy(policy, scenario)
    try:
        return [run_episode(env, pol, seed, policy, scenario) for seed in seeds]
    finally:
        env.close()


def run_pool(policy: str, scenario: str, seeds: list[int], workers: int) -> list:
    """The former ``run_seed_chunks``: chunks of at most 25 seeds over a spawned pool."""
    size = max(1, min(25, math.ceil(len(seeds) / workers)))
    jobs = [(policy, scenario, seeds[i : i + size]) for i in range(0, len(seeds), size)]
    if workers == 1:
        return [r for job in jobs for r in _pool_chunk(job)]
    with mp.get_context("spawn").Pool(workers) as pool:
        return [r for chunk in pool.imap(_pool_chunk, jobs) for r in chunk]


def _time(fn) -> tuple[float, object]:
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, nargs=2, default=[6, 24], metavar=("N1", "N2"))
    parser.add_argument("--policy", default="land-now")
    parser.add_argument("--scenario", default="bench-ss4")
    args = parser.parse_args()
    n1, n2 = args.episodes
    task = landing_task(args.policy, args.scenario)
    seeds = {n: list(range(HELD_OUT_SEED, HELD_OUT_SEED + n)) for n in (n1, n2)}
    serial = {
        n: run_episodes(task, seeds[n], workers=1, backend="serial").records for n in (n1, n2)
    }

    runners = {
        "multiprocessing pool (old)": lambda n, w: run_pool(
            args.policy, args.scenario, seeds[n], w
        ),
        "Ray runner": lambda n, w: run_episodes(task, seeds[n], workers=w, backend="ray").records,
    }
    import ray

    rows: list[tuple[str, int, float, float]] = []
    startup: list[float] = []
    shutdown: list[float] = []
    for workers in (1, 2):
        for name, run in runners.items():
            if name.startswith("Ray"):
                start = time.perf_counter()
                ensure_ray(None, workers)
                startup.append(time.perf_counter() - start)
            times = {}
            for n in (n1, n2):
                times[n], records = _time(lambda n=n, run=run, w=workers: run(n, w))
                assert records == serial[n], f"{name}: records differ from the serial ones"
            rate = (n2 - n1) / (times[n2] - times[n1])  # per episode, fixed costs cancel
            fixed = times[n1] - n1 / rate
            rows.append((name, workers, rate, fixed))
            if name.startswith("Ray"):
                start = time.perf_counter()
                ray.shutdown()
                shutdown.append(time.perf_counter() - start)

    table = Table(
        title=f"{args.policy} on {args.scenario}: per-episode throughput from {n1} and {n2} "
        "episodes (fixed costs cancel)"
    )
    for column in ("runner", "workers", "episodes/s", "vs the pool", "fixed cost (s)"):
        table.add_column(column, justify="right")
    pool = {w: r for name, w, r, _ in rows if name.startswith("multi")}
    for name, workers, rate, fixed in rows:
        table.add_row(
            name, str(workers), f"{rate:.2f}", f"{100 * rate / pool[workers]:.0f} %", f"{fixed:.1f}"
        )
    console = Console()
    console.print(table)
    console.print(
        "fixed cost: worker start-up and environment construction (the pool's 1-worker row "
        "runs in this process).  Ray start-up (ray.init, local, 1 and 2 CPUs): "
        f"{', '.join(f'{s:.2f}' for s in startup)} s; shut-down: "
        f"{', '.join(f'{s:.2f}' for s in shutdown)} s"
    )


if __name__ == "__main__":
    main()
