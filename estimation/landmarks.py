"""Nested landmarks: several AprilTags of different sizes on one deck, and which one to use.

A large tag is decodable from high up and a small one still fits in the view near the deck
(SVGS Sec. 2.5.1 uses three beacon sizes for the same reason).  Every landmark ``L`` lies
on the deck surface with the axes of the deck frame D (AprilTag convention: x right, y down,
z into the deck) and its centre at ``(x, y, 0)`` in D.  The deck frame D stays the landing
point's frame, so an estimate of a landmark's pose ``T_CL`` is turned into ``T_CD`` by

    R_CD = R_CL,    t_CD = t_CL - R_CL (x, y, 0)

and nothing downstream knows which landmark was used.

Choice rule (:func:`choose_landmark`): among the detected tags of the layout, those whose
image side (the shortest side in pixels) lies within ``[min_side_px, max_side_px]`` come
first; among them

* ``prefer="largest"`` (ATDA, camera only) takes the largest image: with corner noise of a
  roughly constant number of pixels the pose error falls with the tag's image size;
* ``prefer="nearest"`` (IHRCF, CRHF) takes the tag nearest the landing point (the origin of
  D).  Their depth and tilt come from the ToF touch points round the camera axis, so a tag
  far from the axis is reconstructed by extrapolating that small patch, and any rotation
  error is multiplied by the tag's offset when the pose is moved to D.  Measured in render
  mode over the high-approach deck at 3 m: IHRCF 0.8 mm from the 0.12 m tag at the landing
  point (18 px) against 6 mm from the 0.4 m tag and 45 mm from the 1.1 m tag 0.78 m away.

A detected tag is fully in view (the detector needs all four corners).  Tags below
``min_side_px`` are at the edge of decoding (measured in render mode: pupil-apriltags
decodes every frame from 12 px side, 8 in 10 at 11 px, 3 in 10 at 10 px) and are used only
when nothing in the band is seen; ``max_side_px`` keeps a tag that fills the view as a last
resort too.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from estimation.errors import ConfigError, require_choice
from estimation.frames import tag_corners_in_tag_frame
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.types import CameraFrame, DeckPoseEstimate, RangeReading, TagDetection

#: Cells across a tag36h11 tag including its black border (the data bits are 6 x 6).
TAG_CELLS = 8

#: tag36h11 has 587 codes.
MAX_TAG_ID = 586

#: Reason of an invalid estimate when no landmark of the layout is detected.
NO_LANDMARK = "no_detection"


@dataclass(frozen=True)
class Landmark:
    """One tag on the deck: its id, black-border edge (m) and centre ``(x, y)`` in D (m)."""

    tag_id: int = limited(limit=Limit(0, MAX_TAG_ID))
    size: float = limited(limit=POSITIVE)
    x: float = 0.0
    y: float = 0.0

    def __post_init__(self) -> None:
        require_limits(self)
        for name in ("x", "y"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(name, f"{getattr(self, name)!r} is not finite")

    @property
    def offset_d(self) -> np.ndarray:
        """The landmark centre in D, metres (on the deck surface: z = 0)."""
        return np.array([self.x, self.y, 0.0])

    def corners_d(self) -> np.ndarray:
        """The 4x3 corners in D, in detection order."""
        return tag_corners_in_tag_frame(self.size) + self.offset_d

    def outer_half_extent(self, quiet_zone_cells: float) -> float:
        """Half the edge of the tag plus its white quiet zone, metres."""
        return 0.5 * self.size * (TAG_CELLS + 2.0 * quiet_zone_cells) / TAG_CELLS


@dataclass(frozen=True)
class LandmarkLayout:
    """The landmarks on a deck: distinct ids, quiet zones that do not overlap."""

    landmarks: tuple[Landmark, ...]
    #: width of the white quiet zone round every tag, in its cells (size / 8)
    quiet_zone_cells: float = limited(1.0, NON_NEGATIVE)

    def __post_init__(self) -> None:
        if not self.landmarks:
            raise ConfigError("landmarks", "need at least one landmark")
        require_limits(self)
        ids = [lm.tag_id for lm in self.landmarks]
        if len(set(ids)) != len(ids):
            raise ConfigError("landmarks", f"tag ids {ids} must be distinct")
        for i, a in enumerate(self.landmarks):
            for b in self.landmarks[i + 1 :]:
                gap = self._gap(a, b)
                if gap < 0.0:
                    raise ConfigError(
                        "landmarks",
                        f"tags {a.tag_id} and {b.tag_id} overlap (with their quiet zones) by "
                        f"{-gap:.3f} m; move them apart or shrink them",
                    )

    def _gap(self, a: Landmark, b: Landmark) -> float:
        """Clearance between the two quiet-zone squares (negative when they overlap)."""
        reach = a.outer_half_extent(self.quiet_zone_cells) + b.outer_half_extent(
            self.quiet_zone_cells
        )
        return max(abs(a.x - b.x), abs(a.y - b.y)) - reach

    @classmethod
    def single(cls, tag_id: int, size: float, quiet_zone_cells: float = 1.0) -> LandmarkLayout:
        """One tag at the deck centre (the default deck)."""
        return cls((Landmark(tag_id, size),), quiet_zone_cells)

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(lm.tag_id for lm in self.landmarks)

    @property
    def is_single_centred(self) -> bool:
        """One tag at the origin of D: estimates need no composition."""
        only = self.landmarks[0]
        return len(self.landmarks) == 1 and only.x == 0.0 and only.y == 0.0

    def by_id(self, tag_id: int) -> Landmark | None:
        for landmark in self.landmarks:
            if landmark.tag_id == tag_id:
                return landmark
        return None

    def extent(self) -> float:
        """The largest ``|x|`` or ``|y|`` in D reached by a tag's quiet zone, metres."""
        return max(
            max(abs(lm.x), abs(lm.y)) + lm.outer_half_extent(self.quiet_zone_cells)
            for lm in self.landmarks
        )

    def check_fits(self, deck_size: float) -> None:
        """Raise ConfigError unless every tag with its quiet zone lies on the square deck."""
        half = 0.5 * deck_size
        for lm in self.landmarks:
            reach = max(abs(lm.x), abs(lm.y)) + lm.outer_half_extent(self.quiet_zone_cells)
            if reach > half + 1e-12:
                raise ConfigError(
                    "landmarks",
                    f"tag {lm.tag_id} (size {lm.size} m at ({lm.x}, {lm.y})) reaches "
                    f"{reach:.3f} m from the deck centre with its quiet zone; the "
                    f"{deck_size} m deck allows {half:.3f} m",
                )


#: What the choice rule prefers among the tags in the pixel band.
PREFERENCES = ("largest", "nearest")


@dataclass(frozen=True)
class LandmarkChoiceConfig:
    """The choice rule: the pixel band and the preference within it (module docstring)."""

    min_side_px: float = limited(12.0, NON_NEGATIVE)
    max_side_px: float = 400.0
    prefer: str = "largest"

    def __post_init__(self) -> None:
        require_choice("prefer", self.prefer, PREFERENCES)
        require_limits(self)
        if not self.max_side_px > self.min_side_px:
            raise ConfigError(
                "max_side_px", f"{self.max_side_px} must exceed min_side_px = {self.min_side_px}"
            )


@dataclass(frozen=True)
class LandmarkChoice:
    """The chosen landmark, its detection and its shortest image side (px)."""

    landmark: Landmark
    detection: TagDetection
    side_px: float
    in_band: bool


def shortest_side_px(corners_px: np.ndarray) -> float:
    """The shortest side of a detected quadrilateral, pixels (NaN if the corners are not finite)."""
    corners = np.asarray(corners_px, dtype=float).reshape(4, 2)
    if not np.all(np.isfinite(corners)):
        return math.nan
    return float(np.min(np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1)))


def choose_landmark(
    frame: CameraFrame,
    layout: LandmarkLayout,
    config: LandmarkChoiceConfig | None = None,
) -> LandmarkChoice | None:
    """The detected landmark to estimate from (the rule in the module docstring), or None."""
    config = config or LandmarkChoiceConfig()
    candidates: list[LandmarkChoice] = []
    for detection in frame.detections:
        landmark = layout.by_id(detection.tag_id)
        if landmark is None:
            continue
        side = shortest_side_px(detection.corners_px)
        if not math.isfinite(side):
            continue
        in_band = config.min_side_px <= side <= config.max_side_px
        candidates.append(LandmarkChoice(landmark, detection, side, in_band))
    if not candidates:
        return None
    if config.prefer == "nearest":
        # in the band first, then the nearest to the landing point, then the largest image
        return max(
            candidates,
            key=lambda c: (c.in_band, -math.hypot(c.landmark.x, c.landmark.y), c.side_px),
        )
    # in the band first, then the largest image; a tie goes to the better-decoded one
    return max(candidates, key=lambda c: (c.in_band, c.side_px, -c.detection.hamming))


def compose_deck_pose(
    rotation_cl: np.ndarray, translation_cl: np.ndarray, landmark: Landmark
) -> tuple[np.ndarray, np.ndarray]:
    """``(R_CD, t_CD)`` of the deck frame from a landmark's pose ``(R_CL, t_CL)``."""
    rotation_cl = np.asarray(rotation_cl, dtype=float)
    return rotation_cl, np.asarray(translation_cl, dtype=float) - rotation_cl @ landmark.offset_d


def landmark_pose_w(
    t_wd: np.ndarray, r_wd: np.ndarray, landmark: Landmark
) -> tuple[np.ndarray, np.ndarray]:
    """A landmark's world pose ``(t_WL, R_WL)`` from the deck frame's ``(t_WD, R_WD)``."""
    r_wd = np.asarray(r_wd, dtype=float)
    return np.asarray(t_wd, dtype=float) + r_wd @ landmark.offset_d, r_wd


@dataclass
class LandmarkEstimator:
    """Runs one estimator per landmark on the chosen landmark and reports ``T_CD`` of D.

    ``make_one(landmark)`` builds the per-landmark estimator (ATDA, IHRCF, CRHF, possibly
    tracked); each sees only its own tag, so its state (ATDA's previous pose, a corner
    track) belongs to that tag.  When no landmark is detected, the last chosen landmark's
    estimator still runs on the frame, so that a corner tracker can bridge the gap.
    ``extras`` gain ``landmark_id`` and ``landmark_side_px``.
    """

    name: str
    layout: LandmarkLayout
    make_one: Callable[[Landmark], object]
    choice: LandmarkChoiceConfig = field(default_factory=LandmarkChoiceConfig)

    def __post_init__(self) -> None:
        self._estimators = {lm.tag_id: self.make_one(lm) for lm in self.layout.landmarks}
        self._last: Landmark | None = None

    def reset(self) -> None:
        for estimator in self._estimators.values():
            estimator.reset()  # type: ignore[attr-defined]
        self._last = None

    def estimate(self, frame: CameraFrame, ranges: RangeReading) -> DeckPoseEstimate:
        chosen = choose_landmark(frame, self.layout, self.choice)
        if chosen is None and self._last is None:
            return DeckPoseEstimate.invalid(self.name, float(frame.timestamp), NO_LANDMARK)
        landmark = chosen.landmark if chosen is not None else self._last
        assert landmark is not None
        inner = self._estimators[landmark.tag_id]
        estimate: DeckPoseEstimate = inner.estimate(frame, ranges)  # type: ignore[attr-defined]
        if chosen is not None:
            self._last = landmark
        extras = {
            **estimate.extras,
            "landmark_id": landmark.tag_id,
            "landmark_side_px": chosen.side_px if chosen is not None else math.nan,
        }
        if not estimate.valid:
            return replace(estimate, method=self.name, extras=extras)
        rotation, translation = compose_deck_pose(estimate.rotation, estimate.translation, landmark)
        return replace(
            estimate,
            method=self.name,
            rotation=rotation,
            translation=translation,
            extras=extras,
        )


def layout_from_pairs(
    pairs: Sequence[tuple[int, float, float, float]], quiet_zone_cells: float = 1.0
) -> LandmarkLayout:
    """A layout from ``(tag_id, size, x, y)`` rows (a convenience for tests and scripts)."""
    return LandmarkLayout(tuple(Landmark(*row) for row in pairs), quiet_zone_cells)


__all__ = [
    "NO_LANDMARK",
    "PREFERENCES",
    "TAG_CELLS",
    "Landmark",
    "LandmarkChoice",
    "LandmarkChoiceConfig",
    "LandmarkEstimator",
    "LandmarkLayout",
    "choose_landmark",
    "compose_deck_pose",
    "landmark_pose_w",
    "layout_from_pairs",
    "shortest_side_px",
]
