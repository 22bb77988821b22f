"""Chessboard intrinsic calibration (CRHF Sec. 2.1–2.2) with OpenCV.

``pattern`` is OpenCV's ``patternSize``: inner corners per row, inner corners per column
(CRHF uses a 7 x 10-corner board).  Corners are in OpenCV pixels (pixel centres at integers).

The intrinsics file (JSON, ``format: deck-landing/camera-intrinsics``, ``format_version: 2``):

* ``camera_model``: ``pinhole-radtan`` (OpenCV's pinhole with k1 k2 p1 p2 k3), the only one;
* ``image_size``: [width, height] in pixels of the images it was made from;
* ``camera_matrix``: K (3x3); ``dist``: (k1, k2, p1, p2, k3);
* ``rms_reprojection_error_px`` and ``per_view_errors_px``;
* ``metadata``: provenance (e.g. the photos used and rejected); ``tag_corners``: optional.

Version 1 files (``version: 1``, no ``camera_model``) are read as ``pinhole-radtan``.
:meth:`IntrinsicsCalibrationResult.require_camera` refuses a file made for another camera.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from estimation.calibration_files import read_document
from estimation.camera_model import CameraIntrinsics

_FORMAT = "deck-landing/camera-intrinsics"
#: the version :meth:`IntrinsicsCalibrationResult.save` writes, and those it reads
FORMAT_VERSION = 2
_READABLE_VERSIONS = (1, 2)
#: OpenCV's pinhole camera with radial-tangential distortion (k1, k2, p1, p2, k3)
CAMERA_MODEL = "pinhole-radtan"

#: image files ``calibrate_from_images`` reads from a folder
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")


def find_chessboard(
    image: np.ndarray, pattern: tuple[int, int] = (7, 10), refine_window: int = 5
) -> np.ndarray | None:
    """The (N, 2) inner corners of a chessboard in an 8-bit grey or RGB image, or ``None``.

    Detected with ``cv2.findChessboardCorners`` and refined with ``cv2.cornerSubPix`` in a
    ``(2 * refine_window + 1)``-pixel window.
    """
    image = np.asarray(image)
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    if grey.dtype != np.uint8:
        raise ValueError("image must be 8-bit")
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, pattern, flags=flags)
    if not found or corners is None:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    refined = cv2.cornerSubPix(
        grey, corners.astype(np.float32), (refine_window, refine_window), (-1, -1), criteria
    )
    return refined.reshape(-1, 2).astype(float)


def chessboard_object_points(pattern: tuple[int, int], square_size: float) -> np.ndarray:
    """The board's (N, 3) inner corners in its own plane, in ``findChessboardCorners`` order."""
    cols, rows = pattern
    grid = np.zeros((rows * cols, 3))
    grid[:, 0] = np.tile(np.arange(cols), rows) * square_size
    grid[:, 1] = np.repeat(np.arange(rows), cols) * square_size
    return grid


@dataclass(frozen=True)
class IntrinsicsCalibrationResult:
    """Camera matrix K, distortion (k1, k2, p1, p2, k3), RMS and per-view errors (pixels).

    ``metadata``: free-form provenance saved with the result (e.g. which simulated camera
    was calibrated, so that a user of the file can tell whether it fits their camera).
    ``tag_corners``: optional, the tag detector's corner offset and noise on this camera
    (:class:`estimation.corner_bias.CornerBiasFit` as a dict), measured after K.
    """

    K: np.ndarray
    dist: np.ndarray
    rms_reprojection_error: float
    per_view_errors: np.ndarray
    image_size: tuple[int, int]
    metadata: dict = field(default_factory=dict)
    tag_corners: dict | None = None
    camera_model: str = CAMERA_MODEL

    def require_camera(
        self,
        image_size: tuple[int, int],
        camera_model: str = CAMERA_MODEL,
        source: str = "the calibration",
        images: str = "the images",
    ) -> None:
        """Raise ``ValueError`` naming the mismatch when this calibration was made for
        another camera: another image size (width x height) or camera model."""
        problems = []
        if self.camera_model != camera_model:
            problems.append(f"camera model {self.camera_model!r}, not {camera_model!r}")
        if tuple(int(v) for v in image_size) != tuple(self.image_size):
            w, h = self.image_size
            problems.append(
                f"image size {w}x{h}, but {images} are {int(image_size[0])}x{int(image_size[1])}"
            )
        if problems:
            raise ValueError(f"{source} is for another camera: {'; '.join(problems)}")

    def to_intrinsics(self) -> CameraIntrinsics:
        """The result as the project's :class:`CameraIntrinsics`."""
        k = self.K
        d = np.zeros(5)
        d[: min(5, len(self.dist))] = self.dist[:5]
        return CameraIntrinsics(
            width=int(self.image_size[0]),
            height=int(self.image_size[1]),
            fx=float(k[0, 0]),
            fy=float(k[1, 1]),
            cx=float(k[0, 2]),
            cy=float(k[1, 2]),
            dist=tuple(float(x) for x in d),  # type: ignore[arg-type]
        )

    def save(self, path: str | Path) -> None:
        """Write the result as JSON."""
        doc = {
            "format": _FORMAT,
            "format_version": FORMAT_VERSION,
            "camera_model": self.camera_model,
            "image_size": list(self.image_size),
            "camera_matrix": self.K.tolist(),
            "dist": self.dist.tolist(),
            "rms_reprojection_error_px": self.rms_reprojection_error,
            "per_view_errors_px": self.per_view_errors.tolist(),
            "metadata": self.metadata,
        }
        if self.tag_corners is not None:
            doc["tag_corners"] = self.tag_corners
        Path(path).write_text(json.dumps(doc, indent=1))

    @classmethod
    def load(cls, path: str | Path) -> IntrinsicsCalibrationResult:
        """Read a result written by :meth:`save`."""
        doc = read_document(path, _FORMAT, _READABLE_VERSIONS, "camera-intrinsics file")
        model = doc.get("camera_model", CAMERA_MODEL)
        if model != CAMERA_MODEL:
            raise ValueError(f"{path}: camera_model {model!r} is unknown; known: {CAMERA_MODEL}")
        return cls(
            K=np.asarray(doc["camera_matrix"], dtype=float),
            dist=np.asarray(doc["dist"], dtype=float),
            rms_reprojection_error=float(doc["rms_reprojection_error_px"]),
            per_view_errors=np.asarray(doc["per_view_errors_px"], dtype=float),
            image_size=(int(doc["image_size"][0]), int(doc["image_size"][1])),
            metadata=dict(doc.get("metadata", {})),
            tag_corners=dict(doc["tag_corners"]) if "tag_corners" in doc else None,
            camera_model=model,
        )


def calibrate(
    corners: Sequence[np.ndarray],
    image_size: tuple[int, int],
    square_size: float,
    pattern: tuple[int, int] = (7, 10),
    flags: int = 0,
) -> IntrinsicsCalibrationResult:
    """Calibrate from per-view chessboard corners with ``cv2.calibrateCamera``.

    ``corners``: one (N, 2) array per view, in ``findChessboardCorners`` order;
    ``image_size``: (width, height); ``square_size``: metres; ``flags``: OpenCV
    ``CALIB_*`` flags (default: full k1, k2, p1, p2, k3 model).
    """
    object_points = chessboard_object_points(pattern, square_size).astype(np.float32)
    n = len(object_points)
    views = [np.asarray(c, dtype=np.float32).reshape(-1, 1, 2) for c in corners]
    if len(views) < 3:
        raise ValueError(f"need at least 3 views, got {len(views)}")
    for i, v in enumerate(views):
        if len(v) != n:
            raise ValueError(f"view {i} has {len(v)} corners; pattern {pattern} has {n}")
    rms, k, dist, _, _, _, _, per_view = cv2.calibrateCameraExtended(  # type: ignore[call-overload]
        [object_points] * len(views), views, tuple(image_size), None, None, flags=flags
    )
    return IntrinsicsCalibrationResult(
        K=np.asarray(k, dtype=float),
        dist=np.asarray(dist, dtype=float).reshape(-1),
        rms_reprojection_error=float(rms),
        per_view_errors=np.asarray(per_view, dtype=float).reshape(-1),
        image_size=(int(image_size[0]), int(image_size[1])),
    )


@dataclass(frozen=True)
class PhotoCalibration:
    """A calibration from photos: the result, the photos used and those rejected with why."""

    result: IntrinsicsCalibrationResult
    used: tuple[str, ...]
    rejected: tuple[tuple[str, str], ...]


def image_files(folder: str | Path) -> list[Path]:
    """The image files of a folder (by :data:`IMAGE_SUFFIXES`), sorted by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder")
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)


def calibrate_from_images(
    paths: Sequence[str | Path],
    pattern: tuple[int, int],
    square_size: float,
    flags: int = 0,
) -> PhotoCalibration:
    """Calibrate from chessboard photos: every photo is read in grey, its board found and
    refined (:func:`find_chessboard`); a photo that cannot be read, whose size differs from
    the first readable photo's or whose board is not found is rejected with the reason.
    ``ValueError`` when fewer than 3 photos remain."""
    if not square_size > 0.0 or not np.isfinite(square_size):
        raise ValueError(f"square size must be a positive number of metres, got {square_size}")
    if len(pattern) != 2 or min(pattern) < 2:
        raise ValueError(f"pattern must be COLSxROWS inner corners, each >= 2, got {pattern}")
    corners, used, rejected = [], [], []
    size: tuple[int, int] | None = None
    for path in paths:
        name = Path(path).name
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if grey is None:
            rejected.append((name, "cannot be read as an image"))
            continue
        this_size = (int(grey.shape[1]), int(grey.shape[0]))
        if size is None:
            size = this_size
        elif this_size != size:
            rejected.append(
                (name, f"size {this_size[0]}x{this_size[1]} differs from {size[0]}x{size[1]}")
            )
            continue
        found = find_chessboard(grey, pattern)
        if found is None:
            rejected.append((name, f"no {pattern[0]}x{pattern[1]} chessboard found"))
            continue
        corners.append(found)
        used.append(name)
    if len(corners) < 3 or size is None:
        reasons = "; ".join(f"{n}: {r}" for n, r in rejected) or "no image files"
        raise ValueError(f"need at least 3 usable photos, got {len(corners)} ({reasons})")
    result = calibrate(corners, size, square_size, pattern, flags)
    metadata = {
        "source": "photos",
        "pattern": list(pattern),
        "square_size_m": float(square_size),
        "photos_used": used,
        "photos_rejected": [{"photo": n, "reason": r} for n, r in rejected],
    }
    result = replace(result, metadata=metadata)
    return PhotoCalibration(result=result, used=tuple(used), rejected=tuple(rejected))
