"""The ``deck-landing`` command line."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from agents.calibrate import add_calibrate_parser
from agents.evaluation import add_evaluate_parser
from agents.evaluation.approach import add_approach_parser
from agents.evaluation.landing import _subparser_group, add_landing_commands


def _demo(args: argparse.Namespace) -> int:
    from agents.demo import run_demo

    log = run_demo(config=args.config, seed=args.seed, out_dir=Path(args.out))
    return 0 if log.final_info.get("outcome") else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="deck-landing",
        description="Quadrotor landing on a moving Stewart-platform deck.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="one seeded episode: summary, camera video, trajectory plot")
    demo.add_argument("--config", default="default", help="a config name in configs/ or a path")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--out", default="results/demo", help="output directory")
    demo.set_defaults(func=_demo)
    add_evaluate_parser(sub)
    add_landing_commands(sub)
    add_approach_parser(_subparser_group(sub.choices["evaluate"]))
    add_calibrate_parser(sub)
    _add_sensors_option(parser)
    return parser


def _add_sensors_option(parser: argparse.ArgumentParser) -> None:
    """``--sensors ideal|realistic`` on every command (the config key ``sensors``)."""
    from landing_env.config import SENSOR_SETS

    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not actions:
        if "--sensors" in parser._option_string_actions:
            return
        parser.add_argument(
            "--sensors",
            choices=SENSOR_SETS,
            default=None,
            help="sensor set for every environment of the run (default: the scenario's)",
        )
        return
    for child in {id(p): p for p in actions[0].choices.values()}.values():
        _add_sensors_option(child)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "sensors", None):
        return args.func(args)
    # the default of the config key ``sensors`` here and in worker processes, for this run
    from landing_env.config import SENSORS_ENV

    before = os.environ.get(SENSORS_ENV)
    os.environ[SENSORS_ENV] = args.sensors
    try:
        return args.func(args)
    finally:
        if before is None:
            os.environ.pop(SENSORS_ENV, None)
        else:
            os.environ[SENSORS_ENV] = before


if __name__ == "__main__":
    sys.exit(main())
