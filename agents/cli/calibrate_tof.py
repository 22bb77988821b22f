"""``deck-landing calibrate tof``: its arguments and what it runs
(:mod:`agents.calibration.tof`)."""

from __future__ import annotations

import argparse

from agents.calibration.tof import run_tof_calibration
from agents.cli.recording_args import add_topic_arguments
from agents.common.user_input import UserError
from agents.io.recording import Topics


def _calibrate_tof(args: argparse.Namespace) -> int:
    try:
        topics = Topics.from_arguments(args)
        run_tof_calibration(
            args.recording, args.out, args.intrinsics, stages_file=args.stages_file, topics=topics
        )
    except ValueError as exc:  # RecordingError, TofRigError, a bad intrinsics file
        raise UserError(str(exc)) from None
    except ImportError as exc:  # an MCAP or rosbag2 recording without the io extra
        raise UserError(
            f"--recording {args.recording}: reading MCAP or rosbag2 needs the io extra ({exc}); "
            "install it with `pip install deck-landing[io]`"
        ) from None
    return 0


def add_tof_parser(kinds: argparse._SubParsersAction) -> None:
    """``calibrate tof`` (a recorded rig) under ``calibrate``'s sub-commands."""
    parser = kinds.add_parser(
        "tof",
        help="the ToF–camera calibration from a recorded pad rig (IHRCF Sec. 2.2)",
        description=(
            "The ToF-camera calibration from a rig's recording: a folder (frames.csv and the "
            "images, ranges.csv), or an MCAP file or rosbag2 folder (the images and the four "
            "ToF ranges), with the stage windows in tof_rig.json (--stages-file)."
        ),
    )
    parser.add_argument(
        "--recording",
        required=True,
        help="the rig's recording: a folder, an .mcap file or a rosbag2 folder",
    )
    parser.add_argument(
        "--stages-file",
        default=None,
        help="the rig file with the stage windows (default: tof_rig.json in the recording's "
        "folder, or beside the .mcap file)",
    )
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
    topics = parser.add_argument_group("MCAP and rosbag2 recordings")
    add_topic_arguments(topics, detections=False, imu=False)
    parser.set_defaults(func=_calibrate_tof, sensors_act=False)
