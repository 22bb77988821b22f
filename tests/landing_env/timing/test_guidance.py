"""The deck-frame guidance of the ship scenarios (``GuidanceGains.track_deck``).

Unit behaviour on synthetic observations (no simulation), then real landings on the ship deck.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation.frames import R_BC, matrix_from_euler_zyx
from landing_env.config import SimulationConfig, load_config
from landing_env.errors import ConfigError
from landing_env.guidance_gains import GuidanceGains
from landing_env.physics.controller import ControllerGains
from landing_env.timing.deck_tracker import DeckTracker, OwnState
from landing_env.timing.guidance import DeckGuidance
from landing_env.timing.timed_descent import timed_descent_reference

DT = 0.05


def _observation(
    deck_offset_c: tuple[float, float, float] | None, tof_m: float | None = None
) -> dict[str, np.ndarray]:
    """An observation of a level deck ``deck_offset_c`` (x, y, z) in the camera frame."""
    pose = np.zeros(6, dtype=np.float32)
    valid = deck_offset_c is not None
    if valid:
        pose[:3] = deck_offset_c
    ranges = np.full(4, tof_m if tof_m is not None else 0.0, dtype=np.float32)
    return {
        "deck_pose": pose,
        "deck_pose_valid": np.array([int(valid)], dtype=np.int8),
        "tof_range": ranges,
        "tof_valid": np.full(4, int(tof_m is not None), dtype=np.int8),
    }


def _level(position: tuple[float, float, float], velocity=(0.0, 0.0, 0.0)) -> OwnState:
    return OwnState(np.array(position, float), np.array(velocity, float), np.eye(3))


def test_the_deck_tracker_recovers_the_heave_rate_of_a_deck_seen_only_by_its_ranges() -> None:
    guidance = DeckGuidance(GuidanceGains(track_deck=True), DT)
    rng = np.random.default_rng(0)
    errors = []
    for k in range(400):
        t = k * DT
        deck_z = 0.5 * math.sin(2 * math.pi * t / 8.8)
        deck_vz = 0.5 * 2 * math.pi / 8.8 * math.cos(2 * math.pi * t / 8.8)
        height = 2.0 - deck_z + rng.normal(0.0, 0.007)  # VL53L1X-like noise at 2 m
        guidance.observe(_observation(None, tof_m=height), _level((0.0, 0.0, 2.0)))
        if t > 5.0:
            errors.append(guidance.tracker.velocity_w[2] - deck_vz)
    # the heave rate is 0.36 m/s in amplitude; the track follows it to a few cm/s
    assert np.sqrt(np.mean(np.square(errors))) < 0.06


def test_the_acceleration_tracker_leads_a_heaving_deck_s_velocity_by_the_loop_s_lag() -> None:
    """A deck heaving 0.5 m at 8.8 s, seen by its ranges: the constant-acceleration track
    gives the heave acceleration, and its velocity carried 0.2 s ahead (``deck_lead_s``) is
    closer to the deck's velocity 0.2 s later than the constant-velocity track's."""
    omega = 2 * math.pi / 8.8
    rng = np.random.default_rng(1)
    trackers = {
        model: DeckGuidance(GuidanceGains(track_deck=True, tracker_model=model), DT)
        for model in ("velocity", "acceleration")
    }
    errors: dict[str, list[float]] = {"velocity": [], "acceleration": [], "accel": []}
    for k in range(400):
        t = k * DT
        height = 2.0 - 0.5 * math.sin(omega * t) + rng.normal(0.0, 0.007)
        for guidance in trackers.values():
            guidance.observe(_observation(None, tof_m=height), _level((0.0, 0.0, 2.0)))
        if t > 5.0:
            ahead = 0.5 * omega * math.cos(omega * (t + 0.2))
            plain, led = trackers["velocity"].tracker, trackers["acceleration"].tracker
            errors["velocity"].append(plain.velocity_w[2] - ahead)
            errors["acceleration"].append(led.velocity_w[2] + 0.2 * led.acceleration_w[2] - ahead)
            errors["accel"].append(led.acceleration_w[2] + 0.5 * omega**2 * math.sin(omega * t))
    rms = {key: float(np.sqrt(np.mean(np.square(v)))) for key, v in errors.items()}
    # the heave acceleration is 0.25 m/s^2 in amplitude
    assert rms["accel"] < 0.1
    assert rms["acceleration"] < 0.8 * rms["velocity"]
    assert np.all(trackers["velocity"].tracker.acceleration_w == 0.0)


def test_a_bad_tracker_setting_is_refused_naming_its_key() -> None:
    with pytest.raises(ConfigError, match="tracker_model"):
        GuidanceGains(tracker_model="kalman")
    with pytest.raises(ConfigError, match="deck_lead_s"):
        GuidanceGains(deck_lead_s=-0.1)
    with pytest.raises(ConfigError, match="tracker_jerk_psd"):
        GuidanceGains(tracker_jerk_psd=0.0)


def _textbook_track(order: int, psd: float, r: float, values: list[float], dt: float):
    """One axis of a constant-velocity (order 2) or constant-acceleration (order 3) Kalman
    filter, written out from Bar-Shalom, Li & Kirubarajan (2001), Sec. 6.2.2-6.2.3: the state
    and covariance after each measurement."""
    if order == 2:
        f = np.array([[1.0, dt], [0.0, 1.0]])
        q = psd * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    else:
        f = np.array([[1.0, dt, dt**2 / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        q = psd * np.array(
            [
                [dt**5 / 20, dt**4 / 8, dt**3 / 6],
                [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                [dt**3 / 6, dt**2 / 2, dt],
            ]
        )
    h = np.zeros((1, order))
    h[0, 0] = 1.0
    x = np.zeros(order)
    x[0] = values[0]
    p = np.diag([r, 4.0, 1.0][:order])  # a deck at up to ~2 m/s and ~1 m/s^2
    for z in values[1:]:
        x, p = f @ x, f @ p @ f.T + q
        k = p @ h.T / (h @ p @ h.T + r)
        x = x + (k * (z - h @ x)).ravel()
        p = (np.eye(order) - k @ h) @ p
    return x, p


@pytest.mark.parametrize("model", ["velocity", "acceleration"])
def test_each_axis_is_the_textbook_kalman_filter_of_its_model(model: str) -> None:
    # the jerk's density by default 2 m^2/s^5
    tracker = DeckTracker(accel_psd=0.3, position_sigma_m=0.02, coast_s=1.0, model=model)
    rng = np.random.default_rng(3)
    heights = list(0.4 * np.sin(np.arange(30) * DT) + rng.normal(0.0, 0.02, 30))
    for z in heights:
        tracker.update_measured(np.array([2.0 * z, -z, z]), DT)
    order = 3 if model == "acceleration" else 2
    psd = 2.0 if model == "acceleration" else 0.3
    x, p = _textbook_track(order, psd, 0.02**2, heights, DT)
    np.testing.assert_allclose(tracker.state[2], x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(tracker.cov[2], p, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(tracker.position_w, [2.0 * x[0], -x[0], x[0]], rtol=1e-9)
    np.testing.assert_allclose(tracker.velocity_w, [2.0 * x[1], -x[1], x[1]], rtol=1e-9)
    expected_acceleration = x[2] * np.array([2.0, -1.0, 1.0]) if order == 3 else np.zeros(3)
    np.testing.assert_allclose(tracker.acceleration_w, expected_acceleration, rtol=1e-9)
    assert tracker.valid and tracker.horizontal_valid
    assert tracker.last_height_w == pytest.approx(x[0], rel=1e-12)


def test_the_tag_is_placed_by_the_drones_heading_and_the_ranges_by_its_tilt() -> None:
    own = np.array([1.0, 2.0, 3.0])
    seen = _observation((0.3, -0.2, 1.5))
    ahead = DeckTracker.measure(seen, _level(tuple(own)))
    turned = DeckTracker.measure(
        seen, OwnState(own, np.zeros(3), matrix_from_euler_zyx(0.0, 0.0, math.pi / 2))
    )
    assert ahead[2] == pytest.approx(3.0 - 1.5)
    assert np.hypot(*(ahead[:2] - own[:2])) == pytest.approx(np.hypot(0.3, 0.2))
    # a quarter turn of the drone turns the offset seen a quarter turn in the world
    np.testing.assert_allclose(turned[:2] - own[:2], [own[1] - ahead[1], ahead[0] - own[0]])
    assert OwnState(own, np.zeros(3), matrix_from_euler_zyx(0.1, 0.2, 0.7)).yaw == pytest.approx(
        0.7
    )
    # no tag: the mean of the valid ranges, times the cosine of the tilt, down to cos 60 deg
    ranges = _observation(None, tof_m=2.0)
    ranges["tof_range"][:] = [2.0, 9.0, 2.2, 9.0]
    ranges["tof_valid"][:] = [1, 0, 1, 0]
    for roll_deg, cos_tilt in ((30.0, math.cos(math.radians(30.0))), (70.0, 0.5)):
        tilted = OwnState(own, np.zeros(3), matrix_from_euler_zyx(math.radians(roll_deg), 0, 0))
        measured = DeckTracker.measure(ranges, tilted)
        assert measured.shape == (3,) and np.isnan(measured[:2]).all()
        assert measured[2] == pytest.approx(3.0 - 2.1 * cos_tilt)
    ranges["tof_valid"][:] = 0
    assert np.isnan(DeckTracker.measure(ranges, _level(tuple(own)))).all()


def test_without_a_range_the_height_track_is_dropped_after_coast_s_and_the_others_slow_down() -> (
    None
):
    dt = 0.25
    tracker = DeckTracker(accel_psd=0.3, position_sigma_m=0.02, coast_s=0.5, velocity_decay_s=2.0)
    for k in range(8):
        tracker.update_measured(np.array([0.1 * k, 0.0, 0.05 * k]), dt)
    height = tracker.last_height_w
    velocity = tracker.velocity_w
    for step in (1, 2):  # unseen for 0.25 s, then exactly coast_s
        tracker.update_measured(np.full(3, np.nan), dt)
        assert tracker.valid
        np.testing.assert_allclose(tracker.velocity_w, velocity * math.exp(-step * dt / 2.0))
    tracker.update_measured(np.full(3, np.nan), dt)
    assert not tracker.valid and tracker.horizontal_valid
    assert tracker.last_height_w == height
    tracker.reset()
    assert tracker.last_height_w is None and not tracker.horizontal_valid
    np.testing.assert_array_equal(tracker.position_w, np.zeros(3))


def test_a_tracker_refuses_an_unknown_model_naming_its_key() -> None:
    with pytest.raises(ConfigError, match=r"^tracker_model: 'kalman' is not allowed; "):
        DeckTracker(accel_psd=0.3, position_sigma_m=0.02, coast_s=0.5, model="kalman")


def test_the_ship_timing_ids_track_lead_and_go_around_the_deck() -> None:
    from landing_env.scenarios import SCENARIO_IDS

    for n in (3, 4, 5, 6):
        overrides = SCENARIO_IDS[f"DeckLandingTiming-ShipSS{n}-v8"].overrides
        # the touchdown control: the relative speed held to the plan, then the land sequence
        assert overrides["timing.guidance.descent_rate_gain"] == 1.0
        assert overrides["touchdown.spool_down_s"] == 0.15
        assert overrides["touchdown.spool_down_final_thrust"] == 0.0
        landing = SCENARIO_IDS[f"DeckLanding-ShipSS{n}-v6"].overrides
        assert landing["timing.guidance.descent_rate_gain"] == 1.0
        assert landing["touchdown.spool_down_s"] == 0.15
        # the superseded v7, kept for the model trained on it, flies as it did
        old = SCENARIO_IDS[f"DeckLandingTiming-ShipSS{n}-v7"]
        assert old.superseded_by == f"DeckLandingTiming-ShipSS{n}-v8"
        assert "timing.guidance.descent_rate_gain" not in old.overrides
        assert "touchdown.spool_down_s" not in old.overrides
        assert {k: v for k, v in overrides.items() if k not in old.overrides} == {
            "timing.guidance.descent_rate_gain": 1.0,
            "touchdown.spool_down_s": 0.15,
            "touchdown.spool_down_final_thrust": 0.0,
        }
        assert all(overrides[k] == v for k, v in old.overrides.items())
        assert overrides["timing.guidance.track_deck"] is True
        assert overrides["timing.guidance.tracker_model"] == "acceleration"
        assert overrides["timing.guidance.deck_lead_s"] == 0.2
        assert overrides["timing.guidance.lost_deck"] == "search"
        assert overrides["timing.guidance.flare_range_m"] == 0.0
        assert overrides["estimation.observed"] == "tight"


def test_the_descent_meets_a_rising_deck_at_the_touchdown_speed_relative_to_it() -> None:
    gains = GuidanceGains(track_deck=True, touchdown_speed=0.25)
    guidance = DeckGuidance(gains, DT)
    for k in range(100):  # the deck rises at 1 m/s under a drone that holds its height
        height = 2.0 - 1.0 * k * DT
        guidance.observe(_observation((0.0, 0.0, height)), _level((0.0, 0.0, 2.0)))
    setpoint = guidance.descend(_observation((0.0, 0.0, 0.1)), _level((0.0, 0.0, 2.0)))
    # the deck's 1 m/s upwards minus 0.25 m/s relative: the drone climbs at 0.75 m/s
    assert setpoint.velocity_h[2] == pytest.approx(0.75, abs=0.05)
    plain = DeckGuidance(GuidanceGains(touchdown_speed=0.25))
    assert plain.descend(_observation((0.0, 0.0, 0.1))).velocity_h[2] == pytest.approx(-0.25)


def test_the_descent_holds_the_measured_relative_speed_to_its_plan_by_the_rate_gain() -> None:
    def setpoint(rate_gain: float, drone_vz: float) -> float:
        gains = GuidanceGains(track_deck=True, touchdown_speed=0.25, descent_rate_gain=rate_gain)
        guidance = DeckGuidance(gains, DT)
        for _ in range(100):  # a deck at rest 2 m under a drone that holds its height
            guidance.observe(_observation((0.0, 0.0, 2.0)), _level((0.0, 0.0, 2.0)))
        # near the deck the plan is the touchdown speed, 0.25 m/s down; the drone sinks at
        # drone_vz (a downdraft), which the deck's track, still at rest, measures as relative
        own = _level((0.0, 0.0, 2.0), velocity=(0.0, 0.0, drone_vz))
        return float(guidance.descend(_observation((0.0, 0.0, 0.1)), own).velocity_h[2])

    # off: the plan alone, whatever the drone does
    assert setpoint(0.0, -0.65) == pytest.approx(-0.25, abs=0.01)
    # sinking 0.4 m/s faster than planned: the set-point rises by the gain times that
    assert setpoint(1.0, -0.65) == pytest.approx(-0.25 + 0.4, abs=0.01)
    assert setpoint(0.5, -0.65) == pytest.approx(-0.25 + 0.2, abs=0.01)
    # descending slower than planned: it pushes down
    assert setpoint(1.0, 0.0) == pytest.approx(-0.5, abs=0.01)
    # on plan: no correction
    assert setpoint(2.0, -0.25) == pytest.approx(-0.25, abs=0.01)


def test_a_drone_leaning_into_the_wind_holds_upwind_of_the_tag_so_the_camera_sees_it() -> None:
    guidance = DeckGuidance(GuidanceGains(track_deck=True), DT)
    # leaning 15 deg nose-down into a wind from ahead (+x): body z tilts towards +x
    leaning = OwnState(np.array([0.0, 0.0, 2.0]), np.zeros(3), matrix_from_euler_zyx(0, 0.26, 0))
    # the tag straight below the drone, seen by the tilted camera 15 deg off its axis
    tag_c = (leaning.rotation_wb @ R_BC).T @ np.array([0.0, 0.0, -2.0])
    for _ in range(60):
        guidance.observe(_observation(tuple(tag_c)), leaning)
    assert np.allclose(guidance.tracker.position_w[:2], 0.0, atol=0.02)
    setpoint = guidance.hold(_observation(tuple(tag_c)), 2.0, leaning)
    # forward (upwind) towards 2 m x tan(15 deg) = 0.53 m ahead of the tag, at k_xy = 0.8
    assert setpoint.velocity_h[0] == pytest.approx(0.8 * 2.0 * math.tan(0.26), abs=0.03)
    assert abs(setpoint.velocity_h[1]) < 0.05


def test_the_descent_stops_as_the_tag_nears_the_image_edge_and_climbs_when_it_is_lost() -> None:
    gains = GuidanceGains(track_deck=True, view_half_tan=0.558, blind_range_m=0.8)
    guidance = DeckGuidance(gains, DT)
    own = _level((0.0, 0.0, 2.0))
    for _ in range(40):
        guidance.observe(_observation((0.0, 0.0, 2.0)), own)
    centred = guidance.descend(_observation((0.0, 0.0, 2.0)), own).velocity_h[2]
    near_edge = guidance.descend(_observation((0.8, 0.0, 2.0)), own).velocity_h[2]
    assert centred < -0.5  # full descent speed
    # the far corner at tan 0.475 of 0.558, inside the 0.08 margin: stopped
    assert abs(near_edge) < 0.05
    for _ in range(10):  # the tag lost for half a second (the ranges still see the deck)
        guidance.observe(_observation(None, tof_m=2.0), own)
    lost = guidance.descend(_observation(None, tof_m=2.0), own).velocity_h[2]
    assert lost == pytest.approx(gains.lost_tag_climb_speed, abs=0.02)


def _lose_the_deck(lost_deck: str) -> tuple[DeckGuidance, OwnState]:
    """A track of the deck straight below at 2 m, then 2 s with neither the tag nor a range
    (longer than the tracker's 1.5 s coast) while the drone drifts 0.5 m forward and 0.3 m
    right."""
    guidance = DeckGuidance(GuidanceGains(track_deck=True, lost_deck=lost_deck), DT)
    for _ in range(40):
        guidance.observe(_observation((0.0, 0.0, 2.0), tof_m=2.0), _level((0.0, 0.0, 2.0)))
        guidance.descend(_observation((0.0, 0.0, 2.0), tof_m=2.0), _level((0.0, 0.0, 2.0)))
    drifted = _level((0.5, -0.3, 2.0))
    for _ in range(40):
        guidance.observe(_observation(None), drifted)
    return guidance, drifted


def test_with_the_deck_lost_high_up_the_search_climbs_back_over_it_where_v2_descends_blind() -> (
    None
):
    searching, drifted = _lose_the_deck("search")
    assert not searching.tracker.valid and searching.tracker.horizontal_valid
    climb = searching.descend(_observation(None), drifted).velocity_h
    # climbing at lost_tag_climb_speed, back towards the deck's tracked position (behind,
    # to the left), where the plain law goes straight down at the last range's speed
    assert climb[2] == pytest.approx(searching.gains.lost_tag_climb_speed, abs=1e-6)
    assert climb[0] < -0.3 and climb[1] > 0.2
    blind = _lose_the_deck("descend")[0].descend(_observation(None), drifted).velocity_h
    assert blind[2] < -0.5 and np.allclose(blind[:2], 0.0)
    # the hold searches too, and no higher than max_search_range_m over the deck's last height
    assert searching.hold(_observation(None), 2.0, drifted).velocity_h[2] > 0.1
    high = _level((0.5, -0.3, searching.gains.max_search_range_m + 0.1))
    assert searching.descend(_observation(None), high).velocity_h[2] == pytest.approx(0.0)


def test_the_search_ends_when_the_deck_is_seen_again_and_the_descent_goes_on() -> None:
    guidance, _ = _lose_the_deck("search")
    above = _level((0.5, -0.3, 2.4))
    guidance.descend(_observation(None), above)
    for _ in range(10):  # the tag straight below again, 2.4 m down
        guidance.observe(_observation((0.0, 0.0, 2.4), tof_m=2.4), above)
    assert guidance.tracker.valid
    assert guidance.descend(_observation((0.0, 0.0, 2.4), tof_m=2.4), above).velocity_h[2] < -0.3


def test_a_track_lost_close_to_the_deck_keeps_descending_on_the_last_range() -> None:
    """Below ``blind_range_m`` the deck is there to land on: no go-around."""
    guidance = DeckGuidance(GuidanceGains(track_deck=True, lost_deck="search"), DT)
    low = _level((0.0, 0.0, 0.2))
    for _ in range(20):
        guidance.observe(_observation(None, tof_m=0.2), low)
        guidance.descend(_observation(None, tof_m=0.2), low)
    for _ in range(40):
        guidance.observe(_observation(None), low)
    assert guidance.descend(_observation(None), low).velocity_h[2] < 0.0


def test_a_bad_lost_deck_setting_is_refused_naming_its_key_and_choices() -> None:
    with pytest.raises(ConfigError, match=r"lost_deck.*search"):
        GuidanceGains(lost_deck="climb")


def test_the_ship_decks_judge_the_drone_to_deck_attitude_by_the_gear_clearance_angle() -> None:
    assert load_config("ship-ss4").touchdown.max_relative_attitude_deg == 40.0
    assert load_config("ship-ss6").touchdown.max_relative_attitude_deg == 40.0
    assert load_config("bench-ss4").touchdown.max_relative_attitude_deg == 10.0


#: the ship's first deck-frame guidance (v1 of the ship timing ids), and with the deck's
#: acceleration tracked and led (v2); the level start with the bench's controller limits
_SHIP_GUIDANCE = {
    1: {"k_xy": 1.5, "blind_range_m": 0.8, "view_half_tan": 0.558, "flare_range_m": 0.5},
    2: {
        "k_xy": 1.5,
        "blind_range_m": 0.8,
        "view_half_tan": 0.558,
        "flare_range_m": 0.5,
        "tracker_model": "acceleration",
        "deck_lead_s": 0.2,
    },
}
LEVEL_START = {
    "start.trim_to_wind": False,
    "controller.vel_i_limit_xy": ControllerGains().vel_i_limit_xy,
    "controller.max_tilt": ControllerGains().max_tilt,
}


def _land_now(track: bool, seeds: range, version: int = 1) -> list[dict]:
    import gymnasium as gym

    import landing_env  # noqa: F401
    from landing_env.config_loading import nested_to_dotted
    from landing_env.scenarios import SCENARIOS, TIMING_TASK

    timing = {
        "hold_height_m": 2.0,
        "descent_timeout_s": 15.0,
        "guidance": {**_SHIP_GUIDANCE[version], "track_deck": track},
    }
    overrides = {
        **SCENARIOS["ship-ss4"].overrides(TIMING_TASK, "truth"),
        **LEVEL_START,
        "lens": "standard",
    }
    overrides = {k: v for k, v in overrides.items() if not k.startswith("timing.")}
    env = gym.make(
        "DeckLandingTiming-v0",
        config="ship-ss4",
        overrides={**overrides, **nested_to_dotted(timing, "timing")},
    )
    touchdowns = []
    try:
        for seed in seeds:
            env.reset(seed=seed)
            _, _, _, _, info = env.step(1)
            touchdowns.append({"outcome": info["outcome"], **info.get("touchdown", {})})
    finally:
        env.close()
    return touchdowns


@pytest.mark.parametrize("version", [1, 2])
def test_on_the_ship_deck_the_deck_frame_descent_lands_where_the_bench_guidance_hits_hard(
    version: int,
) -> None:
    seeds = range(1_000_000, 1_000_003)
    tracked = _land_now(True, seeds, version)
    plain = _land_now(False, seeds)
    assert sum(t["outcome"] == "success" for t in tracked) >= 2
    speeds = [t["relative_normal_speed"] for t in tracked if "relative_normal_speed" in t]
    assert len(speeds) == 3 and max(speeds) < 0.4
    # the bench's law descends at 0.25 m/s relative to the world: the heave decides
    assert sum(t["outcome"] == "success" for t in plain) < sum(
        t["outcome"] == "success" for t in tracked
    )


def test_near_the_deck_the_descent_waits_while_a_gust_leans_the_drone_over() -> None:
    gains = GuidanceGains(
        track_deck=True, blind_range_m=0.8, flare_range_m=0.5, max_touchdown_lean_deg=18.0
    )
    guidance = DeckGuidance(gains, DT)
    upright = _level((0.0, 0.0, 0.4))
    gusted = OwnState(np.array([0.0, 0.0, 0.4]), np.zeros(3), matrix_from_euler_zyx(0, 0.4, 0))
    for _ in range(40):
        guidance.observe(_observation(None, tof_m=0.4), upright)
    assert guidance.descend(_observation(None, tof_m=0.4), upright).velocity_h[2] < -0.2
    # leaning 23 deg: hold over the deck for the lull, at most max_flare_wait_s
    waits = [
        guidance.descend(_observation(None, tof_m=0.4), gusted).velocity_h[2] for _ in range(80)
    ]
    assert abs(waits[0]) < 0.05
    assert waits[-1] < -0.2  # after 3 s it lands all the same


@pytest.mark.parametrize(
    ("profile", "model", "lost_deck"),
    [
        ("range", "velocity", "descend"),
        ("timed", "velocity", "descend"),
        ("range", "acceleration", "descend"),
        ("timed", "acceleration", "search"),
    ],
)
def test_the_deck_frame_guidance_gives_finite_setpoints_for_any_observation(
    profile: str, model: str, lost_deck: str
) -> None:
    from hypothesis import given, settings
    from hypothesis import strategies as st

    finite = st.floats(-50.0, 50.0, allow_nan=False)
    angle = st.floats(-3.1, 3.1, allow_nan=False)

    @settings(max_examples=150, deadline=None, derandomize=True)
    @given(
        st.lists(
            st.tuples(
                st.tuples(finite, finite, finite, angle, st.floats(-1.5, 1.5), angle),
                st.booleans(),
                st.lists(st.floats(0.0, 4.0), min_size=4, max_size=4),
                st.lists(st.booleans(), min_size=4, max_size=4),
                st.tuples(st.floats(-0.7, 0.7), st.floats(-0.7, 0.7), angle),
            ),
            min_size=1,
            max_size=12,
        )
    )
    def run(steps) -> None:
        gains = GuidanceGains(
            track_deck=True,
            view_half_tan=0.558,
            blind_range_m=0.8,
            flare_range_m=0.5,
            descent_profile=profile,
            tracker_model=model,
            deck_lead_s=0.2 if model == "acceleration" else 0.0,
            lost_deck=lost_deck,
            # a short coast, so that a few unseen steps drop the track and start the search
            tracker_coast_s=0.1 if lost_deck == "search" else 1.5,
        )
        guidance = DeckGuidance(gains, DT)
        for pose, seen, ranges, valid, (roll, pitch, yaw) in steps:
            observation = {
                "deck_pose": np.array(pose, dtype=np.float32),
                "deck_pose_valid": np.array([int(seen)], dtype=np.int8),
                "tof_range": np.array(ranges, dtype=np.float32),
                "tof_valid": np.array(valid, dtype=np.int8),
            }
            own = OwnState(np.zeros(3), np.zeros(3), matrix_from_euler_zyx(roll, pitch, yaw))
            guidance.observe(observation, own)
            # descents in a row (a timed descent's clock runs), the bench law without the
            # drone's own state, then a hold (which restarts the clock)
            for setpoint in (
                guidance.descend(observation, own),
                guidance.descend(observation, own),
                guidance.descend(observation, None),
                guidance.hold(observation, 2.0, own),
            ):
                assert np.all(np.isfinite(setpoint.velocity_h))
                assert math.isfinite(setpoint.yaw_rate)

    run()


def test_realistic_sensing_loses_the_deck_in_a_gust_and_the_go_around_finds_it_again() -> None:
    """ship-ss4 through the standard lens (the ids up to v3), seed 1000007 of the evaluation:
    a gust leans the drone 25 deg at the 2 m hold, the tag and all four rays leave the 2 m
    pad; v2's guidance flies on down blind, past the pad's edge, until the descent times out;
    v3's climbs back over the deck's last track, finds it again and lands."""
    from agents.evaluation.landing import run_episode
    from agents.policies.registry import make_env_and_policy

    outcomes = {}
    for lost_deck in ("descend", "search"):
        env, policy = make_env_and_policy(
            "land-now",
            "ship-ss4",
            "tight",
            extra_overrides={
                # the v3 ids' start: level, the bench's controller limits
                **LEVEL_START,
                "sensors": "realistic",
                "lens": "standard",
                "timing.guidance.lost_deck": lost_deck,
                "timing.guidance.view_from_camera": False,
            },
        )
        try:
            outcomes[lost_deck] = run_episode(env, policy, 1_000_007, "land-now", "ship-ss4")
        finally:
            env.close()
    assert outcomes["descend"].outcome == "timeout"
    assert outcomes["search"].success


def test_a_warm_up_hold_that_ends_on_the_deck_is_reported_by_the_first_step_not_raised() -> None:
    """ship-ss5, realistic sensing, a 10 s history: in seed 6010 the heaving deck meets the
    drone during the warm-up hold.  reset returns an observation inside the space with
    ``info["hold_failed"]``; the first step, whatever its action, ends the episode with that
    outcome, no success bonus, and the evaluation counts it as ``hold_failed``."""
    from agents.evaluation.landing import run_episode
    from agents.policies.registry import make_env_and_policy
    from agents.training.sampler import make_timing_env

    # the v5 ids' start (level, the bench's controller limits): the deck meets the drone
    start = LEVEL_START
    env = make_timing_env("ship-ss5", "realistic", "tight", {"timing.history_s": 10.0, **start})
    try:
        observation, info = env.reset(seed=6010)
        assert info["hold_failed"] and info["outcome"] != "in_flight"
        assert env.observation_space.contains(observation)
        observation, reward, terminated, truncated, info = env.step(1)
        assert terminated and not truncated
        assert info["hold_failed"] and not info["is_success"]
        assert info["reward_success"] == 0.0 and reward < 0.0
        assert not info["committed"]
        assert env.observation_space.contains(observation)
        # the next episode starts cleanly
        _, info = env.reset(seed=6011)
        assert not info["hold_failed"] and info["outcome"] == "in_flight"
    finally:
        env.close()
    env, policy = make_env_and_policy(
        "land-now",
        "ship-ss5",
        "tight",
        extra_overrides={"sensors": "realistic", "timing.history_s": 10.0, **start},
    )
    try:
        result = run_episode(env, policy, 6010, "land-now", "ship-ss5")
    finally:
        env.close()
    assert result.outcome == "hold_failed" and not result.success


# ---------------------------------------------------------------- the bench law, unit by unit
_BENCH = GuidanceGains()


def _seen(x_c: float, y_c: float, z_c: float, yaw: float = 0.0, tof_m=None):
    """The tag at (x_c, y_c, z_c) in the camera frame, turned ``yaw`` from the drone."""
    observation = _observation((x_c, y_c, z_c), tof_m=tof_m)
    observation["deck_pose"][5] = yaw
    return observation


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    st.floats(-3.0, 3.0),
    st.floats(-3.0, 3.0),
    st.floats(0.2, 4.0),
    st.floats(-1.5, 1.5),
    st.floats(0.2, 4.0),
)
def test_the_bench_hold_centres_at_k_xy_within_the_speed_limit_and_closes_the_height_at_k_z(
    x_c: float, y_c: float, range_m: float, yaw: float, target_m: float
) -> None:
    g = _BENCH
    observation = _seen(x_c, y_c, 1.0, yaw, tof_m=range_m)
    setpoint = DeckGuidance(g, DT).hold(observation, target_m)
    x32, y32, range32, yaw32 = (float(np.float32(v)) for v in (x_c, y_c, range_m, yaw))
    # forward is up the image (-y_C), left is -x_C
    forward, left = g.k_xy * -y32, g.k_xy * -x32
    speed = math.hypot(forward, left)
    if speed > g.max_horizontal_speed:
        forward, left = (
            forward * g.max_horizontal_speed / speed,
            left * g.max_horizontal_speed / speed,
        )
    vz = float(np.clip(g.k_z * (target_m - range32), -g.max_vertical_speed, g.max_vertical_speed))
    np.testing.assert_allclose(setpoint.velocity_h, [forward, left, vz], rtol=1e-9, atol=1e-12)
    assert setpoint.yaw_rate == pytest.approx(-g.k_yaw * yaw32, rel=1e-9, abs=1e-12)


def test_the_range_is_the_four_rays_mean_else_the_tags_depth_else_the_valid_rays_mean() -> None:
    guidance = DeckGuidance(_BENCH, DT)
    observation = _seen(0.1, 0.2, 1.7, tof_m=1.0)
    observation["tof_range"][:] = [1.0, 1.2, 1.4, 1.8]
    assert guidance.range_m(observation) == pytest.approx(1.35)
    observation["tof_valid"][:] = [1, 0, 1, 0]
    assert guidance.range_m(observation) == pytest.approx(1.7)  # the tag, over two rays
    observation["deck_pose_valid"][0] = 0
    assert guidance.range_m(observation) == pytest.approx(1.2)  # the two valid rays
    observation["tof_valid"][:] = 0
    assert math.isnan(guidance.range_m(observation))
    assert guidance.horizontal_error(observation) is None
    # seen: (forward, left) = (-y_C, -x_C), as floats
    error = guidance.horizontal_error(_seen(0.25, -0.5, 1.0))
    assert error == (pytest.approx(0.5), pytest.approx(-0.25))
    assert all(type(e) is float for e in error)


def test_aligned_is_within_the_tolerance_plus_its_growth_with_the_height_and_never_unseen() -> None:
    gains = GuidanceGains(align_tolerance_m=0.1, align_tolerance_per_m=0.05)
    guidance = DeckGuidance(gains, DT)
    # at 2 m the tolerance is 0.1 + 0.05 x 2 = 0.2 m
    assert guidance.aligned(_seen(0.0, -0.199, 2.0, tof_m=2.0))
    assert not guidance.aligned(_seen(0.0, -0.201, 2.0, tof_m=2.0))
    # both axes count: 0.192 m and 0.208 m off on the diagonal
    assert guidance.aligned(_seen(-0.12, 0.15, 2.0, tof_m=2.0))
    assert not guidance.aligned(_seen(-0.12, 0.17, 2.0, tof_m=2.0))
    assert guidance.aligned(_seen(0.0, 0.19, 2.0, tof_m=2.0))
    # a negative range (a bad ray) does not shrink it below the tolerance at the deck
    assert guidance.aligned(_seen(0.099, 0.0, 1.0, tof_m=-1.0))
    assert not guidance.aligned(_seen(0.101, 0.0, 1.0, tof_m=-1.0))
    assert not guidance.aligned(_observation(None, tof_m=2.0))


def test_a_planned_descent_keeps_its_duration_within_0_2_to_10_s_and_a_reset_forgets_it() -> None:
    guidance = DeckGuidance(GuidanceGains(descent_time_s=1.5), DT)
    assert guidance.descent_time_s == 1.5
    for asked, kept in ((2.5, 2.5), (0.05, 0.2), (12.0, 10.0), (None, 1.5), (math.nan, 1.5)):
        guidance.plan_descent(3.0)
        guidance.plan_descent(asked)
        assert guidance.descent_time_s == kept
        assert type(guidance.descent_time_s) is float
    guidance.plan_descent(math.inf)
    assert guidance.descent_time_s == 1.5
    guidance.plan_descent(4.0)
    guidance.reset()
    assert guidance.descent_time_s == 1.5


def test_the_bench_hold_with_nothing_seen_holds_still_and_the_descent_falls_on_the_last_range() -> (
    None
):
    g = _BENCH
    guidance = DeckGuidance(g, DT)
    still = guidance.hold(_observation(None), 2.0)
    np.testing.assert_array_equal(still.velocity_h, [0.0, 0.0, 0.0])
    assert still.yaw_rate == 0.0
    # never a range: down at the touchdown speed
    blind = guidance.descend(_observation(None))
    np.testing.assert_array_equal(blind.velocity_h, [0.0, 0.0, -g.touchdown_speed])
    # the range schedule: descent_gain x range, between touchdown_speed and descent_speed
    for range_m, speed in ((0.1, g.touchdown_speed), (0.4, 0.6), (2.0, g.descent_speed)):
        setpoint = guidance.descend(_seen(0.0, -0.1, range_m, 0.2, tof_m=range_m))
        assert setpoint.velocity_h[2] == pytest.approx(-speed)
        if range_m > g.blind_range_m:  # centring above the blind range
            assert setpoint.velocity_h[0] == pytest.approx(g.k_xy * 0.1)
            assert setpoint.yaw_rate == pytest.approx(-g.k_yaw * float(np.float32(0.2)))
        else:  # straight down below it
            assert setpoint.velocity_h[0] == 0.0 and setpoint.yaw_rate == 0.0
    # everything lost: the last range's speed (2 m), and the hold's range is kept too
    assert guidance.descend(_observation(None)).velocity_h[2] == pytest.approx(-g.descent_speed)
    guidance.hold(_observation(None, tof_m=0.4), 2.0)
    lost = guidance.descend(_observation(None))
    assert lost.velocity_h[2] == pytest.approx(-0.6)
    np.testing.assert_array_equal(lost.velocity_h[:2], [0.0, 0.0])


# ---------------------------------------------------------------- the deck-frame law, unit by unit
def _tracked(
    gains: GuidanceGains,
    deck_w: tuple[float, float, float],
    deck_v_w: tuple[float, float, float],
    deck_a_w: tuple[float, float, float] = (0.0, 0.0, 0.0),
    own: OwnState | None = None,
    dt: float = DT,
) -> DeckGuidance:
    """A guidance whose tracker holds the deck at ``deck_w`` moving at ``deck_v_w`` (and
    accelerating at ``deck_a_w`` with the acceleration model), all three axes tracked; with
    ``own``, one observation of the tag from it first (its lean taken whole)."""
    guidance = DeckGuidance(gains, dt)
    if own is not None:
        guidance.observe(_observation((0.0, 0.0, 1.0)), own)
    tracker = guidance.tracker
    tracker.state[:, 0], tracker.state[:, 1] = deck_w, deck_v_w
    if tracker.order == 3:
        tracker.state[:, 2] = deck_a_w
    tracker.started[:] = True
    tracker.last_height_w = deck_w[2]
    return guidance


def _heading(v_w: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([c * v_w[0] + s * v_w[1], -s * v_w[0] + c * v_w[1], v_w[2]])


_XY = st.floats(-3.0, 3.0)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    st.tuples(_XY, _XY, st.floats(-1.0, 1.0)),
    st.tuples(_XY, _XY, st.floats(-1.0, 1.0)),
    st.tuples(_XY, _XY, _XY),
    st.tuples(_XY, _XY, st.floats(0.5, 4.0)),
    st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4), st.floats(-3.1, 3.1)),
    st.floats(0.0, 0.5),
    st.floats(0.3, 3.0),
)
def test_the_deck_frame_hold_is_the_led_deck_velocity_plus_the_limited_corrections_by_heading(
    deck_w, deck_v_w, deck_a_w, drone_w, attitude, lead_s: float, target_m: float
) -> None:
    """The set-point (world) is the deck's velocity ``deck_lead_s`` ahead, plus k_xy times the
    offset to the aim point (the deck, moved upwind by the height times the lean) plus the
    vertical speed times the lean, that sum held to max_horizontal_speed, plus the height's
    correction at k_z; then turned into the heading frame."""
    gains = GuidanceGains(track_deck=True, tracker_model="acceleration", deck_lead_s=lead_s)
    roll, pitch, yaw = attitude
    own = OwnState(np.array(drone_w), np.zeros(3), matrix_from_euler_zyx(roll, pitch, yaw))
    guidance = _tracked(gains, deck_w, deck_v_w, deck_a_w, own)
    lean = own.rotation_wb[:2, 2] / own.rotation_wb[2, 2]
    np.testing.assert_allclose(guidance.lean, lean, rtol=1e-12)
    setpoint = guidance.hold(_seen(0.0, 0.0, 1.0, 0.3), target_m, own)
    height = drone_w[2] - deck_w[2]
    vz = float(np.clip(gains.k_z * (target_m - height), -0.8, 0.8))
    aim = np.array(deck_w[:2]) + max(height, 0.0) * lean
    relative = gains.k_xy * (aim - np.array(drone_w[:2])) + vz * lean
    speed = float(np.hypot(*relative))
    if speed > gains.max_horizontal_speed:
        relative *= gains.max_horizontal_speed / speed
    v_w = np.array(deck_v_w) + lead_s * np.array(deck_a_w) + [*relative, vz]
    np.testing.assert_allclose(setpoint.velocity_h, _heading(v_w, yaw), rtol=1e-9, atol=1e-9)
    assert setpoint.yaw_rate == pytest.approx(-gains.k_yaw * float(np.float32(0.3)))
    assert guidance.tracked_range_m(own) == pytest.approx(height)
    # without the tag: no yaw rate; with the height track lost, no tracked range
    assert guidance.hold(_observation(None), target_m, own).yaw_rate == 0.0
    guidance.tracker.started[2] = False
    assert math.isnan(guidance.tracked_range_m(own))


def test_the_lean_is_low_passed_from_the_first_attitude_and_aims_the_camera_upwind() -> None:
    gains = GuidanceGains(track_deck=True, lean_filter_s=0.45)
    guidance = DeckGuidance(gains, DT)
    guidance.observe(_observation((0.0, 0.0, 2.0)), None)  # no own state: nothing learned
    assert not guidance.tracker.valid
    np.testing.assert_array_equal(guidance.lean, [0.0, 0.0])
    first = matrix_from_euler_zyx(0.0, 0.2, 0.0)  # nose down 0.2 rad: body z towards +x
    own = OwnState(np.array([0.0, 0.0, 2.0]), np.zeros(3), first)
    guidance.observe(_observation((0.0, 0.0, 2.0)), own)
    # the first attitude is taken whole: tan 0.2 forward
    np.testing.assert_allclose(guidance.lean, [math.tan(0.2), 0.0], atol=1e-12)
    second = OwnState(own.position_w, np.zeros(3), matrix_from_euler_zyx(-0.3, 0.0, 0.0))
    guidance.observe(_observation((0.0, 0.0, 2.0)), second)
    # then low-passed towards the new lean with alpha = dt / (lean_filter_s + dt) = 0.1
    z_b = second.rotation_wb[:, 2]
    target = z_b[:2] / z_b[2]
    np.testing.assert_allclose(
        guidance.lean, [math.tan(0.2), 0.0] + 0.1 * (target - [math.tan(0.2), 0.0]), atol=1e-12
    )
    # leaning past 60 deg counts as 60 deg's slope over cos 60 (0.5): no blow-up
    over = OwnState(own.position_w, np.zeros(3), matrix_from_euler_zyx(0.0, 1.4, 0.0))
    fresh = DeckGuidance(gains, DT)
    fresh.observe(_observation((0.0, 0.0, 2.0)), over)
    np.testing.assert_allclose(fresh.lean, [math.sin(1.4) / 0.5, 0.0], atol=1e-12)
    # the lean given out is a copy
    fresh.lean[:] = 9.0
    assert fresh.lean[0] == pytest.approx(math.sin(1.4) / 0.5)


@pytest.mark.parametrize(
    ("tag_c", "tof_m", "vertical"),
    [
        ((0.0, 0.0, 2.0), 2.0, -0.8),  # well inside the view: the full 0.8 m/s
        ((0.8, 0.0, 2.0), 2.0, -0.8 * 0.0375),  # room 0.083 of a 0.08 margin: nearly stopped
        ((0.0, -0.726, 2.0), 2.0, -0.8 * 0.5),  # the room 0.12, half the margin past it: half
        ((-0.886, 0.0, 2.0), 2.0, 0.8 * 0.5),  # room 0.04: climbing at half the speed
        ((1.5, 1.5, 2.0), 2.0, 0.8),  # far out: climbing at the full speed
        ((1.5, 1.5, 2.0), 2.6, 0.0),  # but not above max_search_range_m (2.5 m)
        ((0.0, 0.0, 2.6), 2.6, -0.8),  # where it still descends
        ((0.0, 0.0, 0.9), 0.9, -0.8),  # a tag nearer than 1 m, well inside the view
        ((0.3, 0.0, 0.0), 2.0, 0.0),  # a tag at no depth: held
        ((0.3, 0.0, -1.0), 2.0, 0.0),
        ((1.5, 0.0, 2.0), 0.4, -0.6),  # below blind_range_m: no gate, on down at 1.5 x 0.4
    ],
)
def test_the_descent_slows_from_twice_the_view_margin_to_a_stop_at_it_and_climbs_beyond(
    tag_c: tuple[float, float, float], tof_m: float, vertical: float
) -> None:
    """The gate's factor: the tag's farthest corner (its centre's larger tangent plus the
    half size over the depth) against view_half_tan = 0.558, margin 0.08: 1 with twice the
    margin to spare, down to 0 at the margin and -1 at the edge, times the range schedule's
    speed (1.5 x range, at most 0.8 m/s)."""
    gains = GuidanceGains(track_deck=True, view_half_tan=0.558, blind_range_m=0.8)
    own = _level((0.0, 0.0, 2.0))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=own)
    setpoint = guidance.descend(_seen(*tag_c, 0.2, tof_m=tof_m), own)
    assert setpoint.velocity_h[2] == pytest.approx(vertical, abs=2e-3)
    # turning towards the tag only above the blind range
    expected_yaw = -gains.k_yaw * float(np.float32(0.2)) if tof_m > 0.8 else 0.0
    assert setpoint.yaw_rate == pytest.approx(expected_yaw)


def test_the_view_gate_is_off_at_a_zero_half_view_or_without_the_tag_and_climbs_timed_slowly() -> (
    None
):
    own = _level((0.0, 0.0, 2.0))
    off = _tracked(GuidanceGains(track_deck=True), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=own)
    assert off.descend(_seen(1.5, 1.5, 2.0, tof_m=2.0), own).velocity_h[2] == pytest.approx(-0.8)
    gains = GuidanceGains(track_deck=True, view_half_tan=0.558, blind_range_m=0.8)
    unseen = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=own)
    tag_lost = _observation(None, tof_m=2.0)
    tag_lost["deck_pose"][:3] = (1.5, 1.5, 2.0)  # a stale pose, not valid
    assert unseen.descend(tag_lost, own).velocity_h[2] == pytest.approx(-0.8)
    # the timed profile climbs at the factor times the touchdown speed and restarts its clock
    timed = GuidanceGains(
        track_deck=True, view_half_tan=0.558, blind_range_m=0.8, descent_profile="timed"
    )
    guidance = _tracked(timed, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=own)
    guidance.descend(_seen(0.0, 0.0, 2.0, tof_m=2.0), own)
    assert guidance._descent_clock_s == pytest.approx(DT)
    # half way into the margin: half the timed speed, and its clock runs at half speed
    reference, _ = timed_descent_reference(DT, 2.0, 1.2, 0.25, 0.05)
    _, rate = timed_descent_reference(DT + 0.2, 2.0, 1.2, 0.25, 0.05)
    timed_speed = float(np.clip(-rate + 3.0 * (2.0 - reference), 0.0, 0.8))
    half = guidance.descend(_seen(0.0, -0.726, 2.0, tof_m=2.0), own).velocity_h[2]
    assert half == pytest.approx(-0.5 * timed_speed, abs=2e-3)
    assert guidance._descent_clock_s == pytest.approx(1.5 * DT, abs=1e-4)
    # at the margin (a tag at no depth: held), the clock stops
    assert guidance.descend(_seen(0.3, 0.0, 0.0, tof_m=2.0), own).velocity_h[2] == 0.0
    assert guidance._descent_clock_s == pytest.approx(1.5 * DT, abs=1e-4)
    climb = guidance.descend(_seen(-0.886, 0.0, 2.0, tof_m=2.0), own).velocity_h[2]
    assert climb == pytest.approx(0.5 * timed.touchdown_speed, abs=2e-3)
    assert guidance._descent_clock_s is None
    # the tag lost above the blind range: the climb restarts the timed descent too
    guidance.descend(_seen(0.0, 0.0, 2.0, tof_m=2.0), own)
    assert guidance._descent_clock_s == pytest.approx(DT)
    for _ in range(7):
        guidance.observe(_observation(None, tof_m=2.0), own)
    lost = guidance.descend(_observation(None, tof_m=2.0), own).velocity_h[2]
    assert lost == pytest.approx(timed.lost_tag_climb_speed)
    assert guidance._descent_clock_s is None


def test_near_the_deck_the_gust_wait_lasts_max_flare_wait_s_and_only_below_flare_range_m() -> None:
    gains = GuidanceGains(
        track_deck=True, blind_range_m=0.8, flare_range_m=0.5, max_touchdown_lean_deg=18.0
    )
    gusted = OwnState(np.array([0.0, 0.0, 0.4]), np.zeros(3), matrix_from_euler_zyx(0, 0.4, 0))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=gusted)
    # above the flare range a lean does not hold the descent
    assert guidance.descend(_observation(None, tof_m=0.6), gusted).velocity_h[2] < -0.5
    waits = [
        guidance.descend(_observation(None, tof_m=0.4), gusted).velocity_h[2] for _ in range(62)
    ]
    # 3 s of waiting (60 control periods of 50 ms), then on down
    assert all(w == pytest.approx(0.0, abs=1e-12) for w in waits[:59])
    assert waits[-1] < -0.5
    # upright again: no wait
    upright = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=_level((0, 0, 0.4)))
    assert upright.descend(_observation(None, tof_m=0.4), _level((0, 0, 0.4))).velocity_h[2] < -0.5


def test_the_gust_wait_and_the_lost_tag_pause_count_whole_periods_up_to_their_limits() -> None:
    """With a control period that adds up exactly (0.25 s), the gust wait holds the descent for
    max_flare_wait_s (four periods of 1 s), never a period more, and the tag unseen pauses the
    descent only once unseen for longer than lost_tag_pause_s (the third period of 0.5 s)."""
    gains = GuidanceGains(
        track_deck=True,
        blind_range_m=0.8,
        flare_range_m=0.5,
        max_flare_wait_s=1.0,
        lost_tag_pause_s=0.5,
    )
    gusted = OwnState(np.array([0.0, 0.0, 0.4]), np.zeros(3), matrix_from_euler_zyx(0, 0.4, 0))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=gusted, dt=0.25)
    waits = [
        guidance.descend(_observation(None, tof_m=0.4), gusted).velocity_h[2] for _ in range(5)
    ]
    assert waits[:4] == [pytest.approx(0.0, abs=1e-12)] * 4
    assert waits[4] < -0.1
    own = _level((0.0, 0.0, 2.0))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=own, dt=0.25)
    vertical = []
    for _ in range(3):
        guidance.observe(_observation(None, tof_m=2.0), own)
        vertical.append(guidance.descend(_observation(None, tof_m=2.0), own).velocity_h[2])
    assert vertical[0] < -0.5 and vertical[1] < -0.5
    assert vertical[2] == pytest.approx(gains.lost_tag_climb_speed)


def test_an_attitude_rounded_a_hair_past_level_or_upside_down_still_gives_a_setpoint() -> None:
    """The lean's cosine (the rotation's z-z entry) is clipped to [-1, 1] before its arc
    cosine: a rotation rounded to 1 + 2e-16 is level (no gust wait), one rounded to
    -1 - 2e-16 is upside down (a lean of 180 deg: the wait holds)."""
    gains = GuidanceGains(track_deck=True, blind_range_m=0.8, flare_range_m=0.5)
    past = 1.0 + 2.0**-52
    level = OwnState(np.array([0.0, 0.0, 0.4]), np.zeros(3), np.eye(3) * past)
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=_level((0, 0, 0.4)))
    assert guidance.descend(_observation(None, tof_m=0.4), level).velocity_h[2] < -0.1
    flipped = OwnState(np.array([0.0, 0.0, 0.4]), np.zeros(3), np.diag([1.0, -past, -past]))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=_level((0, 0, 0.4)))
    assert guidance.descend(_observation(None, tof_m=0.4), flipped).velocity_h[2] == 0.0


def test_the_rate_gain_holds_the_relative_speed_to_a_moving_decks_track() -> None:
    """A deck rising at 0.5 m/s, the drone near it (the plan: 0.25 m/s down relative to it)
    rising at 0.25 m/s: on plan, no correction; rising with the deck: pushed down."""
    gains = GuidanceGains(track_deck=True, touchdown_speed=0.25, descent_rate_gain=1.0)
    for drone_vz, expected in ((0.25, 0.25), (0.5, 0.0)):
        own = _level((0.0, 0.0, 0.1), velocity=(0.0, 0.0, drone_vz))
        guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.5), own=own)
        setpoint = guidance.descend(_observation(None, tof_m=0.1), own).velocity_h[2]
        assert setpoint == pytest.approx(expected, abs=1e-9)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    st.lists(st.floats(-0.2, 3.0), min_size=1, max_size=30),
    st.floats(0.5, 3.0),
    st.floats(0.0, 0.5),
    st.floats(0.0, 8.0),
)
def test_the_timed_descent_feeds_the_references_rate_forward_by_its_lead_and_corrects_its_height(
    heights_m: list[float], duration_s: float, lead_s: float, track_gain: float
) -> None:
    """From the first height (at least contact_range_m), the reference of
    ``timed_descent_reference``: the speed is minus its rate ``descent_lead_s`` ahead plus
    ``descent_track_gain`` times the height above it, between 0 and max_vertical_speed; its
    clock runs one control period a call."""
    gains = GuidanceGains(
        descent_profile="timed",
        descent_time_s=duration_s,
        descent_lead_s=lead_s,
        descent_track_gain=track_gain,
        contact_range_m=0.05,
        blind_range_m=5.0,  # no centring: the vertical speed alone
    )
    guidance = DeckGuidance(gains, DT)
    start = max(float(np.float32(heights_m[0])), 0.05)
    for k, height in enumerate(heights_m):
        height32 = float(np.float32(height))
        setpoint = guidance.descend(_observation(None, tof_m=height))
        reference, _ = timed_descent_reference(k * DT, start, duration_s, 0.25, 0.05)
        _, rate = timed_descent_reference(k * DT + lead_s, start, duration_s, 0.25, 0.05)
        speed = float(np.clip(-rate + track_gain * (height32 - reference), 0.0, 0.8))
        assert setpoint.velocity_h[2] == pytest.approx(-speed, abs=1e-9)
        assert guidance._descent_clock_s == pytest.approx((k + 1) * DT)


def test_the_go_around_climbs_over_the_decks_last_height_aimed_along_its_coasting_track() -> None:
    """The height track lost above blind_range_m: the set-point is the deck's horizontal
    velocity (its stale heave rate dropped) plus k_xy times the offset to the aim point
    (upwind of the deck by the height over its last tracked height times the lean), and a
    climb at lost_tag_climb_speed up to max_search_range_m over that height, by heading."""
    gains = GuidanceGains(track_deck=True, lost_deck="search")
    attitude = matrix_from_euler_zyx(0.1, -0.15, 0.5)
    own = OwnState(np.array([0.2, 0.1, 1.5]), np.zeros(3), attitude)
    guidance = _tracked(gains, (0.4, -0.3, 0.3), (0.2, 0.1, 0.5), own=own)
    lean = attitude[:2, 2] / attitude[2, 2]
    # while the deck is tracked, the hold is the tracked hold, as without the search
    plain = _tracked(GuidanceGains(track_deck=True), (0.4, -0.3, 0.3), (0.2, 0.1, 0.5), own=own)
    np.testing.assert_array_equal(
        guidance.hold(_observation(None), 2.0, own).velocity_h,
        plain.hold(_observation(None), 2.0, own).velocity_h,
    )
    guidance.tracker.started[2] = False  # the height track lost, its last height 0.3 m
    for setpoint in (
        guidance.hold(_observation(None), 2.0, own),
        guidance.descend(_seen(0, 0, 1), own),
    ):
        above = 1.5 - 0.3
        climb = gains.lost_tag_climb_speed
        aim = np.array([0.4, -0.3]) + above * lean
        relative = gains.k_xy * (aim - [0.2, 0.1]) + climb * lean
        v_w = np.array([0.2 + relative[0], 0.1 + relative[1], climb])
        np.testing.assert_allclose(setpoint.velocity_h, _heading(v_w, 0.5), atol=1e-12)
        assert setpoint.yaw_rate == 0.0
        assert guidance._descent_clock_s is None
    # at max_search_range_m over the last height: no higher
    high = OwnState(np.array([0.2, 0.1, 0.3 + gains.max_search_range_m]), np.zeros(3), attitude)
    assert guidance.hold(_observation(None), 2.0, high).velocity_h[2] == pytest.approx(0.0)
    # and the horizontal track lost too: the drone holds its place while it climbs
    guidance.tracker.started[0] = False
    lost = guidance.descend(_observation(None), own).velocity_h
    np.testing.assert_allclose(lost, [0.0, 0.0, gains.lost_tag_climb_speed], atol=1e-12)


def test_a_deck_tracked_by_its_ranges_alone_is_followed_in_height_at_its_heave_rate() -> None:
    """No tag yet (the horizontal track never started): the set-point holds the drone's place
    horizontally, and vertically follows the deck's heave rate plus the height's correction."""
    gains = GuidanceGains(track_deck=True)
    guidance = _tracked(gains, (0.0, 0.0, 0.2), (0.3, -0.2, 0.5))
    guidance.tracker.started[:2] = False
    own = OwnState(np.array([1.0, 2.0, 2.0]), np.zeros(3), matrix_from_euler_zyx(0.0, 0.0, 0.7))
    setpoint = guidance.hold(_observation(None, tof_m=1.8), 1.5, own)
    vz = 0.5 + gains.k_z * (1.5 - 1.8)
    np.testing.assert_allclose(setpoint.velocity_h, [0.0, 0.0, vz], atol=1e-12)


def test_a_guidance_built_without_a_period_runs_at_the_simulations_default_rate() -> None:
    assert DeckGuidance().dt == 1.0 / SimulationConfig().env_hz


def test_the_deck_tracker_takes_the_guidances_jerk_density() -> None:
    gains = GuidanceGains(track_deck=True, tracker_model="acceleration", tracker_jerk_psd=7.5)
    assert DeckGuidance(gains, DT).tracker.jerk_psd == 7.5
    assert DeckGuidance(GuidanceGains(), DT).tracker.jerk_psd == GuidanceGains().tracker_jerk_psd


@pytest.mark.parametrize("limit_m_s", [0.4, 2.5])
def test_the_bench_centring_keeps_the_tags_direction_at_any_speed_limit(limit_m_s: float) -> None:
    gains = GuidanceGains(max_horizontal_speed=limit_m_s)
    # the tag 3 m forward and 1.5 m right of the camera: (forward, left) = (3, -1.5)
    setpoint = DeckGuidance(gains, DT).hold(_seen(1.5, -3.0, 1.0, tof_m=2.0), 2.0)
    forward, left = setpoint.velocity_h[:2]
    assert math.hypot(forward, left) == pytest.approx(limit_m_s)
    assert left / forward == pytest.approx(-0.5)


def test_with_no_lean_allowed_a_level_drone_still_descends_and_any_lean_waits() -> None:
    gains = GuidanceGains(
        track_deck=True, blind_range_m=0.8, flare_range_m=0.5, max_touchdown_lean_deg=0.0
    )
    level = _level((0.0, 0.0, 0.4))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=level)
    assert guidance.descend(_observation(None, tof_m=0.4), level).velocity_h[2] < -0.5
    tipped = OwnState(np.array([0.0, 0.0, 0.4]), np.zeros(3), matrix_from_euler_zyx(0, 0.01, 0))
    guidance = _tracked(gains, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), own=tipped)
    assert guidance.descend(_observation(None, tof_m=0.4), tipped).velocity_h[2] == pytest.approx(
        0.0, abs=1e-12
    )
