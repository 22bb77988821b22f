"""Evaluation of the landing policies over held-out seeds: tables and plots in ``results/``.

``deck-landing evaluate landing --policy NAME [NAME ...] --scenario NAME --episodes N`` runs
each policy for N episodes (seeds ``--seed``, ``--seed + 1``, ...; the training never uses
them) and writes, per scenario, a Markdown and CSV table (success rate with its 95% Wilson
interval, touchdown relative normal speed mean and 95th percentile, deck tilt and lateral
offset at touchdown, time to land), every episode's record and a figure (histogram of the
touchdown speeds per policy, success rates with their intervals).  With a timing policy among
them the ``oracle`` (:mod:`agents.policies.oracle`, the best any timing could do on the same
seeds) runs too, unless ``--no-oracle``: each timing policy's row gives the oracle's
success, the gap in points and how many of its failures the oracle failed as well (no timing
could avoid them).
The oracle foresees the wind's gusts and the sensors' noise as well as the deck; with
``--deck-oracle`` the deck oracle runs too, which foresees the deck alone (the wind and the
noise to come drawn anew in its look-ahead), and each row gives the gap to it as well: the
part of the gap that better deck sensing and prediction could close.

Scenarios are the shipped bench (``bench-ss*``, ``paper-stewart``) and full-scale ship-deck
(``ship-ss*``) configs with the drone flying instead of pinned, the tag
projected analytically (``camera.mode: project``; ``--mode render`` renders and detects it)
and the chosen estimator (``--estimator``, IHRCF by default) in the observation.

``--record FILE.mcap`` records the first policy's first seed on the first scenario (ROS 2
messages, :class:`agents.io.record.McapRecorder`): the worker that runs that seed wraps its
environment for that one episode, so the recording is the episode in the results, whatever
``--workers`` (with ``--address``, the file is written on that worker's machine).  With
``--resume`` that seed runs again even when its result is kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.common.parallel import batch_session
from agents.evaluation.landing_summary import (
    LandingSummary,
    compare_with_oracle,
    is_timing,
    markdown_table,
    plot_results,
    summarise,
)
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.runner import (
    EpisodeTask,
    RunResult,
    SeedFailure,
    for_each_seed,
    run_episodes,
    split_runs,
)
from agents.evaluation.summary import (
    write_summary_files,
)
from agents.policies.registry import (
    env_settings,
    make_env_and_policy,
    scenario_config,
)
from estimation.registry import ESTIMATOR_NAMES
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.scenarios import SCENARIO_IDS, SCENARIOS

#: first held-out seed: training uses seeds from 0 (and its evaluation 900000 on)
HELD_OUT_SEED = 1_000_000
#: the estimators the observation can carry (the registry's names, ``tight`` and ``fused``
#: included)
ESTIMATORS = ESTIMATOR_NAMES


# ------------------------------------------------------------------------------ episodes
@dataclass
class EpisodeResult(EpisodeRecord):
    """One evaluated landing episode: the shared record (:mod:`agents.evaluation.records`)
    and the timing task's wait."""

    #: the timing task's wait before the commit, seconds (NaN for align-descend)
    wait_s: float = math.nan
    #: the timing task's waved-off descents (``timing.wave_off_tilt_deg``)
    wave_offs: int = 0


def run_episode(env: Any, policy: Any, seed: int, policy_name: str, scenario: str) -> EpisodeResult:
    """Run one episode to its end and record the touchdown metrics."""
    observation, info = env.reset(seed=seed)
    if info.get("hold_failed"):
        # the timing task's warm-up hold ended on the deck or in a crash (a ship deck in wind):
        # a failed episode, not a failed evaluation; its one step reports it
        env.step(0)
        return EpisodeResult(
            policy_name, scenario, seed, "hold_failed", False, failed_checks="hold_failed"
        )
    policy.reset()
    while True:
        observation, _, terminated, truncated, info = env.step(policy(observation))
        if terminated or truncated:
            break
    result = EpisodeResult(
        policy=policy_name,
        scenario=scenario,
        seed=seed,
        outcome=info["outcome"],
        success=info["outcome"] == "success",
        wait_s=float(info.get("wait_s", math.nan)),
        wave_offs=int(info.get("wave_offs", 0)),
    )
    result.record_end(info)
    return result


class _LandingEvaluation:
    """``evaluate landing`` for the runner (:mod:`agents.evaluation.runner`)."""

    record_type = EpisodeResult

    def validate(self, task: EpisodeTask) -> None:
        o = task.options
        env_id, overrides = env_settings(
            task.policy,
            task.scenario,
            o.get("estimator"),
            o.get("camera_mode", "project"),
            extra_overrides=o.get("extra_overrides"),
        )
        scenario = SCENARIO_IDS[env_id]
        load_config(scenario_config(task.scenario), {**scenario.overrides, **overrides})

    def make(self, task: EpisodeTask) -> tuple[Any, Any]:
        options = {k: v for k, v in task.options.items() if k != "record"}
        return make_env_and_policy(task.policy, task.scenario, **options)

    def run_episode(self, env: Any, policy: Any, seed: int, task: EpisodeTask) -> EpisodeResult:
        record = task.options.get("record")
        if record is None or seed != record[1]:
            return run_episode(env, policy, seed, task.policy, task.scenario)
        # mcap and rosbags: the optional extra ``io``, imported for the one recorded episode
        from agents.io.record import McapRecorder

        recorder = McapRecorder(env, record[0])
        try:
            return run_episode(recorder, policy, seed, task.policy, task.scenario)
        finally:
            recorder.finish()  # the file closed, the environment kept for the next seed


#: the runner's handle on this evaluation (``EVALUATIONS["landing"]``)
LANDING_EVALUATION = _LandingEvaluation()


def landing_task(
    policy_name: str,
    scenario: str,
    estimator: str | None = None,
    camera_mode: str = "project",
    model_path: str | None = None,
    extra_overrides: dict[str, Any] | None = None,
    allow_mismatch: tuple[str, ...] = (),
    record: tuple[str, int] | None = None,
) -> EpisodeTask:
    """The runner's task for one policy on one scenario; ``record``: (an MCAP file's
    absolute path, the seed whose episode it records)."""
    options: dict[str, Any] = {
        "estimator": estimator,
        "camera_mode": camera_mode,
        "model_path": model_path,
        "extra_overrides": extra_overrides,
        "allow_mismatch": tuple(allow_mismatch),
    }
    if record is not None:
        options["record"] = (str(record[0]), int(record[1]))
    return EpisodeTask("landing", policy_name, scenario, options)


def evaluate_policy(*args: Any, **kwargs: Any) -> list[EpisodeResult]:
    """``episodes`` episodes of one policy on one scenario, over ``workers`` workers: the
    records of :func:`run_policy` (same arguments)."""
    return run_policy(*args, **kwargs).records  # type: ignore[return-value]


def run_policy(
    policy_name: str,
    scenario: str,
    episodes: int,
    first_seed: int = HELD_OUT_SEED,
    estimator: str | None = None,
    camera_mode: str = "project",
    model_path: str | None = None,
    workers: int = 1,
    progress: bool = False,
    extra_overrides: dict[str, Any] | None = None,
    address: str | None = None,
    results_path: Path | None = None,
    resume: bool = False,
    allow_mismatch: tuple[str, ...] = (),
    record: Path | None = None,
) -> RunResult:
    """As :func:`evaluate_policy`, with the failed seeds and how the run went; ``record``:
    an MCAP file for the episode of ``first_seed`` (module doc)."""
    recorded = None if record is None else (str(Path(record).resolve()), first_seed)
    task = landing_task(
        policy_name,
        scenario,
        estimator,
        camera_mode,
        model_path,
        extra_overrides,
        allow_mismatch,
        recorded,
    )
    return run_episodes(
        task,
        for_each_seed(first_seed, episodes),
        workers=workers,
        address=address,
        results_path=results_path,
        resume=resume,
        progress=progress,
        desc=f"{policy_name} @ {scenario}",
        rerun=() if record is None else (first_seed,),
    )


@dataclass
class LandingEvaluation:
    """All policies on one scenario, and where the outputs went."""

    scenario: str
    summaries: list[LandingSummary]
    results: dict[str, list[EpisodeResult]]
    files: list[Path]
    #: seeds whose worker crashed, per policy (the other seeds' results are kept)
    failures: dict[str, list[SeedFailure]] = field(default_factory=dict)


def evaluate_landing(
    policies: list[str],
    scenario: str,
    episodes: int,
    out_dir: Path | None = Path("results/landing"),
    first_seed: int = HELD_OUT_SEED,
    estimator: str | None = None,
    camera_mode: str = "project",
    model_path: str | None = None,
    workers: int = 2,
    progress: bool = True,
    command: str = "",
    extra_overrides: dict[str, Any] | None = None,
    address: str | None = None,
    resume: bool = False,
    oracle: bool = True,
    allow_mismatch: tuple[str, ...] = (),
    deck_oracle: bool = False,
    record: Path | None = None,
) -> LandingEvaluation:
    """Evaluate every policy on ``scenario``; write the table, the episodes and the figure.

    With ``oracle`` and a timing policy among ``policies``, the oracle runs too (last); with
    ``deck_oracle`` the deck oracle too (it knows the deck's future, not the wind's: costlier,
    a look-ahead of several descents at each check).  ``record``: an MCAP file for the first
    policy's episode of ``first_seed`` (module doc)."""
    if episodes < 1:
        raise ConfigError("episodes", f"{episodes} is out of range; allowed [1, inf]")
    timing_policy = any(is_timing(p) for p in policies)
    for wanted, name in ((deck_oracle, "deck-oracle"), (oracle, "oracle")):
        if wanted and timing_policy and name not in policies:
            policies = [*policies, name]
    runs: dict[str, RunResult] = {}
    for name in policies:  # a bad config fails before Ray starts
        task = landing_task(name, scenario, estimator, camera_mode, model_path, extra_overrides)
        LANDING_EVALUATION.validate(task)
    with batch_session(workers, address):
        for name in policies:
            run = run_policy(
                name,
                scenario,
                episodes,
                first_seed,
                estimator,
                camera_mode,
                model_path,
                workers,
                progress,
                extra_overrides,
                address,
                out_dir / f"landing_{scenario}_{name}.jsonl" if out_dir is not None else None,
                resume,
                allow_mismatch,
                record if name == policies[0] else None,
            )
            runs[name] = run
    results, failures = split_runs(runs)
    summaries = [summarise(rs) for rs in results.values()]
    compare_with_oracle(summaries, results)
    files: list[Path] = []
    if out_dir is not None:
        stem = f"landing_{scenario}"
        observed = ", ".join(f"{name}: {_observed(name, scenario, estimator)}" for name in results)
        title = (
            f"{SCENARIOS[scenario].description}; observed {observed}; "
            f"{episodes} held-out episodes per policy (seeds {first_seed}–"
            f"{first_seed + episodes - 1})"
        )
        files = write_summary_files(
            out_dir,
            stem,
            heading=f"Landing: {scenario}",
            title=title,
            table=markdown_table(summaries),
            summaries=summaries,
            results=results,
            failures=failures,
            settings={
                "scenario": scenario,
                "estimator": estimator,
                "camera_mode": camera_mode,
                "first_seed": first_seed,
                "overrides": extra_overrides or {},
            },
            command=command,
        )
        figure = out_dir / f"{stem}.png"
        plot_results(results, summaries, figure, title)
        files.append(figure)
    return LandingEvaluation(scenario, summaries, results, files, failures)


def _observed(policy: str, scenario: str, estimator: str | None) -> str:
    """The estimator ``policy`` observes on ``scenario`` (``estimator``, its own, the id's)."""
    _, overrides = env_settings(policy, scenario, estimator)
    return str(overrides.get("estimation.observed", SCENARIOS[scenario].estimator))
