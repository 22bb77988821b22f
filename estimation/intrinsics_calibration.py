"""Chessboard intrinsic calibration (CRHF Sec. 2.1–2.2) with OpenCV.

``pattern`` is OpenCV's ``patternSize``: inner corners per row, inner corners per column
(CRHF uses a 7 x 10-corner board).  Corners are in OpenCV pixels (pixel centres at integers).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from estimation.camera_model import CameraIntrinsics

_FORMAT = "deck-landing/camera-intrinsics"
_VERSION = 1


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
            "version": _VERSION,
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
        doc = json.loads(Path(path).read_text())
        if doc.get("format") != _FORMAT:
            raise ValueError(f"{path}: not a camera-intrinsics file")
        if doc.get("version") != _VERSION:
            raise ValueError(f"{path}: unsupported version {doc.get('version')!r}")
        return cls(
            K=np.asarray(doc["camera_matrix"], dtype=float),
            dist=np.asarray(doc["dist"], dtype=float),
            rms_reprojection_error=float(doc["rms_reprojection_error_px"]),
            per_view_errors=np.asarray(doc["per_view_errors_px"], dtype=float),
            image_size=(int(doc["image_size"][0]), int(doc["image_size"][1])),
            metadata=dict(doc.get("metadata", {})),
            tag_corners=dict(doc["tag_corners"]) if "tag_corners" in doc else None,
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
