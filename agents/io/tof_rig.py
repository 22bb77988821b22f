"""A ToF rig's recording, to and from the rig's stages.

A rig's recording is a plain folder (:mod:`agents.io.recording`: ``frames.csv`` and the
images, ``ranges.csv``) or an MCAP file or rosbag2 folder (:mod:`agents.io.tof_rig_bag`:
the images and the four ``sensor_msgs/Range`` topics, read as ``deck-landing estimate``
reads them), with the rig file (:mod:`estimation.tof_rig`: the stage windows and the rig's
settings): ``--stages-file FILE``, or ``tof_rig.json`` in the folder, in the rosbag2 folder or
beside the MCAP file.  :func:`read_rig_recording` groups the frames and the range samples
into stages by the windows; :func:`calibrate_tof_recording` (``deck-landing calibrate tof
--recording``) calibrates them with :func:`estimation.tof_rig.calibrate_rig`, the function
the simulated rig's stages go through too.  :func:`write_rig_recording` writes a rig's
stages as a plain folder (the simulated rig's, with ``deck-landing calibrate``);
:func:`agents.io.tof_rig_bag.write_rig_mcap` as MCAP.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.io.recording import Recording, RecordingError, Topics, read_folder, write_folder
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_rig import (
    RIG_FILE,
    RigCalibration,
    RigFrame,
    RigStage,
    TofRigDescription,
    TofRigError,
    calibrate_rig,
    reading_rows,
)

#: the intrinsics file looked for when ``--calibration`` names a folder
INTRINSICS_NAME = "intrinsics.json"


def write_rig_recording(
    folder: str | Path, stages: Sequence[RigStage], description: TofRigDescription
) -> Path:
    """Write ``stages`` and their rig file as a recording folder that
    :func:`read_rig_recording` reads back exactly (images as PNG, floats as exact text)."""
    folder = Path(folder)
    frames = [(f.t_s, f.name, f.image) for stage in stages for f in stage.frames]
    write_folder(folder, frames, reading_rows(stages))
    description.save(folder / RIG_FILE)
    return folder


def is_rig_folder(path: Path) -> bool:
    """A plain folder recording (any folder but a rosbag2 one, which has metadata.yaml)."""
    return path.is_dir() and not (path / "metadata.yaml").is_file()


def rig_file(recording: Path, stages: str | Path | None = None) -> Path:
    """The rig file: ``stages``, or ``tof_rig.json`` in the recording's folder (a plain or
    rosbag2 folder) or beside it (an MCAP file)."""
    if stages is not None:
        path = Path(stages)
        if not path.is_file():
            raise TofRigError(f"--stages-file {path}: no such file (the rig's stage windows)")
        return path
    inside = recording.is_dir()
    path = (recording if inside else recording.parent) / RIG_FILE
    if not path.is_file():
        raise TofRigError(
            f"{recording}: no {RIG_FILE} {'in the folder' if inside else 'beside it'} and no "
            "--stages-file FILE given (the rig's stage windows)"
        )
    return path


def read_rig_recording(
    path: str | Path, stages: str | Path | None = None, topics: Topics | None = None
) -> tuple[list[RigStage], TofRigDescription, dict]:
    """The stages of a rig's recording (a folder, MCAP file or rosbag2 folder), its rig file
    (``stages``, or found as :func:`rig_file` says) and what was left out (``{reason:
    count}``: unreadable frames and messages, frames and ranges outside every stage).
    ``topics``: an MCAP or rosbag2 recording's images and ranges.

    :class:`~agents.io.recording.RecordingError` or
    :class:`~estimation.tof_rig.TofRigError` name the file, line, topic or stage at fault."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"--recording {path}: not a folder, MCAP file or rosbag2 folder")
    rig_path = rig_file(path, stages)
    description = TofRigDescription.load(rig_path)
    where = f"{rig_path}: stages"
    if is_rig_folder(path):
        if not (path / "ranges.csv").is_file():
            raise RecordingError(
                f"{path}: no ranges.csv (columns t_s,range_1_m,range_2_m,range_3_m,range_4_m)"
            )
        rec = read_folder(path)
        labels = ("frames.csv", "ranges.csv", "row")
        return _stages(rec, description, where, labels, folder=path)
    # mcap and rosbags: the optional extra ``io``, needed for these recordings only
    from agents.io.tof_rig_bag import read_rig_bag, rig_topics

    topics = rig_topics(topics)
    rec = read_rig_bag(path, topics)
    ranges = topics.exact_ranges if topics.exact_ranges else ", ".join(topics.ranges)
    labels = (topics.image, ranges, "range sample")
    return _stages(rec, description, where, labels, folder=None)


def _stages(
    rec: Recording,
    description: TofRigDescription,
    where: str,
    labels: tuple[str, str, str],
    folder: Path | None,
) -> tuple[list[RigStage], TofRigDescription, dict]:
    """Group ``rec``'s frames and ranges into the rig file's stages (``labels``: where the
    frames and the ranges come from, and what one range row is called, for the messages)."""
    frames_label, ranges_label, row = labels
    left_out = dict(rec.skipped)
    frame_t = np.array([f.timestamp for f in rec.frames])
    series_t = [np.asarray(s.t_s, dtype=float) for s in rec.sensors]
    series_r = [np.asarray(s.range_m, dtype=float) for s in rec.sensors]
    used_frames = np.zeros(len(frame_t), dtype=bool)
    used_rows = [np.zeros(len(t), dtype=bool) for t in series_t]
    stages: list[RigStage] = []
    for k, window in enumerate(description.stages):
        at = f"{where}[{k}] ({window.t_start_s} to {window.t_end_s} s)"
        inside = (frame_t >= window.t_start_s) & (frame_t <= window.t_end_s)
        if not inside.any():
            skipped = f" (frames left out: {dict(rec.skipped)})" if rec.skipped else ""
            raise TofRigError(f"{at}: no frame of {frames_label} in it{skipped}")
        used_frames |= inside
        frames = tuple(
            RigFrame(f.timestamp, str(folder / f.source) if folder else f.source, f.image)
            for f, keep in zip(rec.frames, inside, strict=True)
            if keep
        )
        masks = [(t >= window.t_start_s) & (t <= window.t_end_s) for t in series_t]
        if not any(mask.any() for mask in masks):
            raise TofRigError(f"{at}: no {row} of {ranges_label} in it")
        for used, mask in zip(used_rows, masks, strict=True):
            used |= mask
        stages.append(
            RigStage(
                frames,
                tuple(t[mask] for t, mask in zip(series_t, masks, strict=True)),
                tuple(r[mask] for r, mask in zip(series_r, masks, strict=True)),
            )
        )
    if (~used_frames).any():
        left_out[f"{frames_label}: frame outside every stage"] = int((~used_frames).sum())
    outside = max(int((~used).sum()) for used in used_rows)
    if outside:
        left_out[f"{ranges_label}: {row} outside every stage"] = outside
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
    recording: str | Path,
    intrinsics: str | Path | None = None,
    stages_file: str | Path | None = None,
    topics: Topics | None = None,
) -> tuple[RigCalibration, dict]:
    """Calibrate a rig's recording (module doc; ``stages_file`` and ``topics`` as
    :func:`read_rig_recording` takes them); returns the calibration and what was left out.
    ``intrinsics``: the camera's intrinsics file (or a folder holding ``intrinsics.json``);
    without it, the rig file's camera, if any.  Every image must be of the camera's size."""
    stages, description, left_out = read_rig_recording(recording, stages_file, topics)
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
    "is_rig_folder",
    "read_rig_recording",
    "rig_file",
    "write_rig_recording",
]
