"""State, process model and measurement models of the drone–deck relative EKF.

State (15), all in the world frame's axes W (gravity-aligned, z up):

=====  ======  ==============================================================================
0:3    ``p``   the tag centre (deck-frame origin) relative to the drone's centre of mass, m
3:6    ``v``   its rate of change, m/s
6:9    ``th``  the deck's attitude R_WP as ZYX Euler angles (roll, pitch, yaw), rad
9:12   ``w``   their rates, rad/s
12:15  ``ba``  the accelerometer bias, body frame, m/s^2
=====  ======  ==============================================================================

The drone's attitude R_WB is an *input* (the autopilot's attitude estimate), never a state:
the filter estimates only the relative state.  The IMU's specific force gives the drone's
acceleration ``R_WB (f - ba) + g``; the deck's acceleration is white noise (velocity random
walk, PSD ``deck_accel_psd``), and so is the deck's Euler acceleration, or, with a deck
period set (``deck_period_s``), the deck's roll and pitch are a damped oscillator about level
driven by that white noise (the second-order wave-response model of ship motion, e.g. Fossen,
*Handbook of Marine Craft Hydrodynamics and Motion Control*, Sec. 10.2):
``th'' = -w0² th - 2 zeta w0 th' + noise``.

With the sea's two wave components given (``deck_roll_periods_s``, ``deck_pitch_periods_s``)
roll and pitch are each the fourth-order model of those components, the product of two such
second-order factors ``(s² + 2 zeta w1 s + w1²)(s² + 2 zeta w2 s + w2²) th = noise`` in
phase-variable form (a fourth-order wave spectrum with a peak at each component).  The
state then has four more entries (``AJ``: the roll and pitch angular accelerations 15:17 and
jerks 17:19), the white noise drives the jerk's rate, and its PSD is set so that the model's
stationary roll/pitch spread is the sea's (:func:`deck_spectrum`): no tuned constant.

Identified online (estimation/fusion/identify.py), roll and pitch are instead each the SUM
of two damped oscillators (:class:`TwoWaves`), the same four entries holding the second
component's angle (15:17) and rate (17:19).  With the pose sources' coloured tilt errors
modelled (``tilt_error_correlation_s``), the state ends with :data:`N_COLOURED` more: their
roll and pitch errors, unit-variance first-order processes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

N_STATE = 15
#: the state's size with the fourth-order (two-component) deck model
N_STATE_4 = 19
P, V, TH, W, BA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
#: roll and pitch angular accelerations and jerks (fourth-order deck model only)
AJ = slice(15, 19)
#: the pose sources' coloured roll and pitch errors, the state's last entries when modelled
N_COLOURED = 2
GRAVITY_W = np.array([0.0, 0.0, -9.81])
_I3 = np.eye(3)


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Wrap to [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % (2.0 * math.pi) - math.pi


def rotation_zyx(th: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) in closed form (called at the filter rate, where scipy's
    general conversion costs tens of microseconds)."""
    cr, sr = math.cos(th[0]), math.sin(th[0])
    cp, sp = math.cos(th[1]), math.sin(th[1])
    cy, sy = math.cos(th[2]), math.sin(th[2])
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def deck_normal(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The deck's normal R_WP e_z and its 3x3 Jacobian with respect to (roll, pitch, yaw)."""
    cr, sr = math.cos(th[0]), math.sin(th[0])
    cp, sp = math.cos(th[1]), math.sin(th[1])
    cy, sy = math.cos(th[2]), math.sin(th[2])
    normal = np.array([cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr])
    jacobian = np.array(
        [
            [-cy * sp * sr + sy * cr, cy * cp * cr, -sy * sp * cr + cy * sr],
            [-sy * sp * sr - cy * cr, sy * cp * cr, cy * sp * cr + sy * sr],
            [-cp * sr, -sp * cr, 0.0],
        ]
    )
    return normal, jacobian


def deck_polynomial(
    w1: float, w2: float, zeta: float, zeta2: float | None = None
) -> tuple[float, float, float, float]:
    """``(a0, a1, a2, a3)`` of ``s⁴ + a3 s³ + a2 s² + a1 s + a0``, the product of the two
    second-order factors ``s² + 2 zeta w1 s + w1²`` and ``s² + 2 zeta2 w2 s + w2²`` (``zeta2``
    None: ``zeta``)."""
    zeta2 = zeta if zeta2 is None else zeta2
    b1, c1, b2, c2 = 2.0 * zeta * w1, w1 * w1, 2.0 * zeta2 * w2, w2 * w2
    return (c1 * c2, b1 * c2 + b2 * c1, c1 + c2 + b1 * b2, b1 + b2)


def deck_spectrum_of(
    w1: float, zeta1: float, w2: float, zeta2: float, sigma_rad: float, noise_gain: float = 1.0
) -> tuple[tuple[float, float, float, float], float, tuple[float, float]]:
    """The fourth-order deck model of the factors ``(w1, zeta1)`` and ``(w2, zeta2)`` matched
    to a roll/pitch spread ``sigma_rad``: its polynomial, the driving PSD ``q`` (rad²/s⁷) that
    gives it that stationary variance (continuous Lyapunov equation of the phase-variable
    form), times ``noise_gain``, and the stationary sigmas of the angular acceleration and
    jerk (the priors of those states)."""
    from scipy.linalg import solve_continuous_lyapunov

    a0, a1, a2, a3 = deck_polynomial(w1, w2, zeta1, zeta2)
    a = np.zeros((4, 4))
    a[0, 1] = a[1, 2] = a[2, 3] = 1.0
    a[3] = (-a0, -a1, -a2, -a3)
    g = np.zeros((4, 4))
    g[3, 3] = 1.0
    unit = solve_continuous_lyapunov(a, -g)  # stationary covariance for q = 1
    q = noise_gain * sigma_rad * sigma_rad / float(unit[0, 0])
    return (a0, a1, a2, a3), q, (math.sqrt(q * unit[2, 2]), math.sqrt(q * unit[3, 3]))


@lru_cache(maxsize=16)
def deck_spectrum(
    w1: float, w2: float, zeta: float, sigma_rad: float
) -> tuple[tuple[float, float, float, float], float, tuple[float, float]]:
    """:func:`deck_spectrum_of` with one damping ratio for both factors (a given sea)."""
    return deck_spectrum_of(w1, zeta, w2, zeta, sigma_rad)


@dataclass(frozen=True)
class TwoWaves:
    """Roll or pitch as the SUM of two damped oscillators, each driven by its own white
    noise (the parallel form; the identified model, estimation/fusion/identify.py):
    ``theta = theta_1 + theta_2``, ``theta_k'' = -w_k² theta_k - 2 zeta_k w_k theta_k' +
    n_k``, PSD ``q_k``.  Unlike the product form (:func:`deck_spectrum_of`), each
    component's variance is free: a swell and a wind sea of any relative size.  The state
    keeps the total angle and rate (th, w) and holds the second component's angle and rate
    in the fourth-order model's entries 15:17 and 17:19."""

    w1: float
    zeta1: float
    w2: float
    zeta2: float
    q1: float
    q2: float

    @classmethod
    def matched(
        cls, w1: float, zeta1: float, w2: float, zeta2: float, var1: float, var2: float
    ) -> TwoWaves:
        """The components' driving PSDs that give them these stationary variances (rad²):
        ``q = 4 zeta w³ var``."""
        return cls(w1, zeta1, w2, zeta2, 4.0 * zeta1 * w1**3 * var1, 4.0 * zeta2 * w2**3 * var2)

    @property
    def second_sigmas(self) -> tuple[float, float]:
        """The stationary sigmas of the second component's angle and rate (its priors)."""
        sigma = math.sqrt(self.q2 / (4.0 * self.zeta2 * self.w2**3))
        return sigma, self.w2 * sigma


@lru_cache(maxsize=64)
def _process_noise(
    dt: float,
    q_accel: float,
    q_angular: float,
    accel_noise_density: float,
    bias_walk: float,
    q_deck4: tuple[float, ...] | None = None,
    tilt_correlation_s: float = 0.0,
    parallel: bool = False,
) -> np.ndarray:
    """The discrete process noise over ``dt`` (cached: it does not depend on the state).

    ``q_deck4``: the fourth-order deck model's jerk-rate PSDs of roll and pitch, whose noise
    then enters through the jerk alone (yaw keeps the white angular acceleration).
    ``tilt_correlation_s`` > 0: the state ends with the two unit-variance first-order
    (Gauss-Markov) errors of the pose sources' roll and pitch (:data:`N_COLOURED`)."""
    n = (N_STATE_4 if q_deck4 is not None else N_STATE) + (
        N_COLOURED if tilt_correlation_s > 0.0 else 0
    )
    q = np.zeros((n, n))
    d1, d2, d3 = dt, dt * dt / 2.0, dt * dt * dt / 3.0
    # white-acceleration (continuous) noise integrated over dt, per axis
    for pos, vel, psd in ((P, V, q_accel), (TH, W, q_angular)):
        q[pos, pos] = psd * d3 * _I3
        q[pos, vel] = q[vel, pos] = psd * d2 * _I3
        q[vel, vel] = psd * d1 * _I3
    q[V, V] += accel_noise_density**2 * d1 * _I3
    q[BA, BA] = bias_walk**2 * d1 * _I3
    if q_deck4 is not None:
        for i in (6, 7, 9, 10):  # roll and pitch: angle and rate rows and columns
            q[i, :] = 0.0
            q[:, i] = 0.0
        if not parallel:
            q[17, 17], q[18, 18] = q_deck4[0] * d1, q_deck4[1] * d1
        for i in range(2) if parallel else ():
            # white accelerations: n1 drives the total rate, n2 the total and the second
            # component's rate (q_deck4: q1, q2 of roll, then of pitch), integrated over dt
            q1, q2 = q_deck4[2 * i], q_deck4[2 * i + 1]
            for channel, psd in (((6 + i, 9 + i),), q1), (((6 + i, 9 + i), (15 + i, 17 + i)), q2):
                for pos_a, vel_a in channel:
                    for pos_b, vel_b in channel:
                        q[pos_a, pos_b] += psd * d3
                        q[pos_a, vel_b] += psd * d2
                        q[vel_a, pos_b] += psd * d2
                        q[vel_a, vel_b] += psd * d1
    if tilt_correlation_s > 0.0:
        # unit stationary variance: exp(-dt/tau) b + w, var(w) = 1 - exp(-2 dt/tau)
        q[n - 2, n - 2] = q[n - 1, n - 1] = -math.expm1(-2.0 * dt / tilt_correlation_s)
    q.setflags(write=False)
    return q


def predict(
    x: np.ndarray,
    cov: np.ndarray,
    accel_b: np.ndarray,
    r_wb: np.ndarray,
    dt: float,
    q_accel: float,
    q_angular: float,
    accel_noise_density: float,
    bias_walk: float,
    deck_w0: float = 0.0,
    deck_zeta: float = 0.0,
    deck4: tuple | None = None,
    tilt_correlation_s: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """One IMU sample of prediction over ``dt`` (the sample's specific force, body frame).

    ``tilt_correlation_s`` > 0: the last :data:`N_COLOURED` states are the pose sources'
    roll and pitch errors, first-order processes of that correlation time.

    ``deck_w0`` (rad/s, 0: constant Euler rates) and ``deck_zeta``: the deck's roll and pitch
    oscillate about level with this natural frequency and damping ratio.  ``deck4``: the
    fourth-order model of roll and of pitch, each as :func:`deck_spectrum` gives it (the state
    then has :data:`N_STATE_4` entries), in place of the oscillator."""
    n = x.shape[0]
    # relative acceleration = deck (zero mean) - drone (from the IMU)
    a_rel = -(r_wb @ (accel_b - x[BA])) - GRAVITY_W
    x = x.copy()
    x[P] += x[V] * dt + 0.5 * dt * dt * a_rel
    x[V] += a_rel * dt
    rates = x[W].copy()
    x[TH] += rates * dt
    f = np.eye(n)
    parallel = deck4 is not None and isinstance(deck4[0], TwoWaves)
    q_deck4: tuple[Any, ...]
    if parallel:
        assert deck4 is not None
        # roll and pitch: the sum of two oscillators (TwoWaves), explicit Euler
        angles, second, second_rate = x[TH][:2] - rates[:2] * dt, x[15:17].copy(), x[17:19].copy()
        q_deck4 = (deck4[0].q1, deck4[0].q2, deck4[1].q1, deck4[1].q2)
        for i in range(2):
            m = deck4[i]
            c1, d1, c2, d2 = m.w1 * m.w1, 2.0 * m.zeta1 * m.w1, m.w2 * m.w2, 2.0 * m.zeta2 * m.w2
            accel2 = -c2 * second[i] - d2 * second_rate[i]
            accel1 = -c1 * (angles[i] - second[i]) - d1 * (rates[i] - second_rate[i])
            x[9 + i] += (accel1 + accel2) * dt
            x[15 + i] += second_rate[i] * dt
            x[17 + i] += accel2 * dt
            f[9 + i, 6 + i], f[9 + i, 9 + i] = -c1 * dt, 1.0 - d1 * dt
            f[9 + i, 15 + i], f[9 + i, 17 + i] = (c1 - c2) * dt, (d1 - d2) * dt
            f[15 + i, 17 + i] = dt
            f[17 + i, 15 + i], f[17 + i, 17 + i] = -c2 * dt, 1.0 - d2 * dt
    elif deck4 is not None:
        # roll and pitch: angle <- rate <- acceleration <- jerk <- the polynomial, explicit Euler
        angles, accel, jerk = x[TH][:2] - rates[:2] * dt, x[15:17].copy(), x[17:19].copy()
        x[9:11] += accel * dt
        x[15:17] += jerk * dt
        for i in range(2):
            a0, a1, a2, a3 = deck4[i][0]
            x[17 + i] -= (a0 * angles[i] + a1 * rates[i] + a2 * accel[i] + a3 * jerk[i]) * dt
            f[9 + i, 15 + i] = f[15 + i, 17 + i] = dt
            f[17 + i, 6 + i], f[17 + i, 9 + i] = -a0 * dt, -a1 * dt
            f[17 + i, 15 + i], f[17 + i, 17 + i] = -a2 * dt, 1.0 - a3 * dt
        q_deck4 = (deck4[0][1], deck4[1][1])
    elif deck_w0 > 0.0:
        # roll and pitch (not yaw): restoring towards level and damping, explicit Euler
        stiffness, damping = deck_w0 * deck_w0 * dt, 2.0 * deck_zeta * deck_w0 * dt
        angles = x[TH][:2] - rates[:2] * dt
        x[9:11] -= stiffness * angles + damping * rates[:2]
        f[9, 6] = f[10, 7] = -stiffness
        f[9, 9] = f[10, 10] = 1.0 - damping
    f[P, V] = dt * _I3
    f[P, BA] = 0.5 * dt * dt * r_wb
    f[V, BA] = dt * r_wb
    f[TH, W] = dt * _I3
    if tilt_correlation_s > 0.0:
        decay = math.exp(-dt / tilt_correlation_s)
        x[n - N_COLOURED :] *= decay
        f[n - 2, n - 2] = f[n - 1, n - 1] = decay
    noise = _process_noise(
        dt,
        q_accel,
        q_angular,
        accel_noise_density,
        bias_walk,
        None if deck4 is None else q_deck4,
        tilt_correlation_s,
        parallel,
    )
    return x, f @ cov @ f.T + noise


def tof_model(
    x: np.ndarray, origin_b: np.ndarray, r_wb: np.ndarray
) -> tuple[float, np.ndarray] | None:
    """Predicted range of a ToF sensor (origin in B, measuring along body -z) and its 1x15 H.

    The range to the deck plane (through the tag centre, normal R_WP e_z) along the ray;
    None when the ray is (nearly) parallel to the plane or points away from it.
    """
    normal, d_normal = deck_normal(x[TH])
    direction = -r_wb[:, 2]
    q = x[P] - r_wb @ origin_b  # the deck origin relative to the sensor
    along = float(normal @ direction)  # negative: the ray points down into the deck
    if along > -0.2:  # grazing (beyond ~78 degrees of incidence) or pointing away
        return None
    predicted = float(normal @ q) / along
    if predicted <= 0.0:
        return None
    h = np.zeros(x.shape[0])
    h[P] = normal / along
    h[TH] = (q - predicted * direction) @ d_normal / along
    return predicted, h


def ekf_update(
    x: np.ndarray,
    cov: np.ndarray,
    innovation: np.ndarray,
    h: np.ndarray,
    noise: np.ndarray,
    gate: float,
) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """Gated EKF update: (state, covariance, NIS, accepted).

    A measurement whose normalised innovation squared exceeds ``gate`` leaves the state as is.
    With the optimal gain, P - K S K^T equals the Joseph form; it is symmetrised against
    round-off.
    """
    ph = cov @ h.T
    s = h @ ph + noise
    s_inv = np.linalg.inv(s)
    nis = float(innovation @ s_inv @ innovation)
    if not nis <= gate:  # also refuses a NaN
        return x, cov, nis, False
    gain = ph @ s_inv
    x = x + gain @ innovation
    cov = cov - gain @ s @ gain.T
    return x, 0.5 * (cov + cov.T), nis, True
