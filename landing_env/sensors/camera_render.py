"""Rendering what the camera sees: the PyBullet scene (TinyRenderer or EGL) or the planar
scene, drawn with an OpenGL projection built from the intrinsics so that the pinhole model lands
on the rendered pixels, then warped through the lens distortion and, with a camera profile other
than ``ideal``, exposed and passed through the sensor model.

Frames: the camera pose is ``(t_wc, r_wc)`` (columns of ``r_wc`` = OpenCV camera axes in W); see
:mod:`estimation.frames`.  :class:`~landing_env.sensors.camera.CameraSensor` adds the tag
projection and detection on top of :class:`CameraRenderer`.
"""

from __future__ import annotations

import importlib.util
import warnings

import numpy as np
import pybullet as p
from pybullet_utils.bullet_client import BulletClient

from landing_env._quiet import client_id
from landing_env.sensors.camera_config import CameraConfig
from landing_env.sensors.camera_profiles import camera_profile
from landing_env.sensors.camera_realism import Glare, ImageFormation, RelativeMotion
from landing_env.sensors.lens_distortion import DistortionWarp
from landing_env.sensors.planar_renderer import PlanarScene, UnsupportedScene

#: Where each renderer puts the content of a point at OpenCV pixel u (v) relative to u (v),
#: measured with :func:`opengl_projection`: TinyRenderer samples pixel i at screen coordinate
#: i instead of i + 0.5 and flips rows, so it shifts content by (+0.5, -0.5) px; OpenGL
#: (EGL) samples pixel centres and shows no shift (measured with Mesa's llvmpipe: the planar
#: renderer's corners are off OpenGL's by a mean vector under 0.01 px; see
#: ``tests/renderer_agreement.py``).
RENDERER_SHIFT_PX: dict[str, tuple[float, float]] = {"tiny": (0.5, -0.5), "egl": (0.0, 0.0)}

#: Clients of this process with the EGL plugin loaded.  The plugin keeps one scene for the
#: whole process: a second client's renders would show the first one's bodies too (measured:
#: two worlds' decks in one image), so only one client at a time may render with EGL.
_EGL_CLIENTS: set[int] = set()

#: OpenGL camera axes in the OpenCV camera frame: x right, y up, looking along -z.
_CV_FROM_GL = np.diag([1.0, -1.0, -1.0])


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


class CameraRenderer:
    """Renders the images the downward camera of one PyBullet client sees (see the module
    docstring)."""

    #: warnings about the EGL plugin point at the code that builds the camera: this many frames
    #: up from the warning (a subclass whose ``__init__`` calls this one's adds one)
    _BUILDER_STACKLEVEL = 3

    def __init__(self, client: int | BulletClient, config: CameraConfig) -> None:
        self.client = client_id(client)
        self.config = config
        self.intrinsics = config.intrinsics
        self._warp = DistortionWarp(self.intrinsics) if self.intrinsics.has_distortion else None
        self._egl_plugin: int | None = None
        self._planar: PlanarScene | None = None
        self.renderer = "tiny"
        if config.use_egl:
            self._load_egl()
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

    def _load_egl(self) -> None:
        """Load PyBullet's EGL renderer plugin; keep TinyRenderer (and warn) if it fails."""
        live = {c for c in _EGL_CLIENTS if p.isConnected(physicsClientId=c)}
        _EGL_CLIENTS.intersection_update(live)
        if live - {self.client}:
            warnings.warn(
                "EGL renderer already in use by another PyBullet client of this process (its "
                "plugin draws one scene per process); using TinyRenderer",
                stacklevel=self._BUILDER_STACKLEVEL,
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
            warnings.warn(
                f"EGL renderer unavailable ({exc}); using TinyRenderer",
                stacklevel=self._BUILDER_STACKLEVEL,
            )
            return
        if plugin < 0:
            warnings.warn(
                "EGL renderer plugin did not load; using TinyRenderer",
                stacklevel=self._BUILDER_STACKLEVEL,
            )
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
        """Unload the EGL plugin if this camera loaded it."""
        if self._egl_plugin is not None:
            try:
                p.unloadPlugin(self._egl_plugin, physicsClientId=self.client)
            except p.error:
                pass  # the client is already gone, and the plugin with it
            _EGL_CLIENTS.discard(self.client)
            self._egl_plugin = None
            self.renderer = "tiny"

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
