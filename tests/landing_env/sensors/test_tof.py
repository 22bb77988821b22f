"""ToF array: geometry of the rays, invalid readings, self-hits and the VL53L1X noise."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from estimation.frames import R_BC, matrix_from_euler_zyx, tof_positions_in_camera_frame
from landing_env.errors import ConfigError
from landing_env.sensors.tof import TofArray, TofConfig

T_BC = np.array([0.0, 0.0, -0.02])  # camera 2 cm under the body centre


@pytest.fixture()
def client() -> Iterator[int]:
    cid = p.connect(p.DIRECT)
    # a plate whose top surface is at z = 0
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[3, 3, 0.05], physicsClientId=cid)
    p.createMultiBody(0, shape, -1, [0, 0, -0.05], physicsClientId=cid)
    yield cid
    p.disconnect(cid)


def make_drone(client: int, position: np.ndarray, legs: bool = False) -> int:
    """A 0.3 x 0.3 x 0.06 m box that contains the sensor origins, optionally with legs
    hanging 10 cm right under each sensor."""
    box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.15, 0.15, 0.03], physicsClientId=client)
    if not legs:
        return p.createMultiBody(0.5, box, -1, list(position), physicsClientId=client)
    leg = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.01, 0.01, 0.02], physicsClientId=client)
    origins_b = T_BC + (R_BC @ tof_positions_in_camera_frame().T).T
    feet = [list(o + np.array([0.0, 0.0, -0.1])) for o in origins_b]
    return p.createMultiBody(
        0.5,
        box,
        -1,
        list(position),
        linkMasses=[0.01] * 4,
        linkCollisionShapeIndices=[leg] * 4,
        linkVisualShapeIndices=[-1] * 4,
        linkPositions=feet,
        linkOrientations=[[0, 0, 0, 1]] * 4,
        linkInertialFramePositions=[[0, 0, 0]] * 4,
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * 4,
        linkParentIndices=[0] * 4,
        linkJointTypes=[p.JOINT_FIXED] * 4,
        linkJointAxis=[[0, 0, 1]] * 4,
        physicsClientId=client,
    )


def test_level_drone_reads_its_height(client: int) -> None:
    t_wb = np.array([0.2, -0.1, 2.02])  # sensors at 2.00 m
    drone = make_drone(client, t_wb)
    tof = TofArray(client, TofConfig(), np.random.default_rng(0), T_BC)
    reading = tof.measure(0.25, t_wb, np.eye(3), exclude_body=drone)
    assert reading.timestamp == 0.25
    assert reading.valid.all()
    np.testing.assert_allclose(reading.ranges, 2.0, atol=1e-3)


def test_tilted_drone_reads_along_its_tilted_axis(client: int) -> None:
    t_wb = np.array([0.0, 0.0, 1.5])
    r_wb = matrix_from_euler_zyx(np.deg2rad(12.0), np.deg2rad(-7.0), 0.8)
    drone = make_drone(client, t_wb)
    tof = TofArray(client, TofConfig(), np.random.default_rng(0), T_BC)
    reading = tof.measure(0.0, t_wb, r_wb, exclude_body=drone)
    origins_w = t_wb + (r_wb @ tof.origins_b.T).T
    cos_tilt = r_wb[2, 2]  # the body's down axis against the plate normal
    np.testing.assert_allclose(reading.ranges, origins_w[:, 2] / cos_tilt, atol=1e-4)
    # tilt changes the readings by more than the tolerance, so the test means something
    assert np.ptp(reading.ranges) > 0.02


def test_out_of_range_and_no_hit_are_nan_and_invalid(client: int) -> None:
    tof = TofArray(client, TofConfig(max_range=4.0), np.random.default_rng(0), T_BC)
    far = np.array([0.0, 0.0, 4.3])
    drone = make_drone(client, far)
    reading = tof.measure(0.0, far, np.eye(3), exclude_body=drone)
    assert not reading.valid.any() and np.isnan(reading.ranges).all()
    # off the plate's edge: nothing below at all
    off = np.array([10.0, 0.0, 1.0])
    reading = tof.measure(0.0, off, np.eye(3), exclude_body=drone)
    assert not reading.valid.any() and np.isnan(reading.ranges).all()
    # looking up: no hit either
    reading = tof.measure(0.0, np.array([0.0, 0.0, 1.0]), np.diag([1.0, -1.0, -1.0]), drone)
    assert not reading.valid.any()


def test_below_min_range_is_invalid(client: int) -> None:
    tof = TofArray(client, TofConfig(min_range=0.04), np.random.default_rng(0), T_BC)
    near = np.array([0.0, 0.0, 0.05])  # sensors 3 cm above the plate
    reading = tof.measure(0.0, near, np.eye(3), exclude_body=-1)
    assert not reading.valid.any() and np.isnan(reading.ranges).all()
    reading = tof.measure(0.0, near + np.array([0.0, 0.0, 0.02]), np.eye(3), exclude_body=-1)
    np.testing.assert_allclose(reading.ranges, 0.05, atol=1e-4)


def test_the_drone_itself_is_never_hit(client: int) -> None:
    t_wb = np.array([0.0, 0.0, 1.02])
    drone = make_drone(client, t_wb, legs=True)
    tof = TofArray(client, TofConfig(), np.random.default_rng(0), T_BC)
    # without the exclusion the legs right under the sensors are what the rays hit
    blind = tof.measure(0.0, t_wb, np.eye(3), exclude_body=-1)
    np.testing.assert_allclose(blind.ranges, 0.08, atol=1e-3)
    reading = tof.measure(0.0, t_wb, np.eye(3), exclude_body=drone)
    np.testing.assert_allclose(reading.ranges, 1.0, atol=1e-3)
    # a tilted drone too
    r_wb = matrix_from_euler_zyx(0.2, 0.1, 0.0)
    ranges, points = tof.true_ranges(t_wb, r_wb, drone)
    assert np.all(points[:, 2] < 1e-6)  # every hit is on the plate
    assert np.all(ranges > 0.9)


def test_vl53l1x_noise_has_the_configured_std(client: int) -> None:
    config = TofConfig(noise="vl53l1x")
    tof = TofArray(client, config, np.random.default_rng(5), T_BC)
    t_wb = np.array([0.0, 0.0, 2.02])
    samples = np.array(
        [tof.measure(i, t_wb, np.eye(3), exclude_body=-1).ranges for i in range(1000)]
    )
    sigma = config.sigma(np.array(2.0))
    assert sigma == pytest.approx(0.002 + 0.0025 * 2.0)
    assert np.std(samples) == pytest.approx(sigma, rel=0.05)
    assert abs(np.mean(samples) - 2.0) < 4 * sigma / np.sqrt(samples.size)
    # readings come in whole millimetres
    np.testing.assert_allclose(samples * 1000, np.round(samples * 1000), atol=1e-6)


def test_noise_free_by_default_and_seeded(client: int) -> None:
    t_wb = np.array([0.0, 0.0, 1.02])
    exact = TofArray(client, TofConfig(), np.random.default_rng(1), T_BC)
    readings = [exact.measure(i, t_wb, np.eye(3), -1).ranges for i in range(5)]
    for reading in readings[1:]:
        np.testing.assert_array_equal(reading, readings[0])
    noisy = [TofArray(client, TofConfig(noise="vl53l1x"), np.random.default_rng(9), T_BC)]
    noisy.append(TofArray(client, TofConfig(noise="vl53l1x"), np.random.default_rng(9), T_BC))
    first, second = (t.measure(0.0, t_wb, np.eye(3), -1).ranges for t in noisy)
    np.testing.assert_array_equal(first, second)


def test_invalid_status_rate(client: int) -> None:
    config = TofConfig(noise="vl53l1x", invalid_prob=0.2)
    tof = TofArray(client, config, np.random.default_rng(2), T_BC)
    t_wb = np.array([0.0, 0.0, 1.02])
    valid = np.array([tof.measure(i, t_wb, np.eye(3), -1).valid for i in range(1000)])
    assert abs(1.0 - valid.mean() - 0.2) < 4 * np.sqrt(0.2 * 0.8 / valid.size)


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError) as info:
        TofConfig(noise="gaussian")  # type: ignore[arg-type]
    assert info.value.key == "noise" and "'vl53l1x'" in str(info.value)
    with pytest.raises(ConfigError) as info:
        TofConfig(min_range=5.0)
    assert info.value.key == "min_range"


@pytest.mark.parametrize("mount_z", [-0.02, -0.0299, -0.03, -0.0301])
def test_sensor_on_or_near_the_drone_surface(client: int, mount_z: float) -> None:
    """Origins inside, just inside, on and just outside the drone box's bottom face."""
    t_bc = np.array([0.0, 0.0, mount_z])
    t_wb = np.array([0.0, 0.0, 1.5])
    drone = make_drone(client, t_wb)
    tof = TofArray(client, TofConfig(), np.random.default_rng(0), t_bc)
    reading = tof.measure(0.0, t_wb, np.eye(3), exclude_body=drone)
    np.testing.assert_allclose(reading.ranges, 1.5 + mount_z, atol=1e-4)


def test_accepts_a_bullet_client() -> None:
    from pybullet_utils.bullet_client import BulletClient

    client = BulletClient(connection_mode=p.DIRECT)
    try:
        client.createMultiBody(0, client.createCollisionShape(p.GEOM_PLANE), -1, [0, 0, 0])
        tof = TofArray(client, TofConfig(), np.random.default_rng(0), np.zeros(3))
        reading = tof.measure(0.0, np.array([0.0, 0.0, 1.0]), np.eye(3), exclude_body=-1)
        np.testing.assert_allclose(reading.ranges, 1.0, atol=1e-4)
    finally:
        client.disconnect()
