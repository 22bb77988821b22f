"""The one list of estimator names and the registry of single-frame estimator builders.

Every per-frame deck-pose estimator is registered here once, by name, with the config
dataclass it takes and the calibrations it needs; :func:`make_estimator` builds any of them
for one tag and :mod:`estimation.pipeline` builds everything an application asks for from one
options object.  The names that are not single-frame estimators are pipeline stages:
``truth`` (supplied by the simulator), ``beacon`` (bearing + rangefinder), ``auto`` (the
first valid of :data:`AUTO_RANKING`) and ``fused`` (the EKF over the others' output).

Estimators of other packages join through the entry-point group :data:`PLUGIN_GROUP`
(``deck_landing.estimators``): :func:`load_plugins` imports each entry point once, when a
host first needs the names (an environment built, a command's choices), and the entry point
registers its estimator with :func:`register_estimator`.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from estimation.atda import ATDAConfig, AtdaEstimator
from estimation.camera_model import CameraIntrinsics
from estimation.crhf import CRHFConfig, CrhfEstimator
from estimation.estimator import DeckPoseEstimator
from estimation.ihrcf import IHRCFConfig, IhrcfEstimator
from estimation.tight import TightEstimator
from estimation.tight_config import TightConfig

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


def _camera_and_tof(cls: type, needs: str) -> Callable[[BuildInputs], DeckPoseEstimator]:
    """The builder of an estimator of the camera and the ToF sensors (IHRCF, CRHF, tight):
    they take the same inputs; ``needs`` names the calibration it cannot run without."""

    def build(inputs: BuildInputs) -> DeckPoseEstimator:
        assert getattr(inputs, needs) is not None
        return cls(
            tag_size=inputs.tag_size,
            tag_id=inputs.tag_id,
            tof_calibration=inputs.tof_calibration,
            tof_positions_c=inputs.tof_positions_c,
            intrinsics=inputs.intrinsics,
            config=inputs.config,
        )

    return build


_ihrcf = _camera_and_tof(IhrcfEstimator, "tof_calibration")
_crhf = _camera_and_tof(CrhfEstimator, "tof_calibration")
_tight = _camera_and_tof(TightEstimator, "intrinsics")

#: The single-frame camera(+ToF) estimators, by name.
REGISTRY: dict[str, EstimatorSpec] = {
    spec.name: spec
    for spec in (
        EstimatorSpec("atda", ATDAConfig, _atda, True, False, False),
        EstimatorSpec("ihrcf", IHRCFConfig, _ihrcf, False, True, True),
        EstimatorSpec("crhf", CRHFConfig, _crhf, False, True, True),
        # the ranges enter through the sensors' mounts and the noise model, not a look-up
        EstimatorSpec("tight", TightConfig, _tight, True, False, True, True),
    )
}

#: the estimators shipped with the package (the others came through :func:`register_estimator`)
BUILT_IN: frozenset[str] = frozenset(REGISTRY)

#: Names of the single-frame estimators (the ones ``fused`` can take poses from).  A list,
#: extended in place by :func:`register_estimator`, so that every module holding it sees a
#: registered name.
FRAME_ESTIMATOR_NAMES: list[str] = list(REGISTRY)

#: Every name ``estimation.observed`` / ``estimation.compare`` accept (extended in place).
ESTIMATOR_NAMES: list[str] = ["truth", *FRAME_ESTIMATOR_NAMES, "beacon", "auto", "fused"]

#: ``auto``: the first valid of these (IHRCF within ToF range, ATDA above it)
AUTO_RANKING: tuple[str, ...] = ("ihrcf", "atda")


def needs_intrinsics_names() -> frozenset[str]:
    """Names that get the camera intrinsics.  Every camera estimator gets them: those that do
    not solve with K (IHRCF, CRHF) still undistort the corners with its lens model, so a
    changed lens must come with its calibration."""
    return frozenset(set(REGISTRY) | {"beacon"})


def needs_tof_calibration_names(*, optional: bool = False) -> frozenset[str]:
    """Names that need the ToF–camera calibration (``optional``: or use it when there is
    one, a superset)."""
    return frozenset(
        n
        for n, s in REGISTRY.items()
        if s.needs_tof_calibration or (optional and s.wants_tof_calibration)
    )


def register_estimator(
    name: str,
    build: Callable[[BuildInputs], DeckPoseEstimator],
    config_type: type,
    *,
    needs_intrinsics: bool = True,
    needs_tof_calibration: bool = False,
    uses_ranges: bool = False,
    wants_tof_calibration: bool = False,
) -> EstimatorSpec:
    """Make a single-frame estimator usable by name everywhere an estimator name is taken
    (``estimation.observed``, ``estimation.compare``, the pipeline; the command line's
    ``--estimator`` when the call is made by an entry point of :data:`PLUGIN_GROUP`), without
    editing this module.  ``fused`` keeps the shipped estimators as
    its sources (each has its measurement sigmas in :class:`~estimation.fusion.FusionConfig`).

    ``build`` gets the :class:`BuildInputs` of one tag (its ``config`` an instance of
    ``config_type``, the defaults unless the host passes one) and returns a
    :class:`~estimation.estimator.DeckPoseEstimator`.  The flags say which calibrations it
    cannot run without and whether it takes the ToF ranges (see :class:`EstimatorSpec`).
    Register before an environment or a command is built from the name (before or after
    ``import landing_env``: the names are read when a config is built).  A name already taken
    or not a lower-case identifier is refused with a ``ValueError``; ``config_type`` must be a
    class that builds with no arguments.
    """
    if not isinstance(name, str) or not name.isidentifier() or name != name.lower():
        raise ValueError(f"estimator name {name!r}: give a lower-case identifier, e.g. 'mine'")
    if name in ESTIMATOR_NAMES:
        raise ValueError(f"estimator name {name!r} is taken; taken: {', '.join(ESTIMATOR_NAMES)}")
    if not callable(build):
        raise ValueError(f"build of {name!r} must be callable (BuildInputs -> estimator)")
    if not isinstance(config_type, type):
        raise ValueError(f"config_type of {name!r} must be a class, not {config_type!r}")
    try:
        config_type()
    except Exception as exc:
        raise ValueError(
            f"config_type {config_type.__name__} of {name!r} must build with no arguments "
            f"(its defaults): {exc}"
        ) from None
    spec = EstimatorSpec(
        name,
        config_type,
        build,
        needs_intrinsics,
        needs_tof_calibration,
        uses_ranges,
        wants_tof_calibration,
    )
    REGISTRY[name] = spec
    FRAME_ESTIMATOR_NAMES.append(name)
    ESTIMATOR_NAMES.insert(ESTIMATOR_NAMES.index("beacon"), name)
    return spec


def unregister_estimator(name: str) -> None:
    """Remove an estimator added by :func:`register_estimator` (the shipped ones stay)."""
    if name in BUILT_IN:
        raise ValueError(f"{name!r} is shipped with the package and cannot be removed")
    if name not in REGISTRY:
        raise ValueError(f"{name!r} is not registered")
    del REGISTRY[name]
    FRAME_ESTIMATOR_NAMES.remove(name)
    ESTIMATOR_NAMES.remove(name)


#: the entry-point group through which other packages add estimators
PLUGIN_GROUP = "deck_landing.estimators"

_plugins_loaded = False


def load_plugins() -> list[str]:
    """Register the estimators of the installed packages' ``deck_landing.estimators`` entry
    points (once per process; later calls do nothing) and return the names added.

    An entry point is named after its estimator and refers to a module whose import registers
    it (``mine = my_package.estimator``) or to a function of no arguments that does
    (``mine = my_package.estimator:register``).  One that fails to load, or loads without
    registering its name, is skipped with a warning naming it and its cause: it never stops
    the shipped estimators."""
    global _plugins_loaded
    if _plugins_loaded:
        return []
    _plugins_loaded = True
    from importlib.metadata import entry_points

    added: list[str] = []
    for point in entry_points(group=PLUGIN_GROUP):
        where = f"estimator plugin {point.name!r} ({point.value})"
        if point.name in REGISTRY:
            continue
        try:
            loaded = point.load()
            if callable(loaded) and point.attr:
                loaded()
        except Exception as exc:
            warnings.warn(f"{where} skipped: {type(exc).__name__}: {exc}", stacklevel=2)
            continue
        if point.name not in REGISTRY:
            warnings.warn(
                f"{where} skipped: loading it did not register {point.name!r} "
                "(register_estimator with the entry point's name)",
                stacklevel=2,
            )
            continue
        added.append(point.name)
    return added


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
    load_plugins()
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
