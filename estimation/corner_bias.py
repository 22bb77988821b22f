"""The tag detector's systematic corner offset on a given camera, and its correction.

A real camera blurs the image in linear light (optics, demosaicing, resampling) and then
applies a gamma curve; at the edge of the tag's dark border the 50 % level the detector's
edge fit finds then lies inside the true edge, so the detected tag is *smaller* than the
tag: on the realistic camera, for a 70 px tag, by 0.09 px per edge for edges along the pixel
grid and 0.19 px for diagonal ones (blurring and demosaicing act over a wider footprint
across a diagonal edge), and by more on a smaller tag (the corners' rounding weighs more in
a shorter edge fit).  A chessboard calibration cannot see this (its saddle corners are
symmetric), but it matters: a 0.1 px shrink of a 70 px tag reads as a 3 mm longer distance
at 2 m, which the ToF ranges then contradict.

Model: each edge of the detected quadrilateral lies ``offset(edge)`` pixels outside the true
edge along its outward normal,

    offset = a + b * sin²(2 φ) + c / L

with φ the edge's angle to the image axes and ``L`` its length in pixels (``a, b, c`` in px,
px, px²).  A corner moves where its two shifted edges meet.  :func:`fit_corner_bias`
measures ``a, b, c`` from detections of a tag at known poses (the calibration rig,
``landing_env.calibration.tag_corner_sim``) and the residual noise of the corners after
the correction; :meth:`CornerBias.correct` removes the offset from detected corners.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


def _edge_terms(quad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per edge i (corner i to corner i+1): outward unit normal (4x2), sin²(2φ) and 1/L."""
    nxt = np.roll(quad, -1, axis=0)
    edge = nxt - quad
    length = np.linalg.norm(edge, axis=1)
    normal = np.column_stack([edge[:, 1], -edge[:, 0]]) / length[:, None]
    # outward: away from the quadrilateral's centre
    midpoint = 0.5 * (quad + nxt) - quad.mean(axis=0)
    normal *= np.where(np.sum(normal * midpoint, axis=1) < 0.0, -1.0, 1.0)[:, None]
    phi = np.arctan2(edge[:, 1], edge[:, 0])
    return normal, np.sin(2.0 * phi) ** 2, 1.0 / length


def corner_design(quad: np.ndarray) -> np.ndarray | None:
    """The (4, 2, 3) map from ``(a, b, c)`` to each corner's displacement, or None.

    Corner i is shared by edge i-1 (from corner i-1) and edge i; its displacement ``d``
    satisfies ``n_e · d = offset_e`` for both.  None for a degenerate quadrilateral.
    """
    quad = np.asarray(quad, dtype=float)
    if quad.shape != (4, 2) or not np.isfinite(quad).all():
        return None
    normal, s2, inv_len = _edge_terms(quad)
    if not np.all(np.isfinite(inv_len)):
        return None
    terms = np.column_stack([np.ones(4), s2, inv_len])  # offset_e = terms_e · (a, b, c)
    design = np.empty((4, 2, 3))
    for i in range(4):
        before = (i - 1) % 4
        normals = np.array([normal[before], normal[i]])
        det = normals[0, 0] * normals[1, 1] - normals[0, 1] * normals[1, 0]
        if abs(det) < 1e-6:
            return None
        design[i] = np.linalg.solve(normals, np.array([terms[before], terms[i]]))
    return design


@dataclass(frozen=True)
class CornerBias:
    """Edge offset ``a + b sin²(2φ) + c / L`` of the detector on a camera (pixels)."""

    a_px: float = 0.0
    b_px: float = 0.0
    c_px2: float = 0.0

    @property
    def active(self) -> bool:
        return any(v != 0.0 for v in (self.a_px, self.b_px, self.c_px2))

    def displacement(self, quad: np.ndarray) -> np.ndarray:
        """Each corner's systematic offset (detected minus true, 4x2 px; zeros if degenerate).

        Written out in plain floats (it runs on every frame of ``tight``): numpy's per-call
        overhead on 2-vectors costs more than the arithmetic; equal to ``corner_design(quad)
        @ (a, b, c)`` (tested).
        """
        quad = np.asarray(quad, dtype=float)
        if quad.shape != (4, 2) or not np.isfinite(quad).all():
            return np.zeros((4, 2))
        pts = quad.tolist()
        cx = 0.25 * (pts[0][0] + pts[1][0] + pts[2][0] + pts[3][0])
        cy = 0.25 * (pts[0][1] + pts[1][1] + pts[2][1] + pts[3][1])
        normals, offsets = [], []
        for i in range(4):
            (x0, y0), (x1, y1) = pts[i], pts[(i + 1) % 4]
            ex, ey = x1 - x0, y1 - y0
            length = math.hypot(ex, ey)
            if not length > 0.0:
                return np.zeros((4, 2))
            nx, ny = ey / length, -ex / length
            if nx * (0.5 * (x0 + x1) - cx) + ny * (0.5 * (y0 + y1) - cy) < 0.0:
                nx, ny = -nx, -ny
            sin2 = 2.0 * (ex / length) * (ey / length)  # sin(2φ)
            s2 = sin2 * sin2
            normals.append((nx, ny))
            offsets.append(self.a_px + self.b_px * s2 + self.c_px2 / length)
        out = np.empty((4, 2))
        for i in range(4):
            (ax, ay), (bx, by) = normals[i - 1], normals[i]
            det = ax * by - ay * bx
            if abs(det) < 1e-6:
                return np.zeros((4, 2))
            oa, ob = offsets[i - 1], offsets[i]
            out[i, 0] = (oa * by - ob * ay) / det
            out[i, 1] = (ax * ob - bx * oa) / det
        if not np.isfinite(out).all():  # corners so far apart that the arithmetic overflows
            return np.zeros((4, 2))
        return out

    def correct(self, corners: np.ndarray) -> np.ndarray:
        """The detected corners with the offset removed (unchanged where any is unusable)."""
        corners = np.asarray(corners, dtype=float)
        if not self.active:
            return corners
        corrected = corners - self.displacement(corners)
        return corrected if np.isfinite(corrected).all() else corners


def edge_axis_alignment(quad: np.ndarray) -> float:
    """The mean of cos²(2φ) over the quadrilateral's edges: 1 when they lie along the pixel
    axes, 0 on the diagonals (NaN for unusable corners)."""
    pts = np.asarray(quad, dtype=float).reshape(4, 2).tolist()  # plain floats: per frame
    total = 0.0
    for i in range(4):
        ex = pts[(i + 1) % 4][0] - pts[i][0]
        ey = pts[(i + 1) % 4][1] - pts[i][1]
        xx, yy = ex * ex, ey * ey
        if not (xx + yy > 0.0 and math.isfinite(xx + yy)):
            return math.nan
        c2 = (xx - yy) / (xx + yy)  # cos(2φ)
        total += c2 * c2
    return 0.25 * total


@dataclass(frozen=True)
class CornerBiasFit:
    """The fitted offset, the corners' residual noise after it and what it was fitted on.

    ``sigma_px``: the residual noise over all views; ``sigma_diagonal_px`` /
    ``sigma_axes_px``: its model against the edges' angle, ``sigma² = d² + (a² - d²)
    cos²(2φ)`` (edges along the pixel axes are noisier: their sub-pixel phase is the same
    along the whole edge, so its error does not average out).
    """

    bias: CornerBias
    sigma_px: float
    sigma_uncorrected_px: float
    views: int
    sigma_diagonal_px: float = 0.0  # 0: not measured (sigma_px at every angle)
    sigma_axes_px: float = 0.0

    def as_dict(self) -> dict:
        return {
            "edge_offset_a_px": self.bias.a_px,
            "edge_offset_b_px": self.bias.b_px,
            "edge_offset_c_px2": self.bias.c_px2,
            "sigma_px": self.sigma_px,
            "sigma_uncorrected_px": self.sigma_uncorrected_px,
            "views": self.views,
            "sigma_diagonal_px": self.sigma_diagonal_px,
            "sigma_axes_px": self.sigma_axes_px,
        }

    @classmethod
    def from_dict(cls, doc: dict) -> CornerBiasFit:
        return cls(
            CornerBias(
                float(doc["edge_offset_a_px"]),
                float(doc["edge_offset_b_px"]),
                float(doc["edge_offset_c_px2"]),
            ),
            float(doc["sigma_px"]),
            float(doc["sigma_uncorrected_px"]),
            int(doc["views"]),
            float(doc.get("sigma_diagonal_px", 0.0)),
            float(doc.get("sigma_axes_px", 0.0)),
        )


def fit_corner_bias(detected: Sequence[np.ndarray], true: Sequence[np.ndarray]) -> CornerBiasFit:
    """Least-squares ``(a, b, c)`` from detected and true corner pixels (one 4x2 pair a view).

    The true corners are the tag's projection through the calibrated camera at the rig's
    known pose; each view's mean residual is removed first (a principal-point error of the
    calibration shifts all four corners alike, which is not an edge offset).  ``sigma_px``:
    the RMS per coordinate of what the model leaves (3 parameters and 2 per view taken off).
    """
    rows, rhs, raw, alignment = [], [], [], []
    for q, p in zip(detected, true, strict=True):
        q = np.asarray(q, dtype=float)
        p = np.asarray(p, dtype=float)
        design = corner_design(p)
        if design is None or not np.isfinite(q).all():
            continue
        residual = q - p
        residual = residual - residual.mean(axis=0)
        design = design - design.mean(axis=0)
        rows.append(design.reshape(8, 3))
        rhs.append(residual.reshape(8))
        raw.append(residual.reshape(8))
        alignment.append(edge_axis_alignment(p))
    if len(rows) < 3:
        raise ValueError(f"need at least 3 usable views, got {len(rows)}")
    a = np.vstack(rows)
    b = np.concatenate(rhs)
    theta, *_ = np.linalg.lstsq(a, b, rcond=None)
    left = b - a @ theta
    dof = max(len(b) - 3 - 2 * len(rows), 1)
    raw_all = np.concatenate(raw)
    # each view's mean square (6 degrees of freedom of 8 after its mean) against cos²(2φ)
    view_ms = np.sum(left.reshape(-1, 8) ** 2, axis=1) / 6.0
    design = np.column_stack([np.ones(len(view_ms)), alignment])
    (d2, slope), *_ = np.linalg.lstsq(design, view_ms, rcond=None)
    floor = 1e-8
    return CornerBiasFit(
        CornerBias(*(float(v) for v in theta)),
        math.sqrt(float(left @ left) / dof),
        math.sqrt(float(raw_all @ raw_all) / max(len(raw_all) - 2 * len(rows), 1)),
        len(rows),
        math.sqrt(max(float(d2), floor)),
        math.sqrt(max(float(d2 + slope), floor)),
    )
