"""``deck-landing tune timing``: its arguments and what it runs (:mod:`agents.training.tune`)."""

from __future__ import annotations

from typing import Any

from agents.cli.args import positive_int
from agents.training.tune import load_tune_settings, tune_timing


def _tune_timing(args: Any) -> int:
    settings = load_tune_settings(args.config)
    if args.samples is not None:
        settings.samples = args.samples
    if args.timesteps is not None:
        settings.timesteps = args.timesteps
    if args.out is not None:
        settings.out_dir = args.out
    result = tune_timing(settings, address=args.address)
    for trial in sorted(result.trials, key=lambda t: -t.get("success_rate", -1.0)):
        print(f"{trial.get('success_rate', float('nan')):.3f}  {trial['config']}")
    print(f"best: {result.best}\nwritten to {result.out_dir}/ (trials.json, best.yaml)")
    return 0


def add_tune_parser(subparsers: Any) -> None:
    """``deck-landing tune timing``."""
    tune_parser = subparsers.add_parser("tune", help="hyper-parameter search on Ray Tune")
    which = tune_parser.add_subparsers(dest="tuning", required=True)
    timing = which.add_parser("timing", help="the timing policy's hyper-parameters")
    timing.add_argument("--config", default="configs/train/tune_timing.yaml", help="search YAML")
    timing.add_argument("--samples", type=positive_int, default=None, help="default: the YAML's")
    timing.add_argument(
        "--timesteps", type=positive_int, default=None, help="per trial; default: the YAML's"
    )
    timing.add_argument("--address", default=None, help="an existing Ray cluster")
    timing.add_argument("--out", default=None, help="output directory (default: the YAML's)")
    timing.set_defaults(func=_tune_timing)
