"""The ToF–camera calibration from a rig's stages (IHRCF Sec. 2.2, CRHF Sec. 2.3).

A rig holds the drone (or the camera and its sensors) still over a deck carrying one
coloured pad under each sensor (blue, green, yellow, red for sensors 1–4), at several heights
(the *stages*).  At each stage the camera's frames and each sensor's ranges are kept; each pad
is segmented with the papers' YCbCr thresholds (Table 1,
:func:`~estimation.tof_calibration.segment_pad`), closed with the convex hull of its largest
blob, and its centroid paired with the sensor's range.  The pairs give the PCHIP look-up of
:class:`~estimation.tof_calibration.TofCameraCalibration`.

The same :func:`calibrate_rig` serves the simulated rig (in memory) and a recorded one
(``deck-landing calibrate tof --recording``, which groups the recording's frames and ranges
into stages by the time windows of its rig file, :class:`TofRigDescription`).

Per stage and sensor: the range is the mean of the sensor's valid readings in the stage; a
sensor with fewer than half its readings valid is skipped for that stage (``range_invalid``).
The pad's centroid is the mean of its centroids over the stage's frames; a pad that is not
found in any frame (``pad_not_found``: no blob of ``min_pad_area_px``), or touches the image
border in one (``pad_clipped``), is skipped for that stage.  Skips are counted per reason,
never filled in.

The rig file (JSON ``tof_rig.json`` in the recording folder, ``format: deck-landing/tof-rig``,
``format_version: 1``):

* ``stages``: a list of ``{"t_start_s": ..., "t_end_s": ...}`` (optionally ``nominal_range_m``,
  for the record): the windows, on the recording's clock, in which the rig held still at one
  height; in time order, not overlapping, at least two;
* ``min_pad_area_px`` (optional, default 12): a smaller blob is "not found";
* ``camera`` (optional): the camera model of the images (the keys of
  :meth:`~estimation.camera_model.CameraIntrinsics.as_dict`), used when no intrinsics file
  is given;
* ``tof_mount_offsets_c`` (optional): the sensors' positions in the camera frame, metres,
  one [x, y, z] per sensor, copied into the calibration for the estimators;
* ``tof_max_range_m`` (optional) and ``metadata`` (free-form provenance, copied too).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.tof_calibration import (
    PAD_COLOURS,
    TofCameraCalibration,
    largest_blob_hull,
    segment_pad,
)

#: the rig file of a recording folder
RIG_FILE = "tof_rig.json"
RIG_FORMAT = "deck-landing/tof-rig"
RIG_FORMAT_VERSION = 1
DEFAULT_MIN_PAD_AREA_PX = 12.0

#: Skip reasons counted per sensor.
PAD_NOT_FOUND = "pad_not_found"
PAD_CLIPPED = "pad_clipped"
RANGE_INVALID = "range_invalid"
SKIP_REASONS = (PAD_NOT_FOUND, PAD_CLIPPED, RANGE_INVALID)


class TofRigError(ValueError):
    """A rig recording that cannot be calibrated, naming the file, stage or field."""


@dataclass(frozen=True)
class StageWindow:
    """The time window (s, inclusive) in which the rig held still at one height."""

    t_start_s: float
    t_end_s: float
    nominal_range_m: float | None = None


@dataclass(frozen=True)
class TofRigDescription:
    """The rig file's content (module doc)."""

    stages: tuple[StageWindow, ...]
    min_pad_area_px: float = DEFAULT_MIN_PAD_AREA_PX
    camera: CameraIntrinsics | None = None
    tof_mount_offsets_c: tuple[tuple[float, float, float], ...] | None = None
    tof_max_range_m: float | None = None
    metadata: dict = field(default_factory=dict)

    def save(self, path: str | Path) -> None:
        doc: dict = {
            "format": RIG_FORMAT,
            "format_version": RIG_FORMAT_VERSION,
            "stages": [
                {
                    "t_start_s": s.t_start_s,
                    "t_end_s": s.t_end_s,
                    **({} if s.nominal_range_m is None else {"nominal_range_m": s.nominal_range_m}),
                }
                for s in self.stages
            ],
            "min_pad_area_px": self.min_pad_area_px,
            "metadata": self.metadata,
        }
        if self.camera is not None:
            doc["camera"] = self.camera.as_dict()
        if self.tof_mount_offsets_c is not None:
            doc["tof_mount_offsets_c"] = [list(row) for row in self.tof_mount_offsets_c]
        if self.tof_max_range_m is not None:
            doc["tof_max_range_m"] = self.tof_max_range_m
        Path(path).write_text(json.dumps(doc, indent=1))

    @classmethod
    def load(cls, path: str | Path) -> TofRigDescription:
        """Read and check a rig file; :class:`TofRigError` names the file and the field."""
        path = Path(path)
        if not path.is_file():
            raise TofRigError(
                f"{path.parent}: no {path.name} (the rig's stage windows; see the "
                "recorded-data how-to)"
            )
        try:
            doc = json.loads(path.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise TofRigError(f"{path}: not JSON ({exc})") from None
        if not isinstance(doc, dict) or doc.get("format") != RIG_FORMAT:
            raise TofRigError(f"{path}: format must be {RIG_FORMAT!r}")
        if doc.get("format_version") != RIG_FORMAT_VERSION:
            raise TofRigError(
                f"{path}: unsupported format_version {doc.get('format_version')!r}; "
                f"readable: {RIG_FORMAT_VERSION}"
            )
        stages = tuple(
            _window(entry, f"{path}: stages[{k}]")
            for k, entry in enumerate(_list(doc.get("stages"), f"{path}: stages"))
        )
        if len(stages) < 2:
            raise TofRigError(f"{path}: stages: {len(stages)} given; at least 2 are needed")
        for k in range(1, len(stages)):
            if stages[k].t_start_s <= stages[k - 1].t_end_s:
                raise TofRigError(
                    f"{path}: stages[{k}] starts at {stages[k].t_start_s} s, not after "
                    f"stages[{k - 1}] ends ({stages[k - 1].t_end_s} s): windows must be in "
                    "time order and not overlap"
                )
        area = _finite(doc.get("min_pad_area_px", DEFAULT_MIN_PAD_AREA_PX), path, "min_pad_area_px")
        if area < 1.0:
            raise TofRigError(f"{path}: min_pad_area_px {area} must be >= 1")
        camera = None
        if doc.get("camera") is not None:
            try:
                camera = CameraIntrinsics.from_dict(doc["camera"], f"{path}: camera")
            except (ValueError, AttributeError) as exc:
                raise TofRigError(str(exc)) from None
        mounts = None
        if doc.get("tof_mount_offsets_c") is not None:
            rows = np.asarray(doc["tof_mount_offsets_c"], dtype=object)
            try:
                array = np.asarray(rows, dtype=float)
            except (TypeError, ValueError):
                array = np.zeros((0,))
            if array.shape != (len(PAD_COLOURS), 3) or not np.all(np.isfinite(array)):
                raise TofRigError(
                    f"{path}: tof_mount_offsets_c must be {len(PAD_COLOURS)} rows of "
                    "[x, y, z] metres (the sensors in the camera frame)"
                )
            mounts = tuple(tuple(float(v) for v in row) for row in array)
        max_range = doc.get("tof_max_range_m")
        if max_range is not None:
            max_range = _finite(max_range, path, "tof_max_range_m")
        metadata = doc.get("metadata", {})
        if not isinstance(metadata, dict):
            raise TofRigError(f"{path}: metadata must be an object")
        return cls(stages, area, camera, mounts, max_range, metadata)  # type: ignore[arg-type]


def _list(value: object, where: str) -> list:
    if not isinstance(value, list):
        raise TofRigError(f"{where}: missing, or not a list of stage windows")
    return value


def _finite(value: object, path: Path, key: str) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise TofRigError(f"{path}: {key} = {value!r} is not a number") from None
    if not math.isfinite(number):
        raise TofRigError(f"{path}: {key} = {value!r} is not finite")
    return number


def _window(entry: object, where: str) -> StageWindow:
    if not isinstance(entry, dict) or "t_start_s" not in entry or "t_end_s" not in entry:
        raise TofRigError(f"{where}: need an object with t_start_s and t_end_s (seconds)")
    try:
        start, end = float(entry["t_start_s"]), float(entry["t_end_s"])
        nominal = entry.get("nominal_range_m")
        nominal = None if nominal is None else float(nominal)
    except (TypeError, ValueError):
        raise TofRigError(f"{where}: t_start_s, t_end_s and nominal_range_m are numbers") from None
    if not (math.isfinite(start) and math.isfinite(end) and start <= end):
        raise TofRigError(f"{where}: need finite t_start_s <= t_end_s, got {start}, {end}")
    return StageWindow(start, end, nominal)


@dataclass(frozen=True)
class RigFrame:
    """One camera frame of a stage: its stamp (s), its name (file) and its RGB image."""

    t_s: float
    name: str
    image: np.ndarray


@dataclass(frozen=True)
class RigStage:
    """One stage's frames and, per sensor, its readings' stamps (s) and ranges (m; NaN: no
    return)."""

    frames: tuple[RigFrame, ...]
    reading_t_s: tuple[np.ndarray, ...]
    readings_m: tuple[np.ndarray, ...]


def reading_rows(stages: Sequence[RigStage]) -> list[tuple[float, list[float]]]:
    """The stages' readings as rows ``(stamp s, [range m per sensor])`` in stage order, as
    a recording holds them (one row: every sensor at one stamp).  :class:`TofRigError` when
    a stage's sensors are not stamped together."""
    rows = []
    for k, stage in enumerate(stages):
        stamps = np.asarray(stage.reading_t_s[0])
        if any(not np.array_equal(t, stamps) for t in stage.reading_t_s):
            raise TofRigError(
                f"stage {k}: the sensors' readings are not stamped together; a recording's "
                "row of ranges holds the four sensors at one stamp"
            )
        for j, t_s in enumerate(stamps.tolist()):
            rows.append((t_s, [float(r[j]) for r in stage.readings_m]))
    return rows


@dataclass(frozen=True)
class RigCalibration:
    """The calibration, its raw pairs and what was skipped.

    ``ranges`` (stages, sensors) and ``pixels`` (stages, sensors, 2) hold NaN where a stage
    was skipped for a sensor; ``skipped[reason][sensor]`` counts the skips."""

    calibration: TofCameraCalibration
    ranges: np.ndarray
    pixels: np.ndarray
    skipped: dict[str, list[int]]


def pad_centroid_in_image(mask: np.ndarray, min_area_px: float) -> tuple[np.ndarray | None, str]:
    """Centroid (u, v) of the convex hull of the mask's largest blob, or None and a reason.

    A blob touching the image border is refused: the part outside would pull the centroid.
    """
    found = largest_blob_hull(mask)
    if found is None:
        return None, PAD_NOT_FOUND
    hull, moments = found
    if moments["m00"] < min_area_px:
        return None, PAD_NOT_FOUND
    x, y, w, h = cv2.boundingRect(hull)
    height, width = np.asarray(mask).shape
    if x <= 0 or y <= 0 or x + w >= width or y + h >= height:
        return None, PAD_CLIPPED
    return np.array([moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]]), ""


def _stage_range(readings: np.ndarray) -> float | None:
    """The mean of the valid readings, or None when fewer than half are valid."""
    readings = np.asarray(readings, dtype=float)
    valid = np.isfinite(readings) & (readings >= 0.0)
    count = int(valid.sum())
    if count == 0 or 2 * count < len(readings):
        return None
    total = 0.0
    for value in readings[valid].tolist():  # in time order, one by one
        total += value
    return total / count


def _stage_centroid(
    stage: RigStage, colour: str, min_area_px: float
) -> tuple[np.ndarray | None, str]:
    found, reason = [], PAD_NOT_FOUND
    for frame in stage.frames:
        centroid, why = pad_centroid_in_image(segment_pad(frame.image, colour), min_area_px)
        if centroid is None:
            if why == PAD_CLIPPED:
                return None, PAD_CLIPPED
            continue
        found.append(centroid)
    if not found:
        return None, reason
    return (found[0] if len(found) == 1 else np.mean(found, axis=0)), ""


def calibrate_rig(
    stages: Sequence[RigStage],
    rig: TofRigDescription,
    camera: CameraIntrinsics | None = None,
) -> RigCalibration:
    """The ToF–camera calibration of a rig's stages (module doc).

    ``camera``: the images' camera model (default: the rig file's), recorded in the
    calibration's metadata and checked against every image's size.  :class:`TofRigError`
    names the stage, frame or sensor: fewer than two stages, a stage without frames, an
    image that is not 8-bit colour or not the camera's size, a sensor with fewer than two
    usable stages."""
    camera = camera if camera is not None else rig.camera
    n_sensors = len(PAD_COLOURS)
    if len(stages) < 2:
        raise TofRigError(f"{len(stages)} stage(s); at least 2 are needed")
    size: tuple[int, int] | None = None
    for k, stage in enumerate(stages):
        if not stage.frames:
            raise TofRigError(f"stage {k}: no camera frame")
        if len(stage.readings_m) != n_sensors:
            raise TofRigError(f"stage {k}: {len(stage.readings_m)} sensors; need {n_sensors}")
        for frame in stage.frames:
            image = np.asarray(frame.image)
            if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
                raise TofRigError(
                    f"{frame.name}: the pads are found by colour: need an 8-bit RGB image, "
                    f"got {image.dtype} of shape {image.shape}"
                )
            this = (int(image.shape[1]), int(image.shape[0]))
            if camera is not None and this != (camera.width, camera.height):
                raise TofRigError(
                    f"{frame.name}: image is {this[0]}x{this[1]}, the camera model is "
                    f"{camera.width}x{camera.height}: calibrate with this camera's intrinsics"
                )
            if size is not None and this != size:
                raise TofRigError(
                    f"{frame.name}: image is {this[0]}x{this[1]}, the first was {size[0]}x{size[1]}"
                )
            size = this
    ranges = np.full((len(stages), n_sensors), np.nan)
    pixels = np.full((len(stages), n_sensors, 2), np.nan)
    skipped: dict[str, list[int]] = {reason: [0] * n_sensors for reason in SKIP_REASONS}
    for k, stage in enumerate(stages):
        for i, colour in enumerate(PAD_COLOURS):
            value = _stage_range(stage.readings_m[i])
            if value is None:
                skipped[RANGE_INVALID][i] += 1
                continue
            centroid, reason = _stage_centroid(stage, colour, rig.min_pad_area_px)
            if centroid is None:
                skipped[reason][i] += 1
                continue
            ranges[k, i] = value
            pixels[k, i] = centroid
    usable = np.isfinite(ranges).sum(axis=0)
    if np.any(usable < 2):
        short = ", ".join(
            f"sensor {i + 1} ({PAD_COLOURS[i]} pad): {int(usable[i])}"
            for i in range(n_sensors)
            if usable[i] < 2
        )
        raise TofRigError(
            f"usable stages {short}; at least 2 are needed per sensor (skipped: {skipped})"
        )
    metadata = {
        **rig.metadata,
        "camera": None if camera is None else camera.as_dict(),
        "tof_mount_offsets_c": None
        if rig.tof_mount_offsets_c is None
        else [list(row) for row in rig.tof_mount_offsets_c],
        "tof_max_range_m": rig.tof_max_range_m,
        "stages": len(stages),
        "min_pad_area_px": rig.min_pad_area_px,
        "skipped": skipped,
    }
    calibration = TofCameraCalibration.from_measurements(
        ranges,
        pixels,
        method="pchip",
        out_of_range="hyperbola",
        metadata={k: v for k, v in metadata.items() if v is not None},
        image_size=size,
    )
    return RigCalibration(calibration, ranges, pixels, skipped)
