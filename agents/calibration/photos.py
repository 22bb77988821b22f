"""``deck-landing calibrate intrinsics``: a real camera's intrinsics from chessboard photos.

Reads every image of ``--images`` (sorted by name), finds the ``--pattern`` board (inner
corners, COLSxROWS as OpenCV's ``patternSize``) in each, calibrates with OpenCV
(:func:`estimation.intrinsics_calibration.calibrate_from_images`), prints the RMS and
per-photo reprojection errors and the rejected photos with their reasons, and writes the
project's intrinsics file (its format: :mod:`estimation.intrinsics_calibration`).
"""

from __future__ import annotations

import argparse

from rich.console import Console
from rich.table import Table

from estimation.intrinsics_calibration import (
    PhotoCalibration,
)


def parse_pattern(text: str) -> tuple[int, int]:
    """``COLSxROWS`` (inner corners) as a pair of ints; argparse's type."""
    parts = text.lower().split("x")
    try:
        cols, rows = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--pattern {text!r}: expected COLSxROWS inner corners, e.g. 9x6"
        ) from None
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError(f"--pattern {text!r}: each count must be >= 2")
    return cols, rows


def positive_metres(text: str) -> float:
    """A positive length in metres; argparse's type."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of metres") from None
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number of metres")
    return value


def print_report(console: Console, run: PhotoCalibration) -> None:
    """The calibration's figures: K, distortion, RMS, per-photo errors, rejected photos."""
    result = run.result
    k = result.K
    console.print(
        f"[bold]Intrinsics[/bold] from {len(run.used)} photos "
        f"({result.image_size[0]}x{result.image_size[1]}), {len(run.rejected)} rejected; "
        f"RMS reprojection error {result.rms_reprojection_error:.4f} px"
    )
    console.print(
        f"fx {k[0, 0]:.4f}  fy {k[1, 1]:.4f}  cx {k[0, 2]:.4f}  cy {k[1, 2]:.4f} (px); "
        "k1 k2 p1 p2 k3: " + " ".join(f"{d:+.6f}" for d in result.dist[:5])
    )
    table = Table("photo", "RMS error px")
    for name, error in zip(run.used, result.per_view_errors, strict=True):
        table.add_row(name, f"{error:.4f}")
    console.print(table)
    for name, reason in run.rejected:
        console.print(f"rejected {name}: {reason}")
