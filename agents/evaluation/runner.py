"""One runner for every batch of episodes over seeds: serial for short jobs, Ray otherwise.

``evaluate landing`` and ``evaluate approach`` describe what to run as an :class:`EpisodeTask`
(the evaluation's name from :data:`EVALUATIONS`, the policy, the scenario, options) and
:func:`run_episodes` runs it over seeds:

* one worker on this machine: in this process (no start-up cost), the same results;
* more workers, or ``address``: on Ray (``ray.init()`` on this machine by default, an existing
  cluster with ``address``), one actor per worker holding its environment, seeds handed out
  one at a time, so the results are those of the serial run seed by seed; within a
  :func:`~agents.common.parallel.batch_session` the actors outlive a run, and the next run
  (the next policy) takes them, without starting worker processes and importing the
  simulation again;
* a bad config fails fast, before any worker starts, with its message
  (:class:`~estimation.errors.ConfigError` naming the key);
* a worker that crashes (its process dies, or its episode raises) is reported with its seed
  in :attr:`RunResult.failures`; a fresh worker takes over and the other seeds still run;
* each record is appended to ``results_path`` (JSON lines) as it arrives, and ``resume``
  keeps the seeds already there and runs only the missing ones.
"""

from __future__ import annotations

import importlib
import json
import math
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import landing_env  # noqa: F401  (registers the ids; PyBullet's banner silenced there)
from agents.common.parallel import ensure_ray, keep_idle_actor, take_idle_actor, user_error_behind
from agents.common.user_input import USER_ERRORS
from agents.evaluation.records import EpisodeRecord
from estimation.errors import ConfigError

#: calls queued per actor: the next seed waits in the actor while the current one runs, so a
#: worker never idles for the round trip to the driver
PIPELINE_DEPTH = 2

#: evaluation name -> "module:attribute" of its :class:`Evaluation` (imported on use, also in
#: the workers); a test may name its own evaluation by its "module:attribute" directly
EVALUATIONS: dict[str, str] = {
    "landing": "agents.evaluation.landing:LANDING_EVALUATION",
    "approach": "agents.evaluation.approach:APPROACH_EVALUATION",
}


@dataclass(frozen=True)
class EpisodeTask:
    """What a worker needs to run episodes of one policy (picklable)."""

    evaluation: str
    policy: str
    scenario: str
    options: dict[str, Any] = field(default_factory=dict)


class Evaluation(Protocol):
    """How one kind of evaluation makes its environment and policy and runs an episode."""

    record_type: type[EpisodeRecord]

    def validate(self, task: EpisodeTask) -> None:
        """Raise ConfigError for a bad task (builds the config; runs before any worker)."""

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        """The environment and the policy."""

    def run_episode(self, env: Any, policy: Any, seed: int, task: EpisodeTask) -> EpisodeRecord:
        """One episode to its end."""


def get_evaluation(name: str) -> Evaluation:
    """The evaluation registered as ``name`` (or given as "module:attribute")."""
    target = EVALUATIONS.get(name, name)
    module, sep, attribute = target.partition(":")
    if not sep:
        raise ConfigError("evaluation", f"{name!r} is not one of {sorted(EVALUATIONS)}")
    return getattr(importlib.import_module(module), attribute)


@dataclass
class SeedFailure:
    """A seed whose worker crashed or whose episode raised."""

    seed: int
    error: str


@dataclass
class RunResult:
    """The records in seed order, the failed seeds, and how the run went."""

    records: list[EpisodeRecord]
    failures: list[SeedFailure]
    resumed: int = 0
    backend: str = "serial"
    wall_time_s: float = math.nan


def split_runs(
    runs: dict[str, RunResult],
) -> tuple[dict[str, list[Any]], dict[str, list[SeedFailure]]]:
    """The records of every policy that finished an episode, and the failed seeds by policy;
    a RuntimeError naming the seeds when no episode finished at all."""
    failures = {name: run.failures for name, run in runs.items() if run.failures}
    results = {name: list(run.records) for name, run in runs.items() if run.records}
    if not results:
        seeds = ", ".join(str(f.seed) for fs in failures.values() for f in fs)
        raise RuntimeError(f"every episode failed (seeds {seeds})")
    return results, failures


# ------------------------------------------------------------------------------ results file
def _read_done(path: Path, record_type: type[EpisodeRecord], seeds: set[int]) -> dict[int, Any]:
    done: dict[int, Any] = {}
    if not path.is_file():
        return done
    for line in path.read_text().splitlines():
        try:
            data = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut by an interruption: the seed runs again
        if isinstance(data, dict) and data.get("seed") in seeds:
            done[int(data["seed"])] = record_type.from_json(data)
    return done


class _Sink:
    """Appends records to the JSON-lines file and moves the progress bar."""

    def __init__(self, path: Path | None, total: int, done: int, desc: str, progress: bool):
        self.handle = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.handle = path.open("a")
        self.bar = None
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, desc=desc, unit="ep")

    def add(self, record: EpisodeRecord) -> None:
        if self.handle is not None:
            self.handle.write(json.dumps(record.to_json()) + "\n")
            self.handle.flush()
        if self.bar is not None:
            self.bar.update(1)

    def fail(self) -> None:
        if self.bar is not None:
            self.bar.update(1)

    def close(self) -> None:
        if self.handle is not None:
            self.handle.close()
        if self.bar is not None:
            self.bar.close()


# ------------------------------------------------------------------------------ the runner
def run_episodes(
    task: EpisodeTask,
    seeds: list[int],
    *,
    workers: int = 1,
    address: str | None = None,
    results_path: Path | None = None,
    resume: bool = False,
    progress: bool = False,
    desc: str = "",
    backend: str = "auto",
    rerun: tuple[int, ...] = (),
) -> RunResult:
    """Run ``task`` for every seed (see the module docstring); records come back in seed order.

    ``backend``: ``"auto"`` (serial for one local worker or one seed, else Ray), or force
    ``"serial"`` or ``"ray"`` (the benchmark compares them).  ``rerun``: seeds that run even
    when ``resume`` finds them done (an episode to be recorded)."""
    if workers < 1:
        raise ConfigError("workers", f"{workers} is out of range; allowed [1, inf]")
    evaluation = get_evaluation(task.evaluation)
    evaluation.validate(task)  # fail fast, before a worker starts
    wanted = list(dict.fromkeys(seeds))
    done: dict[int, Any] = {}
    if results_path is not None:
        if resume:
            done = _read_done(results_path, evaluation.record_type, set(wanted) - set(rerun))
        elif results_path.exists():
            results_path.unlink()
    todo = [s for s in wanted if s not in done]
    sink = _Sink(results_path, len(wanted), len(done), desc or task.policy, progress)
    started = time.perf_counter()
    try:
        if backend == "auto":
            short = address is None and (workers == 1 or len(todo) <= 1)
            backend = "serial" if short else "ray"
        if backend == "serial":
            records, failures = _run_serial(evaluation, task, todo, sink)
        else:
            records, failures = _run_ray(task, todo, workers, address, sink)
    finally:
        sink.close()
    every = {**done, **{r.seed: r for r in records}}
    return RunResult(
        records=[every[s] for s in wanted if s in every],
        failures=sorted(failures, key=lambda f: f.seed),
        resumed=len(done),
        backend=backend,
        wall_time_s=time.perf_counter() - started,
    )


def _run_serial(
    evaluation: Evaluation, task: EpisodeTask, seeds: list[int], sink: _Sink
) -> tuple[list[EpisodeRecord], list[SeedFailure]]:
    records: list[EpisodeRecord] = []
    failures: list[SeedFailure] = []
    env = policy = None
    try:
        for seed in seeds:
            if env is None:
                env, policy = evaluation.make(task)
            try:
                record = evaluation.run_episode(env, policy, seed, task)
            except USER_ERRORS:
                raise
            except Exception as exc:  # a crashed episode: report its seed, keep the others
                failures.append(SeedFailure(seed, f"{type(exc).__name__}: {exc}"))
                sink.fail()
                env.close()
                env = policy = None
                continue
            records.append(record)
            sink.add(record)
    finally:
        if env is not None:
            env.close()
    return records, failures


# ------------------------------------------------------------------------------ Ray
class _EpisodeWorker:
    """A Ray actor: one environment and policy, kept from seed to seed and from call to call
    (built again only when the task changes), episodes one seed at a time."""

    def __init__(self) -> None:
        self.task: EpisodeTask | None = None
        self.env: Any = None
        self.policy: Any = None

    def run(self, task: EpisodeTask, seed: int) -> dict[str, Any]:
        evaluation = get_evaluation(task.evaluation)
        if task != self.task:
            if self.env is not None:
                self.env.close()
            self.task, self.env = None, None
            # a user error raised here reaches the driver with its type (as a task's error)
            self.env, self.policy = evaluation.make(task)
            self.task = task
        record = evaluation.run_episode(self.env, self.policy, seed, task)
        return record.to_json()


def _run_ray(
    task: EpisodeTask, seeds: list[int], workers: int, address: str | None, sink: _Sink
) -> tuple[list[EpisodeRecord], list[SeedFailure]]:
    import ray
    from ray.exceptions import GetTimeoutError, RayActorError, RayTaskError

    record_type = get_evaluation(task.evaluation).record_type
    started = ensure_ray(address, workers)
    actor_class = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(_EpisodeWorker)
    records: list[EpisodeRecord] = []
    failures: list[SeedFailure] = []
    queue: deque[int] = deque(seeds)
    #: per actor, its calls in the order it runs them (an actor runs one call at a time)
    inflight: dict[Any, deque[tuple[Any, int]]] = {}
    running: dict[Any, Any] = {}  # ref -> actor

    #: seeds whose actor died while they were queued with another: they run again, alone,
    #: so that a crash is put on the seed that caused it
    suspects: set[int] = set()

    def fill(actor: Any) -> None:
        calls = inflight[actor]
        while queue and len(calls) < PIPELINE_DEPTH:
            if queue[0] in suspects and calls:
                break  # a suspect runs alone
            seed = queue.popleft()
            ref = actor.run.remote(task, seed)
            calls.append((ref, seed))
            running[ref] = actor
            if seed in suspects:
                break

    def new_actor() -> None:
        kept = take_idle_actor()
        actor = kept if kept is not None else actor_class.remote()
        inflight[actor] = deque()
        fill(actor)

    def accept(data: dict[str, Any]) -> None:
        record = record_type.from_json(data)
        records.append(record)
        sink.add(record)

    def report(seed: int, error: BaseException) -> None:
        cause = user_error_behind(error)
        if cause is not None:
            raise cause from None
        failures.append(SeedFailure(seed, _describe(error)))
        sink.fail()

    def settle(actor: Any, failed: Any, exc: BaseException) -> None:
        """After an error on ``actor``: keep what its other calls returned, report the seed
        that failed, queue the others again (see ``suspects``)."""
        calls = inflight.pop(actor)
        unfinished: list[int] = []
        for ref, seed in calls:
            running.pop(ref, None)
            if ref == failed:
                unfinished.append(seed)
                continue
            try:
                accept(ray.get(ref, timeout=30.0))
            except (RayTaskError, RayActorError, GetTimeoutError):
                unfinished.append(seed)
        if not isinstance(exc, RayActorError):
            # the episode raised and the actor lives: that call is the one
            seed = next(seed for ref, seed in calls if ref == failed)
            report(seed, exc)
            queue.extendleft(reversed([s for s in unfinished if s != seed]))
            return
        if len(calls) == 1 or (len(unfinished) == 1 and unfinished[0] in suspects):
            report(unfinished[0], exc)  # it ran alone: it took the worker down
            return
        suspects.update(unfinished)
        queue.extendleft(reversed(unfinished))

    finished = False
    try:
        for _ in range(min(workers, len(seeds))):
            new_actor()
        while running:
            ready, _ = ray.wait(list(running), num_returns=1)
            ref = ready[0]
            actor = running.pop(ref)
            try:
                data = ray.get(ref)
            except (RayTaskError, RayActorError) as exc:
                settle(actor, ref, exc)
                ray.kill(actor)
                if queue:
                    new_actor()
                continue
            calls = inflight[actor]
            calls.remove(next(call for call in calls if call[0] == ref))
            accept(data)
            fill(actor)
        finished = True
    finally:
        for actor in inflight:
            # idle now: the batch's next run takes it
            if not (finished and not started and keep_idle_actor(actor)):
                ray.kill(actor)
        if started:
            ray.shutdown()
    return records, failures


def _describe(exc: BaseException) -> str:
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        return f"{type(cause).__name__}: {cause}"
    first = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {first[0] if first else ''}"


def for_each_seed(
    first_seed: int, episodes: int
) -> list[int]:  # the held-out seeds of an evaluation
    """Seeds ``first_seed``, ``first_seed + 1``, ... (``episodes`` of them)."""
    return list(range(first_seed, first_seed + episodes))


__all__ = [
    "EVALUATIONS",
    "EpisodeTask",
    "Evaluation",
    "RunResult",
    "SeedFailure",
    "for_each_seed",
    "get_evaluation",
    "run_episodes",
]
