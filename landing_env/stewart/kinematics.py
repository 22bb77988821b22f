"""Geometry and kinematics of a 6-6 Stewart platform (inverse, forward, workspace clamping).

Frames: the *base frame* has its origin at the centre of the six base joints, z up, x towards
the bow.  The *home frame* is the base frame lifted by ``home_height``; a platform pose is the
6-vector ``(x, y, z, roll, pitch, yaw)`` (metres, radians, Euler ZYX as in
:mod:`estimation.frames`) of the top-plate frame P relative to the home frame.  P's origin is
the centre of the deck's top surface; the top joints sit ``top_anchor_depth`` below it.

Leg i joins base anchor i to top anchor i.  The anchors come in three pairs at 120 degree
spacing; the two legs of a pair start close together on the base and lean away from each
other to neighbouring top pairs (the classic triangular-hexagonal layout).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from estimation.limits import POSITIVE, Limit, limited, require_limits
from landing_env.errors import ConfigError, require_range

#: A pose is (x, y, z, roll, pitch, yaw): metres and radians, P relative to the home frame.
POSE_SIZE = 6


@dataclass(frozen=True)
class StewartGeometry:
    """Dimensions of the platform (metres; angles in degrees, as in every config).

    The defaults describe a bench with a ~1 m deck whose workspace covers at least
    +-0.12 m heave, +-0.08 m surge/sway, +-12 deg roll/pitch and +-10 deg yaw, each on its own
    (tests check this), with a few percent of stroke to spare.
    """

    #: radius of the circle through the base joints
    base_radius: float = limited(0.50, POSITIVE, physical=Limit.positive(100.0))
    #: radius of the circle through the top joints
    top_radius: float = limited(0.36, POSITIVE, physical=Limit.positive(100.0))
    #: half the angle between the two base joints of a pair, degrees
    base_half_angle_deg: float = limited(12.0, Limit(0.0, 60.0))
    #: half the angle between the two top joints of a pair (pairs centred between base
    #: pairs), degrees
    top_half_angle_deg: float = limited(12.0, Limit(0.0, 60.0))
    #: height of P's origin (the deck's top surface) above the base-joint plane at home
    home_height: float = limited(0.55, POSITIVE, physical=Limit.positive(1e3))
    #: depth of the top-joint plane below the deck's top surface (joints hide under the plate)
    top_anchor_depth: float = limited(0.04, physical=Limit.symmetric(100.0))
    #: shortest leg (fully retracted actuator), joint centre to joint centre
    min_leg_length: float = limited(0.47, POSITIVE, physical=Limit.positive(1e3))
    #: longest leg (fully extended actuator)
    max_leg_length: float = limited(0.72, physical=Limit.positive(1e3))
    #: largest angle between a leg and the base normal, degrees; None: no limit
    max_base_joint_angle_deg: float | None = None
    #: largest angle between a leg and the top-plate normal, degrees; None: no limit
    max_top_joint_angle_deg: float | None = None

    def __post_init__(self) -> None:
        require_limits(self)
        require_range(
            "top_anchor_depth",
            self.top_anchor_depth,
            0.0,
            self.home_height,
            bounds_from=f"home_height = {self.home_height}",
        )
        if not self.max_leg_length > self.min_leg_length:
            raise ConfigError(
                "max_leg_length",
                f"{self.max_leg_length} must be above min_leg_length = {self.min_leg_length}",
            )
        for name in ("max_base_joint_angle_deg", "max_top_joint_angle_deg"):
            value = getattr(self, name)
            if value is not None:
                require_range(name, value, 0.0, 90.0, low_inclusive=False)
        kinematics = StewartKinematics(self)
        home = kinematics.home_leg_lengths
        if np.any(home < self.min_leg_length) or np.any(home > self.max_leg_length):
            raise ConfigError(
                "home_height",
                f"home leg length {home[0]:.4f} m (from home_height, base_radius, top_radius, "
                "the half angles and top_anchor_depth) is outside the stroke "
                f"[min_leg_length, max_leg_length] = [{self.min_leg_length}, "
                f"{self.max_leg_length}] m; the home pose must be reachable",
            )
        base_angles, top_angles = kinematics.joint_angles(np.zeros(POSE_SIZE))
        for name, angles in (
            ("max_base_joint_angle_deg", base_angles),
            ("max_top_joint_angle_deg", top_angles),
        ):
            limit = getattr(self, name)
            home_deg = math.degrees(float(np.max(angles)))
            if limit is not None and home_deg >= limit:
                raise ConfigError(
                    name,
                    f"{limit!r} excludes the home pose; allowed: more than the home joint "
                    f"angle {home_deg:.2f} deg, or None",
                )

    @property
    def stroke(self) -> float:
        """Actuator stroke: max minus min leg length (m)."""
        return self.max_leg_length - self.min_leg_length

    def base_anchors(self) -> np.ndarray:
        """6x3 base joint centres in the base frame."""
        angles = _pair_centres() + _pair_signs() * math.radians(self.base_half_angle_deg)
        return _ring(self.base_radius, angles, 0.0)

    def top_anchors(self) -> np.ndarray:
        """6x3 top joint centres in the top-plate frame P."""
        angles = _pair_centres() + _pair_signs() * math.radians(60.0 - self.top_half_angle_deg)
        return _ring(self.top_radius, angles, -self.top_anchor_depth)


@dataclass(frozen=True)
class ClampResult:
    """What :meth:`StewartKinematics.clamp_to_workspace` made of a commanded pose."""

    #: the reachable pose actually applied (6,)
    pose: np.ndarray
    #: True whenever the command was modified
    clamped: bool
    #: leg lengths of ``pose`` (6,), metres
    leg_lengths: np.ndarray
    #: indices of the legs whose limits the *commanded* pose violated (empty when reachable)
    violated_legs: tuple[int, ...]


class ForwardKinematicsError(RuntimeError):
    """The forward-kinematics solver did not reproduce the requested leg lengths."""


class StewartKinematics:
    """Inverse and forward kinematics and workspace checks of one :class:`StewartGeometry`."""

    #: grid points per multisection round in :meth:`clamp_to_workspace`
    _CLAMP_GRID = 33
    #: multisection rounds: the line parameter is resolved to 1 / 32**4 ~ 1e-6
    _CLAMP_ROUNDS = 4

    def __init__(self, geometry: StewartGeometry) -> None:
        self.geometry = geometry
        self.base_anchors = geometry.base_anchors()
        self.top_anchors_p = geometry.top_anchors()
        self._home_offset = np.array([0.0, 0.0, geometry.home_height])
        # Top anchors relative to the home frame's base-frame position, transposed for R @ p.
        self._top_t = np.ascontiguousarray(self.top_anchors_p.T)
        self._base_minus_home = self.base_anchors - self._home_offset
        # Plain-float copies for the single-pose path (pure Python beats numpy for 6 legs).
        self._anchor_pairs = [
            (tuple(top), tuple(base))
            for top, base in zip(
                self.top_anchors_p.tolist(), self.base_anchors.tolist(), strict=True
            )
        ]
        self.home_leg_lengths = self.inverse_kinematics(np.zeros(POSE_SIZE))
        self._cos_base = _cos_deg(geometry.max_base_joint_angle_deg)
        self._cos_top = _cos_deg(geometry.max_top_joint_angle_deg)
        # For surely_reachable: how far any leg may stretch or shrink from its home length
        # (less a rounding guard far above the float error of the full check), and the
        # largest distance of a top anchor from P's origin.
        margin = min(
            float(np.min(self.home_leg_lengths)) - geometry.min_leg_length,
            geometry.max_leg_length - float(np.max(self.home_leg_lengths)),
        )
        joint_limits = self._cos_base is not None or self._cos_top is not None
        self._stroke_margin = -1.0 if joint_limits else margin - 1e-9
        self._top_anchor_reach = float(np.max(np.linalg.norm(self.top_anchors_p, axis=1)))

    # ---------------------------------------------------------------- inverse kinematics
    def leg_vectors(self, pose: np.ndarray) -> np.ndarray:
        """Leg vectors base anchor -> top anchor in the base frame: (6, 3) or (N, 6, 3)."""
        pose = np.asarray(pose, dtype=float)
        if pose.ndim == 1:
            # Single pose: the per-physics-step path, kept to a handful of numpy calls.
            x, y, z, roll, pitch, yaw = pose.tolist()
            top = rotation_matrix_zyx(roll, pitch, yaw) @ self._top_t
            return top.T + (np.array((x, y, z)) - self._base_minus_home)
        rotation = rotation_matrix_zyx(pose[..., 3], pose[..., 4], pose[..., 5])
        top = rotation @ self._top_t  # (..., 3, 6)
        return np.swapaxes(top, -1, -2) + pose[..., None, :3] - self._base_minus_home

    def top_anchors_base(self, pose: np.ndarray) -> np.ndarray:
        """Top joint centres in the base frame for ``pose``: (6, 3) or (N, 6, 3)."""
        return self.leg_vectors(pose) + self.base_anchors

    def inverse_kinematics(self, pose: np.ndarray) -> np.ndarray:
        """Leg lengths (m) of a pose (6,) -> (6,), or of many poses (N, 6) -> (N, 6)."""
        legs = self.leg_vectors(pose)
        return np.sqrt((legs * legs).sum(axis=-1))

    # ---------------------------------------------------------------- forward kinematics
    def jacobian(self, pose: np.ndarray) -> np.ndarray:
        """6x6 derivative of the leg lengths with respect to the pose vector."""
        pose = np.asarray(pose, dtype=float)
        legs = self.leg_vectors(pose)
        units = legs / np.linalg.norm(legs, axis=1, keepdims=True)
        jac = np.empty((6, POSE_SIZE))
        jac[:, :3] = units
        for k, d_rot in enumerate(_rotation_derivatives(*pose[3:])):
            jac[:, 3 + k] = np.einsum("ij,ij->i", units, (d_rot @ self._top_t).T)
        return jac

    def forward_kinematics(
        self, leg_lengths: np.ndarray, initial_guess: np.ndarray | None = None
    ) -> np.ndarray:
        """The pose (6,) whose legs have ``leg_lengths`` (m), by Levenberg-Marquardt.

        Starts from ``initial_guess`` (default: home) and so finds the assembly branch nearest
        to it.  Raises :class:`ForwardKinematicsError` if the residual stays above 1e-9 m.
        """
        target = np.asarray(leg_lengths, dtype=float).reshape(6)
        guess = np.zeros(POSE_SIZE) if initial_guess is None else np.asarray(initial_guess, float)
        solution = least_squares(
            lambda q: self.inverse_kinematics(q) - target,
            guess,
            jac=self.jacobian,
            method="lm",
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
        )
        residual = float(np.max(np.abs(solution.fun)))
        if not np.isfinite(residual) or residual > 1e-9:
            raise ForwardKinematicsError(
                f"no pose found for leg lengths {target.tolist()} (residual {residual:.2e} m)"
            )
        return solution.x

    # ---------------------------------------------------------------- workspace
    def violated_legs(self, pose: np.ndarray) -> np.ndarray:
        """Boolean mask (6,) or (N, 6) of the legs whose limits ``pose`` violates."""
        return self._lengths_and_violations(pose)[1]

    def _check_single(self, pose: np.ndarray) -> tuple[list[float], tuple[int, ...]]:
        """Leg lengths and violated-leg indices of one pose, in plain Python floats.

        This is the per-physics-step path: ~3 us against ~10 us through numpy for six legs.
        """
        x, y, z, roll, pitch, yaw = pose.tolist()
        cr, sr = math.cos(roll), math.sin(roll)
        cp, sp = math.cos(pitch), math.sin(pitch)
        cy, sy = math.cos(yaw), math.sin(yaw)
        r00, r01, r02 = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
        r10, r11, r12 = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
        r20, r21, r22 = -sp, cp * sr, cp * cr
        z += self.geometry.home_height
        low, high = self.geometry.min_leg_length, self.geometry.max_leg_length
        cos_base, cos_top = self._cos_base, self._cos_top
        lengths: list[float] = []
        violated: list[int] = []
        for i, ((px, py, pz), (bx, by, bz)) in enumerate(self._anchor_pairs):
            lx = r00 * px + r01 * py + r02 * pz + x - bx
            ly = r10 * px + r11 * py + r12 * pz + y - by
            lz = r20 * px + r21 * py + r22 * pz + z - bz
            length = math.sqrt(lx * lx + ly * ly + lz * lz)
            lengths.append(length)
            if (
                length < low
                or length > high
                or (cos_base is not None and lz < cos_base * length)
                or (cos_top is not None and lx * r02 + ly * r12 + lz * r22 < cos_top * length)
            ):
                violated.append(i)
        return lengths, tuple(violated)

    def surely_reachable(self, translation_norm: float, sin_half_angle: float) -> bool:
        """A cheap sufficient test of reachability, for the per-physics-step path.

        ``translation_norm``: ``|(x, y, z)|`` of the pose (m); ``sin_half_angle``: sin(theta / 2)
        of its rotation angle theta (the norm of its unit quaternion's vector part).  True
        guarantees that every leg is within its stroke; False says nothing (run the full
        check).  Leg i's vector changes from home by t + (R - I) p_i, and
        ``|(R - I) p| <= 2 sin(theta / 2) |p|``, so no length moves from home by more than
        ``|t| + 2 sin(theta / 2) max|p_i|``.  Joint-angle limits are not bounded this way: when
        either is configured this always returns False.
        """
        deviation = translation_norm + 2.0 * sin_half_angle * self._top_anchor_reach
        return deviation < self._stroke_margin

    def _lengths_and_violations(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        legs = self.leg_vectors(pose)
        lengths = np.sqrt((legs * legs).sum(axis=-1))
        geometry = self.geometry
        bad = (lengths < geometry.min_leg_length) | (lengths > geometry.max_leg_length)
        if self._cos_base is not None:
            bad |= legs[..., 2] < self._cos_base * lengths
        if self._cos_top is not None:
            pose = np.asarray(pose, dtype=float)
            normal = rotation_matrix_zyx(pose[..., 3], pose[..., 4], pose[..., 5])[..., :, 2]
            cos_top = np.einsum("...ij,...j->...i", legs, normal)
            bad |= cos_top < self._cos_top * lengths
        return lengths, bad

    def is_reachable(self, pose: np.ndarray) -> bool | np.ndarray:
        """True when every leg of ``pose`` is within its limits (array for (N, 6) poses)."""
        pose = np.asarray(pose, dtype=float)
        if pose.ndim == 1:
            return not self._check_single(pose)[1]
        return ~np.any(self.violated_legs(pose), axis=-1)

    def clamp_to_workspace(self, pose: np.ndarray) -> ClampResult:
        """The farthest reachable pose on the straight line from home to ``pose``.

        A reachable command comes back unchanged with ``clamped=False``.  Otherwise the line
        parameter s in [0, 1] is found by multisection (a vectorised bisection that evaluates
        a grid of s at once, so it stops at the *first* exit from the workspace even if the
        line re-enters it later); the returned pose is the last reachable grid point,
        within ~1e-6 of the boundary along the line, and ``clamped`` is True.
        """
        pose = np.array(pose, dtype=float).reshape(POSE_SIZE)
        lengths, violated = self._check_single(pose)
        if not violated:
            return ClampResult(pose, False, np.array(lengths), ())
        low, high = 0.0, 1.0
        grid = np.linspace(0.0, 1.0, self._CLAMP_GRID)
        for _ in range(self._CLAMP_ROUNDS):
            s = low + (high - low) * grid
            ok = ~np.any(self.violated_legs(s[:, None] * pose), axis=-1)
            first_bad = int(np.argmin(ok)) if not ok.all() else len(s)
            if first_bad == 0:
                # Home itself is reachable (checked in StewartGeometry), so this only happens
                # when ``low`` sits exactly on the boundary; keep it.
                break
            low = float(s[first_bad - 1])
            high = float(s[first_bad]) if first_bad < len(s) else high
        applied = low * pose
        return ClampResult(applied, True, self.inverse_kinematics(applied), violated)

    def joint_angles(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angles (rad) between each leg and the base normal, and the top-plate normal."""
        pose = np.asarray(pose, dtype=float)
        legs = self.leg_vectors(pose)
        lengths = np.sqrt((legs * legs).sum(axis=-1))
        normal = rotation_matrix_zyx(pose[..., 3], pose[..., 4], pose[..., 5])[..., :, 2]
        cos_top = np.einsum("...ij,...j->...i", legs, normal) / lengths
        cos_base = legs[..., 2] / lengths
        return np.arccos(np.clip(cos_base, -1.0, 1.0)), np.arccos(np.clip(cos_top, -1.0, 1.0))

    def stroke_usage(self, leg_lengths: np.ndarray) -> np.ndarray:
        """Fraction of the stroke in use per leg: 0 fully retracted, 1 fully extended."""
        geometry = self.geometry
        return (np.asarray(leg_lengths) - geometry.min_leg_length) / geometry.stroke


def rotation_matrix_zyx(
    roll: float | np.ndarray, pitch: float | np.ndarray, yaw: float | np.ndarray
) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) for scalars (3, 3) or same-shape arrays (..., 3, 3).

    Written out rather than through scipy's Rotation because it is evaluated every physics
    step (scipy takes ~20 us for one matrix, this ~1 us) and for batches of clamping
    candidates; it equals :func:`estimation.frames.matrix_from_euler_zyx` (tested).
    """
    if np.ndim(roll) == 0 and np.ndim(pitch) == 0 and np.ndim(yaw) == 0:
        cr, sr = math.cos(roll), math.sin(roll)
        cp, sp = math.cos(pitch), math.sin(pitch)
        cy, sy = math.cos(yaw), math.sin(yaw)
        return np.array(
            (
                (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
                (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
                (-sp, cp * sr, cp * cr),
            )
        )
    roll, pitch, yaw = np.broadcast_arrays(roll, pitch, yaw)
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    rotation = np.empty((*roll.shape, 3, 3))
    rotation[..., 0, 0] = cy * cp
    rotation[..., 0, 1] = cy * sp * sr - sy * cr
    rotation[..., 0, 2] = cy * sp * cr + sy * sr
    rotation[..., 1, 0] = sy * cp
    rotation[..., 1, 1] = sy * sp * sr + cy * cr
    rotation[..., 1, 2] = sy * sp * cr - cy * sr
    rotation[..., 2, 0] = -sp
    rotation[..., 2, 1] = cp * sr
    rotation[..., 2, 2] = cp * cr
    return rotation


def angular_velocity_from_euler_rates(attitude: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Angular velocity (rad/s, parent frame) of R = Rz(yaw) Ry(pitch) Rx(roll).

    ``attitude`` is (roll, pitch, yaw) and ``rates`` their time derivatives.
    """
    roll_rate, pitch_rate, yaw_rate = np.asarray(rates, dtype=float).tolist()
    _, pitch, yaw = np.asarray(attitude, dtype=float).tolist()
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        (
            cy * cp * roll_rate - sy * pitch_rate,
            sy * cp * roll_rate + cy * pitch_rate,
            yaw_rate - sp * roll_rate,
        )
    )


def _rotation_derivatives(roll: float, pitch: float, yaw: float) -> list[np.ndarray]:
    """dR/droll, dR/dpitch, dR/dyaw of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    drz = np.array([[-sy, -cy, 0.0], [cy, -sy, 0.0], [0.0, 0.0, 0.0]])
    dry = np.array([[-sp, 0.0, cp], [0.0, 0.0, 0.0], [-cp, 0.0, -sp]])
    drx = np.array([[0.0, 0.0, 0.0], [0.0, -sr, -cr], [0.0, cr, -sr]])
    return [rz @ ry @ drx, rz @ dry @ rx, drz @ ry @ rx]


def _cos_deg(angle_deg: float | None) -> float | None:
    return None if angle_deg is None else math.cos(math.radians(angle_deg))


def _pair_centres() -> np.ndarray:
    return np.repeat(np.deg2rad([0.0, 120.0, 240.0]), 2)


def _pair_signs() -> np.ndarray:
    return np.tile([-1.0, 1.0], 3)


def _ring(radius: float, angles: np.ndarray, z: float) -> np.ndarray:
    return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(6, z)])
