"""The ``deck-landing estimate`` sub-command's arguments (its work: :mod:`agents.io.estimate`,
which needs the optional extra ``io``)."""

from __future__ import annotations

import argparse
import math

from agents.cli_args import add_set_argument
from agents.io.recording import ALIGN_MODES, ESTIMATORS, Topics

#: a frame with no ToF sample within this of its stamp gets no ranges (seconds)
DEFAULT_TOLERANCE_S = 0.02


def _estimate(args: argparse.Namespace) -> int:
    # mcap and rosbags: the optional extra ``io``, imported when the command runs
    from agents.io.estimate import run_estimate

    run_estimate(args)
    return 0


def tolerance_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tolerance {text!r} is not a number") from None
    if not 0.0 <= value < math.inf:
        raise argparse.ArgumentTypeError(f"--tolerance {text!r} must be >= 0 seconds")
    return value


def add_estimate_parser(sub: argparse._SubParsersAction) -> None:
    """The ``estimate`` sub-command."""
    p = sub.add_parser(
        "estimate",
        help="run a deck-pose estimator on a recording (folder, MCAP, rosbag2)",
        description=(
            "Run an estimator on a recording (MCAP, rosbag2 or a plain folder) and "
            "write its deck poses (CSV and MCAP)."
        ),
    )
    p.add_argument("--input", required=True, help="a recording: folder, .mcap or rosbag2 folder")
    p.add_argument("--estimator", required=True, choices=ESTIMATORS)
    p.add_argument(
        "--calibration",
        default=None,
        help="folder: intrinsics.json, tof_camera.json, extrinsics.json (default: the config's)",
    )
    p.add_argument("--out", required=True, help="output path; .csv and .mcap are written")
    p.add_argument("--config", default="default", help="estimator settings: a config name or path")
    p.add_argument(
        "--tolerance",
        type=tolerance_seconds,
        default=DEFAULT_TOLERANCE_S,
        help="range-to-frame time tolerance, s",
    )
    p.add_argument(
        "--align",
        choices=ALIGN_MODES,
        default="nearest",
        help="nearest range sample or linear interpolation",
    )
    t = Topics()
    p.add_argument("--image-topic", default=t.image)
    p.add_argument("--detections-topic", default=t.detections)
    p.add_argument(
        "--range-topics",
        default=",".join(t.ranges),
        help="one topic (sensors by frame id) or four, comma-separated",
    )
    p.add_argument(
        "--range-frames",
        default=",".join(t.range_frames),
        help="the four sensors' frame ids on one range topic",
    )
    p.add_argument("--exact-ranges-topic", default=t.exact_ranges)
    p.add_argument("--imu-topic", default=t.imu)
    add_set_argument(p)
    p.set_defaults(func=_estimate)
