"""Episodes per second of ``evaluate landing`` on Ray against the old multiprocessing pool,
and Ray's fixed start-up and shut-down cost (prints figures; not a test).

    python benchmarks/bench_ray_vs_pool.py [--episodes 10 40] [--repeats 2] [--policy land-now]

For 1 and 2 workers, the previous ``agents/evaluation/parallel.py`` (a spawned
``multiprocessing.Pool`` over chunks of at most 25 seeds, one environment per chunk,
reproduced below; its process start-up inside its time, as in every evaluation; one worker
runs in this process) and the Ray runner (``agents/evaluation/runner.py``: one actor per
worker holding its environment, fresh actors for every call) each run N1 and N2 episodes,
in alternating order, ``--repeats`` times.  Both must return the serial records seed by
seed; the script checks it.  Per run it measures:

* **steady episodes/s**: every episode logs its end time (wall clock, from the worker); the
  rate over the window in which every worker is busy (from the last worker's first episode
  to the first worker's last one), so worker start-up, imports and the environment's
  construction are outside it: the per-episode throughput;
* **two-count episodes/s**: (N2 - N1) / (t2 - t1) from the end-to-end times (fixed costs
  cancel only when they are the same in both runs: on a shared machine they are not);
* **CPU per episode**: CPU seconds of every process of the run (this one, the pool's or
  Ray's workers, Ray's raylet, GCS, agents and log monitor, those that exited included),
  (CPU2 - CPU1) / (N2 - N1): what an episode costs the machine, whatever else runs on it;
* **start-up**: from the call to the first episode's end, minus one steady episode time.

``ray.init`` and ``ray.shutdown`` are timed apart, and the runs start once the processes
that ``ray.init`` started have settled (its idle workers and agents import for seconds after
it returns; that work would otherwise land in the first run).  The ratio "vs the pool" is of the
medians over the repeats.  Wall-clock rates on a shared machine swing with its load; CPU per
episode does not, and with as many workers as cores it bounds the throughput on an idle
machine (cores / CPU per episode).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.common.parallel import ensure_ray
from agents.evaluation.landing import HELD_OUT_SEED, LANDING_EVALUATION, landing_task
from agents.evaluation.runner import EpisodeTask, get_evaluation, run_episodes

#: where every episode appends "pid end_time" (set before the workers start)
LOG_VARIABLE = "DECK_LANDING_BENCH_EPISODE_LOG"


class _LoggedLanding:
    """The landing evaluation, each episode's end time appended to the log."""

    record_type = LANDING_EVALUATION.record_type

    def validate(self, task: EpisodeTask) -> None:
        LANDING_EVALUATION.validate(task)

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        return LANDING_EVALUATION.make(task)

    def run_episode(self, env: Any, policy: Any, seed: int, task: EpisodeTask) -> Any:
        record = LANDING_EVALUATION.run_episode(env, policy, seed, task)
        with open(os.environ[LOG_VARIABLE], "a") as log:
            log.write(f"{os.getpid()} {time.time():.6f}\n")
        return record


LOGGED = _LoggedLanding()


# ------------------------------------------------------------------ the old pool, for reference
def _pool_chunk(job: tuple[EpisodeTask, list[int]]) -> list[Any]:
    task, seeds = job
    evaluation = get_evaluation(task.evaluation)
    env, policy = evaluation.make(task)
    try:
        return [evaluation.run_episode(env, policy, seed, task) for seed in seeds]
    finally:
        env.close()


def run_pool(task: EpisodeTask, seeds: list[int], workers: int) -> list[Any]:
    """The former ``run_seed_chunks``: chunks of at most 25 seeds over a spawned pool."""
    size = max(1, min(25, math.ceil(len(seeds) / workers)))
    jobs = [(task, seeds[i : i + size]) for i in range(0, len(seeds), size)]
    if workers == 1:
        return [r for job in jobs for r in _pool_chunk(job)]
    with mp.get_context("spawn").Pool(workers) as pool:
        return [r for chunk in pool.imap(_pool_chunk, jobs) for r in chunk]


# ------------------------------------------------------------------ measuring
_TICK = os.sysconf("SC_CLK_TCK")


def _tree() -> dict[tuple[int, str], float]:
    """CPU seconds of this process and each descendant, keyed by (pid, start time)."""
    out: dict[tuple[int, str], float] = {}
    stack = [os.getpid()]
    while stack:
        pid = stack.pop()
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            for task in Path(f"/proc/{pid}/task").iterdir():
                stack += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue  # it exited meanwhile
        fields = stat[stat.rfind(")") + 2 :].split()
        # utime and stime; not cutime and cstime (its children are sampled themselves)
        out[(pid, fields[19])] = (int(fields[11]) + int(fields[12])) / _TICK
    return out


class TreeCpu:
    """CPU seconds used by this process and all its descendants while it runs, those that
    exit meanwhile included (sampled every ``period_s``, each process's last sample kept; a
    parent's children's time is not used: Ray's raylet does not reap its workers into it).
    Sampled rarely: the sampling thread shares the interpreter with the pool's one-worker
    row, which runs its episodes in this process."""

    def __init__(self, period_s: float = 1.0) -> None:
        import threading

        self.period_s = period_s
        self.first = _tree()
        self.last = dict(self.first)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._poll, daemon=True)
        self.thread.start()

    def _poll(self) -> None:
        while not self.stop.wait(self.period_s):
            self.last.update(_tree())

    def used_s(self) -> float:
        self.stop.set()
        self.thread.join()
        self.last.update(_tree())
        return sum(cpu - self.first.get(key, 0.0) for key, cpu in self.last.items())


def settled_s(limit_s: float = 60.0) -> float:
    """Wait until the processes that ``ray.init`` started have settled (its idle workers,
    agents and dashboard import at first, after ``ray.init`` returns): until they use less
    than a tenth of a core over a second; the seconds waited."""
    start = time.perf_counter()
    while time.perf_counter() - start < limit_s:
        before = sum(_tree().values())
        time.sleep(1.0)
        if sum(_tree().values()) - before < 0.1:
            break
    return time.perf_counter() - start


@dataclass
class Run:
    wall_s: float
    cpu_s: float
    steady_rate: float
    startup_s: float


def measure(run: Any, log: Path) -> Run:
    log.write_text("")
    meter, start_wall, start = TreeCpu(), time.time(), time.perf_counter()
    run()
    wall = time.perf_counter() - start
    cpu = meter.used_s()
    ends: dict[str, list[float]] = {}
    for line in log.read_text().splitlines():
        pid, end = line.split()
        ends.setdefault(pid, []).append(float(end))
    begin = max(min(e) for e in ends.values())
    finish = min(max(e) for e in ends.values())
    inside = sum(1 for e in ends.values() for t in e if begin < t <= finish)
    rate = inside / (finish - begin) if finish > begin and inside else math.nan
    first = min(min(e) for e in ends.values())
    workers = len(ends)
    return Run(wall, cpu, rate, first - start_wall - workers / rate)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, nargs=2, default=[10, 40], metavar=("N1", "N2"))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--policy", default="land-now")
    parser.add_argument("--scenario", default="bench-ss4")
    args = parser.parse_args()
    n1, n2 = args.episodes
    log = Path(tempfile.mkdtemp()) / "episodes.log"
    os.environ[LOG_VARIABLE] = str(log)  # before any worker starts: they inherit it
    # Ray's workers import this module (the episode log) by its name
    here = str(Path(__file__).resolve().parent)
    os.environ["PYTHONPATH"] = os.pathsep.join(
        p for p in (here, os.environ.get("PYTHONPATH", "")) if p
    )
    task = replace(landing_task(args.policy, args.scenario), evaluation="bench_ray_vs_pool:LOGGED")
    seeds = {n: list(range(HELD_OUT_SEED, HELD_OUT_SEED + n)) for n in (n1, n2)}
    serial = {
        n: run_episodes(task, seeds[n], workers=1, backend="serial").records for n in (n1, n2)
    }
    import ray
    from rich.console import Console
    from rich.table import Table

    def pool(n: int, w: int) -> list[Any]:
        return run_pool(task, seeds[n], w)

    def on_ray(n: int, w: int) -> list[Any]:
        return run_episodes(task, seeds[n], workers=w, backend="ray").records

    runners = {"pool (old)": pool, "Ray runner": on_ray}
    runs: dict[tuple[str, int, int], list[Run]] = {}
    startup: list[float] = []
    settle: list[float] = []
    shutdown: list[float] = []
    console = Console()
    for repeat in range(args.repeats):
        for workers in (1, 2):
            order = list(runners) if (repeat + workers) % 2 else list(reversed(runners))
            for name in order:
                if name.startswith("Ray"):
                    start = time.perf_counter()
                    ensure_ray(None, workers)
                    startup.append(time.perf_counter() - start)
                    settle.append(settled_s())
                for n in (n1, n2):

                    def call(name: str = name, n: int = n, w: int = workers) -> None:
                        records = runners[name](n, w)
                        assert records == serial[n], f"{name}: records differ from serial"

                    runs.setdefault((name, workers, n), []).append(measure(call, log))
                    r = runs[(name, workers, n)][-1]
                    console.print(
                        f"repeat {repeat + 1}, {name}, {workers} worker(s), {n} episodes: "
                        f"{r.wall_s:.1f} s, CPU {r.cpu_s:.1f} s, steady {r.steady_rate:.2f} ep/s"
                    )
                if name.startswith("Ray"):
                    start = time.perf_counter()
                    ray.shutdown()
                    shutdown.append(time.perf_counter() - start)

    table = Table(
        title=f"{args.policy} on {args.scenario}: {n1} and {n2} episodes, medians over "
        f"{args.repeats} alternating repeats"
    )
    for column in (
        "runner",
        "workers",
        "steady ep/s",
        "vs the pool",
        "two-count ep/s",
        "vs the pool",
        "CPU per episode (ms)",
        "vs the pool",
        "start-up (s)",
    ):
        table.add_column(column, justify="right")
    figures: dict[tuple[str, int], tuple[float, float, float, float]] = {}
    for name in runners:
        for workers in (1, 2):
            pairs = list(zip(runs[(name, workers, n1)], runs[(name, workers, n2)], strict=True))
            steady = statistics.median(b.steady_rate for _, b in pairs)
            two = statistics.median((n2 - n1) / (b.wall_s - a.wall_s) for a, b in pairs)
            cpu = statistics.median((b.cpu_s - a.cpu_s) / (n2 - n1) for a, b in pairs)
            up = statistics.median(r.startup_s for pair in pairs for r in pair)
            figures[(name, workers)] = (steady, two, cpu, up)
    for (name, workers), (steady, two, cpu, up) in figures.items():
        ref = figures[("pool (old)", workers)]
        table.add_row(
            name,
            str(workers),
            f"{steady:.2f}",
            f"{100 * steady / ref[0]:.0f} %",
            f"{two:.2f}",
            f"{100 * two / ref[1]:.0f} %",
            f"{1000 * cpu:.0f}",
            f"{100 * ref[2] / cpu:.0f} %",
            f"{up:.1f}",
        )
    console.print(table)
    console.print(
        "CPU per episode 'vs the pool': the pool's CPU per episode over this runner's (above "
        "100 % costs less).  Start-up: the pool's 1-worker row runs in this process.  "
        f"ray.init (local): {', '.join(f'{s:.2f}' for s in startup)} s, and its processes "
        f"busy {', '.join(f'{s:.1f}' for s in settle)} s more (not timed); ray.shutdown: "
        f"{', '.join(f'{s:.2f}' for s in shutdown)} s; load average now "
        f"{', '.join(f'{v:.1f}' for v in os.getloadavg())}"
    )


if __name__ == "__main__":
    main()
