"""Reads an MCAP file or a rosbag2 folder (sqlite3 or MCAP storage) into a
:class:`~agents.io.recording.Recording`, with ``rosbags`` (no ROS install).

Topics (:class:`Topics`, every name configurable):

* camera: ``sensor_msgs/Image`` (mono8, 8UC1, rgb8, bgr8, rgba8, bgra8) or
  ``sensor_msgs/CompressedImage`` (JPEG, PNG), or ``deck_landing_msgs/TagDetections``
  (what the simulator's recorder writes when it projects the tag instead of rendering);
* ToF: ``sensor_msgs/Range`` on four topics (sensor 1..4 in order), or on one topic whose
  ``header.frame_id`` names the sensor; a range outside [min_range, max_range] (or ±inf,
  REP 117) is no return.  ``deck_landing_msgs/TofRanges`` (float64), when present, is used
  instead;
* IMU: ``sensor_msgs/Imu`` (body FLU); its orientation, unless ``orientation_covariance[0]``
  is -1 (REP 145: unknown), is the body's attitude in the world (``fused`` uses it);
* the vehicle's pose: ``tf2_msgs/TFMessage`` (``/tf``), the transforms from the world frame
  to the body frame (``world`` -> ``body``, as the simulator's recorder writes them: W with
  x north, y west, z up; B FLU), each at its own stamp (``deck-landing bridge`` gives it to
  PX4).  Other transforms are not read.

Stamps are the messages' ``header.stamp``.  A message that cannot be decoded, an image of
an unknown encoding, or a range from an unknown frame id is skipped and counted by reason;
ranges out of time order, a corrupt or truncated file and a missing camera topic are errors.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from rosbags.highlevel import AnyReader

from agents.io import messages as m
from agents.io.recording import N_SENSORS, RecordedFrame, Recording, RecordingError, Topics
from estimation.types import ImuSample, TagDetection

#: the raw image encodings read, with their channel counts
CHANNELS = {"mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}
IMAGE_ENCODINGS = tuple(CHANNELS)


def decode_image(message: Any, typename: str, topic: str) -> np.ndarray:
    """An Image or CompressedImage as grey or RGB uint8; ``ValueError`` naming the field."""
    if typename == m.COMPRESSED:
        data = np.frombuffer(bytes(message.data), dtype=np.uint8)
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if image is None or image.dtype != np.uint8:
            raise ValueError(f"{topic}: format {message.format!r} data cannot be decoded")
        if image.ndim == 3:
            code = cv2.COLOR_BGRA2RGB if image.shape[2] == 4 else cv2.COLOR_BGR2RGB
            image = cv2.cvtColor(image, code)
        return image
    encoding = message.encoding
    if encoding not in IMAGE_ENCODINGS:
        raise ValueError(
            f"{topic}: encoding {encoding!r} unknown; known: {', '.join(IMAGE_ENCODINGS)}"
        )
    channels = CHANNELS[encoding]
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.asarray(message.data, dtype=np.uint8)
    if width < 1 or height < 1 or step < width * channels or data.size < step * height:
        raise ValueError(f"{topic}: data holds {data.size} bytes, not {height} rows of {step}")
    rows = data[: step * height].reshape(height, step)[:, : width * channels]
    image = rows.reshape(height, width, channels) if channels > 1 else rows.reshape(height, width)
    if encoding == "bgr8":
        image = image[:, :, ::-1]
    elif encoding == "rgba8":
        image = image[:, :, :3]
    elif encoding == "bgra8":
        image = image[:, :, 2::-1]
    return np.ascontiguousarray(image)


def _range_value(message: Any) -> tuple[float, bool]:
    value = float(message.range)
    lo, hi = float(message.min_range), float(message.max_range)
    ok = math.isfinite(value) and lo <= value <= hi
    return (value if ok else math.nan), ok


def read_bag(path: str | Path, topics: Topics | None = None) -> Recording:
    """Read an MCAP file or a rosbag2 folder (module doc)."""
    topics = topics or Topics()
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file or folder")
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise RecordingError(
            f"{path}: no recording in this folder (a plain folder has frames.csv, a rosbag2 "
            "folder metadata.yaml)"
        )
    rec = Recording()
    try:
        with AnyReader([path], default_typestore=m.TYPESTORE) as reader:
            present = {c.topic: c.msgtype for c in reader.connections}
            # the detections when recorded (exact), else the images (detected here)
            camera = [t for t in (topics.detections, topics.image) if t and t in present][:1]
            if not camera:
                names = [t for t in (topics.image, topics.detections) if t] or ["(none given)"]
                which = "neither camera topic " if len(names) > 1 else "camera topic "
                raise RecordingError(
                    f"{path}: missing topic: {which}{' nor '.join(names)}; the file has "
                    f"{', '.join(sorted(present)) or 'none'}"
                )
            _require_named(path, topics, present)
            exact = bool(topics.exact_ranges) and topics.exact_ranges in present
            wanted = {*camera, topics.imu, *([topics.exact_ranges] if exact else topics.ranges)}
            wanted.discard("")  # a topic not asked for
            rec.missing_topics = sorted(t for t in wanted if t not in present)
            if topics.tf:
                wanted.add(topics.tf)  # optional: no vehicle pose when missing
            connections = [c for c in reader.connections if c.topic in wanted]
            for connection, _, raw in reader.messages(connections=connections):
                _one(rec, topics, camera, connection.topic, connection.msgtype, raw, reader, exact)
    except RecordingError:
        raise
    except Exception as exc:  # rosbags' and mcap's own errors: a damaged file
        raise RecordingError(
            f"{path}: truncated or corrupt recording ({type(exc).__name__}: {exc})"
        ) from None
    rec.frames.sort(key=lambda f: f.timestamp)
    return rec


def _require_named(path: Path, topics: Topics, present: dict[str, str]) -> None:
    """Refuse a topic named in place of a default (``--range-topics``, ``--imu-topic``, ...)
    that the recording does not hold: it would be read as no data."""
    default = Topics()
    named = {
        "--range-topics": topics.ranges if topics.ranges != default.ranges else (),
        "--exact-ranges-topic": (topics.exact_ranges,)
        if topics.exact_ranges not in ("", default.exact_ranges)
        else (),
        "--imu-topic": (topics.imu,) if topics.imu not in ("", default.imu) else (),
    }  # the vehicle's pose (--tf-topic) is optional: its users say what they miss
    for flag, names in named.items():
        absent = [t for t in names if t not in present]
        if absent:
            raise RecordingError(
                f"{flag} {','.join(absent)}: not in {path}; its topics: "
                f"{', '.join(sorted(present)) or 'none'}"
            )


def _one(
    rec: Recording,
    topics: Topics,
    camera: list[str],
    topic: str,
    typename: str,
    raw: bytes,
    reader: Any,
    exact: bool,
) -> None:
    try:
        message = reader.deserialize(raw, typename)
    except Exception:  # one damaged message: skip and count it
        rec.skipped[f"{topic}: message cannot be decoded"] += 1
        return
    if topic == topics.tf and topic not in camera:
        _vehicle(rec, topics, message)
        return
    t = m.stamp_s(message.header)
    if topic in camera:
        _frame(rec, topic, typename, message, t)
    elif topic == topics.exact_ranges and exact:
        ranges, valid = np.asarray(message.range_m, float), np.asarray(message.valid, bool)
        if len(ranges) != N_SENSORS or len(valid) != N_SENSORS:
            rec.skipped[f"{topic}: range_m/valid not {N_SENSORS} long"] += 1
            return
        for i in range(N_SENSORS):
            rec.sensors[i].add(t, ranges[i], bool(valid[i]), f"{topic} (sensor {i + 1})")
    elif topic in topics.ranges and not exact:
        if len(topics.ranges) == N_SENSORS:
            index = topics.ranges.index(topic)
        elif message.header.frame_id in topics.range_frames:
            index = topics.range_frames.index(message.header.frame_id)
        else:
            rec.skipped[f"{topic}: header.frame_id {message.header.frame_id!r} unknown"] += 1
            return
        value, ok = _range_value(message)
        rec.sensors[index].add(t, value, ok, f"{topic} (sensor {index + 1})")
    elif topic == topics.imu:
        accel = message.linear_acceleration
        gyro = message.angular_velocity
        values = np.array([accel.x, accel.y, accel.z, gyro.x, gyro.y, gyro.z], dtype=float)
        if not np.all(np.isfinite(values)):
            rec.skipped[f"{topic}: a non-finite value"] += 1
            return
        rec.imu.append(ImuSample(t, values[:3], values[3:]))
        known = float(message.orientation_covariance[0]) != -1.0
        rec.attitude.append(m.rotation_of(message.orientation) if known else None)


def _vehicle(rec: Recording, topics: Topics, message: Any) -> None:
    """The world -> body transforms of a ``tf2_msgs/TFMessage`` as the vehicle's poses."""
    parent, child = topics.tf_frames
    for transform in getattr(message, "transforms", ()):
        names = (transform.header.frame_id.lstrip("/"), transform.child_frame_id.lstrip("/"))
        if names != (parent, child):
            continue
        q, p = transform.transform.rotation, transform.transform.translation
        values = np.array([q.x, q.y, q.z, q.w, p.x, p.y, p.z], dtype=float)
        norm = float(np.linalg.norm(values[:4]))
        if not (np.all(np.isfinite(values)) and 0.5 < norm < 1.5):
            rec.skipped[f"{topics.tf}: {parent} -> {child} not finite or not a rotation"] += 1
            continue
        rec.vehicle.add(m.stamp_s(transform.header), m.rotation_of(q), values[4:])


def _frame(rec: Recording, topic: str, typename: str, message: Any, t: float) -> None:
    source = f"{topic}@{t:.9f}"
    if typename == m.DETECTIONS:
        detections = tuple(
            TagDetection(
                tag_id=int(d.id),
                corners_px=np.asarray(d.corners_px, dtype=float).reshape(4, 2),
                decision_margin=float(d.decision_margin),
                hamming=int(d.hamming),
            )
            for d in message.detections
        )
        rec.frames.append(RecordedFrame(t, source, None, detections, message.miss_reason))
        return
    if typename not in (m.IMAGE, m.COMPRESSED):
        rec.skipped[f"{topic}: type {typename} is not an image"] += 1
        return
    try:
        image = decode_image(message, typename, topic)
    except ValueError as exc:
        rec.skipped[str(exc)] += 1
        return
    rec.frames.append(RecordedFrame(t, source, image))
