"""``deck-landing calibrate intrinsics``: a real camera's intrinsics from chessboard photos.

Reads every image of ``--images`` (sorted by name), finds the ``--pattern`` board (inner
corners, COLSxROWS as OpenCV's ``patternSize``) in each, calibrates with OpenCV
(:func:`estimation.intrinsics_calibration.calibrate_from_images`), prints the RMS and
per-photo reprojection errors and the rejected photos with their reasons, and writes the
project's intrinsics file (its format: :mod:`estimation.intrinsics_calibration`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console
from rich.table import Table

from agents.cli_args import UserError
from estimation.intrinsics_calibration import (
    PhotoCalibration,
    calibrate_from_images,
    image_files,
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


def _calibrate_intrinsics(args: argparse.Namespace) -> int:
    try:
        run = calibrate_from_images(image_files(args.images), args.pattern, args.square)
    except ValueError as exc:
        raise UserError(f"--images {args.images}: {exc}") from None
    console = Console()
    print_report(console, run)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    run.result.save(out)
    console.print(f"intrinsics: {out}")
    if args.summary:
        Path(args.summary).write_text(
            json.dumps(
                {
                    "rms_reprojection_error_px": run.result.rms_reprojection_error,
                    "camera_matrix": run.result.K.tolist(),
                    "dist": run.result.dist.tolist(),
                    "per_view_errors_px": dict(
                        zip(run.used, run.result.per_view_errors.tolist(), strict=True)
                    ),
                    "rejected": dict(run.rejected),
                },
                indent=1,
            )
        )
    return 0


def add_photo_parsers(kinds: argparse._SubParsersAction) -> None:
    """``calibrate intrinsics`` (real photos) under ``calibrate``'s sub-commands."""
    parser = kinds.add_parser(
        "intrinsics",
        help="a real camera's intrinsics from chessboard photos",
        description=(
            "A real camera's intrinsics from chessboard photos: RMS and per-photo "
            "errors, rejected photos with their reasons."
        ),
    )
    parser.add_argument("--images", required=True, help="a folder of chessboard photos")
    parser.add_argument(
        "--pattern", required=True, type=parse_pattern, help="inner corners COLSxROWS, e.g. 9x6"
    )
    parser.add_argument(
        "--square", required=True, type=positive_metres, help="a square's edge, metres"
    )
    parser.add_argument(
        "--out", default="results/calibration/intrinsics.json", help="the intrinsics file"
    )
    parser.add_argument("--summary", default=None, help="also write the figures as JSON here")
    parser.set_defaults(func=_calibrate_intrinsics)
