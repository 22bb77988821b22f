"""The ``deck-landing estimate`` sub-command's arguments (its work: :mod:`agents.io.estimate`,
which needs the optional extra ``io``)."""

from __future__ import annotations

import argparse

from agents.cli.args import add_set_argument
from agents.cli.recording_args import add_alignment_arguments, add_topic_arguments
from agents.io.recording import recording_estimators


def _estimate(args: argparse.Namespace) -> int:
    # mcap and rosbags: the optional extra ``io``, imported when the command runs
    from agents.io.estimate import run_estimate

    run_estimate(args)
    return 0


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
    p.add_argument("--estimator", required=True, choices=recording_estimators())
    p.add_argument("--out", required=True, help="output path; .csv and .mcap are written")
    p.add_argument("--config", default="default", help="estimator settings: a config name or path")
    add_alignment_arguments(p)
    add_topic_arguments(p)
    add_set_argument(p)
    p.set_defaults(func=_estimate)
