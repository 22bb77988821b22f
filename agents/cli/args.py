"""Argument types and shared options of the ``deck-landing`` command; the user-error type
and the ``--set`` overrides' parser are :mod:`agents.common.user_input`'s.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys

from landing_env.sensors.camera_config import CAMERA_MODES

SET_HELP = "dotted config overrides applied last, e.g. tof.noise=vl53l1x camera.k1=-0.05"


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    return _int_at_least(text, 1)


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0."""
    return _int_at_least(text, 0)


def _int_at_least(text: str, low: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"{value} is out of range; allowed [{low}, inf]")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    return _finite_float(text, zero_allowed=False)


def non_negative_float(text: str) -> float:
    """An argparse type: a finite number >= 0."""
    return _finite_float(text, zero_allowed=True)


def _finite_float(text: str, zero_allowed: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and (value > 0.0 or (zero_allowed and value == 0.0))):
        low = "[0" if zero_allowed else "(0"
        raise argparse.ArgumentTypeError(f"{value} is out of range; allowed {low}, inf)")
    return value


def command_line() -> str:
    """This run's command as a shell line, for the records it writes."""
    return "deck-landing " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def add_mode_argument(
    parser: argparse.ArgumentParser,
    default: str | None = "render",
    help: str = "camera: render and detect the tag, or project it (faster)",
) -> None:
    """``--mode``: the camera's mode (:data:`~landing_env.sensors.camera_config.CAMERA_MODES`)."""
    parser.add_argument("--mode", choices=CAMERA_MODES, default=default, help=help)


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    """``--set KEY=VALUE ...``: dotted config overrides."""
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help=SET_HELP)


def add_batch_arguments(parser: argparse.ArgumentParser, workers: int = 2) -> None:
    """The options of every batch job over seeds (see :mod:`agents.evaluation.runner`)."""
    parser.add_argument(
        "--workers", type=positive_int, default=workers, help="parallel worker processes"
    )
    parser.add_argument(
        "--address",
        default=None,
        help="an existing Ray cluster (e.g. ray://head:10001 or auto); default: this machine",
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="keep the episodes already written in --out and run only the missing seeds",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
