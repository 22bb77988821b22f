"""What better timing could still win on a ship deck, measured on hindsight labels.

    python -m benchmarks.bench_ship_commit_labels [--scenario ship-ss4] [--sensing realistic]
        [--episodes 120] [--seed 6000] [--max-decisions 150] [--every 5]
        [--out results/ship_labels] [--set timing.guidance.tracker_model=velocity ...]
        [--windows 1,2] [--labels results/ship_labels/ship-ss5_labels.npz] [--plot FILE.png]

The oracle (:mod:`agents.policies.oracle`) tries a commit at every decision (0.1 s apart) and
knows the gusts and the heave to come; its lead over a policy mixes what the observation
could tell and
what no observation tells.  This benchmark separates the two:

1. Seeded waiting episodes of the timing task (not the evaluation's held-out seeds); at every
   ``every``-th decision the commit is tried in a snapshot (:mod:`agents.training.hindsight`), so
   each labelled decision has the touchdown committing then would have given.
2. Printed: the success of a commit at a labelled decision; how failures cluster in time (the
   chance that the commit ``every`` decisions later lands after one that failed, against after
   one that landed: persistent causes are in principle visible, isolated ones are luck); the
   best any commit on the labels' grid could do (the oracle on that grid); committing at once
   (``land-now``); and the ``quiescent`` rule (:func:`agents.policies.calm_window.predict_calm`)
   replayed with its defaults and with each of a grid of its settings
   (:func:`agents.training.hindsight.replay_rule`; an episode without a calm decision commits at
   its last label), all judged by the outcome.
3. What the observation can tell: a commit-chance model (:mod:`agents.timing.commit_chance`, a
   logistic regression on statistics of the observed deck motion over ``--windows``) fitted on
   the labels, its held-out AUC (episodes in 5 folds), and its held-out chances replayed
   against the optimal-stopping value of waiting on.

The labels are written to ``--out`` (``<scenario>_labels.npz``) for further analysis.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np

from agents.cli.args import add_set_argument
from agents.common.user_input import parse_overrides
from agents.policies.calm_window import CalmConfig, predict_calm
from agents.timing.commit_chance import CommitChanceModel, commit_features
from agents.training.hindsight import LabelSet, collect_labels, make_timing_env, replay_rule
from landing_env.timing.stopping import StoppingValues

#: the grid of the ``quiescent`` rule's settings replayed
CALM_GRID = {
    "window_s": (1.3, 2.0),
    "max_tilt_deg": (3.0, 4.0, 5.0),
    "max_heave_rate": (0.1, 0.15, 0.3),
    "min_valid_fraction": (0.8, 1.0),
}


def clustering(labels: LabelSet) -> tuple[float, float, int, int]:
    """P(the next labelled commit lands | this one landed), P(... | this one failed), and of
    the failures inside an episode's labels, how many had both neighbours land."""
    after_ok, after_fail, isolated, inner = [], [], 0, 0
    for episode in np.unique(labels.episode):
        s = labels.success[labels.episode == episode]
        for k in range(len(s) - 1):
            (after_ok if s[k] else after_fail).append(bool(s[k + 1]))
        for k in range(1, len(s) - 1):
            if not s[k]:
                inner += 1
                isolated += int(s[k - 1] and s[k + 1])
    return (
        float(np.mean(after_ok)) if after_ok else float("nan"),
        float(np.mean(after_fail)) if after_fail else float("nan"),
        isolated,
        inner,
    )


def calm_commits(labels: LabelSet, layout, dt: float, config: CalmConfig) -> np.ndarray:
    """Whether the ``quiescent`` rule with ``config`` commits at each labelled decision."""
    return np.array(
        [predict_calm(layout.decode(o).history, dt, config).calm for o in labels.observations]
    )


def learned_chance(
    labels: LabelSet, layout, dt: float, windows_s: tuple[float, ...]
) -> CommitChanceModel:
    """The commit-chance model fitted on the labels (held-out chances by episode folds)."""
    features = []
    for observation in labels.observations:
        parts = layout.decode(observation)
        features.append(
            commit_features(parts.history, dt, windows_s, parts.tof_valid, parts.wait_fraction)
        )
    return CommitChanceModel.fit(np.array(features), labels.success, labels.episode, windows_s, dt)


def value_commits(
    chances: np.ndarray,
    decision: np.ndarray,
    decision_s: float,
    wait_limit_s: float,
    opportunity_s: float,
) -> np.ndarray:
    """Whether a chance beats the value of waiting on (over the wait left at its decision)."""
    values = StoppingValues.from_samples(chances)
    left = wait_limit_s - decision * decision_s
    thresholds = np.array([values.threshold(float(r), opportunity_s) for r in left])
    return np.nan_to_num(chances, nan=0.0) >= thresholds


def plot_labels(
    labels: LabelSet,
    chances: np.ndarray,
    calm: np.ndarray,
    grid_s: float,
    title: str,
    path: Path,
) -> Path:
    """Each episode's hindsight outcomes along its wait (a row per episode, the roughest at
    the top), where ``quiescent`` commits, and the learned chance of each label beside the
    outcome (a histogram per outcome)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    episodes = np.unique(labels.episode)
    order = sorted(episodes, key=lambda e: labels.success[labels.episode == e].mean())
    decisions = np.unique(labels.decision)
    step = int(np.diff(decisions).min()) if len(decisions) > 1 else 1
    width = int(labels.decision.max() // step) + 1
    raster = np.full((len(order), width), np.nan)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 5), width_ratios=[2.2, 1])
    for row, episode in enumerate(order):
        mine = labels.episode == episode
        columns = labels.decision[mine] // step
        raster[row, columns] = labels.success[mine]
        hits = np.where(calm[mine])[0]
        column = columns[hits[0]] if len(hits) else columns[-1]
        left.plot((column + 0.5) * grid_s, row + 0.5, "kx", markersize=4)
    left.pcolormesh(
        np.arange(width + 1) * grid_s,
        np.arange(len(order) + 1),
        np.ma.masked_invalid(raster),
        cmap=ListedColormap(["#d62728", "#2ca02c"]),
        vmin=0,
        vmax=1,
    )
    left.set_xlabel("commit at (s into the wait)")
    left.set_ylabel("episode (roughest at the top)")
    left.invert_yaxis()
    left.set_title("a commit then: lands (green) or fails (red); x: quiescent's commit", fontsize=9)
    bins = np.linspace(0.0, 1.0, 21)
    finite = np.isfinite(chances)
    right.hist(chances[finite & labels.success], bins, alpha=0.6, color="#2ca02c", label="lands")
    right.hist(chances[finite & ~labels.success], bins, alpha=0.6, color="#d62728", label="fails")
    right.set_xlabel("learned commit chance (held out)")
    right.set_ylabel("commits")
    right.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="ship-ss4")
    parser.add_argument("--sensing", default="realistic")
    parser.add_argument("--estimator", default="tight")
    parser.add_argument("--episodes", type=int, default=120)
    parser.add_argument("--seed", type=int, default=6000)
    parser.add_argument("--max-decisions", type=int, default=150)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--out", default="results/ship_labels")
    parser.add_argument(
        "--windows",
        default="1,2",
        help="the learned commit chance's windows, seconds (within timing.history_s)",
    )
    parser.add_argument(
        "--labels", default="", help="replay a saved label file instead of collecting labels"
    )
    parser.add_argument("--plot", default="", help="write the labels' figure here (.png)")
    add_set_argument(parser)
    args = parser.parse_args(argv)

    env = make_timing_env(
        args.scenario, args.sensing, args.estimator, parse_overrides(args.set or [])
    )
    base = env.unwrapped
    started = time.perf_counter()
    try:
        if args.labels:
            labels = LabelSet.load(args.labels)
        else:
            labels = collect_labels(
                env,
                list(range(args.seed, args.seed + args.episodes)),
                args.max_decisions,
                args.every,
            )
    finally:
        env.close()
    path = (
        Path(args.labels)
        if args.labels
        else labels.save(Path(args.out) / f"{args.scenario}_labels.npz")
    )
    decision_s = base.timing.steps_per_decision * base.env_dt
    # the labels' own grid (a replayed file need not match the command's --every)
    decisions = np.unique(labels.decision)
    every = int(np.diff(decisions).min()) if len(decisions) > 1 else args.every
    grid_s = every * decision_s
    episodes = np.unique(labels.episode)
    if args.labels:
        origin = f"replayed from {path}"
    else:
        origin = (
            f"seeds {args.seed}-{args.seed + args.episodes - 1}, "
            f"{time.perf_counter() - started:.0f} s; labels in {path}"
        )
    print(
        f"{args.scenario}, {args.sensing}, {args.estimator}: {len(episodes)} episodes, a commit "
        f"tried every {grid_s:g} s from 0 to {decisions.max() * decision_s:g} s into the wait "
        f"({len(labels.success)} labels; {origin})"
    )
    print(f"a commit at a labelled decision lands: {labels.success.mean():.3f}")
    ok_next, fail_next, isolated, inner = clustering(labels)
    print(
        f"the commit {grid_s:g} s later lands: {ok_next:.3f} after one that landed, "
        f"{fail_next:.3f} after one that failed; {isolated} of {inner} failures had both "
        "neighbours land"
    )
    best = np.mean([labels.success[labels.episode == e].any() for e in episodes])
    # judged by the outcome (every check: a tip-over or a bounce fails with a positive margin)
    landed = np.where(labels.success, 0.0, -1.0)
    now = replay_rule(landed, np.ones(len(landed), bool), labels.episode)
    print(f"any commit on the {grid_s:g} s grid (its oracle): {best:.3f}")
    print(f"land-now (the first label): {now['success']:.3f}")
    layout, dt = base.layout, base.env_dt
    default = replay_rule(landed, calm_commits(labels, layout, dt, CalmConfig()), labels.episode)
    print(f"quiescent (its defaults): {default['success']:.3f}")
    rows = []
    for values in itertools.product(*CALM_GRID.values()):
        settings = dict(zip(CALM_GRID, values, strict=True))
        commits = calm_commits(labels, layout, dt, CalmConfig(**settings))
        result = replay_rule(landed, commits, labels.episode)
        rows.append((result["success"], result["episodes_without_commit"], settings))
    rows.sort(key=lambda row: -row[0])
    print(f"quiescent over its {len(rows)} settings of CALM_GRID, best first:")
    for success, without, settings in rows[:5]:
        print(f"  {success:.3f} ({without:.0f} episodes never calm)  {settings}")
    print(f"  worst: {rows[-1][0]:.3f}  {rows[-1][2]}")
    windows = tuple(float(w) for w in args.windows.split(","))
    model = learned_chance(labels, layout, dt, windows)
    weights = sorted(zip(model.names, model.weights[:-1], strict=True), key=lambda r: -abs(r[1]))
    print(
        f"the learned commit chance (agents.timing.commit_chance, windows {list(windows)} s): "
        f"held-out AUC {model.metadata['heldout_auc']:.3f}; largest standardised weights: "
        + ", ".join(f"{name} {w:+.2f}" for name, w in weights[:4])
    )
    decision_s = base.timing.steps_per_decision * dt
    for opportunity_s in (1.0, 3.0):
        commits = value_commits(
            model.heldout_chances,
            labels.decision,
            decision_s,
            base.timing.wait_limit_s,
            opportunity_s,
        )
        result = replay_rule(landed, commits, labels.episode)
        print(
            f"  its held-out chance against the value of waiting on (one opportunity per "
            f"{opportunity_s:g} s): {result['success']:.3f}"
        )
    if args.plot:
        title = (
            f"{args.scenario}, {args.sensing}, {args.estimator}: hindsight commits of "
            f"{len(episodes)} waiting episodes (held-out AUC of the learned chance "
            f"{model.metadata['heldout_auc']:.2f})"
        )
        calm = calm_commits(labels, layout, dt, CalmConfig())
        figure = plot_labels(labels, model.heldout_chances, calm, grid_s, title, Path(args.plot))
        print(f"wrote {figure}")


if __name__ == "__main__":
    main()
