"""Jobs in parallel: Ray on this machine or a cluster, or in this process for one worker.

:func:`map_tasks` maps a function over items (Ray tasks); :func:`batch_session` keeps one Ray
runtime, and the idle actors of a batch of runs, over several runs
(:mod:`agents.evaluation.runner` runs episodes on these actors); :func:`ensure_ray` starts Ray
or connects to a cluster.  A user error raised in a worker reaches the caller with its message
(:func:`user_error_behind`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from agents.common.user_input import USER_ERRORS


def ensure_ray(address: str | None, workers: int) -> bool:
    """Start Ray (this machine, ``workers`` CPUs) or connect to ``address``; True if this
    call started it (the caller shuts it down)."""
    import os

    import ray

    if ray.is_initialized():
        return False
    kwargs: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": True,
        "configure_logging": False,
    }
    if address is None:
        # workers import this checkout's packages (its root on their path)
        root = str(Path(__file__).resolve().parents[2])
        pythonpath = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
        kwargs["num_cpus"] = workers
        kwargs["runtime_env"] = {"env_vars": {"PYTHONPATH": pythonpath}}
        # Ray runs its workers at nice 15 (a cluster keeps its control plane responsive so);
        # here they are the job the user asked for, at the user's priority as the former
        # process pool's were, not behind every other process of the batch
        kwargs["_system_config"] = {"worker_niceness": 0}
    ray.init(address=address, **kwargs)
    return True


#: the idle actors of the current :func:`batch_session` (None outside one): a batch's
#: later runs (the next policy) take them instead of starting worker processes again
_IDLE_ACTORS: list[Any] | None = None


@contextlib.contextmanager
def batch_session(workers: int, address: str | None) -> Iterator[None]:
    """Keep one Ray runtime, and its workers, over several
    :func:`~agents.evaluation.runner.run_episodes` calls
    (several policies) when the job uses Ray; shut it down at the end if this started it."""
    global _IDLE_ACTORS
    started = False
    uses_ray = address is not None or workers > 1
    if uses_ray:
        started = ensure_ray(address, workers)
    outer = _IDLE_ACTORS
    if uses_ray and outer is None:
        _IDLE_ACTORS = []
    try:
        yield
    finally:
        if uses_ray and outer is None:
            release_idle_actors()
            _IDLE_ACTORS = None
        if started:
            import ray

            ray.shutdown()


def release_idle_actors() -> None:
    """Kill the batch's idle actors (they hold a CPU each that a task may need)."""
    if not _IDLE_ACTORS:
        return
    import ray

    while _IDLE_ACTORS:
        ray.kill(_IDLE_ACTORS.pop())


def take_idle_actor() -> Any:
    """An idle actor of the current :func:`batch_session` (None when there is none)."""
    return _IDLE_ACTORS.pop() if _IDLE_ACTORS else None


def keep_idle_actor(actor: Any) -> bool:
    """Keep ``actor`` for the batch's next run; False outside a :func:`batch_session`."""
    if _IDLE_ACTORS is None:
        return False
    _IDLE_ACTORS.append(actor)
    return True


def map_tasks(
    fn: Callable[[Any], Any],
    items: list[Any],
    *,
    workers: int = 1,
    address: str | None = None,
    progress: bool = False,
    desc: str = "",
) -> list[Any]:
    """``[fn(item) for item in items]``: in this process for one local worker, else as Ray
    tasks (``fn`` top level, items picklable), results in the items' order, the progress bar
    moving as each arrives.  A user error (ConfigError...) raised in a task is raised here
    with its message; the other tasks are cancelled."""
    from tqdm import tqdm

    bar = tqdm(total=len(items), desc=desc, unit="run", disable=not progress)
    try:
        if address is None and (workers == 1 or len(items) <= 1):
            out = []
            for item in items:
                out.append(fn(item))
                bar.update(1)
            return out
        import ray
        from ray.exceptions import RayTaskError

        with batch_session(workers, address):
            release_idle_actors()  # their CPUs are the tasks'
            remote = ray.remote(num_cpus=1, max_retries=0)(fn)
            refs = [remote.remote(item) for item in items]
            index = {ref: i for i, ref in enumerate(refs)}
            results: list[Any] = [None] * len(items)
            pending = list(refs)
            try:
                while pending:
                    ready, pending = ray.wait(pending, num_returns=1)
                    try:
                        results[index[ready[0]]] = ray.get(ready[0])
                    except RayTaskError as exc:
                        cause = user_error_behind(exc)
                        raise (cause or exc) from None
                    bar.update(1)
            finally:
                for ref in pending:
                    ray.cancel(ref, force=True)
            return results
    finally:
        bar.close()


def user_error_behind(exc: BaseException) -> BaseException | None:
    """The user error (a ConfigError, a missing file) behind a Ray error, if any: the
    worker's own exception, whose message is the user's one line (Ray's error, typed as
    both, carries the worker's traceback in its message)."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        cause = getattr(current, "cause", None)
        if isinstance(cause, BaseException):
            current = cause
            continue
        if isinstance(current, USER_ERRORS):
            return current
        current = current.__cause__
    return None
