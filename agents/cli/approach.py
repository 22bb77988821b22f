"""``deck-landing evaluate approach``: its arguments and what it runs
(:mod:`agents.evaluation.approach`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from agents.cli.args import add_batch_arguments, add_set_argument, command_line, positive_int
from agents.common.user_input import parse_overrides as _parse_overrides
from agents.evaluation.approach import APPROACH_POLICIES, ROUTINE_TIMINGS, evaluate_approach
from agents.evaluation.pipeline import HELD_OUT_SEED


def _evaluate_approach(args: argparse.Namespace) -> int:
    command = command_line()
    evaluation = evaluate_approach(
        list(args.policy),
        args.scenario,
        args.episodes,
        Path(args.out),
        args.seed,
        args.routine_estimator,
        args.workers,
        progress=not args.no_progress,
        overrides=_parse_overrides(args.set),
        command=command,
        routine_timing=args.routine_timing,
        address=args.address,
        resume=args.resume,
    )
    evaluation.show(args.scenario)
    return 0


def add_approach_parser(evaluate_group: Any) -> None:
    """Add ``approach`` to the ``evaluate`` sub-command group."""
    approach = evaluate_group.add_parser(
        "approach",
        help="the high approach (20 m up, 5 m off): svgs-routine against beacon-range; "
        "success (95%% Wilson interval), touchdown offset, time to land; table, CSV, figure",
    )
    approach.add_argument(
        "--policy",
        nargs="+",
        choices=list(APPROACH_POLICIES),
        default=list(APPROACH_POLICIES),
        help="the approach policies flown",
    )
    approach.add_argument(
        "--scenario", default="high-approach", help="a config in configs/ or a path"
    )
    approach.add_argument("--episodes", type=positive_int, default=20, help="episodes per policy")
    approach.add_argument("--seed", type=int, default=HELD_OUT_SEED, help="first seed")
    approach.add_argument(
        "--routine-estimator",
        default=None,
        help="the routine's estimator (default: fused)",
    )
    approach.add_argument(
        "--routine-timing",
        choices=ROUTINE_TIMINGS,
        default="model",
        help="svgs-routine's commit: the shipped timing policy (where installed) or the "
        "quiescent heuristic",
    )
    approach.add_argument("--out", default="results/approach", help="output directory")
    add_batch_arguments(approach)
    add_set_argument(approach)
    approach.set_defaults(func=_evaluate_approach)
