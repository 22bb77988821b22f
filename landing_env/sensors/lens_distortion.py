"""Lens distortion on rendered images: the warp from the ideal (pinhole) image to the
distorted one, and the radius beyond which the distortion polynomial folds back.
"""

from __future__ import annotations

import cv2
import numpy as np

from estimation.camera_model import CameraIntrinsics


class DistortionWarp:
    """Where each pixel of the distorted image comes from in the ideal (pinhole) image.

    Each distorted pixel looks up its ideal position (cv2.undistortPoints, iterated to
    convergence).  Barrel distortion needs ideal pixels beyond the image; any window of the
    ideal image plane can be rendered (negative coordinates included), so none is lost.  Only
    ideal pixels more than one image size beyond the image are left out (black): a lens that
    maps those into the image is far outside this model's use.
    """

    def __init__(self, intrinsics: CameraIntrinsics) -> None:
        w, h = intrinsics.width, intrinsics.height
        self.limits = (-w, -h, 2 * w, 2 * h)
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        ideal = cv2.undistortPoints(
            grid.astype(np.float64),
            intrinsics.matrix,
            intrinsics.dist_coeffs,
            P=intrinsics.matrix,
            criteria=criteria,
        ).reshape(h, w, 2)
        #: ideal-image coordinates of every distorted pixel
        self.map_x = ideal[..., 0].astype(np.float32)
        self.map_y = ideal[..., 1].astype(np.float32)

    def source_window(self, x0: int, y0: int, x1: int, y1: int) -> tuple[int, int, int, int]:
        """The ideal-image window (x0, y0, x1, y1) that the distorted window needs."""
        mx = self.map_x[y0:y1, x0:x1]
        my = self.map_y[y0:y1, x0:x1]
        lx0, ly0, lx1, ly1 = self.limits
        # one extra pixel each side for bilinear interpolation
        return (
            int(np.clip(np.floor(mx.min()) - 1, lx0, lx1 - 2)),
            int(np.clip(np.floor(my.min()) - 1, ly0, ly1 - 2)),
            int(np.clip(np.ceil(mx.max()) + 2, lx0 + 2, lx1)),
            int(np.clip(np.ceil(my.max()) + 2, ly0 + 2, ly1)),
        )

    def warp(
        self,
        source: np.ndarray,
        source_origin: tuple[int, int],
        window: tuple[int, int, int, int],
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """The distorted ``window`` (x0, y0, x1, y1) from an ideal render starting at origin
        (into ``out`` when given, of the window's shape and the source's type)."""
        x0, y0, x1, y1 = window
        sx, sy = source_origin
        return cv2.remap(
            source,
            self.map_x[y0:y1, x0:x1] - np.float32(sx),
            self.map_y[y0:y1, x0:x1] - np.float32(sy),
            dst=out,
            interpolation=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )


def max_monotonic_radius(dist: np.ndarray) -> float:
    """Largest normalised radius up to which the radial distortion keeps increasing.

    Beyond it the polynomial folds back and far-off points would project into the image.
    """
    k1, k2, _, _, k3 = dist
    radii = np.linspace(0.0, 10.0, 20001)
    r2 = radii**2
    derivative = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2**2 + 7.0 * k3 * r2**3
    bad = np.nonzero(derivative <= 0.0)[0]
    return float(radii[bad[0]]) if bad.size else float("inf")
