"""What a perfect forecast of the deck is worth to simple timing rules on a ship deck.

    python -m benchmarks.bench_ship_deck_prediction --rule calm [--max-tilt-deg 4]
        [--max-heave-rate 0.15] [--scenario ship-ss5] [--episodes 200] [--seed 1000000]
        [--workers 2] [--out results/deck_prediction]
    python -m benchmarks.bench_ship_deck_prediction --rule tilt-window [--window 2.5,5.0]
        [--max-tilt-deg 4.5] [--min-wait-s 3] ...

The deck oracle (:class:`agents.policies.oracle.DeckOracleTimingPolicy`) knows the deck's future and
lands far more often than ``quiescent`` on the ship.  How much of that is the forecast itself?
These rules read the deck's **true** motion, as a perfect ship-motion link and a perfect
forecast would give it (privileged: the motion source of the simulated ship), and fly the
timing task of the scenario (realistic sensing, ``tight`` observed, as the evaluation):

* ``calm``: ``quiescent``'s calm rule (:func:`agents.policies.calm_window.predict_calm`) on the
true deck
  motion over the last 2 s instead of its estimate.
* ``tilt-window``: commit once the true deck tilt stays below ``--max-tilt-deg`` over the whole
  contact window (``--window``, seconds after the commit: the ship's descent meets the deck
  2.5-5 s after it) and the drone has held for ``--min-wait-s``.

Printed: the success, the outcomes, the commits forced at the wait limit and the median wait;
written to ``--out`` as JSON.  The held-out seeds are the evaluation's, so the figures compare
with ``deck-landing evaluate landing --deck-oracle`` on the same seeds.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from agents.common.parallel import map_tasks
from agents.evaluation.landing import HELD_OUT_SEED, make_env_and_policy
from agents.policies.calm_window import CalmConfig, predict_calm
from estimation.frames import tilt_deg
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.timing.history import HISTORY_FEATURES

RULES = ("calm", "tilt-window")
#: the true deck motion the calm rule reads, seconds
CALM_HISTORY_S = 2.0
_Z, _ROLL, _PITCH = (HISTORY_FEATURES.index(n) for n in ("z", "roll", "pitch"))
_VALID = HISTORY_FEATURES.index("valid")


def true_tilt_deg(poses: np.ndarray) -> np.ndarray:
    """The tilt from level (deg) of deck poses (..., 6): the angle of the deck's normal."""
    return tilt_deg(poses[..., 3], poses[..., 4])


def true_history(motion: Any, t: float, dt: float, n: int) -> np.ndarray:
    """Rows of :data:`HISTORY_FEATURES` of the deck's true motion over the last ``n`` samples:
    z as the camera's (the deck falling away is z growing), roll and pitch from level."""
    poses = np.array([motion.pose(t - k * dt) for k in range(n - 1, -1, -1)])
    rows = np.zeros((n, len(HISTORY_FEATURES)))
    rows[:, _Z] = -poses[:, 2]
    rows[:, _ROLL] = poses[:, 3]
    rows[:, _PITCH] = poses[:, 4]
    rows[:, _VALID] = 1.0
    return rows


def commits(settings: dict[str, Any], motion: Any, t: float, dt: float, waited_s: float) -> bool:
    """Does the rule commit at time ``t`` after ``waited_s`` of waiting?"""
    if waited_s < settings["min_wait_s"] - 1e-9:
        return False
    if settings["rule"] == "calm":
        config = CalmConfig(
            max_tilt_deg=settings["max_tilt_deg"], max_heave_rate=settings["max_heave_rate"]
        )
        rows = true_history(motion, t, dt, round(CALM_HISTORY_S / dt))
        return predict_calm(rows, dt, config).calm
    first, last = settings["window_s"]
    ahead = np.arange(first, last + 1e-9, 0.1)
    poses = np.array([motion.pose(t + h) for h in ahead])
    return bool(true_tilt_deg(poses).max() < settings["max_tilt_deg"])


def run_episode(task: tuple[dict[str, Any], int]) -> dict[str, Any]:
    """One episode of the timing task flown by the rule; its outcome and wait."""
    settings, seed = task
    env, _ = make_env_and_policy(
        "land-now", settings["scenario"], "tight", extra_overrides={"sensors": "realistic"}
    )
    try:
        base = env.unwrapped
        _, info = env.reset(seed=seed)
        while True:
            world = base.world
            action = commits(
                settings, world.stewart.motion, world.time, base.env_dt, info.get("wait_s", 0.0)
            )
            _, _, terminated, truncated, info = env.step(int(action))
            if terminated or truncated:
                break
    finally:
        env.close()
    return {"seed": seed, "outcome": info["outcome"], "wait_s": float(info.get("wait_s", 0.0))}


def _window(text: str) -> tuple[float, float]:
    try:
        first, last = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError("window", f"{text!r} must be FIRST,LAST seconds") from None
    require_range("window", first, 0.0, 20.0)
    require_range("window", last, first, 20.0, bounds_from=f"its first value {first}")
    return first, last


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rule", required=True, choices=RULES)
    parser.add_argument("--scenario", default="ship-ss5")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=HELD_OUT_SEED)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--max-tilt-deg", type=float, default=None)
    parser.add_argument("--max-heave-rate", type=float, default=0.15)
    parser.add_argument("--window", type=_window, default=(2.5, 5.0))
    parser.add_argument("--min-wait-s", type=float, default=0.0)
    parser.add_argument("--out", default="results/deck_prediction")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    require_choice("rule", args.rule, RULES)
    require_range("episodes", args.episodes, 1)
    require_range("min_wait_s", args.min_wait_s, 0.0, 15.0)
    max_tilt = args.max_tilt_deg
    if max_tilt is None:
        max_tilt = CalmConfig().max_tilt_deg if args.rule == "calm" else 4.5
    require_range("max_tilt_deg", max_tilt, 0.0, 45.0, low_inclusive=False)
    require_range("max_heave_rate", args.max_heave_rate, 0.0, low_inclusive=False)
    settings = {
        "rule": args.rule,
        "scenario": args.scenario,
        "max_tilt_deg": max_tilt,
        "max_heave_rate": args.max_heave_rate,
        "window_s": args.window,
        "min_wait_s": args.min_wait_s,
    }
    seeds = list(range(args.seed, args.seed + args.episodes))
    results = map_tasks(
        run_episode,
        [(settings, seed) for seed in seeds],
        workers=args.workers,
        progress=not args.no_progress,
        desc=f"{args.scenario} {args.rule}",
    )
    successes = sum(r["outcome"] == "success" for r in results)
    waits = [r["wait_s"] for r in results]
    summary = {
        "settings": settings,
        "seeds": [seeds[0], seeds[-1]],
        "success": successes,
        "episodes": len(results),
        "outcomes": dict(Counter(r["outcome"] for r in results)),
        "forced": sum(w >= 15.0 - 1e-6 for w in waits),
        "wait_median_s": float(np.median(waits)),
        "episodes_detail": results,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rate = f"_{args.max_heave_rate:g}mps" if args.rule == "calm" else ""
    name = f"{args.scenario}_{args.rule}_{max_tilt:g}deg{rate}_wait{args.min_wait_s:g}.json"
    (out / name).write_text(json.dumps(summary, indent=1))
    print(
        f"{args.scenario} {args.rule} ({settings}): {successes} of {len(results)} land "
        f"({100 * successes / len(results):.1f} %); outcomes {summary['outcomes']}; forced "
        f"{summary['forced']}; median wait {summary['wait_median_s']:.1f} s; wrote {out / name}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
