"""ToF–camera calibration: where each range sensor's touch point appears in the image.

IHRCF Sec. 2.2 / CRHF Sec. 2.3: a coloured pad is centred under each sensor; at many
altitudes the pad is segmented in YCbCr (Table 1), its largest blob is closed with a convex
hull and its centroid is recorded with the sensor's range.  The samples give, per sensor, a
map range → pixel, looked up with PCHIP (the papers' choice) or with the hyperbola
``f(r) = a / r + c`` of CRHF Table 4.

Geometry: sensor i sits at ``s_i`` in the camera plane and measures along +z_C, so its
touch point is ``(s_ix, s_iy, r_i)`` whatever the deck's tilt, and its ideal pixel is
``u = fx s_ix / r + cx``, ``v = fy s_iy / r + cy``: exactly the hyperbola, with ``a = f s``
and ``c`` the principal point.  :meth:`TofCameraCalibration.exact` builds that analytic map
(through the lens distortion, if any) for tests and simulation.

The calibration file (JSON, ``format: deck-landing/tof-camera-calibration``,
``format_version: 2``):

* ``image_size``: [width, height] of the images the pads were found in (null when unknown);
* ``method`` (``pchip``, ``hyperbola`` or ``exact``) and ``out_of_range`` (``hyperbola`` or
  ``nan``): how the samples are looked up;
* ``sensors``: per sensor (in the order of the ranges, pads blue, green, yellow, red), its
  samples ``range_m``, ``u_px``, ``v_px`` (raw, distorted image pixels, OpenCV convention);
* ``metadata``: provenance: ``camera`` (the model the images came from), ``tof_mount_offsets_c``
  (the sensors in the camera frame), ``skipped`` (sensor-stages left out, by reason), ...;
* ``exact_model``: only for :meth:`TofCameraCalibration.exact` calibrations.

Version 1 files (``version: 1``, no ``image_size``) are still read.
:meth:`TofCameraCalibration.require_camera` refuses a file made for another image size.
"""

from __future__ import annotations

import json
import math
from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.interpolate import PchipInterpolator

from estimation.calibration_files import read_document
from estimation.camera_model import CameraIntrinsics
from estimation.errors import require_choice

#: Pad colour under sensor i (IHRCF Sec. 2.2: blue, green, yellow, red for ps1..ps4).
PAD_COLOURS: tuple[str, ...] = ("blue", "green", "yellow", "red")

#: IHRCF Table 1 thresholds, inclusive, as (Y, Cb, Cr) ranges in the BT.601 studio range of
#: the papers' Eq. 2 (MATLAB ``rgb2ycbcr``: Y in 16..235, chroma in 16..240).
YCBCR_THRESHOLDS: dict[str, tuple[tuple[float, float], ...]] = {
    "blue": ((0.0, 165.0), (139.0, 255.0), (0.0, 255.0)),
    "green": ((0.0, 255.0), (0.0, 155.0), (0.0, 90.0)),
    "yellow": ((103.0, 255.0), (0.0, 95.0), (0.0, 255.0)),
    "red": ((0.0, 160.0), (0.0, 255.0), (167.0, 255.0)),
}

LOOKUP_METHODS = ("pchip", "hyperbola", "exact")
OUT_OF_RANGE_POLICIES = ("hyperbola", "nan")
_FORMAT = "deck-landing/tof-camera-calibration"
#: the version :meth:`TofCameraCalibration.save` writes, and those it reads
FORMAT_VERSION = 2
_READABLE_VERSIONS = (1, 2)


def ycbcr_studio(image_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Y, Cb, Cr planes (float32) of an 8-bit RGB image in the papers' studio range.

    OpenCV's ``COLOR_RGB2YCrCb`` gives full-range values in the channel order Y, Cr, Cb;
    Table 1 was tuned on the studio-range values of Eq. 2, so the planes are rescaled.
    """
    image_rgb = np.asarray(image_rgb)
    if image_rgb.dtype != np.uint8 or image_rgb.ndim != 3 or image_rgb.shape[2] != 3:
        raise ValueError("image_rgb must be an HxWx3 uint8 RGB image")
    ycrcb = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2YCrCb).astype(np.float32)
    y = 16.0 + ycrcb[..., 0] * (219.0 / 255.0)
    cr = 128.0 + (ycrcb[..., 1] - 128.0) * (224.0 / 255.0)
    cb = 128.0 + (ycrcb[..., 2] - 128.0) * (224.0 / 255.0)
    return y, cb, cr


def _in_box(planes: tuple[np.ndarray, ...], colour: str) -> np.ndarray:
    mask = np.ones(planes[0].shape, dtype=bool)
    for plane, (low, high) in zip(planes, YCBCR_THRESHOLDS[colour], strict=True):
        mask &= (plane >= low) & (plane <= high)
    return mask


def segment_pad(image_rgb: np.ndarray, colour: str) -> np.ndarray:
    """Boolean mask of the pixels of one pad colour (IHRCF Table 1 thresholds).

    Table 1's yellow box also contains saturated green (Y ≈ 145, Cb ≈ 54, Cr ≈ 34 lies in
    it), so the yellow mask excludes pixels that pass the green test; the other pad colours
    do not overlap.
    """
    require_choice("colour", colour, PAD_COLOURS)
    planes = ycbcr_studio(image_rgb)
    mask = _in_box(planes, colour)
    if colour == "yellow":
        mask &= ~_in_box(planes, "green")
    return mask


def largest_blob_hull(mask: np.ndarray) -> tuple[np.ndarray, dict] | None:
    """The convex hull of the mask's largest blob (its outer contour) and the hull's moments;
    ``None`` for an empty mask.  The hull closes holes and notches (IHRCF Eq. 3–6); its
    centroid comes from the polygon's moments (the filled-hull mean of Eq. 7)."""
    mask8 = (np.asarray(mask) > 0).astype(np.uint8)
    contours, _ = cv2.findContours(mask8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    largest = max(contours, key=lambda c: (cv2.contourArea(c), len(c)))
    hull = cv2.convexHull(largest)
    return hull, cv2.moments(hull)


@dataclass(frozen=True)
class HyperbolaFit:
    """``value ≈ a / range + c`` (CRHF Table 4) with the fit's RMS residual (pixels)."""

    a: float
    c: float
    rms: float

    def __call__(self, ranges: np.ndarray | float) -> np.ndarray:
        return self.a / np.asarray(ranges, dtype=float) + self.c


def fit_hyperbola(ranges: np.ndarray, values: np.ndarray) -> HyperbolaFit:
    """Ordinary least-squares fit of ``values = a / ranges + c`` (linear in 1/r)."""
    ranges = np.asarray(ranges, dtype=float)
    values = np.asarray(values, dtype=float)
    design = np.column_stack([1.0 / ranges, np.ones_like(ranges)])
    (a, c), *_ = np.linalg.lstsq(design, values, rcond=None)
    rms = float(np.sqrt(np.mean((design @ np.array([a, c]) - values) ** 2)))
    return HyperbolaFit(a=float(a), c=float(c), rms=rms)


@dataclass(frozen=True)
class TouchPointLookup:
    """Touch-point pixels for the current ranges.

    ``out_of_range[i]``: range i lies outside sensor i's calibrated span; with the
    ``"hyperbola"`` policy its pixel is extrapolated (``valid`` stays True), with ``"nan"``
    it is NaN and ``valid[i]`` is False.
    """

    pixels: np.ndarray
    valid: np.ndarray
    out_of_range: np.ndarray

    @property
    def extrapolated(self) -> np.ndarray:
        return self.out_of_range & self.valid


@dataclass(frozen=True)
class _ExactModel:
    intrinsics: CameraIntrinsics
    tof_positions_c: np.ndarray


def _clean_samples(samples: np.ndarray) -> np.ndarray:
    """Drop non-finite rows, sort by range and average rows with equal ranges."""
    samples = np.asarray(samples, dtype=float).reshape(-1, 3)
    samples = samples[np.all(np.isfinite(samples), axis=1) & (samples[:, 0] > 0.0)]
    ranges, inverse, counts = np.unique(samples[:, 0], return_inverse=True, return_counts=True)
    merged = np.zeros((len(ranges), 3))
    merged[:, 0] = ranges
    for k in (1, 2):
        merged[:, k] = np.bincount(inverse, weights=samples[:, k]) / counts
    return merged


class _PiecewiseCubic:
    """Scalar evaluation of a (u, v)-valued PCHIP, without per-call array overhead.

    The interpolant is scipy's ``PchipInterpolator``; its cubic pieces are evaluated here in
    plain Python because four scalar look-ups per frame are dominated by call overhead.
    """

    def __init__(self, pchip: PchipInterpolator) -> None:
        self._knots = [float(x) for x in pchip.x]
        # c has shape (4, pieces, 2): per piece, the u and v cubic coefficients
        self._u = [tuple(float(c) for c in pchip.c[:, k, 0]) for k in range(pchip.c.shape[1])]
        self._v = [tuple(float(c) for c in pchip.c[:, k, 1]) for k in range(pchip.c.shape[1])]

    def __call__(self, r: float) -> tuple[float, float]:
        k = min(max(bisect_right(self._knots, r) - 1, 0), len(self._u) - 1)
        dx = r - self._knots[k]
        a, b, c, d = self._u[k]
        e, f, g, h = self._v[k]
        return ((a * dx + b) * dx + c) * dx + d, ((e * dx + f) * dx + g) * dx + h


class TofCameraCalibration:
    """Per-sensor range → touch-point pixel maps.

    ``samples[i]`` is an (n_i, 3) array of (range m, u px, v px) for sensor i, in raw
    (distorted) image pixels as the pads are seen.  ``method`` picks the look-up:
    ``"pchip"`` (papers), ``"hyperbola"`` (CRHF Table 4 fit) or ``"exact"`` (the analytic
    map, only for calibrations built by :meth:`exact`).  ``out_of_range`` says what PCHIP
    does outside a sensor's calibrated span: ``"hyperbola"`` extrapolates with the fit and
    flags it, ``"nan"`` returns NaN.  ``image_size``: (width, height) of the images the
    pads were found in (``None`` when unknown).
    """

    def __init__(
        self,
        samples: Sequence[np.ndarray],
        *,
        method: str = "pchip",
        out_of_range: str = "hyperbola",
        metadata: dict | None = None,
        exact_model: _ExactModel | None = None,
        image_size: tuple[int, int] | None = None,
    ) -> None:
        require_choice("method", method, LOOKUP_METHODS)
        require_choice("out_of_range", out_of_range, OUT_OF_RANGE_POLICIES)
        if method == "exact" and exact_model is None:
            raise ValueError(
                "method 'exact' needs a calibration built by TofCameraCalibration.exact"
            )
        cleaned = [_clean_samples(s) for s in samples]
        for i, s in enumerate(cleaned):
            if len(s) < 2:
                raise ValueError(f"sensor {i} has {len(s)} usable samples; at least 2 are needed")
        self.samples: tuple[np.ndarray, ...] = tuple(cleaned)
        self.method = method
        self.out_of_range = out_of_range
        self.metadata: dict = dict(metadata or {})
        self._exact = exact_model
        if image_size is None and exact_model is not None:
            image_size = (exact_model.intrinsics.width, exact_model.intrinsics.height)
        self.image_size = None if image_size is None else (int(image_size[0]), int(image_size[1]))
        self._pchip = [
            _PiecewiseCubic(PchipInterpolator(s[:, 0], s[:, 1:], axis=0)) for s in cleaned
        ]
        self.hyperbola_u = tuple(fit_hyperbola(s[:, 0], s[:, 1]) for s in cleaned)
        self.hyperbola_v = tuple(fit_hyperbola(s[:, 0], s[:, 2]) for s in cleaned)
        self._low = np.array([s[0, 0] for s in cleaned])
        self._high = np.array([s[-1, 0] for s in cleaned])

    @property
    def n_sensors(self) -> int:
        return len(self.samples)

    @property
    def range_span(self) -> np.ndarray:
        """(n_sensors, 2) calibrated (min, max) range per sensor, metres."""
        return np.column_stack([self._low, self._high])

    def with_method(self, method: str, out_of_range: str | None = None) -> TofCameraCalibration:
        """The same samples looked up another way."""
        return TofCameraCalibration(
            self.samples,
            method=method,
            out_of_range=self.out_of_range if out_of_range is None else out_of_range,
            metadata=self.metadata,
            exact_model=self._exact,
            image_size=self.image_size,
        )

    def require_camera(
        self,
        image_size: tuple[int, int],
        source: str = "the ToF-camera calibration",
        images: str = "the images",
    ) -> None:
        """Raise ``ValueError`` naming the mismatch when this calibration's pixels are of
        another image size (width x height); a file that does not say passes."""
        if self.image_size is None:
            return
        w, h = (int(v) for v in image_size)
        if (w, h) != self.image_size:
            cw, ch = self.image_size
            raise ValueError(
                f"{source} is for another camera: image size {cw}x{ch}, but {images} are {w}x{h}"
            )

    def lookup(self, ranges: np.ndarray) -> TouchPointLookup:
        """Touch-point pixels (n_sensors x 2, raw image pixels) for the sensors' ranges."""
        ranges = np.asarray(ranges, dtype=float).reshape(-1)
        n = self.n_sensors
        pixels = np.full((n, 2), np.nan)
        if len(ranges) != n:
            return TouchPointLookup(pixels, np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
        usable = np.isfinite(ranges) & (ranges > 0.0)
        out_of_range = usable & ((ranges < self._low) | (ranges > self._high))
        if self.method == "exact":
            assert self._exact is not None
            points = np.zeros((n, 3))
            points[:, :2] = self._exact.tof_positions_c[:, :2]
            points[:, 2] = np.where(usable, ranges, 1.0)
            projected = self._exact.intrinsics.project(points)
            pixels[usable] = projected[usable]
            valid = usable & np.all(np.isfinite(pixels), axis=1)
            # the analytic map holds at every range: nothing is extrapolated
            return TouchPointLookup(pixels, valid, np.zeros(n, dtype=bool))
        # per-sensor scalar work in plain floats: four look-ups are all call overhead
        rows: list[tuple[float, float]] = []
        flags = out_of_range.tolist()
        for i, (r, ok) in enumerate(zip(ranges.tolist(), usable.tolist(), strict=True)):
            if not ok:
                rows.append((math.nan, math.nan))
            elif self.method == "pchip" and not flags[i]:
                rows.append(self._pchip[i](r))
            elif self.method == "hyperbola" or self.out_of_range == "hyperbola":
                hu, hv = self.hyperbola_u[i], self.hyperbola_v[i]
                rows.append((hu.a / r + hu.c, hv.a / r + hv.c))
            else:
                rows.append((math.nan, math.nan))
        pixels = np.array(rows)
        valid = usable & np.isfinite(pixels).all(axis=1)
        return TouchPointLookup(pixels, valid, out_of_range)

    @classmethod
    def from_measurements(
        cls, ranges: np.ndarray, pixels: np.ndarray, **kwargs: object
    ) -> TofCameraCalibration:
        """Build from calibration frames: ranges (n, k), pad centroids (n, k, 2); NaN = missed."""
        ranges = np.asarray(ranges, dtype=float)
        pixels = np.asarray(pixels, dtype=float)
        if ranges.ndim != 2 or pixels.shape != (*ranges.shape, 2):
            raise ValueError("ranges must be (n, k) and pixels (n, k, 2)")
        samples = [np.column_stack([ranges[:, i], pixels[:, i]]) for i in range(ranges.shape[1])]
        return cls(samples, **kwargs)  # type: ignore[arg-type]

    @classmethod
    def exact(
        cls,
        intrinsics: CameraIntrinsics,
        tof_positions_c: np.ndarray,
        r_min: float,
        r_max: float,
        n_samples: int = 120,
    ) -> TofCameraCalibration:
        """The analytic calibration: touch point ``(s_x, s_y, r)`` projected by the camera.

        Its samples (``n_samples`` ranges from ``r_min`` to ``r_max``) also allow the PCHIP
        and hyperbola look-ups for comparison (``with_method``).
        """
        if not 0.0 < r_min < r_max:
            raise ValueError(f"need 0 < r_min < r_max, got {r_min}, {r_max}")
        positions = np.asarray(tof_positions_c, dtype=float).reshape(-1, 3)
        ranges = np.linspace(r_min, r_max, n_samples)
        samples = []
        for s in positions:
            points = np.column_stack([np.full(n_samples, s[0]), np.full(n_samples, s[1]), ranges])
            samples.append(np.column_stack([ranges, intrinsics.project(points)]))
        metadata = {"source": "exact", "r_min": r_min, "r_max": r_max}
        return cls(
            samples,
            method="exact",
            metadata=metadata,
            exact_model=_ExactModel(intrinsics, positions.copy()),
        )

    def save(self, path: str | Path) -> None:
        """Write the samples, look-up settings and metadata as JSON."""
        doc: dict = {
            "format": _FORMAT,
            "format_version": FORMAT_VERSION,
            "image_size": None if self.image_size is None else list(self.image_size),
            "method": self.method,
            "out_of_range": self.out_of_range,
            "metadata": self.metadata,
            "sensors": [
                {"range_m": s[:, 0].tolist(), "u_px": s[:, 1].tolist(), "v_px": s[:, 2].tolist()}
                for s in self.samples
            ],
        }
        if self._exact is not None:
            doc["exact_model"] = {
                "intrinsics": self._exact.intrinsics.as_dict(),
                "tof_positions_c": self._exact.tof_positions_c.tolist(),
            }
        Path(path).write_text(json.dumps(doc, indent=1))

    @classmethod
    def load(cls, path: str | Path) -> TofCameraCalibration:
        """Read a calibration written by :meth:`save`."""
        doc = read_document(path, _FORMAT, _READABLE_VERSIONS, "ToF–camera calibration file")
        samples = [
            np.column_stack([s["range_m"], s["u_px"], s["v_px"]]).astype(float)
            for s in doc["sensors"]
        ]
        exact_model = None
        if "exact_model" in doc:
            intrinsics = CameraIntrinsics.from_dict(
                doc["exact_model"]["intrinsics"], f"{path}: exact_model.intrinsics"
            )
            positions = np.asarray(doc["exact_model"]["tof_positions_c"], dtype=float)
            exact_model = _ExactModel(intrinsics, positions)
        return cls(
            samples,
            method=doc["method"],
            out_of_range=doc["out_of_range"],
            metadata=doc.get("metadata", {}),
            exact_model=exact_model,
            image_size=_image_size(doc.get("image_size"), path),
        )


def _image_size(value: object, path: str | Path) -> tuple[int, int] | None:
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, int) and v > 0 for v in value)
    ):
        raise ValueError(f"{path}: image_size {value!r} must be [width, height] in pixels")
    return int(value[0]), int(value[1])
