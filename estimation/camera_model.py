"""Pinhole camera model with OpenCV's radial-tangential distortion."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import cv2
import numpy as np


@dataclass(frozen=True)
class CameraIntrinsics:
    """Intrinsics in OpenCV's convention (pixel centres at integers, distortion k1 k2 p1 p2 k3)."""

    width: int = 512
    height: int = 512
    fx: float = 458.5
    fy: float = 457.855
    cx: float = 255.5
    cy: float = 255.5
    dist: tuple[float, float, float, float, float] = field(default=(0.0, 0.0, 0.0, 0.0, 0.0))

    def as_dict(self) -> dict:
        """The model as plain data (the ``camera`` entry of the calibration files)."""
        return {**asdict(self), "dist": list(self.dist)}

    @classmethod
    def from_dict(cls, data: dict, where: str = "camera") -> CameraIntrinsics:
        """The model from :meth:`as_dict`'s data; ``ValueError`` naming ``where`` and the key
        when one is missing or not a number."""
        try:
            dist = tuple(float(d) for d in data.get("dist", (0.0,) * 5))
            camera = cls(
                width=int(data["width"]),
                height=int(data["height"]),
                fx=float(data["fx"]),
                fy=float(data["fy"]),
                cx=float(data["cx"]),
                cy=float(data["cy"]),
                dist=(*dist, 0.0, 0.0, 0.0, 0.0, 0.0)[:5],  # type: ignore[arg-type]
            )
        except KeyError as exc:
            raise ValueError(f"{where}: missing key {exc.args[0]!r}") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise ValueError(f"{where}: not a camera model ({exc})") from None
        if len(dist) > 5:
            raise ValueError(f"{where}.dist: {len(dist)} values; at most 5 (k1 k2 p1 p2 k3)")
        if camera.width < 1 or camera.height < 1 or not camera.fx > 0.0 or not camera.fy > 0.0:
            raise ValueError(f"{where}: need width, height >= 1 px and fx, fy > 0")
        return camera

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=float)

    @property
    def has_distortion(self) -> bool:
        return any(d != 0.0 for d in self.dist)

    def project(self, points_c: np.ndarray, distort: bool = True) -> np.ndarray:
        """Project Nx3 points in the camera frame to Nx2 pixels (NaN behind the camera)."""
        points_c = np.atleast_2d(np.asarray(points_c, dtype=float))
        pixels = np.full((len(points_c), 2), np.nan)
        in_front = points_c[:, 2] > 1e-9
        if not in_front.any():
            return pixels
        if distort and self.has_distortion:
            projected, _ = cv2.projectPoints(
                points_c[in_front], np.zeros(3), np.zeros(3), self.matrix, self.dist_coeffs
            )
            pixels[in_front] = projected.reshape(-1, 2)
        else:
            normalised = points_c[in_front, :2] / points_c[in_front, 2:3]
            pixels[in_front, 0] = self.fx * normalised[:, 0] + self.cx
            pixels[in_front, 1] = self.fy * normalised[:, 1] + self.cy
        return pixels

    def half_view_tan(self) -> float:
        """The tangent of the narrowest half field of view: from the optical axis to the
        nearest image edge (its midpoint, the lens distortion removed), along the image axes.
        A point whose normalised coordinates are within it on both axes is in the image."""
        last_u, last_v = self.width - 1.0, self.height - 1.0
        edges = np.array([[0.0, self.cy], [last_u, self.cy], [self.cx, 0.0], [self.cx, last_v]])
        ideal = self.undistort_pixels(edges)
        tangents = np.concatenate(
            [np.abs(ideal[:2, 0] - self.cx) / self.fx, np.abs(ideal[2:, 1] - self.cy) / self.fy]
        )
        return float(np.min(tangents))

    def undistort_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Remove lens distortion from Nx2 pixels (returns pixels of the ideal pinhole)."""
        pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
        if not self.has_distortion:
            return pixels.copy()
        undistorted = cv2.undistortPoints(
            pixels.reshape(-1, 1, 2), self.matrix, self.dist_coeffs, P=self.matrix
        )
        return undistorted.reshape(-1, 2)
