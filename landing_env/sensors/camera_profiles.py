"""Named camera profiles: shutter, exposure and the sensor's noise and response.

Each profile is one real camera class with its parameters and where each comes from.  The
image is 512 x 512 px over the default field of view (fx = 458.5 px, about 58 degrees across),
i.e. a binned or scaled mode of the sensor; per-row timing is scaled to 512 rows accordingly.
Parameters marked *assumed* are typical of the class and not from a datasheet: replace them
with a measurement (EMVA 1288) of the camera flown.  Both real profiles expose a white
surface to 80 % of the full well (the auto-exposure set point, *assumed*), i.e. 8-bit 230
after the 2.2 gamma.

- ``ideal``: the papers' simulator (no blur, noise, vignetting or response curve); the
  rendered image is the camera image.
- ``ov9281``: OmniVision OV9281/OV9282-class global-shutter machine-vision camera (1280 x 800,
  3 um pixels, RAW10; OmniVision product brief; Linux ``ovti,ov9282`` binding), in colour
  as its Bayer twin OV9782 (same array and shutter), since IHRCF's pad calibration needs
  colour: an RGGB mosaic, one colour sample a pixel, demosaiced by the host (the order
  *assumed*; :func:`landing_env.sensors.camera_realism.bayer_mosaic`).  Exposure
  2 ms (a typical fixed machine-vision exposure outdoors; the sensor accepts 10 us to a frame
  time, Luxonis OV9282 docs); full well 8 500 e- and read noise 4 e- *assumed* (typical of
  3 um global-shutter pixels); the sensor has no ISP, so the host encodes its RAW10 with a
  2.2 gamma for 8-bit output (as V4L2/libcamera display pipelines do; *assumed*); corner
  relative illumination 0.80 (*assumed*, an M12 lens of about 60 degrees).
- ``imx219``: Sony IMX219 rolling-shutter camera (Raspberry Pi Camera Module v2): RAW10 with
  a black level of 64 LSB (IMX219PQH5-C datasheet, Sec. 5-6); a line length of 3448 pixel
  clocks at 182.4 MHz, i.e. 18.9 us a line (datasheet Table 21 with the Pi driver's pixel
  rate), 1232 lines in the 2x2-binned full-field mode, so 23.3 ms to read the frame and
  45.5 us per row of a 512-row image; video signal shading 70 % (datasheet Table 46: the
  corner relative illumination); full well 4 500 e- and read noise 2.5 e- *assumed* (typical of
  1.12 um pixels); an RGGB Bayer mosaic (the Linux imx219 driver's native
  MEDIA_BUS_FMT_SRGGB10 without flips) demosaiced by the Pi ISP; the ISP's sRGB-like gamma
  (2.2); exposure 8 ms (a daylight
  auto-exposure setting of the Pi camera stack, *assumed*).
"""

from __future__ import annotations

from dataclasses import dataclass

from landing_env.errors import ConfigError


@dataclass(frozen=True)
class CameraProfile:
    """One camera class (see the module docstring for the sources)."""

    name: str
    #: "global" or "rolling"
    shutter: str = "global"
    #: exposure time, seconds (0 = an instant)
    exposure_s: float = 0.0
    #: time between the starts of two consecutive rows of the 512-row image, seconds
    line_time_s: float = 0.0
    #: electrons at saturation and the read noise (electrons RMS)
    full_well_e: float = 0.0
    read_noise_e: float = 0.0
    #: ADC bits and black level (DN)
    adc_bits: int = 10
    black_level_dn: float = 0.0
    #: electrons a white surface (rendered 255) gives at ``exposure_s``, as a fraction of the
    #: full well: the auto-exposure set point the scene is lit for
    white_fraction_of_full_well: float = 0.8
    #: relative illumination at the image corner (1 = no vignetting; cos^4-like falloff)
    corner_illumination: float = 1.0
    #: output response curve: 8-bit value = 255 * x^(1 / gamma) of the linear signal x
    gamma: float = 1.0
    #: a single-channel sensor (the image is grey in all three channels); else an RGGB Bayer
    #: sensor, one colour sample a pixel
    mono: bool = False

    @property
    def ideal(self) -> bool:
        return self.name == "ideal"


PROFILES: dict[str, CameraProfile] = {
    "ideal": CameraProfile("ideal"),
    "ov9281": CameraProfile(
        "ov9281",
        shutter="global",
        exposure_s=0.002,
        line_time_s=0.0,
        full_well_e=8500.0,
        read_noise_e=4.0,
        adc_bits=10,
        black_level_dn=16.0,
        white_fraction_of_full_well=0.8,
        corner_illumination=0.80,
        gamma=2.2,
        mono=False,
    ),
    "imx219": CameraProfile(
        "imx219",
        shutter="rolling",
        exposure_s=0.008,
        line_time_s=1232 * 18.9e-6 / 512,
        full_well_e=4500.0,
        read_noise_e=2.5,
        adc_bits=10,
        black_level_dn=64.0,
        white_fraction_of_full_well=0.8,
        corner_illumination=0.70,
        gamma=2.2,
        mono=False,
    ),
}


def camera_profile(name: str) -> CameraProfile:
    """The named profile; a clear error naming the allowed ones otherwise."""
    try:
        return PROFILES[name]
    except KeyError:
        allowed = ", ".join(sorted(PROFILES))
        raise ConfigError(
            "profile", f"{name!r} is not a camera profile; choose {allowed}"
        ) from None
