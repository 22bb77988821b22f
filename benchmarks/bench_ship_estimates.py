"""How the deck-pose estimates fare during landings on the ship deck.

    python -m benchmarks.bench_ship_estimates [--scenario ship-ss4] [--sensors realistic]
        [--episodes 5]

Flies ``land-now`` (commit at the first decision) on ``DeckLandingTiming-ShipSS<n>-v1`` (the
deck-frame guidance, ``tight`` observed) over held-out seeds from 1 000 000 and, at every control
period of the hold and the descent, runs IHRCF, CRHF and ``tight`` side by side on the same
frame and ranges.  Prints, per estimator, the share of periods with a valid estimate, the mean
absolute height (z) error against the true deck pose, and the commonest reasons for an invalid
one (``range_invalid``: a ToF ray missed the pad; ``no_detection``: no tag in the image)
(README "Landing on the ship").
"""

from __future__ import annotations

import argparse
from collections import Counter, defaultdict

import numpy as np

NAMES = ("ihrcf", "crhf", "tight")


def measure(scenario: str, sensors: str, episodes: int) -> dict[str, dict]:
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the environments)
    from landing_env.scenarios import SCENARIO_IDS, TIMING_TASK

    sid = SCENARIO_IDS[f"DeckLandingTiming-ShipSS{scenario[-1]}-v1"]
    overrides = {**sid.overrides, "estimation.compare": list(NAMES), "sensors": sensors}
    env = gym.make(TIMING_TASK, config=scenario, overrides=overrides, **sid.task_kwargs)
    base = env.unwrapped
    periods = 0
    valid: Counter[str] = Counter()
    reasons: dict[str, Counter[str]] = defaultdict(Counter)
    errors: dict[str, list[float]] = defaultdict(list)
    advance = base._advance

    def watched(setpoint):  # every control period of the hold and of the descent
        nonlocal periods
        advance(setpoint)
        periods += 1
        _, t_cd = base.world.true_deck_pose_c()
        for name in NAMES:
            estimate = base._sensing.estimates[name]
            if estimate.valid:
                valid[name] += 1
                errors[name].append(abs(float(estimate.as_vector()[2]) - float(t_cd[2])))
            else:
                reasons[name][estimate.reason] += 1

    base._advance = watched
    try:
        for episode in range(episodes):
            env.reset(seed=1_000_000 + episode)
            env.step(1)
    finally:
        env.close()
    return {
        name: {
            "valid": valid[name] / max(periods, 1),
            "z_mae_m": float(np.mean(errors[name])) if errors[name] else float("nan"),
            "reasons": dict(reasons[name].most_common(3)),
            "periods": periods,
        }
        for name in NAMES
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--scenario", default="ship-ss4", choices=[f"ship-ss{n}" for n in range(3, 7)]
    )
    parser.add_argument("--sensors", default="realistic", choices=("ideal", "realistic"))
    parser.add_argument("--episodes", type=int, default=5)
    args = parser.parse_args()
    result = measure(args.scenario, args.sensors, args.episodes)
    print(f"{args.scenario}, {args.sensors} sensing, {args.episodes} land-now episodes")
    for name, row in result.items():
        print(
            f"{name:6s} valid {100 * row['valid']:5.1f} % of {row['periods']} periods, "
            f"z MAE {1000 * row['z_mae_m']:.1f} mm, invalid: {row['reasons']}"
        )


if __name__ == "__main__":
    main()
