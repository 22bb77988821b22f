"""Evaluation of the landing policies over held-out seeds: tables and plots in ``results/``.

``deck-landing evaluate landing --policy NAME [NAME ...] --scenario NAME --episodes N`` runs
each policy for N episodes (seeds ``--seed``, ``--seed + 1``, ...; the training never uses
them) and writes, per scenario, a Markdown and CSV table (success rate with its 95% Wilson
interval, touchdown relative normal speed mean and 95th percentile, deck tilt and lateral
offset at touchdown, time to land), every episode's record and a figure (histogram of the
touchdown speeds per policy, success rates with their intervals).  With a timing policy among
them the ``oracle`` (:mod:`agents.oracle`, the best any timing could do on the same seeds) runs
too, unless ``--no-oracle``: each timing policy's row gives the oracle's success, the gap in
points and how many of its failures the oracle failed as well (no timing could avoid them).

Scenarios are the shipped bench configs with the drone flying instead of pinned, the tag
projected analytically (``camera.mode: project``; ``--mode render`` renders and detects it)
and the chosen estimator (``--estimator``, IHRCF by default) in the observation.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation import _parse_overrides
from agents.evaluation.parallel import run_seed_chunks
from landing_env.errors import ConfigError, require_choice

#: first held-out seed: training uses seeds from 0 (and its evaluation 900000 on)
HELD_OUT_SEED = 1_000_000
ESTIMATORS = ("ihrcf", "crhf", "atda", "truth")


@dataclass(frozen=True)
class Scenario:
    """A landing scenario: a shipped config and what it shows."""

    config: str
    description: str


SCENARIOS: dict[str, Scenario] = {
    "sea-state-3": Scenario("sea-state-3", "JONSWAP sea state 3 (Hs 0.88 m, Tp 7.5 s)"),
    "sea-state-4": Scenario("sea-state-4", "JONSWAP sea state 4 (Hs 1.88 m, Tp 8.8 s)"),
    "sea-state-5": Scenario("sea-state-5", "JONSWAP sea state 5 (Hs 3.25 m, Tp 9.7 s)"),
    "paper-stewart": Scenario("paper-stewart", "the papers' Stewart bench (sums of sinusoids)"),
}

#: what turns a bench config into a landing scenario
FLYING_OVERRIDES: dict[str, Any] = {
    "simulation.drone_fixed": False,
    "simulation.max_episode_s": 40.0,
    "estimation.compare": [],
}
#: starts: the timing task starts at its hold height; align-descend far and off the deck
START_OVERRIDES: dict[str, dict[str, Any]] = {
    "DeckLandingTiming-v0": {"start.max_offset_m": 0.1, "start.max_yaw_deg": 10.0},
    "DeckLanding-v0": {
        "start.height_m": [1.5, 4.0],
        "start.max_offset_m": 1.0,
        "start.max_yaw_deg": 30.0,
    },
}


def scenario_overrides(
    scenario: str, env_id: str, estimator: str = "ihrcf", camera_mode: str = "project"
) -> dict[str, Any]:
    """The dotted overrides that make ``scenario``'s config a landing run of ``env_id``."""
    require_choice("scenario", scenario, tuple(SCENARIOS))
    require_choice("estimator", estimator, ESTIMATORS)
    require_choice("mode", camera_mode, ("project", "render"))
    return {
        **FLYING_OVERRIDES,
        **START_OVERRIDES[env_id],
        "estimation.observed": estimator,
        "camera.mode": camera_mode,
    }


# ------------------------------------------------------------------------------ episodes
@dataclass
class EpisodeResult:
    """One evaluated episode (NaN where a metric does not exist, e.g. after a crash)."""

    policy: str
    scenario: str
    seed: int
    outcome: str
    success: bool
    relative_normal_speed: float = math.nan
    deck_tilt_deg: float = math.nan
    lateral_offset_m: float = math.nan
    relative_attitude_deg: float = math.nan
    #: simulated time from the episode start to the touchdown, seconds
    time_to_land_s: float = math.nan
    #: the timing task's wait before the commit, seconds (NaN for align-descend)
    wait_s: float = math.nan
    failed_checks: str = ""


def make_env_and_policy(
    policy_name: str,
    scenario: str,
    estimator: str = "ihrcf",
    camera_mode: str = "project",
    model_path: str | None = None,
    render_mode: str | None = None,
    extra_overrides: dict[str, Any] | None = None,
    allow_mismatch: tuple[str, ...] = (),
) -> tuple[Any, Any]:
    """The environment the policy acts in, configured for ``scenario``, and the policy.

    ``extra_overrides`` (dotted keys) apply last, e.g. ``{"tof.noise": "vl53l1x"}``;
    ``allow_mismatch``: fields of a trained model's card that may differ from the environment.
    """
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the environments)
    from agents.policies import POLICY_ENVS, make_policy

    require_choice("policy", policy_name, tuple(POLICY_ENVS))
    env_id = POLICY_ENVS[policy_name]
    overrides = {
        **scenario_overrides(scenario, env_id, estimator, camera_mode),
        **(extra_overrides or {}),
    }
    env = gym.make(
        env_id, config=SCENARIOS[scenario].config, overrides=overrides, render_mode=render_mode
    )
    try:
        policy = make_policy(policy_name, env, model_path, tuple(allow_mismatch))
    except Exception:
        env.close()
        raise
    return env, policy


def run_episode(env: Any, policy: Any, seed: int, policy_name: str, scenario: str) -> EpisodeResult:
    """Run one episode to its end and record the touchdown metrics."""
    observation, info = env.reset(seed=seed)
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
    )
    touchdown = info.get("touchdown")
    if touchdown:
        result.relative_normal_speed = float(touchdown["relative_normal_speed"])
        result.deck_tilt_deg = float(touchdown["deck_tilt_deg"])
        result.lateral_offset_m = float(touchdown["lateral_offset_m"])
        result.relative_attitude_deg = float(touchdown["relative_attitude_deg"])
        result.time_to_land_s = float(touchdown["time_s"])
        result.failed_checks = ";".join(touchdown["failed_checks"])
    elif "crash_contact" in info:
        result.failed_checks = str(info["crash_contact"])
    return result


def _run_chunk(job: tuple) -> list[EpisodeResult]:
    """Worker: one environment, a list of seeds (top level, so that it pickles)."""
    policy_name, scenario, seeds, estimator, camera_mode, model_path, extra, allow = job
    env, policy = make_env_and_policy(
        policy_name,
        scenario,
        estimator,
        camera_mode,
        model_path,
        extra_overrides=extra,
        allow_mismatch=allow,
    )
    try:
        return [run_episode(env, policy, seed, policy_name, scenario) for seed in seeds]
    finally:
        env.close()


def evaluate_policy(
    policy_name: str,
    scenario: str,
    episodes: int,
    first_seed: int = HELD_OUT_SEED,
    estimator: str = "ihrcf",
    camera_mode: str = "project",
    model_path: str | None = None,
    workers: int = 1,
    progress: bool = False,
    extra_overrides: dict[str, Any] | None = None,
    allow_mismatch: tuple[str, ...] = (),
) -> list[EpisodeResult]:
    """``episodes`` episodes of one policy on one scenario, over ``workers`` processes."""
    return run_seed_chunks(
        _run_chunk,
        lambda chunk: (
            policy_name,
            scenario,
            chunk,
            estimator,
            camera_mode,
            model_path,
            extra_overrides,
            tuple(allow_mismatch),
        ),
        list(range(first_seed, first_seed + episodes)),
        workers,
        max_chunk=25,
        desc=f"{policy_name} @ {scenario}",
        progress=progress,
    )


# ------------------------------------------------------------------------------ summaries
def wilson_interval(successes: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (scipy's ``binomtest``)."""
    from scipy.stats import binomtest

    if trials == 0:
        return math.nan, math.nan
    ci = binomtest(successes, trials).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def _mean(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(values.mean()) if values.size else math.nan


def _p95(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.percentile(values, 95)) if values.size else math.nan


@dataclass
class LandingSummary:
    """One policy on one scenario; touchdown metrics over the episodes that touched down."""

    policy: str
    scenario: str
    episodes: int
    successes: int
    success_rate: float
    success_ci_low: float
    success_ci_high: float
    normal_speed_mean: float
    normal_speed_p95: float
    deck_tilt_mean_deg: float
    deck_tilt_p95_deg: float
    lateral_offset_mean_m: float
    time_to_land_mean_s: float
    outcomes: dict[str, int] = field(default_factory=dict)
    #: the oracle's success on the same seeds (NaN without it or outside the timing task)
    oracle_success_rate: float = math.nan
    #: oracle minus this policy, percentage points
    gap_points: float = math.nan
    #: this policy's failures on seeds where the oracle failed too: no timing avoids them
    unavoidable_failures: int = 0


def compare_with_oracle(
    summaries: list[LandingSummary], results: dict[str, list[EpisodeResult]]
) -> None:
    """Fill in the oracle's columns of the timing policies' summaries (seed by seed)."""
    from agents.policies import POLICY_ENVS

    oracle = results.get("oracle")
    if not oracle:
        return
    oracle_success = {r.seed: r.success for r in oracle}
    rate = sum(oracle_success.values()) / len(oracle_success)
    for summary in summaries:
        if POLICY_ENVS.get(summary.policy) != POLICY_ENVS["oracle"]:
            continue
        summary.oracle_success_rate = rate
        summary.gap_points = 100.0 * (rate - summary.success_rate)
        summary.unavoidable_failures = sum(
            1
            for r in results[summary.policy]
            if not r.success and oracle_success.get(r.seed) is False
        )


def summarise(results: list[EpisodeResult]) -> LandingSummary:
    """The figures of the table for the episodes of one policy on one scenario."""
    if not results:
        raise ValueError("no episodes to summarise")
    n = len(results)
    k = sum(r.success for r in results)
    low, high = wilson_interval(k, n)

    def column(name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in results], dtype=float)

    return LandingSummary(
        policy=results[0].policy,
        scenario=results[0].scenario,
        episodes=n,
        successes=k,
        success_rate=k / n,
        success_ci_low=low,
        success_ci_high=high,
        normal_speed_mean=_mean(column("relative_normal_speed")),
        normal_speed_p95=_p95(column("relative_normal_speed")),
        deck_tilt_mean_deg=_mean(column("deck_tilt_deg")),
        deck_tilt_p95_deg=_p95(column("deck_tilt_deg")),
        lateral_offset_mean_m=_mean(column("lateral_offset_m")),
        time_to_land_mean_s=_mean(column("time_to_land_s")),
        outcomes=dict(Counter(r.outcome for r in results)),
    )


TABLE_HEADER = (
    "policy",
    "episodes",
    "success (95% CI)",
    "v_n mean (m/s)",
    "v_n p95 (m/s)",
    "tilt mean / p95 (deg)",
    "offset mean (m)",
    "time to land (s)",
    "outcomes",
    "oracle",
    "gap (points)",
    "failures no timing avoids",
)


def markdown_table(summaries: list[LandingSummary]) -> str:
    """The summaries as a Markdown table (one row per policy)."""
    lines = [
        "| " + " | ".join(TABLE_HEADER) + " |",
        "|" + "|".join("---" for _ in TABLE_HEADER) + "|",
    ]
    for s in summaries:
        outcomes = ", ".join(f"{k} {v}" for k, v in sorted(s.outcomes.items()))
        cells = (
            s.policy,
            str(s.episodes),
            f"{100 * s.success_rate:.1f}% ({100 * s.success_ci_low:.1f}–"
            f"{100 * s.success_ci_high:.1f})",
            f"{s.normal_speed_mean:.3f}",
            f"{s.normal_speed_p95:.3f}",
            f"{s.deck_tilt_mean_deg:.2f} / {s.deck_tilt_p95_deg:.2f}",
            f"{s.lateral_offset_mean_m:.3f}",
            f"{s.time_to_land_mean_s:.2f}",
            outcomes,
            *(
                (
                    f"{100 * s.oracle_success_rate:.1f}%",
                    f"{s.gap_points:+.1f}",
                    f"{s.unavoidable_failures} of {s.episodes - s.successes}",
                )
                if math.isfinite(s.oracle_success_rate)
                else ("", "", "")
            ),
        )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_results(
    results: dict[str, list[EpisodeResult]],
    summaries: list[LandingSummary],
    path: Path,
    title: str,
    speed_limit: float = 0.5,
) -> None:
    """Histogram of touchdown speeds per policy, and success rates with their intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_hist, ax_bar) = plt.subplots(1, 2, figsize=(13, 4.5))
    speeds_all = [
        r.relative_normal_speed
        for rs in results.values()
        for r in rs
        if math.isfinite(r.relative_normal_speed)
    ]
    high = max([speed_limit * 1.3, *speeds_all])
    bins = np.linspace(0.0, high, 31)
    for name, rs in results.items():
        speeds = [r.relative_normal_speed for r in rs if math.isfinite(r.relative_normal_speed)]
        ax_hist.hist(speeds, bins=bins, histtype="step", linewidth=1.8, label=name)
    ax_hist.axvline(speed_limit, color="k", linestyle="--", linewidth=1, label="success limit")
    ax_hist.set(
        xlabel="relative normal speed at touchdown (m/s)",
        ylabel="episodes",
        title="Touchdown speeds",
    )
    ax_hist.legend()
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
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


@dataclass
class LandingEvaluation:
    """All policies on one scenario, and where the outputs went."""

    scenario: str
    summaries: list[LandingSummary]
    results: dict[str, list[EpisodeResult]]
    files: list[Path]


def evaluate_landing(
    policies: list[str],
    scenario: str,
    episodes: int,
    out_dir: Path | None = Path("results/landing"),
    first_seed: int = HELD_OUT_SEED,
    estimator: str = "ihrcf",
    camera_mode: str = "project",
    model_path: str | None = None,
    workers: int = 2,
    progress: bool = True,
    command: str = "",
    extra_overrides: dict[str, Any] | None = None,
    oracle: bool = True,
    allow_mismatch: tuple[str, ...] = (),
) -> LandingEvaluation:
    """Evaluate every policy on ``scenario``; write the table, the episodes and the figure.

    With ``oracle`` and a timing policy among ``policies``, the oracle runs too (last)."""
    from agents.policies import POLICY_ENVS

    if episodes < 1:
        raise ConfigError("episodes", f"{episodes} is out of range; allowed [1, inf]")
    timing_env = POLICY_ENVS["oracle"]
    if oracle and "oracle" not in policies and timing_env in {POLICY_ENVS[p] for p in policies}:
        policies = [*policies, "oracle"]
    results: dict[str, list[EpisodeResult]] = {}
    for name in policies:
        results[name] = evaluate_policy(
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
            allow_mismatch,
        )
    summaries = [summarise(rs) for rs in results.values()]
    compare_with_oracle(summaries, results)
    files: list[Path] = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        stem = f"landing_{scenario}"
        title = (
            f"{SCENARIOS[scenario].description}; {estimator.upper()} in the observation; "
            f"{episodes} held-out episodes per policy (seeds {first_seed}–"
            f"{first_seed + episodes - 1})"
        )
        table = out_dir / f"{stem}.md"
        table.write_text(
            f"# Landing: {scenario}\n\n{title}\n\n"
            + (f"Command: `{command}`\n\n" if command else "")
            + markdown_table(summaries)
            + "\n"
        )
        summary_json = out_dir / f"{stem}.json"
        summary_json.write_text(
            json.dumps(
                {
                    "scenario": scenario,
                    "estimator": estimator,
                    "camera_mode": camera_mode,
                    "first_seed": first_seed,
                    "overrides": extra_overrides or {},
                    "command": command,
                    "summaries": [asdict(s) for s in summaries],
                },
                indent=2,
            )
        )
        episodes_csv = out_dir / f"{stem}_episodes.csv"
        with episodes_csv.open("w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(asdict(results[policies[0]][0])))
            writer.writeheader()
            for rs in results.values():
                writer.writerows(asdict(r) for r in rs)
        figure = out_dir / f"{stem}.png"
        plot_results(results, summaries, figure, title)
        files = [table, summary_json, episodes_csv, figure]
    return LandingEvaluation(scenario, summaries, results, files)


# ------------------------------------------------------------------------------ command line
def _evaluate_landing(args: argparse.Namespace) -> int:
    import shlex
    import sys

    from rich.console import Console

    from agents.policies import POLICY_NAMES

    console = Console()
    policies = list(POLICY_NAMES) if args.policy == ["all"] else args.policy
    command = "deck-landing " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    for scenario in args.scenario:
        evaluation = evaluate_landing(
            policies,
            scenario,
            args.episodes,
            Path(args.out),
            args.seed,
            args.estimator,
            args.mode,
            args.model,
            args.workers,
            progress=not args.no_progress,
            command=command,
            extra_overrides=_parse_overrides(args.set),
            oracle=not args.no_oracle,
            allow_mismatch=tuple(args.allow_mismatch),
        )
        console.print(f"\n[bold]{scenario}[/bold]: {SCENARIOS[scenario].description}")
        print(markdown_table(evaluation.summaries))
        for path in evaluation.files:
            console.print(f"  wrote {path}")
    return 0


def add_landing_parser(evaluate_group: Any) -> None:
    """Add ``landing`` to the ``evaluate`` sub-command group."""
    from agents.policies import POLICY_NAMES

    landing = evaluate_group.add_parser(
        "landing",
        help="landing policies over held-out seeds: success rate (95%% Wilson interval), "
        "touchdown speed, tilt, offset, time to land; table and figures",
    )
    landing.add_argument(
        "--policy",
        nargs="+",
        required=True,
        choices=[*POLICY_NAMES, "all"],
        help="one or more policies, or all",
    )
    landing.add_argument("--scenario", nargs="+", required=True, choices=list(SCENARIOS))
    landing.add_argument("--episodes", type=int, default=100)
    landing.add_argument("--seed", type=int, default=HELD_OUT_SEED, help="first held-out seed")
    landing.add_argument("--estimator", choices=ESTIMATORS, default="ihrcf")
    landing.add_argument("--mode", choices=("project", "render"), default="project")
    landing.add_argument("--model", default=None, help="a trained timing model (timing-ppo)")
    landing.add_argument("--workers", type=int, default=2, help="parallel processes")
    landing.add_argument("--out", default="results/landing", help="output directory")
    landing.add_argument("--no-progress", action="store_true")
    landing.add_argument(
        "--allow-mismatch",
        nargs="*",
        default=[],
        choices=["env_id", "observation", "estimator", "sensing"],
        help="evaluate a trained model although its card differs in these fields (e.g. sensing: "
        "an ideal-trained model under realistic noise)",
    )
    landing.add_argument(
        "--no-oracle",
        action="store_true",
        help="do not run the oracle timing (the best any timing could do) beside timing policies",
    )
    landing.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="dotted config overrides applied last, e.g. tof.noise=vl53l1x",
    )
    landing.set_defaults(func=_evaluate_landing)


def _subparser_group(parser: argparse.ArgumentParser) -> Any:
    for action in parser._actions:  # argparse keeps sub-command groups only here
        if isinstance(action, argparse._SubParsersAction):
            return action
    return None


def add_landing_commands(subparsers: Any) -> None:
    """``train timing`` and ``evaluate landing`` (added to an existing ``evaluate`` group)."""
    from agents.training import add_train_parser

    add_train_parser(subparsers)
    evaluate = subparsers.choices.get("evaluate")
    if evaluate is None:
        evaluate = subparsers.add_parser("evaluate", help="evaluations")
        evaluate.add_subparsers(dest="evaluation", required=True)
    add_landing_parser(_subparser_group(evaluate))
