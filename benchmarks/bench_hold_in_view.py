"""Whether the drone has the deck in view when the timing decision starts, on the ship.

    python -m benchmarks.bench_hold_in_view [--scenario ship-ss4 ship-ss5 ship-ss6]
        [--sensors realistic] [--episodes 100] [--hold] [--outcomes EPISODES.jsonl]
        [--set KEY=VALUE ...]

Resets the timing task of each scenario (``land-now``'s environment: the deck-frame guidance,
the scenario's estimator observed) on held-out seeds from 1 000 000, the seeds `evaluate
landing` uses, and prints at the first decision (after the warm-up hold that fills the
history) the share of episodes whose observed deck-pose estimate is valid and the true
lateral offset of the deck from the camera's axis (median and 90th percentile).  ``--hold``
also waits out the whole hold (action 0 until the wait limit forces the commit) and prints
the share of the hold's decisions with a valid estimate and how many episodes had none.
``--outcomes`` (an evaluation's ``landing_<scenario>_<policy>.jsonl``, one scenario) splits
that run's outcomes by whether the estimate was valid at the first decision.  ``--set``
applies config overrides (e.g. ``wind.enabled=false``) (README "Sea states 5 and 6 in one
model").
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from agents.cli.args import add_set_argument
from agents.common.user_input import parse_overrides

FIRST_SEED = 1_000_000


def measure(
    scenario: str,
    sensors: str,
    episodes: int,
    hold: bool,
    overrides: dict[str, Any] | None = None,
) -> dict[int, dict]:
    """Per seed: ``valid`` at the first decision, the deck's lateral ``offset_m`` then, and
    with ``hold`` the share of the hold's decisions with a valid estimate."""
    from agents.evaluation.landing import SCENARIOS, make_env_and_policy

    env, _ = make_env_and_policy(
        "land-now",
        scenario,
        SCENARIOS[scenario].estimator,
        extra_overrides={"sensors": sensors, **(overrides or {})},
    )
    base = env.unwrapped

    def valid_now() -> bool:
        sensing = getattr(base, "_sensing", None)
        if sensing is None:
            return False
        estimate = sensing.estimates.get(base.config.estimation.observed)
        return bool(estimate is not None and estimate.valid)

    rows: dict[int, dict] = {}
    try:
        for seed in range(FIRST_SEED, FIRST_SEED + episodes):
            env.reset(seed=seed)
            _, t_cd = base.world.true_deck_pose_c()
            row = {"valid": valid_now(), "offset_m": float(np.hypot(t_cd[0], t_cd[1]))}
            if hold:
                seen = [row["valid"]]
                while True:
                    _, _, terminated, truncated, _ = env.step(0)
                    if terminated or truncated or base._committed:
                        break
                    seen.append(valid_now())
                row["hold_valid_share"] = float(np.mean(seen))
            rows[seed] = row
    finally:
        env.close()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", nargs="+", default=["ship-ss4", "ship-ss5", "ship-ss6"])
    parser.add_argument("--sensors", default="realistic")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--hold", action="store_true", help="also wait out the whole hold")
    parser.add_argument("--outcomes", help="an evaluation's episodes (.jsonl) of one scenario")
    add_set_argument(parser)
    args = parser.parse_args(argv)
    overrides = parse_overrides(args.set)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    if args.outcomes and len(args.scenario) != 1:
        parser.error("--outcomes needs exactly one --scenario (the run's)")
    for scenario in args.scenario:
        rows = measure(scenario, args.sensors, args.episodes, args.hold, overrides)
        valid = np.array([r["valid"] for r in rows.values()])
        offset = np.array([r["offset_m"] for r in rows.values()])
        p50, p90 = np.percentile(offset, [50, 90])
        print(
            f"{scenario} ({args.sensors}{''.join(' ' + s for s in args.set)}, {len(rows)} seeds "
            f"from {FIRST_SEED}): valid estimate "
            f"at the first decision {valid.mean():.0%}; deck's lateral offset median {p50:.2f} m, "
            f"p90 {p90:.2f} m"
        )
        if args.hold:
            share = np.array([r["hold_valid_share"] for r in rows.values()])
            print(
                f"  over the hold: {share.mean():.0%} of decisions with a valid estimate; "
                f"{int(np.sum(share == 0.0))} episodes with none"
            )
        if args.outcomes:
            runs = [json.loads(line) for line in Path(args.outcomes).read_text().splitlines()]
            by_seed = {int(r["seed"]): r["outcome"] for r in runs if int(r["seed"]) in rows}
            for flag, label in ((False, "no valid estimate"), (True, "a valid estimate")):
                outcomes = Counter(o for s, o in by_seed.items() if rows[s]["valid"] is flag)
                print(
                    f"  {label} at the first decision: {sum(outcomes.values())} episodes, "
                    + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()))
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
