"""The drone's downward camera as a sensor: AprilTag detection in rendered images, or the
analytic projection of the tag corners.

``render`` renders the image (:class:`~landing_env.sensors.camera_render.CameraRenderer`: the
PyBullet or planar scene through the lens distortion) and runs the AprilTag detector.
``project`` projects the tag corners analytically (with distortion, pixel noise, dropouts and
visibility rules); it is what training uses.

Frames: the camera pose is ``(t_wc, r_wc)`` (columns of ``r_wc`` = OpenCV camera axes in W),
the tag pose ``(t_wd, r_wd)`` (see :mod:`estimation.frames`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pybullet_utils.bullet_client import BulletClient

from estimation.detection import AprilTagDetector
from estimation.frames import tag_corners_in_tag_frame
from estimation.types import CameraFrame, TagDetection
from landing_env.sensors.camera_config import CameraConfig
from landing_env.sensors.camera_render import CameraRenderer
from landing_env.sensors.corner_noise import sigma_px
from landing_env.sensors.detection_overlay import draw_detections
from landing_env.sensors.lens_distortion import max_monotonic_radius
from landing_env.sensors.tag_view import (
    MISS_BEHIND,
    MISS_DROPOUT,
    MISS_NOT_DETECTED,
    MISS_OBLIQUE,
    MISS_OUT_OF_VIEW,
    MISS_SMALL,
    ProjectedTag,
    TagPlacement,
    first_miss,
)

#: each tag corner's successor round the tag (its sides run from a corner to the next)
_NEXT_CORNER = [1, 2, 3, 0]


def tag_detector(c: CameraConfig) -> AprilTagDetector:
    """The AprilTag detector the camera settings ``c`` ask for."""
    return AprilTagDetector(
        quad_decimate=c.quad_decimate,
        quad_sigma=c.quad_sigma,
        refine_edges=c.refine_edges,
        decode_sharpening=c.decode_sharpening,
        nthreads=c.detector_threads,
    )


class CameraSensor(CameraRenderer):
    """The downward camera of one PyBullet client (see the module docstring)."""

    _BUILDER_STACKLEVEL = CameraRenderer._BUILDER_STACKLEVEL + 1

    def __init__(
        self, client: int | BulletClient, config: CameraConfig, rng: np.random.Generator
    ) -> None:
        super().__init__(client, config)
        self.rng = rng
        self._max_radius = max_monotonic_radius(self.intrinsics.dist_coeffs)
        #: the tag corners in the tag frame by tag size (the same every frame)
        self._tag_models: dict[float, np.ndarray] = {}
        self._detector: AprilTagDetector | None = None
        if config.mode == "render":
            self._detector = tag_detector(config)

    def close(self) -> None:
        """Free the detector and unload the EGL plugin if this sensor loaded it."""
        if self._detector is not None:
            self._detector.close()
            self._detector = None
        super().close()

    def annotated_image(self, frame: CameraFrame, t_wc: np.ndarray, r_wc: np.ndarray) -> np.ndarray:
        """A full render from the camera pose with ``frame``'s detections drawn (both modes)."""
        return draw_detections(self.render_image(t_wc, r_wc), frame)

    def tag_window(self, corners_px: np.ndarray) -> tuple[int, int, int, int] | None:
        """The image window (x0, y0, x1, y1) rendered round projected corners; None if empty."""
        k, c = self.intrinsics, self.config
        if not np.isfinite(corners_px).all():
            return None
        low, high = corners_px.min(axis=0), corners_px.max(axis=0)
        grow = c.render_margin_frac * (high - low) + c.render_margin_px
        x0 = max(int(np.floor(low[0] - grow[0])), 0)
        y0 = max(int(np.floor(low[1] - grow[1])), 0)
        x1 = min(int(np.ceil(high[0] + grow[0])) + 1, k.width)
        y1 = min(int(np.ceil(high[1] + grow[1])) + 1, k.height)
        if x1 - x0 < 2 or y1 - y0 < 2:
            return None
        return x0, y0, x1, y1

    # ---------------------------------------------------------------------------- projection
    def project_tag(
        self,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        t_wd: np.ndarray,
        r_wd: np.ndarray,
        tag_size: float,
    ) -> ProjectedTag:
        """Project the tag corners (noise-free) and apply the visibility rules."""
        r_wc = np.asarray(r_wc, dtype=float)
        r_wd = np.asarray(r_wd, dtype=float)
        t_cd = r_wc.T @ (np.asarray(t_wd, dtype=float) - np.asarray(t_wc, dtype=float))
        r_cd = r_wc.T @ r_wd
        model = self._tag_models.get(tag_size)
        if model is None:
            model = self._tag_models[tag_size] = tag_corners_in_tag_frame(tag_size)
        corners_c = t_cd + (r_cd @ model.T).T
        # the tag's visible normal is -z_D (z_D points into the deck); angle to the camera ray
        # np.linalg.norm's own arithmetic (a dot product, its square root) without its checks
        to_camera = -t_cd / max(math.sqrt(float(t_cd.dot(t_cd))), 1e-12)
        cos_angle = float(np.dot(-r_cd[:, 2], to_camera))
        view_angle = float(np.degrees(np.arccos(min(max(cos_angle, -1.0), 1.0))))
        if (corners_c[:, 2] <= self.config.near).any():
            nan_corners = np.full((4, 2), np.nan)
            return ProjectedTag(nan_corners, corners_c, view_angle, float("nan"), MISS_BEHIND)
        normalised = corners_c[:, :2] / corners_c[:, 2:3]
        corners_px = self.intrinsics.project(corners_c)
        k, margin = self.intrinsics, self.config.edge_margin_px
        inside = (
            (corners_px[:, 0] >= margin - 0.5)
            & (corners_px[:, 0] <= k.width - 0.5 - margin)
            & (corners_px[:, 1] >= margin - 0.5)
            & (corners_px[:, 1] <= k.height - 0.5 - margin)
            & (_row_norms(normalised) < self._max_radius)
        )
        sides = _row_norms(corners_px - corners_px[_NEXT_CORNER])
        min_side = float(sides.min())
        if not inside.all():
            reason = MISS_OUT_OF_VIEW
        elif view_angle > self.config.max_view_angle_deg:
            reason = MISS_OBLIQUE
        elif min_side < self.config.min_tag_side_px:
            reason = MISS_SMALL
        else:
            reason = ""
        return ProjectedTag(corners_px, corners_c, view_angle, min_side, reason)

    def corner_sigma_px(self, t_wc: np.ndarray, r_wc: np.ndarray, view: ProjectedTag) -> float:
        """Project mode's corner noise (pixels per axis) for a visible tag."""
        c = self.config
        if c.pixel_noise_model == "constant":
            return c.pixel_noise_px
        blur = 0.0
        if self.formation is not None and self.motion is not None:
            centre = self.intrinsics.project(view.corners_c.mean(axis=0)[None], distort=False)[0]
            blur = self.formation.blur_length_px(t_wc, r_wc, self.motion, tuple(centre))
        return float(sigma_px(c.pixel_noise_fit, view.min_side_px, blur))

    # ------------------------------------------------------------------------------- capture
    def capture(
        self,
        timestamp: float,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        t_wd: np.ndarray,
        r_wd: np.ndarray,
        tag_size: float,
        tag_id: int,
    ) -> CameraFrame:
        """One camera frame: the tag's detection (if seen) and, in render mode, the image."""
        return self.capture_tags(
            timestamp, t_wc, r_wc, (TagPlacement(tag_id, tag_size, t_wd, r_wd),)
        )

    def capture_tags(
        self,
        timestamp: float,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        tags: Sequence[TagPlacement],
    ) -> CameraFrame:
        """One camera frame of several tags (nested landmarks): every tag seen is detected.

        With one tag this is :meth:`capture`.  ``project``: each tag follows the visibility
        rules on its own; a dropout drops the whole frame.  ``render`` with the ``tag``
        region: a window is rendered round each tag (with several tags, only those fully
        in view: a tag cut by the image border cannot be decoded) and searched for it.
        """
        if len(tags) > 1:
            return self._capture_many(timestamp, t_wc, r_wc, tags)
        if self.config.mode == "render":
            return self._capture_render(timestamp, t_wc, r_wc, tags[0])
        return self._capture_project(timestamp, t_wc, r_wc, tags[0])

    def _capture_project(
        self, timestamp: float, t_wc: np.ndarray, r_wc: np.ndarray, tag: TagPlacement
    ) -> CameraFrame:
        # draw the random numbers every frame so the stream does not depend on visibility
        dropped = self.rng.random() < self.config.dropout_prob
        unit = self.rng.normal(0.0, 1.0, size=(4, 2))
        view = self.project_tag(t_wc, r_wc, tag.t_wl, tag.r_wl, tag.size)
        if view.miss_reason:
            return CameraFrame(timestamp, (), None, view.miss_reason)
        if dropped:
            return CameraFrame(timestamp, (), None, MISS_DROPOUT)
        noise = unit * self.corner_sigma_px(t_wc, r_wc, view)
        detection = TagDetection(tag_id=tag.tag_id, corners_px=view.corners_px + noise)
        return CameraFrame(timestamp, (detection,), None, "")

    def _capture_render(
        self, timestamp: float, t_wc: np.ndarray, r_wc: np.ndarray, tag: TagPlacement
    ) -> CameraFrame:
        dropped = self.rng.random() < self.config.dropout_prob
        view = self.project_tag(t_wc, r_wc, tag.t_wl, tag.r_wl, tag.size)
        k = self.intrinsics
        # EGL re-creates its framebuffer whenever the size changes, so windows cost more there
        if self.config.render_region == "full" or self.active_renderer == "egl":
            image = self.render_image(t_wc, r_wc, self.rng)
            patch, origin = image, np.zeros(2)
        else:
            # only the pixels round the tag can make its detection; a render of that window
            # is pixel-for-pixel the full render's, at a fraction of the cost
            image = np.full((k.height, k.width, 3), 127, dtype=np.uint8)
            window = None if view.miss_reason == MISS_BEHIND else self.tag_window(view.corners_px)
            if window is None:
                return CameraFrame(timestamp, (), image, view.miss_reason or MISS_OUT_OF_VIEW)
            x0, y0, x1, y1 = window
            patch = self.render_window(t_wc, r_wc, window, self.rng)
            image[y0:y1, x0:x1] = patch
            origin = np.array([x0, y0], dtype=float)
        if self._detector is None:
            raise RuntimeError("the camera has been closed")
        found = [d for d in self._detector.detect(patch) if d.tag_id == tag.tag_id]
        if not found:
            # say why when the geometry explains it, else the detector simply missed it
            return CameraFrame(timestamp, (), image, view.miss_reason or MISS_NOT_DETECTED)
        if dropped:
            return CameraFrame(timestamp, (), image, MISS_DROPOUT)
        best = max(found, key=lambda d: d.decision_margin)
        detection = TagDetection(
            tag_id=best.tag_id,
            corners_px=best.corners_px + origin,
            decision_margin=best.decision_margin,
            hamming=best.hamming,
        )
        return CameraFrame(timestamp, (detection,), image, "")

    def _capture_many(
        self,
        timestamp: float,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        tags: Sequence[TagPlacement],
    ) -> CameraFrame:
        dropped = self.rng.random() < self.config.dropout_prob
        views = [self.project_tag(t_wc, r_wc, t.t_wl, t.r_wl, t.size) for t in tags]
        if self.config.mode == "project":
            detections = []
            for tag, view in zip(tags, views, strict=True):
                unit = self.rng.normal(0.0, 1.0, size=(4, 2))
                if not view.miss_reason:
                    noise = unit * self.corner_sigma_px(t_wc, r_wc, view)
                    detections.append(TagDetection(tag.tag_id, view.corners_px + noise))
            image = None
        else:
            detections, image = self._detect_rendered(t_wc, r_wc, tags, views)
        if not detections:
            reasons = [v.miss_reason or MISS_NOT_DETECTED for v in views]
            return CameraFrame(timestamp, (), image, first_miss(reasons))
        if dropped:
            return CameraFrame(timestamp, (), image, MISS_DROPOUT)
        return CameraFrame(timestamp, tuple(detections), image, "")

    def _detect_rendered(
        self,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        tags: Sequence[TagPlacement],
        views: Sequence[ProjectedTag],
    ) -> tuple[list[TagDetection], np.ndarray]:
        """Render (windows round the tags in view, or the full image) and detect every tag."""
        if self._detector is None:
            raise RuntimeError("the camera has been closed")
        k = self.intrinsics
        wanted = {t.tag_id for t in tags}
        found: dict[int, TagDetection] = {}

        def keep(detections: Sequence[TagDetection], origin: np.ndarray) -> None:
            for d in detections:
                best = found.get(d.tag_id)
                better = best is None or d.decision_margin > best.decision_margin
                if d.tag_id in wanted and better:
                    found[d.tag_id] = TagDetection(
                        d.tag_id, d.corners_px + origin, d.decision_margin, d.hamming
                    )

        if self.config.render_region == "full" or self.active_renderer == "egl":
            image = self.render_image(t_wc, r_wc, self.rng)
            keep(self._detector.detect(image), np.zeros(2))
        else:
            image = np.full((k.height, k.width, 3), 127, dtype=np.uint8)
            for tag, view in zip(tags, views, strict=True):
                if view.miss_reason in (MISS_BEHIND, MISS_OUT_OF_VIEW) or tag.tag_id in found:
                    continue
                window = self.tag_window(view.corners_px)
                if window is None:
                    continue
                x0, y0, x1, y1 = window
                patch = self.render_window(t_wc, r_wc, window, self.rng)
                image[y0:y1, x0:x1] = patch
                keep(self._detector.detect(patch), np.array([x0, y0], dtype=float))
        order = {t.tag_id: i for i, t in enumerate(tags)}
        return sorted(found.values(), key=lambda d: order[d.tag_id]), image


def _row_norms(rows: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(rows, axis=1)`` of a real array, by the same operations (the square
    root of the row sums of the squares) without its argument handling."""
    return np.sqrt(np.add.reduce(rows * rows, axis=1))
