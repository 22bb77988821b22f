"""Sensors never raise or leave their limits: no return, noise at the range limits, thin images."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest
from pybullet_utils.bullet_client import BulletClient

from estimation.detection import MIN_DETECT_SIDE_PX, AprilTagDetector, min_detect_side_px
from landing_env.sensors.rangefinder import Rangefinder, RangefinderConfig
from landing_env.sensors.tof import TofArray, TofConfig

LEVEL = np.eye(3)
#: the body upside down: the beam points at the sky
UPSIDE_DOWN = np.diag([1.0, -1.0, -1.0])


@pytest.fixture()
def ground() -> Iterator[BulletClient]:
    client = BulletClient(connection_mode=p.DIRECT)
    client.createMultiBody(0.0, client.createCollisionShape(p.GEOM_PLANE))
    yield client
    client.disconnect()


def exact(**kwargs: float) -> RangefinderConfig:
    return RangefinderConfig(sigma_0=0.0, sigma_per_m=0.0, resolution=0.0, **kwargs)


def test_rangefinder_without_a_return_is_invalid_not_an_exception(ground: BulletClient) -> None:
    # quantised, noisy: the default sensor, the case that raised ValueError on round(NaN)
    sensor = Rangefinder(ground, RangefinderConfig(), np.random.default_rng(0))
    for t_wb in ([0.0, 0.0, 2.0], [0.0, 0.0, 500.0]):
        for r_wb in (UPSIDE_DOWN, LEVEL):
            reading = sensor.measure(0.0, np.array(t_wb), r_wb, exclude_body=-1)
            if r_wb is UPSIDE_DOWN or t_wb[2] > 40.0:
                assert reading.valid.tolist() == [False] and np.isnan(reading.ranges[0])
            else:
                assert reading.valid.tolist() == [True]


def test_rangefinder_judges_min_and_max_range_on_the_reported_value(ground: BulletClient) -> None:
    # a sensor 2 cm above the ground with min_range 5 cm: no reading
    near = Rangefinder(ground, exact(min_range=0.05), np.random.default_rng(0))
    below = near.measure(0.0, np.array([0.0, 0.0, 0.05]), LEVEL, exclude_body=-1)
    assert below.valid.tolist() == [False]
    above = near.measure(0.0, np.array([0.0, 0.0, 0.10]), LEVEL, exclude_body=-1)
    assert above.valid.tolist() == [True] and above.ranges[0] == pytest.approx(0.07)
    # true range 9.99 m, max 10 m, noise of 5 cm: every valid reported value is within 10 m,
    # and the readings that the noise pushed past it are invalid
    noisy = Rangefinder(
        ground, RangefinderConfig(max_range=10.0, sigma_0=0.05), np.random.default_rng(3)
    )
    readings = [
        noisy.measure(0.0, np.array([0.0, 0.0, 10.02]), LEVEL, exclude_body=-1) for _ in range(400)
    ]
    valid = np.array([r.valid[0] for r in readings])
    values = np.array([r.ranges[0] for r in readings])
    assert 0.2 < valid.mean() < 0.8  # both sides of the limit were drawn
    assert np.all(values[valid] <= 10.0) and np.isnan(values[~valid]).all()


def test_rangefinder_invalid_prob_drops_that_share_of_readings(ground: BulletClient) -> None:
    sensor = Rangefinder(ground, exact(invalid_prob=0.3), np.random.default_rng(4))
    valid = np.array(
        [sensor.measure(0.0, np.array([0.0, 0.0, 3.0]), LEVEL, -1).valid[0] for _ in range(2000)]
    )
    assert abs((1.0 - valid.mean()) - 0.3) < 4.0 * np.sqrt(0.3 * 0.7 / valid.size)


def test_noisy_tof_reports_no_valid_range_beyond_max_range(ground: BulletClient) -> None:
    config = TofConfig(noise="vl53l1x", max_range=4.0)
    tof = TofArray(ground, config, np.random.default_rng(0), np.zeros(3))
    # sensors 3.995 m above the ground: the noise (12 mm at 4 m) pushes about half past 4 m
    readings = [tof.measure(0.0, np.array([0.0, 0.0, 3.995]), LEVEL, -1) for _ in range(300)]
    valid = np.concatenate([r.valid for r in readings])
    values = np.concatenate([r.ranges for r in readings])
    assert 0.2 < valid.mean() < 0.8
    assert np.all(values[valid] <= config.max_range)
    assert np.all(values[valid] >= config.min_range)
    assert np.isnan(values[~valid]).all()


def test_tof_without_a_return_is_invalid(ground: BulletClient) -> None:
    tof = TofArray(ground, TofConfig(noise="vl53l1x"), np.random.default_rng(0), np.zeros(3))
    reading = tof.measure(0.0, np.array([0.0, 0.0, 1.0]), UPSIDE_DOWN, -1)
    assert not reading.valid.any() and np.isnan(reading.ranges).all()


def test_thin_images_are_not_passed_to_the_native_detector() -> None:
    # in a child: before the guard the (2, 178) patch killed the process with SIGSEGV
    code = (
        "import numpy as np\n"
        "from estimation.detection import AprilTagDetector\n"
        "for decimate in (1.0, 1.5, 3.0, 4.0):\n"
        "    detector = AprilTagDetector(quad_decimate=decimate)\n"
        "    for shape in ((2, 178), (1, 1), (4, 640), (178, 2), (5, 300), (8, 8), (3, 40, 3)):\n"
        "        assert detector.detect(np.full(shape, 103, np.uint8)) == ()\n"
        "print('survived')\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "survived" in run.stdout


def test_detector_guard_grows_with_decimation_and_keeps_detectable_sizes() -> None:
    assert min_detect_side_px(1.0) == MIN_DETECT_SIDE_PX
    assert min_detect_side_px(4.0) == 16 and min_detect_side_px(1.5) == MIN_DETECT_SIDE_PX
    detector = AprilTagDetector()
    # an image at the guard's size goes to the detector (an empty result, no tag in it)
    assert detector.detect(np.full((MIN_DETECT_SIDE_PX, 50), 103, np.uint8)) == ()
    with pytest.raises(TypeError):
        detector.detect(np.zeros((2, 2), dtype=float))


def test_reset_far_above_the_rangefinder_range_gives_an_invalid_range_down() -> None:
    import gymnasium as gym

    import landing_env  # noqa: F401  (registers the environments)

    overrides = {"start.height_m": [41, 41], "simulation.arena_max_height_m": 60}
    env = gym.make("DeckLanding-v2", config="high-approach", overrides=overrides)
    try:
        observation, _ = env.reset(seed=0)
        assert observation["range_down_valid"].tolist() == [0]
        assert observation["range_down"].tolist() == [0.0]
        assert env.observation_space.contains(observation)
    finally:
        env.close()
