"""The ship's helideck mount: a deck servoed along a ship's motion about its home, no legs."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from landing_env.sea.deck_mount import ShipDeck
from landing_env.stewart.kinematics import angular_velocity_from_euler_rates
from landing_env.waves.ship import ShipMotion, ShipMotionConfig

DT = 1.0 / 240.0
#: the deck's home in the world: off the origin, 12 m above the sea plane
HOME_W = np.array([2.0, -1.0, 12.0])


@pytest.fixture
def client() -> Iterator[BulletClient]:
    c = BulletClient(connection_mode=pybullet.DIRECT)
    c.setGravity(0.0, 0.0, -9.81)
    c.setTimeStep(DT)
    yield c
    c.disconnect()


def make_deck(c: BulletClient, motion: ShipMotion) -> ShipDeck:
    """A 2 m deck plate whose base frame is the centre of its top surface, on the ship."""
    shape = c.createCollisionShape(
        pybullet.GEOM_BOX,
        halfExtents=[1.0, 1.0, 0.05],
        collisionFramePosition=[0.0, 0.0, -0.05],
    )
    body = c.createMultiBody(baseMass=50.0, baseCollisionShapeIndex=shape, basePosition=HOME_W)
    return ShipDeck(c, HOME_W, body, motion)


def rough_sea() -> ShipMotion:
    # a sea state 6 (Hs 5 m): the aft deck heaves metres, beyond any platform's stroke
    return ShipMotion(ShipMotionConfig(sea_state=6), np.random.default_rng(0))


def test_the_ship_deck_starts_at_the_ships_pose_and_velocity_about_its_home_and_has_no_legs(
    client: BulletClient,
) -> None:
    motion = rough_sea()
    deck = make_deck(client, motion)
    position, rotation = deck.home_pose_w()
    np.testing.assert_array_equal(position, HOME_W)
    np.testing.assert_array_equal(rotation, np.eye(3))
    # only the deck: no base plate, no leg cylinders or rods
    assert deck.base_body_id == -1 and client.getNumBodies() == 1
    assert deck.cylinder_body_ids == [] and deck.rod_body_ids == []
    status = deck.reset(3.0)
    pose = motion.pose(3.0)
    assert status.t == 3.0 and not status.clamped and status.violated_legs == ()
    np.testing.assert_array_equal(status.commanded_pose, pose)
    np.testing.assert_array_equal(status.applied_pose, pose)
    np.testing.assert_allclose(deck.measured_pose(), pose, atol=1e-7)
    # the deck starts with the ship's velocity, not at rest
    linear, angular = deck.top_plate_velocity_w()
    rates = motion.velocity(3.0)
    np.testing.assert_allclose(linear, rates[:3], atol=1e-9)
    np.testing.assert_allclose(
        angular, angular_velocity_from_euler_rates(pose[3:], rates[3:]), atol=1e-9
    )
    assert np.linalg.norm(linear) > 0.1
    deck.update_leg_visuals()  # no legs to move
    assert client.getNumBodies() == 1


def test_the_ship_deck_follows_metres_of_motion_unclamped_step_by_step(
    client: BulletClient,
) -> None:
    motion = rough_sea()
    deck = make_deck(client, motion)
    deck.reset(0.0)
    heave = []
    for k in range(1, 481):
        t = k * DT
        assert deck.advance(t) is False
        status = deck.last_status
        assert status is not None and status.t == t and not status.clamped
        assert status.violated_legs == ()
        # (the poses are evaluated ahead in batches: the same to rounding)
        np.testing.assert_allclose(status.applied_pose, motion.pose(t), rtol=0.0, atol=1e-12)
        client.stepSimulation()
        np.testing.assert_allclose(deck.measured_pose(), motion.pose(t), atol=1e-6)
        heave.append(deck.measured_pose()[2])
    assert np.ptp(heave) > 0.6  # far beyond the bench platform's workspace
