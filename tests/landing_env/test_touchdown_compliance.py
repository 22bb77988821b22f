"""Compliant landing gear: every touchdown check can fail, each for a physical reason.

A drone dropped disarmed onto the deck (World, no controller) at a chosen normal speed; the
deck either still or rolling.  Figures of the shipped gear (quadrotor.yaml landing_gear):
restitution about 0.25, a few millimetres of deflection, a 1 m/s touchdown that bounces.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from landing_env.config import load_config
from landing_env.physics.controller import VelocitySetpoint
from landing_env.touchdown import Outcome, TouchdownMetrics, evaluate_touchdown
from landing_env.world import World

#: feet bottoms 4 mm above the deck when the drone's centre is this high above it
CLEARANCE_CENTRE_M = 0.084


class RollingDeck:
    """A deck ``arm_m`` above the vessel's roll axis rolling sinusoidally, level and at its
    peak rate at t = 0 (a motion source: pose relative to home, m and rad)."""

    def __init__(self, rate_deg_s: float, omega: float, arm_m: float) -> None:
        self.amplitude = math.radians(rate_deg_s) / omega
        self.omega = omega
        self.arm = arm_m

    def pose(self, t: float) -> np.ndarray:
        phi = self.amplitude * math.sin(self.omega * t)
        return np.array([0.0, -self.arm * math.sin(phi), self.arm * (math.cos(phi) - 1), phi, 0, 0])

    def velocity(self, t: float) -> np.ndarray:
        phi = self.amplitude * math.sin(self.omega * t)
        rate = self.amplitude * self.omega * math.cos(self.omega * t)
        arm = self.arm
        return np.array([0.0, -arm * math.cos(phi) * rate, -arm * math.sin(phi) * rate, rate, 0, 0])


def drop(
    speed: float,
    motion: RollingDeck | None = None,
    yaw: float = 0.0,
    friction: float | None = None,
    roll_deg: float = 0.0,
    **touchdown: float,
) -> tuple[Outcome, TouchdownMetrics, World]:
    overrides = {f"touchdown.{k}": v for k, v in touchdown.items()}
    no_wind = {"motion.kind": "static", "wind.enabled": False}
    config = load_config("ship-ss4", overrides={**no_wind, **overrides})
    world = World(config)
    if friction is not None:
        for foot in world.foot_links:
            world.client.changeDynamics(world.drone.body_id, foot, lateralFriction=friction)
    world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 2.0]), 0.0)
    if motion is not None:
        world.stewart.motion = motion
        world.stewart.reset(0.0)
    deck = world.deck_state().position_w
    start = deck + np.array([0.0, 0.0, CLEARANCE_CENTRE_M])
    world.drone.reset(start, yaw, velocity_w=(0.0, 0.0, -speed))
    if roll_deg:
        half = math.radians(roll_deg) / 2
        world.client.resetBasePositionAndOrientation(
            world.drone.body_id,
            start + np.array([0.0, 0.0, 0.02]),
            (math.sin(half), 0, 0, math.cos(half)),
        )
    world._state = world.drone.read_state()  # the world caches the state between its steps
    world.disarm()
    world.drone.set_rotor_speeds(np.full(4, world.params.omega_min))
    outcome, metrics = touch_and_settle(world, VelocitySetpoint(np.zeros(3), 0.0))
    return outcome, metrics, world


def touch_and_settle(world: World, setpoint: VelocitySetpoint) -> tuple[Outcome, TouchdownMetrics]:
    """Fly ``setpoint`` down to the first contact (within 20 control periods), settle and
    judge the touchdown as the environment does."""
    for _ in range(20):
        report = world.step(setpoint)
        if report.first_contact is not None:
            break
    metrics = report.first_contact
    assert metrics is not None
    feet, on_deck, _, _ = world.settle(world.config.touchdown.settle_time_s, setpoint)
    metrics.all_feet_touched = feet == set(world.foot_links)
    metrics.on_deck_after_settle = on_deck
    return evaluate_touchdown(metrics, world.config.touchdown)


def test_a_gentle_touchdown_on_a_still_deck_succeeds_with_millimetres_of_compression() -> None:
    outcome, metrics, world = drop(0.3)
    assert outcome is Outcome.SUCCESS, metrics.failed_checks
    assert metrics.bounce_height_m < 1e-3
    assert 1.5 < metrics.peak_load_g < 8.0  # the rigid contact gave a 12 g spike
    assert not metrics.tipped_over and metrics.max_settle_attitude_deg < 2.0
    world.close()


def test_a_one_metre_per_second_touchdown_bounces() -> None:
    _, metrics, world = drop(1.0)
    world.close()
    assert metrics.relative_normal_speed == pytest.approx(1.0, abs=0.1)
    assert metrics.bounce_height_m > 0.0  # all four feet left the deck again
    assert "relative_normal_speed" in metrics.failed_checks
    # a stricter bounce limit fails on the bounce itself
    _, strict, world = drop(1.0, max_bounce_m=1e-4)
    world.close()
    assert "bounce" in strict.failed_checks
    # a 3 m/s crash-landing bounces centimetres and fails the default limit (1 cm)
    _, hard, world = drop(3.0)
    world.close()
    assert hard.bounce_height_m > 0.01 and "bounce" in hard.failed_checks


def test_gear_restitution_and_deflection_are_those_documented() -> None:
    _, metrics, world = drop(1.0)
    world.close()
    # rebound speed from the bounce height: (e v)^2 / 2g -> e within 0.1..0.35 (measured 0.25
    # from the rebound velocity; the height also loses the spring's unloading)
    e = math.sqrt(2 * 9.81 * metrics.bounce_height_m) / metrics.relative_normal_speed
    assert 0.02 < e < 0.35
    # the four feet carry ~9-10 g at 1 m/s (the rigid contact: about 25 g)
    assert 5.0 < metrics.peak_load_g < 14.0


def test_a_touchdown_on_a_deck_rolling_at_ten_degrees_per_second_can_tip_the_drone_over() -> None:
    # the deck 10 m above the roll axis sweeps sideways at 1.75 m/s; gripping feet (friction 1,
    # rubber on an anti-slip coating) with the sway across the support polygon's edge (yaw 45)
    rolling = RollingDeck(rate_deg_s=10.0, omega=1.0, arm_m=10.0)
    outcome, metrics, world = drop(0.3, rolling, yaw=math.pi / 4, friction=1.0)
    world.close()
    assert metrics.relative_tangential_speed == pytest.approx(1.75, abs=0.1)
    assert metrics.relative_normal_speed < 0.5 and metrics.deck_tilt_deg < 1.0
    assert outcome is Outcome.HARD_LANDING
    assert metrics.tipped_over and "tip_over" in metrics.failed_checks
    # the same touchdown on a still deck stands
    outcome, still, world = drop(0.3, yaw=math.pi / 4, friction=1.0)
    world.close()
    assert outcome is Outcome.SUCCESS and not still.tipped_over


def test_a_tilted_deck_and_a_rolling_contact_fail_their_own_checks() -> None:
    # touching down as the deck passes 8 deg of roll (its amplitude): over the 5 deg deck-tilt
    # limit, inside the 10 deg drone-to-deck limit for a level drone
    class Tilted(RollingDeck):
        def pose(self, t: float) -> np.ndarray:
            return super().pose(t + 0.5 * math.pi / self.omega)

        def velocity(self, t: float) -> np.ndarray:
            return super().velocity(t + 0.5 * math.pi / self.omega)

    outcome, metrics, world = drop(0.3, Tilted(8.0, 1.0, 3.0))
    world.close()
    assert outcome is Outcome.HARD_LANDING
    assert "deck_tilt" in metrics.failed_checks and "relative_attitude" not in metrics.failed_checks
    assert metrics.deck_tilt_deg == pytest.approx(8.0, abs=0.5)
    # the deck's vertical acceleration at contact is measured (MSI-style), in g
    assert math.isfinite(metrics.deck_vertical_accel_g)


def test_a_drone_leaning_15_deg_is_inside_the_ship_gear_envelope_but_not_the_bench_limit() -> None:
    # the ship decks judge the attitude by the gear's clearance angle (40 deg, ship-ss4.yaml):
    # the lean a 0.8 kg drone needs in sea state 4's wind passes, and the contact decides
    outcome, metrics, world = drop(0.3, roll_deg=15.0)
    world.close()
    assert metrics.relative_attitude_deg == pytest.approx(15.0, abs=1.0)
    assert "relative_attitude" not in metrics.failed_checks
    assert outcome is Outcome.SUCCESS
    # the bench's 10 deg refuses the same touchdown
    outcome, metrics, world = drop(0.3, roll_deg=15.0, max_relative_attitude_deg=10.0)
    world.close()
    assert outcome is Outcome.HARD_LANDING
    assert "relative_attitude" in metrics.failed_checks


def test_a_ship_motion_csv_drives_the_ship_deck_unclamped(tmp_path) -> None:
    from landing_env.stewart.motion import write_motion_csv

    times = np.linspace(0.0, 20.0, 201)
    poses = np.zeros((201, 6))
    poses[:, 2] = 1.5 * np.sin(2 * math.pi * times / 8.0)  # metres of heave
    poses[:, 3] = math.radians(4.0) * np.sin(2 * math.pi * times / 6.0)
    path = tmp_path / "helideck.csv"
    write_motion_csv(path, times, poses)
    config = load_config(
        "ship-ss4",
        overrides={"motion.kind": "csv", "motion.csv.path": str(path), "wind.enabled": False},
    )
    world = World(config)
    try:
        world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 2.0]), 0.0)
        assert world.contact_watch_height_m > 1.5  # the deck's reach is watched
        zero = VelocitySetpoint(np.array([0.0, 0.0, 0.0]), 0.0)
        for _ in range(40):  # 2 s
            world.step(zero)
        height = world.deck_state().position_w[2] - world.deck_home_w[2]
        assert height == pytest.approx(1.5 * math.sin(2 * math.pi * world.time / 8.0), abs=1e-3)
    finally:
        world.close()
