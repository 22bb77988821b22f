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
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.pipeline import (
    HELD_OUT_SEED,
    Evaluated,
    PolicyEvaluation,
    env_config,
    evaluate,
    held_out_seeds,
    run_episode,
    run_task,
)
from agents.evaluation.plots import pyplot
from agents.evaluation.records import EpisodeRecord
from agents.evaluation.runner import EpisodeTask, RunResult
from agents.evaluation.summary import columns, is_timing
from agents.policies.registry import make_env_and_policy
from landing_env.config import TouchdownConfig
from landing_env.scenarios import SCENARIOS


def plot_results(evaluated: Evaluated, path: Path, title: str) -> None:
    """Histograms of the touchdown's relative normal speed and deck tilt per policy (with the
    touchdown checks' limits), and success rates with their intervals."""
    plt = pyplot()

    results, summaries = evaluated.results, evaluated.summaries
    limits = TouchdownConfig()
    fig, (ax_speed, ax_tilt, ax_bar) = plt.subplots(1, 3, figsize=(16, 4.8))
    for ax, field_name, limit, label, heading in (
        (
            ax_speed,
            "relative_normal_speed",
            limits.max_normal_speed,
            "relative normal speed at touchdown (m/s)",
            "Touchdown speeds",
        ),
        (
            ax_tilt,
            "deck_tilt_deg",
            limits.max_deck_tilt_deg,
            "deck tilt at touchdown (deg)",
            "Deck tilt",
        ),
    ):
        values_all = [
            getattr(r, field_name)
            for rs in results.values()
            for r in rs
            if math.isfinite(getattr(r, field_name))
        ]
        bins = np.linspace(0.0, max([limit * 1.3, *values_all]), 31)
        for name, rs in results.items():
            values = [getattr(r, field_name) for r in rs if math.isfinite(getattr(r, field_name))]
            ax.hist(values, bins=bins, histtype="step", linewidth=1.8, label=name)
        ax.axvline(limit, color="k", linestyle="--", linewidth=1, label="success limit")
        ax.set(xlabel=label, ylabel="episodes", title=heading)
        ax.legend(fontsize="small")
    names = [s.policy for s in summaries]
    rates = np.array([100 * s.success_rate for s in summaries])
    errors = np.array(
        [
            [100 * (s.success_rate - s.success_ci_low) for s in summaries],
            [100 * (s.success_ci_high - s.success_rate) for s in summaries],
        ]
    )
    ax_bar.bar(names, rates, yerr=errors, capsize=6, color="tab:blue", alpha=0.8)
    for i, rate in enumerate(rates):
        ax_bar.text(i, 2, f"{rate:.1f}%", ha="center", color="white", fontweight="bold")
    ax_bar.set(ylim=(0, 105), ylabel="success rate (%)", title="Success with 95% Wilson interval")
    ax_bar.tick_params(axis="x", labelrotation=20 if len(names) > 3 else 0)
    fig.suptitle(textwrap.fill(title, 170), fontsize="medium")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: the runner's handle on this evaluation (``EVALUATIONS["landing"]``)
LANDING_EVALUATION = PolicyEvaluation(
    name="landing",
    heading="Landing",
    columns=columns(
        "policy", "episodes", "success (95% CI)", "v_n mean (m/s)", "v_n p95 (m/s)",
        "tilt mean / p95 (deg)", "offset mean (m)", "time to land (s)", "wave-offs",
        "bounce p95 (mm)", "peak load p95 (g)", "outcomes", "failed checks", "oracle",
        "gap (points)", "failures no timing avoids", "deck oracle", "gap to deck oracle",
    ),
    plot=plot_results,
)  # fmt: skip


def landing_task(
    policy_name: str,
    scenario: str,
    estimator: str | None = None,
    *,
    record: tuple[str, int] | None = None,
    **options: Any,
) -> EpisodeTask:
    """The runner's task for one policy on one scenario; ``options``: the rest of
    :func:`~agents.evaluation.pipeline.make_episode`'s (camera_mode, model_path,
    extra_overrides, allow_mismatch); ``record``: (an MCAP file's absolute path, the seed whose
    episode it records)."""
    options["estimator"] = estimator
    if record is not None:
        options["record"] = (str(record[0]), int(record[1]))
    return EpisodeTask("landing", policy_name, scenario, options)


def evaluate_policy(*args: Any, **kwargs: Any) -> list[EpisodeRecord]:
    """``episodes`` episodes of one policy on one scenario, over ``workers`` workers: the
    records of :func:`run_policy` (same arguments)."""
    return run_policy(*args, **kwargs).records


def run_policy(
    policy_name: str,
    scenario: str,
    episodes: int,
    first_seed: int = HELD_OUT_SEED,
    estimator: str | None = None,
    *,
    workers: int = 1,
    progress: bool = False,
    address: str | None = None,
    results_path: Path | None = None,
    resume: bool = False,
    **options: Any,
) -> RunResult:
    """One policy's episodes on one scenario, with the failed seeds and how the run went;
    ``options``: :func:`landing_task`'s."""
    task = landing_task(policy_name, scenario, estimator, **options)
    seeds = held_out_seeds(first_seed, episodes)
    return run_task(task, seeds, workers, progress, address, results_path, resume)


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
) -> Evaluated:
    """Evaluate every policy on ``scenario``; write the table, the episodes and the figure.

    With ``oracle`` and a timing policy among ``policies``, the oracle runs too (last); with
    ``deck_oracle`` the deck oracle too (it knows the deck's future, not the wind's: costlier,
    a look-ahead of several descents at each check).  ``record``: an MCAP file for the first
    policy's episode of ``first_seed`` (module doc)."""
    seeds = held_out_seeds(first_seed, episodes)
    timing_policy = any(is_timing(p) for p in policies)
    for wanted, name in ((deck_oracle, "deck-oracle"), (oracle, "oracle")):
        if wanted and timing_policy and name not in policies:
            policies = [*policies, name]
    recorded = None if record is None else (str(Path(record).resolve()), first_seed)
    options = {
        "camera_mode": camera_mode,
        "model_path": model_path,
        "extra_overrides": extra_overrides,
        "allow_mismatch": tuple(allow_mismatch),
    }
    tasks = [
        landing_task(name, scenario, estimator, record=recorded if i == 0 else None, **options)
        for i, name in enumerate(policies)
    ]
    evaluated = evaluate(
        LANDING_EVALUATION, tasks, seeds, out_dir, workers, progress, address, resume
    )
    if out_dir is not None:
        observed = ", ".join(
            f"{name}: {_observed(name, scenario, estimator)}" for name in evaluated.results
        )
        title = (
            f"{SCENARIOS[scenario].description}; observed {observed}; "
            f"{episodes} held-out episodes per policy (seeds {first_seed}–"
            f"{first_seed + episodes - 1})"
        )
        settings = {
            "scenario": scenario,
            "estimator": estimator,
            "camera_mode": camera_mode,
            "first_seed": first_seed,
            "overrides": extra_overrides or {},
        }
        evaluated.write(out_dir, title, settings, command)
    return evaluated


def _observed(policy: str, scenario: str, estimator: str | None) -> str:
    """The estimator ``policy`` observes on ``scenario`` (``estimator``, its own, the id's)."""
    overrides = env_config(policy, scenario, {"estimator": estimator})[2]
    return str(overrides.get("estimation.observed", SCENARIOS[scenario].estimator))


__all__ = [
    "HELD_OUT_SEED",
    "LANDING_EVALUATION",
    "evaluate_landing",
    "evaluate_policy",
    "landing_task",
    "make_env_and_policy",
    "run_episode",
    "run_policy",
]
