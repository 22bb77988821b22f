"""Small geometric building blocks shared by the estimators.

Every fitting function returns ``None`` for degenerate input (coincident or collinear points,
a singular system, non-finite values) instead of raising, so that an estimator can turn it
into an invalid estimate with a reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from estimation.camera_model import CameraIntrinsics

#: Relative singular-value floor below which a fit is treated as degenerate.
_RANK_TOL = 1e-9
_SQRT2 = float(np.sqrt(2.0))

PLANE_METHODS = ("lstsq", "cross3")


@dataclass(frozen=True)
class PlaneFit:
    """A plane ``normal · p = offset`` in the camera frame with ``normal[2] > 0``.

    ``rms_residual`` (metres) is the RMS of the points' residuals along z (the ToF sensors'
    axis, along which their errors lie); with four points and three plane parameters it
    exposes one corrupted range: on a square layout an error e leaves e/4 on every point.
    """

    normal: np.ndarray
    offset: float
    rms_residual: float

    def z_at(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Z of the plane above (x, y) in the camera frame (IHRCF Eq. 22)."""
        n = self.normal
        return (self.offset - n[0] * np.asarray(x) - n[1] * np.asarray(y)) / n[2]


@dataclass(frozen=True)
class RigidFit:
    """``measured ≈ rotation @ model + translation``, with the RMS residual in metres."""

    rotation: np.ndarray
    translation: np.ndarray
    rms_residual: float


def fit_plane(points: np.ndarray, method: str = "lstsq") -> PlaneFit | None:
    """Fit a plane to Nx3 points (N >= 3); ``None`` if their (x, y) are (nearly) collinear.

    ``"lstsq"``: least squares in z, ``z = a x + b y + c``, over all points.  The ToF touch
    points' (x, y) are the sensors' known positions and only their z (the range) is
    measured, so this is the maximum-likelihood plane; unlike a total-least-squares fit it
    does not tilt towards a gross range error and hide it in a small residual.
    ``"cross3"``: the papers' normal from the first three points,
    ``n = (p1 - p2) × (p2 - p3)`` (IHRCF Eq. 20, CRHF Eq. 25), with the offset averaged over
    all points (CRHF: "d ... by averaging all the sensors' values").
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 3:
        return None
    if not np.all(np.isfinite(points)):
        return None
    if method == "lstsq":
        design = np.column_stack([points[:, :2], np.ones(len(points))])
        coef, _, rank, sing = np.linalg.lstsq(design, points[:, 2], rcond=None)
        if rank < 3 or sing[2] <= _RANK_TOL * sing[0]:
            return None
        normal = np.array([-coef[0], -coef[1], 1.0])
        norm = float(np.linalg.norm(normal))
        normal = normal / norm
        offset = float(coef[2]) / norm
    elif method == "cross3":
        xy = points[:3, :2]
        span = float(np.max(np.abs(xy - xy.mean(axis=0))))
        normal = np.cross(points[0] - points[1], points[1] - points[2])
        if normal[2] < 0.0:
            normal = -normal
        # n_z is twice the area of the three points' (x, y) triangle: zero when collinear
        if span == 0.0 or normal[2] <= _RANK_TOL * span * span:
            return None
        normal = normal / float(np.linalg.norm(normal))
        offset = float(np.mean(points @ normal))
    else:
        raise ValueError(f"plane method {method!r} is not one of {PLANE_METHODS}")
    z_plane = (offset - points[:, :2] @ normal[:2]) / normal[2]
    rms = float(np.sqrt(np.mean((points[:, 2] - z_plane) ** 2)))
    return PlaneFit(normal=normal, offset=offset, rms_residual=rms)


def plane_of_ranges(sensors_c: np.ndarray, ranges: np.ndarray) -> PlaneFit | None:
    """The least-squares plane of ToF ranges: sensor i's touch point lies ``ranges[i]``
    along the camera's axis from its origin ``sensors_c[i]`` (C), whatever the deck's tilt;
    ``None`` as :func:`fit_plane` gives it (fewer than three sites, collinear, not finite)."""
    touch = np.array(sensors_c, dtype=float)
    touch[:, 2] += ranges
    return fit_plane(touch, "lstsq")


class ZPlaneFitter:
    """Least-squares planes ``z = a x + b y + c`` over fixed (x, y) sites (the ToF sensors).

    The same fit as ``fit_plane(points, "lstsq")`` with the pseudo-inverse of the design
    matrix computed once, since the sensors' (x, y) never change.
    """

    def __init__(self, xy: np.ndarray) -> None:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        design = np.column_stack([xy, np.ones(len(xy))])
        sing = np.linalg.svd(design, compute_uv=False)
        if len(xy) < 3 or sing[2] <= _RANK_TOL * sing[0]:
            raise ValueError("the (x, y) sites are collinear: they do not fix a plane")
        self._pinv = np.linalg.pinv(design)
        # plain floats for the per-frame fit: with a handful of sites it is all call overhead
        self._pinv_rows = [row.tolist() for row in self._pinv]
        self._sites = xy.tolist()

    def fit(self, z: np.ndarray) -> PlaneFit | None:
        """The plane through heights ``z`` at the sites; ``None`` if z is not finite."""
        zs = np.asarray(z, dtype=float).reshape(-1).tolist()
        if len(zs) != len(self._sites) or not all(map(math.isfinite, zs)):
            return None
        a, b, c = (
            math.fsum(p * v for p, v in zip(row, zs, strict=True)) for row in self._pinv_rows
        )
        squares = math.fsum(
            (v - (x * a + y * b + c)) ** 2 for (x, y), v in zip(self._sites, zs, strict=True)
        )
        norm = math.sqrt(a * a + b * b + 1.0)
        return PlaneFit(
            normal=np.array([-a / norm, -b / norm, 1.0 / norm]),
            offset=c / norm,
            rms_residual=math.sqrt(squares / len(zs)),
        )


def _normalise(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Hartley normalisation: (normalised points, centroid, scale), mean distance sqrt(2)."""
    centroid = points.mean(axis=0)
    centred = points - centroid
    mean_dist = float(np.sqrt((centred * centred).sum(axis=1)).mean())
    if not np.isfinite(mean_dist) or mean_dist <= 0.0:
        return None
    scale = _SQRT2 / mean_dist
    return centred * scale, centroid, scale


def _normalised_floats(points: np.ndarray) -> tuple[list[float], list[float], float, float, float]:
    """Hartley normalisation of four points in plain floats: (xs, ys, cx, cy, scale)."""
    px = points[:, 0].tolist()
    py = points[:, 1].tolist()
    cx = sum(px) / 4.0
    cy = sum(py) / 4.0
    mean_dist = sum(math.hypot(x - cx, y - cy) for x, y in zip(px, py, strict=True)) / 4.0
    scale = _SQRT2 / mean_dist if mean_dist > 0.0 else 0.0
    return [(x - cx) * scale for x in px], [(y - cy) * scale for y in py], cx, cy, scale


def _three_collinear(xs: list[float], ys: list[float]) -> bool:
    """True if any three of four (normalised) points are (nearly) collinear."""
    for k in range(4):
        i, j = (k + 1) % 4, (k + 2) % 4
        # twice the area of triangle (k, k+1, k+2); the four cover all triples
        area = (xs[i] - xs[k]) * (ys[j] - ys[k]) - (ys[i] - ys[k]) * (xs[j] - xs[k])
        if abs(area) <= 1e-9:
            return True
    return False


def _homography_four(src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """Normalised DLT for exactly four pairs, as an 8x8 linear system with h33 = 1.

    Four pairs fix a unique, non-singular H iff no three points of either set are
    collinear; h33 = 1 is then safe in normalised coordinates unless the source centroid
    maps to infinity, for which ``None`` sends the caller to the SVD path.  Plain floats
    keep this the cheap IHRCF hot path.
    """
    xs, ys, csx, csy, ss = _normalised_floats(src)
    xd, yd, cdx, cdy, sd = _normalised_floats(dst)
    if ss == 0.0 or sd == 0.0 or _three_collinear(xs, ys) or _three_collinear(xd, yd):
        return None
    rows: list[list[float]] = []
    rhs: list[float] = []
    for x, y, u, v in zip(xs, ys, xd, yd, strict=True):
        rows.append([x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y])
        rows.append([0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y])
        rhs.extend((u, v))
    try:
        h8 = np.linalg.solve(np.array(rows), np.array(rhs))
    except np.linalg.LinAlgError:
        return None
    h_norm = np.append(h8, 1.0).reshape(3, 3)
    t_src = np.array([[ss, 0.0, -ss * csx], [0.0, ss, -ss * csy], [0.0, 0.0, 1.0]])
    t_dst_inv = np.array([[1.0 / sd, 0.0, cdx], [0.0, 1.0 / sd, cdy], [0.0, 0.0, 1.0]])
    return t_dst_inv @ h_norm @ t_src


def homography_dlt(src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """Normalised DLT homography ``dst ~ H src`` from N >= 4 point pairs (Nx2 each).

    Returns H scaled so that its Frobenius norm is 1 and ``H[2, 2] >= 0``, or ``None`` when
    the correspondences do not determine a non-singular homography (three collinear points,
    coincident points, non-finite values).  Four pairs are solved exactly as an 8x8 linear
    system; more pairs by the SVD of the 2N x 9 DLT matrix.
    """
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 2 or len(src) < 4:
        return None
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        return None
    if len(src) == 4:
        h = _homography_four(src, dst)
        if h is not None:
            return _canonical_homography(h)
        if _degenerate_four(src) or _degenerate_four(dst):
            return None
    ns = _normalise(src)
    nd = _normalise(dst)
    if ns is None or nd is None:
        return None
    xs, c_src, s_src = ns
    xd, c_dst, s_dst = nd
    n = len(src)
    a = np.zeros((2 * n, 9))
    x, y = xs[:, 0], xs[:, 1]
    # the rows of u (even) and v (odd): (x, y, 1) in columns 0-2 or 3-5, -w (x, y, 1) in 6-8
    for row, w in enumerate((xd[:, 0], xd[:, 1])):
        a[row::2, 3 * row] = x
        a[row::2, 3 * row + 1] = y
        a[row::2, 3 * row + 2] = 1.0
        a[row::2, 6] = -w * x
        a[row::2, 7] = -w * y
        a[row::2, 8] = -w
    _, sing, vt = np.linalg.svd(a)
    # rank 8 is needed for a unique H; degenerate configurations drop the 8th value
    if sing[7] <= _RANK_TOL * sing[0]:
        return None
    h_norm = vt[-1].reshape(3, 3)
    # undo the normalisations: H = T_dst⁻¹ H_norm T_src, with T(p) = s (p - c)
    t_src = np.array([[s_src, 0.0, -s_src * c_src[0]], [0.0, s_src, -s_src * c_src[1]], [0, 0, 1]])
    t_dst_inv = np.array([[1.0 / s_dst, 0.0, c_dst[0]], [0.0, 1.0 / s_dst, c_dst[1]], [0, 0, 1]])
    return _canonical_homography(t_dst_inv @ h_norm @ t_src)


def _degenerate_four(points: np.ndarray) -> bool:
    xs, ys, _, _, scale = _normalised_floats(points)
    return scale == 0.0 or _three_collinear(xs, ys)


def _canonical_homography(h: np.ndarray) -> np.ndarray | None:
    """Scale H to unit Frobenius norm with ``H[2, 2] >= 0``; ``None`` if singular/non-finite."""
    norm = math.sqrt(float((h * h).sum()))
    if not math.isfinite(norm) or norm == 0.0:
        return None
    h = h / (norm if h[2, 2] >= 0.0 else -norm)
    # |det| of a unit-norm 3x3 is at most 3^-1.5; far below that the map is singular
    det = (
        h[0, 0] * (h[1, 1] * h[2, 2] - h[1, 2] * h[2, 1])
        - h[0, 1] * (h[1, 0] * h[2, 2] - h[1, 2] * h[2, 0])
        + h[0, 2] * (h[1, 0] * h[2, 1] - h[1, 1] * h[2, 0])
    )
    if abs(float(det)) <= _RANK_TOL:
        return None
    return h


def apply_homography(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map Nx2 points through H; points sent to infinity (w ≈ 0) become NaN."""
    points = np.asarray(points, dtype=float)
    mapped = points @ h[:, :2].T + h[:, 2]
    w = mapped[:, 2:3]
    at_infinity = np.abs(w[:, 0]) <= 1e-12 * np.abs(mapped).max(axis=1)
    if not at_infinity.any():
        return mapped[:, :2] / w
    with np.errstate(divide="ignore", invalid="ignore"):
        out = mapped[:, :2] / w
    out[at_infinity] = np.nan
    return out


def det3(m: np.ndarray) -> float:
    """Determinant of a 3x3 matrix in plain floats (np.linalg.det costs more than the sum)."""
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


class RigidFitter:
    """:func:`fit_rigid` against one fixed model (the tag), with the model side precomputed."""

    def __init__(self, model: np.ndarray) -> None:
        model = np.asarray(model, dtype=float)
        if model.ndim != 2 or model.shape[1] != 3 or len(model) < 3:
            raise ValueError("the model must be an Nx3 array with N >= 3")
        self._model = model
        self._centroid = model.mean(axis=0)
        self._centred_t = (model - self._centroid).T.copy()

    def fit(self, measured: np.ndarray) -> RigidFit | None:
        """``measured ≈ R @ model + t``; ``None`` for non-finite or collinear points."""
        measured = np.asarray(measured, dtype=float)
        if measured.shape != self._model.shape or not np.isfinite(measured).all():
            return None
        c_meas = measured.mean(axis=0)
        return _kabsch(
            self._centred_t @ (measured - c_meas), self._model, self._centroid, measured, c_meas
        )


def _kabsch(
    cov: np.ndarray,
    model: np.ndarray,
    c_model: np.ndarray,
    measured: np.ndarray,
    c_meas: np.ndarray,
) -> RigidFit | None:
    """Rotation from the cross-covariance by SVD with the reflection fix, then t and RMS."""
    u, sing, vt = np.linalg.svd(cov)
    if not np.isfinite(sing[0]) or sing[0] == 0.0 or sing[1] <= _RANK_TOL * sing[0]:
        return None
    rotation = vt.T @ u.T
    if det3(rotation) < 0.0:
        # the reflection fix: V diag(1, 1, -1) Uᵀ
        vt = vt * np.array([[1.0], [1.0], [-1.0]])
        rotation = vt.T @ u.T
    translation = c_meas - rotation @ c_model
    residual = measured - (model @ rotation.T + translation)
    rms = math.sqrt(float((residual * residual).sum()) / len(model))
    return RigidFit(rotation=rotation, translation=translation, rms_residual=rms)


def fit_rigid(model: np.ndarray, measured: np.ndarray) -> RigidFit | None:
    """Least-squares rigid transform with ``measured ≈ R @ model + t`` (Kabsch/Umeyama).

    CRHF Eq. 54–61: centroids, cross-covariance, SVD, and the reflection fix
    ``R = V diag(1, 1, sign(det(V Uᵀ))) Uᵀ`` so that R is always a proper rotation.  Planar
    point sets (the tag) are fine; collinear or coincident ones return ``None``.
    """
    model = np.asarray(model, dtype=float)
    measured = np.asarray(measured, dtype=float)
    if model.shape != measured.shape or model.ndim != 2 or model.shape[1] != 3:
        return None
    if len(model) < 3 or not (np.isfinite(model).all() and np.isfinite(measured).all()):
        return None
    c_model = model.mean(axis=0)
    c_meas = measured.mean(axis=0)
    cov = (model - c_model).T @ (measured - c_meas)
    return _kabsch(cov, model, c_model, measured, c_meas)


class Undistorter:
    """:func:`undistort_pixels` for one camera, with its matrices built once (per-frame use)."""

    def __init__(self, intrinsics: CameraIntrinsics, iterations: int = 50) -> None:
        self.active = intrinsics.has_distortion
        self._k = intrinsics.matrix
        self._dist = intrinsics.dist_coeffs
        self._criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-12)

    def __call__(self, pixels: np.ndarray) -> np.ndarray:
        """Ideal-pinhole pixels (N x 2) of the raw pixels (a copy when there is no distortion)."""
        pixels = np.asarray(pixels, dtype=float)
        if not self.active:
            return pixels.copy()
        out = cv2.undistortPoints(
            pixels.reshape(-1, 1, 2),
            self._k,
            self._dist,
            R=None,
            P=self._k,
            criteria=self._criteria,
        )
        return out.reshape(-1, 2)


def undistort_pixels(
    pixels: np.ndarray, intrinsics: CameraIntrinsics, iterations: int = 50
) -> np.ndarray:
    """Remove lens distortion from Nx2 pixels, returning ideal-pinhole pixels of the same K.

    Passes a tight stopping rule to ``cv2.undistortPoints``: its default stops after 5
    fixed-point iterations, which left 0.014 px near the image corners with k1 = -0.25
    (measured; 1e-12 px with this rule), enough to cost the noise-free estimators their
    exactness.
    """
    pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
    if not intrinsics.has_distortion:
        return pixels.copy()
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, 1e-12)
    k = intrinsics.matrix
    out = cv2.undistortPoints(
        pixels.reshape(-1, 1, 2), k, intrinsics.dist_coeffs, R=None, P=k, criteria=criteria
    )
    return out.reshape(-1, 2)
