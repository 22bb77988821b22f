"""``deck-landing calibrate tof``: its arguments and what it runs (:mod:`agents.calibrate_tof`)."""

from __future__ import annotations

import argparse

from agents.calibrate_tof import run_tof_calibration
from agents.cli_args import UserError


def _calibrate_tof(args: argparse.Namespace) -> int:
    try:
        run_tof_calibration(args.recording, args.out, args.intrinsics)
    except ValueError as exc:  # RecordingError, TofRigError, a bad intrinsics file
        raise UserError(str(exc)) from None
    return 0


def add_tof_parser(kinds: argparse._SubParsersAction) -> None:
    """``calibrate tof`` (a recorded rig) under ``calibrate``'s sub-commands."""
    parser = kinds.add_parser(
        "tof",
        help="the ToF–camera calibration from a recorded pad rig (IHRCF Sec. 2.2)",
        description=(
            "The ToF-camera calibration from a rig's recording folder: frames.csv and the "
            "images, ranges.csv, and tof_rig.json with the stage windows."
        ),
    )
    parser.add_argument("--recording", required=True, help="the rig's recording folder")
    parser.add_argument(
        "--calibration",
        dest="intrinsics",
        default=None,
        help="the camera's intrinsics file, or a folder holding intrinsics.json "
        "(default: the camera named in tof_rig.json, if any)",
    )
    parser.add_argument(
        "--out", default="results/calibration", help="output folder: tof_camera.json, summary.json"
    )
    parser.set_defaults(func=_calibrate_tof)
