"""Recorded seas as a source of episodes: looped logs from any epoch, seeded random starts,
long files, .npy recordings, and a vessel's log carried to the helideck."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import PchipInterpolator

import landing_env  # noqa: F401  (registers the environments)
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.stewart.motion import MotionConfig, make_motion_source
from landing_env.waves.recording import (
    ChunkedPchip,
    CsvMotion,
    CsvMotionConfig,
    CsvMotionError,
    csv_motion_from_config,
    load_recording,
    write_motion_csv,
    write_motion_npy,
)
from landing_env.waves.ship import ShipMotion, ShipMotionConfig


def smooth_log(t0_s: float, duration_s: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """A smooth deck motion sampled from ``t0_s`` (as a recorded log is stamped)."""
    times = t0_s + np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    phase = 2.0 * math.pi * (times - t0_s) / duration_s
    poses = np.column_stack(
        [0.01 * np.sin(k * phase + k) for k in range(1, 4)]
        + [math.radians(3.0) * np.sin(k * phase) for k in range(1, 4)]
    )
    return times, poses


def test_a_looped_log_stamped_from_10_s_replays_every_loop(tmp_path: Path) -> None:
    times, poses = smooth_log(10.0, 20.0, 10.0)
    path = tmp_path / "log.csv"
    write_motion_csv(path, times, poses)
    for start, offset in (("file_time", 0.0), ("first_sample", 10.0)):
        source = csv_motion_from_config(
            CsvMotionConfig(str(path), end="loop", start=start), np.random.default_rng(0)
        )
        assert source.offset_s == offset
        # five loops, at the physics rate, single calls against the batch
        episode = np.arange(0.0, 5 * 20.0 + 10.0, 1.0 / 240.0)
        batch = source.poses(episode)
        single = np.array([source.pose(float(t)) for t in episode[::7]])
        rates = np.array([source.velocity(float(t)) for t in episode[::7]])
        assert np.all(np.isfinite(batch)) and np.all(np.isfinite(single))
        assert np.all(np.isfinite(rates))
        np.testing.assert_array_equal(single, batch[::7])
        # the replay is periodic in the file's span and starts from the file's own samples
        later = episode[(episode + offset >= 10.0) & (episode < 60.0)]
        np.testing.assert_allclose(source.poses(later + 20.0), source.poses(later), atol=1e-12)
        np.testing.assert_allclose(source.pose(10.0 - offset + 40.0), poses[0], atol=1e-12)
        np.testing.assert_allclose(source.pose(10.0 - offset + 45.0), poses[50], atol=1e-12)
        # velocity is the derivative of the poses, in every loop (away from the wrap)
        probe = 10.0 - offset + np.array([3.05, 23.05, 43.05, 83.05])
        h = 1e-5
        numeric = (source.poses(probe + h) - source.poses(probe - h)) / (2 * h)
        np.testing.assert_allclose(source.velocities(probe), numeric, atol=1e-6)
        np.testing.assert_allclose(
            np.array([source.velocity(float(t)) for t in probe]), numeric, atol=1e-6
        )


def test_seeded_episodes_start_at_reproducible_random_instants(tmp_path: Path) -> None:
    times, poses = smooth_log(1000.0, 300.0, 20.0)
    path = tmp_path / "log.csv"
    write_motion_csv(path, times, poses)
    config = CsvMotionConfig(str(path), start="random", random_margin_s=60.0)
    offsets = [
        csv_motion_from_config(config, np.random.default_rng(seed)).offset_s for seed in range(40)
    ]
    again = [
        csv_motion_from_config(config, np.random.default_rng(seed)).offset_s for seed in range(40)
    ]
    assert offsets == again
    assert len(set(offsets)) == 40
    # end hold: the drawn start leaves the margin of recording after it
    assert min(offsets) >= 1000.0 and max(offsets) <= 1000.0 + 300.0 - 60.0
    assert max(offsets) - min(offsets) > 150.0
    # the episode's deck at t = 0 is the file's pose at the drawn instant
    source = csv_motion_from_config(config, np.random.default_rng(7))
    np.testing.assert_allclose(
        source.pose(0.0), PchipInterpolator(times, poses)(source.offset_s), atol=1e-12
    )
    # end loop: any instant of the file can start an episode
    looped = CsvMotionConfig(str(path), start="random", end="loop")
    spread = [csv_motion_from_config(looped, np.random.default_rng(s)).offset_s for s in range(40)]
    assert max(spread) > 1000.0 + 300.0 - 60.0
    # through the motion factory, with the episode's generator
    motion = MotionConfig(kind="csv", csv=config)
    a = make_motion_source(motion, np.random.default_rng(3))
    b = make_motion_source(motion, np.random.default_rng(3))
    np.testing.assert_array_equal(a.poses(np.arange(0.0, 5.0, 0.1)), b.poses(np.arange(0, 5, 0.1)))


def test_chunked_pchip_equals_the_whole_record_interpolant() -> None:
    rng = np.random.default_rng(4)
    times = np.cumsum(rng.uniform(0.005, 0.02, 1000)) + 10.0
    values = np.cumsum(rng.normal(0.0, 0.01, (1000, 6)), axis=0)
    whole = PchipInterpolator(times, values, axis=0, extrapolate=False)
    chunked = ChunkedPchip(times, values, chunk=37)
    probe = np.concatenate([rng.uniform(times[0], times[-1], 3000), times, [times[0] - 1.0]])
    np.testing.assert_allclose(chunked(probe)[:-1], whole(probe)[:-1], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(
        chunked(probe, derivative=True)[:-1], whole.derivative()(probe)[:-1], atol=1e-9
    )
    assert np.all(np.isnan(chunked(probe)[-1]))


def test_npy_and_csv_recordings_replay_the_same_motion(tmp_path: Path) -> None:
    times, poses = smooth_log(5.0, 30.0, 50.0)
    write_motion_csv(tmp_path / "log.csv", times, poses)
    write_motion_npy(tmp_path / "log.npy", times, poses)
    a = CsvMotion.from_file(tmp_path / "log.csv", end="loop")
    b = CsvMotion.from_file(tmp_path / "log.npy", end="loop")
    probe = np.linspace(0.0, 100.0, 777)
    np.testing.assert_allclose(a.poses(probe), b.poses(probe), atol=1e-12)
    np.save(tmp_path / "bad.npy", np.zeros((5, 6)))
    with pytest.raises(CsvMotionError, match=r"bad\.npy.*\(N, 7\)"):
        CsvMotion.from_file(tmp_path / "bad.npy")
    table = np.column_stack([times, np.degrees(poses)])
    table[3, 2] = np.nan
    np.save(tmp_path / "nan.npy", table)
    with pytest.raises(CsvMotionError, match=r"nan\.npy.*non-finite.*sample 4"):
        CsvMotion.from_file(tmp_path / "nan.npy")


def test_a_rewritten_recording_is_read_again(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    write_motion_csv(path, np.array([0.0, 1.0]), np.zeros((2, 6)))
    assert load_recording(path).samples[1, 0] == 0.0
    write_motion_csv(path, np.array([0.0, 1.0, 2.0]), np.full((3, 6), 0.5))
    assert load_recording(path).samples[1, 0] == 0.5


def test_a_vessel_log_replays_at_the_helideck_as_the_simulated_vessel_does(
    tmp_path: Path,
) -> None:
    ship = ShipMotion(ShipMotionConfig(sea_state=5), np.random.default_rng(11))
    times = 30.0 + np.arange(0.0, 120.0, 0.05)
    path = tmp_path / "vessel.csv"
    write_motion_csv(path, times, ship.vessel_poses(times))
    lever = (-10.0, 0.0, 3.0)
    deck = CsvMotion.from_file(path, frame="vessel", helideck_position_m=lever)
    np.testing.assert_allclose(deck.poses(times), ship.poses(times), atol=1e-9)
    between = times[:-1] + 0.025
    np.testing.assert_allclose(deck.poses(between), ship.poses(between), atol=2e-3)
    np.testing.assert_allclose(
        deck.velocities(between[100:200])[:, 2], ship.velocities(between[100:200])[:, 2], atol=0.02
    )
    # the lever arm matters: the helideck heaves more than the centre of motion
    assert np.std(deck.poses(times)[:, 2]) > 1.05 * np.std(ship.vessel_poses(times)[:, 2])


def test_recording_keys_are_checked_by_name(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    write_motion_csv(path, np.array([0.0, 1.0]), np.zeros((2, 6)))
    base = {"motion.kind": "csv", "motion.csv.path": str(path)}
    cases = {
        "motion.csv.start": "middle",
        "motion.csv.frame": "hull",
        "motion.csv.random_margin_s": -1.0,
        "motion.csv.helideck_position_m": [0.0, 1.0],
        "motion.csv.offset_s": 3.0,
    }
    for key, value in cases.items():
        with pytest.raises(ConfigError) as info:
            load_config("default", overrides={**base, key: value})
        assert key.removeprefix("motion.") in str(info.value), (key, str(info.value))
    with pytest.raises(ConfigError, match=r"motion\.csv\.frame.*deck_mount"):
        load_config("default", overrides={**base, "motion.csv.frame": "vessel"})


@settings(max_examples=40, deadline=None)
@given(
    t0=st.floats(-1e5, 1e5),
    offset=st.floats(-1e4, 1e4),
    t=st.floats(-1e4, 1e6),
    end=st.sampled_from(["hold", "loop"]),
)
def test_any_time_and_offset_give_finite_poses(t0: float, offset: float, t: float, end) -> None:
    times = t0 + np.linspace(0.0, 3.0, 7)
    source = CsvMotion(times, np.random.default_rng(1).normal(0, 0.01, (7, 6)), end, offset)
    assert np.all(np.isfinite(source.pose(t))) and np.all(np.isfinite(source.velocity(t)))


def test_a_ship_deck_env_plays_a_random_stretch_of_a_vessel_log_per_seed(tmp_path: Path) -> None:
    ship = ShipMotion(ShipMotionConfig(sea_state=4), np.random.default_rng(5))
    times = 12.0 + np.arange(0.0, 600.0, 0.1)
    path = tmp_path / "vessel.npy"
    write_motion_npy(path, times, ship.vessel_poses(times))
    overrides = {
        "motion.kind": "csv",
        "motion.csv.path": str(path),
        "motion.csv.frame": "vessel",
        "motion.csv.start": "random",
        "wind.enabled": False,
    }
    env = gym.make("DeckLanding-v2", config="ship-ss4", overrides=overrides)
    try:
        world = env.unwrapped.world
        first = {}
        for seed in (1, 2, 1):
            env.reset(seed=seed)
            deck = world.deck_state().position_w - world.deck_home_w
            motion = world.stewart.motion
            assert isinstance(motion, CsvMotion)
            np.testing.assert_allclose(deck, motion.pose(world.time)[:3], atol=1e-6)
            if seed in first:
                np.testing.assert_allclose(deck, first[seed], atol=1e-9)
            first[seed] = deck
            for _ in range(3):
                env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert not np.allclose(first[1], first[2])
    finally:
        env.close()
