r"""A training run's learning curve: the held-out evaluations ``EvalCallback`` wrote.

``deck-landing train`` evaluates every ``eval.freq`` steps on held-out seeds and SB3 stores
them in ``<run>/eval/evaluations.npz`` (``timesteps``, ``results`` (returns), ``ep_lengths``
and, for environments that report ``info["is_success"]``, ``successes``).  This module reads
that file and draws the success rate and the mean return against the steps trained, with the
wall time of the run where its summary gives it::

    python -m agents.training.learning_curve results/train/lander_ppo \
        --out docs/img/lander-learning-curve.png

Training writes ``<run>/learning_curve.png`` and ``learning_curve.csv`` itself at its end.
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from landing_env.errors import ConfigError


@dataclass(frozen=True)
class LearningCurve:
    """One row per evaluation: steps, success rate, mean and std of the return, mean length."""

    timesteps: np.ndarray
    success_rate: np.ndarray
    return_mean: np.ndarray
    return_std: np.ndarray
    length_mean: np.ndarray
    episodes: int
    wall_time_s: float | None = None


def read_learning_curve(run_dir: str | Path) -> LearningCurve:
    """The evaluations of the run in ``run_dir``; ``ConfigError`` naming the file when it is
    missing or is not an ``EvalCallback`` file."""
    run = Path(run_dir)
    path = run / "eval" / "evaluations.npz"
    if not path.is_file():
        raise ConfigError("run_dir", f"{path} not found: is {run} a `deck-landing train` output?")
    try:
        data = np.load(path)
        timesteps = np.asarray(data["timesteps"], dtype=int)
        returns = np.asarray(data["results"], dtype=float)
    except (KeyError, ValueError, OSError) as error:
        raise ConfigError(
            "run_dir", f"{path} is not an EvalCallback file (timesteps, results): {error}"
        ) from None
    if returns.ndim != 2 or len(returns) != len(timesteps) or len(timesteps) == 0:
        raise ConfigError("run_dir", f"{path} holds no evaluations")
    successes = np.asarray(data["successes"], dtype=float) if "successes" in data else None
    if successes is None or successes.shape != returns.shape:
        successes = np.full_like(returns, np.nan)
    lengths = np.asarray(data["ep_lengths"], dtype=float) if "ep_lengths" in data else returns * 0
    wall = None
    summary = run / "train_summary.yaml"
    if summary.is_file():
        wall = (yaml.safe_load(summary.read_text()) or {}).get("wall_time_s")
    return LearningCurve(
        timesteps=timesteps,
        success_rate=successes.mean(axis=1),
        return_mean=returns.mean(axis=1),
        return_std=returns.std(axis=1),
        length_mean=lengths.mean(axis=1),
        episodes=int(returns.shape[1]),
        wall_time_s=None if wall is None else float(wall),
    )


def write_learning_curve(curve: LearningCurve, png: str | Path, title: str = "") -> Path:
    """The curve as a two-panel PNG at ``png`` and the same rows as a CSV beside it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    with png.with_suffix(".csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["timesteps", "success_rate", "return_mean", "return_std", "length_mean"])
        for row in zip(
            curve.timesteps,
            curve.success_rate,
            curve.return_mean,
            curve.return_std,
            curve.length_mean,
            strict=True,
        ):
            writer.writerow([int(row[0]), *(f"{value:.4g}" for value in row[1:])])
    steps_k = curve.timesteps / 1000.0
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    top.plot(steps_k, 100.0 * curve.success_rate, "o-", color="tab:green")
    top.set_ylabel(f"success, % of {curve.episodes}")
    top.set_ylim(-2, 102)
    top.grid(alpha=0.3)
    bottom.plot(steps_k, curve.return_mean, "o-", color="tab:blue")
    bottom.fill_between(
        steps_k,
        curve.return_mean - curve.return_std,
        curve.return_mean + curve.return_std,
        alpha=0.2,
        color="tab:blue",
    )
    bottom.set_ylabel("return (mean ± std)")
    bottom.set_xlabel("steps trained (thousands)")
    bottom.grid(alpha=0.3)
    wall = "" if curve.wall_time_s is None else f", {curve.wall_time_s / 60.0:.0f} min"
    top.set_title(f"{title}{' ' if title else ''}(held-out evaluations{wall})")
    figure.tight_layout()
    figure.savefig(png, dpi=110)
    plt.close(figure)
    return png


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", help="a `deck-landing train` output directory")
    parser.add_argument("--out", default=None, help="PNG (default: <run_dir>/learning_curve.png)")
    parser.add_argument("--title", default="", help="the figure's title")
    args = parser.parse_args(argv)
    curve = read_learning_curve(args.run_dir)
    png = write_learning_curve(
        curve, args.out or Path(args.run_dir) / "learning_curve.png", args.title
    )
    print(f"{png} ({len(curve.timesteps)} evaluations of {curve.episodes} episodes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
