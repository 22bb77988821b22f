"""The tag detector's corner offset on the configured camera, measured on a rig.

The rig is the environment's own world with the deck held still and level and its tag on
it (the ToF–camera rig's placement, with the tag instead of the pads): the drone, level,
is *placed* at ``stages`` heights from ``min_height_m`` to ``max_height_m`` above the tag,
and at each one in ``views_per_stage`` poses with a random yaw (so the tag's edges take
every angle to the pixel grid) and a random offset of up to ``max_offset_m`` across.  Each
view is captured through the configured camera and detector exactly as in flight; the
detected corners are compared with the tag's corners projected through the calibrated
camera at the rig's known pose, and :func:`estimation.corner_bias.fit_corner_bias` fits the
edge offset and the corners' residual noise (see :mod:`estimation.corner_bias`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.corner_bias import CornerBiasFit, fit_corner_bias
from estimation.frames import tag_corners_in_tag_frame
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.calibration import STILL_RIG
from landing_env.config import DeckLandingConfig, load_config
from landing_env.errors import require_range
from landing_env.world import World


@dataclass(frozen=True)
class TagRigConfig:
    """Where the camera looks at the tag from (heights of the camera above the tag)."""

    stages: int = limited(12, Limit(1))
    views_per_stage: int = limited(20, Limit(1))
    min_height_m: float = limited(0.75, POSITIVE)
    max_height_m: float = 3.5
    max_offset_m: float = limited(0.15, NON_NEGATIVE)

    def __post_init__(self) -> None:
        require_limits(self)
        require_range("max_height_m", self.max_height_m, self.min_height_m)


@dataclass(frozen=True)
class TagCornerReport:
    """The fit, the camera heights of the stages and the views where the tag was missed."""

    fit: CornerBiasFit
    heights_m: np.ndarray
    missed_views: int


def tag_rig_config(config: DeckLandingConfig) -> DeckLandingConfig:
    """The environment config turned into the tag rig (same camera, deck tag and detector)."""
    return load_config(
        config,
        overrides={**STILL_RIG, "camera.mode": "render"},
    )


def calibrate_tag_corners_in_sim(
    config: DeckLandingConfig | None = None,
    intrinsics: CameraIntrinsics | None = None,
    rig: TagRigConfig | None = None,
    rng: np.random.Generator | None = None,
    progress: Callable[[], None] | None = None,
) -> TagCornerReport:
    """Show the tag to the configured camera from the rig's poses and fit the corner offset.

    ``intrinsics``: the calibrated camera the true corners are projected through (default:
    the configured camera's exact model).  Raises ``RuntimeError`` when fewer than 3 views
    detect the tag.
    """
    config = config if config is not None else load_config("default")
    rig = rig or TagRigConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
    rig_cfg = tag_rig_config(config)
    camera = intrinsics if intrinsics is not None else rig_cfg.camera.intrinsics
    model = tag_corners_in_tag_frame(rig_cfg.deck.tag_size)
    tag_id = rig_cfg.deck.tag_id
    heights = np.linspace(rig.min_height_m, rig.max_height_m, rig.stages)
    detected: list[np.ndarray] = []
    true: list[np.ndarray] = []
    missed = 0
    world = World(rig_cfg)
    try:
        world.reset(rng, world.deck_home_w + np.array([0.0, 0.0, 1.0]), 0.0)
        deck = world.deck_state()
        for height in heights:
            for _ in range(rig.views_per_stage):
                position = deck.position_w.copy()
                position[:2] += rng.uniform(-rig.max_offset_m, rig.max_offset_m, 2)
                position[2] += height
                yaw = float(rng.uniform(-np.pi, np.pi))
                world.place_drone(position, yaw)
                # the camera's height above the tag, not the body's
                _, t_cd = world.true_deck_pose_c()
                position[2] += height - float(t_cd[2])
                world.place_drone(position, yaw)
                frame = world.capture()
                found = [d for d in frame.detections if d.tag_id == tag_id]
                if not found:
                    missed += 1
                    continue
                rotation, translation = world.true_deck_pose_c()
                detected.append(np.asarray(found[0].corners_px, dtype=float))
                true.append(camera.project((rotation @ model.T).T + translation))
            if progress is not None:
                progress()
    finally:
        world.close()
    if len(detected) < 3:
        raise RuntimeError(f"the tag was detected in {len(detected)} views; 3 are needed")
    return TagCornerReport(fit_corner_bias(detected, true), heights, missed)


__all__ = ["TagCornerReport", "TagRigConfig", "calibrate_tag_corners_in_sim", "tag_rig_config"]
