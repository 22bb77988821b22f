"""The options that read a recording, shared by ``estimate``, ``bridge --input`` and
``calibrate tof``: the topics (:class:`agents.io.recording.Topics`), the calibration folder
and the range-to-frame alignment.

With ``given_only`` the options default to None (their help names the real default), so a
command that reads a recording only sometimes (``bridge``) can tell which were given;
:meth:`agents.io.recording.Topics.from_arguments` and :func:`fill_alignment_defaults` put
the defaults back.
"""

from __future__ import annotations

import argparse
import math

from agents.io.recording import ALIGN_MODES, Topics

#: a frame with no ToF sample within this of its stamp gets no ranges (seconds)
DEFAULT_TOLERANCE_S = 0.02
DEFAULT_ALIGN = "nearest"


def tolerance_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tolerance {text!r} is not a number") from None
    if not 0.0 <= value < math.inf:
        raise argparse.ArgumentTypeError(f"--tolerance {text!r} must be >= 0 seconds")
    return value


def _default(value: object, given_only: bool) -> object:
    return None if given_only else value


def add_topic_arguments(
    parser: argparse.ArgumentParser,
    *,
    detections: bool = True,
    imu: bool = True,
    tf: bool = False,
    given_only: bool = False,
) -> None:
    """``--image-topic``, ``--range-topics``, ``--range-frames``, ``--exact-ranges-topic``
    and, as asked, ``--detections-topic``, ``--imu-topic``, ``--tf-topic``, ``--tf-frames``."""
    t = Topics()
    options = [
        ("--image-topic", t.image, "sensor_msgs/Image or CompressedImage"),
        ("--detections-topic", t.detections, "the simulator's tag detections, used when present"),
        (
            "--range-topics",
            ",".join(t.ranges),
            "sensor_msgs/Range: one topic (sensors by frame id) or four, comma-separated",
        ),
        ("--range-frames", ",".join(t.range_frames), "the four sensors' frame ids on one topic"),
        (
            "--exact-ranges-topic",
            t.exact_ranges,
            "the float64 deck_landing_msgs/TofRanges, used instead of the Range topics when "
            "present ('' for never)",
        ),
        ("--imu-topic", t.imu, "sensor_msgs/Imu"),
        ("--tf-topic", t.tf, "tf2_msgs/TFMessage with the vehicle's pose"),
        (
            "--tf-frames",
            ",".join(t.tf_frames),
            "PARENT,CHILD of the vehicle's transform: the world (x north, y west, z up) and "
            "the body (FLU)",
        ),
    ]
    left_out = {"--detections-topic": not detections, "--imu-topic": not imu}
    left_out |= {"--tf-topic": not tf, "--tf-frames": not tf}
    for flag, default, meaning in options:
        if not left_out.get(flag, False):
            parser.add_argument(
                flag, default=_default(default, given_only), help=f"{meaning} (default {default})"
            )


def add_alignment_arguments(parser: argparse.ArgumentParser, *, given_only: bool = False) -> None:
    """``--calibration``, ``--tolerance`` and ``--align``."""
    parser.add_argument(
        "--calibration",
        default=None,
        help="folder: intrinsics.json, tof_camera.json, extrinsics.json (default: the config's)",
    )
    parser.add_argument(
        "--tolerance",
        type=tolerance_seconds,
        default=_default(DEFAULT_TOLERANCE_S, given_only),
        help=f"range-to-frame time tolerance, s (default {DEFAULT_TOLERANCE_S})",
    )
    parser.add_argument(
        "--align",
        choices=ALIGN_MODES,
        default=_default(DEFAULT_ALIGN, given_only),
        help=f"nearest range sample or linear interpolation (default {DEFAULT_ALIGN})",
    )


#: the recording options' destinations and flags (what ``given_only`` lets a command check)
RECORDING_OPTIONS = {
    "calibration": "--calibration",
    "tolerance": "--tolerance",
    "align": "--align",
    "image_topic": "--image-topic",
    "detections_topic": "--detections-topic",
    "range_topics": "--range-topics",
    "range_frames": "--range-frames",
    "exact_ranges_topic": "--exact-ranges-topic",
    "imu_topic": "--imu-topic",
    "tf_topic": "--tf-topic",
    "tf_frames": "--tf-frames",
}


def recording_options_given(args: argparse.Namespace) -> list[str]:
    """The recording options given on the command line (``given_only`` parsers)."""
    return [
        flag for dest, flag in RECORDING_OPTIONS.items() if getattr(args, dest, None) is not None
    ]


def fill_alignment_defaults(args: argparse.Namespace) -> None:
    """``--tolerance`` and ``--align`` left at None get their defaults."""
    if args.tolerance is None:
        args.tolerance = DEFAULT_TOLERANCE_S
    if args.align is None:
        args.align = DEFAULT_ALIGN
