"""The environment's configuration: one dataclass tree, loaded from YAML in ``configs/``.

``load_config("paper-stewart", camera={"mode": "render"}, overrides={"tof.noise": "vl53l1x"})``
starts from the dataclass defaults, applies the named YAML and then the overrides.  Unknown
keys and bad values raise :class:`~landing_env.errors.ConfigError` naming the dotted key.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from estimation.atda import ATDAConfig
from estimation.beacon import BeaconConfig
from estimation.crhf import CRHFConfig
from estimation.fusion import FusionConfig
from estimation.ihrcf import IHRCFConfig
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited, require_limits
from estimation.pipeline import needs_intrinsics, needs_tof_calibration
from estimation.registry import ESTIMATOR_NAMES, load_plugins
from estimation.tight_config import TightConfig
from landing_env.config_limits import LIMITS, check_value, physical_limits
from landing_env.config_loading import (
    build_dataclass,
    deep_merge,
    dotted_to_nested,
    nested_to_dotted,
)
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.physics.controller import ControllerGains
from landing_env.physics.wind import WindConfig
from landing_env.resources import config_dir
from landing_env.scene.deck import DeckSurfaceConfig
from landing_env.sensors.camera_config import CameraConfig
from landing_env.sensors.imu import ImuConfig
from landing_env.sensors.rangefinder import RangefinderConfig
from landing_env.sensors.tof import TofConfig
from landing_env.stewart.kinematics import StewartGeometry
from landing_env.stewart.motion import MotionConfig
from landing_env.timing_config import TimingConfig
from landing_env.vision_link import VisionLinkConfig

#: Scenario and training configs shipped with the project (found as package data in a
#: wheel; see :mod:`landing_env.resources`).
CONFIG_DIR = config_dir()

#: ``sensors``: each name is a preset in ``configs/sensors/`` laid over the scenario
SENSOR_SETS = ("ideal", "realistic")
#: the bundle a config has without a ``sensors`` key
DEFAULT_SENSORS = "ideal"
#: ``lens``: each name is a preset in ``configs/lenses/`` (the camera's lens and the
#: calibrations made for it under each sensing profile) laid over the sensing preset
LENS_SETS = ("standard", "wide")
#: the environment variable ``deck-landing --sensors`` sets (worker processes inherit it);
#: it is the default of the ``sensors`` key
SENSORS_ENV = "DECK_LANDING_SENSORS"

#: ``deck_mount``: the deck on the Stewart platform, or on a ship's helideck
#: (:class:`~landing_env.sea.deck_mount.ShipDeck`)
DECK_MOUNTS: tuple[str, ...] = ("stewart", "ship")

#: Where the estimators' calibrations come from: a calibration file or the exact model.
CALIBRATION_SOURCES = ("file", "exact")

#: Calibration files shipped for the default camera and ToF layout (``deck-landing
#: calibrate --install`` rewrites them).
CALIBRATION_DIR = CONFIG_DIR / "calibration"
SHIPPED_INTRINSICS_FILE = CALIBRATION_DIR / "intrinsics.json"
SHIPPED_TOF_CALIBRATION_FILE = CALIBRATION_DIR / "tof_camera.json"


@dataclass
class SimulationConfig:
    """Rates and limits of the simulation."""

    #: PyBullet's step rate, Hz: above 4 kHz a step costs more than any motor/ESC update
    #: rate (<= 2 kHz) justifies, and 1e6 Hz froze a run
    physics_hz: int = limited(
        240, Limit(1), physical=Limit(1, 4000, note="<= 4 kHz (motor/ESC updates <= 2 kHz)")
    )
    env_hz: int = limited(20, Limit(1), physical=Limit(1, 1000))
    #: episode time limit (truncation), seconds
    max_episode_s: float = limited(30.0, POSITIVE, physical=Limit.positive(1e5, "about a day"))
    #: leaving this horizontal distance from the deck's home position is a crash, metres
    arena_half_extent_m: float = limited(8.0, physical=Limit.positive(1e4))
    #: flying higher than this above the deck's home surface is a crash, metres
    arena_max_height_m: float = limited(12.0, physical=Limit.positive(1e4))
    #: attitude tilt beyond which the drone counts as flipped, degrees
    flip_tilt_deg: float = limited(80.0, Limit(0.0, 180.0))
    #: pin the drone at its start pose, as on the papers' bench ("a motionless flying
    #: quadrotor" over the moving platform); the action is then ignored
    drone_fixed: bool = False
    gui: bool = False

    def __post_init__(self) -> None:
        require_limits(self)
        if self.physics_hz % self.env_hz != 0:
            raise ConfigError(
                "physics_hz",
                f"{self.physics_hz} Hz is not a multiple of simulation.env_hz = {self.env_hz} Hz; "
                "choose physics_hz = k * env_hz (e.g. 240 with env_hz 20, 30, 40, 48, 60, 80)",
            )

    @property
    def substeps(self) -> int:
        return self.physics_hz // self.env_hz


@dataclass
class ActionConfig(Limited):
    """Scaling of the Box action in [-1, 1] to velocity set-points of the heading frame, and
    ``DeckLanding``'s land trigger (its fifth entry; see the env card's "Action space")."""

    max_horizontal_speed: float = limited(
        1.5, POSITIVE, physical=Limit.positive(50.0, "multirotor airspeed")
    )
    max_vertical_speed: float = limited(1.0, POSITIVE, physical=Limit.positive(50.0))
    max_yaw_rate_deg: float = limited(60.0, POSITIVE, physical=Limit.positive(1000.0))
    #: the fifth action entry ``land``: above ``land_threshold`` it commits to the timing
    #: task's descent, obeyed only aligned over the tag and within ``land_band_m`` of
    #: ``timing.hold_height_m``; false: the Box(4) velocity task
    land_trigger: bool = True
    land_threshold: float = limited(0.5, Limit(-1.0, 1.0), physical=Limit(-1.0, 1.0))
    land_band_m: float = limited(0.2, Limit.positive(2.0), physical=Limit.positive(2.0))


@dataclass
class StartConfig:
    """Where an episode starts, relative to the deck's home surface centre."""

    #: height of the drone's centre above the deck home surface, min and max, metres
    height_m: tuple[float, float] = limited((1.8, 2.2), physical=Limit(0.2, 1e4))
    #: maximum horizontal offset from the deck centre, metres
    max_offset_m: float = limited(0.3, NON_NEGATIVE, physical=Limit.non_negative(1e4))
    #: minimum horizontal offset, metres (equal to max_offset_m: a fixed distance at a
    #: random bearing, e.g. the high approach's 5 m)
    min_offset_m: float = limited(0.0, physical=Limit.non_negative(1e4))
    #: maximum ``|yaw|`` at the start, degrees
    max_yaw_deg: float = limited(10.0, Limit(0.0, 180.0))
    #: "home": heights and offsets from the deck's home surface; "deck": from where the deck
    #: is at t = 0 (a ship deck can be metres away from home), so the drone starts above it
    relative_to: str = "home"
    #: start in trim with the mean wind (leaning into it, the rotors carrying the drag, the
    #: velocity integrators holding the trim acceleration within their limit), as a drone
    #: that arrived over the deck would be; False starts level with the rotors at hover
    trim_to_wind: bool = False

    def __post_init__(self) -> None:
        require_choice("relative_to", self.relative_to, ("home", "deck"))
        if not isinstance(self.trim_to_wind, bool):
            raise ConfigError("trim_to_wind", f"must be true or false, got {self.trim_to_wind!r}")
        low, high = self.height_m
        if not 0.2 <= low <= high:
            raise ConfigError("height_m", f"{self.height_m} must satisfy 0.2 <= min <= max")
        require_limits(self)
        require_range(
            "min_offset_m",
            self.min_offset_m,
            0.0,
            self.max_offset_m,
            bounds_from=f"max_offset_m = {self.max_offset_m}",
        )


@dataclass
class TouchdownConfig(Limited):
    """Success thresholds of a touchdown; every measured value is reported in ``info``."""

    max_normal_speed: float = limited(0.5, POSITIVE, physical=Limit.positive(20.0))
    max_deck_tilt_deg: float = limited(5.0, Limit(0.0, 90.0))
    max_relative_attitude_deg: float = limited(10.0, Limit(0.0, 180.0))
    #: the drone must still be on the deck this long after the first contact, seconds
    settle_time_s: float = limited(1.0, NON_NEGATIVE, physical=Limit.non_negative(60.0))
    #: a bounce higher than this (lowest foot above the deck, metres) fails the touchdown
    max_bounce_m: float = limited(0.01, Limit(0.0, 1.0))
    #: the drone tipped over when its z axis passed this angle from the deck normal, degrees
    tip_over_deg: float = limited(45.0, Limit(1.0, 180.0))
    #: the land sequence after the first contact, seconds (PX4's land detector: ground
    #: contact, thrust lowered, landed, disarm): the controller stays armed this long,
    #: aiming the thrust along the deck's normal as its ToF ranges measure it (the drone
    #: levels onto its gear; ``World.deck_normal_measured_w``) with the
    #: collective thrust capped on a ramp from the weight down to
    #: ``spool_down_final_thrust`` of it, then disarms for ``settle_time_s``; 0 cuts the
    #: motors at the first contact.  At ``ship-ss6`` 0.15 s kept more touchdowns on the
    #: deck than the cut, 0.4 s and longer fewer (docs/experiments/ship-timing.md)
    spool_down_s: float = limited(0.0, Limit(0.0, 2.0), physical=Limit.non_negative(10.0))
    #: the thrust cap at the end of the land sequence, a fraction of the drone's weight
    spool_down_final_thrust: float = limited(0.0, Limit(0.0, 1.0))
    #: a deck-securing device (a harpoon under the drone engaging a deck grid): from the
    #: first contact it pulls the drone down onto the deck with at most this force, newtons;
    #: 0: none.  An aid the deck and the drone must be fitted with, reported apart from the
    #: unaided landing (:meth:`landing_env.world.World.secure_to_deck`)
    harpoon_force_n: float = limited(0.0, Limit(0.0, 200.0), physical=Limit.non_negative(1e4))


#: the physical range of a reward weight
REWARD_WEIGHT = Limit.non_negative(
    1e4, "reward weight: non-negative (the formula carries the signs)"
)


@dataclass
class RewardConfig:
    """Weights of the reward; see the README for the formula."""

    success_bonus: float = limited(10.0, physical=REWARD_WEIGHT)
    #: ``DeckLanding`` only: any touchdown on the deck (a success or a hard landing) earns it,
    #: so that trying to land pays more than hovering to the time-out; the timing task, whose
    #: every commit ends in a touchdown, leaves it out
    touchdown_bonus: float = limited(5.0, physical=REWARD_WEIGHT)
    crash_penalty: float = limited(10.0, physical=REWARD_WEIGHT)

    #: potential-based shaping on the distance to the deck (horizontal + vertical weight)
    shaping_weight: float = limited(1.0, physical=REWARD_WEIGHT)
    vertical_weight: float = limited(0.5, physical=REWARD_WEIGHT)
    #: ``DeckLanding``: the shaping potential's weight on the relative speed (per m/s), the
    #: cost of the action's change per step (per unit squared), and the touchdown's cost per
    #: (m/s)^2 of normal speed on top of ``normal_speed_penalty``
    velocity_weight: float = limited(0.5, physical=REWARD_WEIGHT)
    action_rate_weight: float = limited(0.002, physical=REWARD_WEIGHT)
    normal_speed_sq_penalty: float = limited(10.0, physical=REWARD_WEIGHT)
    #: per-second cost of flying
    time_cost: float = limited(0.1, physical=REWARD_WEIGHT)
    #: touchdown penalties per unit of normal speed (m/s), deck tilt (deg), lateral offset (m)
    normal_speed_penalty: float = limited(4.0, physical=REWARD_WEIGHT)
    tilt_penalty: float = limited(0.2, physical=REWARD_WEIGHT)
    offset_penalty: float = limited(5.0, physical=REWARD_WEIGHT)


@dataclass
class EstimationConfig:
    """Which deck-pose estimate the observation carries, which others ``info`` compares, and
    the calibrations and settings the estimators run with (see the README's "Estimators and
    calibration").

    ``intrinsics``: the camera model ATDA uses (and IHRCF/CRHF only to undistort):
    ``"file"`` = the chessboard calibration in ``intrinsics_file``, ``"exact"`` = the
    simulated camera's true model.  ``tof_calibration``: the range → touch-pixel map of
    IHRCF/CRHF: ``"file"`` = the pad calibration in ``tof_calibration_file``, looked up by
    ``tof_lookup`` (``"pchip"`` as the papers, or the ``"hyperbola"`` fit), ``"exact"`` =
    the analytic map.  An empty file name means the file shipped in
    ``configs/calibration/`` for the default camera and sensor layout.  ``tracking``: bridge
    up to ``max_bridged_frames`` missed tag detections with the corner Kalman filter (CRHF
    Sec. 2.6); bridged estimates are flagged as predicted.  ``tracking_estimators``: the
    names tracked (empty: all); ``tracking_smooth``: the filter's corners on every frame, as
    CRHF Sec. 2.6 publishes it (off: detected corners pass through, only dropouts bridged).
    ``tof_positions_c``: the ToF layout the estimators are told (empty: the true
    ``tof.mount_offsets_c``); a different one models an estimator whose layout is wrong.
    """

    observed: str = "truth"
    compare: tuple[str, ...] = ()
    intrinsics: str = "file"
    intrinsics_file: str = ""
    tof_calibration: str = "file"
    tof_calibration_file: str = ""
    tof_lookup: str = "pchip"
    tracking: bool = False
    tracking_estimators: tuple[str, ...] = ()
    tracking_smooth: bool = False
    max_bridged_frames: int = limited(3, Limit(0), physical=Limit(0, 1000))
    tof_positions_c: tuple[tuple[float, float, float], ...] = ()
    atda: ATDAConfig = field(default_factory=ATDAConfig)
    ihrcf: IHRCFConfig = field(default_factory=IHRCFConfig)
    crhf: CRHFConfig = field(default_factory=CRHFConfig)
    #: the tightly coupled corners + ranges least squares (estimation/tight.py)
    tight: TightConfig = field(default_factory=TightConfig)
    #: the ``fused`` estimator: EKF of the IMU with the (delayed) poses of ``fusion.sources``
    #: and the ToF ranges (estimation/fusion/)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    #: the IR-LOCK-style ``beacon`` (bearing + rangefinder): its tracking range, max_range_m
    beacon: BeaconConfig = field(default_factory=BeaconConfig)
    #: latency, irregular rate and dropouts of the camera-based estimates (off by default)
    vision_link: VisionLinkConfig = field(default_factory=VisionLinkConfig)

    def __post_init__(self) -> None:
        load_plugins()  # the installed packages' estimators, read when a config is built
        require_choice("observed", self.observed, ESTIMATOR_NAMES)
        for name in self.compare:
            require_choice("compare", name, ESTIMATOR_NAMES)
        require_choice("intrinsics", self.intrinsics, CALIBRATION_SOURCES)
        require_choice("tof_calibration", self.tof_calibration, CALIBRATION_SOURCES)
        require_choice("tof_lookup", self.tof_lookup, ("pchip", "hyperbola"))
        require_limits(self)
        for name in self.tracking_estimators:
            require_choice("tracking_estimators", name, ESTIMATOR_NAMES)
        if any(len(row) != 3 for row in self.tof_positions_c):
            raise ConfigError("tof_positions_c", "need (x, y, z) per sensor, or none")
        names = [self.observed, *self.compare]
        if "fused" in names:
            names += list(self.fusion.sources)
        if self.intrinsics == "file" and needs_intrinsics(names):
            _require_file("intrinsics_file", self.intrinsics_path)
        if self.tof_calibration == "file" and needs_tof_calibration(names):
            _require_file("tof_calibration_file", self.tof_calibration_path)

    @property
    def intrinsics_path(self) -> Path:
        """The intrinsics file used (the shipped one when ``intrinsics_file`` is empty)."""
        return _calibration_path(self.intrinsics_file, SHIPPED_INTRINSICS_FILE)

    @property
    def tof_calibration_path(self) -> Path:
        """The ToF–camera file used (the shipped one when ``tof_calibration_file`` is empty)."""
        return _calibration_path(self.tof_calibration_file, SHIPPED_TOF_CALIBRATION_FILE)


def _calibration_path(name: str, shipped: Path) -> Path:
    """``shipped`` for an empty name; a relative name from the working directory, or else
    from the project root (so that ``configs/...`` in a scenario works from anywhere)."""
    if not name:
        return shipped
    path = Path(name).expanduser()
    if path.is_absolute() or path.exists():
        return path
    from_root = CONFIG_DIR.parent / path
    if from_root.exists():
        return from_root
    if path.parts[:1] == ("configs",):  # "configs/..." in an installed wheel
        shipped_file = CONFIG_DIR.joinpath(*path.parts[1:])
        if shipped_file.exists():
            return shipped_file
    return path


def _require_file(key: str, path: Path) -> None:
    if not path.is_file():
        raise ConfigError(
            key,
            f"{str(path)!r} does not exist; give a calibration file, recompute the shipped "
            "ones with `deck-landing calibrate --install`, or use the exact model "
            f"(estimation.{key.removesuffix('_file')}: exact)",
        )


@dataclass
class DeckLandingConfig:
    """Everything DeckLanding-v2 needs; each section is documented by its dataclass."""

    seed: int | None = limited(None, physical=Limit(0, 2**63 - 1))
    #: "ideal" (the papers' simulator) or "realistic" (OV9281-class camera with blur and
    #: noise, lens distortion, VL53L1X ToF noise and the calibrations made for them): the
    #: preset ``configs/sensors/<name>.yaml`` laid over the scenario, under explicit overrides
    sensors: str = DEFAULT_SENSORS
    #: the camera's lens: "standard" (58 deg horizontal field of view, the papers' camera) or
    #: "wide" (80 deg, ship-ss5's and ship-ss6's): the preset ``configs/lenses/<name>.yaml`` (focal
    #: lengths and, per sensing profile, the calibration files made for it) laid over the
    #: sensing preset, under explicit overrides
    lens: str = "standard"
    #: the deck-tilt predictor fitted to this scenario's deck motion (a shipped one by name,
    #: ``landing_env/assets/predictors/deck_tilt_<name>.npz``, or a path; fitted by
    #: ``python -m agents.training.tilt_predictor_fit fit``); ``timing.tilt_model: scenario``
    #: reads it.  Empty: none fitted
    deck_predictor: str = ""
    #: the seas the ship's helideck forecast (:mod:`landing_env.anticipation.hms_forecast`, read by
    #: the onboard look-ahead) is fitted
    #: on: empty, other realisations of this config's own sea; or a training family of seas
    #: (:data:`landing_env.sea.training_seas.TRAINING_FAMILIES`, e.g. ``ship-broad``), as a held-out
    #: sea's config must name (nothing is fitted on a held-out sea)
    deck_forecast: str = ""
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    action: ActionConfig = field(default_factory=ActionConfig)
    start: StartConfig = field(default_factory=StartConfig)
    touchdown: TouchdownConfig = field(default_factory=TouchdownConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    estimation: EstimationConfig = field(default_factory=EstimationConfig)
    #: vehicle parameter file; empty means the shipped ``landing_env/assets/quadrotor.yaml``
    vehicle: str = ""
    controller: ControllerGains = field(default_factory=ControllerGains)
    wind: WindConfig = field(default_factory=WindConfig)
    deck: DeckSurfaceConfig = field(default_factory=DeckSurfaceConfig)
    stewart: StewartGeometry = field(default_factory=StewartGeometry)
    #: world position of the Stewart platform's base centre (the ship stand-in), metres
    stewart_base_position: tuple[float, float, float] = limited(
        (0.0, 0.0, 0.04), physical=Limit.symmetric(1e3)
    )
    motion: MotionConfig = field(default_factory=MotionConfig)
    #: what carries the deck: "stewart" (the papers' bench, motion clamped to its workspace)
    #: or "ship" (a full-scale helideck moved by the motion as it is, no legs; landing_env/sea/)
    deck_mount: str = "stewart"
    #: deck_mount ship: height of the deck's home surface above the sea plane, metres
    ship_deck_height_m: float = limited(10.0, Limit(2.0, 50.0))
    camera: CameraConfig = field(default_factory=CameraConfig)
    tof: TofConfig = field(default_factory=TofConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    #: the downward long-range rangefinder (observation ``range_down``)
    rangefinder: RangefinderConfig = field(default_factory=RangefinderConfig)
    #: the timing task's settings (``DeckLandingTiming``: hold, descent, wave-off, observation)
    timing: TimingConfig = field(default_factory=TimingConfig)

    def __post_init__(self) -> None:
        if self.vehicle and not Path(self.vehicle).expanduser().is_file():
            raise ConfigError(
                "vehicle",
                f"{self.vehicle!r} is not a file; give a vehicle YAML like the shipped "
                "landing_env/assets/quadrotor.yaml, or leave it empty for that one",
            )
        require_choice("deck_mount", self.deck_mount, DECK_MOUNTS)
        require_limits(self)
        if self.deck_mount == "stewart" and self.motion.kind == "ship":
            raise ConfigError(
                "motion.kind",
                "'ship' moves a full-scale helideck (metres of heave) and needs deck_mount: "
                "ship; the Stewart bench takes static, sinusoids, sea_state or csv",
            )
        if self.motion.kind == "csv" and self.motion.csv.frame == "vessel":
            if self.deck_mount != "ship":
                raise ConfigError(
                    "motion.csv.frame",
                    "'vessel' replays a ship's motion at its centre through the helideck's "
                    "lever arm and needs deck_mount: ship; the bench takes frame: deck",
                )
        require_choice("sensors", self.sensors, SENSOR_SETS)
        require_choice("lens", self.lens, LENS_SETS)


# the loader's table of physical ranges: what every field of the tree declares
LIMITS.update(physical_limits(DeckLandingConfig))


def episode_step_limit(config: DeckLandingConfig, timing: TimingConfig | None = None) -> int:
    """The most steps an episode of this config can take (``max_episode_steps``).

    ``DeckLanding-v2`` (``timing`` None) truncates at ``simulation.max_episode_s``; the timing
    task decides every ``steps_per_decision`` control periods until ``wait_limit_s`` forces
    the commit (one step).
    """
    sim = config.simulation
    if timing is None:
        return round(sim.max_episode_s * sim.env_hz)
    decision_s = timing.steps_per_decision / sim.env_hz
    return math.ceil(timing.wait_limit_s / decision_s - 1e-9) + 1


def available_configs() -> list[str]:
    """Names of the YAML scenarios in ``configs/``."""
    return sorted(p.stem for p in CONFIG_DIR.glob("*.yaml"))


def read_config_data(name_or_path: str | Path) -> dict[str, Any]:
    """A config's YAML data with its ``extends`` chain merged (no validation)."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = CONFIG_DIR / f"{name_or_path}.yaml"
    if not path.is_file():
        names = ", ".join(available_configs())
        raise ConfigError("config", f"{str(name_or_path)!r} not found; choose one of {names}")
    with path.open() as handle:
        data = yaml.safe_load(handle) or {}
    if not isinstance(data, dict):
        raise ConfigError("config", f"{path} does not hold a mapping")
    parent = data.pop("extends", None)
    if parent is not None:
        data = deep_merge(read_config_data(parent), data)
    return data


def load_config(
    config: str | Path | DeckLandingConfig | None = "default",
    overrides: dict[str, Any] | None = None,
    **sections: Any,
) -> DeckLandingConfig:
    """Build a config from a YAML name/path (or an instance), then apply overrides.

    ``sections`` are top-level keys with (possibly partial) mappings or values, e.g.
    ``camera={"mode": "render"}``; ``overrides`` takes dotted keys (``"camera.mode"``).
    """
    if isinstance(config, DeckLandingConfig):
        base: DeckLandingConfig | None = config
        data: dict[str, Any] = {}
    else:
        base = None
        data = read_config_data(config) if config is not None else {}
    user = dotted_to_nested(sections)
    if overrides:
        user = deep_merge(user, dotted_to_nested(overrides))
    sensors = user.get("sensors", data.get("sensors"))
    if sensors is None and os.environ.get(SENSORS_ENV):
        sensors = os.environ[SENSORS_ENV]
        user = deep_merge(user, {"sensors": sensors})
    if sensors is not None:
        data = deep_merge(data, sensor_preset(sensors))
    lens = user.get("lens", data.get("lens"))
    if lens is not None:
        data = deep_merge(data, lens_preset(lens, sensors or "ideal"))
    return build_dataclass(DeckLandingConfig, deep_merge(data, user), base=base, check=check_value)


def sensor_preset(name: str) -> dict[str, Any]:
    """The settings ``sensors: name`` stands for (``configs/sensors/<name>.yaml``)."""
    require_choice("sensors", name, SENSOR_SETS)
    with (CONFIG_DIR / "sensors" / f"{name}.yaml").open() as handle:
        return {"sensors": name, **(yaml.safe_load(handle) or {})}


def sensing_profiles() -> dict[str, dict[str, Any]]:
    """Every sensing profile of ``configs/sensors/`` by name, as the dotted overrides that
    make it (what training and data collection draw by name).

    A bundle, a name of :data:`SENSOR_SETS`, is ``{"sensors": name}``; the default one,
    ``ideal``, adds nothing (the scenario's sensing stays).  Any other file is settings laid
    over a bundle: its own ``sensors`` key names the bundle (none: the scenario's), and the
    rest of it are the overrides (``realistic-2x``: the realistic bundle with its noise
    doubled).
    """
    profiles: dict[str, dict[str, Any]] = {}
    for path in sorted((CONFIG_DIR / "sensors").glob("*.yaml"), key=lambda p: p.stem):
        name = path.stem
        if name in SENSOR_SETS:
            profiles[name] = {} if name == DEFAULT_SENSORS else {"sensors": name}
            continue
        with path.open() as handle:
            data = yaml.safe_load(handle) or {}
        if not isinstance(data, dict):
            raise ConfigError("sensing", f"{path} does not hold a mapping")
        if data.get("sensors", DEFAULT_SENSORS) not in SENSOR_SETS:
            raise ConfigError(
                "sensors",
                f"{path}: {data['sensors']!r} is not a bundle; choose one of {SENSOR_SETS}",
            )
        profiles[name] = nested_to_dotted(data)
    return profiles


def lens_preset(name: str, sensors: str = "ideal") -> dict[str, Any]:
    """The settings ``lens: name`` stands for under the sensing profile ``sensors``
    (``configs/lenses/<name>.yaml``: its ``camera`` section, and its ``calibration`` section's
    entry for that profile, which names the calibration files made for this lens)."""
    require_choice("lens", name, LENS_SETS)
    require_choice("sensors", sensors, SENSOR_SETS)
    path = CONFIG_DIR / "lenses" / f"{name}.yaml"
    with path.open() as handle:
        data = yaml.safe_load(handle) or {}
    calibration = data.get("calibration", {})
    if not isinstance(calibration, dict) or set(calibration) != set(SENSOR_SETS):
        raise ConfigError(
            "lens",
            f"{path}: 'calibration' must name the files for each sensing profile "
            f"({', '.join(SENSOR_SETS)})",
        )
    preset: dict[str, Any] = {"lens": name, "camera": dict(data.get("camera", {}))}
    files = calibration[sensors]
    if files:
        preset["estimation"] = dict(files)
    return preset
