"""``deck-landing calibrate``: its arguments and what it runs
(:mod:`agents.calibration.simulated`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agents.calibration.simulated import run_calibration
from agents.cli.args import add_set_argument, positive_int
from agents.cli.calibrate_photos import add_photo_parsers
from agents.cli.calibrate_tof import add_tof_parser
from agents.common.user_input import parse_overrides


def _calibrate(args: argparse.Namespace) -> int:
    run_calibration(
        config=args.config,
        out_dir=Path(args.out),
        views=args.views,
        stages=args.stages,
        seed=args.seed,
        install=args.install,
        workers=args.workers,
        address=args.address,
        overrides=parse_overrides(args.set),
    )
    return 0


def add_calibrate_parser(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` subcommand to the ``deck-landing`` parser."""
    parser = sub.add_parser(
        "calibrate",
        help="the camera's intrinsics and the ToF–camera calibration: of the simulated rigs, "
        "or of real data (intrinsics: chessboard photos; tof: a recorded pad rig)",
        description=(
            "Both of the papers' calibrations (camera intrinsics and ToF-camera). Without a "
            "sub-command, of the simulated rigs (the options below); `calibrate intrinsics` "
            "takes real chessboard photos, `calibrate tof` a real rig's recording."
        ),
    )
    parser.add_argument("--config", default="default", help="a config name in configs/ or a path")
    parser.add_argument("--out", default="results/calibration", help="output directory")
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=1,
        help="2 runs the two calibrations side by side on Ray (the same results)",
    )
    parser.add_argument("--address", default=None, help="an existing Ray cluster")
    parser.add_argument(
        "--views", type=positive_int, default=20, help="chessboard poses (CRHF: 20)"
    )
    parser.add_argument(
        "--stages",
        type=positive_int,
        default=120,
        help="climb stages of the pad rig (papers: ~120)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seeds the board poses and noise")
    parser.add_argument(
        "--install",
        action="store_true",
        help="also copy the files to configs/calibration/ (the environment's defaults)",
    )
    add_set_argument(parser)
    parser.set_defaults(func=_calibrate)
    # real rigs: `calibrate intrinsics` (photos), `calibrate tof` (a recorded pad rig);
    # without a kind, the simulated rigs above
    kinds = parser.add_subparsers(dest="calibration", required=False)
    add_photo_parsers(kinds)
    add_tof_parser(kinds)
