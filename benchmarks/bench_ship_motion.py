"""Deck motion statistics of the ship-ss* and bench-ss* scenarios, beside the limits.

    python -m benchmarks.bench_ship_motion [--seeds 5] [--minutes 30]

For each scenario the motion source its config builds (no physics: the deck body tracks it to
~1e-6 m) is sampled at 10 Hz for ``--minutes`` per seed.  Prints the Hs, Tp and gamma in use,
the deck's heave, roll, pitch, vertical-velocity and vertical-acceleration RMS, and the mean
over the seeds of the largest roll, pitch, inclination and heave rate in the first 20 minutes
(CAP 437 reports peaks over a period), next to the STANAG 4154 RMS criteria for helicopter
operations and CAP 437's helideck peak limits (README "Ship deck").
"""

from __future__ import annotations

import argparse

import numpy as np

from landing_env.config import load_config
from landing_env.stewart.motion import make_motion_source

SCENARIOS = ("ship-ss3", "ship-ss4", "ship-ss5", "ship-ss6", "bench-ss3", "bench-ss4", "bench-ss5")


def statistics(scenario: str, seeds: int, minutes: float) -> dict[str, float]:
    config = load_config(scenario)
    times = np.arange(0.0, minutes * 60.0, 0.1)
    window = times < 20 * 60.0
    rows = []
    for seed in range(seeds):
        source = make_motion_source(config.motion, np.random.default_rng(seed))
        poses = source.poses(times)
        if hasattr(source, "velocities"):
            velocity = source.velocities(times)[:, 2]
        else:
            velocity = np.array([source.velocity(float(t))[2] for t in times])
        acceleration = np.gradient(velocity, times)
        roll, pitch = np.rad2deg(poses[:, 3]), np.rad2deg(poses[:, 4])
        inclination = np.rad2deg(
            np.arccos(np.clip(np.cos(poses[:, 3]) * np.cos(poses[:, 4]), -1.0, 1.0))
        )
        rows.append(
            [
                np.std(poses[:, 2]),
                np.std(roll),
                np.std(pitch),
                np.std(velocity),
                np.std(acceleration) / 9.81,
                np.max(np.abs(roll[window])),
                np.max(np.abs(pitch[window])),
                np.max(inclination[window]),
                np.max(np.abs(velocity[window])),
            ]
        )
    mean = np.mean(rows, axis=0)
    motion = config.motion
    sea = motion.ship if motion.kind == "ship" else motion.sea_state
    keys = ("heave", "roll", "pitch", "vvel", "vacc_g", "roll_pk", "pitch_pk", "incl_pk", "vvel_pk")
    return {
        "hs": sea.hs,
        "tp": sea.tp,
        "gamma": sea.gamma_in_use,
        **dict(zip(keys, mean, strict=True)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--scenario", nargs="*", default=list(SCENARIOS))
    args = parser.parse_args()
    print(
        "| scenario | Hs (m) | Tp (s) | gamma | heave RMS (m) | roll RMS (deg) | pitch RMS (deg) "
        "| deck vert. velocity RMS (m/s) | deck vert. accel. RMS (g) | peak roll / pitch / "
        "inclination (deg), 20 min | peak heave rate (m/s), 20 min |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenario:
        s = statistics(name, args.seeds, args.minutes)
        print(
            f"| `{name}` | {s['hs']:.2f} | {s['tp']:.1f} | {s['gamma']:.1f} | {s['heave']:.3f} "
            f"| {s['roll']:.2f} | {s['pitch']:.2f} | {s['vvel']:.3f} | {s['vacc_g']:.3f} "
            f"| {s['roll_pk']:.1f} / {s['pitch_pk']:.1f} / {s['incl_pk']:.1f} "
            f"| {s['vvel_pk']:.2f} |"
        )
    print(
        "| STANAG 4154 (helicopter ops, RMS) | | | | | 2.5 | 1.5 | 1.0 | | | |\n"
        "| CAP 437 helideck limits (peak) | | | | | | | | | 3 / 3 / 3.5 | 1.3 |"
    )


if __name__ == "__main__":
    main()
