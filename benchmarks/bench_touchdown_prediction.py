"""What a linear deck-tilt predictor is worth for the timing task, measured on hindsight labels.

    python -m benchmarks.bench_touchdown_prediction [--scenario bench-ss4 bench-ss5]
        [--sensing realistic] [--episodes 20] [--seed 800000] [--max-decisions 60] [--every 3]
        [--descent timed|range]

The "quiescent period prediction" of ship landing (Sidar and Doolin, IEEE TAC 28(3), 1983;
Yumori, OCEANS 1981; Triantafyllou, Bodson and Athans, IEEE JOE 8(1), 1983) predicts the deck
motion a descent ahead from its recent history with a linear (AR / Kalman) model.  Here:

1. Seeded waiting episodes of the timing task (not the evaluation's held-out seeds); at every
   ``every``-th decision the commit is tried in a snapshot (:mod:`agents.training.hindsight`), so
   each labelled decision has the touchdown that committing then would have given.
2. A direct linear predictor (ridge least squares on the last 2 s of the *estimated*, levelled
   roll and pitch) of the estimated roll and pitch 1.0-2.7 s ahead is fitted on half the
   episodes' estimate series (self-supervised: no labels needed) and applied to the other half,
   and the other way round.
3. Printed: the time from the commit to the first contact, the predictor's tilt error against
   the touchdown's deck tilt per horizon, the success of a commit per bin of the predicted
   largest tilt over the likely contact times (the measured commit-to-contact time's mean +-
   one standard deviation, at least +-0.1 s), and the replayed rule "commit when that
   prediction is below a threshold".
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from agents.training.hindsight import collect_labels, make_timing_env, replay_rule
from landing_env.timing.history import HISTORY_FEATURES

#: prediction horizons, in samples of the history (20 Hz): 1.0-2.7 s
HORIZONS = np.arange(20, 56, 2)
WINDOW = 40
_ROLL, _PITCH, _VALID = (HISTORY_FEATURES.index(n) for n in ("roll", "pitch", "valid"))


def estimate_series(waited: np.ndarray, layout) -> np.ndarray:
    """(rows, 2) levelled roll and pitch of one episode, from its successive observations (each
    adds the decision's new rows to the previous history); an invalid row repeats the last."""
    first = layout.decode(waited[0]).history
    rows = [first]
    for observation in waited[1:]:
        rows.append(layout.decode(observation).history[-2:])
    series = np.concatenate(rows)
    values = series[:, [_ROLL, _PITCH]].copy()
    for i in range(len(values)):
        if series[i, _VALID] < 0.5:
            values[i] = values[i - 1] if i else 0.0
    return values


def _window(values: np.ndarray) -> np.ndarray:
    return np.r_[values[:, 0], values[:, 1], 1.0]


def fit_predictor(series: list[np.ndarray], ridge: float = 1e-4) -> np.ndarray:
    """Ridge weights mapping a 2 s window to roll and pitch at :data:`HORIZONS`."""
    x, y = [], []
    for values in series:
        for end in range(WINDOW - 1, len(values) - HORIZONS.max()):
            x.append(_window(values[end - WINDOW + 1 : end + 1]))
            y.append(np.r_[values[end + HORIZONS, 0], values[end + HORIZONS, 1]])
    x, y = np.array(x), np.array(y)
    return np.linalg.solve(x.T @ x + ridge * len(x) * np.eye(x.shape[1]), x.T @ y)


def predicted_tilt_deg(observations: np.ndarray, weights: np.ndarray, layout) -> np.ndarray:
    """(N, horizons) predicted tilt from each observation's own 2 s history."""
    out = []
    for observation in observations:
        history = layout.decode(observation).history
        values = history[:, [_ROLL, _PITCH]].copy()
        for i in range(len(values)):
            if history[i, _VALID] < 0.5:
                values[i] = values[i - 1] if i else 0.0
        p = _window(values[-WINDOW:]) @ weights
        n = len(HORIZONS)
        out.append(np.degrees(np.arccos(np.clip(np.cos(p[:n]) * np.cos(p[n:]), -1.0, 1.0))))
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenario", nargs="+", default=["bench-ss4", "bench-ss5"])
    parser.add_argument("--sensing", default="realistic")
    parser.add_argument("--episodes", type=int, default=20, help="per scenario")
    parser.add_argument("--seed", type=int, default=800_000)
    parser.add_argument("--max-decisions", type=int, default=60)
    parser.add_argument("--every", type=int, default=3)
    parser.add_argument(
        "--descent",
        choices=("timed", "range"),
        default="timed",
        help="the final descent (the bench scenarios' timed one, or the range schedule of v0)",
    )
    args = parser.parse_args()

    started = time.process_time()
    margin, tilt, predicted, episode, descent = [], [], [], [], []
    for k, scenario in enumerate(args.scenario):
        env = make_timing_env(
            scenario,
            args.sensing,
            "tight",
            {"touchdown.settle_time_s": 0.5, "timing.guidance.descent_profile": args.descent},
        )
        layout = env.unwrapped.layout
        seeds = list(range(args.seed + 10_000 * k, args.seed + 10_000 * k + args.episodes))
        labels = collect_labels(env, seeds, args.max_decisions, args.every)
        env.close()
        descent.append(labels.descent_s[np.isfinite(labels.deck_tilt_deg)])
        series = [estimate_series(w, layout) for w in labels.waited]
        halves = (np.arange(len(series)) % 2 == 0, np.arange(len(series)) % 2 == 1)
        for fit_on, apply_to in (halves, halves[::-1]):
            weights = fit_predictor([s for s, use in zip(series, fit_on, strict=True) if use])
            rows = apply_to[labels.episode]
            predicted.append(predicted_tilt_deg(labels.observations[rows], weights, layout))
            margin.append(labels.margin[rows])
            tilt.append(labels.deck_tilt_deg[rows])
            episode.append(labels.episode[rows] + 1_000_000 * k)
    margin, tilt = np.concatenate(margin), np.concatenate(tilt)
    predicted, episode = np.concatenate(predicted), np.concatenate(episode)
    print(
        f"{len(margin)} labelled decisions of {len(np.unique(episode))} episodes "
        f"({', '.join(args.scenario)}, sensing {args.sensing}, tight observed, "
        f"{args.descent} descent), "
        f"{time.process_time() - started:.0f} s CPU"
    )
    descent = np.concatenate(descent)
    print(
        f"commit to first contact: {descent.mean():.2f} s mean, {descent.std():.2f} s sd, "
        f"{descent.min():.2f}-{descent.max():.2f} s"
    )
    now = replay_rule(margin, np.ones(len(margin), dtype=bool), episode)
    best = np.mean([margin[episode == e].max() >= 0.0 for e in np.unique(episode)])
    print(f"land-now {100 * now['success']:.1f}%; some labelled decision lands: {100 * best:.1f}%")
    touched = np.isfinite(tilt)
    print("tilt error |predicted - touchdown deck tilt| (deg), mean by horizon:")
    print(
        "  "
        + "  ".join(
            f"{h * 0.05:.1f}s {np.mean(np.abs(predicted[touched, j] - tilt[touched])):.2f}"
            for j, h in enumerate(HORIZONS)
        )
    )
    spread = max(float(descent.std()), 0.1)
    low_s, high_s = descent.mean() - spread, descent.mean() + spread
    contact = (HORIZONS * 0.05 >= low_s - 1e-9) & (HORIZONS * 0.05 <= high_s + 1e-9)
    if not contact.any():
        contact = np.abs(HORIZONS * 0.05 - descent.mean()) == np.min(
            np.abs(HORIZONS * 0.05 - descent.mean())
        )
    score = predicted[:, contact].max(axis=1)
    print(f"success of a commit by predicted largest tilt at {low_s:.1f}-{high_s:.1f} s:")
    for low, high in ((0, 1.5), (1.5, 2), (2, 2.5), (2.5, 3), (3, 4), (4, 6), (6, 90)):
        inside = (score >= low) & (score < high)
        rate = 100 * np.mean(margin[inside] >= 0.0) if inside.any() else float("nan")
        print(f"  [{low}, {high}) deg: {inside.sum():5d} decisions, {rate:5.1f}% land")
    print("replayed rule 'commit when the predicted largest tilt < threshold':")
    for threshold in (1.5, 2.0, 2.5, 3.0, 3.5):
        r = replay_rule(margin, score < threshold, episode)
        print(
            f"  {threshold:.1f} deg: success {100 * r['success']:.1f}%, precision "
            f"{100 * r['precision']:.1f}%, {int(r['episodes_without_commit'])} of "
            f"{int(r['episodes'])} without a commit in {args.max_decisions / 10:.1f} s"
        )


if __name__ == "__main__":
    main()
