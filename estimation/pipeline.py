"""Builds every estimator an application asks for from one options object.

As OpenVINS' ``VioManager`` builds its whole estimator from one ``VioManagerOptions``, the
simulator (``landing_env.estimators.EstimatorBank``) and any other host (a real drone's
sensor loop) fill one :class:`EstimationOptions` and call :func:`build_estimators`; the
host supplies only what is not estimation: the ground truth (``truth``) and, for
``beacon``, the rangefinder's latest reading.  What runs after the per-frame estimators (the
vision link and the ``fused`` EKF) takes their output.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from estimation.atda import ATDAConfig, JointAtdaEstimator
from estimation.beacon import BeaconConfig, BeaconEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.errors import ConfigError
from estimation.estimator import DeckPoseEstimator, RankedEstimator
from estimation.landmarks import LandmarkChoiceConfig, LandmarkEstimator, LandmarkLayout
from estimation.registry import (
    AUTO_RANKING,
    ESTIMATOR_NAMES,
    REGISTRY,
    load_plugins,
    make_estimator,
    needs_intrinsics_names,
    needs_tof_calibration_names,
)
from estimation.tof_calibration import TofCameraCalibration
from estimation.tracking import CornerTracker, TrackedEstimator
from estimation.types import RangeReading

#: Names the host supplies (nothing in estimation/ can build the ground truth).
HOST_SUPPLIED = ("truth",)


def names_to_build(
    observed: str, compare: tuple[str, ...] = (), fusion_sources: tuple[str, ...] = ()
) -> list[str]:
    """The per-frame estimators to run, in order, for an observed and compared set:
    ``fused`` is replaced by its sources (it runs after them, on their output)."""
    names = list(dict.fromkeys((observed, *compare)))
    if "fused" in names:
        names = [n for n in dict.fromkeys((*names, *fusion_sources)) if n != "fused"]
    return names


def needs_intrinsics(names: tuple[str, ...] | list[str]) -> bool:
    expanded = set(names) | (set(AUTO_RANKING) if "auto" in names else set())
    return bool(expanded & needs_intrinsics_names())


def needs_tof_calibration(names: tuple[str, ...] | list[str], *, optional: bool = False) -> bool:
    """Whether the names need the ToF–camera calibration (``optional``: or can use one)."""
    expanded = set(names) | (set(AUTO_RANKING) if "auto" in names else set())
    return bool(expanded & needs_tof_calibration_names(optional=optional))


@dataclass(frozen=True)
class EstimationOptions:
    """Everything the estimators are built from.

    ``names``: the per-frame estimators to build (:func:`names_to_build`).  ``intrinsics`` /
    ``tof_calibration``: the calibrations (needed only by the names that use them, see
    :func:`needs_intrinsics`).  ``tof_positions_c``: the ToF sensors' origins in C.
    ``layout``: the deck's landmarks.  ``configs``: per registered name, its config
    dataclass (defaults where absent).  ``tracking``: wrap each estimator in the corner
    Kalman tracker, frames ``tracking_dt_s`` apart, bridging up to ``max_bridged_frames``
    (only the names in ``tracking_names`` when it is not empty; ``tracking_smooth``: the
    filtered corners on every frame, CRHF Sec. 2.6).
    ``range_down`` / ``range_offset_m``: the downward rangefinder's latest reading and its
    origin below the camera along the optical axis (``beacon`` only).
    """

    names: tuple[str, ...]
    layout: LandmarkLayout
    intrinsics: CameraIntrinsics | None = None
    tof_calibration: TofCameraCalibration | None = None
    tof_positions_c: np.ndarray | None = None
    configs: Mapping[str, object] = field(default_factory=dict)
    tracking: bool = False
    tracking_names: tuple[str, ...] = ()
    tracking_smooth: bool = False
    tracking_dt_s: float = 0.05
    max_bridged_frames: int = 3
    range_down: Callable[[], RangeReading] | None = None
    range_offset_m: float = 0.0


def build_estimators(
    options: EstimationOptions, supplied: Mapping[str, DeckPoseEstimator] | None = None
) -> dict[str, DeckPoseEstimator]:
    """One estimator per name of ``options.names``; ``supplied`` gives the host's own
    (``truth``).  A config error is re-raised under ``estimation.<name>``."""
    load_plugins()
    supplied = dict(supplied or {})
    return {name: _build(name, options, supplied) for name in options.names}


def _build(
    name: str, options: EstimationOptions, supplied: dict[str, DeckPoseEstimator]
) -> DeckPoseEstimator:
    if name in supplied:
        return supplied[name]
    if name in HOST_SUPPLIED:
        raise ConfigError("estimation.observed", f"{name!r} must be supplied by the host")
    if name not in ESTIMATOR_NAMES or name == "fused":
        allowed = ", ".join(n for n in ESTIMATOR_NAMES if n != "fused")
        raise ConfigError("estimation.observed", f"cannot build {name!r}; allowed: {allowed}")
    if name == "beacon":
        return _beacon(options)
    if name == "auto":
        # its own instances: the ranked ones may also be compared under their names
        return RankedEstimator(name, tuple(_build(n, options, supplied) for n in AUTO_RANKING))
    layout = options.layout
    if layout.is_single_centred:
        only = layout.landmarks[0]
        return _for_tag(name, options, only.tag_id, only.size)
    # nested landmarks: one estimator per tag, run on the chosen one, reporting T_CD of D;
    # the range-using estimators prefer the tag nearest the landing point (under the rays)
    prefer = "nearest" if REGISTRY[name].uses_ranges else "largest"
    choice = LandmarkChoiceConfig(prefer=prefer)
    single = LandmarkEstimator(
        name, layout, lambda lm: _for_tag(name, options, lm.tag_id, lm.size), choice
    )
    atda = options.configs.get("atda") or ATDAConfig()
    assert isinstance(atda, ATDAConfig)
    if name != "atda" or not atda.joint_landmarks:
        return single
    # ATDA: one PnP over every detected tag, the chosen tag alone when only one is seen
    assert options.intrinsics is not None
    return JointAtdaEstimator(
        intrinsics=options.intrinsics,
        layout=layout,
        single=single,
        min_side_px=choice.min_side_px,
        config=atda,
    )


def _for_tag(
    name: str, options: EstimationOptions, tag_id: int, tag_size: float
) -> DeckPoseEstimator:
    spec = REGISTRY[name]
    try:
        estimator = make_estimator(
            name,
            intrinsics=options.intrinsics,
            tag_size=tag_size,
            tag_id=tag_id,
            tof_calibration=options.tof_calibration
            if spec.wants_tof_calibration or spec.needs_tof_calibration
            else None,
            tof_positions_c=options.tof_positions_c if spec.uses_ranges else None,
            config=options.configs.get(name),
        )
    except ConfigError as exc:
        raise exc.under(f"estimation.{name}") from None
    if options.tracking and (not options.tracking_names or name in options.tracking_names):
        tracker = CornerTracker(
            dt=options.tracking_dt_s,
            max_bridged_frames=options.max_bridged_frames,
            smooth=options.tracking_smooth,
        )
        estimator = TrackedEstimator(estimator, tracker, name=name)
    return estimator


def _beacon(options: EstimationOptions) -> DeckPoseEstimator:
    """The IR-LOCK-style ``beacon`` estimator: tag-centre bearing + the downward rangefinder
    (position only; its orientation is reported level, ``orientation_known = False``)."""

    if options.range_down is None or options.intrinsics is None:
        raise ConfigError("estimation.observed", "beacon needs the intrinsics and a rangefinder")
    intrinsics, range_down = options.intrinsics, options.range_down

    configured = options.configs.get("beacon") or BeaconConfig()
    assert isinstance(configured, BeaconConfig)
    config = replace(configured, range_offset_m=options.range_offset_m)

    def one(tag_id: int) -> BeaconEstimator:
        return BeaconEstimator(intrinsics, tag_id, range_down, config)

    layout = options.layout
    if layout.is_single_centred:
        return one(layout.landmarks[0].tag_id)
    # nested landmarks: the chosen tag's centre, moved to D's origin under the level assumption
    return LandmarkEstimator("beacon", layout, lambda lm: one(lm.tag_id))
