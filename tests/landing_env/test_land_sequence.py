"""What follows the first contact: the motors cut (the default), the land sequence (levelled
onto the deck while the thrust falls, then disarmed: ``touchdown.spool_down_s``) and the
deck-securing harpoon (``touchdown.harpoon_force_n``).

The drone touches a deck 10 m above its roll axis (still, or rolling sinusoidally) at
0.3 m/s with the controller armed and pressing down, as the guidance's final descent does.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from landing_env.config import ConfigError, load_config
from landing_env.envs.snapshot import restore_snapshot, save_snapshot
from landing_env.physics.controller import VelocitySetpoint
from landing_env.touchdown import Outcome, TouchdownMetrics, spool_down_thrust_n
from landing_env.world import World
from tests.landing_env.test_touchdown_compliance import RollingDeck, touch_and_settle

PRESS = VelocitySetpoint(np.array([0.0, 0.0, -0.3]), 0.0)


def touch_down(
    roll_rate_deg_s: float = 0.0, watch: list | None = None, **touchdown: float
) -> tuple[Outcome, TouchdownMetrics, World]:
    """An armed touchdown at 0.3 m/s, yawed 45 deg, on feet that grip (friction 1); with
    ``watch`` each settle step's (armed, thrust cap, thrust axis, deck normal) is kept."""
    overrides = {f"touchdown.{k}": v for k, v in touchdown.items()}
    config = load_config(
        "ship-ss4", overrides={"motion.kind": "static", "wind.enabled": False, **overrides}
    )
    world = World(config)
    for foot in world.foot_links:
        world.client.changeDynamics(world.drone.body_id, foot, lateralFriction=1.0)
    world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 2.0]), 0.0)
    if roll_rate_deg_s:
        world.stewart.motion = RollingDeck(roll_rate_deg_s, omega=1.0, arm_m=10.0)
        world.stewart.reset(0.0)
    start = world.deck_state().position_w + np.array([0.0, 0.0, 0.084])
    world.drone.reset(start, math.pi / 4, velocity_w=(0.0, 0.0, -0.3))
    world._state = world.drone.read_state()
    if watch is not None:
        step = world.step

        def watched(setpoint, monitor_contacts=True):
            if world._touchdown is not None:  # after the first contact: the settle
                controller = world.controller
                normal = world.deck_state().rotation_wp[:, 2]
                watch.append(
                    (world.armed, controller.thrust_cap_n, controller.thrust_axis_w, normal)
                )
            return step(setpoint, monitor_contacts)

        world.step = watched  # type: ignore[method-assign]
    outcome, metrics = touch_and_settle(world, PRESS)
    return outcome, metrics, world


def test_the_land_sequence_cap_falls_linearly_from_the_weight_to_its_final_share() -> None:
    assert spool_down_thrust_n(0.0, 8.0, 0.2) == pytest.approx(8.0)
    assert spool_down_thrust_n(0.5, 8.0, 0.2) == pytest.approx(4.8)
    assert spool_down_thrust_n(1.0, 8.0, 0.2) == pytest.approx(1.6)
    assert spool_down_thrust_n(3.0, 8.0, 0.2) == pytest.approx(1.6)


def test_by_default_the_motors_are_cut_at_the_first_contact() -> None:
    seen: list = []
    _, _, world = touch_down(watch=seen)
    world.close()
    assert len(seen) == 20  # settle_time_s 1 s at 20 Hz
    assert all(not armed for armed, *_ in seen)


def test_the_land_sequence_levels_onto_the_deck_lowers_the_thrust_then_disarms() -> None:
    seen: list = []
    _, _, world = touch_down(6.0, watch=seen, spool_down_s=0.15)
    weight = world.params.weight
    assert not world.armed and world.controller.thrust_axis_w is None
    world.close()
    sequence, settle = seen[:3], seen[3:]
    assert all(armed for armed, *_ in sequence)
    assert [cap / weight for _, cap, _, _ in sequence] == pytest.approx([2 / 3, 1 / 3, 0.0])
    for _, _, axis, normal in sequence:
        # the deck's normal as the ToF ranges measure it (their noise: within a degree of
        # the truth), not the vertical
        assert math.degrees(math.acos(min(1.0, float(np.dot(axis, normal))))) < 1.0
        assert math.degrees(math.acos(axis[2])) > 0.05
    assert len(settle) == 20 and all(not armed for armed, *_ in settle)  # the whole settle


def test_the_measured_deck_normal_follows_a_tilted_deck_and_needs_three_ranges() -> None:
    config = load_config("ship-ss4", overrides={"motion.kind": "static", "wind.enabled": False})
    world = World(config)
    world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 0.5]), 0.0)
    level = world.deck_normal_measured_w()
    assert level is not None and math.degrees(math.acos(level[2])) < 1.0
    # the drone rolled 8 deg over a level deck measures the deck tilted 8 deg the other way
    # in its own frame, and level again in W once turned by its attitude
    roll = Rotation.from_euler("x", 8.0, degrees=True)
    world.drone.reset(world.deck_home_w + np.array([0, 0, 0.5]), 0.0, rotation_wb=roll.as_matrix())
    world._state = world.drone.read_state()
    rolled = world.deck_normal_measured_w()
    assert rolled is not None and math.degrees(math.acos(rolled[2])) < 1.0
    # too far for the ToF (4 m): no normal
    world.drone.reset(world.deck_home_w + np.array([0, 0, 6.0]), 0.0)
    world._state = world.drone.read_state()
    assert world.deck_normal_measured_w() is None
    world.close()


def test_a_short_land_sequence_lands_where_the_cut_tips_over_and_a_long_one_bounces() -> None:
    _, cut_metrics, world = touch_down(8.0)
    world.close()
    assert "tip_over" in cut_metrics.failed_checks
    short, metrics, world = touch_down(8.0, spool_down_s=0.15)
    world.close()
    assert short is Outcome.SUCCESS, metrics.failed_checks
    # a thrust near the weight for longer lifts the levelled drone off again
    _, long_metrics, world = touch_down(8.0, spool_down_s=0.4)
    world.close()
    assert long_metrics.failed_checks == ("bounce",)


def test_a_harpoon_keeps_a_drone_on_a_fast_rolling_deck_from_tipping_over() -> None:
    _, free, world = touch_down(10.0)
    world.close()
    assert free.tipped_over
    outcome, held, world = touch_down(10.0, harpoon_force_n=40.0)
    world.close()
    assert outcome is Outcome.SUCCESS, held.failed_checks


def test_a_negative_harpoon_force_is_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError, match=r"touchdown\.harpoon_force_n"):
        load_config("ship-ss4", overrides={"touchdown.harpoon_force_n": -1.0})


def test_a_look_ahead_whose_harpoon_fired_leaves_no_hold_after_the_restore() -> None:
    config = load_config("ship-ss4", overrides={"touchdown.harpoon_force_n": 40.0})
    env = SimpleNamespace(world=World(config), config=config)
    env.world.reset(np.random.default_rng(0), env.world.deck_home_w + np.array([0, 0, 2.0]), 0.0)
    before = env.world.client.getNumConstraints()
    snapshot = save_snapshot(env)
    env.world.secure_to_deck(40.0)  # what a look-ahead's touchdown does
    assert env.world.client.getNumConstraints() == before + 1
    restore_snapshot(env, snapshot, keep=False)
    assert env.world.client.getNumConstraints() == before
    env.world.close()
