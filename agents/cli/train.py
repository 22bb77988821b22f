"""``deck-landing train timing|landing``: the arguments and what they run."""

from __future__ import annotations

from typing import Any

from agents.cli.args import non_negative_int, positive_float, positive_int
from agents.training.trainer import TASK_ALGOS, install_path, load_train_config, train
from landing_env.errors import ConfigError
from landing_env.scenarios import LANDING_TASK, TIMING_TASK

#: the subcommand of each task
TASK_OF = {"timing": TIMING_TASK, "landing": LANDING_TASK}


def _train(args: Any) -> int:
    from rich.console import Console

    console = Console()
    config = load_train_config(args.config, algo=args.algo)
    task = TASK_OF[args.training]
    if config.task != task:
        raise ConfigError(
            "config",
            f"{args.config} trains {config.task} ({config.env_id}); use `deck-landing train "
            f"{'landing' if config.task == LANDING_TASK else 'timing'}`",
        )
    if args.seed is not None:
        config.settings.seed = args.seed
    if args.n_envs is not None:
        config.hyperparams["n_envs"] = args.n_envs
    if args.max_minutes is not None:
        config.settings.max_minutes = args.max_minutes
    if args.eval_freq is not None:
        config.settings.eval.freq = args.eval_freq
    if args.eval_episodes is not None:
        config.settings.eval.episodes = args.eval_episodes
    result = train(
        config,
        out_dir=args.out,
        total_timesteps=args.timesteps,
        progress_bar=not args.no_progress,
        install=args.install,
        force=args.force,
    )
    minutes = result.wall_time_s / 60.0
    console.print(
        f"trained {result.timesteps} steps in {minutes:.1f} min ({result.stopped_because})"
    )
    for steps, rate in result.evaluations:
        console.print(f"  evaluation at {steps:>8d} steps: success rate {rate:.3f}")
    console.print(f"final model: {result.model_path}\nbest model: {result.best_model_path}")
    if args.install:
        console.print(f"installed as {install_path(config)}")
    return 0


def _add_task(which: Any, name: str, help_text: str, default_config: str, model: str) -> None:
    parser = which.add_parser(name, help=help_text)
    algos = TASK_ALGOS[TASK_OF[name]]
    parser.add_argument("--config", default=default_config, help="training YAML")
    parser.add_argument("--algo", choices=algos, default=None, help="default: the YAML's")
    parser.add_argument(
        "--timesteps",
        type=non_negative_int,
        default=None,
        help="default: n_timesteps; 0: the imitation stage alone (deck_landing.imitation)",
    )
    parser.add_argument("--seed", type=int, default=None, help="default: the YAML's")
    parser.add_argument(
        "--n-envs", type=positive_int, default=None, help="default: the YAML's n_envs"
    )
    parser.add_argument(
        "--max-minutes",
        type=positive_float,
        default=None,
        help="wall-clock budget (default: the YAML's max_minutes)",
    )
    parser.add_argument(
        "--eval-freq",
        type=positive_int,
        default=None,
        help="evaluate every this many steps (default: the YAML's eval.freq)",
    )
    parser.add_argument(
        "--eval-episodes",
        type=positive_int,
        default=None,
        help="held-out episodes per evaluation (default: the YAML's eval.episodes)",
    )
    parser.add_argument("--out", default=None, help="output directory (default: the YAML's)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--install",
        action="store_true",
        help=f"copy the best model to agents/models/{model}_<algo>.zip (the shipped policy)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="with --install: replace a shipped model there (a policy flies it)",
    )
    parser.set_defaults(func=_train)


def add_train_parser(subparsers: Any) -> None:
    """Add ``train timing`` and ``train landing`` to the ``deck-landing`` command."""
    train_parser = subparsers.add_parser("train", help="train a landing policy with SB3")
    which = train_parser.add_subparsers(dest="training", required=True)
    _add_task(
        which,
        "timing",
        "the landing-timing policy of DeckLandingTiming-v0 (PPO, DQN or RecurrentPPO)",
        "configs/train/timing_ppo.yaml",
        "timing",
    )
    _add_task(
        which,
        "landing",
        "a lander of DeckLanding-v2, end to end (PPO, SAC or TQC)",
        "configs/train/lander_ppo.yaml",
        "lander",
    )
