"""ROS 2 messages: the standard schemas (from ``rosbags``' ROS 2 Humble store), the project's
three own messages, conversions, and an MCAP writer of CDR-encoded messages.

The project's messages (package ``deck_landing_msgs``), for what no standard schema holds:

* ``TagDetections``: a camera frame's AprilTag detections (corners in OpenCV pixels, the
  order of :data:`estimation.frames.TAG_CORNER_SIGNS`), and why the tag is missing when it
  is: what the estimators consume when the simulator projects the tag instead of rendering;
* ``TofRanges``: the four ToF ranges in float64 with their validity (``sensor_msgs/Range``
  holds float32, which rounds a range by up to 0.1 µm: enough to change an estimate's bits);
* ``EstimateStatus``: whether a method's estimate of a frame is valid, and why not.
"""

from __future__ import annotations

from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

PROJECT_MSGS = {
    "deck_landing_msgs/msg/TagDetection": (
        "int32 id\nfloat64[8] corners_px\nfloat64 decision_margin\nint32 hamming\n"
    ),
    "deck_landing_msgs/msg/TagDetections": (
        "std_msgs/Header header\nstring miss_reason\ndeck_landing_msgs/TagDetection[] detections\n"
    ),
    "deck_landing_msgs/msg/TofRanges": "std_msgs/Header header\nfloat64[] range_m\nbool[] valid\n",
    "deck_landing_msgs/msg/EstimateStatus": (
        "std_msgs/Header header\nstring method\nbool valid\nstring reason\n"
    ),
}

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
for _name, _text in PROJECT_MSGS.items():
    TYPESTORE.register(get_types_from_msg(_text, _name))

RANGE = "sensor_msgs/msg/Range"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
IMU = "sensor_msgs/msg/Imu"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE = "geometry_msgs/msg/PoseStamped"
TF = "tf2_msgs/msg/TFMessage"
DETECTIONS = "deck_landing_msgs/msg/TagDetections"
TOF_RANGES = "deck_landing_msgs/msg/TofRanges"
STATUS = "deck_landing_msgs/msg/EstimateStatus"


def msg(typename: str, **fields: Any) -> Any:
    """A message object of ``typename`` from its fields."""
    return TYPESTORE.types[typename](**fields)


def to_ns(t_s: float) -> int:
    """Seconds as integer nanoseconds (rounded)."""
    return round(float(t_s) * 1e9)


def header(t_s: float, frame_id: str) -> Any:
    ns = to_ns(t_s)
    stamp = msg("builtin_interfaces/msg/Time", sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return msg("std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)


def stamp_s(hdr: Any) -> float:
    """A header's stamp in seconds."""
    return hdr.stamp.sec + hdr.stamp.nanosec * 1e-9


def quaternion_xyzw(rotation: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(np.asarray(rotation, dtype=float)).as_quat()


def rotation_of(q: Any) -> np.ndarray:
    """The rotation matrix of a ``geometry_msgs/Quaternion``."""
    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()


def pose(rotation: np.ndarray, translation: np.ndarray) -> Any:
    q = quaternion_xyzw(rotation)
    t = np.asarray(translation, dtype=float)
    return msg(
        "geometry_msgs/msg/Pose",
        position=msg("geometry_msgs/msg/Point", x=t[0], y=t[1], z=t[2]),
        orientation=msg("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3]),
    )


def transform(
    t_s: float, parent: str, child: str, rotation: np.ndarray, translation: np.ndarray
) -> Any:
    """A ``geometry_msgs/TransformStamped``: ``child``'s pose in ``parent``."""
    q = quaternion_xyzw(rotation)
    t = np.asarray(translation, dtype=float)
    return msg(
        "geometry_msgs/msg/TransformStamped",
        header=header(t_s, parent),
        child_frame_id=child,
        transform=msg(
            "geometry_msgs/msg/Transform",
            translation=msg("geometry_msgs/msg/Vector3", x=t[0], y=t[1], z=t[2]),
            rotation=msg("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def vector3(v: np.ndarray) -> Any:
    return msg("geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))


#: the ToF sensors' frame ids, sensor 1..4
TOF_FRAME_IDS = ("tof_1", "tof_2", "tof_3", "tof_4")
#: the ToF sensors' field of view in ``sensor_msgs/Range`` (the VL53L1X's 27 degrees)
TOF_FOV_RAD = float(np.deg2rad(27.0))


def image_rgb8(t_s: float, image: np.ndarray, frame_id: str = "camera") -> Any:
    """A ``sensor_msgs/Image`` (``rgb8``) of an 8-bit RGB (or RGBA: alpha dropped) image."""
    pixels = np.ascontiguousarray(np.asarray(image, dtype=np.uint8)[:, :, :3])
    height, width = pixels.shape[:2]
    return msg(
        IMAGE,
        header=header(t_s, frame_id),
        height=height,
        width=width,
        encoding="rgb8",
        is_bigendian=0,
        step=3 * width,
        data=pixels.reshape(-1),
    )


def tof_messages(
    t_s: float,
    ranges_m: np.ndarray,
    valid: np.ndarray,
    *,
    min_range_m: float,
    max_range_m: float,
    fov_rad: float = TOF_FOV_RAD,
    frame_ids: tuple[str, ...] = TOF_FRAME_IDS,
) -> tuple[list[Any], Any]:
    """One reading of the ToF sensors: a ``sensor_msgs/Range`` per sensor (frame id
    ``frame_ids[i]``, infrared; no return is +inf, REP 117) and the float64
    ``deck_landing_msgs/TofRanges`` (frame ``body``)."""
    values = np.asarray(ranges_m, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool)
    ranges = [
        msg(
            RANGE,
            header=header(t_s, frame_id),
            radiation_type=1,  # INFRARED
            field_of_view=float(fov_rad),
            min_range=float(min_range_m),
            max_range=float(max_range_m),
            range=float(value) if good else float("inf"),
        )
        for frame_id, value, good in zip(frame_ids, values, ok, strict=True)
    ]
    exact = msg(TOF_RANGES, header=header(t_s, "body"), range_m=values, valid=ok)
    return ranges, exact


class McapWriter:
    """Writes CDR-encoded ROS 2 messages to an MCAP file (profile ``ros2``), registering
    each schema (its ``ros2msg`` definition) and topic the first time it is written."""

    def __init__(self, stream: BinaryIO) -> None:
        self._writer = Writer(stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="deck-landing")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._sequence = 0

    def write(self, topic: str, typename: str, message: Any, t_s: float) -> None:
        """Write ``message`` on ``topic``, logged and published at ``t_s`` seconds."""
        if topic not in self._channels:
            if typename not in self._schemas:
                text, _ = TYPESTORE.generate_msgdef(typename, ros_version=2)
                self._schemas[typename] = self._writer.register_schema(
                    name=typename, encoding="ros2msg", data=text.encode()
                )
            channel = self._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=self._schemas[typename]
            )
            self._channels[topic] = (channel, typename)
        channel, registered = self._channels[topic]
        if registered != typename:
            raise ValueError(f"topic {topic} carries {registered}, not {typename}")
        data = TYPESTORE.serialize_cdr(message, typename)
        ns = max(to_ns(t_s), 0)
        self._writer.add_message(
            channel, log_time=ns, publish_time=ns, data=data, sequence=self._sequence
        )
        self._sequence += 1

    def metadata(self, name: str, values: dict[str, str]) -> None:
        self._writer.add_metadata(name, values)

    def finish(self) -> None:
        self._writer.finish()
