"""Settings of the drone–deck fusion EKF (:mod:`estimation.fusion`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.special import gammaincinv

from estimation.errors import ConfigError, require_choice
from estimation.fusion.model import TwoWaves, deck_spectrum
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from estimation.noise import (
    IMU_NOISE_DENSITY,
    VL53L1X_RESOLUTION_M,
    VL53L1X_SIGMA_0_M,
    VL53L1X_SIGMA_PER_M,
    TofNoiseModel,
)
from estimation.registry import BUILT_IN, FRAME_ESTIMATOR_NAMES

#: Estimators whose deck pose (T_CD) the fusion can take as a measurement: the shipped
#: single-frame ones, each with its measurement sigmas below (an estimator registered by
#: ``estimation.registry.register_estimator``, before or after this import, is not a source:
#: it has no sigmas here)
POSE_SOURCES: tuple[str, ...] = tuple(n for n in FRAME_ESTIMATOR_NAMES if n in BUILT_IN)

#: The SVGS paper's innovation gate for SVGS and for the IR beacon with its rangefinder:
#: 10 standard deviations (paper 003, Table 1), deliberately relaxed so that intermittent
#: vision measurements are fused rather than rejected.
PAPER_GATE_SD = 10.0


def nis_gate(dof: int, gate_probability: float, gate_sd: float | None) -> float:
    """The largest accepted normalised innovation squared (NIS) of a ``dof``-dimensional
    update: ``gate_sd`` squared when a gate in standard deviations is set (a Mahalanobis
    distance of ``gate_sd``, as PX4 EKF2 states its gates), else the chi-square quantile
    ``gate_probability`` with ``dof`` degrees of freedom (0.9995 is 3.5 SD for one)."""
    if gate_sd is not None:
        return float(gate_sd) ** 2
    # scipy.stats.chi2.ppf's own formula: scipy.special is loaded already, scipy.stats is not
    return float(2.0 * gammaincinv(0.5 * dof, gate_probability))


def _check_sigmas(key: str, sigmas: tuple[float, ...]) -> None:
    if len(sigmas) != 6:
        raise ConfigError(key, f"{sigmas!r} needs 6 values: x, y, z (m), roll, pitch, yaw (deg)")
    for value in sigmas:
        # .inf is allowed and means "do not use this component of the measurement"
        if not (value > 0.0 or math.isinf(value)):
            raise ConfigError(key, f"{sigmas!r}: every sigma must be > 0 (or .inf: unused)")


#: the identification's windows and refit interval, seconds
_WINDOW_S = Limit(0.0, 1e4, low_inclusive=False)


@dataclass
class FusionConfig:
    """The EKF of the relative drone–deck state (see :mod:`estimation.fusion`).

    Pose-measurement sigmas are per source, 1-sigma per frame: x, y, z of ``t_CD`` in the
    camera frame (metres) and roll, pitch, yaw of the deck (degrees); ``.inf`` drops a
    component (e.g. IHRCF's z, roll and pitch, which come from the same ToF ranges the filter
    already fuses).  Process noises are power spectral densities of white deck accelerations.
    """

    #: estimators whose (delayed) poses are fused; each must also be computed by the env
    sources: tuple[str, ...] = ("atda", "crhf")
    #: fuse the four ToF ranges (undelayed: a range to the deck plane along each ray)
    use_tof: bool = True
    #: how far back a delayed measurement is still fused at its own timestamp, seconds
    horizon_s: float = limited(0.5, Limit(0.0, 10.0), physical=Limit.non_negative(10.0))
    #: chi-square innovation gate: a measurement whose NIS exceeds this quantile is rejected
    gate_probability: float = limited(
        0.9995, Limit(0.0, 1.0, low_inclusive=False, high_inclusive=False)
    )
    #: the gate as a Mahalanobis distance in standard deviations (replaces gate_probability
    #: when set; PAPER_GATE_SD = 10 is the SVGS paper's); None: the chi-square gate above
    gate_sd: float | None = limited(None, Limit(0.0, 1e3, low_inclusive=False))
    #: no accepted pose update for this long: the estimate is invalid and the filter
    #: re-initialises from the next pose measurement, seconds
    reset_timeout_s: float = limited(1.0, POSITIVE, physical=Limit.positive(60.0))
    #: white deck linear-acceleration PSD, m^2/s^3 (a random walk in velocity)
    deck_accel_psd: float = limited(0.02, NON_NEGATIVE, physical=Limit.non_negative(1e3))
    #: white deck angular-acceleration PSD (of the Euler angles), rad^2/s^3
    deck_angular_accel_psd: float = limited(0.002, NON_NEGATIVE, physical=Limit.non_negative(1e3))
    #: the deck's roll/pitch natural period, s (0: constant-rate Euler angles, the white
    #: angular acceleration above); with a period, roll and pitch are a damped oscillator about
    #: level driven by that noise (estimation/fusion/model.py), damping ratio below
    deck_period_s: float = limited(
        0.0,
        NON_NEGATIVE,
        physical=Limit.non_negative(1e3, "0: no deck oscillator; ships roll at 5-30 s"),
    )
    deck_damping_ratio: float = limited(0.3, NON_NEGATIVE, physical=Limit.non_negative(10.0))
    #: the sea's two wave components as seen in the deck's roll and in its pitch: periods, s
    #: (empty: none).  With both set, roll and pitch are each the fourth-order model of two
    #: components (estimation/fusion/model.py) with the damping ratio above, driven by the
    #: white noise that gives the model the sea's spread deck_attitude_rms_deg (roll, pitch);
    #: deck_period_s is then unused and deck_angular_accel_psd drives yaw alone
    deck_roll_periods_s: tuple[float, ...] = ()
    deck_pitch_periods_s: tuple[float, ...] = ()
    deck_attitude_rms_deg: tuple[float, ...] = limited(
        (3.0, 3.0), physical=Limit.positive(90.0, "roll, pitch")
    )
    #: a simulator (or any host that knows the sea) replaces the three above by the sea's own
    #: (landing_env: the two largest roll and pitch components of a `sinusoids` motion)
    deck_waves_from_motion: bool = False
    #: identify roll's and pitch's model online from the filter's own estimates (estimation/
    #: fusion/identify.py: a sliding-window AR fit, two wave components).  Until the first
    #: fit the model is a broad initial one (the identify_initial_* keys).  Given wave
    #: periods above (a prior: the scenario's spectrum, an HMS report) are the model instead
    identify_deck_motion: bool = True
    #: the window of the latest motion the fit uses, the minimum before the first fit, the
    #: interval between fits and the spacing of the (block-averaged) samples, s
    identify_window_s: float = limited(90.0, _WINDOW_S)
    identify_min_window_s: float = limited(15.0, _WINDOW_S)
    identify_refit_s: float = limited(1.0, _WINDOW_S)
    identify_sample_s: float = limited(0.5, Limit(0.01, 5.0))
    #: the order of the autoregressive fit (even: pole pairs; 4 is the two components alone)
    identify_ar_order: int = 8
    #: the identified factors are held inside these periods (s) and damping ratios
    identify_period_range_s: tuple[float, ...] = (2.0, 30.0)
    identify_damping_range: tuple[float, ...] = (0.05, 2.0)
    #: the driving noise of the identified model, as a multiple of the one that gives it the
    #: window's RMS: room for what a 90 s window leaves uncertain.  On the tuning motions
    #: (4 runs of 120 s) gain 1 gave roll/pitch NEES 2.47 and MAE 0.62 / 0.55 deg, gain 2
    #: NEES 2.15 (chi-square mean 2) and 0.61 / 0.57
    identify_noise_gain: float = limited(2.0, Limit(0.0, 1e3, low_inclusive=False))
    #: the broad model before the first fit without a prior: both axes two factors at these
    #: periods (s) with this damping ratio, at deck_attitude_rms_deg
    identify_initial_periods_s: tuple[float, ...] = (10.0, 5.0)
    identify_initial_damping: float = limited(0.5, Limit(0.005, 10.0))
    #: the pose sources' roll and pitch errors are not independent from frame to frame
    #: (tight's on realistic sensing: autocorrelation 0.5-0.75 at a lag of one frame, still
    #: 0.07-0.34 at five, and 1.25-1.6 times its own sigma).  They are modelled as a white
    #: part plus a first-order (Gauss-Markov) part of this correlation time (s) and share of
    #: the variance, two more states the filter estimates (estimation/fusion/model.py),
    #: rather than averaged as independent; and the sources' roll/pitch sigma is multiplied
    #: by tilt_error_sigma_scale.  Fitted to tight's errors on the tuning motions (the bench's
    #: JONSWAP seas, benchmarks/fused_motions.py): at sea state 4 a share of 0.8 with rho
    #: 0.67 per 50 ms frame (0.8 rho = 0.54, 0.8 rho² = 0.36) and 1.25-1.44 times its
    #: sigma, at sea state 3 (slower, so longer-lived pose-dependent errors) 0.93 with rho
    #: 0.8 and 1.6 times; pooled: 0.85, 170 ms (rho 0.75), 1.45.  0: independent errors,
    #: no extra states
    tilt_error_correlation_s: float = limited(0.17, Limit(0.0, 10.0))
    tilt_error_coloured_share: float = limited(0.85, Limit(0.0, 1.0, high_inclusive=False))
    tilt_error_sigma_scale: float = limited(1.45, Limit(0.0, 100.0, low_inclusive=False))
    #: IMU accelerometer white-noise density, m/s^2/sqrt(Hz) and bias random walk, m/s^3/sqrt(Hz)
    accel_noise_density: float = limited(1.0e-3, NON_NEGATIVE, physical=IMU_NOISE_DENSITY)
    accel_bias_random_walk: float = limited(4.0e-4, NON_NEGATIVE, physical=IMU_NOISE_DENSITY)
    #: prior 1-sigma of the accelerometer bias (m/s^2), the relative velocity (m/s) and the
    #: deck's Euler rates (rad/s) when the filter (re)initialises
    initial_accel_bias_sigma: float = limited(0.05, POSITIVE, physical=Limit.positive(1e3))
    initial_velocity_sigma: float = limited(0.3, POSITIVE, physical=Limit.positive(1e3))
    initial_rate_sigma: float = limited(0.2, POSITIVE, physical=Limit.positive(1e3))
    #: ToF range noise: sigma = tof_sigma_m + tof_sigma_per_m * range, with readings in steps
    #: of tof_resolution_m (estimation.noise.TofNoiseModel; defaults: the VL53L1X model)
    tof_sigma_m: float = limited(VL53L1X_SIGMA_0_M, NON_NEGATIVE, physical=Limit.positive(1.0))
    tof_sigma_per_m: float = limited(
        VL53L1X_SIGMA_PER_M, NON_NEGATIVE, physical=Limit.non_negative(1.0)
    )
    tof_resolution_m: float = limited(
        VL53L1X_RESOLUTION_M,
        NON_NEGATIVE,
        physical=Limit.non_negative(0.1, "VL53L1X reports whole millimetres"),
    )
    #: a simulator (or any host that knows its sensors) replaces the ToF noise above by the
    #: configured sensor's model (landing_env: the `tof` section), so that the filter weights
    #: exact ranges as exact and noisy ones as noisy
    noise_from_sensors: bool = True
    #: per-source pose sigmas: x, y, z (m, camera frame), roll, pitch, yaw (deg).  IHRCF's
    #: and CRHF's z, roll and pitch are the plane through the same ToF ranges the filter
    #: fuses itself (undelayed): using them again would count that noise twice; .inf drops a
    #: component of that source's pose measurement (x, y, z along the camera's axes: the
    #: filter takes the measurement along them)
    atda_sigma: tuple[float, ...] = limited(
        (0.003, 0.003, 0.008, 3.0, 3.0, 0.3),
        physical=Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    )
    ihrcf_sigma: tuple[float, ...] = limited(
        (0.002, 0.002, math.inf, math.inf, math.inf, 0.3),
        physical=Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    )
    crhf_sigma: tuple[float, ...] = limited(
        (0.002, 0.002, math.inf, math.inf, math.inf, 0.3),
        physical=Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    )
    #: tight: used only when an estimate carries no covariance (see covariance_sources)
    tight_sigma: tuple[float, ...] = limited(
        (0.002, 0.002, 0.005, 1.0, 1.0, 0.3),
        physical=Limit(0.0, 1e3, low_inclusive=False, allow_inf=True),
    )
    #: sources whose own 6x6 covariance (from their measurement model, e.g. tight's
    #: Jacobian) is the measurement noise, in place of the fixed sigmas above
    covariance_sources: tuple[str, ...] = ("tight",)

    def __post_init__(self) -> None:
        self.sources = tuple(self.sources)
        for name in self.sources:
            require_choice("sources", name, POSE_SOURCES)
        self.covariance_sources = tuple(self.covariance_sources)
        for name in self.covariance_sources:
            require_choice("covariance_sources", name, POSE_SOURCES)
        require_limits(self)
        self.deck_roll_periods_s = tuple(float(v) for v in self.deck_roll_periods_s)
        self.deck_pitch_periods_s = tuple(float(v) for v in self.deck_pitch_periods_s)
        self.deck_attitude_rms_deg = tuple(float(v) for v in self.deck_attitude_rms_deg)
        for key in ("deck_roll_periods_s", "deck_pitch_periods_s"):
            periods = getattr(self, key)
            # explicit Euler at the IMU rate needs w dt << 1: waves at sea are 2-30 s
            if periods and (len(periods) != 2 or not all(0.5 <= p <= 1e3 for p in periods)):
                raise ConfigError(key, f"{periods!r}: two periods in 0.5-1000 s, or [] for none")
        if bool(self.deck_roll_periods_s) != bool(self.deck_pitch_periods_s):
            raise ConfigError("deck_pitch_periods_s", "set with deck_roll_periods_s, or neither")
        if len(self.deck_attitude_rms_deg) != 2 or not all(
            0.0 < v <= 90.0 for v in self.deck_attitude_rms_deg
        ):
            raise ConfigError("deck_attitude_rms_deg", "two values in (0, 90]: roll, pitch (deg)")
        if self.deck_roll_periods_s and not self.deck_damping_ratio >= 0.005:
            # undamped, the model has no stationary spread to derive its driving noise from
            raise ConfigError("deck_damping_ratio", "must be >= 0.005 with the wave periods")
        self._check_identification()
        for name in POSE_SOURCES:
            key = f"{name}_sigma"
            setattr(self, key, tuple(float(v) for v in getattr(self, key)))
            _check_sigmas(key, getattr(self, key))

    def _check_identification(self) -> None:
        if self.identify_ar_order not in range(4, 17, 2):
            raise ConfigError("identify_ar_order", f"{self.identify_ar_order!r}: 4, 6, ..., 16")
        if self.identify_min_window_s > self.identify_window_s:
            raise ConfigError("identify_min_window_s", "must be <= identify_window_s")
        if self.identify_min_window_s < 3 * self.identify_ar_order * self.identify_sample_s:
            raise ConfigError(
                "identify_min_window_s",
                "needs 3 * identify_ar_order samples (identify_sample_s apart) or more",
            )
        for key, low, high in (
            ("identify_period_range_s", 0.5, 1e3),
            ("identify_initial_periods_s", 0.5, 1e3),
            ("identify_damping_range", 0.005, 10.0),
        ):
            values = tuple(float(v) for v in getattr(self, key))
            setattr(self, key, values)
            if len(values) != 2 or not all(low <= v <= high for v in values):
                raise ConfigError(key, f"{values!r}: two values in [{low:g}, {high:g}]")
            if key != "identify_initial_periods_s" and not values[0] < values[1]:
                raise ConfigError(key, f"{values!r}: the low end first, below the high end")

    @property
    def deck_w0(self) -> float:
        """The deck's natural angular frequency, rad/s (0: none)."""
        return 2.0 * math.pi / self.deck_period_s if self.deck_period_s > 0.0 else 0.0

    @property
    def deck4(self) -> tuple | None:
        """The fourth-order deck model per axis (roll, pitch), each ``(polynomial, PSD,
        stationary sigmas of acceleration and jerk)`` (:func:`~estimation.fusion.model.
        deck_spectrum`), or None when no wave periods are set."""
        if not self.deck_roll_periods_s:
            return None
        return tuple(
            deck_spectrum(
                2.0 * math.pi / periods[0],
                2.0 * math.pi / periods[1],
                self.deck_damping_ratio,
                math.radians(rms),
            )
            for periods, rms in zip(
                (self.deck_roll_periods_s, self.deck_pitch_periods_s),
                self.deck_attitude_rms_deg,
                strict=True,
            )
        )

    @property
    def deck4_initial(self) -> tuple | None:
        """The deck model the filter starts from: the prior (:attr:`deck4`), else, when it
        identifies the motion, the broad initial model; None: neither."""
        if not self.identifies:
            return self.deck4
        w1, w2 = (2.0 * math.pi / p for p in self.identify_initial_periods_s)
        zeta = self.identify_initial_damping
        return tuple(
            TwoWaves.matched(w1, zeta, w2, zeta, *(0.5 * math.radians(rms) ** 2,) * 2)
            for rms in self.deck_attitude_rms_deg
        )

    @property
    def identifies(self) -> bool:
        """Whether the filter identifies the deck's motion: asked to, and no prior given
        (given wave periods are the model, as before)."""
        return self.identify_deck_motion and not self.deck_roll_periods_s

    @property
    def tof_noise(self) -> TofNoiseModel:
        return TofNoiseModel(self.tof_sigma_m, self.tof_sigma_per_m, self.tof_resolution_m)

    def gate(self, dof: int) -> float:
        """The largest accepted NIS of a ``dof``-dimensional update (:func:`nis_gate`)."""
        return nis_gate(dof, self.gate_probability, self.gate_sd)

    def pose_sigma(self, source: str) -> tuple[float, ...]:
        """The 1-sigma of a source's pose: metres and degrees."""
        return getattr(self, f"{source}_sigma")
