"""The ``tight`` estimator's least-squares problem and its solver.

:class:`TightProblem` holds one frame's whitened residuals (the tag corners through the
calibrated camera, then the ToF ranges to the deck plane) with their analytic Jacobian over a
left-multiplicative update ``R <- Exp(dtheta) R``, ``t <- t + dt``, and refines a pose by
Levenberg–Marquardt (:meth:`TightProblem.solve`); :func:`rotation_exp` is that update's
exponential and :func:`euler_jacobian` maps its covariance to roll, pitch and yaw.  The cost
and the estimator that builds the problem are described in :mod:`estimation.tight`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.camera_model import CameraIntrinsics


def rotation_exp(dtheta: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: the rotation matrix of the rotation vector ``dtheta``."""
    wx, wy, wz = float(dtheta[0]), float(dtheta[1]), float(dtheta[2])
    angle2 = wx * wx + wy * wy + wz * wz
    if angle2 < 1e-24:
        return np.array([[1.0, -wz, wy], [wz, 1.0, -wx], [-wy, wx, 1.0]])
    angle = math.sqrt(angle2)
    a = math.sin(angle) / angle
    b = (1.0 - math.cos(angle)) / angle2
    return np.array(
        [
            [1.0 - b * (wy * wy + wz * wz), b * wx * wy - a * wz, b * wx * wz + a * wy],
            [b * wx * wy + a * wz, 1.0 - b * (wx * wx + wz * wz), b * wy * wz - a * wx],
            [b * wx * wz - a * wy, b * wy * wz + a * wx, 1.0 - b * (wx * wx + wy * wy)],
        ]
    )


@dataclass(frozen=True)
class TightSolution:
    """A local minimum of the tight cost."""

    rotation: np.ndarray
    translation: np.ndarray
    cost: float
    jacobian: np.ndarray
    residuals: np.ndarray
    iterations: int


class TightProblem:
    """The whitened residuals and their Jacobian for one frame's measurements.

    Parameters are ``(dt, dtheta)`` of ``t <- t + dt``, ``R <- Exp(dtheta) R``.  Residual
    order: each corner's (u, v), then the ranges.  The problem is small (at most 8 + 4
    residuals), so the residuals and the Jacobian rows are computed in plain floats: numpy's
    per-call overhead on 4-element arrays costs more than the arithmetic.
    """

    def __init__(
        self,
        model_d: np.ndarray,
        pixels: np.ndarray,
        intrinsics: CameraIntrinsics,
        pixel_sigma_px: float,
        sensors_c: np.ndarray,
        ranges: np.ndarray,
        range_sigma_m: np.ndarray,
    ) -> None:
        model = np.asarray(model_d, dtype=float)
        if not np.allclose(model[:, 2], 0.0):
            raise ValueError("the tag model must lie in its plane z = 0")
        pixels = np.asarray(pixels, dtype=float)
        k = intrinsics
        # the model's (x, y) and the measured pixels in normalised camera units
        normalised = (pixels - (k.cx, k.cy)) / (k.fx, k.fy)
        self._corners = np.hstack([model[:, :2], normalised]).tolist()
        self.n_corners = len(self._corners)
        sensors = np.asarray(sensors_c, dtype=float).reshape(-1, 3)
        ranges = np.asarray(ranges, dtype=float).reshape(-1, 1)
        weights = 1.0 / np.asarray(range_sigma_m, dtype=float).reshape(-1, 1)
        self._ranges = np.hstack([sensors, ranges, weights]).tolist()
        self.n_ranges = len(self._ranges)
        self.pixel_sigma_px = float(pixel_sigma_px)
        self._wu = k.fx / self.pixel_sigma_px
        self._wv = k.fy / self.pixel_sigma_px
        self._dist = tuple(float(d) for d in k.dist) if k.has_distortion else None
        self.m = 2 * self.n_corners + self.n_ranges

    def cost(self, rotation: np.ndarray, translation: np.ndarray) -> float:
        """The whitened cost (sum of squared residuals) of a pose; NaN behind the camera."""
        res = self._evaluate(rotation, translation, False)[0]
        return math.fsum(v * v for v in res)

    def residuals(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """Whitened residuals (m) of a pose (NaN where a corner is behind the camera)."""
        return np.array(self._evaluate(rotation, translation, False)[0])

    def linearise(
        self, rotation: np.ndarray, translation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residuals (m) and their Jacobian (m x 6) of a pose."""
        res, rows = self._evaluate(rotation, translation, True)
        return np.array(res), np.array(rows).reshape(self.m, 6)

    def _evaluate(
        self, rotation: np.ndarray, translation: np.ndarray, jacobian: bool
    ) -> tuple[list[float], list[list[float]]]:
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation.tolist()
        tx, ty, tz = translation.tolist()
        wu, wv = self._wu, self._wv
        dist = self._dist
        res: list[float] = []
        rows: list[list[float]] = []
        for mx, my, mu, mv in self._corners:
            qx = r00 * mx + r01 * my
            qy = r10 * mx + r11 * my
            qz = r20 * mx + r21 * my
            pz = qz + tz
            if not pz > 0.0:
                res += [math.nan, math.nan]
                rows += [[math.nan] * 6, [math.nan] * 6]
                continue
            iz = 1.0 / pz
            x = (qx + tx) * iz
            y = (qy + ty) * iz
            if dist is None:
                res += [(x - mu) * wu, (y - mv) * wv]
                if jacobian:
                    cu0, cu1, cu2 = wu * iz, 0.0, -wu * iz * x
                    cv0, cv1, cv2_ = 0.0, wv * iz, -wv * iz * y
            else:
                k1, k2, p1, p2, k3 = dist
                xx, yy, xy = x * x, y * y, x * y
                r2 = xx + yy
                radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
                xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
                yd = y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
                res += [(xd - mu) * wu, (yd - mv) * wv]
                if jacobian:
                    dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
                    a11 = radial + 2.0 * xx * dr + 2.0 * p1 * y + 6.0 * p2 * x
                    a12 = 2.0 * xy * dr + 2.0 * p1 * x + 2.0 * p2 * y
                    a22 = radial + 2.0 * yy * dr + 6.0 * p1 * y + 2.0 * p2 * x
                    fu, fv = wu * iz, wv * iz
                    cu0, cu1 = fu * a11, fu * a12
                    cu2 = -(cu0 * x + cu1 * y)
                    cv0, cv1 = fv * a12, fv * a22
                    cv2_ = -(cv0 * x + cv1 * y)
            if jacobian:
                # dp/dtheta = -[q]x  =>  the row c becomes q x c
                rows.append(
                    [cu0, cu1, cu2, qy * cu2 - qz * cu1, qz * cu0 - qx * cu2, qx * cu1 - qy * cu0]
                )
                rows.append(
                    [
                        cv0,
                        cv1,
                        cv2_,
                        qy * cv2_ - qz * cv1,
                        qz * cv0 - qx * cv2_,
                        qx * cv1 - qy * cv0,
                    ]
                )
        if self._ranges:
            inz = 1.0 / r22 if r22 != 0.0 else math.inf
            for sx, sy, sz, measured, w in self._ranges:
                ax, ay, az = tx - sx, ty - sy, tz - sz
                rho = (ax * r02 + ay * r12 + az * r22) * inz
                res.append((rho - measured) * w)
                if jacobian:
                    wn = w * inz
                    gx, gy, gz = ax * wn, ay * wn, (az - rho) * wn
                    rows.append(
                        [
                            r02 * wn,
                            r12 * wn,
                            r22 * wn,
                            r12 * gz - r22 * gy,
                            r22 * gx - r02 * gz,
                            r02 * gy - r12 * gx,
                        ]
                    )
        return res, rows

    def solve(
        self,
        rotation: np.ndarray,
        translation: np.ndarray,
        max_iterations: int,
        step_tol: float = 1e-9,
        cost_tol: float = 1e-4,
    ) -> TightSolution | None:
        """Levenberg–Marquardt from ``(rotation, translation)``; None if it breaks down.

        It stops when a step is below ``step_tol`` (metres and radians), which on noise-free
        data leaves errors far below 1e-6 m (Gauss–Newton converges quadratically there), or
        when a step lowered the whitened cost by less than ``cost_tol`` (times the cost per
        residual where that exceeds 1, i.e. where the sigmas are set too small): the pose
        then moved by about sqrt(cost_tol) = 1 % of its standard deviation.
        """
        rotation = np.asarray(rotation, dtype=float)
        translation = np.asarray(translation, dtype=float)
        r, j = self.linearise(rotation, translation)
        cost = float(r @ r)
        if not math.isfinite(cost):
            return None
        lam = 1e-6
        iterations = 0
        for iterations in range(1, max_iterations + 1):  # noqa: B007
            h = j.T @ j
            damped = h + np.diag(lam * (np.diag(h) + 1e-12))
            step = np.linalg.solve(damped, -(j.T @ r))
            new_t = translation + step[:3]
            new_r = rotation_exp(step[3:]) @ rotation
            r_new, j_new = self.linearise(new_r, new_t)
            cost_new = float(r_new @ r_new)
            small = float(np.max(np.abs(step))) < step_tol
            if cost_new <= cost:  # NaN is never accepted
                # in units of the cost per residual, so that a mis-set sigma does not
                # change when it stops
                small = small or cost - cost_new <= cost_tol * max(1.0, cost / self.m)
                rotation, translation, r, j, cost = new_r, new_t, r_new, j_new, cost_new
                lam = max(lam * 0.1, 1e-9)
            else:
                lam *= 10.0
                if lam > 1e8:
                    break
            if small:
                break
        return TightSolution(rotation, translation, cost, j, r, iterations)


def euler_jacobian(rotation: np.ndarray) -> np.ndarray:
    """d(roll, pitch, yaw)/d(dtheta) for the left update ``R <- Exp(dtheta) R`` (ZYX)."""
    sp = -float(rotation[2, 0])
    cp = math.sqrt(max(0.0, 1.0 - sp * sp))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    cy, sy = math.cos(yaw), math.sin(yaw)
    # the angular velocity in C of (roll, pitch, yaw) rates: columns Rz Ry e_x, Rz e_y, e_z
    e = np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])
    return np.linalg.inv(e)
