"""A ToF rig's run as an MCAP or rosbag2 recording: written (the simulated rig's) and read
(``deck-landing calibrate tof --recording REC.mcap``).  Needs the optional extra ``io``.

The recording holds the rig's camera images (``sensor_msgs/Image``) and the four sensors'
ranges (``sensor_msgs/Range`` on one topic with a frame id per sensor, or on four topics, as
:class:`agents.io.recording.Topics` names them), read by :func:`agents.io.bag.read_bag` as
``deck-landing estimate`` reads a recording; when the float64 ``deck_landing_msgs/TofRanges``
is there too it is used instead of the float32 ``Range``.  The stage windows are the rig file
(:class:`estimation.tof_rig.TofRigDescription`), beside the recording
(:mod:`agents.io.tof_rig`).

:func:`write_rig_mcap` writes a rig's stages with the simulator recorder's messages
(:func:`agents.io.messages.image_rgb8`, :func:`agents.io.messages.tof_messages`) and writer
(:class:`agents.io.messages.McapWriter`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.io import messages as m
from agents.io.bag import read_bag
from agents.io.recording import Recording, RecordingError, Topics
from estimation.tof_rig import RIG_FILE, RigStage, TofRigDescription, reading_rows

#: a Range's max_range when the rig file gives no maximum (the largest float32)
NO_MAXIMUM_M = float(np.finfo(np.float32).max)


def rig_topics(topics: Topics | None = None) -> Topics:
    """The topics a rig's run is read from: the images and the ranges only (no tag
    detections, IMU or tf)."""
    return dataclasses.replace(topics or Topics(), detections="", imu="", tf="")


def write_rig_mcap(
    path: str | Path,
    stages: Sequence[RigStage],
    description: TofRigDescription,
    topics: Topics | None = None,
    stages_file: str | Path | None = None,
) -> Path:
    """Write ``stages`` as an MCAP file at ``path`` (module doc) and the rig file to
    ``stages_file`` (default: ``tof_rig.json`` beside it).  The ranges go on the topics'
    Range topic(s) and, unless ``topics.exact_ranges`` is empty, as float64 TofRanges."""
    topics = rig_topics(topics)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = reading_rows(stages)
    max_range = description.tof_max_range_m
    limits = {
        "min_range_m": 0.0,
        "max_range_m": NO_MAXIMUM_M if max_range is None else float(max_range),
    }
    frame_ids = topics.range_frames if len(topics.ranges) == 1 else m.TOF_FRAME_IDS
    # in time order, as recorded: each stage's image, then its readings
    images = [(f.t_s, 0, f.image) for stage in stages for f in stage.frames]
    readings = [(t_s, 1, np.asarray(values, dtype=float)) for t_s, values in rows]
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        for t_s, kind, data in sorted(images + readings, key=lambda e: (e[0], e[1])):
            if kind == 0:
                writer.write(topics.image, m.IMAGE, m.image_rgb8(t_s, data), t_s)
                continue
            valid = np.isfinite(data) & (data >= 0.0)  # as the plain folder reads them
            messages, exact = m.tof_messages(t_s, data, valid, frame_ids=frame_ids, **limits)
            for i, message in enumerate(messages):
                topic = topics.ranges[0] if len(topics.ranges) == 1 else topics.ranges[i]
                writer.write(topic, m.RANGE, message, t_s)
            if topics.exact_ranges:
                writer.write(topics.exact_ranges, m.TOF_RANGES, exact, t_s)
        writer.finish()
    description.save(Path(stages_file) if stages_file is not None else path.parent / RIG_FILE)
    return path


def read_rig_bag(path: str | Path, topics: Topics | None = None) -> Recording:
    """The rig's images and ranges of an MCAP file or rosbag2 folder.
    :class:`~agents.io.recording.RecordingError` names the file and the topic: a missing
    camera or range topic, a sensor with no range on a shared topic, a damaged file."""
    topics = rig_topics(topics)
    rec = read_bag(path, topics)
    missing = [t for t in rec.missing_topics if t in topics.ranges]
    if missing:
        raise RecordingError(
            f"{path}: missing topic(s) {', '.join(missing)} (sensor_msgs/Range of the ToF "
            f"sensors; nor {topics.exact_ranges or 'an exact ranges topic'})"
        )
    for i, series in enumerate(rec.sensors):
        if not series.t_s:
            where = (
                f"frame id {topics.range_frames[i]} on {topics.ranges[0]}"
                if len(topics.ranges) == 1
                else f"topic {topics.ranges[i]}"
            )
            raise RecordingError(f"{path}: no range of sensor {i + 1} ({where})")
    return rec


__all__ = ["read_rig_bag", "rig_topics", "write_rig_mcap"]
