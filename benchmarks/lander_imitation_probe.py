"""Which half of an imitated lander loses landings: its *how* or its *when*.

Flies ``DeckLanding-BenchSS4-v2`` (realistic sensing, ``tight``) with the set-points of one
policy and the ``land`` entry of another, the student being a trained lander
(``--model``) and the teacher ``align-predictive``; ``--bias-vy`` and ``--noise`` add a
constant and a white error (in action units) to the set-points flown.

    python -m benchmarks.lander_imitation_probe --model M --how student --when teacher \\
        --episodes 100 --seed 7000000
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import landing_env  # noqa: F401
from agents.policies.lander import TrainedLanderPolicy
from agents.policies.registry import make_policy


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="the student (a trained lander)")
    parser.add_argument("--how", choices=("teacher", "student"), default="teacher")
    parser.add_argument("--when", choices=("teacher", "student"), default="teacher")
    parser.add_argument("--bias-vy", type=float, default=0.0)
    parser.add_argument("--noise", type=float, default=0.0)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=7_000_000)
    args = parser.parse_args(argv)
    env = gym.make(
        "DeckLanding-BenchSS4-v2",
        overrides={"sensors": "realistic", "estimation.observed": "tight"},
    )
    teacher = make_policy("align-predictive", env)
    student = TrainedLanderPolicy(args.model) if args.model else None
    if student is None and "student" in (args.how, args.when):
        parser.error("--model is needed to fly the student")
    rng = np.random.default_rng(0)
    outcomes: dict[str, int] = {}
    for episode in range(args.episodes):
        observation, _ = env.reset(seed=args.seed + episode)
        teacher.reset()
        if student is not None:
            student.reset()
        while True:
            by = {"teacher": teacher.act(observation)}
            if student is not None:
                by["student"] = student.act(observation)
            action = np.concatenate([by[args.how][:4], by[args.when][4:]]).astype(np.float32)
            action[:4] += rng.normal(0.0, args.noise, 4).astype(np.float32) if args.noise else 0.0
            action[1] += args.bias_vy
            observation, _, terminated, truncated, info = env.step(np.clip(action, -1.0, 1.0))
            if terminated or truncated:
                break
        outcomes[info["outcome"]] = outcomes.get(info["outcome"], 0) + 1
    print(f"how {args.how}, when {args.when}, bias {args.bias_vy}, noise {args.noise}: {outcomes}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
