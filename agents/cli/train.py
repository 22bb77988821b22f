"""``deck-landing train timing``: its arguments and what it runs (:mod:`agents.timing.training`)."""

from __future__ import annotations

from typing import Any

from agents.cli_args import positive_int
from agents.timing.policies import shipped_timing_model
from agents.timing.training import ALGOS, load_train_config, train


def _train_timing(args: Any) -> int:
    from rich.console import Console

    console = Console()
    config = load_train_config(args.config, algo=args.algo)
    if args.seed is not None:
        config.settings.seed = args.seed
    if args.n_envs is not None:
        config.hyperparams["n_envs"] = args.n_envs
    result = train(
        config,
        out_dir=args.out,
        total_timesteps=args.timesteps,
        progress_bar=not args.no_progress,
        install=args.install,
    )
    minutes = result.wall_time_s / 60.0
    console.print(
        f"trained {result.timesteps} steps in {minutes:.1f} min ({result.stopped_because})"
    )
    for steps, rate in result.evaluations:
        console.print(f"  evaluation at {steps:>8d} steps: success rate {rate:.3f}")
    console.print(f"final model: {result.model_path}\nbest model: {result.best_model_path}")
    if args.install:
        console.print(f"installed as {shipped_timing_model(config.settings.algo)}")
    return 0


def add_train_parser(subparsers: Any) -> None:
    """Add ``train timing`` to the ``deck-landing`` command."""
    train_parser = subparsers.add_parser("train", help="train a landing policy with SB3")
    which = train_parser.add_subparsers(dest="training", required=True)
    timing = which.add_parser(
        "timing", help="the landing-timing policy of DeckLandingTiming-v0 (PPO or DQN)"
    )
    timing.add_argument("--config", default="configs/train/timing_ppo.yaml", help="training YAML")
    timing.add_argument("--algo", choices=ALGOS, default=None, help="default: the YAML's")
    timing.add_argument("--timesteps", type=positive_int, default=None, help="default: n_timesteps")
    timing.add_argument("--seed", type=int, default=None, help="default: the YAML's")
    timing.add_argument(
        "--n-envs", type=positive_int, default=None, help="default: the YAML's n_envs"
    )
    timing.add_argument("--out", default=None, help="output directory (default: the YAML's)")
    timing.add_argument("--no-progress", action="store_true", help="no progress bar")
    timing.add_argument(
        "--install",
        action="store_true",
        help="copy the best model to agents/models/timing_<algo>.zip (the shipped policy)",
    )
    timing.set_defaults(func=_train_timing)
