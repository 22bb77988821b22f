"""The drone's downward camera: rendered images + AprilTag detection, or analytic projection.

``render`` draws the PyBullet scene with an OpenGL projection built from the intrinsics so that
the pinhole model lands on the rendered pixels, warps the ideal image through the lens
distortion and runs the AprilTag detector.  ``project`` projects the tag corners analytically
(with distortion, pixel noise, dropouts and visibility rules); it is what training uses.

Frames: the camera pose is ``(t_wc, r_wc)`` (columns of ``r_wc`` = OpenCV camera axes in W),
the tag pose ``(t_wd, r_wd)`` (see :mod:`estimation.frames`).
"""

from __future__ import annotations

import importlib.util
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient

from estimation.camera_model import CameraIntrinsics
from estimation.detection import AprilTagDetector
from estimation.frames import tag_corners_in_tag_frame
from estimation.types import CameraFrame, TagDetection
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.sensors.camera_profiles import PROFILES, camera_profile
from landing_env.sensors.camera_realism import Glare, ImageFormation, RelativeMotion
from landing_env.sensors.corner_noise import sigma_px
from landing_env.sensors.planar_renderer import PlanarScene, UnsupportedScene

#: Miss reasons a CameraFrame can carry.
MISS_BEHIND = "behind_camera"
MISS_OUT_OF_VIEW = "out_of_view"
MISS_OBLIQUE = "too_oblique"
MISS_SMALL = "too_small"
MISS_DROPOUT = "dropout"
MISS_NOT_DETECTED = "not_detected"

#: With several tags and none seen, the frame reports the miss nearest to a detection.
_MISS_PRIORITY = (MISS_NOT_DETECTED, MISS_SMALL, MISS_OBLIQUE, MISS_OUT_OF_VIEW, MISS_BEHIND)

#: Where each renderer puts the content of a point at OpenCV pixel u (v) relative to u (v),
#: measured with this module's projection: TinyRenderer samples pixel i at screen coordinate
#: i instead of i + 0.5 and flips rows, so it shifts content by (+0.5, -0.5) px; OpenGL
#: (EGL) samples pixel centres and shows no shift (measured with Mesa's llvmpipe: the planar
#: renderer's corners are off OpenGL's by a mean vector under 0.01 px; see
#: :mod:`landing_env.sensors.renderer_agreement`).
RENDERER_SHIFT_PX: dict[str, tuple[float, float]] = {"tiny": (0.5, -0.5), "egl": (0.0, 0.0)}

#: Clients of this process with the EGL plugin loaded.  The plugin keeps one scene for the
#: whole process: a second client's renders would show the first one's bodies too (measured:
#: two worlds' decks in one image), so only one client at a time may render with EGL.
_EGL_CLIENTS: set[int] = set()

#: OpenGL camera axes in the OpenCV camera frame: x right, y up, looking along -z.
_CV_FROM_GL = np.diag([1.0, -1.0, -1.0])


def _client_id(client: int | BulletClient) -> int:
    """The physics-client id of an id or a ``pybullet_utils`` BulletClient (which keeps it in
    ``_client``; it has no public accessor)."""
    return int(getattr(client, "_client", client))


@dataclass
class CameraConfig:
    """Camera model, simulation mode, visibility rules and detector settings."""

    mode: Literal["render", "project"] = "project"
    width: int = 512
    height: int = 512
    fx: float = 458.5
    fy: float = 457.855
    #: principal point, pixels (OpenCV convention); None = image centre, (width - 1) / 2
    cx: float | None = None
    cy: float | None = None
    #: OpenCV radial-tangential distortion
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    #: clipping planes of the renderer, metres; nearer tag corners count as behind the camera
    near: float = 0.05
    far: float = 30.0
    #: Gaussian corner noise, pixels (project mode)
    pixel_noise_px: float = 0.0
    #: project mode's corner noise: "constant" (``pixel_noise_px``) or "fitted": sigma from
    #: the tag's side and blur in pixels with ``pixel_noise_fit`` = (base px, size px^3,
    #: blur fraction, side^2 coefficient), fitted to render-and-detect under a camera profile
    #: (:mod:`landing_env.sensors.corner_noise`; ``sensors: realistic`` sets both)
    pixel_noise_model: Literal["constant", "fitted"] = "constant"
    pixel_noise_fit: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    #: probability that a visible tag is dropped from a frame (both modes)
    dropout_prob: float = 0.0
    #: angle between the tag normal and the ray from the tag centre to the camera, degrees
    max_view_angle_deg: float = 75.0
    #: shortest tag side in pixels below which the tag is not detected (project mode)
    min_tag_side_px: float = 12.0
    #: corners must lie this far inside the image, pixels
    edge_margin_px: float = 2.0
    #: pupil-apriltags settings (render mode)
    quad_decimate: float = 1.0
    quad_sigma: float = 0.0
    refine_edges: bool = True
    decode_sharpening: float = 0.25
    detector_threads: int = 1
    #: render mode: "tag" renders and searches only a window round where the tag projects
    #: (the pixels there are the same as in a full render; the frame's image is grey outside
    #: it); "full" renders the whole image.  Both detect from pixels only.
    render_region: Literal["tag", "full"] = "tag"
    #: the "tag" window extends the tag's pixel bounding box by this fraction of its size
    #: and ``render_margin_px`` on each side (the quiet zone is 1/8 of the tag)
    render_margin_frac: float = 0.25
    render_margin_px: int = 8
    #: render with the EGL plugin (OpenGL, falls back to TinyRenderer when it cannot load);
    #: EGL always renders the full image (its cost jumps whenever the image size changes),
    #: and it only draws bodies created after it is loaded (the world creates its camera
    #: first); it draws one scene per process, so only one client at a time may use it
    use_egl: bool = False
    #: "planar" draws the scene a downward camera sees with OpenCV homographies and polygons
    #: (:mod:`landing_env.sensors.planar_renderer`: about 1-3 ms a frame at any height) when
    #: the world has attached its scene (:meth:`CameraSensor.attach_scene`); "bullet" is the
    #: reference, PyBullet's TinyRenderer (or EGL with ``use_egl``).  Without an attached
    #: scene (calibration rigs, bare clients) the camera renders with "bullet".
    renderer: Literal["planar", "bullet"] = "planar"
    #: the camera class (:mod:`landing_env.sensors.camera_profiles`): "ideal" (the papers'
    #: simulator: the rendered image as it is), "ov9281" (global shutter) or "imx219"
    #: (rolling shutter); the others add exposure blur, noise, vignetting and response
    profile: str = "ideal"
    #: exposure time, seconds; None = the profile's
    exposure_s: float | None = None
    #: analog gain (1 = the sensor's 0 dB, where full well meets the ADC's top)
    gain: float = 1.0
    #: direction towards the sun in the world (x, y, z) for specular glare on the deck;
    #: None = no glare.  ``glare_strength``: the lobe's peak in white-surface units
    sun_direction_w: tuple[float, float, float] | None = None
    glare_strength: float = 4.0
    glare_shininess: float = 300.0
    #: renderer lighting; specular off so the white quiet zone does not saturate in patches
    light_ambient: float = 0.6
    light_diffuse: float = 0.4
    light_specular: float = 0.0

    def __post_init__(self) -> None:
        require_choice("mode", self.mode, ("render", "project"))
        require_range("width", self.width, 16, 8192)
        require_range("height", self.height, 16, 8192)
        require_range("fx", self.fx, 0.0, low_inclusive=False)
        require_range("fy", self.fy, 0.0, low_inclusive=False)
        if self.cx is not None:
            require_range(
                "cx", self.cx, -0.5, self.width - 0.5, bounds_from=f"width = {self.width}"
            )
        if self.cy is not None:
            require_range(
                "cy", self.cy, -0.5, self.height - 0.5, bounds_from=f"height = {self.height}"
            )
        require_range("near", self.near, 0.0, low_inclusive=False)
        if self.far <= self.near:
            raise ConfigError("far", f"{self.far} must be greater than near = {self.near}")
        require_range("pixel_noise_px", self.pixel_noise_px, 0.0)
        require_choice("pixel_noise_model", self.pixel_noise_model, ("constant", "fitted"))
        if len(self.pixel_noise_fit) != 4 or any(
            not np.isfinite(v) or v < 0.0 for v in self.pixel_noise_fit
        ):
            raise ConfigError(
                "pixel_noise_fit", f"{self.pixel_noise_fit!r}: need four finite values >= 0"
            )
        require_range("dropout_prob", self.dropout_prob, 0.0, 1.0)
        require_range("max_view_angle_deg", self.max_view_angle_deg, 0.0, 90.0)
        require_range("min_tag_side_px", self.min_tag_side_px, 0.0)
        require_range(
            "edge_margin_px", self.edge_margin_px, 0.0, 0.25 * min(self.width, self.height)
        )
        require_range("quad_decimate", self.quad_decimate, 1.0)
        require_range("quad_sigma", self.quad_sigma, 0.0)
        require_range("decode_sharpening", self.decode_sharpening, 0.0)
        require_range("detector_threads", self.detector_threads, 1, 64)
        require_choice("render_region", self.render_region, ("tag", "full"))
        require_choice("renderer", self.renderer, ("planar", "bullet"))
        require_choice("profile", self.profile, tuple(PROFILES))
        if self.exposure_s is not None:
            require_range("exposure_s", self.exposure_s, 0.0, 0.1)
        require_range("gain", self.gain, 0.0, 64.0, low_inclusive=False)
        if self.sun_direction_w is not None:
            sun = np.asarray(self.sun_direction_w, dtype=float)
            if sun.shape != (3,) or not np.all(np.isfinite(sun)) or np.linalg.norm(sun) == 0:
                raise ConfigError(
                    "sun_direction_w", f"{self.sun_direction_w!r}: need a nonzero (x, y, z)"
                )
        require_range("glare_strength", self.glare_strength, 0.0)
        require_range("glare_shininess", self.glare_shininess, 1.0)
        require_range("render_margin_frac", self.render_margin_frac, 0.0)
        require_range("render_margin_px", self.render_margin_px, 0)
        for name in ("light_ambient", "light_diffuse", "light_specular"):
            require_range(name, getattr(self, name), 0.0, 1.0)

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera model (principal point defaulted to the image centre)."""
        return CameraIntrinsics(
            width=self.width,
            height=self.height,
            fx=self.fx,
            fy=self.fy,
            cx=(self.width - 1) / 2 if self.cx is None else self.cx,
            cy=(self.height - 1) / 2 if self.cy is None else self.cy,
            dist=(self.k1, self.k2, self.p1, self.p2, self.k3),
        )


def opengl_projection(
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    width: int,
    height: int,
    near: float,
    far: float,
) -> np.ndarray:
    """The 4x4 OpenGL projection (row-major) whose viewport pixels match the pinhole model.

    OpenCV pixel u spans the image as [-0.5, width - 0.5], i.e. x_ndc = 2 (u + 0.5) / width - 1,
    and the image top (v = -0.5) is y_ndc = +1.  Points are in OpenGL eye coordinates.
    """
    projection = np.zeros((4, 4))
    projection[0, 0] = 2.0 * fx / width
    projection[0, 2] = 1.0 - 2.0 * (cx + 0.5) / width
    projection[1, 1] = 2.0 * fy / height
    projection[1, 2] = 2.0 * (cy + 0.5) / height - 1.0
    projection[2, 2] = -(far + near) / (far - near)
    projection[2, 3] = -2.0 * far * near / (far - near)
    projection[3, 2] = -1.0
    return projection


def opengl_view(t_wc: np.ndarray, r_wc: np.ndarray) -> np.ndarray:
    """The 4x4 OpenGL view matrix (row-major, world to eye) of an OpenCV camera pose."""
    r_w_gl = np.asarray(r_wc, dtype=float) @ _CV_FROM_GL
    view = np.eye(4)
    view[:3, :3] = r_w_gl.T
    view[:3, 3] = -r_w_gl.T @ np.asarray(t_wc, dtype=float)
    return view


def _column_major(matrix: np.ndarray) -> list[float]:
    """Flatten a 4x4 matrix the way PyBullet (OpenGL) expects it."""
    return matrix.flatten(order="F").tolist()


class _DistortionWarp:
    """Where each pixel of the distorted image comes from in the ideal (pinhole) image.

    Each distorted pixel looks up its ideal position (cv2.undistortPoints, iterated to
    convergence).  Barrel distortion needs ideal pixels beyond the image; any window of the
    ideal image plane can be rendered (negative coordinates included), so none is lost.  Only
    ideal pixels more than one image size beyond the image are left out (black): a lens that
    maps those into the image is far outside this model's use.
    """

    def __init__(self, intrinsics: CameraIntrinsics) -> None:
        w, h = intrinsics.width, intrinsics.height
        self.limits = (-w, -h, 2 * w, 2 * h)
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        ideal = cv2.undistortPoints(
            grid.astype(np.float64),
            intrinsics.matrix,
            intrinsics.dist_coeffs,
            P=intrinsics.matrix,
            criteria=criteria,
        ).reshape(h, w, 2)
        #: ideal-image coordinates of every distorted pixel
        self.map_x = ideal[..., 0].astype(np.float32)
        self.map_y = ideal[..., 1].astype(np.float32)

    def source_window(self, x0: int, y0: int, x1: int, y1: int) -> tuple[int, int, int, int]:
        """The ideal-image window (x0, y0, x1, y1) that the distorted window needs."""
        mx = self.map_x[y0:y1, x0:x1]
        my = self.map_y[y0:y1, x0:x1]
        lx0, ly0, lx1, ly1 = self.limits
        # one extra pixel each side for bilinear interpolation
        return (
            int(np.clip(np.floor(mx.min()) - 1, lx0, lx1 - 2)),
            int(np.clip(np.floor(my.min()) - 1, ly0, ly1 - 2)),
            int(np.clip(np.ceil(mx.max()) + 2, lx0 + 2, lx1)),
            int(np.clip(np.ceil(my.max()) + 2, ly0 + 2, ly1)),
        )

    def warp(
        self,
        source: np.ndarray,
        source_origin: tuple[int, int],
        window: tuple[int, int, int, int],
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """The distorted ``window`` (x0, y0, x1, y1) from an ideal render starting at origin
        (into ``out`` when given, of the window's shape and the source's type)."""
        x0, y0, x1, y1 = window
        sx, sy = source_origin
        return cv2.remap(
            source,
            self.map_x[y0:y1, x0:x1] - np.float32(sx),
            self.map_y[y0:y1, x0:x1] - np.float32(sy),
            dst=out,
            interpolation=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )


def _max_monotonic_radius(dist: np.ndarray) -> float:
    """Largest normalised radius up to which the radial distortion keeps increasing.

    Beyond it the polynomial folds back and far-off points would project into the image.
    """
    k1, k2, _, _, k3 = dist
    radii = np.linspace(0.0, 10.0, 20001)
    r2 = radii**2
    derivative = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2**2 + 7.0 * k3 * r2**3
    bad = np.nonzero(derivative <= 0.0)[0]
    return float(radii[bad[0]]) if bad.size else float("inf")


@dataclass(frozen=True)
class TagPlacement:
    """One tag in the world: id, black-border edge (m) and its frame's pose (t_wl, r_wl)."""

    tag_id: int
    size: float
    t_wl: np.ndarray
    r_wl: np.ndarray


def _first_miss(reasons: Sequence[str]) -> str:
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


class CameraSensor:
    """The downward camera of one PyBullet client (see the module docstring)."""

    def __init__(
        self, client: int | BulletClient, config: CameraConfig, rng: np.random.Generator
    ) -> None:
        self.client = _client_id(client)
        self.config = config
        self.rng = rng
        self.intrinsics = config.intrinsics
        self._max_radius = _max_monotonic_radius(self.intrinsics.dist_coeffs)
        self._warp = _DistortionWarp(self.intrinsics) if self.intrinsics.has_distortion else None
        self._egl_plugin: int | None = None
        self._planar: PlanarScene | None = None
        self.renderer = "tiny"
        if config.use_egl:
            self._load_egl()
        self._detector: AprilTagDetector | None = None
        if config.mode == "render":
            self._detector = self._make_detector()
        #: exposure and sensor model (None for the ideal profile)
        self.formation = self._make_formation(config)
        #: the camera's and deck's motion for the next exposure (set by the world)
        self.motion: RelativeMotion | None = None
        #: noise for images made only to be looked at (rgb_array), so that rendering them
        #: leaves the sensing streams as they are
        self._display_rng = np.random.default_rng(0)

    def _make_formation(self, c: CameraConfig) -> ImageFormation | None:
        profile = camera_profile(c.profile)
        if profile.ideal:
            return None
        glare = None
        if c.sun_direction_w is not None:
            glare = Glare(
                np.asarray(c.sun_direction_w, dtype=float), c.glare_strength, c.glare_shininess
            )
        return ImageFormation(profile, self.intrinsics, c.exposure_s, c.gain, glare)

    def _make_detector(self) -> AprilTagDetector:
        c = self.config
        return AprilTagDetector(
            quad_decimate=c.quad_decimate,
            quad_sigma=c.quad_sigma,
            refine_edges=c.refine_edges,
            decode_sharpening=c.decode_sharpening,
            nthreads=c.detector_threads,
        )

    def _load_egl(self) -> None:
        """Load PyBullet's EGL renderer plugin; keep TinyRenderer (and warn) if it fails."""
        live = {c for c in _EGL_CLIENTS if p.isConnected(physicsClientId=c)}
        _EGL_CLIENTS.intersection_update(live)
        if live - {self.client}:
            warnings.warn(
                "EGL renderer already in use by another PyBullet client of this process (its "
                "plugin draws one scene per process); using TinyRenderer",
                stacklevel=3,
            )
            return
        try:
            spec = importlib.util.find_spec("eglRenderer")
            if spec is not None and spec.origin:
                plugin = p.loadPlugin(
                    spec.origin, "_eglRendererPlugin", physicsClientId=self.client
                )
            else:
                plugin = p.loadPlugin("eglRendererPlugin", physicsClientId=self.client)
        except (p.error, ImportError, ValueError) as exc:
            warnings.warn(f"EGL renderer unavailable ({exc}); using TinyRenderer", stacklevel=3)
            return
        if plugin < 0:
            warnings.warn("EGL renderer plugin did not load; using TinyRenderer", stacklevel=3)
            return
        self._egl_plugin = plugin
        self.renderer = "egl"
        _EGL_CLIENTS.add(self.client)

    def attach_scene(self, scene: PlanarScene) -> None:
        """Let the planar renderer draw this client's scene (when ``renderer`` is "planar")."""
        if self.config.renderer == "planar":
            self._planar = scene

    @property
    def active_renderer(self) -> str:
        """What draws the images: "planar", "tiny" (TinyRenderer) or "egl"."""
        return "planar" if self._planar is not None else self.renderer

    def close(self) -> None:
        """Free the detector and unload the EGL plugin if this sensor loaded it."""
        if self._detector is not None:
            self._detector.close()
            self._detector = None
        if self._egl_plugin is not None:
            try:
                p.unloadPlugin(self._egl_plugin, physicsClientId=self.client)
            except p.error:
                pass  # the client is already gone, and the plugin with it
            _EGL_CLIENTS.discard(self.client)
            self._egl_plugin = None
            self.renderer = "tiny"

    # ----------------------------------------------------------------------------- rendering
    def _render_canvas(
        self, t_wc: np.ndarray, r_wc: np.ndarray, window: tuple[int, int, int, int]
    ) -> np.ndarray:
        """Render the window (x0, y0, x1, y1) of the ideal (pinhole) image plane as RGB uint8.

        A window is rendered by moving the principal point, so its pixels equal those of a
        full render; it may extend beyond the image (negative coordinates included).
        """
        k = self.intrinsics
        x0, y0, x1, y1 = window
        width, height = x1 - x0, y1 - y0
        if self._planar is not None:
            try:
                self._planar.refresh_if_changed()
                k_window = k.matrix - np.array([[0, 0, x0], [0, 0, y0], [0, 0, 0]], dtype=float)
                return self._planar.render(
                    t_wc, r_wc, k_window, width, height, self.config.near, self.config.far
                )
            except UnsupportedScene as exc:
                warnings.warn(f"planar renderer: {exc}; using the bullet renderer", stacklevel=2)
                self._planar = None
        # compensate the renderer's sampling offset so content lands where the model says
        shift_u, shift_v = RENDERER_SHIFT_PX[self.renderer]
        projection = opengl_projection(
            k.fx,
            k.fy,
            k.cx - x0 - shift_u,
            k.cy - y0 - shift_v,
            width,
            height,
            self.config.near,
            self.config.far,
        )
        renderer = p.ER_BULLET_HARDWARE_OPENGL if self.renderer == "egl" else p.ER_TINY_RENDERER
        _, _, rgba, _, _ = p.getCameraImage(
            width,
            height,
            viewMatrix=_column_major(opengl_view(t_wc, r_wc)),
            projectionMatrix=_column_major(projection),
            shadow=0,
            lightAmbientCoeff=self.config.light_ambient,
            lightDiffuseCoeff=self.config.light_diffuse,
            lightSpecularCoeff=self.config.light_specular,
            flags=p.ER_NO_SEGMENTATION_MASK,
            renderer=renderer,
            physicsClientId=self.client,
        )
        return np.ascontiguousarray(np.reshape(rgba, (height, width, 4))[..., :3], dtype=np.uint8)

    def render_window(
        self,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        window: tuple[int, int, int, int],
        rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        """Render the image window (x0, y0, x1, y1) (exclusive ends) with lens distortion.

        With a profile other than ``ideal`` the window is exposed (blur, rolling shutter,
        glare) and goes through the sensor model, drawing its noise from ``rng`` (None: a
        stream kept for display images).
        """
        if self.formation is None:
            if self._warp is None:
                return self._render_canvas(t_wc, r_wc, window)
            sx0, sy0, sx1, sy1 = self._warp.source_window(*window)
            source = self._render_canvas(t_wc, r_wc, (sx0, sy0, sx1, sy1))
            return self._warp.warp(source, (sx0, sy0), window)
        source_window = window if self._warp is None else self._warp.source_window(*window)
        exposed = self.formation.expose(
            lambda w: self._render_canvas(t_wc, r_wc, w), t_wc, r_wc, source_window, self.motion
        )
        if self._warp is not None:
            x0, y0, x1, y1 = window
            shape = (y1 - y0, x1 - x0, *exposed.shape[2:])
            out = self.formation.working_image("distorted", shape)
            exposed = self._warp.warp(exposed, source_window[:2], window, out=out)
        noise = self._display_rng if rng is None else rng
        return self.formation.sensor(exposed, window[:2], noise)

    def render_image(
        self, t_wc: np.ndarray, r_wc: np.ndarray, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """Render the scene as this camera sees it: HxWx3 uint8 RGB, lens distortion applied.

        Works in both modes (e.g. for ``render_mode="rgb_array"``).
        """
        k = self.intrinsics
        return self.render_window(t_wc, r_wc, (0, 0, k.width, k.height), rng)

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
        corners_c = t_cd + (r_cd @ tag_corners_in_tag_frame(tag_size).T).T
        # the tag's visible normal is -z_D (z_D points into the deck); angle to the camera ray
        to_camera = -t_cd / max(float(np.linalg.norm(t_cd)), 1e-12)
        cos_angle = float(np.dot(-r_cd[:, 2], to_camera))
        view_angle = float(np.degrees(np.arccos(np.clip(cos_angle, -1.0, 1.0))))
        nan_corners = np.full((4, 2), np.nan)
        if np.any(corners_c[:, 2] <= self.config.near):
            return ProjectedTag(nan_corners, corners_c, view_angle, float("nan"), MISS_BEHIND)
        normalised = corners_c[:, :2] / corners_c[:, 2:3]
        corners_px = self.intrinsics.project(corners_c)
        k, margin = self.intrinsics, self.config.edge_margin_px
        inside = (
            (corners_px[:, 0] >= margin - 0.5)
            & (corners_px[:, 0] <= k.width - 0.5 - margin)
            & (corners_px[:, 1] >= margin - 0.5)
            & (corners_px[:, 1] <= k.height - 0.5 - margin)
            & (np.linalg.norm(normalised, axis=1) < self._max_radius)
        )
        sides = np.linalg.norm(corners_px - np.roll(corners_px, -1, axis=0), axis=1)
        min_side = float(sides.min())
        if not np.all(inside):
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
        only = tags[0]
        t_wd, r_wd, tag_size, tag_id = only.t_wl, only.r_wl, only.size, only.tag_id
        if self.config.mode == "render":
            return self._capture_render(timestamp, t_wc, r_wc, t_wd, r_wd, tag_size, tag_id)
        return self._capture_project(timestamp, t_wc, r_wc, t_wd, r_wd, tag_size, tag_id)

    def _capture_project(
        self,
        timestamp: float,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        t_wd: np.ndarray,
        r_wd: np.ndarray,
        tag_size: float,
        tag_id: int,
    ) -> CameraFrame:
        # draw the random numbers every frame so the stream does not depend on visibility
        dropped = self.rng.random() < self.config.dropout_prob
        unit = self.rng.normal(0.0, 1.0, size=(4, 2))
        view = self.project_tag(t_wc, r_wc, t_wd, r_wd, tag_size)
        if view.miss_reason:
            return CameraFrame(timestamp, (), None, view.miss_reason)
        if dropped:
            return CameraFrame(timestamp, (), None, MISS_DROPOUT)
        noise = unit * self.corner_sigma_px(t_wc, r_wc, view)
        detection = TagDetection(tag_id=tag_id, corners_px=view.corners_px + noise)
        return CameraFrame(timestamp, (detection,), None, "")

    def _capture_render(
        self,
        timestamp: float,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        t_wd: np.ndarray,
        r_wd: np.ndarray,
        tag_size: float,
        tag_id: int,
    ) -> CameraFrame:
        dropped = self.rng.random() < self.config.dropout_prob
        view = self.project_tag(t_wc, r_wc, t_wd, r_wd, tag_size)
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
        found = [d for d in self._detector.detect(patch) if d.tag_id == tag_id]
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
            return CameraFrame(timestamp, (), image, _first_miss(reasons))
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


def draw_detections(image: np.ndarray, frame: CameraFrame) -> np.ndarray:
    """A copy of ``image`` (RGB) with the frame's tag outlines, corner 0 and ids drawn."""
    canvas = np.ascontiguousarray(image[..., :3], dtype=np.uint8).copy()
    shift = 4  # fixed-point bits so the sub-pixel corners are drawn where they are
    scale = 1 << shift
    for detection in frame.detections:
        corners = np.asarray(detection.corners_px, dtype=float)
        if not np.all(np.isfinite(corners)):
            continue
        points = np.rint(corners * scale).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(canvas, [points], True, (0, 255, 0), 2, cv2.LINE_AA, shift)
        colours = ((255, 0, 0), (0, 255, 255), (255, 0, 255), (0, 0, 255))
        for point, colour in zip(points[:, 0], colours, strict=True):
            cv2.circle(
                canvas, tuple(int(c) for c in point), 4 * scale, colour, 2, cv2.LINE_AA, shift
            )
        # label above the tag so it does not hide the corners
        left, top = corners.min(axis=0)
        cv2.putText(
            canvas,
            f"id {detection.tag_id}",
            (int(left), max(int(top) - 8, 12)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5,
            (255, 64, 64),
            1,
            cv2.LINE_AA,
        )
    if frame.miss_reason:
        cv2.putText(
            canvas,
            frame.miss_reason,
            (8, 20),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.6,
            (255, 0, 0),
            2,
            cv2.LINE_AA,
        )
    return canvas
