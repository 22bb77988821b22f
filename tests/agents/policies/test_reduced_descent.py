"""The onboard look-ahead's reduced model: the drone's closed loop through a commit as a point
mass, every draw of a check at once, judged by the touchdown's own criteria; and its verdicts
set against the simulation's replay on a recorded check."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import landing_env  # noqa: F401  (registers the ids)
from agents.policies.deck_forecast import DeckForecastTimingPolicy, OnboardModelConfig
from agents.policies.lookahead import LookaheadSettings, check_features
from agents.policies.reduced_descent import (
    MODEL_DT_S,
    DeckTrack,
    DescentStart,
    DrawSet,
    ReducedDescentModel,
    ReducedLookahead,
)
from agents.policies.registry import make_env_and_policy
from estimation.frames import R_BC
from landing_env.config import TouchdownConfig
from landing_env.errors import ConfigError
from landing_env.guidance_gains import GuidanceGains
from landing_env.physics.controller import ControllerGains
from landing_env.scenarios import SHIP_TIMING
from landing_env.timing.timed_descent import timed_descent_reference, timed_descent_references
from landing_env.touchdown import Outcome

DT_S = MODEL_DT_S
THRESHOLDS = TouchdownConfig(max_relative_attitude_deg=40.0)
FEET_B = np.array(
    [[0.1, 0.0, -0.068], [0.0, 0.1, -0.068], [-0.1, 0.0, -0.068], [0.0, -0.1, -0.068]]
)


def _model(**gains) -> ReducedDescentModel:
    guidance = {k: v for k, v in SHIP_TIMING["guidance"].items() if k != "view_from_camera"}
    return ReducedDescentModel(
        GuidanceGains(**{**guidance, **gains}),
        ControllerGains(),
        mass_kg=0.8,
        linear_drag_b=np.array([0.25, 0.25, 0.35]),
        control_dt_s=0.05,
    )


def _start(**changes) -> DescentStart:
    """Hovering 2.1 m over the tag centre, level, in still air."""
    start = DescentStart(
        position_w=np.array([0.0, 0.0, 2.1]),
        velocity_w=np.zeros(3),
        rotation_wb=np.eye(3),
        velocity_integral_w=np.zeros(3),
        wind_w=np.zeros(3),
        lean=np.zeros(2),
        descent_time_s=1.2,
        feet_b=FEET_B,
        foot_radius_m=0.012,
        camera_offset_b=np.array([0.0, 0.0, -0.03]),
        camera_rotation_bc=R_BC,
    )
    return dataclasses.replace(start, **changes)


def _deck(heave_m=None, roll_rad=None) -> DeckTrack:
    """A deck at the origin whose height and roll follow the given functions of time."""
    times = DT_S * np.arange(int(4.0 / DT_S) + 3)
    z = np.zeros_like(times) if heave_m is None else heave_m(times)
    roll = np.zeros_like(times) if roll_rad is None else roll_rad(times)
    position = np.stack([np.zeros_like(times), np.zeros_like(times), z], axis=1)
    c, s = np.cos(roll), np.sin(roll)
    rotation = np.zeros((len(times), 3, 3))
    rotation[:, 0, 0] = 1.0
    rotation[:, 1, 1], rotation[:, 1, 2] = c, -s
    rotation[:, 2, 1], rotation[:, 2, 2] = s, c
    velocity = np.gradient(position, DT_S, axis=0)
    return DeckTrack(times, position, rotation, velocity, np.gradient(velocity, DT_S, axis=0))


def _draws(n: int = 1, seed: int = 0, spread: float = 0.0) -> DrawSet:
    rng = np.random.default_rng(seed)
    return DrawSet(
        shift_w=spread * 0.01 * rng.standard_normal((n, 3)),
        gust_w=spread * 0.4 * rng.standard_normal((n, 3)),
        drag_scale=1.0 + spread * 0.2 * rng.uniform(-1.0, 1.0, n),
        thrust_scale=1.0 + spread * 0.05 * rng.uniform(-1.0, 1.0, n),
    )


# ------------------------------------------------------------------------------ the flight
def test_a_reduced_future_over_a_calm_deck_lands_gently_and_level() -> None:
    touchdowns = _model().fly(_start(), _deck(), _draws())
    outcome, touchdown = touchdowns.judged(0, THRESHOLDS)
    assert outcome is Outcome.SUCCESS
    assert 1.0 < touchdowns.time_s[0] < 4.0
    # the range schedule ends at its touchdown speed, 0.25 m/s
    assert touchdown["relative_normal_speed"] == pytest.approx(0.25, abs=0.05)
    assert touchdown["deck_tilt_deg"] == pytest.approx(0.0, abs=1e-9)
    assert touchdown["relative_attitude_deg"] < 2.0
    assert touchdown["lateral_offset_m"] < 0.02


def test_a_timed_descent_meets_a_calm_deck_about_its_planned_time_after_the_commit() -> None:
    # the bench's timed profile: the feet touch 1.30 +- 0.06 s after a 1.2 s reference
    touchdowns = _model(descent_profile="timed").fly(
        _start(position_w=np.array([0.0, 0.0, 0.6])), _deck(), _draws()
    )
    outcome, touchdown = touchdowns.judged(0, THRESHOLDS)
    assert outcome is Outcome.SUCCESS
    assert 1.1 < touchdowns.time_s[0] < 1.6
    assert touchdown["relative_normal_speed"] == pytest.approx(0.25, abs=0.1)


def test_a_descent_onto_a_deck_heaving_up_fast_at_contact_fails_on_the_relative_speed() -> None:
    calm = _model().fly(_start(), _deck(), _draws()).time_s[0]
    rise_from_s = calm - 0.2

    def heave(times):
        return 2.0 * np.clip(times - rise_from_s, 0.0, None)

    touchdowns = _model().fly(_start(), _deck(heave_m=heave), _draws())
    outcome, touchdown = touchdowns.judged(0, THRESHOLDS)
    assert outcome is Outcome.HARD_LANDING
    assert touchdown["failed_checks"] == ["relative_normal_speed"]
    assert touchdown["relative_normal_speed"] > THRESHOLDS.max_normal_speed


def test_a_deck_rolled_past_the_limit_at_contact_fails_on_its_tilt() -> None:
    touchdowns = _model().fly(_start(), _deck(roll_rad=lambda t: np.full_like(t, 0.12)), _draws())
    outcome, touchdown = touchdowns.judged(0, THRESHOLDS)
    assert outcome is Outcome.HARD_LANDING
    assert "deck_tilt" in touchdown["failed_checks"]
    assert touchdown["deck_tilt_deg"] == pytest.approx(np.degrees(0.12), abs=1e-6)


def test_draws_flown_together_equal_the_same_draws_flown_one_by_one() -> None:
    deck = _deck(heave_m=lambda t: 0.4 * np.sin(0.9 * t), roll_rad=lambda t: 0.03 * np.sin(1.3 * t))
    start = _start(
        wind_w=np.array([-6.0, 3.0, 0.0]), velocity_integral_w=np.array([2.0, -1.0, 0.0])
    )
    draws = _draws(5, seed=3, spread=1.0)
    model = _model()
    together = model.fly(start, deck, draws)
    for k in range(len(draws)):
        alone = model.fly(start, deck, draws.row(k))
        for field in dataclasses.fields(together):
            assert getattr(alone, field.name)[0] == pytest.approx(
                getattr(together, field.name)[k], rel=1e-9, abs=1e-12, nan_ok=True
            )
    # the draws differ, and so do their touchdowns
    assert len(set(np.round(together.relative_attitude_deg, 6))) == len(draws)


def test_a_draw_that_never_reaches_the_deck_is_no_touchdown_and_fails() -> None:
    # the deck falls away faster than the controller lets the drone descend (2 m/s)
    sinking = _deck(heave_m=lambda t: -3.0 * t)
    touchdowns = _model().fly(_start(), sinking, _draws())
    outcome, touchdown = touchdowns.judged(0, THRESHOLDS)
    assert np.isnan(touchdowns.time_s[0])
    assert outcome is Outcome.TIMEOUT and touchdown is None


def test_a_start_or_a_forecast_that_is_not_finite_is_refused_by_the_check() -> None:
    assert not _start(position_w=np.array([0.0, np.nan, 2.0])).finite()
    assert not _start(descent_time_s=float("inf")).finite()
    assert not _deck(heave_m=lambda t: np.where(t > 1.0, np.nan, 0.0)).finite()
    assert _start().finite() and _deck().finite() and _draws(3, spread=1.0).finite()


def test_the_vectorised_timed_reference_is_the_guidance_reference_element_by_element() -> None:
    clocks = np.linspace(-0.2, 2.0, 23)
    starts = np.linspace(0.3, 2.5, 23)
    heights, rates = timed_descent_references(clocks, starts, 1.2, 0.25, 0.05)
    for t, h0, height, rate in zip(clocks, starts, heights, rates, strict=True):
        assert (height, rate) == pytest.approx(timed_descent_reference(t, h0, 1.2, 0.25, 0.05))


# ------------------------------------------------------------------------------ settings
def test_the_onboard_model_is_a_look_ahead_setting_that_only_the_reduced_model_signs() -> None:
    assert "model" not in LookaheadSettings().signature()
    assert LookaheadSettings(model="reduced").signature()["model"] == "reduced"
    signed = LookaheadSettings(model="reduced", draws=16).signature()
    assert LookaheadSettings.from_signature(signed) == LookaheadSettings(model="reduced", draws=16)
    with pytest.raises(ConfigError, match=r"lookahead\.model"):
        LookaheadSettings(model="pybullet")


# ------------------------------------------------------------------------------ in the task
def test_a_check_without_a_deck_estimate_is_an_invalid_feature_not_a_crash(
    small_forecast, monkeypatch
) -> None:
    env, _ = make_env_and_policy("land-now", "ship-ss4", "tight")
    try:
        env.reset(seed=2)
        base = env.unwrapped
        look = ReducedLookahead(env, draws=4, forecast=small_forecast, onboard=OnboardModelConfig())
        invalid = dataclasses.replace(base._sensing.estimates["tight"], valid=False)
        monkeypatch.setitem(base._sensing.estimates, "tight", invalid)
        tries = look.try_commits(0)
        assert tries is None
        assert check_features(tries)[0] == 0.0
    finally:
        env.close()


def test_the_reduced_model_gives_the_replays_verdicts_on_a_recorded_check(small_forecast) -> None:
    """A handful of draws of one check of ship-ss4 (realistic sensing, the shipped look-ahead's
    airframes in trim), flown by the replay of the simulation and by the reduced model: the
    same verdicts on all but at most one (the replay also draws the gusts' innovations and
    the sensors' noise, which the reduced model does not know)."""
    env, _ = make_env_and_policy(
        "land-now", "ship-ss4", "tight", extra_overrides={"sensors": "realistic"}
    )
    try:
        env.reset(seed=1_000_000)
        base = env.unwrapped
        while not base._sensing.estimates["tight"].valid:
            env.step(0)
        settings = {
            "draws": 4,
            "forecast": small_forecast,
            "min_margin": 0.15,
            "onboard": OnboardModelConfig(airframe_in_trim=True),
        }
        replay = DeckForecastTimingPolicy(env, **settings).try_commits(0)
        reduced = ReducedLookahead(env, **settings).try_commits(0)
        assert replay is not None and reduced is not None
        for verdict in ("success", "lands"):
            alike = [
                getattr(a, verdict) == getattr(b, verdict)
                for a, b in zip(replay, reduced, strict=True)
            ]
            assert sum(alike) >= 3, (verdict, replay, reduced)
    finally:
        env.close()
