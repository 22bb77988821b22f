"""``deck-landing evaluate landing``: its arguments and what it runs
(:mod:`agents.evaluation.landing`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from agents.cli.args import add_batch_arguments, add_mode_argument, command_line, positive_int
from agents.common.user_input import parse_overrides as _parse_overrides
from agents.evaluation.landing import HELD_OUT_SEED, evaluate_landing
from agents.policies.registry import (
    POLICY_NAMES,
    default_policy,
)
from estimation.registry import ESTIMATOR_NAMES
from landing_env.scenarios import SCENARIOS


def _evaluate_landing(args: argparse.Namespace) -> int:
    command = command_line()
    for n, scenario in enumerate(args.scenario):
        if args.policy is None:
            policies = [default_policy(scenario)]
        elif args.policy == ["all"]:
            policies = list(POLICY_NAMES)
        else:
            policies = args.policy
        evaluation = evaluate_landing(
            policies,
            scenario,
            args.episodes,
            Path(args.out),
            args.seed,
            args.estimator,
            args.mode,
            args.model,
            args.workers,
            progress=not args.no_progress,
            command=command,
            extra_overrides=_parse_overrides(args.set),
            address=args.address,
            resume=args.resume,
            oracle=not args.no_oracle,
            allow_mismatch=tuple(args.allow_mismatch),
            deck_oracle=args.deck_oracle,
            record=Path(args.record) if args.record and n == 0 else None,
        )
        evaluation.show(f"{scenario}: {SCENARIOS[scenario].description}")
    return 0


def add_landing_parser(evaluate_group: Any) -> None:
    """Add ``landing`` to the ``evaluate`` sub-command group."""
    landing = evaluate_group.add_parser(
        "landing",
        help="landing policies over held-out seeds: success rate (95%% Wilson interval), "
        "touchdown speed, tilt, offset, time to land; table and figures",
    )
    landing.add_argument(
        "--policy",
        nargs="+",
        default=None,
        choices=[*POLICY_NAMES, "all"],
        help="one or more policies, or all (default: the scenario's recommended policy, "
        "deck-landing list policies)",
    )
    landing.add_argument("--scenario", nargs="+", required=True, choices=list(SCENARIOS))
    landing.add_argument(
        "--episodes", type=positive_int, default=100, help="episodes per policy and scenario"
    )
    landing.add_argument("--seed", type=int, default=HELD_OUT_SEED, help="first held-out seed")
    landing.add_argument(
        "--estimator",
        choices=ESTIMATOR_NAMES,
        default=None,
        help="the estimate in the observation (default: the policy's own, else the "
        "scenario's: ihrcf on the bench, tight on the ship decks)",
    )
    add_mode_argument(landing, "project")
    landing.add_argument(
        "--model", default=None, help="a trained model (timing-model, lander-model)"
    )
    landing.add_argument("--out", default="results/landing", help="output directory")
    landing.add_argument(
        "--record",
        default=None,
        metavar="FILE.mcap",
        help="record the first episode (first scenario, first policy, first seed) as ROS 2 "
        "messages (needs the extra io)",
    )
    add_batch_arguments(landing)
    landing.add_argument(
        "--allow-mismatch",
        nargs="*",
        default=[],
        choices=["env_id", "observation", "estimator", "sensing"],
        help="evaluate a trained model although its card differs in these fields (e.g. sensing: "
        "an ideal-trained model under realistic noise)",
    )
    landing.add_argument(
        "--no-oracle",
        action="store_true",
        help="do not run the oracle timing (the best any timing could do) beside timing policies",
    )
    landing.add_argument(
        "--deck-oracle",
        action="store_true",
        help="also run the deck oracle beside timing policies: it knows the deck's future "
        "motion but not the wind's or the sensors' noise (several look-ahead descents at each "
        "check: a few times the oracle's cost)",
    )
    landing.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="dotted config overrides applied last, e.g. tof.noise=vl53l1x; keys under timing. "
        "set the timing task (e.g. timing.guidance.descent_profile=range)",
    )
    landing.set_defaults(func=_evaluate_landing)
