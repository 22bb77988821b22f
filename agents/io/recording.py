"""A recording in memory, the plain-folder reader and the time alignment of the ranges.

A :class:`Recording` holds camera frames (an image, or the tag detections the simulator
projected), each ToF sensor's time series, the IMU samples and, where a ROS 2 recording has
them on ``/tf``, the vehicle's poses (the body in the world), all stamped in seconds.
:func:`read_folder` reads the plain folder format (:func:`write_folder` writes it);
:mod:`agents.io.bag` reads MCAP and rosbag2.  :meth:`Recording.ranges_at` gives each frame
the ranges nearest to its stamp (or interpolated) within a tolerance; a sensor without a
sample inside it is invalid for that frame (an estimator then falls back to the camera
alone, or says why it cannot); :meth:`PoseSeries.at` aligns the vehicle's pose the same way.

Plain folder (for users without ROS)::

    REC/frames.csv   t_s,image            # image: a file name relative to REC
    REC/ranges.csv   t_s,range_1_m,range_2_m,range_3_m,range_4_m   # empty or nan: no return
    REC/imu.csv      t_s,ax,ay,az,gx,gy,gz[,qx,qy,qz,qw]            # optional (``fused``)

Stamps are seconds on one clock, increasing down each file; images are 8-bit grey or colour
files that OpenCV reads (PNG, JPEG, ...).  The IMU is in the body frame (FLU, m/s², rad/s);
its optional quaternion is the body's attitude in the world (FLU body, ENU-like world, z up).
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from estimation.fusion import METHOD as FUSED
from estimation.registry import FRAME_ESTIMATOR_NAMES, load_plugins
from estimation.types import ImuSample, RangeReading, TagDetection

N_SENSORS = 4
ALIGN_MODES = ("nearest", "interpolate")


def recording_estimators() -> tuple[str, ...]:
    """The estimators a recording can be run through: the single-frame ones (those of the
    installed plugins included) and ``fused``."""
    load_plugins()
    return (*FRAME_ESTIMATOR_NAMES, FUSED)


class RecordingError(ValueError):
    """A recording that cannot be used, naming the file, topic or field."""


@dataclass(frozen=True)
class RecordedFrame:
    """One camera frame: an image, or (recorded from the simulator) its tag detections."""

    timestamp: float
    source: str
    image: np.ndarray | None = None
    detections: tuple[TagDetection, ...] | None = None
    miss_reason: str = ""


@dataclass
class SensorSeries:
    """One ToF sensor's samples: stamps (s, increasing), ranges (m) and validity."""

    t_s: list[float] = field(default_factory=list)
    range_m: list[float] = field(default_factory=list)
    valid: list[bool] = field(default_factory=list)

    def add(self, t_s: float, range_m: float, valid: bool, where: str) -> None:
        if self.t_s and t_s < self.t_s[-1]:
            raise RecordingError(
                f"{where}: ranges out of time order: stamp {t_s:.9f} s after {self.t_s[-1]:.9f} s"
            )
        ok = bool(valid) and math.isfinite(range_m)
        self.t_s.append(float(t_s))
        self.range_m.append(float(range_m) if ok else math.nan)
        self.valid.append(ok)


@dataclass
class PoseSeries:
    """The vehicle's poses: the body B in the world W (``r_wb``, ``t_wb`` metres), stamped in
    seconds (any order while read; :meth:`at` sorts them)."""

    t_s: list[float] = field(default_factory=list)
    r_wb: list[np.ndarray] = field(default_factory=list)
    t_wb: list[np.ndarray] = field(default_factory=list)
    _sorted: bool = field(default=True, repr=False)

    def __len__(self) -> int:
        return len(self.t_s)

    def add(self, t_s: float, r_wb: np.ndarray, t_wb: np.ndarray) -> None:
        if self.t_s and t_s < self.t_s[-1]:
            self._sorted = False
        self.t_s.append(float(t_s))
        self.r_wb.append(np.asarray(r_wb, dtype=float))
        self.t_wb.append(np.asarray(t_wb, dtype=float))

    def _sort(self) -> None:
        if not self._sorted:
            order = sorted(range(len(self.t_s)), key=self.t_s.__getitem__)
            self.t_s = [self.t_s[k] for k in order]
            self.r_wb = [self.r_wb[k] for k in order]
            self.t_wb = [self.t_wb[k] for k in order]
            self._sorted = True

    def at(
        self, t_s: float, tolerance_s: float, mode: str = "nearest"
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """``(r_wb, t_wb)`` at ``t_s``: the nearest pose within ``tolerance_s``, or with
        ``interpolate`` the position interpolated linearly and the attitude by slerp between
        the poses on either side (both within the tolerance); None when there is none."""
        self._sort()
        near = _near(self.t_s, t_s, tolerance_s)
        if not near:
            return None
        if mode == "interpolate" and len(near) == 2 and self.t_s[near[1]] > self.t_s[near[0]]:
            j0, j1 = near
            w = (t_s - self.t_s[j0]) / (self.t_s[j1] - self.t_s[j0])
            turn = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([self.r_wb[j0], self.r_wb[j1]])))
            r_wb = turn([w]).as_matrix()[0]
            return r_wb, (1.0 - w) * self.t_wb[j0] + w * self.t_wb[j1]
        best = min(near, key=lambda j: abs(self.t_s[j] - t_s))
        return self.r_wb[best].copy(), self.t_wb[best].copy()


@dataclass
class Recording:
    """Everything read from a recording; ``skipped``: bad messages left out, by reason."""

    frames: list[RecordedFrame] = field(default_factory=list)
    sensors: list[SensorSeries] = field(default_factory=lambda: [SensorSeries() for _ in "1234"])
    imu: list[ImuSample] = field(default_factory=list)
    #: per IMU sample, the body's attitude R_WB when the sample carries one
    attitude: list[np.ndarray | None] = field(default_factory=list)
    #: the vehicle's poses (``/tf``'s world -> body, :attr:`Topics.tf_frames`), if recorded
    vehicle: PoseSeries = field(default_factory=PoseSeries)
    skipped: Counter = field(default_factory=Counter)
    #: topics asked for that the file does not have
    missing_topics: list[str] = field(default_factory=list)

    @property
    def has_ranges(self) -> bool:
        return any(s.t_s for s in self.sensors)

    def image_size(self) -> tuple[int, int] | None:
        """(width, height) of the images (None when the frames hold detections only)."""
        for frame in self.frames:
            if frame.image is not None:
                return int(frame.image.shape[1]), int(frame.image.shape[0])
        return None

    def ranges_at(self, t_s: float, tolerance_s: float, mode: str = "nearest") -> RangeReading:
        """The four ranges for a frame at ``t_s`` (see the module doc); NaN / invalid where
        a sensor has no sample within ``tolerance_s``."""
        ranges = np.full(N_SENSORS, np.nan)
        valid = np.zeros(N_SENSORS, dtype=bool)
        for i, series in enumerate(self.sensors):
            value = _aligned(series, t_s, tolerance_s, mode)
            if value is not None:
                ranges[i], valid[i] = value, True
        return RangeReading(timestamp=t_s, ranges=ranges, valid=valid)

    def imu_between(self, after_s: float, until_s: float) -> list[ImuSample]:
        """The IMU samples stamped in (after_s, until_s] (compared in whole nanoseconds)."""
        hi = round(until_s * 1e9)
        if not math.isfinite(after_s):
            return [s for s in self.imu if round(s.timestamp * 1e9) <= hi]
        lo = round(after_s * 1e9)
        return [s for s in self.imu if lo < round(s.timestamp * 1e9) <= hi]

    def attitude_at(self, t_s: float) -> np.ndarray | None:
        """The latest attitude R_WB at or before ``t_s`` (None when there is none)."""
        latest = None
        limit = round(t_s * 1e9)
        for sample, r_wb in zip(self.imu, self.attitude, strict=True):
            if round(sample.timestamp * 1e9) > limit:
                break
            if r_wb is not None:
                latest = r_wb
        return latest


@dataclass(frozen=True)
class Topics:
    """The topics read of a ROS 2 recording (defaults: what :class:`agents.io.record.McapRecorder`
    writes; :mod:`agents.io.bag` says what each carries)."""

    image: str = "/camera/image_raw"
    detections: str = "/camera/tag_detections"
    ranges: tuple[str, ...] = ("/tof/range",)
    range_frames: tuple[str, ...] = ("tof_1", "tof_2", "tof_3", "tof_4")
    exact_ranges: str = "/tof/ranges"
    imu: str = "/imu/data"
    #: ``tf2_msgs/TFMessage``: the vehicle's pose is the transform ``tf_frames`` (parent
    #: world W, child body B); an empty name reads none
    tf: str = "/tf"
    tf_frames: tuple[str, str] = ("world", "body")

    @classmethod
    def from_arguments(cls, args: Any) -> Topics:
        """From a command's options (``--image-topic``, ``--range-topics a,b,c,d``, ...,
        ``--tf-frames PARENT,CHILD``); an option the command lacks, or left at None, keeps
        its default."""
        default = cls()

        def given(name: str, value: Any) -> Any:
            chosen = getattr(args, name, None)
            return value if chosen is None else chosen

        def names(name: str, value: tuple[str, ...]) -> tuple[str, ...]:
            text = given(name, ",".join(value))
            return tuple(t.strip() for t in text.split(",") if t.strip())

        frames = names("tf_frames", default.tf_frames)
        if len(frames) != 2:
            raise RecordingError(f"--tf-frames: give PARENT,CHILD (e.g. world,body), got {frames}")
        return cls(
            image=given("image_topic", default.image),
            detections=given("detections_topic", default.detections),
            ranges=names("range_topics", default.ranges),
            range_frames=names("range_frames", default.range_frames),
            exact_ranges=given("exact_ranges_topic", default.exact_ranges),
            imu=given("imu_topic", default.imu),
            tf=given("tf_topic", default.tf),
            tf_frames=(frames[0], frames[1]),
        )

    def __post_init__(self) -> None:
        if len(self.ranges) not in (1, N_SENSORS):
            raise RecordingError(
                f"range topics: give one (sensors by frame id) or {N_SENSORS}, got {self.ranges}"
            )
        if len(self.ranges) == 1 and len(self.range_frames) != N_SENSORS:
            raise RecordingError(f"range frame ids: give {N_SENSORS}, got {self.range_frames}")


def _near(times: Sequence[float], t_s: float, tolerance_s: float) -> list[int]:
    """The indices of the samples either side of ``t_s`` (increasing stamps) within the
    tolerance."""
    if not len(times):
        return []
    k = int(np.searchsorted(times, t_s))
    candidates = [j for j in (k - 1, k) if 0 <= j < len(times)]
    return [j for j in candidates if abs(times[j] - t_s) <= tolerance_s + 1e-12]


def _aligned(series: SensorSeries, t_s: float, tolerance_s: float, mode: str) -> float | None:
    near = _near(series.t_s, t_s, tolerance_s)
    if not near:
        return None
    times = np.asarray(series.t_s)
    if mode == "interpolate" and len(near) == 2 and all(series.valid[j] for j in near):
        j0, j1 = near
        if times[j1] > times[j0]:
            w = (t_s - times[j0]) / (times[j1] - times[j0])
            return float((1.0 - w) * series.range_m[j0] + w * series.range_m[j1])
    best = min(near, key=lambda j: abs(times[j] - t_s))
    return series.range_m[best] if series.valid[best] else None


def _rows(path: Path, required: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    try:
        with path.open(newline="") as stream:
            reader = csv.DictReader(stream)
            columns = reader.fieldnames or []
            missing = [c for c in required if c not in columns]
            if missing:
                raise RecordingError(
                    f"{path}: missing column(s) {', '.join(missing)}; has {', '.join(columns)}"
                )
            return [(n + 2, row) for n, row in enumerate(reader)]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise RecordingError(f"{path}: not a CSV file ({exc})") from None


def _number(text: str | None, path: Path, line: int, column: str) -> float:
    if text is None or text.strip() == "" or text.strip().lower() == "nan":
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise RecordingError(f"{path} line {line}: {column} = {text!r} is not a number") from None


def read_image(path: Path) -> np.ndarray | None:
    """An image file as grey or RGB uint8 (None when OpenCV cannot read it)."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint8:
        return None
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    elif image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return image


def read_folder(folder: str | Path) -> Recording:
    """Read the plain folder format (module doc).  A frame whose image is missing or
    unreadable, or whose stamp is not a number, is skipped and counted; frames out of time
    order, ranges out of time order and malformed ranges are errors naming file and line."""
    folder = Path(folder)
    rec = Recording()
    frames_csv = folder / "frames.csv"
    if not frames_csv.is_file():
        raise RecordingError(f"{folder}: no frames.csv (columns t_s,image)")
    last = -math.inf
    for line, row in _rows(frames_csv, ("t_s", "image")):
        t = _number(row["t_s"], frames_csv, line, "t_s")
        if not math.isfinite(t):
            rec.skipped[f"{frames_csv.name}: t_s not a number"] += 1
            continue
        if t < last:
            raise RecordingError(f"{frames_csv} line {line}: frames out of time order")
        last = t
        image = read_image(folder / row["image"])
        if image is None:
            rec.skipped[f"{frames_csv.name}: image missing or unreadable"] += 1
            continue
        rec.frames.append(RecordedFrame(timestamp=t, source=row["image"], image=image))
    ranges_csv = folder / "ranges.csv"
    if ranges_csv.is_file():
        columns = tuple(f"range_{i + 1}_m" for i in range(N_SENSORS))
        for line, row in _rows(ranges_csv, ("t_s", *columns)):
            t = _number(row["t_s"], ranges_csv, line, "t_s")
            if not math.isfinite(t):
                raise RecordingError(f"{ranges_csv} line {line}: t_s is not a number")
            for i, column in enumerate(columns):
                value = _number(row[column], ranges_csv, line, column)
                where = f"{ranges_csv} line {line}"
                rec.sensors[i].add(t, value, math.isfinite(value) and value >= 0.0, where)
    imu_csv = folder / "imu.csv"
    if imu_csv.is_file():
        axes = ("ax", "ay", "az", "gx", "gy", "gz")
        for line, row in _rows(imu_csv, ("t_s", *axes)):
            values = [_number(row[c], imu_csv, line, c) for c in ("t_s", *axes)]
            if not all(math.isfinite(v) for v in values):
                rec.skipped[f"{imu_csv.name}: a value is not a number"] += 1
                continue
            quat = [_number(row.get(c), imu_csv, line, c) for c in ("qx", "qy", "qz", "qw")]
            rec.imu.append(ImuSample(values[0], np.array(values[1:4]), np.array(values[4:7])))
            rec.attitude.append(_attitude(quat))
    return rec


def _csv_number(value: float) -> str:
    """A float as its shortest exact text (read back bit for bit); empty for no value."""
    return repr(float(value)) if math.isfinite(value) else ""


def write_folder(
    folder: str | Path,
    frames: Iterable[tuple[float, str, np.ndarray]],
    ranges: Iterable[tuple[float, Sequence[float]]],
) -> Path:
    """Write a plain folder (module doc) that :func:`read_folder` reads back exactly:
    ``frames`` as (stamp s, file name, 8-bit grey or RGB image; written losslessly, so use
    ``.png``), ``ranges`` as (stamp s, the four ranges in m, NaN for no return)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "frames.csv").open("w", newline="") as stream:
        table = csv.writer(stream)
        table.writerow(["t_s", "image"])
        for t_s, name, image in frames:
            image = np.asarray(image)
            if image.ndim == 3:
                image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
            if not cv2.imwrite(str(folder / name), image):
                raise RecordingError(f"{folder / name}: OpenCV cannot write this image")
            table.writerow([_csv_number(t_s), name])
    with (folder / "ranges.csv").open("w", newline="") as stream:
        table = csv.writer(stream)
        table.writerow(["t_s", *(f"range_{i + 1}_m" for i in range(N_SENSORS))])
        for t_s, values in ranges:
            if len(values) != N_SENSORS:
                raise RecordingError(f"{len(values)} ranges at {t_s} s; need {N_SENSORS}")
            table.writerow([_csv_number(t_s), *(_csv_number(v) for v in values)])
    return folder


def _attitude(quat_xyzw: list[float]) -> np.ndarray | None:
    q = np.asarray(quat_xyzw, dtype=float)
    if not np.all(np.isfinite(q)) or not 0.5 < np.linalg.norm(q) < 1.5:
        return None
    return Rotation.from_quat(q).as_matrix()
