"""The one policy evaluation pipeline: environment and policy, episode, record, summary, table.

Every evaluation of policies over seeds runs the same steps, and ``evaluate landing``,
``evaluate approach`` and the demo differ only in their configuration:

* :func:`make_episode`: the environment and the policy; a scenario of the table flies its
  registered id with the policy's settings (:func:`agents.policies.registry.make_env_and_policy`),
  any other config, by name or path, the policy's bare task;
* :func:`run_episode`: one episode to its end, as an :class:`EpisodeRecord`; a :class:`Watch`
  sees every step (the approach's trajectory, the demo's log and frames);
* :class:`PolicyEvaluation`: an evaluation for the runner (:mod:`agents.evaluation.runner`,
  serial or Ray), with the columns of its table and files and its figure;
* :func:`evaluate`: every policy over the seeds, each one's summary
  (:class:`~agents.evaluation.summary.Summary`, with the oracles' gap where they ran), and
  :meth:`Evaluated.write`: the table, the JSON summary, the episodes' CSV and the figure.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from agents.common.parallel import batch_session
from agents.evaluation.records import EpisodeRecord, own_fields
from agents.evaluation.runner import (
    EpisodeTask,
    RunResult,
    SeedFailure,
    for_each_seed,
    run_episodes,
    split_runs,
)
from agents.evaluation.summary import (
    Column,
    Summary,
    compare_with_oracle,
    markdown_table,
    summarise,
)
from agents.policies.registry import (
    env_settings,
    make_env_and_policy,
    make_policy,
    policy_spec,
    require_model,
    scenario_config,
)
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.scenarios import APPROACH_SCENARIOS, SCENARIO_IDS, SCENARIOS

#: first held-out seed: training uses seeds from 0 (and its evaluation 900000 on)
HELD_OUT_SEED = 1_000_000


# ------------------------------------------------------------------------------ environment
def is_scenario(name: str) -> bool:
    """Whether ``name`` is a scenario of the table (else a config by name or path)."""
    return name in SCENARIOS or name in APPROACH_SCENARIOS


def env_config(policy: str, scenario: str, options: dict[str, Any]) -> tuple[str, str, dict]:
    """The id ``policy`` flies on ``scenario``, the config, and the overrides laid over it
    (``options``: :func:`make_episode`'s)."""
    estimator, camera_mode = options.get("estimator"), options.get("camera_mode", "project")
    extra = options.get("extra_overrides") or {}
    if is_scenario(scenario):
        env_id, overrides = env_settings(
            policy, scenario, estimator, camera_mode, extra_overrides=extra
        )
        return env_id, scenario_config(scenario), overrides
    overrides = {} if estimator is None else {"estimation.observed": estimator}
    if camera_mode != "project":
        overrides["camera.mode"] = camera_mode
    return policy_spec(policy).task, scenario, {**overrides, **extra}


def make_episode(policy_name: str, scenario: str, **options: Any) -> tuple[Any, Any]:
    """The environment ``policy_name`` flies on ``scenario`` (module doc), and the policy;
    ``options``: :func:`agents.policies.registry.make_env_and_policy`'s keyword arguments."""
    if is_scenario(scenario):
        return make_env_and_policy(policy_name, scenario, **options)
    import gymnasium as gym

    env_id, config, overrides = env_config(policy_name, scenario, options)
    env = gym.make(
        env_id, config=config, overrides=overrides, render_mode=options.get("render_mode")
    )
    try:
        allow = tuple(options.get("allow_mismatch", ()))
        return env, make_policy(policy_name, env, options.get("model_path"), allow)
    except Exception:
        env.close()
        raise


# ------------------------------------------------------------------------------ the episode
class Watch:
    """Sees an episode of :func:`run_episode` step by step (this one does nothing)."""

    def start(self, env: Any, policy: Any, observation: Any, info: dict[str, Any]) -> None:
        """After the reset."""

    def step(self, observation: Any, reward: float, done: bool, info: dict[str, Any]) -> None:
        """After each step."""

    def finish(self, record: EpisodeRecord) -> None:
        """At the end, with the record (to add to it)."""


def run_episode(
    env: Any,
    policy: Any,
    seed: int,
    policy_name: str,
    scenario: str,
    watch: Watch | None = None,
) -> EpisodeRecord:
    """Run one episode to its end and record how it ended and the touchdown metrics."""
    watch = watch or Watch()
    observation, info = env.reset(seed=seed)
    watch.start(env, policy, observation, info)
    if info.get("hold_failed"):
        # the timing task's warm-up hold ended on the deck or in a crash (a ship deck in wind):
        # a failed episode, not a failed evaluation; its one step reports it
        observation, reward, _, _, info = env.step(0)
        watch.step(observation, reward, True, info)
        record = EpisodeRecord(
            policy_name, scenario, seed, "hold_failed", False, failed_checks="hold_failed"
        )
    else:
        policy.reset()
        while True:
            observation, reward, terminated, truncated, info = env.step(policy(observation))
            watch.step(observation, reward, terminated or truncated, info)
            if terminated or truncated:
                break
        record = EpisodeRecord(
            policy_name,
            scenario,
            seed,
            info["outcome"],
            info["outcome"] == "success",
            wait_s=float(info.get("wait_s", math.nan)),
            wave_offs=int(info.get("wave_offs", 0)),
        )
        record.record_end(info)
    watch.finish(record)
    return record


# ------------------------------------------------------------------------------ an evaluation
@dataclass(frozen=True)
class PolicyEvaluation:
    """One configuration of the pipeline, for the runner (``EVALUATIONS``).

    A task's options are :func:`make_episode`'s keyword arguments, and ``record``: (an
    MCAP file's absolute path, the seed whose episode it records)."""

    #: the runner's name of it, the stem of its files, and the mark of the fields of the
    #: record and the summary that it alone fills (:func:`agents.evaluation.records.own_fields`)
    name: str
    #: the table's first word ("Landing: bench-ss4")
    heading: str
    #: the columns of its table (:data:`agents.evaluation.summary.COLUMNS`)
    columns: tuple[Column, ...]
    #: its figure: (the evaluation, the PNG's path, the title)
    plot: Callable[[Evaluated, Path, str], None]
    #: a watch of each episode (its own record columns)
    watch: Callable[[EpisodeTask], Watch] = lambda task: Watch()

    record_type: ClassVar[type[EpisodeRecord]] = EpisodeRecord

    def validate(self, task: EpisodeTask) -> None:
        """Build the task's config (a bad key raises ConfigError before any worker starts)."""
        require_model(task.policy, task.options.get("model_path"))
        env_id, config, overrides = env_config(task.policy, task.scenario, task.options)
        scenario = SCENARIO_IDS.get(env_id)
        load_config(config, {**(scenario.overrides if scenario else {}), **overrides})

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        options = {k: v for k, v in task.options.items() if k != "record"}
        return make_episode(task.policy, task.scenario, **options)

    def run_episode(self, env: Any, policy: Any, seed: int, task: EpisodeTask) -> EpisodeRecord:
        record = task.options.get("record")
        watch = self.watch(task)
        if record is None or seed != record[1]:
            return run_episode(env, policy, seed, task.policy, task.scenario, watch)
        # mcap and rosbags: the optional extra ``io``, imported for the one recorded episode
        from agents.io.record import McapRecorder

        recorder = McapRecorder(env, record[0])
        try:
            return run_episode(recorder, policy, seed, task.policy, task.scenario, watch)
        finally:
            recorder.finish()  # the file closed, the environment kept for the next seed

    def stem(self, scenario: str) -> str:
        """The files' stem: ``landing_bench-ss4``."""
        return f"{self.name}_{Path(scenario).stem}"


def run_task(
    task: EpisodeTask,
    seeds: list[int],
    workers: int = 1,
    progress: bool = False,
    address: str | None = None,
    results_path: Path | None = None,
    resume: bool = False,
) -> RunResult:
    """The task's episodes over ``workers`` workers (Ray beyond one); the recorded seed runs
    even when ``resume`` keeps its result."""
    record = task.options.get("record")
    return run_episodes(
        task,
        seeds,
        workers=workers,
        address=address,
        results_path=results_path,
        resume=resume,
        progress=progress,
        desc=f"{task.policy} @ {task.scenario}",
        rerun=() if record is None else (record[1],),
    )


@dataclass
class Evaluated:
    """Every policy on one scenario, and where the outputs went."""

    evaluation: PolicyEvaluation
    scenario: str
    summaries: list[Summary]
    results: dict[str, list[EpisodeRecord]]
    #: seeds whose worker crashed, per policy (the other seeds' results are kept)
    failures: dict[str, list[SeedFailure]] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)

    @property
    def table(self) -> str:
        """The Markdown table, one row per policy."""
        return markdown_table(self.summaries, self.evaluation.columns)

    def failures_note(self) -> str:
        """A line per crashed seed (empty when none crashed)."""
        if not self.failures:
            return ""
        lines = ["", "Seeds whose worker crashed (not in the table):", ""]
        for name, fs in self.failures.items():
            lines += [f"- {name}, seed {f.seed}: {f.error}" for f in fs]
        return "\n".join(lines) + "\n"

    def show(self, heading: str) -> None:
        """The table, the crashed seeds and the files written, on the console."""
        from rich.console import Console

        console = Console()
        console.print(f"\n[bold]{heading}[/bold]")
        print(self.table)
        if self.failures:
            console.print(self.failures_note(), style="yellow")
        for path in self.files:
            console.print(f"  wrote {path}")

    def write(
        self,
        out_dir: Path,
        title: str,
        settings: dict[str, Any],
        command: str = "",
        notes: str = "",
    ) -> list[Path]:
        """Write ``STEM.md`` (heading, title, command, table, notes, crashed seeds),
        ``STEM.json`` (``settings``, the command and the summaries), ``STEM_episodes.csv``
        (one row per episode) and the figure ``STEM.png``: :attr:`files`."""
        e = self.evaluation
        out_dir.mkdir(parents=True, exist_ok=True)
        stem = out_dir / e.stem(self.scenario)
        markdown, summary, episodes, figure = (
            Path(f"{stem}{end}") for end in (".md", ".json", "_episodes.csv", ".png")
        )
        markdown.write_text(
            f"# {e.heading}: {self.scenario}\n\n{title}\n\n"
            + (f"Command: `{command}`\n\n" if command else "")
            + f"{self.table}\n"
            + (f"\n{notes}\n" if notes else "")
            + self.failures_note()
        )
        fields = own_fields(Summary, e.name)
        summaries = [{k: getattr(s, k) for k in fields} for s in self.summaries]
        summary.write_text(
            json.dumps({**settings, "command": command, "summaries": summaries}, indent=2)
        )
        with episodes.open("w", newline="") as handle:
            columns = own_fields(EpisodeRecord, e.name)
            writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
            writer.writeheader()
            for records in self.results.values():
                writer.writerows(asdict(r) for r in records)
        e.plot(self, figure, title)
        self.files = [markdown, summary, episodes, figure]
        return self.files


def evaluate(
    evaluation: PolicyEvaluation,
    tasks: Sequence[EpisodeTask],
    seeds: list[int],
    out_dir: Path | None = None,
    workers: int = 1,
    progress: bool = False,
    address: str | None = None,
    resume: bool = False,
) -> Evaluated:
    """Every task (one a policy, on one scenario) over ``seeds``; each policy's episodes go to
    ``OUT_DIR/STEM_POLICY.jsonl`` as they come, and its summary is compared with the oracles
    where they ran (:func:`agents.evaluation.summary.compare_with_oracle`)."""
    for task in tasks:  # a bad config fails before Ray starts
        evaluation.validate(task)
    runs: dict[str, RunResult] = {}
    with batch_session(workers, address):
        for task in tasks:
            path = None
            if out_dir is not None:
                path = out_dir / f"{evaluation.stem(task.scenario)}_{task.policy}.jsonl"
            runs[task.policy] = run_task(task, seeds, workers, progress, address, path, resume)
    results, failures = split_runs(runs)
    summaries = [summarise(records) for records in results.values()]
    compare_with_oracle(summaries, results)
    return Evaluated(evaluation, tasks[0].scenario, summaries, results, failures)


def held_out_seeds(first_seed: int, episodes: int) -> list[int]:
    """``episodes`` seeds from ``first_seed``; a clear error for fewer than one."""
    if episodes < 1:
        raise ConfigError("episodes", f"{episodes} is out of range; allowed [1, inf]")
    return for_each_seed(first_seed, episodes)
