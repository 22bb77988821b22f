"""A ToF rig's recording: a plain folder with its rig file, to and from the rig's stages.

The folder is the plain recording format (:mod:`agents.io.recording`: ``frames.csv`` and the
images, ``ranges.csv``) with the rig file ``tof_rig.json`` (:mod:`estimation.tof_rig`: the
stage windows and the rig's settings).  :func:`read_rig_recording` groups the frames and the
range samples into stages by the windows; :func:`calibrate_tof_recording` (``deck-landing
calibrate tof --recording``) calibrates them with :func:`estimation.tof_rig.calibrate_rig`,
the function the simulated rig's stages go through too.  :func:`write_rig_recording` writes
a rig's stages as such a folder (the simulated rig's, with ``deck-landing calibrate``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.io.recording import RecordingError, read_folder, write_folder
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_rig import (
    RIG_FILE,
    RigCalibration,
    RigFrame,
    RigStage,
    TofRigDescription,
    TofRigError,
    calibrate_rig,
)

#: the intrinsics file looked for when ``--calibration`` names a folder
INTRINSICS_NAME = "intrinsics.json"


def write_rig_recording(
    folder: str | Path, stages: Sequence[RigStage], description: TofRigDescription
) -> Path:
    """Write ``stages`` and their rig file as a recording folder that
    :func:`read_rig_recording` reads back exactly (images as PNG, floats as exact text)."""
    folder = Path(folder)
    frames, rows = [], []
    for k, stage in enumerate(stages):
        frames.extend((f.t_s, f.name, f.image) for f in stage.frames)
        stamps = stage.reading_t_s[0]
        if any(not np.array_equal(t, stamps) for t in stage.reading_t_s):
            raise RecordingError(
                f"stage {k}: the sensors' readings are not stamped together; a row of "
                "ranges.csv holds the four sensors at one stamp"
            )
        for j, t_s in enumerate(stamps.tolist()):
            rows.append((t_s, [float(r[j]) for r in stage.readings_m]))
    write_folder(folder, frames, rows)
    description.save(folder / RIG_FILE)
    return folder


def read_rig_recording(folder: str | Path) -> tuple[list[RigStage], TofRigDescription, dict]:
    """The stages of a rig's recording folder, its rig file, and what was left out
    (``{reason: count}``: unreadable frames, frames and range rows outside every stage).

    :class:`~agents.io.recording.RecordingError` or
    :class:`~estimation.tof_rig.TofRigError` name the file, line or stage at fault."""
    folder = Path(folder)
    if not folder.is_dir():
        raise RecordingError(f"--recording {folder}: not a folder")
    description = TofRigDescription.load(folder / RIG_FILE)
    if not (folder / "ranges.csv").is_file():
        raise RecordingError(
            f"{folder}: no ranges.csv (columns t_s,range_1_m,range_2_m,range_3_m,range_4_m)"
        )
    rec = read_folder(folder)
    left_out = dict(rec.skipped)
    frame_t = np.array([f.timestamp for f in rec.frames])
    series_t = [np.asarray(s.t_s, dtype=float) for s in rec.sensors]
    series_r = [np.asarray(s.range_m, dtype=float) for s in rec.sensors]
    used_frames = np.zeros(len(frame_t), dtype=bool)
    used_rows = np.zeros(len(series_t[0]), dtype=bool)
    stages: list[RigStage] = []
    for k, window in enumerate(description.stages):
        where = f"{folder / RIG_FILE}: stages[{k}] ({window.t_start_s} to {window.t_end_s} s)"
        inside = (frame_t >= window.t_start_s) & (frame_t <= window.t_end_s)
        if not inside.any():
            skipped = f" (frames left out: {dict(rec.skipped)})" if rec.skipped else ""
            raise TofRigError(f"{where}: no frame of frames.csv in it{skipped}")
        used_frames |= inside
        frames = tuple(
            RigFrame(f.timestamp, str(folder / f.source), f.image)
            for f, keep in zip(rec.frames, inside, strict=True)
            if keep
        )
        masks = [(t >= window.t_start_s) & (t <= window.t_end_s) for t in series_t]
        if not any(mask.any() for mask in masks):
            raise TofRigError(f"{where}: no row of ranges.csv in it")
        used_rows |= masks[0]
        stages.append(
            RigStage(
                frames,
                tuple(t[mask] for t, mask in zip(series_t, masks, strict=True)),
                tuple(r[mask] for r, mask in zip(series_r, masks, strict=True)),
            )
        )
    if (~used_frames).any():
        left_out["frames.csv: frame outside every stage"] = int((~used_frames).sum())
    if (~used_rows).any():
        left_out["ranges.csv: row outside every stage"] = int((~used_rows).sum())
    return stages, description, left_out


def intrinsics_file(path: str | Path) -> Path:
    """``--calibration``: an intrinsics file, or a folder holding ``intrinsics.json``."""
    path = Path(path)
    if path.is_dir():
        path = path / INTRINSICS_NAME
    if not path.is_file():
        raise RecordingError(f"--calibration {path}: no such intrinsics file")
    return path


def calibrate_tof_recording(
    folder: str | Path, intrinsics: str | Path | None = None
) -> tuple[RigCalibration, dict]:
    """Calibrate a rig's recording folder (module doc); returns the calibration and what
    was left out.  ``intrinsics``: the camera's intrinsics file (or a folder holding
    ``intrinsics.json``); without it, the rig file's camera, if any.  Every image must be of
    the camera's size."""
    stages, description, left_out = read_rig_recording(folder)
    camera = None
    if intrinsics is not None:
        path = intrinsics_file(intrinsics)
        result = IntrinsicsCalibrationResult.load(path)
        first = stages[0].frames[0]
        height, width = first.image.shape[:2]
        result.require_camera((width, height), source=str(path), images=f"images ({first.name})")
        camera = result.to_intrinsics()
    return calibrate_rig(stages, description, camera), left_out


__all__ = [
    "calibrate_tof_recording",
    "intrinsics_file",
    "read_rig_recording",
    "write_rig_recording",
]
