"""The deck-relative guidance that the timing task and the scripted policies fly.

:class:`DeckGuidance` turns the *observation* (the estimated deck pose and the ToF ranges, never
the truth) into velocity set-points: hold centred over the tag at a height, or fly the final
descent to touchdown.  ``DeckLandingTiming-v0`` holds and descends with it, and the
``align-descend`` policy of ``DeckLanding-v2`` flies its approach and descent with the same
gains.

Two laws, chosen by ``GuidanceGains.track_deck``:

* off (the bench default): proportional servoing on the camera-frame tag offset and range,
  as the papers' bench needs (a deck that heaves centimetres, no wind);
* on (the ship scenarios): the guidance flies **in the deck's frame**.

  - A constant-velocity (or constant-acceleration, ``tracker_model``) Kalman filter per
    world axis (:class:`~landing_env.timing.deck_tracker.DeckTracker`) tracks where the deck
    is and how fast it moves, from the tag seen by a *level* camera (the drone's lean
    removed) and, with the tag lost, the ToF ranges, plus the drone's own navigation estimate
    (:class:`~landing_env.timing.deck_tracker.OwnState`: the autopilot's position, velocity
    and attitude, as PX4's EKF2 gives them to a companion computer).
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
  The motors are cut at the first contact (``World.settle``), as a land detector does, or
  after a short land sequence (``touchdown.spool_down_s``).

The final descent's speed has two profiles (``GuidanceGains.descent_profile``): ``range``
schedules it on the range (fast high up, ``touchdown_speed`` near the deck), and ``timed``
makes the height over the deck track a reference
(:func:`~landing_env.timing.timed_descent.timed_descent_reference`) that reaches the deck
``descent_time_s`` after the commit, its rate fed forward by the velocity loop's lag
and its error corrected, so that the feet touch a fixed time after the commit (1.30 +- 0.06 s
on the bench for 1.2 s, against 1.85 +- 0.35 s on the range schedule, whose last centimetres
the ground effect slows by varying amounts): the time-to-contact guidance of the landing
literature (Lee 1976, *Perception* 5:437-459, tau theory; Kendoul 2014, *Int. J. Robotics
Research* 33:237-267, time-to-contact landing of rotorcraft), which fixes the time a timing
policy must predict.
"""

from __future__ import annotations

import math

import numpy as np

from estimation.frames import camera_to_heading_xy
from landing_env.guidance_gains import GuidanceGains
from landing_env.physics.controller import VelocitySetpoint
from landing_env.timing.deck_tracker import DeckTracker, OwnState
from landing_env.timing.timed_descent import timed_descent_reference


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
        #: the timed descent's start height
        self._descent_start_m = 0.0
        self.reset()

    def reset(self) -> None:
        self._last_range = math.inf
        self._lean = np.zeros(2)
        self._lean_started = False
        self._tag_unseen_s = math.inf
        self._flare_wait_s = 0.0
        #: the timed descent's clock (None: not descending)
        self._descent_clock_s: float | None = None
        #: searching for the lost deck (``lost_deck = "search"``)
        self._search_on = False
        #: the timed descent's duration (``plan_descent``; the gains' by default)
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

    @property
    def lean(self) -> np.ndarray:
        """The low-passed lean (the body z axis' horizontal slope, world x, y) the camera's aim
        allows for."""
        return np.array(self._lean, dtype=float)

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
            vertical = -speed
            if g.descent_rate_gain > 0.0:
                # the relative speed as measured (the tracked range's rate) held to the plan
                measured = float(own.velocity_w[2]) - float(self.tracker.velocity_w[2])
                vertical += g.descent_rate_gain * (vertical - measured)
            return self._deck_frame_setpoint(own, vertical, yaw_rate)
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
