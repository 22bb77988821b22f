"""The ``deck-landing`` command line: every sub-command's arguments, and one error path.

A user error (a bad flag or config key, a missing file or model) prints one line naming the
problem and exits with status 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from agents.cli.approach import add_approach_parser
from agents.cli.args import add_mode_argument, add_set_argument, positive_int
from agents.cli.bridge import add_bridge_parser
from agents.cli.calibrate import add_calibrate_parser
from agents.cli.catalogue import add_list_parser, add_model_parser
from agents.cli.demo import run_demo
from agents.cli.estimate import add_estimate_parser
from agents.cli.landing import add_landing_parser
from agents.cli.train import add_train_parser
from agents.common.user_input import USER_ERRORS, parse_overrides
from agents.evaluation import SWEEP_PARAMETERS
from agents.evaluation.estimators import RunSettings, evaluate_estimators
from agents.evaluation.sweep import SweepSettings, run_sweep, write_sweep
from estimation.registry import load_plugins
from landing_env.config import SENSOR_SETS, SENSORS_ENV


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's defaults in --help, where there is one to show: not for a flag that is off
    unless given, an unset option or a help that already says its default."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        unset = default is None or default is False or default is argparse.SUPPRESS
        if unset or default == [] or "default" in text:
            return text
        return super()._get_help_string(action) or text


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block), exit status 2, and the
    defaults shown in every sub-command's --help."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


# ---------------------------------------------------------------------------------- demo
def _demo(args: argparse.Namespace) -> int:

    log = run_demo(
        config=args.config,
        seed=args.seed,
        out_dir=Path(args.out),
        timing=not args.no_timing,
        episodes=args.episodes,
        camera_mode=args.mode,
        record=Path(args.record) if args.record else None,
    )
    return 0 if log.final_info.get("outcome") else 1


def _add_demo_parser(sub: argparse._SubParsersAction) -> None:
    demo = sub.add_parser("demo", help="seeded episodes: summary, camera video, trajectory plot")
    demo.add_argument("--config", default="default", help="a config name in configs/ or a path")
    demo.add_argument("--seed", type=int, default=0, help="the first episode's seed")
    demo.add_argument("--episodes", type=positive_int, default=1, help="episodes (seeds on)")
    add_mode_argument(demo)
    demo.add_argument(
        "--no-timing",
        action="store_true",
        help="skip the second episode: bench-ss4's recommended timing policy (deck-landing "
        "list policies) waiting for a calm deck",
    )
    demo.add_argument("--out", default="results/demo", help="output directory")
    demo.add_argument("--record", default=None, help="record the first episode to FILE.mcap")
    demo.set_defaults(func=_demo)


# ------------------------------------------------------------------ evaluate estimators/sweep
def _evaluate_estimators(args: argparse.Namespace) -> int:

    settings = RunSettings(
        scenario=args.scenario,
        duration_s=args.duration,
        seed=args.seed,
        camera_mode=args.mode,
        estimators=tuple(args.estimators) if args.estimators else None,
        overrides=parse_overrides(args.set),
    )
    out = Path(args.out) if args.out else None
    result = evaluate_estimators(settings, out, plots=not args.no_plots)
    print((result.out_dir / "errors.md").read_text())
    steps = max(result.record.n_frames - 1, 1)
    print(
        f"{result.record.n_frames} frames in {result.record.wall_time_s:.1f} s "
        f"({1000 * result.record.wall_time_s / steps:.1f} ms per step); "
        f"written to {result.out_dir}/"
    )
    return 0


def _evaluate_sweep(args: argparse.Namespace) -> int:

    settings = SweepSettings(
        scenario=args.scenario,
        duration_s=args.duration,
        seed=args.seed,
        camera_mode=args.mode,
        parameters=None if args.parameters is None else tuple(args.parameters),
        overrides=parse_overrides(args.set),
        calibration_dir=str(Path(args.out) / "calibration"),
        workers=args.workers,
        address=args.address,
    )
    points = run_sweep(settings)
    files = write_sweep(points, settings, Path(args.out))
    print((Path(args.out) / "sweep.md").read_text())
    print("written: " + ", ".join(str(f) for f in files))
    return 0


def _add_evaluate_parser(sub: argparse._SubParsersAction) -> argparse._SubParsersAction:
    """``evaluate`` with ``estimators`` and ``sweep``; returns its sub-command group."""
    evaluate = sub.add_parser("evaluate", help="evaluations of the estimators and the policies")
    which = evaluate.add_subparsers(dest="evaluation", required=True)
    est = which.add_parser(
        "estimators",
        help="run a scenario with the drone pinned over the moving deck; tables and figures "
        "beside the papers' Tables 2 and 5",
    )
    est.add_argument(
        "--scenario", required=True, help="a config in configs/ (e.g. paper-stewart) or a path"
    )
    est.add_argument(
        "--duration", type=float, default=None, help="simulated seconds (default: the scenario's)"
    )
    est.add_argument("--out", default=None, help="output directory (default: results/SCENARIO)")
    est.add_argument("--seed", type=int, default=None, help="default: the scenario's seed")
    add_mode_argument(est)
    est.add_argument(
        "--estimators", nargs="+", default=None, help="default: the scenario's (truth excluded)"
    )
    est.add_argument("--no-plots", action="store_true", help="tables only")
    add_set_argument(est)
    est.set_defaults(func=_evaluate_estimators)

    sweep = which.add_parser(
        "sweep", help="each estimator's error against height, ToF noise, deck tilt and k1"
    )
    sweep.add_argument("--scenario", default="paper-stewart", help="the base scenario")
    sweep.add_argument("--duration", type=float, default=10.0, help="simulated s per point")
    sweep.add_argument("--seed", type=int, default=0, help="seeds the scenario at every point")
    add_mode_argument(sweep)
    sweep.add_argument(
        "--parameters",
        nargs="+",
        choices=SWEEP_PARAMETERS,
        default=None,
        help="the swept parameters (default: all; pixel_noise only with --mode project)",
    )
    sweep.add_argument("--out", default="results/sweep", help="output directory")
    sweep.add_argument(
        "--workers", type=positive_int, default=1, help="parallel workers (Ray beyond one)"
    )
    sweep.add_argument("--address", default=None, help="an existing Ray cluster")
    add_set_argument(sweep)
    sweep.set_defaults(func=_evaluate_sweep)
    return which


# ---------------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    load_plugins()  # the installed packages' estimators join the flags' choices
    parser = _Parser(
        prog="deck-landing",
        description="Quadrotor landing on a moving deck: a Stewart-platform bench or a ship's "
        "helideck; camera+ToF deck-pose estimators and landing policies.",
    )
    parser.add_argument("--debug", action="store_true", help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_demo_parser(sub)
    which = _add_evaluate_parser(sub)
    add_landing_parser(which)
    add_approach_parser(which)
    add_train_parser(sub)
    add_estimate_parser(sub)
    add_calibrate_parser(sub)
    add_list_parser(sub)
    add_model_parser(sub)
    add_bridge_parser(sub)
    _add_sensors_option(parser)
    return parser


def _add_sensors_option(parser: argparse.ArgumentParser) -> None:
    """``--sensors ideal|realistic`` on every command that builds a config (the config key
    ``sensors``); not where it would do nothing (``set_defaults(sensors_act=False)``: list,
    model show, the calibrations of real data)."""

    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if parser.get_default("sensors_act") is False:
        return
    if not actions or parser.get_default("func") is not None:
        if "--sensors" in parser._option_string_actions:
            return
        parser.add_argument(
            "--sensors",
            choices=SENSOR_SETS,
            default=None,
            help="sensor set for every environment of the run (default: the scenario's)",
        )
        if not actions:
            return
    for child in {id(p): p for p in actions[0].choices.values()}.values():
        _add_sensors_option(child)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    if isinstance(exc, FileNotFoundError) and exc.filename and str(exc.filename) not in text:
        text = f"{text}: {exc.filename}"
    return " ".join(text.split())


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if not getattr(args, "sensors", None):
            return int(args.func(args))
        # the default of the config key ``sensors`` here and in worker processes, for this run

        before = os.environ.get(SENSORS_ENV)
        os.environ[SENSORS_ENV] = args.sensors
        try:
            return int(args.func(args))
        finally:
            if before is None:
                os.environ.pop(SENSORS_ENV, None)
            else:
                os.environ[SENSORS_ENV] = before
    except USER_ERRORS as exc:
        if args.debug:
            raise
        print(f"deck-landing {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("deck-landing: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
