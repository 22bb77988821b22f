"""The gains and limits of the deck-relative guidance (:class:`GuidanceGains`).

The config's ``timing.guidance`` section (:class:`~landing_env.timing_config.TimingConfig`);
the guidance that flies with them is :class:`~landing_env.timing.guidance.DeckGuidance`.
"""

from __future__ import annotations

from dataclasses import dataclass

from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice
from landing_env.physics.controller import PID_GAIN

#: the deck tracker's motion models (:attr:`GuidanceGains.tracker_model`,
#: :class:`~landing_env.timing.deck_tracker.DeckTracker`)
TRACKER_MODELS = ("velocity", "acceleration")
#: the final descent's profiles (:attr:`GuidanceGains.descent_profile`)
DESCENT_PROFILES = ("range", "timed")
#: what the deck-frame guidance does once the deck's height track is lost
#: (:attr:`GuidanceGains.lost_deck`)
LOST_DECK_ACTIONS = ("descend", "search")


@dataclass
class GuidanceGains:
    """Gains and limits of the deck-relative guidance (hold, approach and final descent)."""

    #: horizontal velocity per metre of horizontal error, 1/s
    k_xy: float = limited(0.8, POSITIVE, physical=PID_GAIN)
    max_horizontal_speed: float = limited(
        1.0, POSITIVE, physical=Limit.non_negative(50.0, "m/s; a multirotor's is < 30")
    )
    #: yaw rate per radian of tag yaw, 1/s
    k_yaw: float = limited(0.8, NON_NEGATIVE, physical=PID_GAIN)
    #: vertical velocity per metre of height error while holding, 1/s
    k_z: float = limited(1.2, POSITIVE, physical=PID_GAIN)
    max_vertical_speed: float = limited(0.8, POSITIVE, physical=Limit.non_negative(20.0, "m/s"))
    #: final descent: speed = descent_gain * range, between touchdown_speed and descent_speed
    descent_gain: float = limited(1.5, POSITIVE, physical=PID_GAIN)
    descent_speed: float = limited(0.8, POSITIVE, physical=Limit.non_negative(20.0, "m/s"))
    touchdown_speed: float = limited(0.25, POSITIVE)
    #: below this range the tag no longer fits the image: descend on the ToF alone, metres
    blind_range_m: float = limited(0.3, NON_NEGATIVE, physical=Limit.non_negative(100.0, "m"))
    #: the final descent's profile: ``"range"`` (the speed above, scheduled on the range: the
    #: last centimetres, cushioned by the ground effect, take a varying time, so the contact
    #: comes 1.1-2.6 s after the commit) or ``"timed"`` (the height over the deck tracks a
    #: reference that meets the deck ``descent_time_s`` after the commit at ``touchdown_speed``
    #: (:func:`~landing_env.timing.timed_descent.timed_descent_reference`): the contact time
    #: is fixed, so a timing policy has to predict the deck that far ahead and no further)
    descent_profile: str = "range"
    descent_time_s: float = limited(1.2, Limit(0.2, 10.0))
    #: the timed profile's correction of the height error, 1/s
    descent_track_gain: float = limited(3.0, Limit(0.0, 20.0))
    #: the timed profile's reference rate is fed forward this early: the lag of the velocity
    #: loop (its vertical P gain, ``controller.vel_p_z`` = 5/s, is a 0.2 s time constant), s
    descent_lead_s: float = limited(0.2, Limit(0.0, 2.0))
    #: the camera's range over the deck when the feet touch it (the timed reference ends
    #: there): the feet's bottoms are 0.080 m below the centre of mass and the camera 0.030 m
    #: (assets/quadrotor.urdf, quadrotor.yaml), metres
    contact_range_m: float = limited(0.05, Limit(0.0, 0.5))
    #: aligned when the horizontal error is below this plus ``align_tolerance_per_m`` * range
    align_tolerance_m: float = limited(0.08, NON_NEGATIVE, physical=Limit.non_negative(100.0, "m"))
    align_tolerance_per_m: float = limited(
        0.08, NON_NEGATIVE, physical=Limit.non_negative(10.0, "m of tolerance per m of range")
    )
    #: fly in the deck's frame (deck-velocity feed-forward from
    #: :class:`~landing_env.timing.deck_tracker.DeckTracker`, relative descent speed); needs
    #: the drone's navigation estimate (:class:`~landing_env.timing.deck_tracker.OwnState`)
    track_deck: bool = False
    #: the tracker's process noise: the deck's acceleration spectral density, m^2/s^3 (the
    #: ship decks' vertical acceleration is 0.3-0.8 m/s^2 RMS at 0.1-0.2 Hz)
    tracker_accel_psd: float = limited(
        0.5, POSITIVE, physical=Limit.non_negative(1e6, "(m/s^2)^2/Hz")
    )
    #: the tracker's measurement noise (1 sigma) of the deck position, metres
    tracker_position_sigma_m: float = limited(
        0.02, POSITIVE, physical=Limit.non_negative(100.0, "m")
    )
    #: without any measurement for this long the tracker is dropped (the plain law flies)
    tracker_coast_s: float = limited(1.5, POSITIVE, physical=Limit.non_negative(600.0, "s"))
    #: time constant of the low-pass on the drone's lean (for aiming the camera), seconds
    lean_filter_s: float = limited(1.0, POSITIVE, physical=Limit.non_negative(60.0, "s"))
    #: in the deck-frame descent, the tag unseen this long above ``blind_range_m`` pauses the
    #: descent until it is seen again, seconds
    lost_tag_pause_s: float = limited(0.3, POSITIVE, physical=Limit.non_negative(600.0, "s"))
    #: ... and the drone climbs at this speed relative to the deck meanwhile, m/s, up to
    #: ``max_search_range_m`` above it
    lost_tag_climb_speed: float = limited(
        0.2, NON_NEGATIVE, physical=Limit.non_negative(20.0, "m/s")
    )
    max_search_range_m: float = limited(2.5, POSITIVE, physical=Limit.non_negative(1e3, "m"))
    #: touchdown when the lean allows: below ``flare_range_m`` the deck-frame descent holds
    #: its height over the deck while the drone leans more than ``max_touchdown_lean_deg``
    #: from the vertical (a gust), for at most ``max_flare_wait_s``; 0 turns it off.  On
    #: the ship decks 5 % of the touchdowns below 18 deg tipped over or bounced when the
    #: motors stopped, 16 % at 18-22 deg and 39 % above 22 deg (README "Landing on the ship")
    flare_range_m: float = limited(0.0, Limit(0.0, 3.0))
    max_touchdown_lean_deg: float = limited(18.0, Limit(0.0, 90.0))
    max_flare_wait_s: float = limited(3.0, NON_NEGATIVE, physical=Limit.non_negative(600.0, "s"))
    #: in the deck-frame descent, the tag must stay inside the view: the descent slows to a
    #: stop as the tag's farthest corner comes within ``view_margin`` (tangent of the angle)
    #: of this half field of view (tangent: half the image width over the focal length,
    #: 256 / 458.5 for the default camera), and climbs beyond it; 0 turns the gate off
    view_half_tan: float = limited(
        0.0, NON_NEGATIVE, physical=Limit.positive(100.0, "tan of half the field of view")
    )
    #: the gate's half field of view is the camera's, as its calibration gives it (the
    #: narrowest half view, :meth:`~estimation.camera_model.CameraIntrinsics.half_view_tan`;
    #: the timing task sets ``view_half_tan`` from it), not the number above: a lens change
    #: cannot leave the gate behind
    view_from_camera: bool = False
    view_margin: float = limited(
        0.08, NON_NEGATIVE, physical=Limit.non_negative(10.0, "fraction of the view")
    )
    #: half the tag's side, metres (for the gate: the corners, not the centre, must fit)
    tag_half_size_m: float = limited(0.15, NON_NEGATIVE, physical=Limit.positive(100.0, "m"))
    #: a coasting track's velocity decays with this time constant (the deck's horizontal
    #: motion is oscillatory: holding a stale velocity drifts away), seconds
    tracker_velocity_decay_s: float = limited(1.0, POSITIVE, physical=Limit.positive(600.0, "s"))
    #: the tracker's motion model: ``"velocity"`` (constant velocity, white-noise
    #: acceleration of ``tracker_accel_psd``) or ``"acceleration"`` (constant acceleration,
    #: white-noise jerk of ``tracker_jerk_psd``: Bar-Shalom, Li & Kirubarajan 2001, Sec.
    #: 6.2.3), whose acceleration estimate is fed forward ``deck_lead_s`` ahead
    tracker_model: str = "velocity"
    #: the deck's jerk spectral density for the ``acceleration`` model, m^2/s^5 (a heave of
    #: 0.5-1 m/s^2 at 0.1-0.15 Hz: a jerk of 0.3-1 m/s^3)
    tracker_jerk_psd: float = limited(2.0, POSITIVE, physical=Limit.positive(1e6, "(m/s^3)^2/Hz"))
    #: the set-point carries the deck's velocity this far ahead (its velocity plus the tracked
    #: acceleration times this): the velocity loop lags its set-point by about its time
    #: constant (``controller.vel_p_z`` = 5/s: 0.2 s), so a set-point of the present deck
    #: velocity meets an accelerating deck late; 0 turns it off, seconds
    deck_lead_s: float = limited(0.0, Limit(0.0, 2.0))
    #: in the deck-frame descent, the relative vertical speed the drone measures (its own
    #: vertical velocity minus the tracked deck's: the rate of the tracked range) fed back:
    #: the set-point adds this gain times the planned minus the measured relative speed, so
    #: a vertical gust or the ship's airwake that pushes the drone down faster than planned
    #: is met by the guidance as well as by the velocity loop; 0 turns it off
    descent_rate_gain: float = limited(0.0, Limit(0.0, 10.0))
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
        require_limits(self)
        require_choice("descent_profile", self.descent_profile, DESCENT_PROFILES)
        require_choice("tracker_model", self.tracker_model, TRACKER_MODELS)
        require_choice("lost_deck", self.lost_deck, LOST_DECK_ACTIONS)
        if self.touchdown_speed > self.descent_speed:
            raise ConfigError(
                "touchdown_speed",
                f"{self.touchdown_speed} must not exceed descent_speed = {self.descent_speed}",
            )
