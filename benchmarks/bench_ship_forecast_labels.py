"""What the helideck forecast tells a learned timing policy, measured on hindsight labels.

    python -m benchmarks.bench_ship_forecast_labels [--scenario ship-ss5] [--episodes 60]
        [--seed 6000] [--every 5] [--out results/ship_forecast_labels]
        [--labels FILE.npz [FILE.npz ...]]

The timing task's ``forecast`` observation (the ship ids' v5) holds the newest deck-pose
estimate, the ToF ranges, the ship's helideck forecast 0-8 s ahead and the drone's own
velocity and lean.  Seeded waiting episodes (not the evaluation's held-out seeds) are flown
with it, and at every ``every``-th decision a commit is tried in a snapshot
(:func:`agents.training.hindsight.collect_labels`), so each labelled observation has the touchdown a
commit then would have given.  Then, with the episodes in 5 folds (held out by episode), a
logistic regression and a two-layer MLP (64 units, PyTorch) are fitted on three subsets of
the observation: the present alone (estimate, ranges, wait, own state), the present and the
forecast, and the forecast alone.  Printed for each: the held-out AUC of the commit's
success, and the success of replaying its held-out chances (:func:`agents.training.hindsight.
replay_rule`) against the value of waiting on and, in hindsight, at the best fixed threshold;
then committing at once and the best commit on the labels' grid.

Two processes collecting half the seeds each (``--seed 6000`` and ``--seed 6060``) and one
replay of both files (``--labels a.npz b.npz``) is how the README's figures were made.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from agents.training.hindsight import LabelSet, collect_labels, make_timing_env, replay_rule
from landing_env.timing.layout import timing_layout
from landing_env.timing.stopping import StoppingValues

#: the subsets of the observation compared (names of :func:`observation_columns`' groups)
SUBSETS = {
    "present": ("present",),
    "present + forecast": ("present", "forecast"),
    "forecast": ("forecast",),
}


def observation_columns(env) -> dict[str, list[int]]:
    """The flat observation's columns of the newest estimate, ranges and wait fraction and own
    state ("present"), and of the forecast and its validity ("forecast")."""
    base = env.unwrapped
    layout = timing_layout(base.timing, base.config.simulation.env_hz)
    head = layout.observed_rows * 10
    forecast = head + 9
    own = forecast + layout.n_forecast * 5 + 1
    return {
        "present": [*range(0, forecast), *range(own, layout.size)],
        "forecast": list(range(forecast, own)),
    }


def auc(score: np.ndarray, success: np.ndarray) -> float:
    """The area under the ROC curve of ``score`` for ``success`` (Mann-Whitney)."""
    from scipy.stats import rankdata

    ranks = rankdata(score)
    n1 = int(success.sum())
    n0 = len(success) - n1
    if n1 == 0 or n0 == 0:
        return float("nan")
    return float((ranks[success].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def heldout_chances(
    features: np.ndarray, success: np.ndarray, episode: np.ndarray, hidden: int, seed: int = 0
) -> np.ndarray:
    """Each example's chance of success from a model fitted on the other folds' episodes
    (``hidden`` 0: logistic regression; else a two-layer MLP of that width)."""
    import torch

    episodes = np.unique(episode)
    np.random.default_rng(seed).shuffle(episodes)
    chances = np.zeros(len(success))
    for fold in np.array_split(episodes, 5):
        test = np.isin(episode, fold)
        train = ~test
        torch.manual_seed(seed)
        mean = features[train].mean(axis=0)
        scale = features[train].std(axis=0) + 1e-6
        x = torch.tensor((features - mean) / scale, dtype=torch.float32)
        y = torch.tensor(success, dtype=torch.float32)
        width = features.shape[1]
        net: torch.nn.Module
        if hidden:
            net = torch.nn.Sequential(
                torch.nn.Linear(width, hidden),
                torch.nn.ReLU(),
                torch.nn.Linear(hidden, hidden),
                torch.nn.ReLU(),
                torch.nn.Linear(hidden, 1),
            )
        else:
            net = torch.nn.Linear(width, 1)
        optimiser = torch.optim.Adam(
            net.parameters(), lr=3e-3, weight_decay=1e-2 if hidden else 1e-3
        )
        rows = torch.tensor(np.where(train)[0])
        for _ in range(150 if hidden else 300):
            optimiser.zero_grad()
            logits = net(x[rows]).squeeze(-1)
            loss = torch.nn.functional.binary_cross_entropy_with_logits(logits, y[rows])
            loss.backward()
            optimiser.step()
        with torch.no_grad():
            chances[test] = torch.sigmoid(
                net(x[torch.tensor(np.where(test)[0])]).squeeze(-1)
            ).numpy()
    return chances


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="ship-ss5")
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=6000)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--out", default="results/ship_forecast_labels")
    parser.add_argument("--labels", nargs="+", default=[], help="replay saved label files")
    args = parser.parse_args(argv)

    env = make_timing_env(args.scenario, "realistic", "tight", {"timing.observation": "forecast"})
    base = env.unwrapped
    columns = observation_columns(env)
    decision_s = base.timing.steps_per_decision * base.env_dt
    wait_limit_s = base.timing.wait_limit_s
    started = time.perf_counter()
    try:
        if args.labels:
            sets = [LabelSet.load(path) for path in args.labels]
        else:
            seeds = list(range(args.seed, args.seed + args.episodes))
            sets = [collect_labels(env, seeds, round(wait_limit_s / decision_s), args.every)]
            path = Path(args.out) / f"{args.scenario}_seed{args.seed}_labels.npz"
            sets[0].save(path)
            print(f"labels of seeds {seeds[0]}-{seeds[-1]} in {path}")
    finally:
        env.close()
    observations = np.concatenate([s.observations for s in sets]).astype(float)
    success = np.concatenate([s.success for s in sets])
    episode = np.concatenate([s.episode + 100_000 * k for k, s in enumerate(sets)])
    decision = np.concatenate([s.decision for s in sets])
    print(
        f"{args.scenario}: {len(np.unique(episode))} episodes, {len(success)} labels, a commit "
        f"lands {success.mean():.3f} ({time.perf_counter() - started:.0f} s)"
    )
    landed = np.where(success, 0.0, -1.0)
    left_s = wait_limit_s - decision * decision_s
    for name, groups in SUBSETS.items():
        features = observations[:, [c for group in groups for c in columns[group]]]
        for hidden in (0, 64):
            chances = heldout_chances(features, success, episode, hidden)
            values = StoppingValues.from_samples(chances)
            thresholds = np.array([values.threshold(float(r), 1.0) for r in left_s])
            by_value = replay_rule(landed, chances >= thresholds, episode)["success"]
            fixed = max(
                (replay_rule(landed, chances >= t, episode)["success"], t)
                for t in np.arange(0.5, 0.96, 0.05)
            )
            model = f"MLP {hidden}x{hidden}" if hidden else "logistic"
            print(
                f"  {name:20s} {model:10s} held-out AUC {auc(chances, success):.3f}; replayed "
                f"against the value of waiting {by_value:.3f}, at the best fixed threshold "
                f"{fixed[0]:.3f} ({fixed[1]:.2f}, chosen in hindsight)"
            )
    now = replay_rule(landed, np.ones(len(success), bool), episode)["success"]
    best = np.mean([success[episode == e].any() for e in np.unique(episode)])
    print(f"  commit at once: {now:.3f}; the best commit on the labels' grid: {best:.3f}")


if __name__ == "__main__":
    main()
