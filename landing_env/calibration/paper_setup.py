"""The papers' own setup, as their published data imply it (CRHF Sec. 2.2-2.3, Tables 2-4).

The papers state a 512 x 512 camera and four ToF sensors "0.1 m from the camera at 45°"
(IHRCF Eq. 12, CRHF Eq. 21-24), and give a chessboard calibration (CRHF Eq. 10).  Their
calibration tables pin the simulated camera and the sensor layout down more tightly:

* **Camera**: CoppeliaSim's vision sensor takes its perspective angle across the image;
  a 60° angle on 512 px gives ``f = 256 / tan(30°) = 443.405 px``.  CRHF Table 4's hyperbola
  ``pixel = a / range + c`` has ``c = 256.6`` on both axes: the image centre, 256.5 in
  MATLAB's one-based pixels (255.5 in OpenCV's), so the principal point is centred.
* **Layout**: ``a = f · s`` with ``s`` the sensor's offset from the optical axis.  Table 4's
  ``|a| = 44.43 px·m`` and frames 2-3 of Tables 2-3 (``|u - c| · r`` = 44.24-44.59, mean
  44.43) give ``s = 44.43 / 443.405 = 0.1002 m`` on each axis: the sensors sit at ±0.1 m per
  axis (0.141 m from the camera), not at the ±0.0707 m that "0.1 m at 45°" reads as.  The
  pads' pixel quadrants in Table 2 fix the order: blue (+x, -y), green (+x, +y), yellow
  (-x, +y), red (-x, -y) in the camera frame; Table 4's signs (a < 0 in x, > 0 in y) are the
  yellow sensor's.
* **Chessboard calibration**: Eq. 10 (MATLAB's transposed intrinsic matrix, one-based
  pixels) is fx 458.5, fy 457.855, cx 258.7735, cy 252.308: fx 3.4 % above the camera its
  tables imply, the principal point (2.3, -4.2) px off.  CRHF Sec. 2.2 photographed the board
  at the ToF sensors' maximum range, where focal length and distance trade off.  The
  paper-setup scenarios give the estimators this result as their calibration while the
  simulated camera is the implied one.
* **Frame 1 of Tables 2-3** is about 1.4 % low in ``|u - c| · r`` on all four sensors
  (43.6-43.9 against 44.2-44.6): its image was taken about 4 mm of climb away from its
  ranges, a sign that the papers' images and ranges were not sampled at the same instant.

:func:`reproduce_calibration_tables` runs the project's pad rig in this setup and returns
Tables 2-4's quantities for comparison (``tests/landing_env/calibration/test_paper_setup.py``
holds them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimation.camera_model import CameraIntrinsics
from estimation.intrinsics_calibration import IntrinsicsCalibrationResult
from estimation.tof_calibration import PAD_COLOURS, fit_hyperbola
from landing_env.calibration.intrinsics_sim import camera_metadata
from landing_env.calibration.tof_camera_sim import TofRigConfig, calibrate_tof_camera_in_sim
from landing_env.config import DeckLandingConfig, load_config

#: MATLAB's pixel centres are one-based, OpenCV's (the project's) zero-based.
MATLAB_PIXEL_OFFSET = 1.0

#: CoppeliaSim's perspective angle that the papers' data imply, degrees
PAPER_FOV_DEG = 60.0
#: the implied focal length on the 512-px image, pixels
PAPER_FOCAL_PX = 256.0 / math.tan(math.radians(PAPER_FOV_DEG / 2.0))

#: CRHF Eq. 10 as published (MATLAB, one-based): fx, fy, cx, cy
EQ10_MATLAB = (458.5, 457.855, 258.7735, 252.308)

#: CRHF Table 2: per pad colour, frames 1-3, (u, v) in MATLAB pixels
TABLE2_CENTROIDS_PX = np.array(
    [
        [[400.0070961, 112.909046], [392.6057903, 120.4082739], [383.8957617, 129.1591336]],
        [[399.5563178, 399.9410627], [392.0877826, 392.3846207], [383.3468678, 383.720831]],
        [[112.5299193, 400.1530166], [119.9678525, 392.630475], [128.6982725, 384.0305636]],
        [[112.8321163, 112.9362624], [120.3259779, 120.4101189], [129.0014117, 129.1613991]],
    ]
)
#: CRHF Table 3: per pad colour, the ranges of frames 1-3, metres
TABLE3_RANGES_M = np.array(
    [
        [0.305179805, 0.32637015, 0.348936737],
        [0.304939508, 0.32626918, 0.34884578],
        [0.304848552, 0.32633689, 0.348892212],
        [0.304876596, 0.326466531, 0.349034697],
    ]
)


@dataclass(frozen=True)
class HyperbolaRow:
    """One column of CRHF Table 4: ``pixel = a / range + c`` with its goodness of fit
    (SSE in px², RMSE = sqrt(SSE / (n - 2)) as MATLAB's fit reports it, n points)."""

    a: float
    c: float
    sse: float
    rmse: float
    n: int


#: CRHF Table 4 (the yellow sensor, MATLAB pixels): x and y.  SSE / RMSE² = 118 on both
#: axes, so n = 120: the 120 stages of Sec. 2.3
TABLE4 = (
    HyperbolaRow(a=-44.43, c=256.6, sse=0.1409, rmse=0.03456, n=120),
    HyperbolaRow(a=44.43, c=256.6, sse=0.1323, rmse=0.03348, n=120),
)
#: the sensor Table 4 describes (index into PAD_COLOURS)
TABLE4_SENSOR = PAD_COLOURS.index("yellow")


def implied_sensor_offset_m(focal_px: float = PAPER_FOCAL_PX) -> float:
    """The sensors' per-axis offset from the optical axis implied by Tables 2-3 (frames 2
    and 3; frame 1 is out of step, see the module docstring), metres."""
    centre = 255.5 + MATLAB_PIXEL_OFFSET
    products = np.abs(TABLE2_CENTROIDS_PX[:, 1:] - centre) * TABLE3_RANGES_M[:, 1:, None]
    return float(products.mean() / focal_px)


#: the layout in the papers' order (blue, green, yellow, red), camera frame C, metres
PAPER_TOF_MOUNTS_C = (
    (0.1, -0.1, 0.0),
    (0.1, 0.1, 0.0),
    (-0.1, 0.1, 0.0),
    (-0.1, -0.1, 0.0),
)
#: the papers' stated layout (Eq. 12: 0.1 m from the camera at 45°), same order
STATED_TOF_MOUNTS_C = tuple(
    (x * math.cos(math.pi / 4), y * math.cos(math.pi / 4), 0.0) for x, y, _ in PAPER_TOF_MOUNTS_C
)


def paper_camera() -> CameraIntrinsics:
    """The simulated camera the papers' data imply: 512 px, f 443.405 px, centred."""
    return CameraIntrinsics(
        width=512, height=512, fx=PAPER_FOCAL_PX, fy=PAPER_FOCAL_PX, cx=255.5, cy=255.5
    )


def eq10_intrinsics() -> CameraIntrinsics:
    """CRHF Eq. 10 in the project's (OpenCV, zero-based) pixels, no distortion."""
    fx, fy, cx, cy = EQ10_MATLAB
    return CameraIntrinsics(
        width=512,
        height=512,
        fx=fx,
        fy=fy,
        cx=cx - MATLAB_PIXEL_OFFSET,
        cy=cy - MATLAB_PIXEL_OFFSET,
    )


def write_eq10_calibration(path: str | Path) -> Path:
    """Write CRHF Eq. 10 as the intrinsics file of the papers' camera (its metadata names
    the implied camera it stands for; the paper gives no reprojection error: NaN)."""
    k = eq10_intrinsics()
    result = IntrinsicsCalibrationResult(
        K=k.matrix,
        dist=np.zeros(5),
        rms_reprojection_error=math.nan,
        per_view_errors=np.zeros(0),
        image_size=(512, 512),
        metadata={
            "source": "CRHF paper (Drones 2022, 6, 60), Eq. 10, MATLAB one-based pixels "
            "converted to zero-based (cx, cy - 1); a chessboard calibration at the ToF maximum "
            "range (Sec. 2.2), not made by this project",
            "camera": camera_metadata(paper_camera()),
        },
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    result.save(path)
    return path


@dataclass(frozen=True)
class CalibrationTables:
    """Tables 2-4 as the rig measures them in the papers' setup.

    ``centroids_px`` (4 sensors, 3 frames, 2) in MATLAB pixels at Table 3's ranges;
    ``fits`` per sensor the (x, y) :class:`HyperbolaRow` of the 120-stage climb (c in MATLAB
    pixels); ``stage_ranges_m`` the climb's ranges.
    """

    centroids_px: np.ndarray
    fits: tuple[tuple[HyperbolaRow, HyperbolaRow], ...]
    stage_ranges_m: np.ndarray


def climb_rig() -> TofRigConfig:
    """The papers' 120-stage climb: Table 3's first ranges step 0.0212 and 0.0226 m, so a
    linear climb from 0.305 m in 0.0219 m steps (to 2.91 m; neither paper gives the top)."""
    start, step, stages = 0.305, 0.0219, 120
    return TofRigConfig(
        stages=stages,
        ranges_m=tuple(float(start + step * i) for i in range(stages)),
        spacing="linear",
    )


def rig_source_config(scenario: str = "paper-setup-crhf") -> DeckLandingConfig:
    """The scenario with the exact models, for making its calibration files (the files to
    be made cannot be read yet)."""
    return load_config(
        scenario,
        overrides={"estimation.intrinsics": "exact", "estimation.tof_calibration": "exact"},
    )


def make_paper_setup_calibrations(out_dir: str | Path) -> list[Path]:
    """Write the paper-setup scenarios' calibration files into ``out_dir``: CRHF Eq. 10 as
    the intrinsics, and the pad rig's PCHIP look-up over the papers' 120-stage climb."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    intrinsics = write_eq10_calibration(out / "intrinsics-eq10.json")
    report = calibrate_tof_camera_in_sim(rig_source_config(), climb_rig())
    tof = out / "tof_camera.json"
    report.calibration.save(tof)
    return [intrinsics, tof]


def _hyperbola_row(ranges: np.ndarray, values: np.ndarray) -> HyperbolaRow:
    fit = fit_hyperbola(ranges, values)
    residual = fit(ranges) - values
    sse = float(np.sum(residual**2))
    n = len(ranges)
    return HyperbolaRow(
        a=fit.a, c=fit.c + MATLAB_PIXEL_OFFSET, sse=sse, rmse=math.sqrt(sse / (n - 2)), n=n
    )


def reproduce_calibration_tables(config: DeckLandingConfig | None = None) -> CalibrationTables:
    """Run the pad rig of ``config`` (default: ``paper-setup-crhf``) at Table 3's ranges and
    over the 120-stage climb, and return Tables 2-4's quantities."""
    config = config if config is not None else rig_source_config()
    frames = calibrate_tof_camera_in_sim(
        config, TofRigConfig(stages=3, ranges_m=tuple(TABLE3_RANGES_M.mean(axis=0)))
    )
    centroids = np.transpose(frames.pixels, (1, 0, 2)) + MATLAB_PIXEL_OFFSET
    climb = calibrate_tof_camera_in_sim(config, climb_rig())
    fits = []
    for sensor in range(climb.ranges.shape[1]):
        ok = np.isfinite(climb.ranges[:, sensor])
        ranges = climb.ranges[ok, sensor]
        fits.append(
            tuple(_hyperbola_row(ranges, climb.pixels[ok, sensor, axis]) for axis in range(2))
        )
    return CalibrationTables(
        centroids_px=centroids,
        fits=tuple(fits),  # type: ignore[arg-type]
        stage_ranges_m=climb.ranges,
    )


__all__ = [
    "EQ10_MATLAB",
    "PAPER_FOCAL_PX",
    "PAPER_TOF_MOUNTS_C",
    "STATED_TOF_MOUNTS_C",
    "TABLE2_CENTROIDS_PX",
    "TABLE3_RANGES_M",
    "TABLE4",
    "CalibrationTables",
    "eq10_intrinsics",
    "implied_sensor_offset_m",
    "make_paper_setup_calibrations",
    "paper_camera",
    "reproduce_calibration_tables",
    "write_eq10_calibration",
]
