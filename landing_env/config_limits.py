"""Physical limits of the numeric config values, in one table, checked as a config is loaded.

Every number that enters a config through YAML, ``overrides`` or section keywords passes
:func:`check_value`: NaN and infinities are refused everywhere (except where ``inf`` has a
meaning, ``allow_inf``), and a key listed in :data:`LIMITS` must lie in its physical range.
Tuples are checked element by element.  The dataclasses' own ``__post_init__`` checks (and
the cross-field ones there) still run afterwards; this table adds the bounds they lack, so a
value is refused with its own key before it can make a later check or the physics fail.

To validate a new numeric key, add one line here (or a ``require_range`` in its dataclass);
``tests/test_config_validation.py`` fuzzes every numeric key with NaN, inf and +-1e9.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from landing_env.errors import require_finite, require_range


@dataclass(frozen=True)
class Limit:
    """``low <= value <= high`` (ends exclusive when asked); ``inf`` allowed if ``allow_inf``."""

    low: float | None = None
    high: float | None = None
    low_inclusive: bool = True
    high_inclusive: bool = True
    allow_inf: bool = False
    #: where the bound comes from (a datasheet, a standard) or why it is there
    note: str = ""


def _positive(high: float, note: str = "") -> Limit:
    return Limit(0.0, high, low_inclusive=False, note=note)


def _nonneg(high: float, note: str = "") -> Limit:
    return Limit(0.0, high, note=note)


def _sym(bound: float, note: str = "") -> Limit:
    return Limit(-bound, bound, note=note)


_GAIN = _nonneg(1e3, "PID gain; PX4's defaults are O(0.1-10)")
_RATE_HZ = _positive(1e4, "a filter cut-off; above the physics rate it has no effect")
_PERIOD_S = _positive(1e3, "ship-motion periods are seconds to a minute")
_DAMPING = _nonneg(10.0, "damping ratio")
_WEIGHT = _nonneg(1e4, "reward weight: non-negative (the formula carries the signs)")
_NOISE_DENSITY = _nonneg(10.0, "IMU noise densities: MEMS datasheets give 1e-5..1e-2")

#: Dotted key -> physical range, for the DeckLanding-v2 config tree.
LIMITS: dict[str, Limit] = {
    "seed": Limit(0, 2**63 - 1),
    # simulation: PyBullet is stepped at 240 Hz by default; above 4 kHz a step costs more
    # than any motor/ESC update rate (<= 2 kHz) justifies, and 1e6 Hz froze a run
    "simulation.physics_hz": Limit(1, 4000, note="<= 4 kHz (motor/ESC updates <= 2 kHz)"),
    "simulation.env_hz": Limit(1, 1000),
    "simulation.max_episode_s": _positive(1e5, "about a day"),
    "simulation.arena_half_extent_m": _positive(1e4),
    "simulation.arena_max_height_m": _positive(1e4),
    "action.max_horizontal_speed": _positive(50.0, "multirotor airspeed"),
    "action.max_vertical_speed": _positive(50.0),
    "action.max_yaw_rate_deg": _positive(1000.0),
    "action.land_threshold": Limit(-1.0, 1.0),
    "action.land_band_m": _positive(2.0),
    "start.height_m": Limit(0.2, 1e4),
    "start.max_offset_m": _nonneg(1e4),
    "start.min_offset_m": _nonneg(1e4),
    "touchdown.max_normal_speed": _positive(20.0),
    "touchdown.settle_time_s": _nonneg(60.0),
    "reward.success_bonus": _WEIGHT,
    "reward.touchdown_bonus": _WEIGHT,
    "reward.crash_penalty": _WEIGHT,
    "reward.shaping_weight": _WEIGHT,
    "reward.vertical_weight": _WEIGHT,
    "reward.time_cost": _WEIGHT,
    "reward.normal_speed_penalty": _WEIGHT,
    "reward.tilt_penalty": _WEIGHT,
    "reward.offset_penalty": _WEIGHT,
    "reward.velocity_weight": _WEIGHT,
    "reward.action_rate_weight": _WEIGHT,
    "reward.normal_speed_sq_penalty": _WEIGHT,
    "estimation.max_bridged_frames": Limit(0, 1000),
    "estimation.atda.history_timeout_s": _nonneg(60.0),
    "estimation.atda.max_reprojection_error_px": _positive(1e4),
    "estimation.atda.min_corner_area_px": _nonneg(1e7),
    "estimation.fusion.horizon_s": _nonneg(10.0),
    "estimation.fusion.reset_timeout_s": _positive(60.0),
    "estimation.fusion.deck_accel_psd": _nonneg(1e3),
    "estimation.fusion.deck_angular_accel_psd": _nonneg(1e3),
    "estimation.fusion.deck_period_s": _nonneg(1e3, "0: no deck oscillator; ships roll at 5-30 s"),
    "estimation.fusion.deck_damping_ratio": _nonneg(10.0),
    "estimation.fusion.deck_attitude_rms_deg": _positive(90.0, "roll, pitch"),
    "estimation.fusion.accel_noise_density": _NOISE_DENSITY,
    "estimation.fusion.accel_bias_random_walk": _NOISE_DENSITY,
    "estimation.fusion.initial_accel_bias_sigma": _positive(1e3),
    "estimation.fusion.initial_velocity_sigma": _positive(1e3),
    "estimation.fusion.initial_rate_sigma": _positive(1e3),
    "estimation.fusion.tof_sigma_m": _positive(1.0),
    "estimation.fusion.tof_sigma_per_m": _nonneg(1.0),
    # .inf drops a component of that source's pose measurement
    "estimation.fusion.atda_sigma": Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    "estimation.fusion.ihrcf_sigma": Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    "estimation.fusion.crhf_sigma": Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    "estimation.fusion.tight_sigma": Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    "estimation.fusion.tof_resolution_m": _nonneg(0.1, "VL53L1X reports whole millimetres"),
    # tight: noise weights (VL53L1X datasheet model, pixels) and solver settings
    "estimation.tight.pixel_sigma_px": _positive(100.0, "corner noise, pixels"),
    "estimation.tight.tof_sigma_0_m": _positive(1.0),
    "estimation.tight.tof_sigma_per_m": _nonneg(1.0),
    "estimation.tight.tof_resolution_m": _nonneg(0.1, "VL53L1X reports whole millimetres"),
    "estimation.tight.tof_sigma_min_m": _nonneg(1.0),
    "estimation.tight.pixel_sigma_axes_px": _nonneg(100.0, "0: pixel_sigma_px at every angle"),
    "estimation.tight.corner_bias_px": _sym(100.0, "detector edge offset a, b (px), c (px^2)"),
    "estimation.tight.max_iterations": Limit(1, 1000),
    "estimation.tight.range_gate_sigma": _positive(1e3, "gate in sigmas"),
    "estimation.tight.max_reprojection_error_px": _positive(1e4),
    "estimation.tight.min_corner_area_px": _nonneg(1e7, "a 512x512 image holds 2.6e5 px^2"),
    "estimation.tight.ambiguity_ratio_threshold": Limit(0.0, 1.0),
    "estimation.tight.history_timeout_s": _nonneg(60.0),
    "estimation.tight.start_cost_margin": _nonneg(1e6),
    "estimation.vision_link.latency_s": _nonneg(10.0),
    "estimation.vision_link.latency_jitter_s": _nonneg(10.0),
    "estimation.vision_link.rate_hz": _positive(1e3),
    "estimation.vision_link.max_age_s": _positive(60.0),
    "motion.ship.wave_direction_deg": Limit(-360.0, 360.0, note="from the bow, degrees"),
    "wind.mean_velocity_w": _sym(100.0, "m/s; hurricane force is ~33 m/s"),
    "wind.gust_intensity": _nonneg(100.0),
    "wind.gust_time_constant": _positive(1e3),
    "deck.size": _positive(1e3),
    "deck.thickness": _positive(10.0),
    "deck.tag_size": _positive(1e3),
    "deck.quiet_zone_cells": _nonneg(100.0),
    "deck.pad_radius": _positive(10.0),
    "stewart.base_radius": _positive(100.0),
    "stewart.top_radius": _positive(100.0),
    "stewart.top_anchor_depth": _sym(100.0),
    "stewart.min_leg_length": _positive(1e3),
    "stewart.max_leg_length": _positive(1e3),
    "stewart.home_height": _positive(1e3),
    "stewart_base_position": _sym(1e3),
    "motion.static.position_m": _sym(100.0),
    "motion.static.attitude_deg": _sym(90.0),
    "motion.sinusoids.amplitudes": _nonneg(100.0, "metres and degrees"),
    "motion.sinusoids.frequencies_hz": _nonneg(100.0),
    "motion.sinusoids.phases_deg": _sym(3600.0),
    "motion.sea_state.wave_direction_deg": _sym(360.0),
    "motion.sea_state.direction_spread_deg": _nonneg(180.0),
    "motion.sea_state.heave_period_s": _PERIOD_S,
    "motion.sea_state.roll_period_s": _PERIOD_S,
    "motion.sea_state.pitch_period_s": _PERIOD_S,
    "motion.sea_state.surge_sway_period_s": _PERIOD_S,
    "motion.sea_state.yaw_period_s": _PERIOD_S,
    "motion.sea_state.heave_damping": _DAMPING,
    "motion.sea_state.roll_damping": _DAMPING,
    "motion.sea_state.pitch_damping": _DAMPING,
    "motion.sea_state.surge_sway_damping": _DAMPING,
    "motion.sea_state.yaw_damping": _DAMPING,
    "motion.sea_state.scale": _nonneg(100.0),
    "camera.fx": _positive(1e5, "pixels"),
    "camera.fy": _positive(1e5, "pixels"),
    "camera.cx": _sym(1e5),
    "camera.cy": _sym(1e5),
    # OpenCV's distortion model: |k| of real lenses is < 10
    "camera.k1": _sym(100.0),
    "camera.k2": _sym(100.0),
    "camera.p1": _sym(100.0),
    "camera.p2": _sym(100.0),
    "camera.k3": _sym(100.0),
    "camera.near": _positive(1e3),
    "camera.far": _positive(1e4),
    "camera.pixel_noise_px": _nonneg(100.0),
    "camera.pixel_noise_fit": _nonneg(1e6, "fitted (base px, size px^3, blur, floor)"),
    "camera.glare_strength": _nonneg(1e3, "the lobe's peak in white-surface units"),
    "camera.glare_shininess": Limit(1.0, 1e5, note="Phong exponent"),
    "camera.min_tag_side_px": _nonneg(1e4),
    "camera.edge_margin_px": _nonneg(1e4),
    "camera.quad_decimate": Limit(1.0, 16.0),
    "camera.quad_sigma": _nonneg(10.0),
    "camera.decode_sharpening": _nonneg(10.0),
    "camera.render_margin_frac": _nonneg(10.0),
    "camera.render_margin_px": Limit(0, 10_000),
    "camera.detector_threads": Limit(1, 256),
    "tof.max_range": _positive(100.0, "VL53L1X: 4 m"),
    "tof.min_range": _nonneg(100.0),
    "tof.sigma_0": _nonneg(1.0),
    "tof.sigma_per_m": _nonneg(1.0),
    "tof.resolution": _nonneg(1.0),
    "tof.mount_offsets_c": _sym(10.0),
    "imu.accel_noise_density": _NOISE_DENSITY,
    "imu.gyro_noise_density": _NOISE_DENSITY,
    "imu.accel_bias_random_walk": _NOISE_DENSITY,
    "imu.gyro_bias_random_walk": _NOISE_DENSITY,
    "imu.accel_bias_sigma": _nonneg(100.0),
    "imu.gyro_bias_sigma": _nonneg(100.0),
    "rangefinder.max_range": _positive(1e3, "LIDAR-Lite v3: 40 m"),
    "rangefinder.min_range": _nonneg(1e3),
    "rangefinder.sigma_0": _nonneg(10.0),
    "rangefinder.sigma_per_m": _nonneg(1.0),
    "rangefinder.resolution": _nonneg(10.0),
    "rangefinder.mount_offset_b": _sym(10.0),
    # the timing task's guidance (landing_env/timing/guidance.py): gains, speeds, distances
    "timing.guidance.k_xy": _GAIN,
    "timing.guidance.k_yaw": _GAIN,
    "timing.guidance.k_z": _GAIN,
    "timing.guidance.descent_gain": _GAIN,
    "timing.guidance.max_horizontal_speed": _nonneg(50.0, "m/s; a multirotor's is < 30"),
    "timing.guidance.max_vertical_speed": _nonneg(20.0, "m/s"),
    "timing.guidance.descent_speed": _nonneg(20.0, "m/s"),
    "timing.guidance.lost_tag_climb_speed": _nonneg(20.0, "m/s"),
    "timing.guidance.blind_range_m": _nonneg(100.0, "m"),
    "timing.guidance.align_tolerance_m": _nonneg(100.0, "m"),
    "timing.guidance.align_tolerance_per_m": _nonneg(10.0, "m of tolerance per m of range"),
    "timing.guidance.max_search_range_m": _nonneg(1e3, "m"),
    "timing.guidance.tag_half_size_m": _positive(100.0, "m"),
    "timing.guidance.view_half_tan": _positive(100.0, "tan of half the field of view"),
    "timing.guidance.view_margin": _nonneg(10.0, "fraction of the view"),
    "timing.guidance.tracker_accel_psd": _nonneg(1e6, "(m/s^2)^2/Hz"),
    "timing.guidance.tracker_jerk_psd": _positive(1e6, "(m/s^3)^2/Hz"),
    "timing.guidance.tracker_position_sigma_m": _nonneg(100.0, "m"),
    "timing.guidance.tracker_coast_s": _nonneg(600.0, "s"),
    "timing.guidance.tracker_velocity_decay_s": _positive(600.0, "s"),
    "timing.guidance.lean_filter_s": _nonneg(60.0, "s"),
    "timing.guidance.lost_tag_pause_s": _nonneg(600.0, "s"),
    "timing.guidance.max_flare_wait_s": _nonneg(600.0, "s"),
    # the IR-LOCK-style beacon (estimation/beacon.py)
    "estimation.beacon.min_corner_area_px": _nonneg(1e7, "px^2; a 4 K frame has 8.3e6"),
    "estimation.beacon.max_range_m": _positive(1e4, "m; the paper's COTS beacon: 40 m"),
}
for _source in ("ihrcf", "crhf"):
    # inf disables these two checks (RangeFusionConfig)
    LIMITS[f"estimation.{_source}.max_plane_rms_m"] = Limit(
        0.0, 100.0, low_inclusive=False, allow_inf=True
    )
    LIMITS[f"estimation.{_source}.max_rigid_rms_rel"] = Limit(
        0.0, 100.0, low_inclusive=False, allow_inf=True
    )
    LIMITS[f"estimation.{_source}.min_corner_area_px"] = _nonneg(1e7)
for _gain in (
    "vel_p_xy vel_i_xy vel_d_xy vel_p_z vel_i_z vel_d_z vel_i_limit_xy vel_i_limit_z att_p_rp "
    "att_p_yaw rate_p_rp rate_i_rp rate_d_rp rate_p_yaw rate_i_yaw rate_d_yaw "
    "rate_i_limit_rp rate_i_limit_yaw"
).split():
    LIMITS[f"controller.{_gain}"] = _GAIN
for _limit in "max_horizontal_speed max_climb_rate max_descent_rate".split():
    LIMITS[f"controller.{_limit}"] = _positive(50.0)
for _limit in "max_accel_up max_accel_down max_rate_rp max_rate_yaw".split():
    LIMITS[f"controller.{_limit}"] = _positive(100.0)
LIMITS["controller.vel_d_cutoff_hz"] = _RATE_HZ
LIMITS["controller.rate_d_cutoff_hz"] = _RATE_HZ


def _numbers(value: Any) -> list[float] | None:
    """The numbers in ``value`` (a number, or a nested tuple/list/array of them), or None."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        return [float(value)]
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        return [float(v) for v in value.reshape(-1)]
    if isinstance(value, (tuple, list)):
        numbers: list[float] = []
        for item in value:
            inner = _numbers(item)
            if inner is None:
                return None
            numbers.extend(inner)
        return numbers
    return None


def check_value(key: str, value: Any, limits: dict[str, Limit] | None = None) -> None:
    """Refuse a non-finite number anywhere and a number outside ``limits[key]``.

    ``key`` is the full dotted key; list indices (``height_m[1]``) are looked up without them.
    """
    numbers = _numbers(value)
    if not numbers:
        return
    table = LIMITS if limits is None else limits
    limit = table.get(key.split("[", 1)[0])
    for number in numbers:
        if limit is not None and limit.allow_inf and math.isinf(number) and number > 0:
            continue
        require_finite(key, number)
        if limit is not None:
            require_range(
                key,
                number,
                limit.low,
                limit.high,
                low_inclusive=limit.low_inclusive,
                high_inclusive=limit.high_inclusive,
            )


def config_leaves(cls: type, prefix: str = "") -> list[tuple[str, Any]]:
    """(dotted key, default value) of every leaf (non-dataclass field) of a config tree."""
    import dataclasses
    import typing

    hints = typing.get_type_hints(cls)
    leaves: list[tuple[str, Any]] = []
    defaults = cls()
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(hints[f.name]):
            leaves.extend(config_leaves(hints[f.name], key + "."))
        else:
            leaves.append((key, getattr(defaults, f.name)))
    return leaves


def numeric_leaves(cls: type) -> list[tuple[str, Any]]:
    """The leaves holding numbers (a number or tuples of them): what the fuzzers of
    ``tests/`` and ``benchmarks/`` vary."""
    return [(key, value) for key, value in config_leaves(cls) if _numbers(value)]
