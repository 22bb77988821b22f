"""What a horizontal reference below the tag's view would buy a ship landing (privileged).

    python -m benchmarks.bench_blind_reference --policy quiescent land-now \\
        [--scenario ship-ss4] [--sensors realistic] [--episodes 200] [--seed 1000000] \\
        [--out results/blind-reference]

On the ship the deck-frame guidance sees the tag down to ``blind_range_m`` (0.8 m: below it
the tag no longer fits the view of a camera leaning 10-25 deg in wind); lower, the ToF
measures the height and nothing measures where the pad is, so the horizontal track coasts
and is dropped after ``tracker_coast_s``.  When the last 0.2 m over a rising deck take two
seconds or more, the helideck's sway carries the pad from under the drone (README "Sea state
4 on 200 more seeds").  Here the guidance's deck tracker is given the **true** horizontal
position of the tag whenever the tag is not seen: a perfect reference, the upper bound of
what an aid such as the ship's HMS data link or a small nested tag at the landing point
could give.  Everything else is the evaluation's: the same environment, policy and held-out
seeds as ``deck-landing evaluate landing``; a policy's look-ahead (the oracles, the
look-ahead DQN) flies the aided guidance as well.

Writes ``landing_<scenario>_<policy>+xy-truth.jsonl`` in ``--out`` (one episode a line, the
evaluation's records), so that ``python -m agents.evaluation.paired`` compares it with the
unaided run seed by seed.  One process, one core: split the seeds over two processes
(``--seed``, ``--episodes``) to use both.
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from agents.evaluation.landing import SCENARIOS, EpisodeResult, make_env_and_policy, run_episode
from landing_env.config import SENSORS_ENV

#: the suffix of an aided policy's name in the records
SUFFIX = "+xy-truth"


@contextmanager
def aided_tracker(env: Any) -> Iterator[None]:
    """While inside, the deck tracker of the guidance gets the true horizontal tag position
    whenever the observation does not measure it (``env``: the unwrapped timing task; the
    look-ahead's restored copies are read through it, as they replace its state in place).
    The tracker's own ``measure`` is put back on leaving, so that each run aids only its own
    environment."""
    from landing_env.timing.deck_tracker import DeckTracker

    measure = DeckTracker.measure

    def aided(observation: dict[str, np.ndarray], own: Any) -> np.ndarray:
        measured = measure(observation, own)
        if not np.isfinite(measured[0]):
            measured[:2] = env.world.deck_state().tag_centre_w[:2]
        return measured

    DeckTracker.measure = staticmethod(aided)  # type: ignore[method-assign]
    try:
        yield
    finally:
        DeckTracker.measure = staticmethod(measure)  # type: ignore[method-assign]


def run(
    policy: str,
    scenario: str,
    episodes: int,
    seed: int,
    out: Path,
    allow_mismatch: tuple[str, ...] = (),
) -> Path:
    env, actor = make_env_and_policy(
        policy, scenario, SCENARIOS[scenario].estimator, allow_mismatch=allow_mismatch
    )
    with aided_tracker(env.unwrapped):
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"landing_{scenario}_{policy}{SUFFIX}.jsonl"
        landed = 0
        with path.open("a") as sink:
            bar = tqdm(range(seed, seed + episodes), desc=f"{policy}{SUFFIX} @ {scenario}")
            for episode_seed in bar:
                result: EpisodeResult = run_episode(
                    env, actor, episode_seed, policy + SUFFIX, scenario
                )
                sink.write(json.dumps(result.to_json()) + "\n")
                sink.flush()
                landed += int(result.success)
                bar.set_postfix(success=f"{landed}/{episode_seed - seed + 1}")
    env.close()
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--policy", nargs="+", required=True)
    parser.add_argument("--scenario", default="ship-ss4")
    parser.add_argument("--sensors", default="realistic")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--out", type=Path, default=Path("results/blind-reference"))
    parser.add_argument("--allow-mismatch", nargs="*", default=[], help="as evaluate landing's")
    args = parser.parse_args(argv)
    os.environ[SENSORS_ENV] = args.sensors
    for policy in args.policy:
        mismatch = tuple(args.allow_mismatch)
        path = run(policy, args.scenario, args.episodes, args.seed, args.out, mismatch)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
