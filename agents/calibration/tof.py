"""``deck-landing calibrate tof``: the ToF–camera calibration of a recorded rig.

Reads a rig's recording (:mod:`agents.io.tof_rig`: a folder of ``frames.csv``, the images
and ``ranges.csv``, or an MCAP file or rosbag2 folder of images and ranges; the rig file
``tof_rig.json`` or ``--stages-file``), calibrates it with
:func:`estimation.tof_rig.calibrate_rig` (IHRCF Sec. 2.2: pads, YCbCr thresholds, hull,
centroids, PCHIP), prints each sensor's samples, skips and hyperbola fit (CRHF Table 4), and
writes ``tof_camera.json`` (its format: :mod:`estimation.tof_calibration`) and
``summary.json`` to ``--out``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.table import Table

from agents.calibration.simulated import SUMMARY_NAME, TOF_NAME
from agents.io.recording import Topics
from agents.io.tof_rig import calibrate_tof_recording
from estimation.tof_calibration import PAD_COLOURS
from estimation.tof_rig import RigCalibration


@dataclass(frozen=True)
class TofRecordingRun:
    """The calibration, what the recording left out, and the files written."""

    result: RigCalibration
    left_out: dict
    files: dict[str, Path]


def tof_summary(result: RigCalibration, left_out: dict | None = None) -> dict:
    """The calibration's figures as plain data."""
    cal = result.calibration
    return {
        "image_size": None if cal.image_size is None else list(cal.image_size),
        "left_out": dict(left_out or {}),
        "sensors": [
            {
                "pad": PAD_COLOURS[i],
                "samples": len(cal.samples[i]),
                "range_span_m": cal.range_span[i].tolist(),
                "skipped": {reason: counts[i] for reason, counts in result.skipped.items()},
                "hyperbola_u": {"a": hu.a, "c": hu.c, "rms_px": hu.rms},
                "hyperbola_v": {"a": hv.a, "c": hv.c, "rms_px": hv.rms},
            }
            for i, (hu, hv) in enumerate(zip(cal.hyperbola_u, cal.hyperbola_v, strict=True))
        ],
    }


def print_tof_summary(console: Console, result: RigCalibration, left_out: dict) -> None:
    """Per sensor: samples, calibrated span, skips and the a / r + c fits."""
    cal = result.calibration
    table = Table("sensor", "samples", "span m", "skipped", "u: a px·m, c px", "v: a px·m, c px")
    for i, (hu, hv) in enumerate(zip(cal.hyperbola_u, cal.hyperbola_v, strict=True)):
        low, high = cal.range_span[i]
        skipped = ", ".join(f"{r} {c[i]}" for r, c in result.skipped.items() if c[i]) or "none"
        table.add_row(
            f"{i + 1} {PAD_COLOURS[i]}",
            str(len(cal.samples[i])),
            f"{low:.3f}–{high:.3f}",
            skipped,
            f"{hu.a:.2f}, {hu.c:.2f} (RMS {hu.rms:.2f})",
            f"{hv.a:.2f}, {hv.c:.2f} (RMS {hv.rms:.2f})",
        )
    console.print(
        f"[bold]ToF–camera[/bold] from {cal.metadata.get('stages')} stages; "
        "touch-point pixel = a / range + c per sensor and axis (CRHF Table 4)"
    )
    console.print(table)
    for reason, count in left_out.items():
        console.print(f"left out: {count} x {reason}")


def run_tof_calibration(
    recording: str | Path,
    out_dir: str | Path,
    intrinsics: str | Path | None = None,
    console: Console | None = None,
    stages_file: str | Path | None = None,
    topics: Topics | None = None,
) -> TofRecordingRun:
    """Calibrate ``recording``, print the figures, write the files (module doc)."""
    console = console or Console()
    result, left_out = calibrate_tof_recording(recording, intrinsics, stages_file, topics)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"tof_camera": out / TOF_NAME, "summary": out / SUMMARY_NAME}
    result.calibration.save(files["tof_camera"])
    files["summary"].write_text(json.dumps(tof_summary(result, left_out), indent=1))
    print_tof_summary(console, result, left_out)
    for key, path in files.items():
        console.print(f"{key}: {path}")
    return TofRecordingRun(result, left_out, files)
