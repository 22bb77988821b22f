"""The camera's configuration: intrinsics, simulation mode, visibility rules, detector,
renderer and image-formation settings (:class:`CameraConfig`, the ``camera`` config section).

:class:`~landing_env.sensors.camera.CameraSensor` is built from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.sensors.camera_profiles import PROFILES

#: the camera's modes: render the scene and detect the tag, or project the tag's corners
CAMERA_MODES = ("render", "project")


@dataclass
class CameraConfig:
    """Camera model, simulation mode, visibility rules and detector settings."""

    mode: Literal["render", "project"] = "project"
    width: int = limited(512, Limit(16, 8192))
    height: int = limited(512, Limit(16, 8192))
    fx: float = limited(458.5, POSITIVE, physical=Limit.positive(1e5, "pixels"))
    fy: float = limited(457.855, POSITIVE, physical=Limit.positive(1e5, "pixels"))
    #: principal point, pixels (OpenCV convention); None = image centre, (width - 1) / 2
    cx: float | None = limited(None, physical=Limit.symmetric(1e5))
    cy: float | None = limited(None, physical=Limit.symmetric(1e5))
    #: OpenCV radial-tangential distortion (real lenses have coefficients below 10 in magnitude)
    k1: float = limited(0.0, physical=Limit.symmetric(100.0))
    k2: float = limited(0.0, physical=Limit.symmetric(100.0))
    p1: float = limited(0.0, physical=Limit.symmetric(100.0))
    p2: float = limited(0.0, physical=Limit.symmetric(100.0))
    k3: float = limited(0.0, physical=Limit.symmetric(100.0))
    #: clipping planes of the renderer, metres; nearer tag corners count as behind the camera
    near: float = limited(0.05, POSITIVE, physical=Limit.positive(1e3))
    far: float = limited(30.0, physical=Limit.positive(1e4))
    #: Gaussian corner noise, pixels (project mode)
    pixel_noise_px: float = limited(0.0, NON_NEGATIVE, physical=Limit.non_negative(100.0))
    #: project mode's corner noise: "constant" (``pixel_noise_px``) or "fitted": sigma from
    #: the tag's side and blur in pixels with ``pixel_noise_fit`` = (base px, size px^3,
    #: blur fraction, side^2 coefficient), fitted to render-and-detect under a camera profile
    #: (:mod:`landing_env.sensors.corner_noise`; ``sensors: realistic`` sets both)
    pixel_noise_model: Literal["constant", "fitted"] = "constant"
    pixel_noise_fit: tuple[float, float, float, float] = limited(
        (0.0, 0.0, 0.0, 0.0),
        physical=Limit.non_negative(1e6, "fitted (base px, size px^3, blur, floor)"),
    )
    #: probability that a visible tag is dropped from a frame (both modes)
    dropout_prob: float = limited(0.0, Limit(0.0, 1.0))
    #: angle between the tag normal and the ray from the tag centre to the camera, degrees
    max_view_angle_deg: float = limited(75.0, Limit(0.0, 90.0))
    #: shortest tag side in pixels below which the tag is not detected (project mode)
    min_tag_side_px: float = limited(12.0, NON_NEGATIVE, physical=Limit.non_negative(1e4))
    #: corners must lie this far inside the image, pixels
    edge_margin_px: float = limited(2.0, physical=Limit.non_negative(1e4))
    #: pupil-apriltags settings (render mode)
    quad_decimate: float = limited(1.0, Limit(1.0), physical=Limit(1.0, 16.0))
    quad_sigma: float = limited(0.0, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    refine_edges: bool = True
    decode_sharpening: float = limited(0.25, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    detector_threads: int = limited(1, Limit(1, 64), physical=Limit(1, 256))
    #: render mode: "tag" renders and searches only a window round where the tag projects
    #: (the pixels there are the same as in a full render; the frame's image is grey outside
    #: it); "full" renders the whole image.  Both detect from pixels only.
    render_region: Literal["tag", "full"] = "tag"
    #: the "tag" window extends the tag's pixel bounding box by this fraction of its size
    #: and ``render_margin_px`` on each side (the quiet zone is 1/8 of the tag)
    render_margin_frac: float = limited(0.25, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    render_margin_px: int = limited(8, Limit(0), physical=Limit(0, 10_000))
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
    exposure_s: float | None = limited(None, Limit(0.0, 0.1))
    #: analog gain (1 = the sensor's 0 dB, where full well meets the ADC's top)
    gain: float = limited(1.0, Limit(0.0, 64.0, low_inclusive=False))
    #: direction towards the sun in the world (x, y, z) for specular glare on the deck;
    #: None = no glare.  ``glare_strength``: the lobe's peak in white-surface units
    sun_direction_w: tuple[float, float, float] | None = None
    glare_strength: float = limited(
        4.0,
        NON_NEGATIVE,
        physical=Limit.non_negative(1e3, "the lobe's peak in white-surface units"),
    )
    glare_shininess: float = limited(
        300.0, Limit(1.0), physical=Limit(1.0, 1e5, note="Phong exponent")
    )
    #: renderer lighting; specular off so the white quiet zone does not saturate in patches
    light_ambient: float = limited(0.6, Limit(0.0, 1.0))
    light_diffuse: float = limited(0.4, Limit(0.0, 1.0))
    light_specular: float = limited(0.0, Limit(0.0, 1.0))

    def __post_init__(self) -> None:
        require_choice("mode", self.mode, CAMERA_MODES)
        require_limits(self)
        if self.cx is not None:
            require_range(
                "cx", self.cx, -0.5, self.width - 0.5, bounds_from=f"width = {self.width}"
            )
        if self.cy is not None:
            require_range(
                "cy", self.cy, -0.5, self.height - 0.5, bounds_from=f"height = {self.height}"
            )
        if self.far <= self.near:
            raise ConfigError("far", f"{self.far} must be greater than near = {self.near}")
        require_choice("pixel_noise_model", self.pixel_noise_model, ("constant", "fitted"))
        if len(self.pixel_noise_fit) != 4 or any(
            not np.isfinite(v) or v < 0.0 for v in self.pixel_noise_fit
        ):
            raise ConfigError(
                "pixel_noise_fit", f"{self.pixel_noise_fit!r}: need four finite values >= 0"
            )
        require_range(
            "edge_margin_px", self.edge_margin_px, 0.0, 0.25 * min(self.width, self.height)
        )
        require_choice("render_region", self.render_region, ("tag", "full"))
        require_choice("renderer", self.renderer, ("planar", "bullet"))
        require_choice("profile", self.profile, tuple(PROFILES))
        if self.sun_direction_w is not None:
            sun = np.asarray(self.sun_direction_w, dtype=float)
            if sun.shape != (3,) or not np.all(np.isfinite(sun)) or np.linalg.norm(sun) == 0:
                raise ConfigError(
                    "sun_direction_w", f"{self.sun_direction_w!r}: need a nonzero (x, y, z)"
                )

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
