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
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

N_STATE = 15
#: the state's size with the fourth-order (two-component) deck model
N_STATE_4 = 19
P, V, TH, W, BA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
#: roll and pitch angular accelerations and jerks (fourth-order deck model only)
AJ = slice(15, 19)
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


def deck_polynomial(w1: float, w2: float, zeta: float) -> tuple[float, float, float, float]:
    """``(a0, a1, a2, a3)`` of ``s⁴ + a3 s³ + a2 s² + a1 s + a0``, the product of the two
    second-order factors ``s² + 2 zeta w s + w²``."""
    b1, c1, b2, c2 = 2.0 * zeta * w1, w1 * w1, 2.0 * zeta * w2, w2 * w2
    return (c1 * c2, b1 * c2 + b2 * c1, c1 + c2 + b1 * b2, b1 + b2)


@lru_cache(maxsize=16)
def deck_spectrum(
    w1: float, w2: float, zeta: float, sigma_rad: float
) -> tuple[tuple[float, float, float, float], float, tuple[float, float]]:
    """The fourth-order deck model matched to a sea whose roll/pitch spread is ``sigma_rad``:
    its polynomial, the driving PSD ``q`` (rad²/s⁷) that gives it that stationary variance
    (continuous Lyapunov equation of the phase-variable form) and the stationary sigmas of the
    angular acceleration and jerk (the priors of those states)."""
    from scipy.linalg import solve_continuous_lyapunov

    a0, a1, a2, a3 = deck_polynomial(w1, w2, zeta)
    a = np.zeros((4, 4))
    a[0, 1] = a[1, 2] = a[2, 3] = 1.0
    a[3] = (-a0, -a1, -a2, -a3)
    g = np.zeros((4, 4))
    g[3, 3] = 1.0
    unit = solve_continuous_lyapunov(a, -g)  # stationary covariance for q = 1
    q = sigma_rad * sigma_rad / float(unit[0, 0])
    return (a0, a1, a2, a3), q, (math.sqrt(q * unit[2, 2]), math.sqrt(q * unit[3, 3]))


@lru_cache(maxsize=64)
def _process_noise(
    dt: float,
    q_accel: float,
    q_angular: float,
    accel_noise_density: float,
    bias_walk: float,
    q_deck4: tuple[float, float] | None = None,
) -> np.ndarray:
    """The discrete process noise over ``dt`` (cached: it does not depend on the state).

    ``q_deck4``: the fourth-order deck model's jerk-rate PSDs of roll and pitch, whose noise
    then enters through the jerk alone (yaw keeps the white angular acceleration)."""
    n = N_STATE_4 if q_deck4 is not None else N_STATE
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
        q[17, 17], q[18, 18] = q_deck4[0] * d1, q_deck4[1] * d1
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
) -> tuple[np.ndarray, np.ndarray]:
    """One IMU sample of prediction over ``dt`` (the sample's specific force, body frame).

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
    if deck4 is not None:
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
        noise = _process_noise(dt, q_accel, q_angular, accel_noise_density, bias_walk, q_deck4)
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
    if deck4 is None:
        noise = _process_noise(dt, q_accel, q_angular, accel_noise_density, bias_walk)
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
