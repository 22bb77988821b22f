"""A real camera's image from the rendered one: exposure, rolling shutter, noise, response.

Two stages, applied by :class:`~landing_env.sensors.camera_render.CameraRenderer` when its
profile is not ``ideal`` (:mod:`landing_env.sensors.camera_profiles`):

The rendered image is taken as display-referred (gamma 2.2): it is linearised first, and
blur, glare and noise act on linear radiance.

1. :meth:`ImageFormation.expose` (on the ideal pinhole image, before lens distortion): the
   exposure integrates the scene over ``exposure_s`` centred on the frame's timestamp, and a
   rolling shutter starts row ``v`` ``(v - (H - 1) / 2) * line_time_s`` later than the middle
   row.  The deck is a plane, so its image at time ``t`` is a homography of its image at the
   timestamp: ``x_0 = G_0 G_t^-1 x_t`` with ``G_t = K [r1 r2 t]`` of the deck in the camera
   at ``t``, both bodies moved by their linear and angular velocities (constant over the
   few milliseconds).  The image is the mean of ``N`` sub-exposure remaps (``N`` from the
   blur length: about two per pixel of motion, at most 32), each row at its own time, the
   mapping linear in time between the earliest and the latest instant (exact to second
   order in the motion).  The sea and the platform below move with the deck in this model;
   they are uniform, so this only matters at the deck's edge.  An optional sun gives the
   deck's specular glare (a Phong lobe on the deck's plane, the sea round it included,
   which may saturate).
2. :meth:`ImageFormation.sensor` (on the distorted image): relative illumination falls off
   as ``(1 + (r/f')^2)^-2`` (cos^4-like, ``f'`` set by the profile's corner value); a white
   surface gives ``white_fraction_of_full_well * full_well_e`` electrons at the profile's
   exposure (proportionally more with a longer one); photon shot noise is Poisson, read noise
   Gaussian (electrons), the analog ``gain`` scales the conversion (DN per electron is
   ``(2^bits - 1 - black) / full_well`` at gain 1, the datasheet's 0 dB), the ADC rounds
   and clips, and the 8-bit output is ``255 * x^(1/gamma)`` of the linear signal above black.

Seeded and deterministic: all draws come from the generator passed in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.frames import matrix_from_rotvec
from landing_env.sensors.camera_profiles import CameraProfile

#: sub-exposures per pixel of blur, and their most
_SAMPLES_PER_PX = 2.0
_MAX_SAMPLES = 32
#: mean electrons above which shot noise is drawn in its Gaussian form (where the read noise
#: does not already make the sum Gaussian, see ImageFormation.raw_dn)
_GAUSSIAN_FROM_E = 25.0
#: the skew of the (shot + read) electrons below which one normal draw stands for the sum:
#: Poisson's own skew at _GAUSSIAN_FROM_E
_MAX_SKEW = 1.0 / math.sqrt(_GAUSSIAN_FROM_E)

#: the renderers' images are display-referred (sRGB-like, gamma 2.2): linear radiance is
#: (value / 255)^2.2, 1.0 = a white surface
RENDER_GAMMA = 2.2
_TO_LINEAR = ((np.arange(256, dtype=np.float64) / 255.0) ** RENDER_GAMMA).astype(np.float32)


def to_linear(image: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Linear radiance (float32, 1.0 = white) of a rendered uint8 image (into ``out``)."""
    image = np.asarray(image)
    if image.size and (image.ndim == 2 or (image.ndim == 3 and 1 <= image.shape[2] <= 4)):
        # OpenCV's table look-up: the same values, five times faster than numpy's gather
        if out is not None and out.shape == image.shape:
            cv2.LUT(np.ascontiguousarray(image), _TO_LINEAR, dst=out)
            return out
        return cv2.LUT(np.ascontiguousarray(image), _TO_LINEAR).reshape(image.shape)
    return _TO_LINEAR[image]


def standard_normal(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Standard normal float32 draws of ``shape``, seeded from ``rng``.

    Drawn by OpenCV's normal generator (``cv2.randn``, four times numpy's
    ``Generator.standard_normal`` on this machine: this runs on every pixel of every frame)
    seeded from one draw of ``rng``, so the result is as deterministic as ``rng``.  OpenCV's
    generator state is per thread.
    """
    out = np.empty((1, max(int(np.prod(shape)), 1)), dtype=np.float32)
    cv2.setRNGSeed(int(rng.integers(1, 2**31 - 1)))
    out = cv2.randn(out, 0.0, 1.0)
    return out.reshape(-1)[: int(np.prod(shape))].reshape(shape)


@dataclass(frozen=True)
class RelativeMotion:
    """What moves during an exposure: the camera and the deck plate (frame P, top at z = 0),
    world velocities of their origins and angular velocities in the world."""

    v_camera_w: np.ndarray
    omega_camera_w: np.ndarray
    t_wp: np.ndarray
    r_wp: np.ndarray
    v_plate_w: np.ndarray
    omega_plate_w: np.ndarray


@dataclass(frozen=True)
class Glare:
    """A sun (direction towards it in the world) and the deck's specular lobe.

    ``strength`` is the lobe's peak in units of a white surface's signal (above 1 it
    saturates); ``shininess`` its Phong exponent (a few hundred: painted steel, *assumed*).
    """

    sun_direction_w: np.ndarray
    strength: float = 4.0
    shininess: float = 300.0


def _rotate(omega: np.ndarray, t: float, rotation: np.ndarray) -> np.ndarray:
    return matrix_from_rotvec(np.asarray(omega, dtype=float) * t) @ rotation


class ImageFormation:
    """Exposure and sensor model of one camera (see the module docstring)."""

    def __init__(
        self,
        profile: CameraProfile,
        intrinsics: CameraIntrinsics,
        exposure_s: float | None = None,
        gain: float = 1.0,
        glare: Glare | None = None,
    ) -> None:
        self.profile = profile
        self.k = intrinsics
        self.exposure_s = profile.exposure_s if exposure_s is None else float(exposure_s)
        self.gain = float(gain)
        self.glare = glare
        self.line_time_s = profile.line_time_s if profile.shutter == "rolling" else 0.0
        # vignetting: (1 + (r/f')^2)^-2 equals corner_illumination at the farthest corner
        corners = np.array([[0, 0], [intrinsics.width - 1, 0], [0, intrinsics.height - 1]])
        corners = np.vstack([corners, [intrinsics.width - 1, intrinsics.height - 1]])
        r_corner = float(np.max(np.linalg.norm(corners - [intrinsics.cx, intrinsics.cy], axis=1)))
        c = float(profile.corner_illumination)
        self._vignette_scale = 0.0 if c >= 1.0 else (c**-0.5 - 1.0) / max(r_corner, 1e-9) ** 2
        # the skew of Poisson(m) + N(0, r^2) is m / (m + r^2)^1.5, at most 2 / (3^1.5 r) (at
        # m = 2 r^2): with r >= 1.93 e- it stays below _MAX_SKEW at every signal, and one
        # normal draw gives the sum everywhere (see raw_dn)
        read = profile.read_noise_e
        self._exact_shot = read <= 0.0 or 2.0 / (3.0**1.5 * read) > _MAX_SKEW
        self._max_dn = float(2**profile.adc_bits - 1)
        #: the exposure's working images, kept from frame to frame: allocating megabytes
        #: afresh each frame costs as much again in page faults as the arithmetic
        self._buffers: dict[str, np.ndarray] = {}
        self._dn_per_e = (
            (self._max_dn - profile.black_level_dn) / profile.full_well_e
            if profile.full_well_e > 0
            else 0.0
        )
        # the full frame's relative illumination, sliced for windows inside the image
        self._vignette_full = self._vignetting_of((0, 0, intrinsics.width, intrinsics.height))
        # the ADC's output is an integer 0 .. 2^bits - 1: its 8-bit value is a table look-up
        self._to_8bit = self._response(np.arange(2**profile.adc_bits, dtype=np.float32))

    def working_image(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """A float32 working image of ``shape``, reused by the next call for ``name``.

        Allocating megabytes afresh each frame costs as much again in page faults as the
        arithmetic on them; the frame's intermediate images live here instead.
        """
        size = int(np.prod(shape))
        flat = self._buffers.get(name)
        if flat is None or flat.size < size:
            flat = np.empty(size, dtype=np.float32)
            self._buffers[name] = flat
        return flat[:size].reshape(shape)

    # ------------------------------------------------------------------ exposure
    @property
    def has_exposure_effects(self) -> bool:
        return self.exposure_s > 0.0 or self.line_time_s > 0.0

    def row_time_s(self, v: np.ndarray | float) -> np.ndarray | float:
        """When row ``v`` (full image) is exposed, relative to the frame's timestamp."""
        return (np.asarray(v, dtype=float) - 0.5 * (self.k.height - 1)) * self.line_time_s

    def plate_homography(
        self, t_wc: np.ndarray, r_wc: np.ndarray, motion: RelativeMotion, t: float
    ) -> np.ndarray:
        """``G_t``: plate (x, y, 1) to ideal full-image pixels at time ``t``."""
        r_wc_t = _rotate(motion.omega_camera_w, t, r_wc)
        t_wc_t = np.asarray(t_wc, dtype=float) + motion.v_camera_w * t
        r_wp_t = _rotate(motion.omega_plate_w, t, motion.r_wp)
        t_wp_t = motion.t_wp + motion.v_plate_w * t
        r_cp = r_wc_t.T @ r_wp_t
        t_cp = r_wc_t.T @ (t_wp_t - t_wc_t)
        return self.k.matrix @ np.column_stack([r_cp[:, 0], r_cp[:, 1], t_cp])

    def blur_length_px(
        self,
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        motion: RelativeMotion,
        point_px: tuple[float, float],
    ) -> float:
        """How far the deck point seen at ``point_px`` moves during a global exposure."""
        g0 = self.plate_homography(t_wc, r_wc, motion, 0.0)
        half = 0.5 * self.exposure_s
        ends = []
        for t in (-half, half):
            m = g0 @ np.linalg.inv(self.plate_homography(t_wc, r_wc, motion, t))
            q = m @ np.array([*point_px, 1.0])
            ends.append(q[:2] / q[2])
        return float(np.linalg.norm(ends[1] - ends[0]))

    def expose(
        self,
        render_canvas: Callable[[tuple[int, int, int, int]], np.ndarray],
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        window: tuple[int, int, int, int],
        motion: RelativeMotion | None,
    ) -> np.ndarray:
        """The exposed ideal window (float32 linear radiance, 1.0 = a white surface).

        With motion the result is a working image of this object, valid until its next
        ``expose``: copy it to keep it.
        """
        x0, y0, x1, y1 = window
        if motion is None or not self.has_exposure_effects:
            canvas = to_linear(render_canvas(window))
            return self._add_glare(canvas, window, t_wc, r_wc, motion)
        half = 0.5 * self.exposure_s
        t_first = float(self.row_time_s(y0)) - half
        t_last = float(self.row_time_s(y1 - 1)) + half
        g0 = self.plate_homography(t_wc, r_wc, motion, 0.0)

        def source_of(t: float) -> np.ndarray:
            """x_0 = G_0 G_t^-1 x_t: where the image at ``t`` takes each pixel from."""
            return g0 @ np.linalg.inv(self.plate_homography(t_wc, r_wc, motion, t))

        m_first, m_last = source_of(t_first), source_of(t_last)
        corners = np.array([[x0, y0], [x1 - 1, y0], [x0, y1 - 1], [x1 - 1, y1 - 1]], float)
        ends = [_apply(m, np.column_stack([corners, np.ones(4)])) for m in (m_first, m_last)]
        reach = max(float(np.abs(e - corners).max()) for e in ends)
        blur = float(np.max(np.linalg.norm(ends[1] - ends[0], axis=1)))
        if not np.isfinite(reach) or reach > 0.5 * max(self.k.width, self.k.height):
            # a degenerate view (the deck plane through the camera): no blur
            canvas = to_linear(render_canvas(window))
            return self._add_glare(canvas, window, t_wc, r_wc, motion)
        margin = math.ceil(reach) + 2
        grown = (x0 - margin, y0 - margin, x1 + margin, y1 + margin)
        rendered = render_canvas(grown)
        canvas = to_linear(rendered, out=self.working_image("canvas", rendered.shape))
        canvas = self._add_glare(canvas, grown, t_wc, r_wc, motion)
        samples = 1
        if self.exposure_s > 0.0:
            samples = int(np.clip(math.ceil(blur * _SAMPLES_PER_PX) + 1, 1, _MAX_SAMPLES))
        size = (x1 - x0, y1 - y0)
        to_full = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])
        to_canvas = np.array([[1.0, 0.0, -grown[0]], [0.0, 1.0, -grown[1]], [0.0, 0.0, 1.0]])
        offsets = [(j + 0.5) / samples * self.exposure_s - half for j in range(samples)]
        total = self.working_image("total", (size[1], size[0], canvas.shape[2]))
        total[...] = 0.0
        scratch = self.working_image("sample", total.shape)
        if self.line_time_s == 0.0:
            # global shutter: each sub-exposure is one homography
            for offset in offsets:
                m = to_canvas @ source_of(offset) @ to_full
                warped = cv2.warpPerspective(
                    canvas,
                    m,
                    size,
                    dst=scratch,
                    flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                    borderMode=cv2.BORDER_REPLICATE,
                )
                total += warped.reshape(total.shape)
            total *= np.float32(1.0 / samples)
            return total
        # rolling shutter: each row at its own time, linear in time between the extremes
        points = np.stack(
            np.meshgrid(np.arange(x0, x1, dtype=np.float32), np.arange(y0, y1, dtype=np.float32)),
            axis=-1,
        ).reshape(-1, 1, 2)
        src_first = cv2.perspectiveTransform(points, to_canvas @ m_first).reshape(
            size[1], size[0], 2
        )
        src_last = cv2.perspectiveTransform(points, to_canvas @ m_last).reshape(size[1], size[0], 2)
        delta = src_last - src_first
        span = max(t_last - t_first, 1e-12)
        row_t = np.asarray(self.row_time_s(np.arange(y0, y1)), dtype=np.float64)
        for offset in offsets:
            alpha = ((row_t + offset - t_first) / span).astype(np.float32)[:, None, None]
            coords = src_first + alpha * delta
            warped = cv2.remap(
                canvas,
                np.ascontiguousarray(coords[..., 0]),
                np.ascontiguousarray(coords[..., 1]),
                dst=scratch,
                interpolation=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )
            total += warped.reshape(total.shape)
        total *= np.float32(1.0 / samples)
        return total

    def _add_glare(
        self,
        canvas: np.ndarray,
        window: tuple[int, int, int, int],
        t_wc: np.ndarray,
        r_wc: np.ndarray,
        motion: RelativeMotion | None,
    ) -> np.ndarray:
        """Add the sun's specular lobe on the deck (needs the deck pose from ``motion``)."""
        if self.glare is None or motion is None:
            return canvas
        x0, y0, x1, y1 = window
        us, vs = np.meshgrid(np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float))
        rays_c = np.stack([us, vs, np.ones_like(us)], axis=-1) @ np.linalg.inv(self.k.matrix).T
        rays_w = rays_c @ np.asarray(r_wc, dtype=float).T
        normal = motion.r_wp[:, 2]
        denominator = rays_w @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = ((motion.t_wp - t_wc) @ normal) / denominator
        # the lobe is drawn on the deck's plane wherever it is in front of the camera: on
        # the deck and on the sea round it (which glints as well)
        on_plane = np.isfinite(depth) & (depth > 0.0)
        sun = np.asarray(self.glare.sun_direction_w, dtype=float)
        sun = sun / np.linalg.norm(sun)
        reflected = 2.0 * (normal @ sun) * normal - sun
        view = -rays_w / np.linalg.norm(rays_w, axis=-1, keepdims=True)
        lobe = np.clip(view @ reflected, 0.0, 1.0) ** self.glare.shininess
        lobe = np.where(on_plane, lobe, 0.0)
        return canvas + (self.glare.strength * lobe).astype(np.float32)[..., None]

    # -------------------------------------------------------------------- sensor
    def vignetting(self, window: tuple[int, int, int, int]) -> np.ndarray:
        """Relative illumination of each pixel of a window (HxW float32)."""
        x0, y0, x1, y1 = window
        full_h, full_w = self._vignette_full.shape
        if 0 <= x0 <= x1 <= full_w and 0 <= y0 <= y1 <= full_h:
            return self._vignette_full[y0:y1, x0:x1]
        return self._vignetting_of(window)

    def _vignetting_of(self, window: tuple[int, int, int, int]) -> np.ndarray:
        x0, y0, x1, y1 = window
        us, vs = np.meshgrid(
            np.arange(x0, x1, dtype=np.float32), np.arange(y0, y1, dtype=np.float32)
        )
        r2 = (us - np.float32(self.k.cx)) ** 2 + (vs - np.float32(self.k.cy)) ** 2
        return (1.0 + np.float32(self._vignette_scale) * r2) ** -2

    def electrons_at_white(self) -> float:
        """Mean electrons a white surface gives at this exposure (before vignetting)."""
        p = self.profile
        nominal = p.exposure_s if p.exposure_s > 0.0 else 1.0
        scale = self.exposure_s / nominal if p.exposure_s > 0.0 else 1.0
        return p.white_fraction_of_full_well * p.full_well_e * scale

    def raw_dn(self, signal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """ADC output (DN, float32) of a linear signal (1.0 = white, vignetting applied).

        Shot noise is Poisson, read noise Gaussian.  Their sum is drawn as one normal draw
        of the same mean and variance wherever its skew is below ``_MAX_SKEW`` (0.2, the
        Poisson law's own skew at ``_GAUSSIAN_FROM_E`` = 25 e-), which is ten times faster.
        With the read noise of the OV9281 (4 e-) and IMX219 (2.5 e-) profiles that holds at
        every signal (largest skew 0.10 and 0.15): after the ADC (8.4 and 4.7 e- per DN) the
        CDFs of the exact and the normal law differ by at most 0.006 and 0.010 over all
        means (tests/landing_env/sensors/test_camera_realism.py).  With less read noise, shot
        noise below 25 e- is drawn from the Poisson law.
        """
        p = self.profile
        # in place, float32: this runs on every pixel of every frame
        signal = np.asarray(signal, dtype=np.float32)
        mean_e = self.working_image("mean_e", signal.shape)
        np.maximum(signal, np.float32(0.0), out=mean_e)
        mean_e *= np.float32(self.electrons_at_white())
        electrons = standard_normal(rng, mean_e.shape)
        low = None
        if self._exact_shot:
            low = (mean_e < _GAUSSIAN_FROM_E) & (mean_e > 0.0)
            z_low = electrons[low]
        sigma = self.working_image("sigma_e", signal.shape)
        np.add(mean_e, np.float32(p.read_noise_e**2), out=sigma)
        electrons *= np.sqrt(sigma, out=sigma)
        electrons += mean_e
        if low is not None and z_low.size:
            shot = rng.poisson(mean_e[low]).astype(np.float32)
            electrons[low] = shot + np.float32(p.read_noise_e) * z_low
        # the well clips the collected charge (read noise comes after it)
        np.minimum(electrons, np.float32(p.full_well_e + 4.0 * p.read_noise_e), out=electrons)
        electrons *= np.float32(self._dn_per_e * self.gain)
        electrons += np.float32(p.black_level_dn)
        np.rint(electrons, out=electrons)
        return np.clip(electrons, 0.0, self._max_dn, out=electrons)

    def dn_variance(self, mean_electrons: float) -> float:
        """The model's DN variance at a mean signal (shot + read + quantisation)."""
        g = self._dn_per_e * self.gain
        return g * g * (mean_electrons + self.profile.read_noise_e**2) + 1.0 / 12.0

    def sensor(
        self, image: np.ndarray, origin: tuple[int, int], rng: np.random.Generator
    ) -> np.ndarray:
        """The 8-bit camera image (HxWx3 uint8) of an exposed window at ``origin``.

        ``image`` is rendered (uint8) or exposed (float32 linear), RGB in its first three
        channels (any further channel is ignored).

        A colour sensor has one photosite per pixel behind a Bayer filter (RGGB from the
        image's top-left pixel): each pixel collects, and is noised in, the one channel its
        filter passes, and the colour image is demosaiced from that mosaic on the linear ADC
        values (edge-aware, as a camera's ISP does, not bilinear) before the response curve.
        A ``mono`` sensor collects the luma.  Either way one value per pixel is noised.
        """
        p = self.profile
        signal = to_linear(image) if image.dtype == np.uint8 else np.asarray(image, np.float32)
        signal = signal[..., :3]
        h, w = signal.shape[:2]
        x0, y0 = origin
        if p.mono:
            raw = signal @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
        else:
            raw = bayer_mosaic(signal, origin, out=self.working_image("mosaic", (h, w)))
        raw *= self.vignetting((x0, y0, x0 + w, y0 + h))
        dn = self.raw_dn(raw, rng).astype(np.uint16)
        if p.mono or min(h, w) < 2:
            return np.ascontiguousarray(np.repeat(np.take(self._to_8bit, dn)[..., None], 3, 2))
        rgb = cv2.cvtColor(dn, _DEMOSAIC[(y0 % 2, x0 % 2)])
        return np.take(self._to_8bit, rgb)

    def _response(self, dn: np.ndarray) -> np.ndarray:
        """8-bit output of ADC values: ``255 * x^(1/gamma)`` of the linear signal above black."""
        p = self.profile
        linear = np.clip((dn - p.black_level_dn) / (self._max_dn - p.black_level_dn), 0.0, 1.0)
        if p.gamma != 1.0:
            linear = linear ** (1.0 / p.gamma)
        return np.rint(255.0 * linear).astype(np.uint8)


#: OpenCV's edge-aware demosaicing of a window whose top-left pixel has the phase (row,
#: column) of the image's RGGB pattern (OpenCV names a pattern by its second row's 2nd and
#: 3rd pixels)
_DEMOSAIC = {
    (0, 0): cv2.COLOR_BayerBG2RGB_EA,
    (0, 1): cv2.COLOR_BayerGB2RGB_EA,
    (1, 0): cv2.COLOR_BayerGR2RGB_EA,
    (1, 1): cv2.COLOR_BayerRG2RGB_EA,
}


def bayer_mosaic(
    signal: np.ndarray, origin: tuple[int, int], out: np.ndarray | None = None
) -> np.ndarray:
    """What an RGGB Bayer sensor collects of an HxWx3 window at ``origin`` (HxW float32).

    The pattern is anchored at the full image's pixel (0, 0), so a window's mosaic is the
    full image's (red where row and column are even, blue where both are odd).
    """
    x0, y0 = origin
    even_r, odd_r = slice(y0 % 2, None, 2), slice(1 - y0 % 2, None, 2)
    even_c, odd_c = slice(x0 % 2, None, 2), slice(1 - x0 % 2, None, 2)
    mosaic = np.empty(signal.shape[:2], dtype=np.float32) if out is None else out
    mosaic[even_r, even_c] = signal[even_r, even_c, 0]
    mosaic[even_r, odd_c] = signal[even_r, odd_c, 1]
    mosaic[odd_r, even_c] = signal[odd_r, even_c, 1]
    mosaic[odd_r, odd_c] = signal[odd_r, odd_c, 2]
    return mosaic


def _apply(matrix: np.ndarray, grid: np.ndarray) -> np.ndarray:
    q = grid @ matrix.T
    return q[..., :2] / q[..., 2:3]
