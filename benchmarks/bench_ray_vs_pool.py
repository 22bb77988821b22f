"""Episodes per second of ``evaluate landing`` on Ray against the old multiprocessing pool,
and Ray's fixed start-up and shut-down cost (prints figures; not a test).

    python benchmarks/bench_ray_vs_pool.py [--episodes 24] [--policy land-now] [--repeats 2]

For 1 and 2 workers: the previous ``agents/evaluation/parallel.py`` (a spawned
``multiprocessing.Pool`` over chunks of seeds, reproduced below for the comparison; its
process start-up is inside its time, as it was in every evaluation), and the Ray runner
(``agents/evaluation/runner.py``, one actor per worker, seeds one at a time) timed from the
first submission to the last record, with ``ray.init`` and ``ray.shutdown`` timed apart.
The serial in-process run is the reference.  Both parallel paths must return the serial
records; the script checks it.  Best of ``--repeats`` wall-clock times; the machine may be
shared, so compare rows of one run only.
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


def _best(fn, repeats: int) -> tuple[float, object]:
    best, out = math.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=24)
    parser.add_argument("--policy", default="land-now")
    parser.add_argument("--scenario", default="sea-state-4")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    seeds = list(range(HELD_OUT_SEED, HELD_OUT_SEED + args.episodes))
    task = landing_task(args.policy, args.scenario)
    rows: list[tuple[str, int, float]] = []

    serial_s, serial = _best(
        lambda: run_episodes(task, seeds, workers=1, backend="serial").records, args.repeats
    )
    rows.append(("serial, in process", 1, serial_s))
    for workers in (1, 2):
        pool_s, pooled = _best(
            lambda w=workers: run_pool(args.policy, args.scenario, seeds, w), args.repeats
        )
        assert pooled == serial, "the pool's records differ from the serial ones"
        rows.append(("multiprocessing pool (old)", workers, pool_s))

    import ray

    startup, shutdown = [], []
    for workers in (1, 2):
        start = time.perf_counter()
        ensure_ray(None, workers)
        startup.append(time.perf_counter() - start)
        ray_s, result = _best(
            lambda w=workers: run_episodes(task, seeds, workers=w, backend="ray"), args.repeats
        )
        assert result.records == serial, "Ray's records differ from the serial ones"
        rows.append(("Ray runner (start-up apart)", workers, ray_s))
        start = time.perf_counter()
        ray.shutdown()
        shutdown.append(time.perf_counter() - start)

    table = Table(
        title=f"{args.policy} on {args.scenario}: {args.episodes} episodes, best of {args.repeats}"
    )
    for column in ("runner", "workers", "wall (s)", "episodes/s", "vs the pool"):
        table.add_column(column, justify="right")
    pool_rate = {w: args.episodes / t for name, w, t in rows if name.startswith("multi")}
    for name, workers, seconds in rows:
        rate = args.episodes / seconds
        ratio = f"{100 * rate / pool_rate[workers]:.0f} %" if workers in pool_rate else "-"
        table.add_row(name, str(workers), f"{seconds:.2f}", f"{rate:.2f}", ratio)
    console = Console()
    console.print(table)
    console.print(
        f"Ray start-up (ray.init, local): {', '.join(f'{s:.2f}' for s in startup)} s; "
        f"shut-down: {', '.join(f'{s:.2f}' for s in shutdown)} s (for 1 and 2 workers)"
    )


if __name__ == "__main__":
    main()
