"""The one place that defines the project's frames and conventions.

Frames (all right-handed, metres, radians):

* ``W`` world: x forward (north-ish), y left, z up; gravity along -z.  The ground is *not*
  assumed to be at z = 0 for anything that matters (ground effect and touchdown use the
  surface actually under the drone).
* ``B`` drone body: FLU, x forward, y left, z up; origin at the centre of mass.
* ``C`` camera: OpenCV, x right in the image, y down in the image, z along the optical axis.
  The camera looks down the body's -z axis, with the image top towards the body's nose:
  ``x_C = -y_B``, ``y_C = -x_B``, ``z_C = -z_B``.
* ``P`` deck (top plate of the Stewart platform): origin at the centre of the top surface,
  z along the surface normal (up), x towards the platform's bow, y to port.
* ``D`` tag/deck-pose frame: origin at the tag centre on the deck surface, with the AprilTag
  convention: x to the tag's right, y to the tag's bottom, z *into* the deck.  It is fixed to
  ``P`` by ``R_PD = R_BC``, so a level drone at zero yaw above a level deck sees
  ``R_CD = I``, and the deck 2 m below gives ``t_CD = (0, 0, 2)`` (as in CRHF Sec. 4.1).

The deck pose that every estimator returns and the environment reports is ``T_CD``: the
rotation ``R_CD`` (columns are the D axes in C) and the translation ``t_CD`` (the tag centre in
C).  Euler angles are ZYX (intrinsic yaw, then pitch, then roll) and are reported as
``(roll, pitch, yaw)``.

Pixels follow OpenCV: the centre of the top-left pixel is (0, 0).  Tag corners are always in
the AprilTag/IPPE_SQUARE order of :data:`TAG_CORNER_SIGNS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

#: Camera axes expressed in the body frame (columns): x_C = -y_B, y_C = -x_B, z_C = -z_B.
R_BC: np.ndarray = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

#: Tag frame axes expressed in the deck (top-plate) frame; equal to R_BC by construction.
R_PD: np.ndarray = R_BC.copy()

#: Corner order of a detected tag, in units of half the tag size, in the tag frame D:
#: (-1, +1), (+1, +1), (+1, -1), (-1, -1).  This is pupil-apriltags' order and the order that
#: OpenCV's SOLVEPNP_IPPE_SQUARE expects.  With y down this is bottom-left, bottom-right,
#: top-right, top-left as seen by a camera with R_CD = I.
TAG_CORNER_SIGNS: np.ndarray = np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])

#: Distance of each ToF sensor from the camera and its angle to the camera axes (IHRCF Eq. 12).
TOF_ARM_DISTANCE_M: float = 0.1
TOF_ARM_ANGLE_RAD: float = np.deg2rad(45.0)


def tag_corners_in_tag_frame(tag_size: float) -> np.ndarray:
    """Return the 4x3 tag corners in the tag frame D (z = 0), in detection order."""
    half = 0.5 * tag_size
    corners = np.zeros((4, 3))
    corners[:, :2] = TAG_CORNER_SIGNS * half
    return corners


def tof_positions_in_camera_frame(
    distance: float = TOF_ARM_DISTANCE_M, angle: float = TOF_ARM_ANGLE_RAD
) -> np.ndarray:
    """Return the 4x3 ToF sensor origins in the camera frame C (IHRCF Eq. 12, centred).

    The paper puts sensor 1 at its origin and numbers the others round the square
    (Ps2 along +x, Ps3 diagonal, Ps4 along +y); here the same square is centred on the
    camera: sensor i sits ``distance`` from the camera at ``angle`` to the camera axes.
    All four lie in the camera's plane (z = 0) and measure along +z_C (the body's down axis).
    """
    dx = distance * np.cos(angle)
    dy = distance * np.sin(angle)
    return np.array([[-dx, -dy, 0.0], [dx, -dy, 0.0], [dx, dy, 0.0], [-dx, dy, 0.0]])


def camera_to_heading_xy(xy_c: np.ndarray) -> np.ndarray:
    """Horizontal camera-frame offsets ``(x_C, y_C)`` as ``(forward, left)`` of a level drone.

    The heading frame of a level drone is its body frame, so this is ``R_BC`` applied to the
    offset (``forward = -y_C``, ``left = -x_C``: the image top is the nose, x_C points right).
    Works on one offset ``(2,)`` or a stack ``(n, 2)``.
    """
    xy = np.asarray(xy_c, dtype=float)
    return xy @ R_BC[:2, :2].T


def euler_zyx_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """Return (roll, pitch, yaw) in radians of a rotation matrix, ZYX (yaw-pitch-roll) order.

    Closed form for R = Rz(yaw) Ry(pitch) Rx(roll) (it runs every step, where scipy's
    general conversion costs ~100 µs); agrees with ``Rotation.as_euler("ZYX")`` away from
    gimbal lock, where roll is set to 0 as scipy does.
    """
    return np.array(euler_zyx_from_rows(np.asarray(rotation).ravel().tolist()))


def euler_zyx_from_rows(rotation: Sequence[float]) -> tuple[float, float, float]:
    """:func:`euler_zyx_from_matrix` of a rotation matrix given as its 9 entries, row by row
    (as plain floats: what the per-step code holds)."""
    r00, r01, _, r10, r11, _, r20, r21, r22 = rotation
    sin_pitch = -float(r20)
    if abs(sin_pitch) >= 1.0 - 1e-12:
        pitch = math.copysign(math.pi / 2.0, sin_pitch)
        return (0.0, pitch, math.atan2(-float(r01), float(r11)))
    return (
        math.atan2(float(r21), float(r22)),
        math.asin(sin_pitch),
        math.atan2(float(r10), float(r00)),
    )


def matrix_from_euler_zyx(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Return the rotation matrix R = Rz(yaw) Ry(pitch) Rx(roll).

    ``Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()`` written out in plain
    floats, operation for operation as scipy computes it (the three elementary quaternions
    composed in turn, then the matrix of the quaternion), so the two agree bit for bit at a
    tenth of the cost; non-finite angles go to scipy.
    """
    roll, pitch, yaw = float(roll), float(pitch), float(yaw)
    if not (math.isfinite(roll) and math.isfinite(pitch) and math.isfinite(yaw)):
        return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    # q = qz(yaw) * qy(pitch), then * qx(roll); each product as scipy's _compose_quat
    sz, cz = math.sin(yaw / 2), math.cos(yaw / 2)
    sy, cy = math.sin(pitch / 2), math.cos(pitch / 2)
    sx, cx = math.sin(roll / 2), math.cos(roll / 2)
    # (0, 0, sz, cz) * (0, sy, 0, cy)
    x = cz * 0.0 + cy * 0.0 + (0.0 * 0.0 - sz * sy)
    y = cz * sy + cy * 0.0 + (sz * 0.0 - 0.0 * 0.0)
    z = cz * 0.0 + cy * sz + (0.0 * sy - 0.0 * 0.0)
    w = cz * cy - 0.0 * 0.0 - 0.0 * sy - sz * 0.0
    # (x, y, z, w) * (sx, 0, 0, cx)
    x, y, z, w = (
        w * sx + cx * x + (y * 0.0 - z * 0.0),
        w * 0.0 + cx * y + (z * sx - x * 0.0),
        w * 0.0 + cx * z + (x * 0.0 - y * sx),
        w * cx - x * sx - y * 0.0 - z * 0.0,
    )
    return _matrix_of_quaternion(x, y, z, w)


def matrix_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    """Return the rotation matrix of a rotation vector (axis times angle, radians).

    ``Rotation.from_rotvec(rotvec).as_matrix()`` written out in plain floats, operation for
    operation as scipy computes it (its series below 1 mrad included), so the two agree bit
    for bit; a non-finite vector goes to scipy.
    """
    x, y, z = (float(v) for v in np.asarray(rotvec, dtype=float).reshape(3))
    angle = math.sqrt(x * x + y * y + z * z)
    if not math.isfinite(angle):
        return Rotation.from_rotvec([x, y, z]).as_matrix()
    if angle <= 1e-3:
        angle2 = angle * angle
        scale = 0.5 - angle2 / 48 + angle2 * angle2 / 3840
    else:
        scale = math.sin(angle / 2) / angle
    return _matrix_of_quaternion(scale * x, scale * y, scale * z, math.cos(angle / 2))


def _matrix_of_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The rotation matrix of a unit quaternion, as scipy's ``as_matrix`` computes it."""
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return np.array(
        [
            [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
            [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
            [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2],
        ]
    )


def deck_pose_in_camera(
    t_wb: np.ndarray,
    r_wb: np.ndarray,
    t_wp: np.ndarray,
    r_wp: np.ndarray,
    t_bc: np.ndarray,
    tag_offset_p: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(R_CD, t_CD)`` from the world poses of the body and the top plate.

    ``t_bc`` is the camera origin in the body frame; ``tag_offset_p`` the tag centre in the
    top-plate frame (default: the plate origin).
    """
    offset = np.zeros(3) if tag_offset_p is None else np.asarray(tag_offset_p, dtype=float)
    r_wc = r_wb @ R_BC
    t_wc = t_wb + r_wb @ t_bc
    r_wd = r_wp @ R_PD
    t_wd = t_wp + r_wp @ offset
    r_cd = r_wc.T @ r_wd
    t_cd = r_wc.T @ (t_wd - t_wc)
    return r_cd, t_cd


def tilt_deg(roll: np.ndarray | float, pitch: np.ndarray | float) -> np.ndarray:
    """The angle between a frame's z axis and the reference z axis for ZYX ``roll`` and
    ``pitch`` (rad; yaw does not tilt), degrees: the deck's tilt from level for the levelled
    pose, the tag's from the optical axis for the camera-frame one."""
    cosine = np.clip(np.cos(roll) * np.cos(pitch), -1.0, 1.0)
    return np.degrees(np.arccos(cosine))


def level_from_body(r_wb: np.ndarray) -> np.ndarray:
    """R_HB: the body frame in the levelled heading frame H (the drone's roll and pitch
    removed, its yaw kept), from the drone's attitude R_WB (an autopilot's estimate)."""
    roll, pitch, _ = euler_zyx_from_matrix(r_wb)
    return matrix_from_euler_zyx(roll, pitch, 0.0)


def levelled_deck_pose(deck_pose: np.ndarray, r_hb: np.ndarray) -> np.ndarray:
    """The deck pose (x, y, z, roll, pitch, yaw of T_CD) as a level camera would see it.

    The level camera C' is the camera of the same drone with its roll and pitch removed
    (``r_hb`` from :func:`level_from_body`): ``R_C'C = R_BC^T R_HB R_BC``.  Its roll and pitch
    are the deck's tilt relative to gravity, which is what the touchdown criterion judges;
    the camera-frame ones also hold the drone's own tilt (a few degrees in wind).  For a
    level drone the two poses are the same.
    """
    pose = np.asarray(deck_pose, dtype=float)
    r_lc = R_BC.T @ np.asarray(r_hb, dtype=float) @ R_BC
    r_cd = matrix_from_euler_zyx(*pose[3:6])
    return np.concatenate([r_lc @ pose[:3], euler_zyx_from_matrix(r_lc @ r_cd)])
