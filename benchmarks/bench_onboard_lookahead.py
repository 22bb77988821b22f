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
and the replay's.  ``--out`` writes one JSON line per check (both models' verdicts and
margins per draw, the CPU times).
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


def record_scenario(
    scenario: str, episodes: int, first_seed: int, checks: int
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
                    rows.append(
                        {
                            "scenario": scenario,
                            "seed": seed,
                            "decision": pending["decision"],
                            "replay": _verdicts(pending["replay"]),
                            "reduced": _verdicts(reduced),
                            "replay_cpu_s": pending["replay_cpu_s"],
                            "reduced_cpu_s": reduced_cpu,
                        }
                    )
                    seen += 1
                observation, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
    finally:
        env.close()
    return rows


def agreement(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per verdict: the share of draws alike and the confusion counts (replay, reduced);
    checks where either model made no look-ahead are counted apart."""
    pairs = [
        (a, b)
        for row in rows
        if row["replay"] is not None and row["reduced"] is not None
        for a, b in zip(row["replay"], row["reduced"], strict=True)
    ]
    summary: dict[str, Any] = {
        "checks": len(rows),
        "draws": len(pairs),
        "checks_valid_alike": sum(
            (row["replay"] is None) == (row["reduced"] is None) for row in rows
        ),
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
        summary[verdict] = {"agreement": alike / max(len(pairs), 1), **counts}
    reduced_ms = [1000.0 * row["reduced_cpu_s"] for row in rows if row["reduced"] is not None]
    replay_ms = [1000.0 * row["replay_cpu_s"] for row in rows if row["replay"] is not None]
    for name, values in (("reduced_check_ms", reduced_ms), ("replay_check_ms", replay_ms)):
        if values:
            summary[name] = {
                "p50": float(np.percentile(values, 50)),
                "p95": float(np.percentile(values, 95)),
            }
    return summary


def _print(name: str, summary: dict[str, Any]) -> None:
    print(f"{name}: {summary['checks']} checks, {summary['draws']} draws")
    for verdict in ("success", "lands"):
        s = summary[verdict]
        print(
            f"  {verdict:8s} agreement {100 * s['agreement']:.1f} %  "
            f"both {s['both']}  replay only {s['replay_only']}  "
            f"reduced only {s['reduced_only']}  neither {s['neither']}"
        )
    for key in ("reduced_check_ms", "replay_check_ms"):
        if key in summary:
            print(f"  {key}: p50 {summary[key]['p50']:.1f}  p95 {summary[key]['p95']:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", action="append", default=None, help="repeatable")
    parser.add_argument("--episodes", type=int, default=12, help="episodes per scenario")
    parser.add_argument("--checks", type=int, default=4, help="checks recorded per episode")
    parser.add_argument("--first-seed", type=int, default=1_000_000)
    parser.add_argument("--out", type=Path, default=None, help="one JSON line per check")
    args = parser.parse_args()
    scenarios = args.scenario or ["ship-ss6"]
    rows: list[dict[str, Any]] = []
    for scenario in scenarios:
        mine = record_scenario(scenario, args.episodes, args.first_seed, args.checks)
        _print(scenario, agreement(mine))
        rows += mine
        if args.out is not None:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            with args.out.open("w") as handle:
                for row in rows:
                    handle.write(json.dumps(row) + "\n")
    if len(scenarios) > 1:
        _print("all", agreement(rows))


if __name__ == "__main__":
    main()
