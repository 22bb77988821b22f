"""The quadrotor: vehicle parameters, its state, and its rotor/drag/ground-effect physics.

Frames follow :mod:`estimation.frames`: world W z-up, body B FLU with its origin at the centre of
mass.  PyBullet integrates the rigid body; this module adds, once per physics step, the rotor
thrusts and yaw torques (with a first-order motor lag), the linear body drag against the
air-relative velocity (see :mod:`landing_env.physics.wind`), and ground effect computed from the
surface actually under each rotor (one ray batch per step, so a moving deck at any height works).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pybullet as p
import yaml
from pybullet_utils.bullet_client import BulletClient
from scipy.spatial.transform import Rotation

from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.physics.wind import WindModel

#: the vehicle YAML shipped with the package
DEFAULT_PARAMS_PATH: Path = Path(__file__).resolve().parent.parent / "assets" / "quadrotor.yaml"

GRAVITY: float = 9.81

#: ``sanchez_cuevas``: the four-rotor model of Sanchez-Cuevas, Heredia & Ollero (2017),
#: *Characterization of the aerodynamic ground effect and its influence in multirotor
#: control*, Int. J. Aerospace Eng. 2017:1823056, Eq. (8):
#: T_IGE/T_OGE = 1 / (1 - (R/4z)^2 - R^2 z / (d^2 + 4z^2)^1.5 - (R^2/2) z / (2d^2 + 4z^2)^1.5
#:                    - 2 R^2 z K_b / (b^2 + 4z^2)^1.5)
#: with z the rotor's height, d the distance between adjacent rotors, b the arm length (rotor
#: to body centre) and K_b the body-lift coefficient fitted in the paper (2).  The first term
#: is the single-rotor Cheeseman-Bennett (1955) model, kept as ``cheeseman_bennett``.
_GROUND_EFFECT_MODELS = ("cheeseman_bennett", "sanchez_cuevas")


@dataclass(frozen=True)
class QuadrotorParams:
    """Vehicle parameters (SI units, body frame FLU); load them with :meth:`from_yaml`."""

    name: str
    urdf_path: Path
    #: total mass (kg) and principal inertia about the CoM (kg m^2, body axes)
    mass: float
    inertia_diag: np.ndarray
    #: horizontal distance from the CoM to each rotor hub (m)
    arm_length: float
    #: 4x3 rotor hub positions in B (m), order front-left, front-right, back-right, back-left
    rotor_positions_b: np.ndarray
    #: rotation sense of each rotor about body +z (+1 counter-clockwise seen from above)
    spin_directions: np.ndarray
    rotor_radius: float
    #: thrust k_f w^2 (N) and yaw reaction torque k_m w^2 (N m) of one rotor at w rad/s
    k_f: float
    k_m: float
    motor_time_constant: float
    omega_min: float
    omega_max: float
    #: linear body drag: force_b = -diag(linear_drag_b) v_air_b (N per m/s)
    linear_drag_b: np.ndarray
    ground_effect_enabled: bool
    ground_effect_model: str
    ground_effect_coefficient: float
    ground_effect_max_gain: float
    ground_effect_ray_length: float
    #: body-lift coefficient K_b of the sanchez_cuevas model
    ground_effect_body_coefficient: float
    #: landing gear: contact stiffness (N/m) and damping (N s/m) of each foot, friction
    #: coefficient foot-deck (see quadrotor.yaml for the sources)
    gear_stiffness: float
    gear_damping: float
    gear_friction: float
    #: camera origin in B (m); the camera looks down body -z
    camera_offset_b: np.ndarray
    #: body z of the ToF sensors (m) and their distance from the camera axis (m)
    tof_mount_z: float
    tof_arm_distance: float
    #: the part of ``linear_drag_b`` that is the airframe's own (arms, body, gear: it acts
    #: whatever the rotors do); the rest is rotor drag (blade flapping and induced drag), which
    #: grows with the rotor speed, so it is scaled by the mean rotor speed over the hover speed
    #: (at hover the whole ``linear_drag_b`` acts; with the motors cut to idle, little of the
    #: rotor part does).  1 keeps the whole drag whatever the rotor speed
    drag_airframe_fraction: float = 1.0

    def __post_init__(self) -> None:
        for name in ("inertia_diag", "rotor_positions_b", "spin_directions"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float))
        for name in ("linear_drag_b", "camera_offset_b"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float))
        object.__setattr__(self, "urdf_path", Path(self.urdf_path))
        self._validate()

    def _validate(self) -> None:
        if not self.urdf_path.is_file():
            raise ConfigError("urdf_path", f"{self.urdf_path} is not a file")
        require_range("mass", self.mass, 0.0, 100.0, low_inclusive=False)
        _require_shape("inertia_diag", self.inertia_diag, (3,))
        ixx, iyy, izz = self.inertia_diag
        if min(ixx, iyy, izz) <= 0.0:
            raise ConfigError("inertia_diag", "all three moments must be > 0")
        if ixx + iyy < izz or iyy + izz < ixx or izz + ixx < iyy:
            raise ConfigError("inertia_diag", "moments violate the triangle inequality")
        require_range("arm_length", self.arm_length, 0.0, 5.0, low_inclusive=False)
        _require_shape("rotor_positions_b", self.rotor_positions_b, (4, 3))
        radii = np.hypot(self.rotor_positions_b[:, 0], self.rotor_positions_b[:, 1])
        if np.max(np.abs(radii - self.arm_length)) > 1e-3:
            raise ConfigError(
                "rotor_positions_b", f"hubs must lie arm_length={self.arm_length} m from the CoM"
            )
        # The mixer shifts all four rotors by the same thrust to keep roll/pitch authority; that
        # leaves the torques unchanged only if the rotors' centroid is on the thrust axis.
        if np.max(np.abs(self.rotor_positions_b[:, :2].mean(axis=0))) > 1e-3:
            raise ConfigError(
                "rotor_positions_b", "the rotors' centroid must be on the body z axis"
            )
        _require_shape("spin_directions", self.spin_directions, (4,))
        if not np.all(np.isin(self.spin_directions, (-1.0, 1.0))) or self.spin_directions.sum():
            raise ConfigError("spin_directions", "need two rotors of +1 and two of -1")
        require_range(
            "rotor_radius",
            self.rotor_radius,
            0.0,
            self.arm_length,
            low_inclusive=False,
            bounds_from=f"arm_length = {self.arm_length}",
        )
        require_range("k_f", self.k_f, 0.0, low_inclusive=False)
        require_range("k_m", self.k_m, 0.0, low_inclusive=False)
        require_range(
            "motor_time_constant", self.motor_time_constant, 0.0, 1.0, low_inclusive=False
        )
        require_range("omega_min", self.omega_min, 0.0)
        require_range(
            "omega_max",
            self.omega_max,
            self.omega_min,
            low_inclusive=False,
            bounds_from=f"omega_min = {self.omega_min}",
        )
        if self.thrust_to_weight <= 1.0:
            raise ConfigError(
                "omega_max",
                f"thrust-to-weight {self.thrust_to_weight:.2f} must exceed 1 to hover",
            )
        _require_shape("linear_drag_b", self.linear_drag_b, (3,))
        if np.any(self.linear_drag_b < 0.0):
            raise ConfigError("linear_drag_b", "drag coefficients must be >= 0")
        require_range("drag_airframe_fraction", self.drag_airframe_fraction, 0.0, 1.0)
        require_choice("ground_effect_model", self.ground_effect_model, _GROUND_EFFECT_MODELS)
        require_range("ground_effect_coefficient", self.ground_effect_coefficient, 0.0, 10.0)
        require_range("ground_effect_max_gain", self.ground_effect_max_gain, 1.0, 10.0)
        require_range(
            "ground_effect_ray_length",
            self.ground_effect_ray_length,
            0.0,
            100.0,
            low_inclusive=False,
        )
        require_range(
            "ground_effect_body_coefficient", self.ground_effect_body_coefficient, 0.0, 10.0
        )
        # 0 = PyBullet's rigid contact; otherwise a few mm under a touchdown load
        require_range("gear_stiffness", self.gear_stiffness, 0.0, 1e7)
        require_range("gear_damping", self.gear_damping, 0.0, 1e5)
        if (self.gear_stiffness > 0.0) != (self.gear_damping > 0.0):
            raise ConfigError(
                "gear_damping", "stiffness and damping are both 0 (rigid) or both > 0"
            )
        require_range("gear_friction", self.gear_friction, 0.0, 5.0)
        _require_shape("camera_offset_b", self.camera_offset_b, (3,))
        require_range("tof_arm_distance", self.tof_arm_distance, 0.0, low_inclusive=False)

    @property
    def kf(self) -> float:
        """Alias of :attr:`k_f` (the name landing_env.world uses)."""
        return self.k_f

    @property
    def camera_offset(self) -> np.ndarray:
        """Alias of :attr:`camera_offset_b`, the camera origin t_bc in B (m)."""
        return self.camera_offset_b

    @property
    def weight(self) -> float:
        """Weight (N)."""
        return self.mass * GRAVITY

    @property
    def max_rotor_thrust(self) -> float:
        """Thrust of one rotor at omega_max (N)."""
        return self.k_f * self.omega_max**2

    @property
    def min_rotor_thrust(self) -> float:
        """Thrust of one rotor at omega_min (N)."""
        return self.k_f * self.omega_min**2

    @property
    def thrust_to_weight(self) -> float:
        """Total maximum thrust over weight."""
        return 4.0 * self.max_rotor_thrust / self.weight

    @property
    def hover_omega(self) -> float:
        """Rotor speed (rad/s) at which the four rotors carry the weight out of ground effect."""
        return math.sqrt(self.weight / (4.0 * self.k_f))

    @classmethod
    def from_yaml(cls, path: Path | None = None) -> QuadrotorParams:
        """Load and validate a vehicle YAML (default: the shipped ``quadrotor.yaml``)."""
        path = DEFAULT_PARAMS_PATH if path is None else Path(path)
        with path.open() as stream:
            data = yaml.safe_load(stream)
        if not isinstance(data, dict):
            raise ConfigError(str(path), "the file must hold a mapping")
        reader = _SectionReader(data, "")
        body = reader.section("body")
        rotors = reader.section("rotors")
        motors = reader.section("motors")
        drag = reader.section("drag")
        ground = reader.section("ground_effect")
        gear = reader.section("landing_gear")
        sensors = reader.section("sensors")
        try:
            params = cls(
                name=str(reader.get("name")),
                urdf_path=path.parent / str(reader.get("urdf")),
                mass=body.number("mass"),
                inertia_diag=body.get("inertia_diag"),
                arm_length=body.number("arm_length"),
                rotor_positions_b=rotors.get("positions_b"),
                spin_directions=rotors.get("spin_directions"),
                rotor_radius=rotors.number("radius"),
                k_f=motors.number("k_f"),
                k_m=motors.number("k_m"),
                motor_time_constant=motors.number("time_constant"),
                omega_min=motors.number("omega_min"),
                omega_max=motors.number("omega_max"),
                linear_drag_b=drag.get("linear_b"),
                drag_airframe_fraction=drag.number("airframe_fraction"),
                ground_effect_enabled=bool(ground.get("enabled")),
                ground_effect_model=str(ground.get("model")),
                ground_effect_coefficient=ground.number("coefficient"),
                ground_effect_max_gain=ground.number("max_gain"),
                ground_effect_ray_length=ground.number("ray_length"),
                ground_effect_body_coefficient=ground.number("body_coefficient"),
                gear_stiffness=gear.number("contact_stiffness"),
                gear_damping=gear.number("contact_damping"),
                gear_friction=gear.number("friction"),
                camera_offset_b=sensors.get("camera_offset_b"),
                tof_mount_z=sensors.number("tof_mount_z"),
                tof_arm_distance=sensors.number("tof_arm_distance"),
            )
        except ConfigError as error:
            # Name the key as it is spelt in the YAML, not the dataclass field.
            raise ConfigError(_YAML_KEYS.get(error.key, error.key), error.detail) from error
        except (TypeError, ValueError) as error:
            raise ConfigError(str(path), f"malformed value: {error}") from error
        for section in (reader, body, rotors, motors, drag, ground, gear, sensors):
            section.reject_unused()
        return params


#: dataclass field -> dotted YAML key, for error messages
_YAML_KEYS: dict[str, str] = {
    "urdf_path": "urdf",
    "mass": "body.mass",
    "inertia_diag": "body.inertia_diag",
    "arm_length": "body.arm_length",
    "rotor_positions_b": "rotors.positions_b",
    "spin_directions": "rotors.spin_directions",
    "rotor_radius": "rotors.radius",
    "k_f": "motors.k_f",
    "k_m": "motors.k_m",
    "motor_time_constant": "motors.time_constant",
    "omega_min": "motors.omega_min",
    "omega_max": "motors.omega_max",
    "linear_drag_b": "drag.linear_b",
    "drag_airframe_fraction": "drag.airframe_fraction",
    "ground_effect_model": "ground_effect.model",
    "ground_effect_coefficient": "ground_effect.coefficient",
    "ground_effect_max_gain": "ground_effect.max_gain",
    "ground_effect_ray_length": "ground_effect.ray_length",
    "ground_effect_body_coefficient": "ground_effect.body_coefficient",
    "gear_stiffness": "landing_gear.contact_stiffness",
    "gear_damping": "landing_gear.contact_damping",
    "gear_friction": "landing_gear.friction",
    "camera_offset_b": "sensors.camera_offset_b",
    "tof_arm_distance": "sensors.tof_arm_distance",
}


def _require_shape(key: str, value: np.ndarray, shape: tuple[int, ...]) -> None:
    if value.shape != shape or not np.all(np.isfinite(value)):
        raise ConfigError(key, f"needs finite values of shape {shape}, got shape {value.shape}")


class _SectionReader:
    """Reads one YAML mapping, naming missing or unknown keys by their dotted path."""

    def __init__(self, data: Any, prefix: str) -> None:
        if not isinstance(data, dict):
            raise ConfigError(prefix or "<root>", "must be a mapping")
        self._data = data
        self._prefix = prefix
        self._used: set[str] = set()

    def _key(self, key: str) -> str:
        return f"{self._prefix}.{key}" if self._prefix else key

    def get(self, key: str) -> Any:
        if key not in self._data:
            raise ConfigError(self._key(key), "is missing")
        self._used.add(key)
        return self._data[key]

    def number(self, key: str) -> float:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(self._key(key), f"{value!r} is not a number")
        return float(value)

    def section(self, key: str) -> _SectionReader:
        return _SectionReader(self.get(key), self._key(key))

    def reject_unused(self) -> None:
        unknown = sorted(set(self._data) - self._used)
        if unknown:
            raise ConfigError(self._key(unknown[0]), "is not a known key")


class StateFloats(NamedTuple):
    """A :class:`DroneState` as plain Python floats, for the per-physics-step code.

    Tiny numpy arrays cost far more to make and to index than tuples, and the controller,
    the motors and the IMU run 240 times per simulated second.
    """

    #: body-frame origin in W (m)
    position_w: tuple[float, ...]
    #: orientation of B in W as a quaternion (x, y, z, w)
    quaternion_xyzw: tuple[float, ...]
    #: R_WB row-major: (r00, r01, r02, r10, ..., r22)
    rotation_wb: tuple[float, ...]
    #: CoM velocity in W (m/s)
    velocity_w: tuple[float, ...]
    #: angular velocity in the BODY frame (rad/s)
    angular_velocity_b: tuple[float, ...]


class DroneState:
    """The drone's rigid-body state at one instant (read-only).

    The state is held as plain floats (:attr:`floats`); the numpy arrays below are built from
    them on first access and then kept, because most physics steps never look at them.
    """

    __slots__ = ("_arrays", "_euler", "floats")

    floats: StateFloats

    def __init__(
        self,
        position_w: np.ndarray,
        quaternion_xyzw: np.ndarray,
        rotation_wb: np.ndarray,
        velocity_w: np.ndarray,
        angular_velocity_b: np.ndarray,
        euler: np.ndarray | None = None,
    ) -> None:
        """A state from arrays (``euler`` defaults to the ZYX angles of ``rotation_wb``)."""
        self.floats = StateFloats(
            _float_tuple(position_w, 3),
            _float_tuple(quaternion_xyzw, 4),
            _float_tuple(rotation_wb, 9),
            _float_tuple(velocity_w, 3),
            _float_tuple(angular_velocity_b, 3),
        )
        self._euler: tuple[float, ...] | None = None if euler is None else _float_tuple(euler, 3)
        self._arrays: dict[str, np.ndarray] | None = None

    @classmethod
    def from_floats(cls, values: StateFloats) -> DroneState:
        """Wrap plain floats without copying (what :meth:`Quadrotor.read_state` uses)."""
        state = cls.__new__(cls)
        state.floats = values
        state._euler = None
        state._arrays = None
        return state

    def _array(self, name: str) -> np.ndarray:
        arrays = self._arrays
        if arrays is None:
            arrays = self._arrays = {}
        array = arrays.get(name)
        if array is None:
            if name == "rotation_wb":
                array = np.array(self.floats.rotation_wb).reshape(3, 3)
            elif name == "euler":
                array = np.array(self.euler_tuple)
            else:
                array = np.array(getattr(self.floats, name))
            arrays[name] = array
        return array

    @property
    def position_w(self) -> np.ndarray:
        """Body-frame origin in W (m): the base link's CoM, 0.7 mm above the vehicle's CoM."""
        return self._array("position_w")

    @property
    def quaternion_xyzw(self) -> np.ndarray:
        """Orientation of B in W as a quaternion (x, y, z, w)."""
        return self._array("quaternion_xyzw")

    @property
    def rotation_wb(self) -> np.ndarray:
        """R_WB (3, 3): columns are the body axes in W."""
        return self._array("rotation_wb")

    @property
    def velocity_w(self) -> np.ndarray:
        """CoM velocity in W (m/s)."""
        return self._array("velocity_w")

    @property
    def angular_velocity_b(self) -> np.ndarray:
        """Angular velocity in the BODY frame (rad/s), as a gyro measures it."""
        return self._array("angular_velocity_b")

    @property
    def euler(self) -> np.ndarray:
        """(roll, pitch, yaw) in radians, ZYX convention."""
        return self._array("euler")

    @property
    def euler_tuple(self) -> tuple[float, ...]:
        """:attr:`euler` as plain floats."""
        if self._euler is None:
            r00, _, _, r10, _, _, r20, r21, r22 = self.floats.rotation_wb
            self._euler = (
                math.atan2(r21, r22),
                math.asin(-r20 if -1.0 <= -r20 <= 1.0 else math.copysign(1.0, -r20)),
                math.atan2(r10, r00),
            )
        return self._euler

    @property
    def yaw(self) -> float:
        """Yaw (rad)."""
        if self._euler is not None:
            return self._euler[2]
        rotation = self.floats.rotation_wb
        return math.atan2(rotation[3], rotation[0])

    def __repr__(self) -> str:
        f = self.floats
        return (
            f"DroneState(position_w={f.position_w}, quaternion_xyzw={f.quaternion_xyzw}, "
            f"velocity_w={f.velocity_w}, angular_velocity_b={f.angular_velocity_b})"
        )


class Quadrotor:
    """One quadrotor body in a PyBullet world, driven by rotor speed commands."""

    def __init__(
        self,
        client: BulletClient,
        params: QuadrotorParams | None = None,
        wind: WindModel | None = None,
        position_w: tuple[float, float, float] = (0.0, 0.0, 1.0),
        yaw: float = 0.0,
    ) -> None:
        self.client = client
        self.params = QuadrotorParams.from_yaml() if params is None else params
        self.wind = wind
        # The hot path calls pybullet's module functions with the client id directly: going
        # through BulletClient's attribute lookup costs about a microsecond per call.
        self._cid: int = client._client
        self.body_id: int = client.loadURDF(
            str(self.params.urdf_path),
            basePosition=position_w,
            baseOrientation=client.getQuaternionFromEuler((0.0, 0.0, yaw)),
            flags=p.URDF_USE_INERTIA_FROM_FILE,
        )
        feet = []
        for joint in range(client.getNumJoints(self.body_id)):
            info = client.getJointInfo(self.body_id, joint)
            if info[12].decode().startswith("foot"):
                feet.append(joint)
        #: link indices of the four landing feet (front, left, back, right)
        self.foot_link_indices: tuple[int, ...] = tuple(feet)
        # PyBullet's default linear/angular damping would be a second, unmodelled drag.
        for link in (-1, *feet):
            client.changeDynamics(self.body_id, link, linearDamping=0.0, angularDamping=0.0)
        self._apply_landing_gear()

        #: the whole body's centre of mass in the base frame (m): the feet lower it slightly
        self.com_offset_b: tuple[float, float, float] = self._combined_com_offset()
        prm = self.params
        self._zero3 = (0.0, 0.0, 0.0)
        self._nan4 = (math.nan, math.nan, math.nan, math.nan)
        # Plain-float copies of the parameters for the per-step path, refreshed by
        # _sync_constants whenever ``params`` is replaced or the step length changes.
        self._constants_for: tuple[QuadrotorParams, float] | None = None
        self._alpha = 0.0
        self._k_f = 0.0
        self._omega_range = (0.0, 0.0)
        self._rotor_terms: tuple[tuple[float, float, float], ...] = ()
        self._rotors: tuple[tuple[float, float, float], ...] = ()
        self._drag = self._zero3
        self._ground_effect_on = False
        self._ge_const = 0.0
        self._ge_min_denominator = 1.0
        self._ge_max_gain = 1.0
        self._ge_ray_length = 0.0

        #: True while the motors respond to commands; disarmed rotors spin down to zero
        self.armed: bool = True
        #: time advanced by :meth:`apply_rotor_commands` (s); drives the wind model
        self.time: float = 0.0
        self._omega = [prm.hover_omega] * 4
        #: True when the last command had a rotor outside [omega_min, omega_max] (it was clamped)
        self.last_saturated: bool = False
        #: per-rotor thrust applied in the last step (N), ground effect included
        self.last_thrusts: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)
        #: per-rotor distance from the hub to the surface below along body -z (m); NaN: none
        self.last_ground_heights: tuple[float, ...] = self._nan4
        #: per-rotor thrust gain T_IGE/T_OGE of the last step
        self.last_ground_effect_gains: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
        #: True when a rotor's ground-effect gain hit ground_effect_max_gain in the last step
        self.last_ground_effect_capped: bool = False
        #: wind velocity (m/s, W) used when no WindModel is attached: set it before each
        #: apply_rotor_commands to drive the wind from outside
        self.wind_velocity_w: np.ndarray | tuple[float, float, float] = self._zero3
        #: wind velocity (m/s, W) used for the drag in the last step
        self.last_wind_w: tuple[float, float, float] = self._zero3

    def _apply_landing_gear(self) -> None:
        """Give each foot its contact stiffness, damping and friction (quadrotor.yaml).

        Bullet turns stiffness k and damping c into a soft constraint (ERP = dt k / (dt k + c),
        CFM = 1 / (dt k + c)); restitution stays 0, the energy loss is the damping's.
        """
        prm = self.params
        for link in self.foot_link_indices:
            if prm.gear_stiffness > 0.0:
                self.client.changeDynamics(
                    self.body_id,
                    link,
                    contactStiffness=prm.gear_stiffness,
                    contactDamping=prm.gear_damping,
                    lateralFriction=prm.gear_friction,
                    restitution=0.0,
                )
            else:
                self.client.changeDynamics(
                    self.body_id, link, lateralFriction=prm.gear_friction, restitution=0.0
                )

    def _combined_com_offset(self) -> tuple[float, float, float]:
        """Centre of mass of base and feet together, in the base frame."""
        client = self.client
        base_pos, base_quat = client.getBasePositionAndOrientation(self.body_id)
        rotation = np.array(client.getMatrixFromQuaternion(base_quat)).reshape(3, 3)
        total = client.getDynamicsInfo(self.body_id, -1)[0]
        moment = np.zeros(3)
        for link in self.foot_link_indices:
            mass = client.getDynamicsInfo(self.body_id, link)[0]
            centre = np.array(client.getLinkState(self.body_id, link)[0]) - base_pos
            moment += mass * (rotation.T @ centre)
            total += mass
        offset = moment / total
        if math.hypot(offset[0], offset[1]) > 1e-6:
            raise ConfigError("urdf", "the feet must not move the CoM off the body z axis")
        return (0.0, 0.0, float(offset[2]))

    # ------------------------------------------------------------------ state

    def reset(
        self,
        position_w: np.ndarray | tuple[float, float, float],
        yaw: float,
        velocity_w: np.ndarray | tuple[float, float, float] | None = None,
        rotation_wb: np.ndarray | None = None,
    ) -> None:
        """Put the drone level at ``position_w`` (m, W) with ``yaw`` (rad), rotors at hover;
        ``rotation_wb`` (a rotation matrix) replaces the level attitude."""
        position = [float(v) for v in position_w]
        velocity = self._zero3 if velocity_w is None else [float(v) for v in velocity_w]
        quaternion = (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw))
        if rotation_wb is not None:
            quaternion = tuple(float(v) for v in Rotation.from_matrix(rotation_wb).as_quat())
        self.client.resetBasePositionAndOrientation(self.body_id, position, quaternion)
        self.client.resetBaseVelocity(self.body_id, velocity, self._zero3)
        self._omega = [self.params.hover_omega] * 4
        self.armed = True
        self.last_saturated = False
        self.last_thrusts = (0.0, 0.0, 0.0, 0.0)
        self.last_ground_heights = self._nan4
        self.last_ground_effect_gains = (1.0, 1.0, 1.0, 1.0)
        self.last_ground_effect_capped = False

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Current (lagged) rotor speeds (rad/s)."""
        return np.array(self._omega)

    def set_rotor_speeds(self, omega: np.ndarray | list[float]) -> None:
        """Set the actual rotor speeds (rad/s) directly, e.g. for a test or a warm start."""
        self._omega = [float(v) for v in omega]

    def read_state(self) -> DroneState:
        """Query PyBullet (one pose and one velocity call) and return the state."""
        cid = self._cid
        pos, quat = p.getBasePositionAndOrientation(self.body_id, physicsClientId=cid)
        vel, (wx, wy, wz) = p.getBaseVelocity(self.body_id, physicsClientId=cid)
        rot = _rotation_from_quaternion(quat)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot
        omega_b = (
            r00 * wx + r10 * wy + r20 * wz,
            r01 * wx + r11 * wy + r21 * wz,
            r02 * wx + r12 * wy + r22 * wz,
        )
        return DroneState.from_floats(StateFloats(pos, quat, rot, vel, omega_b))

    # ---------------------------------------------------------------- actuation

    def _sync_constants(self, dt: float) -> None:
        """Copy the parameters the per-step path needs into plain floats."""
        prm = self.params
        self._constants_for = (prm, dt)
        # Exact discretisation of the first-order motor lag over one step.
        self._alpha = 1.0 - math.exp(-dt / prm.motor_time_constant)
        self._k_f = float(prm.k_f)
        self._omega_range = (float(prm.omega_min), float(prm.omega_max))
        self._rotors = tuple(
            (float(x), float(y), float(z)) for x, y, z in prm.rotor_positions_b.tolist()
        )
        # per rotor: hub x, hub y (m) and the yaw reaction torque per (rad/s)^2 (N m)
        self._rotor_terms = tuple(
            (x, y, -float(spin) * prm.k_m)
            for (x, y, _), spin in zip(self._rotors, prm.spin_directions.tolist(), strict=True)
        )
        d0, d1, d2 = prm.linear_drag_b.tolist()
        self._drag = (float(d0), float(d1), float(d2))
        # drag = linear_b (airframe + (1 - airframe) * mean rotor speed / hover speed)
        self._drag_airframe = float(prm.drag_airframe_fraction)
        self._drag_per_omega = (1.0 - self._drag_airframe) / (4.0 * float(prm.hover_omega))
        self._ground_effect_on = bool(prm.ground_effect_enabled)
        self._ge_const = prm.ground_effect_coefficient * (prm.rotor_radius / 4.0) ** 2
        self._ge_multirotor = prm.ground_effect_model == "sanchez_cuevas"
        hubs = prm.rotor_positions_b[:, :2]
        gaps = np.linalg.norm(hubs[:, None, :] - hubs[None, :, :], axis=-1)
        adjacent = float(np.min(gaps[gaps > 1e-9]))
        r2 = float(prm.rotor_radius) ** 2
        # (d^2, 2 d^2, b^2, R^2, R^2 / 2, 2 K_b R^2) of the four-rotor model
        self._ge_terms = (
            adjacent**2,
            2.0 * adjacent**2,
            float(prm.arm_length) ** 2,
            r2,
            0.5 * r2,
            2.0 * float(prm.ground_effect_body_coefficient) * r2,
        )
        self._ge_min_denominator = 1.0 / prm.ground_effect_max_gain
        self._ge_max_gain = float(prm.ground_effect_max_gain)
        self._ge_ray_length = float(prm.ground_effect_ray_length)

    def apply_rotor_commands(
        self, omega_cmd: np.ndarray | list[float], dt: float, state: DroneState | None = None
    ) -> None:
        """Advance the motors by ``dt`` towards ``omega_cmd`` (rad/s) and apply this step's forces.

        Commands are clamped to [omega_min, omega_max] and ``last_saturated`` reports it.  The
        forces hold for the next ``stepSimulation`` only (PyBullet clears them).  ``state``:
        the state read this step, which saves the pose queries; ``None`` queries PyBullet.
        """
        constants_for = self._constants_for
        if constants_for is None or constants_for[0] is not self.params or constants_for[1] != dt:
            self._sync_constants(dt)
        alpha = self._alpha
        omega = self._omega
        saturated = False
        if self.armed:
            lo, hi = self._omega_range
            commands = omega_cmd.tolist() if isinstance(omega_cmd, np.ndarray) else omega_cmd
            for i in range(4):
                c = commands[i]
                if c < lo:
                    c = lo
                    saturated = True
                elif c > hi:
                    c = hi
                    saturated = True
                elif c != c:  # NaN: a broken controller; hold idle and say so
                    c = lo
                    saturated = True
                omega[i] += (c - omega[i]) * alpha
        else:
            for i in range(4):
                omega[i] -= omega[i] * alpha
        self.last_saturated = saturated

        # Pose and velocity: the state read this step when given.
        if state is not None:
            floats = state.floats
            pos = floats.position_w
            rot = floats.rotation_wb
            vel = floats.velocity_w
        else:
            cid = self._cid
            pos, quat = p.getBasePositionAndOrientation(self.body_id, physicsClientId=cid)
            vel = p.getBaseVelocity(self.body_id, physicsClientId=cid)[0]
            rot = _rotation_from_quaternion(quat)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot

        k_f = self._k_f
        thrusts = [k_f * w * w for w in omega]
        if self._ground_effect_on:
            gains = self._ground_effect(pos, rot)
            if gains is not None:
                thrusts = [t * g for t, g in zip(thrusts, gains, strict=True)]
        fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for t, w, (x, y, yaw_coeff) in zip(thrusts, omega, self._rotor_terms, strict=True):
            fz += t
            tx += y * t  # r x (0, 0, T) = (y T, -x T, 0)
            ty -= x * t
            tz += yaw_coeff * w * w
        self.last_thrusts = tuple(thrusts)

        # Linear drag against the air-relative velocity, in the body frame.
        self.time += dt
        if self.wind is not None:
            wind = self.wind.velocity_tuple(self.time, dt)
        else:
            outside = self.wind_velocity_w
            ox, oy, oz = outside.tolist() if isinstance(outside, np.ndarray) else outside
            wind = (float(ox), float(oy), float(oz))
        self.last_wind_w = wind
        ax = vel[0] - wind[0]
        ay = vel[1] - wind[1]
        az = vel[2] - wind[2]
        d0, d1, d2 = self._drag
        # the rotor drag grows with the rotor speed (Mahony, Kumar & Corke 2012), the
        # airframe's does not: at hover the scale is 1
        scale = self._drag_airframe + self._drag_per_omega * (
            omega[0] + omega[1] + omega[2] + omega[3]
        )
        fx = -scale * d0 * (r00 * ax + r10 * ay + r20 * az)
        fy = -scale * d1 * (r01 * ax + r11 * ay + r21 * az)
        fz -= scale * d2 * (r02 * ax + r12 * ay + r22 * az)

        # The net force acts at the whole body's CoM (drag through the CoM, as modelled); the
        # thrusts' torques about it equal the torques computed above because the CoM lies on
        # the body z axis, parallel to the thrusts.  One force and one torque call replace
        # four per-rotor forces.
        cid = self._cid
        p.applyExternalForce(
            self.body_id, -1, (fx, fy, fz), self.com_offset_b, p.LINK_FRAME, physicsClientId=cid
        )
        p.applyExternalTorque(self.body_id, -1, (tx, ty, tz), p.LINK_FRAME, physicsClientId=cid)

    def _ground_effect(self, pos: Any, rot: Any) -> list[float] | None:
        """Per-rotor T_IGE/T_OGE from one ray batch down body -z from the four hubs.

        ``None`` when no ray hits anything (all gains 1, the usual case in flight).
        """
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot
        px, py, pz = pos
        length = self._ge_ray_length
        dx = -length * r02
        dy = -length * r12
        dz = -length * r22
        starts = [
            (
                px + r00 * x + r01 * y + r02 * z,
                py + r10 * x + r11 * y + r12 * z,
                pz + r20 * x + r21 * y + r22 * z,
            )
            for x, y, z in self._rotors
        ]
        ends = [(hx + dx, hy + dy, hz + dz) for hx, hy, hz in starts]
        # The hubs lie outside the drone's collision shapes (frame box and feet), so the rays
        # start at the hubs; a hit on the drone itself is ignored all the same.
        hits = p.rayTestBatch(starts, ends, physicsClientId=self._cid)
        body = self.body_id
        for hit in hits:
            if hit[0] >= 0 and hit[0] != body:
                break
        else:
            # Nothing within reach (the usual case in flight).
            self.last_ground_heights = self._nan4
            self.last_ground_effect_gains = (1.0, 1.0, 1.0, 1.0)
            self.last_ground_effect_capped = False
            return None
        heights = []
        gains = []
        capped = False
        const = self._ge_const
        min_den = self._ge_min_denominator
        for hit in hits:
            if hit[0] < 0 or hit[0] == body:
                heights.append(math.nan)
                gains.append(1.0)
                continue
            h = hit[2] * length
            heights.append(h)
            # Cheeseman–Bennett: T_IGE/T_OGE = 1/(1 - c (R/4h)^2), which diverges at h = R/4
            # (c = 1); the gain is capped at max_gain and the cap is flagged.
            denominator = 1.0 - const / (h * h) if h > 0.0 else -1.0
            if self._ge_multirotor and h > 0.0:
                # Sanchez-Cuevas et al. (2017): the neighbours' and the body's images too
                d2, d2x2, b2, r2, r2_half, body = self._ge_terms
                four_h2 = 4.0 * h * h
                denominator -= (
                    r2 * h / (d2 + four_h2) ** 1.5
                    + r2_half * h / (d2x2 + four_h2) ** 1.5
                    + body * h / (b2 + four_h2) ** 1.5
                )
            if denominator <= min_den:
                gains.append(self._ge_max_gain)
                capped = True
            else:
                gains.append(1.0 / denominator)
        self.last_ground_heights = tuple(heights)
        self.last_ground_effect_gains = tuple(gains)
        self.last_ground_effect_capped = capped
        return gains


def _float_tuple(value: Any, size: int) -> tuple[float, ...]:
    """``value`` (array-like of ``size`` numbers, any shape) as a tuple of floats."""
    return tuple(np.asarray(value, dtype=float).reshape(size).tolist())


def _rotation_from_quaternion(q: Any) -> tuple[float, ...]:
    """Row-major R_WB (9 floats) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    xx = x * x
    yy = y * y
    zz = z * z
    xy = x * y
    xz = x * z
    yz = y * z
    wx = w * x
    wy = w * y
    wz = w * z
    return (
        1.0 - 2.0 * (yy + zz),
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        1.0 - 2.0 * (xx + zz),
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        1.0 - 2.0 * (xx + yy),
    )
