"""LANDING_TARGET (MAVLink common, #149) fields of a deck-pose estimate, per autopilot.

The estimators give ``T_CD``: the tag frame D in the camera frame C (:mod:`estimation.frames`).
PX4 and ArduPilot read LANDING_TARGET in different frames, so the same estimate becomes
different fields for each.  Frames used here, besides those of :mod:`estimation.frames`:

* ``FRD`` body: x forward, y right, z down; ``v_FRD = S v_B`` with ``S = diag(1, -1, -1)``
  (B is FLU).
* ``NED`` local: x north, y east, z down, fixed to the autopilot's local origin.  The
  simulator's world W has x north(-ish), y left, z up, so ``p_NED = S p_W`` and
  ``R_NED,FRD = S R_WB S``.
* ``F`` deck FRD: origin at the tag centre, x to the deck's bow, y to starboard, z down into
  the deck.  It is D turned about its z axis: ``x_F = -y_D``, ``y_F = x_D``, ``z_F = z_D``
  (``R_DF`` below).  A level drone at zero yaw over a level deck sees ``F`` aligned with its
  own FRD axes, so ``q = (1, 0, 0, 0)`` there.

What each autopilot reads (the public sources, read to learn the conventions):

* **PX4** (``src/modules/mavlink/mavlink_receiver.cpp``,
  ``MavlinkReceiver::handle_message_landing_target`` in github.com/PX4/PX4-Autopilot): only
  ``position_valid = 1`` with ``frame = MAV_FRAME_LOCAL_NED`` is used; x, y, z become the
  target's *absolute* position in the local NED frame (``landing_target_pose.x_abs`` ...,
  "relative to origin", docs.px4.io/main/en/msg_docs/LandingTargetPose), stamped with
  ``time_usec`` mapped through the TIMESYNC offset once that has converged, else on receipt
  (``Timesync::sync_stamp``, ``src/lib/timesync/Timesync.cpp``): ``time_usec`` stays on the
  companion's clock and PX4 converts it (:mod:`agents.io.timesync`).  Another frame with
  ``position_valid = 1`` is refused ("coordinate frame unsupported"); ``position_valid = 0`` is
  read as an IR-LOCK report of angles.  q is not read.  So PX4 needs the vehicle's attitude and
  local position at the measurement's time (:class:`VehiclePose`) to place the target.  PX4
  "assumes that the target is visible when it is receiving MAVLink LANDING_TARGET messages"
  (docs.px4.io/main/en/advanced_features/precland).
* **ArduPilot** (``libraries/AC_PrecLand/AC_PrecLand_MAVLink.cpp``,
  ``AC_PrecLand_MAVLink::handle_msg``, and ``AC_PrecLand.cpp`` in github.com/ArduPilot/ardupilot;
  ardupilot.org/dev/docs/mavlink-precision-landing.html): with ``position_valid = 1`` it
  takes ``frame = MAV_FRAME_BODY_FRD`` (newer versions also ``MAV_FRAME_LOCAL_FRD``) and the
  unit line-of-sight vector ``(x, y, z) / distance``; ``distance`` must be positive (else the
  message is dropped).  The vector is from the *camera*: the camera's offset is the parameter
  ``PLND_CAM_POS_X/Y/Z`` (body FRD, metres), and with ``PLND_ORIENT`` at its default 25
  (down, ``ROTATION_PITCH_270``) and ``PLND_YAW_ALIGN = 0`` the vector is used as body FRD
  without further rotation.  It rotates the vector to NED with the attitude ``PLND_LAG``
  seconds before receipt: ``time_usec`` and q are not read ("does not need to be
  synchronised").  ``position_valid = 0`` means ``angle_x``/``angle_y`` hold the measurement.

Since ``position_valid = 0`` is a *measurement* for both autopilots, an invalid estimate is
never sent (see :mod:`agents.io.mavlink`).  ``q`` is the MAVLink order ``(w, x, y, z)``: the
rotation from the deck frame F to the message's frame, scalar part non-negative.
``angle_x``/``angle_y`` are filled for both: ``atan(x_C / z_C)`` and ``atan(y_C / z_C)``, the
target's angular offset from the image centre, which is what ArduPilot's angle path expects
(its line of sight ``(-tan angle_y, tan angle_x, 1)`` in FRD).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from estimation.errors import ConfigError, require_choice
from estimation.frames import R_BC

#: the autopilots the bridge speaks to
AUTOPILOTS: tuple[str, ...] = ("px4", "ardupilot")

#: MAV_FRAME values (MAVLink common): the frames the autopilots read LANDING_TARGET in
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_FRD = 12
#: LANDING_TARGET_TYPE_VISION_FIDUCIAL: a fiducial (the AprilTag) seen by a camera
LANDING_TARGET_TYPE_VISION_FIDUCIAL = 2

#: FLU <-> FRD (and world FLU-like <-> NED): flip y and z; its own inverse
S_FLIP: np.ndarray = np.diag([1.0, -1.0, -1.0])

#: the deck FRD frame F's axes in the tag frame D (columns): x_F = -y_D, y_F = x_D, z_F = z_D
R_DF: np.ndarray = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraMount:
    """The camera's extrinsics in the body frame B (FLU): ``r_bc`` (C's axes in B, columns)
    and ``t_bc`` (the camera origin in B, metres).  The default is the project's camera
    looking down with the image top to the nose, at the body origin."""

    r_bc: np.ndarray = field(default_factory=lambda: R_BC.copy())
    t_bc: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        r_bc = np.asarray(self.r_bc, dtype=float)
        t_bc = np.asarray(self.t_bc, dtype=float)
        if r_bc.shape != (3, 3) or not np.all(np.isfinite(r_bc)):
            raise ConfigError("camera mount r_bc", f"must be a finite 3x3 rotation, got {r_bc}")
        if not np.allclose(r_bc.T @ r_bc, np.eye(3), atol=1e-6) or np.linalg.det(r_bc) < 0:
            raise ConfigError("camera mount r_bc", "must be a proper rotation (R^T R = I, det +1)")
        if t_bc.shape != (3,) or not np.all(np.isfinite(t_bc)):
            raise ConfigError("camera mount t_bc", f"must be 3 finite metres, got {t_bc}")
        object.__setattr__(self, "r_bc", r_bc)
        object.__setattr__(self, "t_bc", t_bc)

    @property
    def t_bc_frd(self) -> np.ndarray:
        """The camera origin in body FRD: ArduPilot's ``PLND_CAM_POS_X/Y/Z``."""
        return S_FLIP @ self.t_bc


@dataclass(frozen=True)
class VehiclePose:
    """The vehicle in the autopilot's local NED frame: the body origin (metres) and the body
    FRD axes in NED (columns), at one instant."""

    position_ned_m: np.ndarray
    rotation_ned_frd: np.ndarray

    @classmethod
    def from_world(cls, t_wb: np.ndarray, r_wb: np.ndarray) -> VehiclePose:
        """From the simulator's world pose of the body (W: x north, y left, z up; B: FLU)."""
        t_wb = np.asarray(t_wb, dtype=float)
        r_wb = np.asarray(r_wb, dtype=float)
        return cls(S_FLIP @ t_wb, S_FLIP @ r_wb @ S_FLIP)


@dataclass(frozen=True)
class LandingTargetFields:
    """The geometric fields of one LANDING_TARGET (float64 here; the wire holds float32)."""

    frame: int
    x: float
    y: float
    z: float
    #: (w, x, y, z): the deck frame F in the message's frame
    q: tuple[float, float, float, float]
    distance: float
    angle_x: float
    angle_y: float


def quaternion_wxyz(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """A rotation matrix as MAVLink's quaternion ``(w, x, y, z)`` with ``w >= 0``."""
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    sign = -1.0 if w < 0.0 else 1.0
    return (sign * float(w), sign * float(x), sign * float(y), sign * float(z))


def _fields(
    frame: int, point: np.ndarray, r_axes_c: np.ndarray, r_cd: np.ndarray, t_cd: np.ndarray
) -> LandingTargetFields:
    """The fields of the tag centre at ``point`` in ``frame``, whose axes are ``r_axes_c``
    from the camera's: q is the deck frame F in them; distance and angles from ``t_cd``."""
    return LandingTargetFields(
        frame=frame,
        x=float(point[0]),
        y=float(point[1]),
        z=float(point[2]),
        q=quaternion_wxyz(r_axes_c @ np.asarray(r_cd, dtype=float) @ R_DF),
        distance=float(np.linalg.norm(t_cd)),
        angle_x=math.atan2(float(t_cd[0]), float(t_cd[2])),
        angle_y=math.atan2(float(t_cd[1]), float(t_cd[2])),
    )


def ardupilot_fields(r_cd: np.ndarray, t_cd: np.ndarray, mount: CameraMount) -> LandingTargetFields:
    """ArduPilot: the tag centre from the camera origin in body FRD axes (MAV_FRAME_BODY_FRD),
    ``distance = |t_CD|``; q is the deck frame F in body FRD (ArduPilot does not read it)."""
    t_cd = np.asarray(t_cd, dtype=float)
    r_frd_c = S_FLIP @ mount.r_bc
    return _fields(MAV_FRAME_BODY_FRD, r_frd_c @ t_cd, r_frd_c, r_cd, t_cd)


def px4_fields(
    r_cd: np.ndarray, t_cd: np.ndarray, mount: CameraMount, vehicle: VehiclePose
) -> LandingTargetFields:
    """PX4: the tag centre's absolute position in the local NED frame (MAV_FRAME_LOCAL_NED),
    ``p = p_vehicle + R_NED,FRD S (t_BC + R_BC t_CD)``; q is the deck frame F in NED."""
    t_cd = np.asarray(t_cd, dtype=float)
    r_ned_b = vehicle.rotation_ned_frd @ S_FLIP  # FLU body axes in NED
    position = vehicle.position_ned_m + r_ned_b @ (mount.t_bc + mount.r_bc @ t_cd)
    return _fields(MAV_FRAME_LOCAL_NED, position, r_ned_b @ mount.r_bc, r_cd, t_cd)


def landing_target_fields(
    autopilot: str,
    r_cd: np.ndarray,
    t_cd: np.ndarray,
    mount: CameraMount,
    vehicle: VehiclePose | None = None,
) -> LandingTargetFields:
    """The fields ``autopilot`` reads for the deck pose ``(R_CD, t_CD)``; PX4 needs ``vehicle``
    (the pose at the measurement's time)."""
    require_choice("autopilot", autopilot, AUTOPILOTS)
    if autopilot == "ardupilot":
        return ardupilot_fields(r_cd, t_cd, mount)
    if vehicle is None:
        raise ConfigError(
            "vehicle pose",
            "px4 reads LANDING_TARGET in MAV_FRAME_LOCAL_NED, which needs the vehicle's "
            "attitude and local position at the measurement's time; none was given",
        )
    return px4_fields(r_cd, t_cd, mount, vehicle)


def ardupilot_parameters(mount: CameraMount) -> dict[str, float]:
    """The ArduPilot parameters under which :func:`ardupilot_fields` reads right: MAVLink
    precision landing, the vector taken as body FRD (orientation down, no yaw alignment:
    the camera's rotation is applied here), the camera's offset in body FRD."""
    x, y, z = (float(v) for v in mount.t_bc_frd)
    return {
        "PLND_ENABLED": 1,
        "PLND_TYPE": 1,
        "PLND_ORIENT": 25,
        "PLND_YAW_ALIGN": 0,
        "PLND_CAM_POS_X": x,
        "PLND_CAM_POS_Y": y,
        "PLND_CAM_POS_Z": z,
    }
