"""A timing policy on every member of a training family of seas: what a setting is chosen on
(the family's seas), never a held-out sea.

Each member is flown as ``deck-landing evaluate landing`` on its scenario with its sea's
overrides (:mod:`landing_env.sea.training_seas`) and the ``--set`` given here; prints each
member's line and the family's total.  Output under ``--out/<member>/``.

    python benchmarks/evaluate_on_family.py --family bench-broad --policy predictive \\
        --episodes 60 --seed 6000000 --set timing.tilt_model=bench-broad timing.opportunity_s=0.6 \\
        --out results/tune-opportunity/opp0.6
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from landing_env.sea.training_seas import TRAINING_FAMILIES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--family", required=True, choices=sorted(TRAINING_FAMILIES))
    parser.add_argument("--policy", required=True)
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=6_000_000)
    parser.add_argument("--sensors", default="realistic")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    landed = flown = 0
    for member in TRAINING_FAMILIES[args.family]:
        out = args.out / member.name
        sets = [f"{k}={'null' if v is None else v}" for k, v in member.overrides.items()]
        command = [
            sys.executable, "-m", "agents.cli", "evaluate", "landing",
            "--scenario", member.scenario, "--sensors", args.sensors,
            "--policy", args.policy, "--no-oracle", "--workers", "1", "--no-progress",
            "--episodes", str(args.episodes), "--seed", str(args.seed), "--out", str(out),
            "--set", *sets, *args.set,
        ]  # fmt: skip
        subprocess.run(command, check=True, capture_output=True)
        rows = [json.loads(line) for line in out.glob("*.jsonl").__next__().open()]
        wins = sum(bool(r["success"]) for r in rows)
        landed, flown = landed + wins, flown + len(rows)
        print(f"{member.name:32s} {wins:4d} / {len(rows)}", flush=True)
    print(f"{args.family} {args.policy} {' '.join(args.set)}: {landed} / {flown} "
          f"= {100.0 * landed / max(flown, 1):.1f} %")  # fmt: skip


if __name__ == "__main__":
    main()
