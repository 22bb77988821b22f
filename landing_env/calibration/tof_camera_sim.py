"""ToF–camera calibration run in the simulator (IHRCF Sec. 2.2, CRHF Sec. 2.3).

The rig is the environment's own world with the deck turned into the calibration target:
the tag is left out, a coloured pad (blue, green, yellow, red for sensors 1–4) is centred on
each sensor's touch point, and the Stewart platform holds the deck still and level.  The
drone, level and at zero yaw with its camera above the deck centre, is *placed* at each of
``stages`` heights from ``min_range_m`` up to just below the sensors' maximum range (it is a
calibration rig: the pose is set directly, without flying, so every stage is exactly level
and centred and no controller transient leaks into the data).  At each stage the camera image
is rendered (lens distortion included, the drone's own airframe hidden), each pad is
segmented with the papers' YCbCr thresholds (Table 1), closed with a convex hull and its
centroid kept with the sensor's range (the mean of ``readings_per_stage`` readings: the rig
holds still, and a sensor noise of a few millimetres would otherwise scramble the order of
the closely spaced near stages).  The range → pixel pairs give the PCHIP look-up
(:class:`~estimation.tof_calibration.TofCameraCalibration`) and the hyperbola fits of CRHF
Table 4.

The same :func:`estimation.tof_rig.calibrate_rig` that calibrates a real rig's recording
calibrates the stages: :func:`record_tof_rig_in_sim` returns them with the rig file
(:class:`TofRigRecording`), which ``agents.io.tof_rig`` writes as a recording folder (the
simulated rig's clock: stage k starts at ``k (n + 1) 20 ms`` with its image, its ``n``
readings follow every 20 ms).

Stages are spaced evenly in log-range (the pixel offset of a touch point falls as 1/r, so
this keeps the pixel steps between stages similar instead of crowding the far end).
The floor round the deck is made neutral grey in the rig: the scene's sea blue passes
Table 1's blue thresholds and would be taken for the blue pad.  A stage where a pad is not
found, is clipped by the image border or whose range is invalid is skipped for that sensor
and counted (``skipped``), never filled in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.frames import R_BC, R_PD
from estimation.limits import POSITIVE, Limit, limited, require_limits
from estimation.tof_calibration import PAD_COLOURS, HyperbolaFit, TofCameraCalibration
from estimation.tof_rig import (
    PAD_NOT_FOUND,
    SKIP_REASONS,
    RigCalibration,
    RigFrame,
    RigStage,
    StageWindow,
    TofRigDescription,
    calibrate_rig,
)
from landing_env.calibration import STILL_RIG
from landing_env.config import DeckLandingConfig, load_config
from landing_env.errors import ConfigError, require_choice
from landing_env.world import World

#: the simulated rig's ToF reading period (its clock: module doc)
READING_PERIOD_S = 0.02


@dataclass(frozen=True)
class TofRigConfig:
    """The pad rig and the climb.

    ``stages``: heights visited (papers: about 120).  ``min_range_m``: first sensor-to-deck
    range.  ``max_range_fraction``: the last stage's range as a fraction of ``tof.max_range``
    (a reading at exactly the maximum is invalid).  ``spacing``: ``"log"`` or ``"linear"``
    in range.  ``readings_per_stage``: ToF readings averaged at each stage (the rig holds
    still, so averaging only removes sensor noise; a sensor needs at least half of them
    valid).  ``pad_radius_m``: pads must stay apart (< half the distance between adjacent
    touch points) and be large enough to be segmented at the top stage (0.06 m is about
    7 px of radius at 4 m with the default camera).  ``min_pad_area_px``: fewer segmented
    pixels than this is "not found".  ``floor_rgb``: the rig's floor colour (0–1).
    """

    stages: int = limited(120, Limit(2))
    min_range_m: float = limited(0.3, POSITIVE)
    max_range_fraction: float = limited(0.995, Limit(0.0, 1.0, low_inclusive=False))
    spacing: str = "log"
    readings_per_stage: int = limited(10, Limit(1))
    pad_radius_m: float = limited(0.06, POSITIVE)
    min_pad_area_px: float = limited(12.0, Limit(1.0))
    floor_rgb: tuple[float, float, float] = (0.5, 0.5, 0.5)
    ranges_m: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if any(not (math.isfinite(r) and r > 0.0) for r in self.ranges_m):
            raise ConfigError("ranges_m", f"{self.ranges_m!r}: need finite ranges > 0 m")
        require_limits(self)
        require_choice("spacing", self.spacing, ("log", "linear"))
        if len(self.floor_rgb) != 3 or any(not 0.0 <= c <= 1.0 for c in self.floor_rgb):
            raise ConfigError("floor_rgb", f"{self.floor_rgb!r}: need three values in [0, 1]")

    def stage_ranges(self, max_range: float) -> np.ndarray:
        """The sensor-to-deck ranges of the stages, metres."""
        if self.ranges_m:
            too_far = [r for r in self.ranges_m if r >= max_range]
            if too_far:
                raise ConfigError(
                    "ranges_m", f"{too_far} reach the ToF maximum range {max_range} m"
                )
            return np.asarray(self.ranges_m, dtype=float)
        top = self.max_range_fraction * max_range
        if not self.min_range_m < top:
            raise ConfigError(
                "min_range_m", f"{self.min_range_m} must be below the top stage at {top:.3f} m"
            )
        if self.spacing == "log":
            return np.geomspace(self.min_range_m, top, self.stages)
        return np.linspace(self.min_range_m, top, self.stages)


@dataclass(frozen=True)
class TofSimReport:
    """The calibration with the raw pairs, what was skipped and its error against the truth.

    ``ranges`` (stages, sensors) and ``pixels`` (stages, sensors, 2) hold NaN where a stage
    was skipped for a sensor.  ``exact_error_px`` is the largest distance between the PCHIP
    look-up and the analytic touch-point pixel over each sensor's calibrated span;
    ``sample_error_px`` the RMS distance of the measured centroids from it.
    """

    calibration: TofCameraCalibration
    ranges: np.ndarray
    pixels: np.ndarray
    skipped: dict[str, list[int]]
    exact: TofCameraCalibration
    exact_error_px: np.ndarray
    sample_error_px: np.ndarray
    metadata: dict = field(default_factory=dict)

    @property
    def hyperbolas(self) -> list[tuple[HyperbolaFit, HyperbolaFit]]:
        """Per sensor, the (u, v) fits ``pixel = a / r + c`` (CRHF Table 4)."""
        cal = self.calibration
        return list(zip(cal.hyperbola_u, cal.hyperbola_v, strict=True))


def rig_config(config: DeckLandingConfig, rig: TofRigConfig) -> DeckLandingConfig:
    """The environment config turned into the pad rig (same camera, drone and sensors)."""
    mounts = np.asarray(config.tof.mount_offsets_c, dtype=float)
    # a level, zero-yaw drone over a level deck sees R_CD = I: sensor (x, y) in C touches the
    # deck at (x, y) in D, i.e. R_PD (x, y, 0) in P
    pads_p = (R_PD @ np.column_stack([mounts[:, :2], np.zeros(len(mounts))]).T).T
    if len(mounts) != len(PAD_COLOURS):
        raise ConfigError(
            "tof.mount_offsets_c",
            f"the pad rig has {len(PAD_COLOURS)} pad colours; the config has {len(mounts)} sensors",
        )
    return load_config(
        config,
        overrides={
            "deck.tag": False,
            "deck.pads": True,
            "deck.pad_radius": rig.pad_radius_m,
            "deck.pad_centres_p": [tuple(float(v) for v in row[:2]) for row in pads_p],
            **STILL_RIG,
            "camera.mode": "project",
        },
    )


def _touch_point_error(
    calibration: TofCameraCalibration, exact: TofCameraCalibration, n: int = 400
) -> np.ndarray:
    """Per sensor, the worst |look-up - exact| (px) over the sensor's calibrated span."""
    spans = calibration.range_span
    worst = np.zeros(calibration.n_sensors)
    for ratio in np.linspace(0.0, 1.0, n):
        ranges = spans[:, 0] + ratio * (spans[:, 1] - spans[:, 0])
        diff = calibration.lookup(ranges).pixels - exact.lookup(ranges).pixels
        worst = np.maximum(worst, np.linalg.norm(diff, axis=1))
    return worst


@dataclass(frozen=True)
class TofRigRecording:
    """The simulated rig's stages and its rig file (a recording's content, in memory)."""

    stages: tuple[RigStage, ...]
    description: TofRigDescription


def record_tof_rig_in_sim(
    config: DeckLandingConfig | None = None,
    rig: TofRigConfig | None = None,
    rng: np.random.Generator | None = None,
    progress: Callable[[], None] | None = None,
) -> TofRigRecording:
    """Climb through the stages over the pad deck: each stage's image and readings.

    ``config``: the environment config whose camera, ToF sensors and drone are calibrated
    (default: ``configs/default.yaml``); its ToF noise model applies.  ``rng`` seeds the
    sensor noise.  ``progress`` is called once per stage.  A reading without a return is NaN.
    """
    config = config if config is not None else load_config("default")
    rig = rig or TofRigConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
    rig_cfg = rig_config(config, rig)
    n_readings = rig.readings_per_stage
    world = World(rig_cfg)
    stages: list[RigStage] = []
    windows: list[StageWindow] = []
    try:
        world.client.changeVisualShape(world.ground_id, -1, rgbaColor=[*rig.floor_rgb, 1.0])
        # the deck at home, still; the drone placed anywhere for now
        world.reset(rng, world.deck_home_w + np.array([0.0, 0.0, 1.0]), 0.0)
        deck = world.deck_state()
        mounts_c = np.asarray(rig_cfg.tof.mount_offsets_c, dtype=float)
        # sensor origins in B: their common height decides where the body goes for a range
        sensors_b = world.t_bc + (R_BC @ mounts_c.T).T
        stage_ranges = rig.stage_ranges(rig_cfg.tof.max_range)
        for stage, target in enumerate(stage_ranges):
            position = deck.position_w.copy()
            position[:2] -= world.t_bc[:2]  # camera above the deck centre
            position[2] += target - float(np.mean(sensors_b[:, 2]))
            world.place_drone(position, 0.0)
            t0 = round(stage * (n_readings + 1) * READING_PERIOD_S, 9)
            frame = RigFrame(t0, f"stage_{stage:04d}.png", world.render_camera_image())
            readings = [world.measure_ranges() for _ in range(n_readings)]
            values = np.array([np.where(r.valid, r.ranges, np.nan) for r in readings])
            stamps = np.array(
                [round(t0 + (j + 1) * READING_PERIOD_S, 9) for j in range(n_readings)]
            )
            stages.append(
                RigStage(
                    (frame,),
                    tuple(stamps.copy() for _ in PAD_COLOURS),
                    tuple(values[:, i].copy() for i in range(len(PAD_COLOURS))),
                )
            )
            end = round(t0 + (n_readings + 0.5) * READING_PERIOD_S, 9)
            windows.append(StageWindow(t0, end, float(target)))
            if progress is not None:
                progress()
    finally:
        world.close()
    description = TofRigDescription(
        stages=tuple(windows),
        min_pad_area_px=rig.min_pad_area_px,
        camera=rig_cfg.camera.intrinsics,
        tof_mount_offsets_c=tuple(tuple(row) for row in mounts_c.tolist()),
        tof_max_range_m=rig_cfg.tof.max_range,
        metadata={
            "source": "simulator",
            "tof_noise": rig_cfg.tof.noise,
            "readings_per_stage": n_readings,
            "stage_spacing": rig.spacing,
            "pad_radius_m": rig.pad_radius_m,
        },
    )
    return TofRigRecording(tuple(stages), description)


def tof_sim_report(result: RigCalibration, description: TofRigDescription) -> TofSimReport:
    """The simulated rig's calibration with its error against the analytic touch points
    (the rig file's camera and sensor layout are the truth)."""
    camera, mounts = description.camera, description.tof_mount_offsets_c
    if camera is None or mounts is None:
        raise ValueError("the simulated rig's file names its camera and sensor layout")
    mounts_c = np.asarray(mounts, dtype=float)
    calibration = result.calibration
    exact = _exact_calibration(camera, mounts_c, calibration)
    sample_error = np.zeros(calibration.n_sensors)
    for i, samples in enumerate(calibration.samples):
        truth = _project_touch_points(camera, mounts_c[i], samples[:, 0])
        sample_error[i] = math.sqrt(float(np.mean(np.sum((samples[:, 1:] - truth) ** 2, axis=1))))
    return TofSimReport(
        calibration=calibration,
        ranges=result.ranges,
        pixels=result.pixels,
        skipped=result.skipped,
        exact=exact,
        exact_error_px=_touch_point_error(calibration, exact),
        sample_error_px=sample_error,
        metadata=calibration.metadata,
    )


def calibrate_tof_camera_in_sim(
    config: DeckLandingConfig | None = None,
    rig: TofRigConfig | None = None,
    rng: np.random.Generator | None = None,
    progress: Callable[[], None] | None = None,
) -> TofSimReport:
    """Climb through the stages over the pad deck and build the ToF–camera calibration
    (:func:`record_tof_rig_in_sim`'s arguments).  Raises
    :class:`~estimation.tof_rig.TofRigError` when a sensor has fewer than two usable stages."""
    recorded = record_tof_rig_in_sim(config, rig, rng, progress)
    return tof_sim_report(
        calibrate_rig(recorded.stages, recorded.description), recorded.description
    )


def _project_touch_points(
    camera: CameraIntrinsics, sensor_c: np.ndarray, ranges: np.ndarray
) -> np.ndarray:
    points = np.column_stack(
        [np.full(len(ranges), sensor_c[0]), np.full(len(ranges), sensor_c[1]), ranges]
    )
    return camera.project(points)


def _exact_calibration(
    camera: CameraIntrinsics, mounts_c: np.ndarray, calibration: TofCameraCalibration
) -> TofCameraCalibration:
    spans = calibration.range_span
    return TofCameraCalibration.exact(
        camera, mounts_c, float(spans[:, 0].min()), float(spans[:, 1].max())
    )


__all__ = [
    "PAD_NOT_FOUND",
    "SKIP_REASONS",
    "TofRigConfig",
    "TofRigRecording",
    "TofSimReport",
    "calibrate_tof_camera_in_sim",
    "record_tof_rig_in_sim",
    "rig_config",
    "tof_sim_report",
]
