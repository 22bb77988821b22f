"""What follows the first contact: the motors cut (the default), the land sequence (thrust
lowered, then disarmed, ``touchdown.spool_down_s``) and the deck-securing harpoon
(``touchdown.harpoon_force_n``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from landing_env.config import ConfigError, load_config
from landing_env.physics.controller import VelocitySetpoint
from landing_env.touchdown import spool_down_thrust_n
from landing_env.world import World
from tests.landing_env.test_touchdown_compliance import RollingDeck, drop


def settle_steps(**touchdown: float) -> tuple[list[tuple[bool, float]], World]:
    """Touch a still deck at 0.3 m/s with the controller armed, then settle; return the
    (armed, thrust cap) each settle step flew with."""
    overrides = {f"touchdown.{k}": v for k, v in touchdown.items()}
    config = load_config(
        "ship-ss4", overrides={"motion.kind": "static", "wind.enabled": False, **overrides}
    )
    world = World(config)
    world.reset(np.random.default_rng(0), world.deck_home_w + np.array([0, 0, 2.0]), 0.0)
    start = world.deck_state().position_w + np.array([0.0, 0.0, 0.084])
    world.drone.reset(start, 0.0, (0.0, 0.0, -0.3))
    world._state = world.drone.read_state()
    press = VelocitySetpoint(np.array([0.0, 0.0, -0.3]), 0.0)
    for _ in range(20):
        if world.step(press).first_contact is not None:
            break
    seen: list[tuple[bool, float]] = []
    step = world.step

    def watched(setpoint, monitor_contacts=True):
        seen.append((world.armed, world.controller.thrust_cap_n))
        return step(setpoint, monitor_contacts)

    world.step = watched  # type: ignore[method-assign]
    world.settle(config.touchdown.settle_time_s, press)
    return seen, world


def test_the_land_sequence_cap_falls_linearly_from_the_weight_to_its_final_share() -> None:
    assert spool_down_thrust_n(0.0, 8.0, 0.2) == pytest.approx(8.0)
    assert spool_down_thrust_n(0.5, 8.0, 0.2) == pytest.approx(4.8)
    assert spool_down_thrust_n(1.0, 8.0, 0.2) == pytest.approx(1.6)
    assert spool_down_thrust_n(3.0, 8.0, 0.2) == pytest.approx(1.6)


def test_by_default_the_motors_are_cut_at_the_first_contact() -> None:
    seen, world = settle_steps()
    world.close()
    assert len(seen) == 20  # settle_time_s 1 s at 20 Hz
    assert all(not armed for armed, _ in seen)


def test_the_land_sequence_lowers_the_thrust_then_disarms_for_the_whole_settle() -> None:
    seen, world = settle_steps(spool_down_s=0.4, spool_down_final_thrust=0.25)
    weight = world.params.weight
    assert not world.armed and math.isinf(world.controller.thrust_cap_n)
    world.close()
    spool, settle = seen[:8], seen[8:]
    assert all(armed for armed, _ in spool)
    caps = [cap / weight for _, cap in spool]
    assert caps == pytest.approx([1.0 - 0.75 * (i + 1) / 8 for i in range(8)])
    assert len(settle) == 20 and all(not armed for armed, _ in settle)


def test_a_harpoon_keeps_a_drone_on_a_fast_rolling_deck_from_tipping_over() -> None:
    rolling = RollingDeck(rate_deg_s=10.0, omega=1.0, arm_m=10.0)
    _, free, world = drop(0.3, rolling, yaw=math.pi / 4, friction=1.0)
    world.close()
    assert free.tipped_over
    _, held, world = drop(0.3, rolling, yaw=math.pi / 4, friction=1.0, harpoon_force_n=50.0)
    world.close()
    assert not held.tipped_over and held.on_deck_after_settle, held.failed_checks


def test_a_harpoon_force_beyond_its_range_is_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError, match=r"touchdown\.harpoon_force_n"):
        load_config("ship-ss4", overrides={"touchdown.harpoon_force_n": -1.0})
