"""PX4-style cascade flight controller: velocity -> attitude -> body rate -> mixer -> rotor speeds.

The set-point is a velocity in the heading frame H (the world frame turned by the drone's
current yaw: x forward, y left, z up) and a yaw rate.  The loops, run at the physics rate:

1. velocity PID (world frame, derivative on the measured velocity, conditional-integration
   anti-windup and integrator limits) -> desired acceleration, with vertical acceleration and
   tilt limits that keep the vertical component first;
2. thrust vector -> collective thrust (projected on the current body z, as PX4 does) and a
   desired body z axis; the yaw set-point is integrated from the yaw rate;
3. tilt-prioritised attitude P control: the tilt error (shortest rotation from the current to
   the desired body z) and the heading error get separate gains, so a yaw error never costs
   tilt tracking; plus the yaw-rate feed-forward;
4. body-rate PID (derivative on the measured rate) -> angular acceleration -> torque with the
   gyroscopic term;
5. mixer: per-rotor thrusts from the inverse allocation matrix, with priorities when motors
   saturate: roll/pitch first, then collective thrust, then yaw.

Every limit that acts is reported in :class:`ControllerStatus` (``CascadeController.status``).
Gains are in physical units of acceleration, so they carry over between vehicles of similar
bandwidth; mass and inertia come from :class:`QuadrotorParams`.  The hot path is plain floats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from estimation.limits import POSITIVE, Limit, limited, require_limits
from landing_env.errors import ConfigError, require_range
from landing_env.physics.drone_state import DroneState
from landing_env.physics.quadrotor_params import GRAVITY, QuadrotorParams


@dataclass(frozen=True)
class VelocitySetpoint:
    """Velocity (m/s) in the heading frame H and yaw rate (rad/s, about world z)."""

    velocity_h: np.ndarray
    yaw_rate: float = 0.0

    def __post_init__(self) -> None:
        velocity = np.asarray(self.velocity_h, dtype=float)
        if velocity.shape != (3,):
            raise ValueError(f"velocity_h needs shape (3,), got {velocity.shape}")
        object.__setattr__(self, "velocity_h", velocity)
        object.__setattr__(self, "yaw_rate", float(self.yaw_rate))


#: the physical range of a PID gain, and of a derivative filter's cut-off
PID_GAIN = Limit.non_negative(1e3, "PID gain; PX4's defaults are O(0.1-10)")
FILTER_CUTOFF_HZ = Limit.positive(1e4, "a filter cut-off; above the physics rate it has no effect")


@dataclass(frozen=True)
class ControllerGains:
    """Gains (accelerations per unit error) and saturation limits of the cascade."""

    # velocity loop: a = P e + I int(e) - D dv/dt  (1/s, 1/s^2, dimensionless)
    vel_p_xy: float = limited(3.0, physical=PID_GAIN)
    vel_i_xy: float = limited(1.0, physical=PID_GAIN)
    vel_d_xy: float = limited(0.2, physical=PID_GAIN)
    vel_p_z: float = limited(5.0, physical=PID_GAIN)
    vel_i_z: float = limited(4.0, physical=PID_GAIN)
    vel_d_z: float = limited(0.0, physical=PID_GAIN)
    #: integrator magnitude limits (m/s^2)
    vel_i_limit_xy: float = limited(3.0, physical=PID_GAIN)
    vel_i_limit_z: float = limited(4.0, physical=PID_GAIN)
    #: cut-off of the first-order filter on the velocity derivative (Hz)
    vel_d_cutoff_hz: float = limited(10.0, POSITIVE, physical=FILTER_CUTOFF_HZ)
    # set-point limits (m/s)
    max_horizontal_speed: float = limited(5.0, physical=Limit.positive(50.0))
    max_climb_rate: float = limited(3.0, physical=Limit.positive(50.0))
    max_descent_rate: float = limited(2.0, physical=Limit.positive(50.0))
    # acceleration and tilt limits
    max_tilt: float = limited(
        math.radians(35.0), Limit(0.0, math.radians(80.0), low_inclusive=False)
    )
    max_accel_up: float = limited(6.0, physical=Limit.positive(100.0))
    max_accel_down: float = limited(
        5.0, Limit(0.0, GRAVITY, high_inclusive=False), physical=Limit.positive(100.0)
    )
    # attitude loop: body rate per radian of error (1/s)
    att_p_rp: float = limited(6.5, physical=PID_GAIN)
    att_p_yaw: float = limited(2.8, physical=PID_GAIN)
    #: the yaw set-point is kept within this of the actual yaw (rad)
    max_yaw_error: float = limited(0.5, Limit(0.0, math.pi, low_inclusive=False))
    # rate limits (rad/s)
    max_rate_rp: float = limited(math.radians(220.0), POSITIVE, physical=Limit.positive(100.0))
    max_rate_yaw: float = limited(math.radians(200.0), POSITIVE, physical=Limit.positive(100.0))
    # rate loop: angular acceleration = P e + I int(e) - D d(omega)/dt
    rate_p_rp: float = limited(20.0, physical=PID_GAIN)
    rate_i_rp: float = limited(10.0, physical=PID_GAIN)
    rate_d_rp: float = limited(0.0, physical=PID_GAIN)
    rate_p_yaw: float = limited(15.0, physical=PID_GAIN)
    rate_i_yaw: float = limited(5.0, physical=PID_GAIN)
    rate_d_yaw: float = limited(0.0, physical=PID_GAIN)
    #: rate integrator limits (rad/s^2)
    rate_i_limit_rp: float = limited(30.0, physical=PID_GAIN)
    rate_i_limit_yaw: float = limited(10.0, physical=PID_GAIN)
    #: cut-off of the first-order filter on the rate derivative (Hz)
    rate_d_cutoff_hz: float = limited(30.0, POSITIVE, physical=FILTER_CUTOFF_HZ)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            require_range(f.name, value, 0.0)
            if not math.isfinite(value):
                raise ConfigError(f.name, f"{value!r} is not finite")
        require_limits(self)


@dataclass(frozen=True)
class ControllerStatus:
    """Which limits acted in the last update."""

    #: the set-point speed, climb/descent rate or yaw rate (or yaw error) was limited
    setpoint_limited: bool = False
    #: the vertical acceleration hit max_accel_up/max_accel_down
    vertical_accel_limited: bool = False
    #: the horizontal acceleration was cut to respect the tilt limit or the thrust limit
    tilt_limited: bool = False
    #: the collective thrust hit the motors' range
    thrust_limited: bool = False
    #: a velocity or rate integrator hit its limit
    integrator_limited: bool = False
    #: a body-rate set-point hit max_rate_rp/max_rate_yaw
    rate_limited: bool = False
    #: the mixer scaled down the roll/pitch torque (it did not fit in the motors' range)
    roll_pitch_reduced: bool = False
    #: the mixer moved the collective thrust to keep roll/pitch authority
    thrust_shifted: bool = False
    #: the mixer scaled down the yaw torque
    yaw_reduced: bool = False

    @property
    def mixer_saturated(self) -> bool:
        """True when the mixer had to give up any demanded torque or thrust."""
        return self.roll_pitch_reduced or self.thrust_shifted or self.yaw_reduced

    @property
    def any(self) -> bool:
        """True when any limit acted."""
        return any(getattr(self, f.name) for f in fields(self))


class CascadeController:
    """Velocity/yaw-rate set-point to rotor speed commands (rad/s), PX4 style."""

    def __init__(self, params: QuadrotorParams, gains: ControllerGains | None = None) -> None:
        self.params = params
        self.gains = ControllerGains() if gains is None else gains
        prm = params
        self._mass = prm.mass
        self._inertia = tuple(float(v) for v in prm.inertia_diag)
        self._k_f = prm.k_f
        self._f_min = prm.min_rotor_thrust
        self._f_max = prm.max_rotor_thrust
        self._omega_min = prm.omega_min
        self._omega_max = prm.omega_max
        # Allocation: [T, tau_x, tau_y, tau_z] = A f, with thrust along body z at (x, y) and
        # the reaction torque -spin k_m/k_f per newton of thrust.
        positions = prm.rotor_positions_b
        allocation = np.vstack(
            [
                np.ones(4),
                positions[:, 1],
                -positions[:, 0],
                -prm.spin_directions * prm.k_m / prm.k_f,
            ]
        )
        self._mix = tuple(tuple(row) for row in np.linalg.inv(allocation).tolist())
        self._tan_tilt = math.tan(self.gains.max_tilt)
        self.reset()

    def reset(self) -> None:
        """Clear integrators, filters and the yaw set-point (taken from the next state)."""
        self._initialised = False
        self._vel_int = [0.0, 0.0, 0.0]
        self._rate_int = [0.0, 0.0, 0.0]
        self._vel_prev = (0.0, 0.0, 0.0)
        self._rate_prev = (0.0, 0.0, 0.0)
        self._vel_deriv = [0.0, 0.0, 0.0]
        self._rate_deriv = [0.0, 0.0, 0.0]
        self._filter_dt = -1.0
        self._vel_beta = 0.0
        self._rate_beta = 0.0
        self.yaw_setpoint = 0.0
        self._flags = [False] * 9
        #: last torque demanded of the mixer (N m, body frame), before any mixer reduction
        self.last_torque_setpoint_b: tuple[float, float, float] = (0.0, 0.0, 0.0)
        #: the most collective thrust the velocity loop may ask for, N (a land sequence
        #: lowers it after the first contact, :meth:`~landing_env.world.World.settle`);
        #: the rotors' own range bounds it too
        self.thrust_cap_n = math.inf
        #: the thrust direction (a world unit vector) the attitude loop aims the body z at in
        #: place of the velocity loop's (a land sequence levelling the drone on the deck);
        #: None: the velocity loop's
        self.thrust_axis_w: tuple[float, float, float] | None = None

    def preload_acceleration(self, acceleration_w: np.ndarray) -> None:
        """Start the horizontal velocity integrators at ``acceleration_w``'s horizontal part
        (m/s^2, W; a trim's), within their limit."""
        ax, ay = float(acceleration_w[0]), float(acceleration_w[1])
        norm = math.hypot(ax, ay)
        limit = self.gains.vel_i_limit_xy
        if norm > limit:
            ax, ay = ax * limit / norm, ay * limit / norm
        self._vel_int[0], self._vel_int[1] = ax, ay

    @property
    def velocity_integral_w(self) -> np.ndarray:
        """The velocity loop's integrators now (world x, y, z; m/s^2 of acceleration)."""
        return np.array(self._vel_int, dtype=float)

    def scale_thrust_model(self, factor: float) -> None:
        """Scale the thrust the controller expects of a rotor speed (``k_f``, and with it the
        rotors' thrust range) by ``factor``: what a hover-thrust estimator learns of rotors
        that give ``factor`` times the nominal thrust (PX4's ``MPC_USE_HTE``, ArduPilot's
        ``MOT_THST_HOVER`` learning)."""
        if not math.isfinite(factor) or factor <= 0.0:
            raise ValueError(f"factor must be a positive finite number, got {factor!r}")
        self._k_f *= factor
        self._f_min *= factor
        self._f_max *= factor

    @property
    def status(self) -> ControllerStatus:
        """The limits that acted in the last :meth:`update`."""
        return ControllerStatus(*self._flags)

    def update(self, state: DroneState, setpoint: VelocitySetpoint, dt: float) -> np.ndarray:
        """One control step of ``dt`` seconds; returns the 4 rotor speed commands (rad/s)."""
        return np.array(self.update_floats(state, setpoint, dt))

    def update_floats(
        self, state: DroneState, setpoint: VelocitySetpoint, dt: float
    ) -> list[float]:
        """:meth:`update` with the commands as a list of floats (the physics step's form)."""
        g = self.gains
        floats = state.floats
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = floats.rotation_wb
        vx, vy, vz = floats.velocity_w
        wx, wy, wz = floats.angular_velocity_b
        yaw = state.yaw
        if not self._initialised:
            self._initialised = True
            self.yaw_setpoint = yaw
            self._vel_prev = (vx, vy, vz)
            self._rate_prev = (wx, wy, wz)
        if dt != self._filter_dt:
            self._filter_dt = dt
            self._vel_beta = 1.0 - math.exp(-2.0 * math.pi * g.vel_d_cutoff_hz * dt)
            self._rate_beta = 1.0 - math.exp(-2.0 * math.pi * g.rate_d_cutoff_hz * dt)

        # ---- set-point limits, heading frame -> world
        sx, sy, sz = setpoint.velocity_h.tolist()
        yaw_rate = setpoint.yaw_rate
        sp_limited = False
        speed = math.hypot(sx, sy)
        if speed > g.max_horizontal_speed:
            scale = g.max_horizontal_speed / speed
            sx *= scale
            sy *= scale
            sp_limited = True
        if sz > g.max_climb_rate:
            sz = g.max_climb_rate
            sp_limited = True
        elif sz < -g.max_descent_rate:
            sz = -g.max_descent_rate
            sp_limited = True
        if yaw_rate > g.max_rate_yaw:
            yaw_rate = g.max_rate_yaw
            sp_limited = True
        elif yaw_rate < -g.max_rate_yaw:
            yaw_rate = -g.max_rate_yaw
            sp_limited = True
        cy = math.cos(yaw)
        sn = math.sin(yaw)
        ex = cy * sx - sn * sy - vx
        ey = sn * sx + cy * sy - vy
        ez = sz - vz

        # ---- velocity PID -> acceleration (derivative on measurement: no set-point kick)
        beta = self._vel_beta
        pvx, pvy, pvz = self._vel_prev
        dv = self._vel_deriv
        dv[0] += beta * ((vx - pvx) / dt - dv[0])
        dv[1] += beta * ((vy - pvy) / dt - dv[1])
        dv[2] += beta * ((vz - pvz) / dt - dv[2])
        self._vel_prev = (vx, vy, vz)
        vi = self._vel_int
        ax = g.vel_p_xy * ex + vi[0] - g.vel_d_xy * dv[0]
        ay = g.vel_p_xy * ey + vi[1] - g.vel_d_xy * dv[1]
        az = g.vel_p_z * ez + vi[2] - g.vel_d_z * dv[2]

        vert_limited = 0  # +1 limited from above, -1 from below
        if az > g.max_accel_up:
            az = g.max_accel_up
            vert_limited = 1
        elif az < -g.max_accel_down:
            az = -g.max_accel_down
            vert_limited = -1
        # Vertical first: the horizontal acceleration gets what the tilt limit and the
        # remaining thrust allow.
        lift = az + GRAVITY
        t_max = 4.0 * self._f_max
        t_min = 4.0 * self._f_min
        a_max = t_max / self._mass
        horizontal_room = min(
            lift * self._tan_tilt, math.sqrt(max(a_max * a_max - lift * lift, 0.0))
        )
        a_h = math.hypot(ax, ay)
        tilt_limited = a_h > horizontal_room
        if tilt_limited:
            scale = horizontal_room / a_h
            ax *= scale
            ay *= scale

        # ---- thrust vector -> collective thrust on the current body z, desired body z
        m = self._mass
        fx = m * ax
        fy = m * ay
        fz = m * lift
        thrust = fx * r02 + fy * r12 + fz * r22
        thrust_limited = 0
        if thrust > t_max:
            thrust = t_max
            thrust_limited = 1
        elif thrust < t_min:
            thrust = t_min
            thrust_limited = -1
        if thrust > self.thrust_cap_n:
            thrust = max(self.thrust_cap_n, t_min)
            thrust_limited = 1

        # Velocity integrators: conditional integration (no growth into an active limit).
        int_limited = False
        if not tilt_limited or ex * ax < 0.0:
            vi[0] += g.vel_i_xy * ex * dt
        if not tilt_limited or ey * ay < 0.0:
            vi[1] += g.vel_i_xy * ey * dt
        pushing_up = vert_limited > 0 or thrust_limited > 0
        pushing_down = vert_limited < 0 or thrust_limited < 0
        if not ((pushing_up and ez > 0.0) or (pushing_down and ez < 0.0)):
            vi[2] += g.vel_i_z * ez * dt
        i_xy = math.hypot(vi[0], vi[1])
        if i_xy > g.vel_i_limit_xy:
            vi[0] *= g.vel_i_limit_xy / i_xy
            vi[1] *= g.vel_i_limit_xy / i_xy
            int_limited = True
        if abs(vi[2]) > g.vel_i_limit_z:
            vi[2] = math.copysign(g.vel_i_limit_z, vi[2])
            int_limited = True

        # ---- attitude: tilt error (body z -> desired body z) and heading error
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        dzx = fx / norm
        dzy = fy / norm
        dzz = fz / norm
        if self.thrust_axis_w is not None:
            dzx, dzy, dzz = self.thrust_axis_w
        cx = r12 * dzz - r22 * dzy  # z_B x z_d, world frame
        cyw = r22 * dzx - r02 * dzz
        cz = r02 * dzy - r12 * dzx
        sin_tilt = math.sqrt(cx * cx + cyw * cyw + cz * cz)
        cos_tilt = r02 * dzx + r12 * dzy + r22 * dzz
        tilt_err = math.atan2(sin_tilt, cos_tilt)
        if sin_tilt > 1e-9:
            k = g.att_p_rp * tilt_err / sin_tilt
            # rotation axis in the body frame (R^T c); its body-z part is zero by construction
            qx = k * (r00 * cx + r10 * cyw + r20 * cz)
            qy = k * (r01 * cx + r11 * cyw + r21 * cz)
        elif cos_tilt < 0.0:  # upside down: any horizontal axis will do
            qx = g.att_p_rp * math.pi
            qy = 0.0
        else:
            qx = 0.0
            qy = 0.0

        yaw_sp = self.yaw_setpoint + yaw_rate * dt
        yaw_err = math.remainder(yaw_sp - yaw, math.tau)
        if abs(yaw_err) > g.max_yaw_error:
            yaw_err = math.copysign(g.max_yaw_error, yaw_err)
            sp_limited = True
        self.yaw_setpoint = math.remainder(yaw + yaw_err, math.tau)
        # Yaw about world z (feedback + feed-forward), expressed in the body frame.
        yaw_dot = g.att_p_yaw * yaw_err + yaw_rate
        px_sp = qx + yaw_dot * r20
        py_sp = qy + yaw_dot * r21
        pz_sp = yaw_dot * r22

        rate_limited = False
        lim = g.max_rate_rp
        if px_sp > lim:
            px_sp, rate_limited = lim, True
        elif px_sp < -lim:
            px_sp, rate_limited = -lim, True
        if py_sp > lim:
            py_sp, rate_limited = lim, True
        elif py_sp < -lim:
            py_sp, rate_limited = -lim, True
        lim = g.max_rate_yaw
        if pz_sp > lim:
            pz_sp, rate_limited = lim, True
        elif pz_sp < -lim:
            pz_sp, rate_limited = -lim, True

        # ---- body-rate PID -> angular acceleration -> torque
        beta = self._rate_beta
        pwx, pwy, pwz = self._rate_prev
        dw = self._rate_deriv
        dw[0] += beta * ((wx - pwx) / dt - dw[0])
        dw[1] += beta * ((wy - pwy) / dt - dw[1])
        dw[2] += beta * ((wz - pwz) / dt - dw[2])
        self._rate_prev = (wx, wy, wz)
        erx = px_sp - wx
        ery = py_sp - wy
        erz = pz_sp - wz
        ri = self._rate_int
        alpha_x = g.rate_p_rp * erx + ri[0] - g.rate_d_rp * dw[0]
        alpha_y = g.rate_p_rp * ery + ri[1] - g.rate_d_rp * dw[1]
        alpha_z = g.rate_p_yaw * erz + ri[2] - g.rate_d_yaw * dw[2]
        jx, jy, jz = self._inertia
        # tau = J alpha + omega x (J omega)
        tau_x = jx * alpha_x + (jz - jy) * wy * wz
        tau_y = jy * alpha_y + (jx - jz) * wz * wx
        tau_z = jz * alpha_z + (jy - jx) * wx * wy
        self.last_torque_setpoint_b = (tau_x, tau_y, tau_z)

        # ---- mixer with priorities: roll/pitch, then collective thrust, then yaw
        # (written out per rotor: four named floats are much faster than lists here)
        f_min = self._f_min
        f_max = self._f_max
        (a0, b0, c0, d0), (a1, b1, c1, d1), (a2, b2, c2, d2), (a3, b3, c3, d3) = self._mix
        rp0 = b0 * tau_x + c0 * tau_y
        rp1 = b1 * tau_x + c1 * tau_y
        rp2 = b2 * tau_x + c2 * tau_y
        rp3 = b3 * tau_x + c3 * tau_y
        span = max(rp0, rp1, rp2, rp3) - min(rp0, rp1, rp2, rp3)
        room = f_max - f_min
        rp_reduced = span > room
        if rp_reduced:
            scale = room / span
            rp0 *= scale
            rp1 *= scale
            rp2 *= scale
            rp3 *= scale
        f0 = a0 * thrust + rp0
        f1 = a1 * thrust + rp1
        f2 = a2 * thrust + rp2
        f3 = a3 * thrust + rp3
        low = min(f0, f1, f2, f3)
        high = max(f0, f1, f2, f3)
        shift = 0.0
        if low < f_min:
            shift = f_min - low
        elif high > f_max:
            shift = f_max - high
        thrust_shifted = shift != 0.0
        if thrust_shifted:
            f0 += shift
            f1 += shift
            f2 += shift
            f3 += shift
        # per rotor: thrust without yaw, and the thrust change the full yaw torque asks for
        rotors = ((f0, d0 * tau_z), (f1, d1 * tau_z), (f2, d2 * tau_z), (f3, d3 * tau_z))
        # s: the largest share of the yaw torque (0..1) that keeps every rotor in range
        s = 1.0
        for fi, yi in rotors:
            if yi != 0.0:
                limit = ((f_max if yi > 0.0 else f_min) - fi) / yi
                if limit < s:
                    s = limit
        if s < 0.0:
            s = 0.0
        yaw_reduced = s < 1.0

        # Rate integrators: frozen on an axis whose torque the mixer could not deliver.
        if not rp_reduced:
            ri[0] += g.rate_i_rp * erx * dt
            ri[1] += g.rate_i_rp * ery * dt
        if not yaw_reduced:
            ri[2] += g.rate_i_yaw * erz * dt
        for i, limit in ((0, g.rate_i_limit_rp), (1, g.rate_i_limit_rp), (2, g.rate_i_limit_yaw)):
            if abs(ri[i]) > limit:
                ri[i] = math.copysign(limit, ri[i])
                int_limited = True

        k_f = self._k_f
        omega_min = self._omega_min
        omega_max = self._omega_max
        omegas = []
        for fi, yi in rotors:
            w = math.sqrt(max(fi + s * yi, 0.0) / k_f)
            # Guard against rounding only: f is already within [f_min, f_max].
            omegas.append(omega_min if w < omega_min else omega_max if w > omega_max else w)

        self._flags = [
            sp_limited,
            vert_limited != 0,
            tilt_limited,
            thrust_limited != 0,
            int_limited,
            rate_limited,
            rp_reduced,
            thrust_shifted,
            yaw_reduced,
        ]
        return omegas
