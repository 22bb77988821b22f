"""Argument types and the user-error type of the ``deck-landing`` command (a leaf module).

Every user error (a bad flag, a config key, a missing file) reaches :func:`agents.cli.main`,
which prints one line and exits with status 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from estimation.errors import ConfigError

SET_HELP = "dotted config overrides applied last, e.g. tof.noise=vl53l1x camera.k1=-0.05"


class UserError(Exception):
    """A mistake in what the user asked for (reported as one line, exit status 2)."""


#: what :func:`agents.cli.main` reports as a user error rather than a crash
USER_ERRORS: tuple[type[BaseException], ...] = (ConfigError, UserError, FileNotFoundError)


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is out of range; allowed [1, inf]")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"{value} is out of range; allowed (0, inf)")
    return value


def parse_overrides(pairs: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs (dotted keys, YAML values) as an overrides mapping."""
    import yaml

    overrides: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", f"{pair!r} is not KEY=VALUE (e.g. tof.noise=vl53l1x)")
        try:
            overrides[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            raise ConfigError(key.strip(), f"{value!r} is not a YAML value: {exc}") from None
    return overrides


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
