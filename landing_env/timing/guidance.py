"""The deck-relative guidance that the timing task and the scripted policies fly.

:class:`DeckGuidance` turns the *observation* (the estimated deck pose and the ToF ranges, never
the truth) into velocity set-points: hold centred over the tag at a height, or fly the final
descent to touchdown.  ``DeckLandingTiming-v0`` holds and descends with it, and the
``align-descend`` policy of ``DeckLanding-v0`` flies its approach and descent with the same
gains.

Two laws, chosen by ``GuidanceGains.track_deck``:

* off (the bench default): proportional servoing on the camera-frame tag offset and range,
  as the papers' bench needs (a deck that heaves centimetres, no wind);
* on (the ship scenarios): the guidance flies **in the deck's frame**.

  - A constant-velocity (or constant-acceleration, ``tracker_model``) Kalman filter per
    world axis (:class:`DeckTracker`) tracks where the deck is and how fast it moves, from
    the tag seen by a *level* camera (the drone's lean removed) and, with the tag lost, the
    ToF ranges, plus the drone's own navigation estimate (:class:`OwnState`: the autopilot's
    position, velocity and attitude, as PX4's EKF2 gives them to a companion computer).
  - The set-point is the estimated deck velocity (feed-forward; with the acceleration model,
    carried ``deck_lead_s`` ahead to meet the velocity loop's lag) plus a proportional
    correction of the deck-relative position, so the drone holds station on a deck that
    surges, sways and heaves without the lag of a proportional law; the velocity loop's
    integrator (the PX4-style cascade of :mod:`landing_env.physics.controller`) rejects the
    mean wind.
  - The camera, not the body, is aimed at the tag: a drone leaning into the wind looks
    downwind, so it stands upwind of the tag by the height times its (low-passed) lean.
  - The final descent's speed is *relative* to the deck (the deck's vertical velocity minus
    a range-scheduled descent speed), so the drone meets a heaving deck at about
    ``touchdown_speed``.  It slows to a stop while the tag nears the image edge
    (``view_half_tan``) and climbs back while the tag is lost above ``blind_range_m``; with
    ``lost_deck = "search"`` it goes around when the deck itself is lost (neither tag nor
    range for the tracker's coast): a climb over the deck's last height and track.

  This is the structure of ship-landing guidance that tracks the deck rather than the sea
  (Marconi, Isidori & Serrani 2002, *Automatica* 38:21-32: vertical landing on an
  oscillating platform with an internal model of its motion; Herissé et al. 2012, *IEEE
  T-RO* 28:77-89: landing on a moving platform from the relative motion the camera sees).
  The motors are cut at the first contact (``World.settle``), as a land detector does.

The final descent's speed has two profiles (``GuidanceGains.descent_profile``): ``range``
schedules it on the range (fast high up, ``touchdown_speed`` near the deck), and ``timed``
makes the height over the deck track a reference (:func:`timed_descent_reference`) that reaches
the deck ``descent_time_s`` after the commit, its rate fed forward by the velocity loop's lag
and its error corrected, so that the feet touch a fixed time after the commit (1.30 +- 0.06 s
on the bench for 1.2 s, against 1.85 +- 0.35 s on the range schedule, whose last centimetres
the ground effect slows by varying amounts): the time-to-contact guidance of the landing
literature (Lee 1976, *Perception* 5:437-459, tau theory; Kendoul 2014, *Int. J. Robotics
Research* 33:237-267, time-to-contact landing of rotorcraft), which fixes the time a timing
policy must predict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.frames import (
    camera_to_heading_xy,
    euler_zyx_from_matrix,
    level_from_body,
    levelled_deck_pose,
)
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.physics.controller import VelocitySetpoint

#: the final descent's profiles (:attr:`GuidanceGains.descent_profile`)
DESCENT_PROFILES = ("range", "timed")
#: the deck tracker's motion models (:attr:`GuidanceGains.tracker_model`)
TRACKER_MODELS = ("velocity", "acceleration")
#: what the deck-frame guidance does once the deck's height track is lost
#: (:attr:`GuidanceGains.lost_deck`)
LOST_DECK_ACTIONS = ("descend", "search")


def timed_descent_reference(
    t_s: float, start_m: float, duration_s: float, end_speed: float, end_m: float = 0.0
) -> tuple[float, float]:
    """The timed descent's reference height over the deck and its rate at ``t_s`` after the
    commit: a cubic from ``start_m`` at rest to ``end_m`` at ``-end_speed`` after
    ``duration_s`` (Hermite end conditions: the drone leaves the hold without a jerk in its
    velocity set-point and meets the deck at the touchdown speed), then on down at that speed.
    """
    if t_s >= duration_s:
        return end_m - end_speed * (t_s - duration_s), -end_speed
    s = max(t_s, 0.0) / duration_s
    drop = start_m - end_m
    # Hermite basis: h00 = 2s^3 - 3s^2 + 1 (start height), h11 = s^3 - s^2 (end slope)
    height = end_m + drop * (2 * s**3 - 3 * s**2 + 1) - end_speed * duration_s * (s**3 - s**2)
    rate = (drop * (6 * s**2 - 6 * s) - end_speed * duration_s * (3 * s**2 - 2 * s)) / duration_s
    return height, rate


@dataclass
class GuidanceGains:
    """Gains and limits of the deck-relative guidance (hold, approach and final descent)."""

    #: horizontal velocity per metre of horizontal error, 1/s
    k_xy: float = 0.8
    max_horizontal_speed: float = 1.0
    #: yaw rate per radian of tag yaw, 1/s
    k_yaw: float = 0.8
    #: vertical velocity per metre of height error while holding, 1/s
    k_z: float = 1.2
    max_vertical_speed: float = 0.8
    #: final descent: speed = descent_gain * range, between touchdown_speed and descent_speed
    descent_gain: float = 1.5
    descent_speed: float = 0.8
    touchdown_speed: float = 0.25
    #: below this range the tag no longer fits the image: descend on the ToF alone, metres
    blind_range_m: float = 0.3
    #: the final descent's profile: ``"range"`` (the speed above, scheduled on the range: the
    #: last centimetres, cushioned by the ground effect, take a varying time, so the contact
    #: comes 1.1-2.6 s after the commit) or ``"timed"`` (the height over the deck tracks a
    #: reference that meets the deck ``descent_time_s`` after the commit at ``touchdown_speed``
    #: (:func:`timed_descent_reference`): the contact time is fixed, so a timing policy has to
    #: predict the deck that far ahead and no further)
    descent_profile: str = "range"
    descent_time_s: float = 1.2
    #: the timed profile's correction of the height error, 1/s
    descent_track_gain: float = 3.0
    #: the timed profile's reference rate is fed forward this early: the lag of the velocity
    #: loop (its vertical P gain, ``controller.vel_p_z`` = 5/s, is a 0.2 s time constant), s
    descent_lead_s: float = 0.2
    #: the camera's range over the deck when the feet touch it (the timed reference ends
    #: there): the feet's bottoms are 0.080 m below the centre of mass and the camera 0.030 m
    #: (assets/quadrotor.urdf, quadrotor.yaml), metres
    contact_range_m: float = 0.05
    #: aligned when the horizontal error is below this plus ``align_tolerance_per_m`` * range
    align_tolerance_m: float = 0.08
    align_tolerance_per_m: float = 0.08
    #: fly in the deck's frame (deck-velocity feed-forward from :class:`DeckTracker`, relative
    #: descent speed); needs the drone's navigation estimate (:class:`OwnState`)
    track_deck: bool = False
    #: the tracker's process noise: the deck's acceleration spectral density, m^2/s^3 (the
    #: ship decks' vertical acceleration is 0.3-0.8 m/s^2 RMS at 0.1-0.2 Hz)
    tracker_accel_psd: float = 0.5
    #: the tracker's measurement noise (1 sigma) of the deck position, metres
    tracker_position_sigma_m: float = 0.02
    #: without any measurement for this long the tracker is dropped (the plain law flies)
    tracker_coast_s: float = 1.5
    #: time constant of the low-pass on the drone's lean (for aiming the camera), seconds
    lean_filter_s: float = 1.0
    #: in the deck-frame descent, the tag unseen this long above ``blind_range_m`` pauses the
    #: descent until it is seen again, seconds
    lost_tag_pause_s: float = 0.3
    #: ... and the drone climbs at this speed relative to the deck meanwhile, m/s, up to
    #: ``max_search_range_m`` above it
    lost_tag_climb_speed: float = 0.2
    max_search_range_m: float = 2.5
    #: touchdown when the lean allows: below ``flare_range_m`` the deck-frame descent holds
    #: its height over the deck while the drone leans more than ``max_touchdown_lean_deg``
    #: from the vertical (a gust), for at most ``max_flare_wait_s``; 0 turns it off.  On
    #: the ship decks 5 % of the touchdowns below 18 deg tipped over or bounced when the
    #: motors stopped, 16 % at 18-22 deg and 39 % above 22 deg (README "Landing on the ship")
    flare_range_m: float = 0.0
    max_touchdown_lean_deg: float = 18.0
    max_flare_wait_s: float = 3.0
    #: in the deck-frame descent, the tag must stay inside the view: the descent slows to a
    #: stop as the tag's farthest corner comes within ``view_margin`` (tangent of the angle)
    #: of this half field of view (tangent: half the image width over the focal length,
    #: 256 / 458.5 for the default camera), and climbs beyond it; 0 turns the gate off
    view_half_tan: float = 0.0
    #: the gate's half field of view is the camera's, as its calibration gives it (the
    #: narrowest half view, :meth:`~estimation.camera_model.CameraIntrinsics.half_view_tan`;
    #: the timing task sets ``view_half_tan`` from it), not the number above: a lens change
    #: cannot leave the gate behind
    view_from_camera: bool = False
    view_margin: float = 0.08
    #: half the tag's side, metres (for the gate: the corners, not the centre, must fit)
    tag_half_size_m: float = 0.15
    #: a coasting track's velocity decays with this time constant (the deck's horizontal
    #: motion is oscillatory: holding a stale velocity drifts away), seconds
    tracker_velocity_decay_s: float = 1.0
    #: the tracker's motion model: ``"velocity"`` (constant velocity, white-noise
    #: acceleration of ``tracker_accel_psd``) or ``"acceleration"`` (constant acceleration,
    #: white-noise jerk of ``tracker_jerk_psd``: Bar-Shalom, Li & Kirubarajan 2001, Sec.
    #: 6.2.3), whose acceleration estimate is fed forward ``deck_lead_s`` ahead
    tracker_model: str = "velocity"
    #: the deck's jerk spectral density for the ``acceleration`` model, m^2/s^5 (a heave of
    #: 0.5-1 m/s^2 at 0.1-0.15 Hz: a jerk of 0.3-1 m/s^3)
    tracker_jerk_psd: float = 2.0
    #: the set-point carries the deck's velocity this far ahead (its velocity plus the tracked
    #: acceleration times this): the velocity loop lags its set-point by about its time
    #: constant (``controller.vel_p_z`` = 5/s: 0.2 s), so a set-point of the present deck
    #: velocity meets an accelerating deck late; 0 turns it off, seconds
    deck_lead_s: float = 0.0
    #: what the deck-frame guidance does once neither the tag nor a ToF range has measured
    #: the deck for ``tracker_coast_s`` (the height track dropped) while the drone was above
    #: ``blind_range_m``: ``"descend"`` flies the plain law on (nothing seen: straight down
    #: at the last range's speed, which off the pad's edge falls past the deck) or
    #: ``"search"``: the go-around of ship landing (a pilot who loses the visual reference
    #: on the approach aborts and climbs; CAP 437, *Standards for offshore helicopter
    #: landing areas*, and the US Navy's NATOPS LHA/LHD procedures): climb at
    #: ``lost_tag_climb_speed`` to ``max_search_range_m`` over the deck's last tracked height,
    #: re-centred (the camera aimed) on its coasting horizontal track, until a measurement
    #: restarts the track and the descent
    lost_deck: str = "descend"

    def __post_init__(self) -> None:
        for name in (
            "k_xy",
            "max_horizontal_speed",
            "k_z",
            "max_vertical_speed",
            "descent_gain",
            "descent_speed",
            "touchdown_speed",
        ):
            require_range(name, getattr(self, name), 0.0, low_inclusive=False)
        require_range("lost_tag_climb_speed", self.lost_tag_climb_speed, 0.0)
        require_choice("descent_profile", self.descent_profile, DESCENT_PROFILES)
        require_choice("tracker_model", self.tracker_model, TRACKER_MODELS)
        require_choice("lost_deck", self.lost_deck, LOST_DECK_ACTIONS)
        require_range("tracker_jerk_psd", self.tracker_jerk_psd, 0.0, low_inclusive=False)
        require_range("deck_lead_s", self.deck_lead_s, 0.0, 2.0)
        require_range("descent_time_s", self.descent_time_s, 0.2, 10.0)
        require_range("descent_track_gain", self.descent_track_gain, 0.0, 20.0)
        require_range("descent_lead_s", self.descent_lead_s, 0.0, 2.0)
        require_range("contact_range_m", self.contact_range_m, 0.0, 0.5)
        require_range("max_search_range_m", self.max_search_range_m, 0.0, low_inclusive=False)
        require_range("flare_range_m", self.flare_range_m, 0.0, 3.0)
        require_range("max_touchdown_lean_deg", self.max_touchdown_lean_deg, 0.0, 90.0)
        require_range("max_flare_wait_s", self.max_flare_wait_s, 0.0)
        require_range("view_half_tan", self.view_half_tan, 0.0)
        require_range("view_margin", self.view_margin, 0.0)
        require_range("tag_half_size_m", self.tag_half_size_m, 0.0)
        for name in (
            "k_yaw",
            "blind_range_m",
            "align_tolerance_m",
            "align_tolerance_per_m",
        ):
            require_range(name, getattr(self, name), 0.0)
        for name in (
            "tracker_accel_psd",
            "tracker_position_sigma_m",
            "tracker_coast_s",
            "lean_filter_s",
            "lost_tag_pause_s",
            "tracker_velocity_decay_s",
        ):
            require_range(name, getattr(self, name), 0.0, low_inclusive=False)
        if self.touchdown_speed > self.descent_speed:
            raise ConfigError(
                "touchdown_speed",
                f"{self.touchdown_speed} must not exceed descent_speed = {self.descent_speed}",
            )


@dataclass(frozen=True)
class OwnState:
    """The drone's own navigation estimate, as the autopilot gives it to the guidance (PX4's
    EKF2 local position: position and velocity in a local level frame, attitude); in the
    simulation the true state stands in for it, as for the levelled history."""

    position_w: np.ndarray
    velocity_w: np.ndarray
    rotation_wb: np.ndarray

    @property
    def yaw(self) -> float:
        return float(euler_zyx_from_matrix(self.rotation_wb)[2])


class DeckTracker:
    """Where the deck (the tag centre) is and how fast it moves, in the world frame.

    One constant-velocity Kalman filter per axis (white-noise acceleration of spectral density
    ``accel_psd``; Bar-Shalom, Li & Kirubarajan 2001, *Estimation with Applications to Tracking and
    Navigation*, Sec. 6.2.2), or with ``model = "acceleration"`` a constant-acceleration one
    (white-noise jerk of density ``jerk_psd``, Sec. 6.2.3).  A measurement is the drone's position
    plus the tag offset seen by a level camera (the deck pose rotated by the drone's roll and pitch,
    then by its yaw); with the tag lost, the ToF ranges (their mean along the body axis, times the
    cosine of the drone's tilt) still measure the height.  The vertical position tracked is the
    drone's centre's height minus the camera's range, so that ``range = own z - tracked z``.
    Without measurements a track coasts with its velocity decaying (``velocity_decay_s``): the deck
    of a ship hove-to oscillates about a fixed mean, so the last position is the best guess of where
    to look again; the height track is dropped after ``coast_s`` without a range."""

    def __init__(
        self,
        accel_psd: float,
        position_sigma_m: float,
        coast_s: float,
        velocity_decay_s: float = math.inf,
        model: str = "velocity",
        jerk_psd: float = 2.0,
    ) -> None:
        require_choice("tracker_model", model, TRACKER_MODELS)
        self.accel_psd = accel_psd
        self.jerk_psd = jerk_psd
        self.r = position_sigma_m**2
        self.coast_s = coast_s
        self.velocity_decay_s = velocity_decay_s
        self.model = model
        #: states per axis: position, velocity (and acceleration)
        self.order = 3 if model == "acceleration" else 2
        self.reset()

    def reset(self) -> None:
        #: per axis (x, y, z): state [position, velocity(, acceleration)] and its covariance
        self.state = np.zeros((3, self.order))
        self.cov = np.zeros((3, self.order, self.order))
        self.started = np.zeros(3, dtype=bool)
        self.unseen_s = np.full(3, math.inf)
        #: the deck's height when its track was last measured (None: never measured)
        self.last_height_w: float | None = None

    @property
    def valid(self) -> bool:
        """The height has a track (the horizontal axes may have lost theirs)."""
        return bool(self.started[2])

    @property
    def horizontal_valid(self) -> bool:
        return bool(self.started[:2].all())

    @property
    def position_w(self) -> np.ndarray:
        return self.state[:, 0].copy()

    @property
    def velocity_w(self) -> np.ndarray:
        return self.state[:, 1].copy()

    @property
    def acceleration_w(self) -> np.ndarray:
        """The tracked acceleration (zeros for the constant-velocity model)."""
        return self.state[:, 2].copy() if self.order == 3 else np.zeros(3)

    def update(self, observation: dict[str, np.ndarray], own: OwnState, dt: float) -> None:
        """Predict by ``dt`` and correct with whatever this observation measures."""
        self._predict(dt)
        measured = self.measure(observation, own)
        for axis in range(3):
            value = measured[axis]
            if math.isfinite(value):
                self._correct(axis, value)
                self.unseen_s[axis] = 0.0
                if axis == 2:
                    self.last_height_w = float(self.state[2, 0])
            elif axis == 2 and self.unseen_s[axis] > self.coast_s:
                # no range for that long: the height track is dropped (the horizontal ones
                # coast on: a hove-to ship's deck oscillates about a fixed mean position)
                self.started[axis] = False
            else:
                # coasting: let the velocity (and acceleration) decay (an oscillating
                # deck's stale velocity would carry the track away)
                self.state[axis, 1:] *= math.exp(-dt / self.velocity_decay_s)

    @staticmethod
    def measure(observation: dict[str, np.ndarray], own: OwnState) -> np.ndarray:
        """The deck position in the world this observation gives (NaN where it gives none)."""
        measured = np.full(3, math.nan)
        yaw = own.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        if observation["deck_pose_valid"][0]:
            level = levelled_deck_pose(
                observation["deck_pose"].astype(float), level_from_body(own.rotation_wb)
            )
            forward, left = camera_to_heading_xy(level[:2])
            measured[0] = own.position_w[0] + c * forward - s * left
            measured[1] = own.position_w[1] + s * forward + c * left
            measured[2] = own.position_w[2] - float(level[2])
            return measured
        valid = observation["tof_valid"].astype(bool)
        if valid.any():
            cos_tilt = float(np.clip(own.rotation_wb[2, 2], 0.5, 1.0))
            height = float(np.mean(observation["tof_range"][valid])) * cos_tilt
            measured[2] = own.position_w[2] - height
        return measured

    def _predict(self, dt: float) -> None:
        if self.order == 3:
            f = np.array([[1.0, dt, dt**2 / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
            q = self.jerk_psd * np.array(
                [
                    [dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0],
                    [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0],
                    [dt**3 / 6.0, dt**2 / 2.0, dt],
                ]
            )
        else:
            f = np.array([[1.0, dt], [0.0, 1.0]])
            q = self.accel_psd * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        for axis in range(3):
            if self.started[axis]:
                self.state[axis] = f @ self.state[axis]
                self.cov[axis] = f @ self.cov[axis] @ f.T + q
        self.unseen_s += dt

    def _correct(self, axis: int, value: float) -> None:
        if not self.started[axis]:
            self.state[axis] = 0.0
            self.state[axis, 0] = value
            # a deck moving at up to ~2 m/s and accelerating at up to ~1 m/s^2: start with
            # those uncertainties
            self.cov[axis] = np.diag([self.r, 4.0, 1.0][: self.order])
            self.started[axis] = True
            return
        p = self.cov[axis]
        innovation = value - self.state[axis, 0]
        gain = p[:, 0] / (p[0, 0] + self.r)
        self.state[axis] = self.state[axis] + gain * innovation
        self.cov[axis] = p - np.outer(gain, p[0, :])


class DeckGuidance:
    """Velocity set-points from the *observation* (estimated deck pose and ToF), never the truth.

    The deck pose is the tag in the camera frame (x right, y down the image, z along the
    optical axis, image top = nose); :func:`~estimation.frames.camera_to_heading_xy` maps its
    offset to the heading frame.  Set-points are in the heading frame (x forward, y left,
    z up), m/s, rad/s.
    """

    def __init__(self, gains: GuidanceGains | None = None, dt: float = 0.05) -> None:
        self.gains = gains or GuidanceGains()
        self.dt = dt
        g = self.gains
        self.tracker = DeckTracker(
            g.tracker_accel_psd,
            g.tracker_position_sigma_m,
            g.tracker_coast_s,
            g.tracker_velocity_decay_s,
            g.tracker_model,
            g.tracker_jerk_psd,
        )
        self._last_range = math.inf
        self._lean = np.zeros(2)
        self._lean_started = False
        self._tag_unseen_s = math.inf
        self._flare_wait_s = 0.0
        #: searching for the lost deck (``lost_deck = "search"``)
        self._search_on = False
        #: the timed descent's clock and start height (None: not descending)
        self._descent_clock_s: float | None = None
        self._descent_start_m = 0.0
        #: the timed descent's duration (``plan_descent``; the gains' by default)
        self.descent_time_s = self.gains.descent_time_s

    def reset(self) -> None:
        self._last_range = math.inf
        self._lean = np.zeros(2)
        self._lean_started = False
        self._tag_unseen_s = math.inf
        self._flare_wait_s = 0.0
        self._descent_clock_s = None
        self._search_on = False
        self.descent_time_s = self.gains.descent_time_s
        self.tracker.reset()

    def plan_descent(self, duration_s: float | None = None) -> None:
        """Give the next timed descent this duration (None: ``gains.descent_time_s``), e.g. to
        meet the deck at a chosen moment; it is kept between 0.2 and 10 s."""
        duration = self.gains.descent_time_s if duration_s is None else duration_s
        if not math.isfinite(duration):
            duration = self.gains.descent_time_s
        self.descent_time_s = float(np.clip(duration, 0.2, 10.0))

    def observe(self, observation: dict[str, np.ndarray], own: OwnState | None) -> None:
        """Feed one control period's observation to the deck tracker (``track_deck`` only;
        call it once per control period, before :meth:`hold` or :meth:`descend`)."""
        if self.gains.track_deck and own is not None:
            self.tracker.update(observation, own, self.dt)
            seen = bool(observation["deck_pose_valid"][0])
            self._tag_unseen_s = 0.0 if seen else self._tag_unseen_s + self.dt
            # the lean (the body z axis' horizontal slope), low-passed: the camera looks
            # that much downwind of the point under the drone
            z_b = own.rotation_wb[:, 2]
            lean = z_b[:2] / max(float(z_b[2]), 0.5)
            if not self._lean_started:
                self._lean, self._lean_started = lean, True
            alpha = self.dt / (self.gains.lean_filter_s + self.dt)
            self._lean = self._lean + alpha * (lean - self._lean)

    def _tracking(self, own: OwnState | None) -> bool:
        return self.gains.track_deck and own is not None and self.tracker.valid

    def _deck_frame_setpoint(
        self, own: OwnState, vertical_h: float, yaw_rate: float
    ) -> VelocitySetpoint:
        """Deck velocity + proportional correction of the horizontal offset and the given
        relative vertical speed, turned into the heading frame."""
        g = self.gains
        # the deck's velocity ``deck_lead_s`` ahead: the velocity loop's lag is met early
        deck_v = self.tracker.velocity_w + g.deck_lead_s * self.tracker.acceleration_w
        if not self.tracker.valid:
            deck_v[2] = 0.0  # the height track is lost (searching): no stale heave rate
        relative = np.zeros(2)
        if not self.tracker.horizontal_valid:
            deck_v[:2] = 0.0
        else:
            # aim the camera, not the body, at the tag: stand upwind of it by the height
            # times the lean, so that the tag stays near the image centre
            # (the aim point moves with the deck and, as the height changes, along the lean)
            aim = self.tracker.position_w[:2] + max(self._last_range, 0.0) * self._lean
            offset = aim - own.position_w[:2]
            relative = g.k_xy * offset + vertical_h * self._lean
            speed = float(np.hypot(*relative))
            if speed > g.max_horizontal_speed:
                relative *= g.max_horizontal_speed / speed
        v_w = np.array([deck_v[0] + relative[0], deck_v[1] + relative[1], deck_v[2] + vertical_h])
        yaw = own.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        v_h = np.array([c * v_w[0] + s * v_w[1], -s * v_w[0] + c * v_w[1], v_w[2]])
        return VelocitySetpoint(v_h, yaw_rate)

    def _searching(self, own: OwnState | None) -> bool:
        """``lost_deck = "search"`` applies: the deck's height track, once held, is lost while
        the drone was last above ``blind_range_m``."""
        g = self.gains
        if (
            not g.track_deck
            or g.lost_deck != "search"
            or own is None
            or self.tracker.valid
            or self.tracker.last_height_w is None
        ):
            self._search_on = False
        elif self._last_range > g.blind_range_m:
            self._search_on = True  # and it goes on until the track is found again
        return self._search_on

    def _search(self, own: OwnState) -> VelocitySetpoint:
        """The go-around with the deck lost (see ``GuidanceGains.lost_deck``): climb at
        ``lost_tag_climb_speed`` to ``max_search_range_m`` over the deck's last tracked
        height, over its coasting horizontal track; a timed descent starts again once the
        deck is found."""
        g = self.gains
        self._descent_clock_s = None
        assert self.tracker.last_height_w is not None
        above = float(own.position_w[2]) - self.tracker.last_height_w
        self._last_range = above
        climb = g.lost_tag_climb_speed if above < g.max_search_range_m else 0.0
        return self._deck_frame_setpoint(own, climb, 0.0)

    def tracked_range_m(self, own: OwnState) -> float:
        """The camera's height above the deck from the tracker (NaN without a track)."""
        if not self.tracker.valid:
            return math.nan
        return float(own.position_w[2] - self.tracker.position_w[2])

    def range_m(self, observation: dict[str, np.ndarray]) -> float:
        """Camera height above the deck: the mean of the valid ToF ranges, else the tag's z.

        The four sensors sit symmetrically about the camera, so on a tilted plane their mean
        is the range at the centre.  NaN when neither is available.
        """
        valid = observation["tof_valid"].astype(bool)
        if valid.all():
            return float(np.mean(observation["tof_range"]))
        if observation["deck_pose_valid"][0]:
            return float(observation["deck_pose"][2])
        if valid.any():
            return float(np.mean(observation["tof_range"][valid]))
        return math.nan

    def horizontal_error(self, observation: dict[str, np.ndarray]) -> tuple[float, float] | None:
        """(forward, left) offset of the tag centre from the camera, metres; None if unseen."""
        if not observation["deck_pose_valid"][0]:
            return None
        forward, left = camera_to_heading_xy(observation["deck_pose"][:2])
        return float(forward), float(left)

    def aligned(self, observation: dict[str, np.ndarray]) -> bool:
        """The tag is seen and the drone is centred over it within the tolerance."""
        error = self.horizontal_error(observation)
        if error is None:
            return False
        height = self.range_m(observation)
        g = self.gains
        tolerance = g.align_tolerance_m + g.align_tolerance_per_m * max(height, 0.0)
        return math.hypot(*error) < tolerance

    def _centre(self, observation: dict[str, np.ndarray]) -> tuple[float, float, float]:
        """Horizontal velocity and yaw rate that centre the drone over the tag."""
        error = self.horizontal_error(observation)
        if error is None:
            return 0.0, 0.0, 0.0
        g = self.gains
        vx, vy = g.k_xy * error[0], g.k_xy * error[1]
        speed = math.hypot(vx, vy)
        if speed > g.max_horizontal_speed:
            vx, vy = vx * g.max_horizontal_speed / speed, vy * g.max_horizontal_speed / speed
        return vx, vy, self._yaw_rate(observation)

    def _descent_speed(self, height: float, progress: float = 1.0) -> float:
        """The final descent's speed (down, relative to the deck) at ``height``: the range
        schedule, or the timed profile's reference rate plus the correction of its height
        error (its clock runs at ``progress`` of real time: 0 while a gate holds the descent;
        a climb restarts it from where the drone then is)."""
        g = self.gains
        if g.descent_profile == "range" or not math.isfinite(height):
            return float(np.clip(g.descent_gain * height, g.touchdown_speed, g.descent_speed))
        if self._descent_clock_s is None or progress < 0.0:
            self._descent_clock_s = 0.0
            self._descent_start_m = max(height, g.contact_range_m)
        reference, _ = timed_descent_reference(
            self._descent_clock_s,
            self._descent_start_m,
            self.descent_time_s,
            g.touchdown_speed,
            g.contact_range_m,
        )
        # the reference's rate is fed forward ``descent_lead_s`` early: the velocity loop lags
        # its set-point by about that much
        _, rate = timed_descent_reference(
            self._descent_clock_s + g.descent_lead_s,
            self._descent_start_m,
            self.descent_time_s,
            g.touchdown_speed,
            g.contact_range_m,
        )
        self._descent_clock_s += self.dt * float(np.clip(progress, 0.0, 1.0))
        speed = -rate + g.descent_track_gain * (height - reference)
        return float(np.clip(speed, 0.0, g.max_vertical_speed))

    def _view_factor(self, observation: dict[str, np.ndarray]) -> float:
        """1 while the tag sits well inside the image, falling to 0 at ``view_margin`` from
        its edge and to -1 (climb) at the edge: descending brings the tag's corners outwards,
        so the descent waits for the centring to bring the tag in first."""
        g = self.gains
        x, y, z = (float(v) for v in observation["deck_pose"][:3])
        if z <= 0.0:
            return 0.0
        extent = max(abs(x), abs(y)) / z + g.tag_half_size_m / z
        room = g.view_half_tan - extent
        if room >= 2.0 * g.view_margin:
            return 1.0
        return float(np.clip((room - g.view_margin) / g.view_margin, -1.0, 1.0))

    def _yaw_rate(self, observation: dict[str, np.ndarray]) -> float:
        """Turn towards the tag's yaw (zero when the tag is not seen)."""
        if not observation["deck_pose_valid"][0]:
            return 0.0
        return -self.gains.k_yaw * float(observation["deck_pose"][5])

    def hold(
        self,
        observation: dict[str, np.ndarray],
        target_range_m: float,
        own: OwnState | None = None,
    ) -> VelocitySetpoint:
        """Centre over the tag and hold the camera ``target_range_m`` above the deck.

        With nothing seen the drone holds its height (zero vertical set-point).  With
        ``track_deck`` and ``own``, it holds station in the deck's frame instead.
        """
        g = self.gains
        self._descent_clock_s = None
        if self._searching(own):
            assert own is not None
            return self._search(own)
        if self._tracking(own):
            assert own is not None
            height = self.tracked_range_m(own)
            self._last_range = height
            vz = float(
                np.clip(
                    g.k_z * (target_range_m - height), -g.max_vertical_speed, g.max_vertical_speed
                )
            )
            yaw_rate = self._yaw_rate(observation)
            return self._deck_frame_setpoint(own, vz, yaw_rate)
        vx, vy, yaw_rate = self._centre(observation)
        height = self.range_m(observation)
        vz = 0.0
        if math.isfinite(height):
            self._last_range = height
            vz = float(
                np.clip(
                    g.k_z * (target_range_m - height), -g.max_vertical_speed, g.max_vertical_speed
                )
            )
        return VelocitySetpoint(np.array([vx, vy, vz]), yaw_rate)

    def descend(
        self, observation: dict[str, np.ndarray], own: OwnState | None = None
    ) -> VelocitySetpoint:
        """The final descent: centre while the tag is seen, slow to ``touchdown_speed`` near the
        deck, and keep going down on the last range when everything is lost close to it.

        With ``track_deck`` and ``own`` the speeds are relative to the deck: the set-point is
        the deck's estimated velocity plus the centring correction and minus the scheduled
        descent speed, so the drone meets the deck at ``touchdown_speed`` relative to it."""
        g = self.gains
        if self._tracking(own):
            assert own is not None
            measured = self.range_m(observation)
            height = measured if math.isfinite(measured) else self.tracked_range_m(own)
            self._last_range = height
            centre = height > g.blind_range_m
            # how far the descent may go on: 1 on, 0 held (a gate), negative climbs
            progress = 1.0
            lost = centre and self._tag_unseen_s > g.lost_tag_pause_s
            if not lost and centre and g.view_half_tan > 0.0 and observation["deck_pose_valid"][0]:
                progress = self._view_factor(observation)
            flare = False
            if 0.0 < height < g.flare_range_m and self._flare_wait_s < g.max_flare_wait_s:
                lean_deg = math.degrees(math.acos(float(np.clip(own.rotation_wb[2, 2], -1, 1))))
                if lean_deg > g.max_touchdown_lean_deg:
                    # a gust leans the drone over: wait over the deck for the lull
                    flare = True
                    self._flare_wait_s += self.dt
            if lost:
                # the tag is lost above the blind range: climb slowly (relative to the deck,
                # widening the view) and re-centre on the tracked deck until it is seen again
                # (a timed descent starts again from where the drone then is)
                speed = -g.lost_tag_climb_speed
                self._descent_clock_s = None
            elif flare:
                speed = 0.0
            elif progress < 0.0 and g.descent_profile == "timed":
                speed = progress * g.touchdown_speed
                self._descent_clock_s = None
            else:
                speed = progress * self._descent_speed(height, progress)
            if speed < 0.0 and height >= g.max_search_range_m:
                speed = 0.0  # climb to widen the view, but no higher than this
            yaw_rate = self._yaw_rate(observation) if centre else 0.0
            return self._deck_frame_setpoint(own, -speed, yaw_rate)
        if self._searching(own):
            assert own is not None
            return self._search(own)
        height = self.range_m(observation)
        if math.isfinite(height):
            self._last_range = height
        else:
            height = self._last_range
        vx = vy = yaw_rate = 0.0
        if height > g.blind_range_m:
            vx, vy, yaw_rate = self._centre(observation)
        if math.isfinite(height):
            speed = self._descent_speed(height)
        else:
            speed = g.touchdown_speed
        return VelocitySetpoint(np.array([vx, vy, -speed]), yaw_rate)
