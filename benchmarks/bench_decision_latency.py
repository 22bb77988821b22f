"""How long a scenario's recommended policy takes to decide, on one core.

    nice -n 19 python -m benchmarks.bench_decision_latency \\
        [--scenario ship-ss6 --scenario ship-ss5] [--episodes 10] [--first-seed 1000000]

Without ``--scenario`` it measures ``ship-ss6``.  Each episode is flown by the scenario's
recommended policy (``evaluate landing --scenario S`` without ``--policy``), realistic
sensing, seeds from ``--first-seed``.  Every call of the
policy on an observation is timed by ``time.process_time`` (this process's CPU, one thread):
its decision as a companion computer would run it, the environment's step not included.  The
table gives the decisions, their p50 / p95 / max in milliseconds and the decision period
(a timing policy decides every ``timing.steps_per_decision`` control periods).
"""

from __future__ import annotations

import os

# one core: a decision's latency is that of one thread
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from agents.evaluation.pipeline import run_episode  # noqa: E402
from agents.policies.registry import default_policy, make_env_and_policy  # noqa: E402


class TimedPolicy:
    """The policy, with the CPU time of each of its decisions recorded."""

    def __init__(self, policy: Any) -> None:
        self.policy = policy
        self.seconds: list[float] = []

    def __call__(self, observation: Any) -> Any:
        start = time.process_time()
        action = self.policy(observation)
        self.seconds.append(time.process_time() - start)
        return action

    def __getattr__(self, name: str) -> Any:
        return getattr(self.policy, name)


def measure(scenario: str, episodes: int, first_seed: int) -> dict[str, Any]:
    """The recommended policy of ``scenario`` over ``episodes`` seeded episodes."""
    name = default_policy(scenario)
    env, policy = make_env_and_policy(name, scenario, sensing="realistic")
    timed = TimedPolicy(policy)
    try:
        base = env.unwrapped
        timing = getattr(base, "timing", None)
        period_s = base.env_dt * (timing.steps_per_decision if timing is not None else 1)
        for seed in range(first_seed, first_seed + episodes):
            run_episode(env, timed, seed, name, scenario)
    finally:
        env.close()
    ms = 1e3 * np.asarray(timed.seconds)
    return {
        "scenario": scenario,
        "policy": name,
        "decisions": int(ms.size),
        "p50_ms": float(np.percentile(ms, 50)) if ms.size else float("nan"),
        "p95_ms": float(np.percentile(ms, 95)) if ms.size else float("nan"),
        "max_ms": float(ms.max()) if ms.size else float("nan"),
        "period_ms": 1e3 * period_s,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", action="append")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=1_000_000)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    print("| scenario | policy | decisions | p50 ms | p95 ms | max ms | decision period ms |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for scenario in args.scenario or ["ship-ss6"]:
        row = measure(scenario, args.episodes, args.first_seed)
        print(
            f"| {row['scenario']} | `{row['policy']}` | {row['decisions']} | "
            f"{row['p50_ms']:.3f} | {row['p95_ms']:.3f} | {row['max_ms']:.3f} | "
            f"{row['period_ms']:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
