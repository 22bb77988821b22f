"""The SVGS comparison like for like (paper 003): the landing-target filter and its gate in
standard deviations, the fusion's gate in standard deviations, the IR beacon's range, the 20
searches, the paper's landing-error metric and the svgs-100m scenario."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.evaluation.approach import landing_error_p
from agents.policies.beacon_range import BeaconRangeConfig, BeaconRangePolicy, PrecLandState
from estimation.beacon import (
    BEYOND_BEACON_RANGE,
    IR_LOCK_MAX_RANGE_M,
    BeaconConfig,
    BeaconEstimator,
)
from estimation.camera_model import CameraIntrinsics
from estimation.errors import ConfigError
from estimation.frames import R_PD, tag_corners_in_tag_frame
from estimation.fusion.config import PAPER_GATE_SD, FusionConfig, nis_gate
from estimation.landing_target import (
    ACCEPTED,
    INITIALISED,
    INVALID_INPUT,
    REJECTED,
    LandingTargetConfig,
    LandingTargetFilter,
)
from estimation.types import CameraFrame, RangeReading, TagDetection
from landing_env.config import load_config
from landing_env.vision_link import VisionLinkConfig
from tests.agents.policies.test_svgs_routine import observation


def settled_filter(config: LandingTargetConfig | None = None) -> LandingTargetFilter:
    """A filter that has tracked a target at (3, -1) m for a while (hovering vehicle)."""
    target = LandingTargetFilter(config)
    for _ in range(100):
        target.predict(np.zeros(2), 0.05)
        assert target.update(np.array([3.0, -1.0]), 10.0) in (ACCEPTED, INITIALISED)
    return target


def fix_at_sd(target: LandingTargetFilter, sd: float, distance_m: float) -> np.ndarray:
    """A fix ``sd`` innovation standard deviations off the estimate along x."""
    sigma = math.sqrt(target.covariance[0, 0, 0] + target.measurement_sigma_m(distance_m) ** 2)
    return target.position_xy + np.array([sd * sigma, 0.0])


@pytest.mark.parametrize(("sd", "expected"), [(9.0, ACCEPTED), (11.0, REJECTED)])
def test_landing_target_gate_of_10_sd_accepts_9_and_rejects_11(sd: float, expected: str) -> None:
    target = settled_filter()
    assert target.config.gate_sd == PAPER_GATE_SD == 10.0
    target.predict(np.zeros(2), 0.05)
    before = target.position_xy
    fix = fix_at_sd(target, sd, 10.0)
    assert target.innovation_sd(fix, 10.0)[0] == pytest.approx(sd)
    assert target.update(fix, 10.0) == expected
    moved = float(np.linalg.norm(target.position_xy - before))
    assert (moved > 0.0) if expected == ACCEPTED else (moved == 0.0 and target.rejections == 1)


def test_landing_target_filter_follows_the_vehicle_acceleration_between_fixes() -> None:
    target = settled_filter()
    # the vehicle accelerates at 1 m/s^2 towards +x for 1 s without a fix: the target, still
    # in the world, comes 0.5 m closer in x and moves at -1 m/s relative to the vehicle
    for _ in range(20):
        target.predict(np.array([1.0, 0.0]), 0.05)
    assert target.position_xy == pytest.approx([2.5, -1.0], abs=0.02)
    assert target.velocity_xy == pytest.approx([-1.0, 0.0], abs=0.02)
    assert target.valid
    for _ in range(30):  # past the 2 s timeout without a fix: invalid, re-initialised by one
        target.predict(np.zeros(2), 0.05)
    assert not target.valid
    assert target.update(np.array([0.0, 0.0]), 5.0) == INITIALISED and target.valid


@pytest.mark.parametrize(
    "fix", [np.array([np.nan, 0.0]), np.array([np.inf, 1.0]), np.array([1.0, 2.0, 3.0])]
)
def test_landing_target_filter_ignores_bad_input_without_raising(fix: np.ndarray) -> None:
    target = settled_filter()
    before = target.position_xy
    assert target.update(fix, 10.0) == INVALID_INPUT
    assert target.update(np.zeros(2), math.nan) == INVALID_INPUT
    assert not target.predict(np.array([math.nan, 0.0]), 0.05)  # constant velocity instead
    assert target.predict(np.zeros(2), -1.0) is False
    assert np.allclose(target.position_xy, before, atol=1e-9)
    with pytest.raises(ConfigError, match="gate_sd"):
        LandingTargetConfig(gate_sd=0.0)


def test_fusion_gate_in_standard_deviations_replaces_the_chi_square_gate() -> None:
    default = FusionConfig()
    # the chi-square 0.9995 gate of one degree of freedom is 3.5 SD
    assert math.sqrt(default.gate(1)) == pytest.approx(3.48, abs=0.01)
    paper = FusionConfig(gate_sd=PAPER_GATE_SD)
    assert [paper.gate(dof) for dof in (1, 3, 6)] == [100.0, 100.0, 100.0]
    assert nis_gate(2, 0.9995, 9.0) < 10.0**2 < nis_gate(2, 0.9995, 11.0)
    with pytest.raises(ConfigError, match="gate_sd"):
        FusionConfig(gate_sd=-1.0)


def test_vision_link_latency_is_the_papers_175_to_230_ms() -> None:
    link = VisionLinkConfig()
    low, high = link.latency_s - link.latency_jitter_s, link.latency_s + link.latency_jitter_s
    assert (low, high) == pytest.approx((0.175, 0.230))


def test_beacon_is_seen_only_within_its_range() -> None:
    camera = CameraIntrinsics()
    assert BeaconConfig().max_range_m == IR_LOCK_MAX_RANGE_M == 40.0

    def estimate(height_m: float, config: BeaconConfig | None = None):
        t_cd = np.array([0.5, -0.3, height_m])
        corners = camera.project(tag_corners_in_tag_frame(3.0) + t_cd)
        frame = CameraFrame(1.0, (TagDetection(0, corners),))
        reading = RangeReading(1.0, np.array([height_m]), np.array([True]))
        return BeaconEstimator(camera, 0, lambda: reading, config).estimate(frame, reading)

    assert estimate(39.0).valid
    far = estimate(45.0)
    assert not far.valid and far.reason == BEYOND_BEACON_RANGE
    assert estimate(45.0, BeaconConfig(max_range_m=60.0)).valid
    with pytest.raises(ConfigError, match="max_range_m"):
        BeaconConfig(max_range_m=0.0)
    config = load_config("high-approach", {"estimation.beacon.max_range_m": 25.0})
    assert config.estimation.beacon.max_range_m == 25.0


def test_beacon_range_searches_20_times_before_landing_in_place() -> None:
    assert BeaconRangeConfig().max_searches == 20
    policy = BeaconRangePolicy(dt=0.1, config=BeaconRangeConfig(search_timeout_s=0.5))
    for _ in range(2000):  # never a beacon, hovering at the search height
        policy(observation(None, range_down=20.0))
        if policy.state is PrecLandState.FALLBACK:
            break
    reasons = [reason for _, _, reason in policy.transitions]
    assert policy.state is PrecLandState.FALLBACK and policy.searches == 20
    assert "searches exhausted" in reasons[-1]


def test_beacon_range_search_descends_to_the_search_height_from_above() -> None:
    policy = BeaconRangePolicy(dt=0.1)
    for _ in range(30):  # no beacon at 35 m (range known): beacon lost, search
        action = policy(observation(None, range_down=35.0))
    assert policy.state is PrecLandState.SEARCH and action[2] < 0.0
    for _ in range(30):  # above the rangefinder's reach: no height, still descends
        action = policy(observation(None))
    assert action[2] < 0.0


def test_landing_error_is_commanded_minus_actual_in_the_deck_plate_frame() -> None:
    deck = np.array([10.0, -4.0, 0.5])
    level = np.zeros(3)
    # the drone touched down 0.3 m along +x_P and 0.1 m along -y_P of the deck centre
    drone = deck + np.array([0.3, -0.1, 0.2])
    assert landing_error_p(np.zeros(2), drone, deck, level) == pytest.approx([-0.3, 0.1])
    # a commanded point 1 m along x_D is R_PD (1, 0, 0) in P
    commanded_p = (R_PD @ np.array([1.0, 0.0, 0.0]))[:2]
    expected = commanded_p - np.array([0.3, -0.1])
    assert landing_error_p(np.array([1.0, 0.0]), drone, deck, level) == pytest.approx(expected)
    # a yawed deck: the same world offset seen in the plate's axes
    yawed = np.array([0.0, 0.0, math.pi / 2])
    assert landing_error_p(np.zeros(2), drone, deck, yawed) == pytest.approx([0.1, 0.3])


def test_svgs_100m_scenario_is_the_papers_setup() -> None:
    config = load_config("svgs-100m")
    assert config.start.height_m == (101.65, 106.65)
    assert (config.start.min_offset_m, config.start.max_offset_m) == (1.6, 5.0)
    assert config.motion.kind == "static"
    sizes = sorted(lm.size for lm in config.deck.layout.landmarks)
    # each tag decodes (12 px at fx 458.5) up to the top of its Table 3 range: 20, 85, 200 m
    decode_m = [size * config.camera.fx / config.camera.min_tag_side_px for size in sizes]
    assert decode_m == pytest.approx([20.0, 85.0, 200.0], rel=0.01)
    assert config.estimation.fusion.gate_sd == 10.0
    assert config.estimation.beacon.max_range_m == 40.0
    link = config.estimation.vision_link
    assert link.latency_s - link.latency_jitter_s == pytest.approx(0.175)
    assert link.latency_s + link.latency_jitter_s == pytest.approx(0.230)
    assert config.camera.far >= 200.0 and config.simulation.arena_max_height_m > 106.65
    irlock = load_config("svgs-100m-irlock")
    assert irlock.start.height_m == (53.11, 54.95) and irlock.deck.size == config.deck.size
