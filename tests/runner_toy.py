"""A toy evaluation for the runner's tests: no simulation, a crash or an error on request."""

from __future__ import annotations

import os
from typing import Any

from agents.evaluation.records import EpisodeRecord
from agents.evaluation.runner import EpisodeTask
from estimation.errors import ConfigError


class _Env:
    made = 0  # environments made in this process

    def __init__(self) -> None:
        _Env.made += 1
        self.number = _Env.made

    def close(self) -> None:
        pass


class ToyEvaluation:
    record_type = EpisodeRecord

    def validate(self, task: EpisodeTask) -> None:
        if task.options.get("bad_key"):
            raise ConfigError("tof.nosie", "unknown key")

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        if task.options.get("bad_in_worker"):
            raise ConfigError("camera.mode", "'raytrace' is not allowed")
        return _Env(), object()

    def run_episode(self, env: Any, policy: Any, seed: int, task: EpisodeTask) -> EpisodeRecord:
        if seed == task.options.get("crash_seed"):
            os._exit(3)  # the worker process dies
        if seed == task.options.get("raise_seed"):
            raise RuntimeError(f"episode {seed} blew up")
        record = EpisodeRecord(task.policy, task.scenario, seed, "success", True, 0.001 * seed)
        if task.options.get("report_worker"):
            record.failed_checks = f"{os.getpid()}:{env.number}"  # which process, which env
        return record


def square(x: int) -> int:
    """A task for :func:`agents.common.parallel.map_tasks`."""
    return x * x


TOY = ToyEvaluation()
