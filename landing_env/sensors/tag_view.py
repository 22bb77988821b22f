"""A tag as the camera sees it: where it is placed, its analytic projection
(:meth:`~landing_env.sensors.camera.CameraSensor.project_tag` makes it) and the reasons a
camera frame can miss it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Miss reasons a CameraFrame can carry.
MISS_BEHIND = "behind_camera"
MISS_OUT_OF_VIEW = "out_of_view"
MISS_OBLIQUE = "too_oblique"
MISS_SMALL = "too_small"
MISS_DROPOUT = "dropout"
MISS_NOT_DETECTED = "not_detected"

#: With several tags and none seen, the frame reports the miss nearest to a detection.
_MISS_PRIORITY = (MISS_NOT_DETECTED, MISS_SMALL, MISS_OBLIQUE, MISS_OUT_OF_VIEW, MISS_BEHIND)


@dataclass(frozen=True)
class TagPlacement:
    """One tag in the world: id, black-border edge (m) and its frame's pose (t_wl, r_wl)."""

    tag_id: int
    size: float
    t_wl: np.ndarray
    r_wl: np.ndarray


def first_miss(reasons: Sequence[str]) -> str:
    """The reason to report when no tag of several is seen (see ``_MISS_PRIORITY``)."""
    for reason in _MISS_PRIORITY:
        if reason in reasons:
            return reason
    return reasons[0] if reasons else MISS_OUT_OF_VIEW


@dataclass(frozen=True)
class ProjectedTag:
    """The analytic view of the tag: corners and the quantities the visibility rules use."""

    corners_px: np.ndarray
    corners_c: np.ndarray
    view_angle_deg: float
    min_side_px: float
    miss_reason: str
