"""The one list of estimator names and the registry of single-frame estimator builders.

Every per-frame deck-pose estimator is registered here once, by name, with the config
dataclass it takes and the calibrations it needs; :func:`make_estimator` builds any of them
for one tag and :mod:`estimation.pipeline` builds everything an application asks for from one
options object.  The names that are not single-frame estimators are pipeline stages:
``truth`` (supplied by the simulator), ``beacon`` (bearing + rangefinder), ``auto`` (the
first valid of :data:`AUTO_RANKING`) and ``fused`` (the EKF over the others' output).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from estimation.atda import ATDAConfig, AtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.crhf import CRHFConfig, CrhfEstimator
from estimation.estimator import DeckPoseEstimator
from estimation.ihrcf import IHRCFConfig, IhrcfEstimator
from estimation.tight import TightConfig, TightEstimator

if TYPE_CHECKING:
    from estimation.tof_calibration import TofCameraCalibration


@dataclass(frozen=True)
class BuildInputs:
    """What a single-frame estimator for one tag is built from."""

    intrinsics: CameraIntrinsics | None
    tag_size: float
    tag_id: int
    tof_calibration: TofCameraCalibration | None
    tof_positions_c: np.ndarray | None
    config: object


@dataclass(frozen=True)
class EstimatorSpec:
    """A registered single-frame estimator.

    ``needs_intrinsics`` / ``needs_tof_calibration``: the calibrations it cannot run
    without; ``wants_tof_calibration``: it uses the ToF–camera calibration when there is
    one (tight: the principal point); ``uses_ranges``: it takes the ToF ranges (on a deck
    of nested landmarks it then prefers the tag nearest the landing point, under the rays).
    """

    name: str
    config_type: type
    build: Callable[[BuildInputs], DeckPoseEstimator]
    needs_intrinsics: bool
    needs_tof_calibration: bool
    uses_ranges: bool
    wants_tof_calibration: bool = False


def _atda(inputs: BuildInputs) -> DeckPoseEstimator:
    assert inputs.intrinsics is not None
    return AtdaEstimator(
        intrinsics=inputs.intrinsics,
        tag_size=inputs.tag_size,
        tag_id=inputs.tag_id,
        config=inputs.config,  # type: ignore[arg-type]
    )


def _homography_fusion(cls: type) -> Callable[[BuildInputs], DeckPoseEstimator]:
    """The builder of IHRCF or CRHF: the papers' camera+ToF fusions take the same inputs."""

    def build(inputs: BuildInputs) -> DeckPoseEstimator:
        assert inputs.tof_calibration is not None
        return cls(
            tag_size=inputs.tag_size,
            tag_id=inputs.tag_id,
            tof_calibration=inputs.tof_calibration,
            tof_positions_c=inputs.tof_positions_c,
            intrinsics=inputs.intrinsics,
            config=inputs.config,
        )

    return build


def _tight(inputs: BuildInputs) -> DeckPoseEstimator:
    assert inputs.intrinsics is not None
    return TightEstimator(
        intrinsics=inputs.intrinsics,
        tag_size=inputs.tag_size,
        tag_id=inputs.tag_id,
        tof_positions_c=inputs.tof_positions_c,
        tof_calibration=inputs.tof_calibration,
        config=inputs.config,  # type: ignore[arg-type]
    )


#: The single-frame camera(+ToF) estimators, by name.
REGISTRY: dict[str, EstimatorSpec] = {
    spec.name: spec
    for spec in (
        EstimatorSpec("atda", ATDAConfig, _atda, True, False, False),
        EstimatorSpec("ihrcf", IHRCFConfig, _homography_fusion(IhrcfEstimator), False, True, True),
        EstimatorSpec("crhf", CRHFConfig, _homography_fusion(CrhfEstimator), False, True, True),
        # the ranges enter through the sensors' mounts and the noise model, not a look-up
        EstimatorSpec("tight", TightConfig, _tight, True, False, True, True),
    )
}

#: Names of the single-frame estimators (the ones ``fused`` can take poses from).
FRAME_ESTIMATOR_NAMES: tuple[str, ...] = tuple(REGISTRY)

#: Every name ``estimation.observed`` / ``estimation.compare`` accept.
ESTIMATOR_NAMES: tuple[str, ...] = ("truth", *FRAME_ESTIMATOR_NAMES, "beacon", "auto", "fused")

#: ``auto``: the first valid of these (IHRCF within ToF range, ATDA above it)
AUTO_RANKING: tuple[str, ...] = ("ihrcf", "atda")

#: Names that need the camera intrinsics / the ToF–camera calibration.  Every camera
#: estimator gets the intrinsics: those that do not solve with K (IHRCF, CRHF) still undistort
#: the corners with its lens model, so a changed lens must come with its calibration.
NEEDS_INTRINSICS: frozenset[str] = frozenset(set(REGISTRY) | {"beacon"})
NEEDS_TOF_CALIBRATION: frozenset[str] = frozenset(
    n for n, s in REGISTRY.items() if s.needs_tof_calibration
)
#: Names that use the ToF–camera calibration when it is available (a superset of the above).
WANTS_TOF_CALIBRATION: frozenset[str] = frozenset(
    n for n, s in REGISTRY.items() if s.needs_tof_calibration or s.wants_tof_calibration
)


def make_estimator(
    name: str,
    *,
    intrinsics: CameraIntrinsics | None,
    tag_size: float,
    tag_id: int = 0,
    tof_calibration: TofCameraCalibration | None = None,
    tof_positions_c: np.ndarray | None = None,
    config: object | None = None,
) -> DeckPoseEstimator:
    """Build the single-frame estimator ``name`` (one of :data:`FRAME_ESTIMATOR_NAMES`).

    ``intrinsics``: calibrated camera (required by ATDA and tight; IHRCF/CRHF only use it to
    undistort).  ``tag_size``: black-border edge length of the tag, metres.
    ``tof_calibration`` (required by IHRCF and CRHF) and ``tof_positions_c`` (default
    :func:`~estimation.frames.tof_positions_in_camera_frame`).  ``config``: the method's
    config dataclass (its defaults if None; tight's noise defaults are the VL53L1X model and
    0.5 px, :mod:`estimation.noise`).
    """
    spec = REGISTRY.get(name)
    if spec is None:
        allowed = ", ".join(FRAME_ESTIMATOR_NAMES)
        raise ValueError(f"unknown estimator {name!r}; allowed: {allowed}")
    if spec.needs_intrinsics and intrinsics is None:
        raise ValueError(f"{name} needs the camera intrinsics")
    if spec.needs_tof_calibration and tof_calibration is None:
        raise ValueError(f"{name} needs a tof_calibration")
    if config is not None and not isinstance(config, spec.config_type):
        raise TypeError(f"{name} expects a {spec.config_type.__name__}")
    inputs = BuildInputs(
        intrinsics=intrinsics,
        tag_size=tag_size,
        tag_id=tag_id,
        tof_calibration=tof_calibration,
        tof_positions_c=tof_positions_c,
        config=config if config is not None else spec.config_type(),
    )
    return spec.build(inputs)
