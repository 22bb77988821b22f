"""The timing task's settings: the ``timing`` section of the environment config.

``gym.make(id, overrides={"timing.wait_limit_s": 30})`` sets them, as every other section; a
YAML config may hold a ``timing:`` section too.  The registered ids lay their scenario's
settings under the user's (:mod:`landing_env.scenarios`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from estimation.limits import Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.guidance_gains import GuidanceGains

#: the wave-off's predictors of the deck tilt at the contact (``TimingConfig.wave_off_predictor``)
WAVE_OFF_PREDICTORS = ("linear", "quadratic", "model")
#: what the model wave-off compares its chance with (``TimingConfig.wave_off_rule``)
WAVE_OFF_RULES = ("fixed", "value")
#: a wave-off climbs back to the hold for at most this long, seconds (it nearly always takes
#: all of it: the last 5 cm to the hold are slow)
WAVE_OFF_CLIMB_S = 1.5
#: the shortest timed descent a contact window may ask for, seconds
MIN_CHOSEN_DESCENT_S = 1.0
#: what the observation holds (``TimingConfig.observation``)
OBSERVATION_KINDS = ("history", "prediction")

#: the camera sits this far below the drone's centre of mass (body z), metres; the start
#: height puts the *camera* at the hold height
CAMERA_BELOW_COM_M = 0.03


#: ``timing.tilt_model`` that stands for the scenario's own deck-tilt predictor (its config's
#: ``deck_predictor``): one model card then fits every scenario it was trained over
SCENARIO_TILT_MODEL = "scenario"


@dataclass
class TimingConfig:
    """The timing task's settings (the config's ``timing`` section:
    ``gym.make("DeckLandingTiming-v0", overrides={"timing.hold_height_m": 1.0})``)."""

    #: camera height above the deck (along the tag's z / the ToF mean) while waiting, metres
    hold_height_m: float = limited(0.7, Limit(0.3, 3.0))
    #: length of the pose history in the observation, seconds
    history_s: float = limited(2.0, Limit(0.1, 10.0))
    #: window of the least-squares rates, seconds
    rate_window_s: float = 0.5
    #: control periods per decision (a wait lasts this many periods)
    steps_per_decision: int = limited(2, Limit(1, 20))
    #: the descent is committed regardless once the drone has waited this long, seconds
    wait_limit_s: float = limited(15.0, Limit(0.0, 600.0, low_inclusive=False))
    #: a descent that has not touched down after this long ends the episode (timeout), seconds
    descent_timeout_s: float = limited(6.0, Limit(0.5, 120.0))
    #: the history holds the deck pose as a level camera sees it (the drone's roll and pitch,
    #: from its attitude, removed), so that the deck's tilt relative to gravity, which the
    #: touchdown judges, is not confused with the drone's own tilt in wind; False keeps the
    #: camera-frame pose
    level_history: bool = True
    guidance: GuidanceGains = field(default_factory=GuidanceGains)
    #: wave-off (the go-around of ship landing): during a chosen (not forced) timed descent,
    #: from ``wave_off_from_s`` (at least one decision period) after the commit until
    #: ``wave_off_until_s`` (the tag leaves the view at about 0.75 s), the deck tilt
    #: predicted at the contact (the newest history row's roll and pitch carried along their
    #: least-squares rates to ``expected_contact_s`` after the commit) above
    #: ``wave_off_tilt_deg`` aborts the descent: the guidance climbs back to the hold (within
    #: 5 cm, at most 1.5 s) in the same step, which ends without a touchdown, and the agent
    #: decides again (``info["wave_offs"]``; the aborted descent and the climb count as
    #: waiting).  0 turns it off
    wave_off_tilt_deg: float = limited(0.0, Limit(0.0, 45.0))
    wave_off_from_s: float = limited(0.4, Limit(0.0, 10.0))
    wave_off_until_s: float = 0.7
    #: how the wave-off predicts the deck: ``linear`` (the newest row carried along its 0.5 s
    #: least-squares rates) or ``quadratic`` (a parabola fitted to roll and pitch over the last
    #: ``wave_off_window_s``: the deck's curvature, at the price of a noisier acceleration)
    #: or ``model``: the scenario's fitted linear (Wiener) predictor ``tilt_model``
    #: (:class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor` on the history,
    #: which must be at least its window long), which aborts when the chance that the tilt at the
    #: contact is within ``wave_off_tilt_deg`` is below what ``wave_off_rule`` asks (its error
    #: measured on held-out episodes: the chance is honest where a straight line's is not)
    wave_off_predictor: str = "linear"
    wave_off_window_s: float = limited(1.0, Limit(0.2, 10.0))
    wave_off_probability: float = limited(0.8, Limit(0.0, 1.0))
    #: what the ``model`` wave-off compares the chance with: ``fixed``
    #: (``wave_off_probability``) or ``value``: the value of waiting on, i.e. the
    #: optimal-stopping value (:mod:`estimation.anticipation.stopping`) of the chance a commit
    #: gets, over the wait that will be left once the climb back is done, with one
    #: independent opportunity per ``opportunity_s``: it aborts a descent only when a retry
    #: is expected to do better, so less and less often as the wait limit nears
    wave_off_rule: str = "fixed"
    #: the deck's chance of a good contact decorrelates over about this long: the wait left
    #: holds one independent opportunity per ``opportunity_s`` (read by the ``value``
    #: wave-off and the ``predictive`` policy; 1 s was chosen offline on the predictors'
    #: fitting episodes at bench sea states 4 and 5 and checked on the tuning seeds, README
    #: "Predicting the deck a descent ahead")
    opportunity_s: float = limited(1.0, Limit(0.05, 60.0))
    #: the deck-tilt predictor of this scenario: ``scenario`` (the one its config names,
    #: ``deck_predictor``: the bench scenarios' are shipped), a shipped one by name
    #: (``bench-ss4``: landing_env/assets/predictors/deck_tilt_bench-ss4.npz, fitted by
    #: :mod:`agents.training.tilt_predictor_fit`) or a path; read by the ``model`` wave-off and
    #: the ``predictive`` policy; empty: none
    tilt_model: str = ""
    #: the timed descent's contact, seconds after the commit (1.2 s reference: 1.30 s measured)
    expected_contact_s: float = limited(1.3, Limit(0.1, 10.0))
    #: the contact time chosen at each commit: with a window ``[first, last]`` (seconds after
    #: the commit) the deck-tilt predictor ``tilt_model`` predicts the deck at every
    #: ``contact_step_s`` of it, and the timed descent is given the duration that meets the
    #: deck where the chance of a tilt within the touchdown limit is best (its reference
    #: ``guidance.descent_time_s`` shifted by the contact's shift from
    #: ``expected_contact_s``): the commit picks *when* to touch as well as when to leave.
    #: Empty: every descent takes ``guidance.descent_time_s`` (contact at
    #: ``expected_contact_s``)
    contact_window_s: list[float] = field(default_factory=list)
    contact_step_s: float = limited(0.1, Limit(0.05, 1.0))
    #: what the observation holds: ``history`` (the deck-pose history, as every id up to the
    #: bench's v4) or ``prediction``: instead of the history, what the ``predictive`` rule
    #: weighs, for a learned policy to weigh: the chance ``tilt_model`` gives of a deck within
    #: the touchdown limit at each of ``contact_times_s``, the value of waiting on (the
    #: optimal-stopping value of such chances over the wait left, one opportunity per
    #: ``opportunity_s``) and the prediction's validity (:class:`TimingObservationLayout`)
    observation: str = "history"

    def __post_init__(self) -> None:
        require_limits(self)
        require_range(
            "rate_window_s",
            self.rate_window_s,
            0.1,
            self.history_s,
            bounds_from=f"history_s = {self.history_s}",
        )
        require_range(
            "wave_off_until_s",
            self.wave_off_until_s,
            self.wave_off_from_s,
            10.0,
            bounds_from=f"wave_off_from_s = {self.wave_off_from_s}",
        )
        require_choice("wave_off_predictor", self.wave_off_predictor, WAVE_OFF_PREDICTORS)
        require_choice("wave_off_rule", self.wave_off_rule, WAVE_OFF_RULES)
        require_choice("observation", self.observation, OBSERVATION_KINDS)
        if self.wave_off_rule == "value" and self.wave_off_predictor != "model":
            raise ConfigError(
                "wave_off_rule",
                "'value' weighs the model wave-off's chance: it needs wave_off_predictor = "
                f"model (not {self.wave_off_predictor!r})",
            )
        if self.wave_off_predictor == "quadratic":
            # the parabola is fitted to the history: the window must fit in it
            require_range(
                "wave_off_window_s",
                self.wave_off_window_s,
                0.2,
                self.history_s,
                bounds_from=f"history_s = {self.history_s}",
            )
        self._check_contact_window()
        if self.wave_off_tilt_deg > 0.0 and self.guidance.descent_profile != "timed":
            raise ConfigError(
                "wave_off_tilt_deg",
                f"{self.wave_off_tilt_deg} needs the timed descent (guidance.descent_profile "
                f"= 'timed', not {self.guidance.descent_profile!r}): only it has a known "
                "contact time to predict the deck at",
            )

    def _check_contact_window(self) -> None:
        window = list(self.contact_window_s)
        if not window:
            return
        if len(window) != 2 or not all(isinstance(v, int | float) for v in window):
            raise ConfigError(
                "contact_window_s", f"{window!r} must be [first, last] seconds, or empty"
            )
        if self.guidance.descent_profile != "timed":
            raise ConfigError(
                "contact_window_s",
                "needs the timed descent (guidance.descent_profile = 'timed', not "
                f"{self.guidance.descent_profile!r}): only it can be given a contact time",
            )
        # the shortest descent must still meet the deck gently: below 1.0 s the touchdown
        # speed grows (bench-ss5: 0.33 m/s mean at 1.0 s, 0.42 at 0.9, against 0.21 from 1.2 s)
        lag_s = self.expected_contact_s - self.guidance.descent_time_s
        require_range(
            "contact_window_s",
            window[0],
            lag_s + MIN_CHOSEN_DESCENT_S,
            window[1],
            bounds_from=f"a descent of at least {MIN_CHOSEN_DESCENT_S} s and the window's last",
        )
        require_range("contact_window_s", window[1], window[0], 10.0)

    @property
    def contact_times_s(self) -> tuple[float, ...]:
        """The contact times a commit chooses among (seconds after it): the window's grid,
        or ``expected_contact_s`` alone."""
        if not self.contact_window_s:
            return (self.expected_contact_s,)
        first, last = (float(v) for v in self.contact_window_s)
        n = math.floor((last - first) / self.contact_step_s + 1e-9)
        return tuple(round(first + i * self.contact_step_s, 9) for i in range(n + 1))

    def descent_time_for(self, contact_s: float) -> float:
        """The timed descent's duration whose contact comes ``contact_s`` after the commit."""
        return self.guidance.descent_time_s + contact_s - self.expected_contact_s
