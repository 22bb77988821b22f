"""Camera frames drawn for people: a frame's tag outlines, corners, ids and miss reason."""

from __future__ import annotations

import cv2
import numpy as np

from estimation.types import CameraFrame


def draw_detections(image: np.ndarray, frame: CameraFrame) -> np.ndarray:
    """A copy of ``image`` (RGB) with the frame's tag outlines, corner 0 and ids drawn."""
    canvas = np.ascontiguousarray(image[..., :3], dtype=np.uint8).copy()
    shift = 4  # fixed-point bits so the sub-pixel corners are drawn where they are
    scale = 1 << shift
    for detection in frame.detections:
        corners = np.asarray(detection.corners_px, dtype=float)
        if not np.all(np.isfinite(corners)):
            continue
        points = np.rint(corners * scale).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(canvas, [points], True, (0, 255, 0), 2, cv2.LINE_AA, shift)
        colours = ((255, 0, 0), (0, 255, 255), (255, 0, 255), (0, 0, 255))
        for point, colour in zip(points[:, 0], colours, strict=True):
            cv2.circle(
                canvas, tuple(int(c) for c in point), 4 * scale, colour, 2, cv2.LINE_AA, shift
            )
        # label above the tag so it does not hide the corners
        left, top = corners.min(axis=0)
        cv2.putText(
            canvas,
            f"id {detection.tag_id}",
            (int(left), max(int(top) - 8, 12)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5,
            (255, 64, 64),
            1,
            cv2.LINE_AA,
        )
    if frame.miss_reason:
        cv2.putText(
            canvas,
            frame.miss_reason,
            (8, 20),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.6,
            (255, 0, 0),
            2,
            cv2.LINE_AA,
        )
    return canvas
