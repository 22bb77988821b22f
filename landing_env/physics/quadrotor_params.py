"""The quadrotor's parameters: the vehicle YAML read, checked and held as SI values.

:class:`QuadrotorParams` is what :class:`~landing_env.physics.quadrotor.Quadrotor` flies and
what the controller and the sensors' mounts read; :meth:`QuadrotorParams.from_yaml` loads the
shipped ``quadrotor.yaml`` (or another vehicle) and names a missing, unknown or out-of-range
key by its dotted YAML path.  Frames follow :mod:`estimation.frames` (body B FLU, origin at
the centre of mass).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice, require_range

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
    mass: float = limited(limit=Limit(0.0, 100.0, low_inclusive=False))
    inertia_diag: np.ndarray
    #: horizontal distance from the CoM to each rotor hub (m)
    arm_length: float = limited(limit=Limit(0.0, 5.0, low_inclusive=False))
    #: 4x3 rotor hub positions in B (m), order front-left, front-right, back-right, back-left
    rotor_positions_b: np.ndarray
    #: rotation sense of each rotor about body +z (+1 counter-clockwise seen from above)
    spin_directions: np.ndarray
    rotor_radius: float
    #: thrust k_f w^2 (N) and yaw reaction torque k_m w^2 (N m) of one rotor at w rad/s
    k_f: float = limited(limit=POSITIVE)
    k_m: float = limited(limit=POSITIVE)
    motor_time_constant: float = limited(limit=Limit(0.0, 1.0, low_inclusive=False))
    omega_min: float = limited(limit=NON_NEGATIVE)
    omega_max: float
    #: linear body drag: force_b = -diag(linear_drag_b) v_air_b (N per m/s)
    linear_drag_b: np.ndarray
    ground_effect_enabled: bool
    ground_effect_model: str
    ground_effect_coefficient: float = limited(limit=Limit(0.0, 10.0))
    ground_effect_max_gain: float = limited(limit=Limit(1.0, 10.0))
    ground_effect_ray_length: float = limited(limit=Limit(0.0, 100.0, low_inclusive=False))
    #: body-lift coefficient K_b of the sanchez_cuevas model
    ground_effect_body_coefficient: float = limited(limit=Limit(0.0, 10.0))
    #: landing gear: contact stiffness (N/m) and damping (N s/m) of each foot, friction
    #: coefficient foot-deck (see quadrotor.yaml for the sources)
    gear_stiffness: float = limited(limit=Limit(0.0, 1e7))
    gear_damping: float = limited(limit=Limit(0.0, 1e5))
    gear_friction: float = limited(limit=Limit(0.0, 5.0))
    #: camera origin in B (m); the camera looks down body -z
    camera_offset_b: np.ndarray
    #: body z of the ToF sensors (m) and their distance from the camera axis (m)
    tof_mount_z: float
    tof_arm_distance: float = limited(limit=POSITIVE)
    #: the part of ``linear_drag_b`` that is the airframe's own (arms, body, gear: it acts
    #: whatever the rotors do); the rest is rotor drag (blade flapping and induced drag), which
    #: grows with the rotor speed, so it is scaled by the mean rotor speed over the hover speed
    #: (at hover the whole ``linear_drag_b`` acts; with the motors cut to idle, little of the
    #: rotor part does).  1 keeps the whole drag whatever the rotor speed
    drag_airframe_fraction: float = limited(1.0, Limit(0.0, 1.0))

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
        require_limits(self)
        _require_shape("inertia_diag", self.inertia_diag, (3,))
        ixx, iyy, izz = self.inertia_diag
        if min(ixx, iyy, izz) <= 0.0:
            raise ConfigError("inertia_diag", "all three moments must be > 0")
        if ixx + iyy < izz or iyy + izz < ixx or izz + ixx < iyy:
            raise ConfigError("inertia_diag", "moments violate the triangle inequality")
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
        require_choice("ground_effect_model", self.ground_effect_model, _GROUND_EFFECT_MODELS)
        # 0 = PyBullet's rigid contact; otherwise a few mm under a touchdown load
        if (self.gear_stiffness > 0.0) != (self.gear_damping > 0.0):
            raise ConfigError(
                "gear_damping", "stiffness and damping are both 0 (rigid) or both > 0"
            )
        _require_shape("camera_offset_b", self.camera_offset_b, (3,))

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
        kwargs = {f.name: _read(data, _YAML_KEYS[f.name], f.type) for f in fields(cls)}
        kwargs["urdf_path"] = path.parent / kwargs["urdf_path"]
        try:
            params = cls(**kwargs)
        except ConfigError as error:
            # Name the key as it is spelt in the YAML, not the dataclass field.
            raise ConfigError(_YAML_KEYS.get(error.key, error.key), error.detail) from error
        except (TypeError, ValueError) as error:
            raise ConfigError(str(path), f"malformed value: {error}") from error
        sections = dict.fromkeys(key.rpartition(".")[0] for key in _YAML_KEYS.values())
        for section in sections:
            keys = (key.rpartition(".") for key in _YAML_KEYS.values())
            known = {name for within, _, name in keys if within == section}
            mapping = data[section] if section else data
            unknown = sorted(set(mapping) - known - (set(sections) if not section else set()))
            if unknown:
                raise ConfigError(_join(section, unknown[0]), "is not a known key")
        return params


#: dataclass field -> dotted YAML key (the file's layout), for reading and for error messages
_YAML_KEYS: dict[str, str] = {
    "name": "name",
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
    "ground_effect_enabled": "ground_effect.enabled",
    "ground_effect_model": "ground_effect.model",
    "ground_effect_coefficient": "ground_effect.coefficient",
    "ground_effect_max_gain": "ground_effect.max_gain",
    "ground_effect_ray_length": "ground_effect.ray_length",
    "ground_effect_body_coefficient": "ground_effect.body_coefficient",
    "gear_stiffness": "landing_gear.contact_stiffness",
    "gear_damping": "landing_gear.contact_damping",
    "gear_friction": "landing_gear.friction",
    "camera_offset_b": "sensors.camera_offset_b",
    "tof_mount_z": "sensors.tof_mount_z",
    "tof_arm_distance": "sensors.tof_arm_distance",
    "drag_airframe_fraction": "drag.airframe_fraction",
}


def _join(section: str, key: str) -> str:
    return f"{section}.{key}" if section else key


def _read(data: dict, key: str, kind: str) -> Any:
    """The value at the dotted ``key`` as the field's type ``kind`` (numbers checked, paths
    and names as strings, arrays as given), naming a missing key or a non-mapping section."""
    section, _, name = key.rpartition(".")
    mapping = data
    if section:
        if section not in data:
            raise ConfigError(section, "is missing")
        mapping = data[section]
        if not isinstance(mapping, dict):
            raise ConfigError(section, "must be a mapping")
    if name not in mapping:
        raise ConfigError(key, "is missing")
    value = mapping[name]
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(key, f"{value!r} is not a number")
        return float(value)
    return {"str": str, "Path": str, "bool": bool}.get(kind, lambda v: v)(value)


def _require_shape(key: str, value: np.ndarray, shape: tuple[int, ...]) -> None:
    if value.shape != shape or not np.all(np.isfinite(value)):
        raise ConfigError(key, f"needs finite values of shape {shape}, got shape {value.shape}")
