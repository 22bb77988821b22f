"""Evaluation of the deck-pose estimators: the papers' Stewart-platform experiments and sweeps.

:mod:`agents.evaluation.estimators` runs a scenario and scores every estimator (tables),
:mod:`agents.evaluation.plots` draws the papers' figures, :mod:`agents.evaluation.sweep` plots
the errors against height, ToF noise, deck tilt and lens distortion.  The command line is
``deck-landing evaluate estimators --scenario NAME`` and ``deck-landing evaluate sweep``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from estimation.errors import ConfigError

#: the conditions ``evaluate sweep`` can vary (see :mod:`agents.evaluation.sweep`)
SWEEP_PARAMETERS: tuple[str, ...] = ("height", "tof_noise", "pixel_noise", "tilt", "k1")

SET_HELP = "dotted config overrides, e.g. tof.noise=vl53l1x camera.k1=-0.05"


def _parse_overrides(pairs: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs (dotted keys, YAML values) as an overrides mapping."""
    import yaml

    overrides: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", f"{pair!r} is not KEY=VALUE (e.g. tof.noise=vl53l1x)")
        overrides[key.strip()] = yaml.safe_load(value)
    return overrides


def _evaluate_estimators(args: argparse.Namespace) -> int:
    from agents.evaluation.estimators import RunSettings, evaluate_estimators

    settings = RunSettings(
        scenario=args.scenario,
        duration_s=args.duration,
        seed=args.seed,
        camera_mode=args.mode,
        estimators=tuple(args.estimators) if args.estimators else None,
        overrides=_parse_overrides(args.set),
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
    from agents.evaluation.sweep import SweepSettings, run_sweep, write_sweep

    settings = SweepSettings(
        scenario=args.scenario,
        duration_s=args.duration,
        seed=args.seed,
        camera_mode=args.mode,
        parameters=tuple(args.parameters) if args.parameters else None,
        overrides=_parse_overrides(args.set),
        calibration_dir=str(Path(args.out) / "calibration"),
    )
    points = run_sweep(settings)
    files = write_sweep(points, settings, Path(args.out))
    print((Path(args.out) / "sweep.md").read_text())
    print("written: " + ", ".join(str(f) for f in files))
    return 0


def _guarded(handler: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Report a configuration error as one line and exit status 2, not a traceback."""

    def run(args: argparse.Namespace) -> int:
        try:
            return handler(args)
        except ConfigError as exc:
            print(f"deck-landing evaluate: {exc}", file=sys.stderr)
            return 2

    return run


def add_evaluate_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``evaluate estimators`` and ``evaluate sweep`` to the ``deck-landing`` command."""
    evaluate = subparsers.add_parser(
        "evaluate", help="score the deck-pose estimators against the ground truth"
    )
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
    est.add_argument("--mode", choices=("render", "project"), default="render", help="camera mode")
    est.add_argument(
        "--estimators", nargs="+", default=None, help="default: the scenario's (truth excluded)"
    )
    est.add_argument("--no-plots", action="store_true", help="tables only")
    est.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help=SET_HELP)
    est.set_defaults(func=_guarded(_evaluate_estimators))

    sweep = which.add_parser(
        "sweep", help="each estimator's error against height, ToF noise, deck tilt and k1"
    )
    sweep.add_argument("--scenario", default="paper-stewart", help="the base scenario")
    sweep.add_argument("--duration", type=float, default=10.0, help="simulated s per point")
    sweep.add_argument("--seed", type=int, default=0)
    sweep.add_argument(
        "--mode", choices=("render", "project"), default="render", help="camera mode"
    )
    sweep.add_argument(
        "--parameters",
        nargs="+",
        choices=SWEEP_PARAMETERS,
        default=None,
        help="default: all (pixel_noise only in project mode)",
    )
    sweep.add_argument("--out", default="results/sweep", help="output directory")
    sweep.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help=SET_HELP)
    sweep.set_defaults(func=_guarded(_evaluate_sweep))
