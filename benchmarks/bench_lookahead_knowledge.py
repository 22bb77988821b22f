"""What each thing the drone does not know costs the look-ahead: its checks, told apart.

    python -m benchmarks.bench_lookahead_knowledge --data FILE.npz [--episodes N] [--draws D]
        [--variants deck-oracle forecast onboard] [--onboard KEY=VALUE ...] [--out FILE.npz]

Replays recorded look-ahead episodes (``python -m agents.training.lookahead_data collect``; the
drone waits through every check) and, at each recorded check, tries the commit now again in
``draws`` futures of other look-aheads, the gusts' and the sensors' draws shared (the same seeds)
with the recorded one (:data:`VARIANTS`):

* ``deck-oracle``: the deck's true future and the true present (drone, gust, airframe), as
  :class:`agents.policies.oracle.DeckOracleTimingPolicy`;
* ``forecast``: the ship's HMS forecast of the deck, the true present, as ``deck-forecast``
  (:class:`agents.policies.deck_forecast.DeckForecastTimingPolicy`);
* ``onboard``: the drone's own look-ahead with ``--onboard``'s changes to its
  :class:`~agents.policies.deck_forecast.OnboardModelConfig` (none: the recorded one, again);
* ``recorded``, always: the drone's own look-ahead as recorded (its first ``draws`` draws).

For each it prints the ROC AUC of the share of draws landing with the margin and of the
mean score for the recorded commit's outcome (``bench_ship_forecast_labels.auc``), how often
all draws land, and the success of the rule "commit at the first check where all draws land
with the margin" replayed on the recording (README "What the look-ahead does not know, at
sea state 6").  ``--out`` saves every check's tried commits.  Each replayed check's commit
is also tried again in the episode's own future and compared with the record: the replay
reproduces the recorded episode, or it says so (run it with the sensing the file was
recorded with, e.g. ``DECK_LANDING_SENSORS=realistic``).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from agents.policies.lookahead import LookaheadSettings, check_features
from agents.policies.oracle import TriedCommit
from agents.training.lookahead_data import recorded_tries
from benchmarks.bench_ship_forecast_labels import auc
from landing_env.errors import ConfigError

#: the look-aheads that can be tried again, by name: ``deck-oracle`` (the deck's true future,
#: the true present), ``forecast`` (the HMS forecast, the true present), ``onboard`` (the
#: forecast and the drone's belief of the present: :class:`OnboardModelConfig`, with the
#: ``--onboard`` changes)
VARIANTS: tuple[str, ...] = ("deck-oracle", "forecast", "onboard")
#: the drone's own look-ahead as the file recorded it
RECORDED = "recorded"


def replay_episode(
    scenario: str,
    seed: int,
    settings: LookaheadSettings,
    draws: int,
    forecast: Any = None,
    variants: tuple[str, ...] = VARIANTS[:2],
    onboard: Any = None,
) -> tuple[list[dict[str, Any]], list[bool]]:
    """Each check of episode ``seed`` as the drone waited through it: the tried commits of
    each of ``variants`` (:data:`VARIANTS`), and whether a commit there lands in the episode's
    own future (to compare with the record).  ``forecast``: the helideck forecast the
    recording used (default: the scenario's); ``onboard``: the ``onboard`` variant's model
    (default: :class:`OnboardModelConfig`'s, the recorded look-ahead's)."""
    from agents.evaluation.landing import SCENARIOS, make_env_and_policy
    from agents.policies.deck_forecast import DeckForecastTimingPolicy, OnboardModelConfig
    from agents.policies.lookahead import in_flight
    from agents.policies.oracle import DeckOracleTimingPolicy
    from landing_env.envs.snapshot import restore_snapshot, save_snapshot

    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        raise ConfigError("variants", f"unknown {unknown}; allowed: {list(VARIANTS)}")
    env, _ = make_env_and_policy("land-now", scenario, SCENARIOS[scenario].estimator)
    base = env.unwrapped
    common = dict(
        draws=draws,
        check_every_s=settings.check_every_s,
        seed=settings.seed,
        min_margin=settings.min_margin,
    )
    builders = {
        "deck-oracle": lambda: DeckOracleTimingPolicy(base, **common),
        "forecast": lambda: DeckForecastTimingPolicy(base, forecast=forecast, **common),
        "onboard": lambda: DeckForecastTimingPolicy(
            base, forecast=forecast, onboard=onboard or OnboardModelConfig(), **common
        ),
    }
    planners = {name: builders[name]() for name in variants}
    decision_s = base.env_dt * base.timing.steps_per_decision
    stride = max(1, round(settings.check_every_s / decision_s))
    checks: list[dict[str, Any]] = []
    commits: list[bool] = []
    try:
        base.reset(seed=seed)
        for planner in planners.values():
            planner.reset()
        decision = 0
        while True:
            row: dict[str, Any] = dict.fromkeys(variants)
            commit = False
            if in_flight(base):
                for name, planner in planners.items():
                    row[name] = planner.try_commits(decision)
                here = save_snapshot(base)
                try:
                    _, _, _, _, info = base.step(1)
                finally:
                    restore_snapshot(base, here, keep=False)
                commit = info["outcome"] == "success"
            checks.append(row)
            commits.append(commit)
            ended = False
            for _ in range(stride):
                _, _, terminated, truncated, _ = base.step(0)
                decision += 1
                if terminated or truncated:
                    ended = True
                    break
            if ended:
                break
    finally:
        env.close()
    return checks, commits


def figures(
    tries: dict[str, list[list[TriedCommit] | None]],
    lands: np.ndarray,
    episodes: np.ndarray,
    wait_success: dict[int, bool],
) -> dict[str, dict[str, float]]:
    """Each variant's AUCs, all-draws share and replayed rule (the module's doc)."""
    out: dict[str, dict[str, float]] = {}
    for variant, rows in tries.items():
        features = np.array([check_features(t) for t in rows])
        tried = features[:, 0] > 0
        chance, mean_score = features[:, 1], features[:, 3]
        all_land = tried & (chance >= 1.0 - 1e-9)
        successes = []
        for seed in np.unique(episodes):
            index = np.flatnonzero(episodes == seed)
            hits = index[all_land[index]]
            successes.append(bool(lands[hits[0]]) if len(hits) else wait_success[int(seed)])
        out[variant] = {
            "auc_chance": auc(chance[tried], lands[tried]),
            "auc_mean_score": auc(mean_score[tried], lands[tried]),
            "all_draws_land": float(all_land[tried].mean()) if tried.any() else float("nan"),
            "lands_when_all": float(lands[all_land].mean()) if all_land.any() else float("nan"),
            "rule_success": float(np.mean(successes)),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from agents.common.user_input import parse_overrides
    from agents.policies.deck_forecast import OnboardModelConfig
    from landing_env.config_loading import build_dataclass

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="recorded transitions (.npz)")
    parser.add_argument("--episodes", type=int, default=8, help="the file's first N episodes")
    parser.add_argument("--draws", type=int, default=8, help="draws per check and look-ahead")
    parser.add_argument(
        "--variants",
        nargs="+",
        default=list(VARIANTS[:2]),
        choices=VARIANTS,
        help="the look-aheads to try again beside the recorded one",
    )
    parser.add_argument(
        "--onboard",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="the onboard variant's model: OnboardModelConfig's keys changed",
    )
    parser.add_argument("--out", help="also save every check's tried commits here (.npz)")
    args = parser.parse_args(argv)
    try:
        onboard = build_dataclass(OnboardModelConfig, parse_overrides(args.onboard), "onboard")
    except ConfigError as error:
        parser.error(f"--onboard: {error}")
    with np.load(args.data) as file:
        data = {key: file[key] for key in file.files}
    recorded = json.loads(str(data["settings"]))
    fields = {k: recorded[k] for k in asdict(LookaheadSettings()) if k in recorded}
    settings = LookaheadSettings(**fields)
    if args.draws > settings.draws:
        parser.error(f"--draws: the file holds {settings.draws} draws per check")
    scenario = str(data["scenario"])
    seeds = list(dict.fromkeys(data["episode"].tolist()))[: args.episodes]
    names = (*args.variants, RECORDED)
    tries: dict[str, list[list[TriedCommit] | None]] = {v: [] for v in names}
    lands, episodes, mismatches = [], [], 0
    wait_success: dict[int, bool] = {}
    for seed in tqdm(seeds, desc=f"look-ahead knowledge @ {scenario}"):
        rows = np.flatnonzero(data["episode"] == seed)
        checks, commits = replay_episode(
            scenario,
            int(seed),
            settings,
            args.draws,
            variants=tuple(args.variants),
            onboard=onboard,
        )
        if len(checks) != len(rows):
            print(f"episode {seed}: {len(checks)} checks replayed, {len(rows)} recorded")
        for k, row in enumerate(rows[: len(checks)]):
            mismatches += int(commits[k] != bool(data["commit_success"][row]))
            for variant in args.variants:
                tries[variant].append(checks[k][variant])
            tries[RECORDED].append(recorded_tries(data, row, args.draws))
            lands.append(bool(data["commit_success"][row]))
            episodes.append(int(seed))
        wait_success[int(seed)] = bool(data["wait_success"][rows[-1]])
        if args.out:
            save_tries(args.out, tries, lands, episodes, wait_success, args.draws)
    changed = f" (onboard: {' '.join(args.onboard)})" if args.onboard else ""
    print(
        f"{scenario}: {len(seeds)} episodes, {len(lands)} checks, {args.draws} draws each"
        f"{changed}; a commit lands at {np.mean(lands):.1%}; replayed commits unlike the "
        f"record: {mismatches}"
    )
    table = figures(tries, np.asarray(lands), np.asarray(episodes), wait_success)
    print("| look-ahead | AUC chance | AUC mean score | all draws land | lands then | rule |")
    print("|---|---:|---:|---:|---:|---:|")
    for variant, f in table.items():
        print(
            f"| {variant} | {f['auc_chance']:.3f} | {f['auc_mean_score']:.3f} | "
            f"{f['all_draws_land']:.1%} | {f['lands_when_all']:.1%} | {f['rule_success']:.1%} |"
        )
    return 0


def save_tries(
    path: str,
    tries: dict[str, list[list[TriedCommit] | None]],
    lands: list[bool],
    episodes: list[int],
    wait_success: dict[int, bool],
    draws: int,
) -> None:
    """Every check's tried commits of each variant (lands, success, margin: checks x draws;
    NaN margins where nothing was tried), the recorded commits' outcomes and episodes."""
    arrays: dict[str, np.ndarray] = {}
    for variant, rows in tries.items():
        key = variant.replace("-", "_")
        for field in ("lands", "success", "margin"):
            values = np.full((len(rows), draws), np.nan)
            for i, row in enumerate(rows):
                for k, tried in enumerate(row or []):
                    values[i, k] = float(getattr(tried, field))
            arrays[f"{key}_{field}"] = values
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        commit_success=np.asarray(lands),
        episode=np.asarray(episodes),
        wait_seeds=np.asarray(list(wait_success)),
        wait_success=np.asarray(list(wait_success.values())),
        **arrays,
    )


if __name__ == "__main__":
    raise SystemExit(main())
