"""AprilTag detection (pupil-apriltags) returning corners in the project's pixel convention.

pupil-apriltags puts pixel centres at ``i + 0.5`` (measured: a black square over pixel columns
100..199 gives corner x ~ 99.9 and ~ 199.9), while the project uses OpenCV's convention
(centre of the top-left pixel at (0, 0)); corners are therefore shifted by -0.5.  Its corner
order is kept: it is the order of :data:`estimation.frames.TAG_CORNER_SIGNS`.
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import cv2
import numpy as np
from pupil_apriltags import Detector

from estimation.types import TagDetection

#: pupil-apriltags' pixel-centre offset relative to OpenCV's convention.
PUPIL_TO_OPENCV_OFFSET_PX: float = -0.5

#: Smallest image side (pixels, before decimation) handed to the native detector.
#: pupil-apriltags 1.0.4 segfaults on thin images: measured in subprocesses
#: (``git show f2da2cc:benchmarks/probe_detector_min_size.py``) it crashed for min(h, w) up to 4 at
#: ``quad_decimate`` 1, 5 at 1.5, 6 at 3 and 8 at 4, and never from the sizes below up to
#: +30 px.  A tag36h11 needs 10 modules across (8 black-border modules and the white quiet
#: zone), so nothing detectable is lost: a smaller image holds no tag at one pixel a module.
MIN_DETECT_SIDE_PX: int = 10


def min_detect_side_px(quad_decimate: float) -> int:
    """The smallest image side passed to pupil-apriltags at this decimation (see above)."""
    return max(MIN_DETECT_SIDE_PX, 4 * math.ceil(quad_decimate))


def _release_safely(detector: Detector) -> None:
    """Free a pupil-apriltags detector: the detector first, then its tag families.

    pupil-apriltags' own ``__del__`` frees the family first, and freeing the detector then
    reads the freed family (intermittent segfaults; pupil-labs/apriltags issues 34 and 46,
    fixed the same way in the dt-apriltags fork).  Clearing the pointer makes its ``__del__``
    a no-op.
    """
    pointer = getattr(detector, "tag_detector_ptr", None)
    if pointer is None:
        return
    libc = detector.libc
    libc.apriltag_detector_destroy.restype = None
    libc.apriltag_detector_destroy(pointer)
    for family, family_pointer in detector.tag_families.items():
        destroy = getattr(libc, f"{family}_destroy")
        destroy.restype = None
        destroy(family_pointer)
    detector.tag_detector_ptr = None


def to_gray(image: np.ndarray) -> np.ndarray:
    """Return a contiguous uint8 grey image from a uint8 grey, RGB or RGBA image."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise TypeError(f"expected a uint8 image, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_RGBA2GRAY)
    elif image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    elif image.ndim != 2:
        raise ValueError(f"expected an HxW, HxWx3 or HxWx4 image, got shape {image.shape}")
    return np.ascontiguousarray(image)


class AprilTagDetector:
    """A pupil-apriltags detector with the project's corner convention.

    Parameters are pupil-apriltags' own: ``quad_decimate`` > 1 speeds detection up at the
    cost of range (small tags are lost) but not of corner accuracy (edges are refined on the
    full-resolution image when ``refine_edges`` is on).
    """

    def __init__(
        self,
        families: str = "tag36h11",
        quad_decimate: float = 1.0,
        quad_sigma: float = 0.0,
        refine_edges: bool = True,
        decode_sharpening: float = 0.25,
        nthreads: int = 1,
        max_hamming: int = 0,
    ) -> None:
        if quad_decimate < 1.0:
            raise ValueError(f"quad_decimate must be >= 1, got {quad_decimate}")
        if nthreads < 1:
            raise ValueError(f"nthreads must be >= 1, got {nthreads}")
        self.families = families
        self.max_hamming = max_hamming
        self._arguments = (
            families,
            quad_decimate,
            quad_sigma,
            refine_edges,
            decode_sharpening,
            nthreads,
            max_hamming,
        )
        #: images with a smaller side hold no tag and are never passed to the native code
        self.min_side_px = min_detect_side_px(quad_decimate)
        self._detector = Detector(
            families=families,
            nthreads=nthreads,
            quad_decimate=quad_decimate,
            quad_sigma=quad_sigma,
            refine_edges=int(refine_edges),
            decode_sharpening=decode_sharpening,
        )
        # runs when this wrapper is collected or at interpreter exit, before pupil's __del__
        self._finalizer = weakref.finalize(self, _release_safely, self._detector)

    def close(self) -> None:
        """Free the C detector now (it is freed on collection otherwise)."""
        self._finalizer()

    def __deepcopy__(self, memo: dict[int, Any]) -> AprilTagDetector:
        """Shared, not copied: a detection depends on its image alone (no state is carried
        from one call to the next), and the native detector holds C pointers that cannot be
        copied. An environment snapshot (the oracle's look-ahead) relies on this."""
        memo[id(self)] = self
        return self

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled as its settings: the receiving process builds its own native detector."""
        return (AprilTagDetector, self._arguments)

    def detect(self, gray_or_rgb: np.ndarray) -> tuple[TagDetection, ...]:
        """Detect tags; corners are 4x2 OpenCV pixels in AprilTag order (see module doc)."""
        if not self._finalizer.alive:
            raise RuntimeError("the detector has been closed")
        image = np.asarray(gray_or_rgb)
        if image.dtype != np.uint8:
            raise TypeError(f"expected a uint8 image, got {image.dtype}")
        if image.ndim in (2, 3) and min(image.shape[:2]) < self.min_side_px:
            # too small to hold a tag, and such shapes crash the C detector (see above)
            return ()
        gray = to_gray(image)
        results = self._detector.detect(gray)
        detections = []
        for result in results:
            if result.hamming > self.max_hamming:
                continue
            corners = np.asarray(result.corners, dtype=float) + PUPIL_TO_OPENCV_OFFSET_PX
            detections.append(
                TagDetection(
                    tag_id=int(result.tag_id),
                    corners_px=corners,
                    decision_margin=float(result.decision_margin),
                    hamming=int(result.hamming),
                )
            )
        return tuple(detections)
