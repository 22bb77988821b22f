"""The gains and limits of the deck-relative guidance (:class:`GuidanceGains`).

The config's ``timing.guidance`` section (:class:`~landing_env.timing_config.TimingConfig`);
the guidance that flies with them is :class:`~landing_env.timing.guidance.DeckGuidance`.
"""

from __future__ import annotations

from dataclasses import dataclass

from landing_env.errors import ConfigError, require_choice, require_range

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
    #: (:func:`~landing_env.timing.timed_descent.timed_descent_reference`): the contact time
    #: is fixed, so a timing policy has to predict the deck that far ahead and no further)
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
    #: fly in the deck's frame (deck-velocity feed-forward from
    #: :class:`~landing_env.timing.deck_tracker.DeckTracker`, relative descent speed); needs
    #: the drone's navigation estimate (:class:`~landing_env.timing.deck_tracker.OwnState`)
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
