"""The onboard look-ahead's reduced model against the simulation's replay, on recorded checks.

    nice -n 19 python -m benchmarks.bench_onboard_lookahead \\
        --scenario ship-ss6 --scenario ship-ss5 --episodes 12 --checks 4 \\
        [--first-seed 1000000] [--out results/onboard-lookahead.jsonl]

Each episode of a scenario (realistic sensing, seeds from ``--first-seed``) is flown by the
recommended ship policy, ``timing-dqn-lookahead`` (its look-ahead replays the simulation:
:class:`~agents.policies.deck_forecast.DeckForecastTimingPolicy`).  At each of its first
``--checks`` checks the same check is also flown by the reduced model
(:class:`~agents.policies.reduced_descent.ReducedLookahead`: the same belief, forecast and
draws), and both verdicts of every draw are recorded: whether it succeeds
(:func:`landing_env.touchdown.evaluate_touchdown`'s criteria) and whether it lands with the
look-ahead's ``min_margin`` (the ``chance`` feature's verdict).  The output gives, per
scenario and over all, the share of draws with the same verdict, the confusion counts
(replay / reduced), and the CPU time of a check (``time.process_time`` of this process, one
thread): the reduced model's whole check (forecast, draws, flight, verdicts) at p50 / p95,
over all checks and over those after an episode's first (which also sets up the episode's
HMS record and forecast), and the replay's.  ``--out`` writes one JSON line per check (both
models' verdicts and margins per draw, the CPU times).

The replay's own verdicts are not fixed by a draw: each replayed future also draws the gusts'
innovations and the sensors' noise anew, which no onboard model can know.  ``--repeat`` replays
each check a second time with those drawn from another stream (the draws' airframe, gust and
position unchanged) and reports how often the replay agrees with itself: the agreement that
a model without them can be expected to reach.
"""

from __future__ import annotations

import os

# one core: the latency of a check is that of one thread
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

import landing_env  # noqa: E402, F401
from agents.policies.oracle import TriedCommit  # noqa: E402
from agents.policies.reduced_descent import ReducedLookahead  # noqa: E402
from agents.policies.registry import make_env_and_policy  # noqa: E402

POLICY = "timing-dqn-lookahead"


def reduced_twin(planner: Any) -> ReducedLookahead:
    """The reduced model's look-ahead with ``planner``'s settings (draws, seed, margin,
    onboard model, forecast)."""
    base = planner.env
    decision_s = base.env_dt * base.timing.steps_per_decision
    return ReducedLookahead(
        base,
        hms=planner.hms,
        forecast=planner.forecast,
        onboard=planner.onboard,
        min_margin=planner.min_margin,
        draws=planner.draws,
        min_chance=planner.min_chance,
        check_every_s=planner.stride * decision_s,
        seed=planner.seed,
    )


def _verdicts(tries: list[TriedCommit] | None) -> list[dict[str, Any]] | None:
    if tries is None:
        return None
    return [
        {
            "lands": bool(t.lands),
            "success": bool(t.success),
            "margin": float(t.margin) if math.isfinite(t.margin) else None,
        }
        for t in tries
    ]


def replay_again(planner: Any, decision: int) -> list[TriedCommit] | None:
    """``planner``'s check replayed with the unknowable future (gust innovations, sensor
    noise) drawn from another stream than its own (the world class's method is wrapped: each
    draw restores a copy of the world)."""
    world_class = type(planner.env.world)
    redraw = world_class.redraw_unknowable_future

    def other(world: Any, rng: np.random.Generator) -> None:
        redraw(world, np.random.default_rng([int(rng.integers(2**63)), 0x5EED]))

    world_class.redraw_unknowable_future = other
    try:
        return type(planner).try_commits(planner, decision, 0.0)
    finally:
        world_class.redraw_unknowable_future = redraw


def record_scenario(
    scenario: str, episodes: int, first_seed: int, checks: int, repeat: bool = False
) -> list[dict[str, Any]]:
    """Both models' verdicts at the first ``checks`` checks of each episode."""
    env, policy = make_env_and_policy(POLICY, scenario, extra_overrides={"sensors": "realistic"})
    rows: list[dict[str, Any]] = []
    try:
        planner = policy.observer.planner
        twin = reduced_twin(planner)
        replay = planner.try_commits
        pending: dict[str, Any] = {}

        def recorded(decision: int = 0, needed: float = 0.0) -> list[TriedCommit] | None:
            start = time.process_time()
            tries = replay(decision, needed)
            pending["replay_cpu_s"] = time.process_time() - start
            pending["replay"] = tries
            pending["decision"] = decision
            return tries

        planner.try_commits = recorded
        for episode in range(episodes):
            seed = first_seed + episode
            observation, _ = env.reset(seed=seed)
            policy.reset()
            twin.reset()
            done, seen = False, 0
            while not done and seen < checks:
                pending.clear()
                action = policy.act(observation)
                if "replay" in pending:
                    start = time.process_time()
                    reduced = twin.try_commits(pending["decision"])
                    reduced_cpu = time.process_time() - start
                    row = {
                        "scenario": scenario,
                        "seed": seed,
                        "decision": pending["decision"],
                        # the episode's first check also sets up its HMS record and forecast
                        "first": seen == 0,
                        "replay": _verdicts(pending["replay"]),
                        "reduced": _verdicts(reduced),
                        "replay_cpu_s": pending["replay_cpu_s"],
                        "reduced_cpu_s": reduced_cpu,
                    }
                    if repeat:
                        row["replay_again"] = _verdicts(replay_again(planner, pending["decision"]))
                    rows.append(row)
                    seen += 1
                observation, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
    finally:
        env.close()
    return rows


def agreement(rows: list[dict[str, Any]], other: str = "reduced") -> dict[str, Any]:
    """Per verdict: the share of draws alike and the confusion counts (the replay, ``other``:
    ``reduced`` or ``replay_again``); checks where either made no look-ahead are counted
    apart."""
    rows = [row for row in rows if other in row]
    pairs = [
        (a, b)
        for row in rows
        if row["replay"] is not None and row[other] is not None
        for a, b in zip(row["replay"], row[other], strict=True)
    ]
    summary: dict[str, Any] = {
        "checks": len(rows),
        "draws": len(pairs),
        "checks_valid_alike": sum((row["replay"] is None) == (row[other] is None) for row in rows),
    }
    for verdict in ("success", "lands"):
        counts = {"both": 0, "replay_only": 0, "reduced_only": 0, "neither": 0}
        for a, b in pairs:
            key = (
                ("both" if b[verdict] else "replay_only")
                if a[verdict]
                else ("reduced_only" if b[verdict] else "neither")
            )
            counts[key] += 1
        alike = counts["both"] + counts["neither"]
        # the feature the policy reads: the share of a check's draws with the verdict
        gaps = [
            abs(
                float(np.mean([d[verdict] for d in row["replay"]]))
                - float(np.mean([d[verdict] for d in row[other]]))
            )
            for row in rows
            if row["replay"] is not None and row[other] is not None
        ]
        summary[verdict] = {
            "agreement": alike / max(len(pairs), 1),
            **counts,
            "share_gap_mean": float(np.mean(gaps)) if gaps else math.nan,
        }
    reduced_ms = [1000.0 * row["reduced_cpu_s"] for row in rows if row["reduced"] is not None]
    later_ms = [
        1000.0 * row["reduced_cpu_s"]
        for row in rows
        if row["reduced"] is not None and not row.get("first", False)
    ]
    replay_ms = [1000.0 * row["replay_cpu_s"] for row in rows if row["replay"] is not None]
    for name, values in (
        ("reduced_check_ms", reduced_ms),
        ("reduced_later_check_ms", later_ms),
        ("replay_check_ms", replay_ms),
    ):
        if values:
            summary[name] = {
                "p50": float(np.percentile(values, 50)),
                "p95": float(np.percentile(values, 95)),
            }
    return summary


def _print(name: str, summary: dict[str, Any], other: str = "reduced") -> None:
    print(f"{name}, replay against {other}: {summary['checks']} checks, {summary['draws']} draws")
    for verdict in ("success", "lands"):
        s = summary[verdict]
        print(
            f"  {verdict:8s} agreement {100 * s['agreement']:.1f} %  "
            f"both {s['both']}  replay only {s['replay_only']}  "
            f"{other} only {s['reduced_only']}  neither {s['neither']}  "
            f"mean gap of a check's share {s['share_gap_mean']:.3f}"
        )
    for key in ("reduced_check_ms", "reduced_later_check_ms", "replay_check_ms"):
        if key in summary:
            print(f"  {key}: p50 {summary[key]['p50']:.1f}  p95 {summary[key]['p95']:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", action="append", default=None, help="repeatable")
    parser.add_argument("--episodes", type=int, default=12, help="episodes per scenario")
    parser.add_argument("--checks", type=int, default=4, help="checks recorded per episode")
    parser.add_argument("--first-seed", type=int, default=1_000_000)
    parser.add_argument("--out", type=Path, default=None, help="one JSON line per check")
    parser.add_argument(
        "--repeat", action="store_true", help="replay each check again with other innovations"
    )
    args = parser.parse_args()
    scenarios = args.scenario or ["ship-ss6"]
    rows: list[dict[str, Any]] = []
    for scenario in scenarios:
        mine = record_scenario(scenario, args.episodes, args.first_seed, args.checks, args.repeat)
        _print(scenario, agreement(mine))
        if args.repeat:
            _print(scenario, agreement(mine, "replay_again"), "replay_again")
        rows += mine
        if args.out is not None:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            with args.out.open("w") as handle:
                for row in rows:
                    handle.write(json.dumps(row) + "\n")
    if len(scenarios) > 1:
        _print("all", agreement(rows))
        if args.repeat:
            _print("all", agreement(rows, "replay_again"), "replay_again")


if __name__ == "__main__":
    main()
