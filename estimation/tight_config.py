"""The settings of the ``tight`` estimator (:class:`TightConfig`): its noise models, solver
limits, gates and principal-point source (:mod:`estimation.tight` uses them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from estimation.errors import ConfigError, require_choice
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.noise import (
    DEFAULT_PIXEL_SIGMA_PX,
    VL53L1X_RESOLUTION_M,
    VL53L1X_SIGMA_0_M,
    VL53L1X_SIGMA_PER_M,
    TofNoiseModel,
)

PRINCIPAL_POINT_SOURCES = ("touch_points", "calibrated")
#: where the previous estimate enters as a start (``TightConfig.previous_start``)
PREVIOUS_STARTS = ("fallback", "first")


@dataclass(frozen=True)
class TightConfig:
    """Settings of :class:`~estimation.tight.TightEstimator`.

    ``pixel_sigma_px``: 1-sigma of a detected corner coordinate (default
    :data:`estimation.noise.DEFAULT_PIXEL_SIGMA_PX`); with ``pixel_sigma_axes_px`` set (> 0)
    it is the sigma when the tag's edges lie on the image diagonals, ``pixel_sigma_axes_px``
    the sigma when they lie along the pixel axes, and each frame's is
    ``sqrt(d² + (a² - d²) cos²(2φ))`` for its edges' angle φ
    (:func:`estimation.corner_bias.edge_axis_alignment`; the tag rig measures both).
    ``tof_sigma_0_m``,
    ``tof_sigma_per_m``, ``tof_resolution_m``, ``tof_sigma_min_m`` (a floor, 0 by default):
    the ToF noise model
    (:class:`estimation.noise.TofNoiseModel`; defaults: the VL53L1X model the simulator's
    ``tof.noise: vl53l1x`` draws from).  ``max_iterations``: LM iterations per start.
    ``range_gate_sigma``: a range further than this many sigma from the solution is dropped
    and the pose solved again.  ``max_reprojection_error_px``: a larger RMS corner error
    at the solution means the corners are not the tag's (invalid).
    ``ambiguity_ratio_threshold`` / ``history_timeout_s``: without ranges, two IPPE
    solutions whose RMS errors are this close are told apart by the previous estimate
    (as ATDA does).  ``start_cost_margin``: only the starts whose whitened cost is within
    this of the lowest start's are refined (``inf``: all of them); the others start in
    another basin with a cost higher by more than sqrt(50) ≈ 7 sigma.
    ``previous_start``: ``"fallback"`` starts from the previous estimate (within
    ``history_timeout_s``) only when neither IPPE nor the ToF plane gives a start;
    ``"first"`` refines the previous estimate alone first when the frame has four corners
    and three or more ranges, and keeps it when its whitened cost is within
    ``start_cost_margin`` of what a pose in the right basin costs (the number of residuals,
    or the previous estimate's cost where that is higher), else searches from every start
    as ``"fallback"`` does.
    ``principal_point``: ``"touch_points"`` (with a ToF–camera calibration) moves the
    calibrated principal point by the median offset between the pads' measured touch pixels
    and their projection through the calibrated camera (the calibrations' disagreement,
    which CRHF removes by estimating its own principal point, CRHF Sec. 2.7: a chessboard
    calibration off by 0.3 px in cx shifts x by 1.3 mm at 2 m); ``"calibrated"`` keeps K.
    ``corner_bias_px``: the detector's edge offset ``(a, b, c)`` on this camera
    (:class:`estimation.corner_bias.CornerBias`: ``a + b sin²(2φ) + c / L`` pixels outward
    per tag edge), removed from the detected corners before they enter the cost; measured
    with the intrinsics (``deck-landing calibrate`` stores it in the intrinsics file).
    ``noise_from_sensors``: a host that knows its sensors (the simulator) replaces the ToF
    noise above by the configured sensor's model, and the pixel sigma and corner offset by
    the camera's: the configured corner noise in ``project`` mode (no offset), the
    calibrated ones of the intrinsics file when rendering.
    """

    pixel_sigma_px: float = limited(
        DEFAULT_PIXEL_SIGMA_PX, POSITIVE, physical=Limit.positive(100.0, "corner noise, pixels")
    )
    pixel_sigma_axes_px: float = limited(
        0.0, NON_NEGATIVE, physical=Limit.non_negative(100.0, "0: pixel_sigma_px at every angle")
    )
    tof_sigma_0_m: float = limited(VL53L1X_SIGMA_0_M, NON_NEGATIVE, physical=Limit.positive(1.0))
    tof_sigma_per_m: float = limited(
        VL53L1X_SIGMA_PER_M, NON_NEGATIVE, physical=Limit.non_negative(1.0)
    )
    tof_resolution_m: float = limited(
        VL53L1X_RESOLUTION_M,
        NON_NEGATIVE,
        physical=Limit.non_negative(0.1, "VL53L1X reports whole millimetres"),
    )
    tof_sigma_min_m: float = limited(0.0, NON_NEGATIVE, physical=Limit.non_negative(1.0))
    max_iterations: int = limited(12, Limit(1), physical=Limit(1, 1000))
    range_gate_sigma: float = limited(6.0, POSITIVE, physical=Limit.positive(1e3, "gate in sigmas"))
    max_reprojection_error_px: float = limited(10.0, POSITIVE, physical=Limit.positive(1e4))
    min_corner_area_px: float = limited(
        4.0, NON_NEGATIVE, physical=Limit.non_negative(1e7, "a 512x512 image holds 2.6e5 px^2")
    )
    ambiguity_ratio_threshold: float = limited(
        0.6, Limit(0.0, 1.0, low_inclusive=False), physical=Limit(0.0, 1.0)
    )
    history_timeout_s: float = limited(0.5, NON_NEGATIVE, physical=Limit.non_negative(60.0))
    start_cost_margin: float = limited(50.0, NON_NEGATIVE, physical=Limit.non_negative(1e6))
    previous_start: str = "fallback"
    principal_point: str = "touch_points"
    corner_bias_px: tuple[float, float, float] = limited(
        (0.0, 0.0, 0.0), physical=Limit.symmetric(100.0, "detector edge offset a, b (px), c (px^2)")
    )
    noise_from_sensors: bool = True

    def __post_init__(self) -> None:
        require_limits(self)
        require_choice("principal_point", self.principal_point, PRINCIPAL_POINT_SOURCES)
        require_choice("previous_start", self.previous_start, PREVIOUS_STARTS)
        if len(self.corner_bias_px) != 3 or not all(
            math.isfinite(float(v)) for v in self.corner_bias_px
        ):
            raise ConfigError(
                "corner_bias_px", f"{self.corner_bias_px!r}: need three finite numbers (a, b, c)"
            )

    @property
    def tof_noise(self) -> TofNoiseModel:
        return TofNoiseModel(
            self.tof_sigma_0_m, self.tof_sigma_per_m, self.tof_resolution_m, self.tof_sigma_min_m
        )
