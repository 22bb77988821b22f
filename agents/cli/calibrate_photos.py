"""``deck-landing calibrate intrinsics``: its arguments and what it runs
(:mod:`agents.calibration.photos`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console

from agents.calibration.photos import parse_pattern, positive_metres, print_report
from agents.common.user_input import UserError
from estimation.intrinsics_calibration import (
    calibrate_from_images,
    image_files,
)


def _calibrate_intrinsics(args: argparse.Namespace) -> int:
    try:
        files = image_files(args.images)
    except ValueError as exc:  # names the folder
        raise UserError(f"--images {exc}") from None
    try:
        run = calibrate_from_images(files, args.pattern, args.square)
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
    parser.set_defaults(func=_calibrate_intrinsics, sensors_act=False)
