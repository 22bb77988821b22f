"""Recorded seas as a source of episodes: looped logs from any epoch, seeded random starts,
long files, .npy recordings, and a vessel's log carried to the helideck."""

from __future__ import annotations

import math
import os
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
    Recording,
    csv_motion_from_config,
    load_recording,
    read_recording,
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


def test_a_replay_config_refuses_a_bad_choice_or_lever_arm_naming_the_key(tmp_path: Path) -> None:
    cases = {
        "end": ({"end": "pause"}, "'pause' is not allowed; choose one of 'hold', 'loop'"),
        "start": ({"start": "middle"}, "choose one of 'file_time', 'first_sample', 'random'"),
        "frame": ({"frame": "hull"}, "choose one of 'deck', 'vessel'"),
        "random_margin_s": ({"random_margin_s": -1.0}, "-1.0"),
        "helideck_position_m": ({"helideck_position_m": (1.0, 2.0)}, "needs 3 values, got 2"),
        "helideck_position_m[y]": ({"helideck_position_m": (0.0, 200.5, 0.0)}, "[-200.0, 200.0]"),
    }
    for key, (fields, text) in cases.items():
        with pytest.raises(ConfigError) as info:
            CsvMotionConfig("log.csv", **fields)
        assert info.value.key == key and text in str(info.value), (key, str(info.value))
    config = CsvMotionConfig(tmp_path / "log.csv", helideck_position_m=[-200, 200, 3])
    assert config.path == str(tmp_path / "log.csv")
    assert config.helideck_position_m == (-200.0, 200.0, 3.0)
    assert all(isinstance(v, float) for v in config.helideck_position_m)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "bad.csv: empty file; expected header t,x,y,z,roll,pitch,yaw"),
        ("\n\n", "bad.csv: empty file; expected header t,x,y,z,roll,pitch,yaw"),
        (
            "time,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n",
            "bad.csv: header is 'time,x,y,z,roll,pitch,yaw'; expected 't,x,y,z,roll,pitch,yaw' "
            "(seconds, metres, degrees)",
        ),
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,0,0,0\n",
            "bad.csv, line 3: expected 7 columns, got 6",
        ),
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0,0\n",
            "line 3: expected 7 columns, got 8",
        ),
        # the file's own line, blank lines counted
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n\n1,0,0,x,0,0,0\n",
            "bad.csv, line 4: not a number",
        ),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0 # late\n", "line 3: not a number"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0\n1,0,0,0,0,0\n", "line 2: expected 7 columns, got 6"),
        ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n", "bad.csv: needs at least two samples"),
        ("t,x,y,z,roll,pitch,yaw\n", "bad.csv: needs at least two samples"),
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0\n1,0,0,0,0,0,0\n",
            "bad.csv, line 4: time 1.0 does not increase (previous 1.0)",
        ),
        (
            "t,x,y,z,roll,pitch,yaw\n\n0,0,0,0,0,0,0\n\n1,0,0,0,0,0,0\n\n0.5,0,0,0,0,0,0\n",
            "bad.csv, line 7: time 0.5 does not increase (previous 1.0)",
        ),
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n   \n1,0,0,0,0,0,0\n0.5,0,0,0,0,0,0\n",
            "bad.csv, line 5: time 0.5 does not increase (previous 1.0)",
        ),
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1,0,0,nan,0,0,0\n",
            "non-finite values (sample 2)",
        ),
    ],
)
@pytest.mark.filterwarnings("ignore:loadtxt")  # a header alone: numpy warns of no data
def test_a_malformed_recording_is_refused_naming_the_file_and_the_line(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(CsvMotionError) as info:
        load_recording(path)
    assert message in str(info.value)
    with pytest.raises(
        FileNotFoundError, match=r"motion recording '.*missing\.csv' does not exist"
    ):
        load_recording(tmp_path / "missing.csv")


def test_a_csv_header_is_read_without_case_or_spaces_and_blank_rows_are_skipped(
    tmp_path: Path,
) -> None:
    path = tmp_path / "log.csv"
    path.write_text(" T, X,y,z,Roll,pitch,YAW \n0,1,2,3,90,0,0\n\n1,1,2,3,180,0,0\n")
    times, poses = read_recording(path)
    np.testing.assert_array_equal(times, [0.0, 1.0])
    np.testing.assert_allclose(
        poses[:, :4], [[1.0, 2.0, 3.0, math.pi / 2], [1.0, 2.0, 3.0, math.pi]]
    )
    # a file numpy cannot read at once (a row of another length) is read row by row
    path.write_text("t,x,y,z,roll,pitch,yaw\n0,1,2,3,0,0,0\n1,1,2,3,0,0,0\n2,1,2,3,0,0,0,\n")
    with pytest.raises(CsvMotionError, match="line 4: expected 7 columns, got 8"):
        read_recording(path)


def test_npy_recordings_hold_seven_numeric_columns(tmp_path: Path) -> None:
    np.save(tmp_path / "text.npy", np.array([["a"] * 7, ["b"] * 7]))
    with pytest.raises(CsvMotionError) as info:
        read_recording(tmp_path / "text.npy")
    assert "text.npy: holds a <U1 array of shape (2, 7); expected (N, 7) numbers" in str(info.value)
    np.save(tmp_path / "flat.npy", np.zeros(7))
    with pytest.raises(CsvMotionError, match=r"flat\.npy: holds a float64 array of shape \(7,\)"):
        read_recording(tmp_path / "flat.npy")
    np.save(tmp_path / "objects.npy", np.array([{"t": 0}], dtype=object), allow_pickle=True)
    with pytest.raises(CsvMotionError, match=r"objects\.npy: not a numpy array file"):
        read_recording(tmp_path / "objects.npy")
    # integers are numbers; the upper-case suffix is .npy too
    table = np.array([[0, 1, 2, 3, 90, 0, 0], [1, 1, 2, 3, 0, 0, 180]])
    with (tmp_path / "ints.NPY").open("wb") as handle:
        np.save(handle, table)
    times, poses = read_recording(tmp_path / "ints.NPY")
    np.testing.assert_array_equal(times, [0.0, 1.0])
    np.testing.assert_allclose(poses[:, 3], [math.pi / 2, 0.0])
    np.testing.assert_allclose(poses[:, 5], [0.0, math.pi])


def test_written_recordings_read_back_the_same_poses_in_degrees_on_file(tmp_path: Path) -> None:
    times = np.array([0.5, 1.0, 1.7])
    poses = np.random.default_rng(2).normal(0.0, 0.3, (3, 6))
    write_motion_csv(tmp_path / "log.csv", times, poses)
    write_motion_npy(tmp_path / "log.npy", times, poses)
    rows = (tmp_path / "log.csv").read_text().splitlines()
    assert rows[0] == "t,x,y,z,roll,pitch,yaw" and len(rows) == 4
    first = [float(v) for v in rows[1].split(",")]
    np.testing.assert_allclose(first[:4], [0.5, *poses[0, :3]], rtol=0.0, atol=0.0)
    np.testing.assert_allclose(first[4:], np.degrees(poses[0, 3:]), rtol=1e-15)
    stored = np.load(tmp_path / "log.npy")
    np.testing.assert_allclose(stored[:, 4:], np.degrees(poses[:, 3:]), rtol=1e-15)
    np.testing.assert_array_equal(stored[:, :4], np.column_stack([times, poses[:, :3]]))
    for name in ("log.csv", "log.npy"):
        read_times, read_poses = read_recording(tmp_path / name)
        np.testing.assert_array_equal(read_times, times)
        np.testing.assert_allclose(read_poses, poses, rtol=1e-14, atol=1e-16)
    # the poses given are left as they were
    again = poses.copy()
    write_motion_csv(tmp_path / "again.csv", times, again)
    write_motion_npy(tmp_path / "again.npy", times, again)
    np.testing.assert_array_equal(again, poses)


def test_recorded_samples_must_be_finite_increasing_pairs_of_time_and_pose() -> None:
    cases = [
        (np.array([0.0]), np.zeros((1, 6)), "need at least two samples"),
        (np.array([[0.0, 1.0]]), np.zeros((2, 6)), "need at least two samples"),
        (np.array([0.0, 1.0]), np.zeros((2, 5)), "need at least two samples"),
        (np.array([0.0, 1.0, 1.0]), np.zeros((3, 6)), "it does not at sample 2"),
        (np.array([0.0, 2.0, 1.0, 3.0]), np.zeros((4, 6)), "it does not at sample 2"),
        (np.array([0.0, np.inf]), np.zeros((2, 6)), "samples must be finite"),
        (np.array([0.0, 1.0]), np.full((2, 6), np.nan), "samples must be finite"),
    ]
    for times, poses, message in cases:
        with pytest.raises(CsvMotionError, match=message):
            CsvMotion(times, poses)
    assert CsvMotion([0, 1, 3], np.zeros((3, 6))).duration == 3.0


def test_the_chunked_interpolant_keeps_its_eight_newest_pieces_and_takes_a_chunk_of_one() -> None:
    times = np.arange(0.0, 100.0, 1.0)
    values = np.column_stack([np.sin(times / 7.0), np.cos(times / 5.0)])
    chunked = ChunkedPchip(times, values, chunk=10)
    for index in range(9):
        chunked(np.array([10.0 * index + 5.0]))
    assert list(chunked._pieces) == list(range(1, 9))  # the oldest dropped
    chunked(np.array([15.0]))  # in use again: the newest
    assert list(chunked._pieces) == [*range(2, 9), 1]
    chunked(np.array([95.0]))
    assert list(chunked._pieces) == [*range(3, 9), 1, 9]
    whole = PchipInterpolator(times, values, axis=0)
    ends = np.array([0.0, 99.0, 50.0])
    np.testing.assert_allclose(chunked(ends), whole(ends), atol=1e-12)
    assert np.all(np.isnan(chunked(np.array([-1e-9, 99.0 + 1e-9]))))
    single = ChunkedPchip(times, values, chunk=0)
    assert single.chunk == 1
    probe = np.array([0.0, 3.3, 50.5, 99.0])
    np.testing.assert_allclose(single(probe), whole(probe), atol=1e-12)
    np.testing.assert_allclose(single(probe, derivative=True), whole.derivative()(probe), atol=1e-9)


def test_a_loaded_recording_is_kept_per_file_frame_and_lever_for_the_four_newest(
    tmp_path: Path,
) -> None:
    times = np.linspace(0.0, 2.0, 5)
    poses = np.column_stack([np.zeros((5, 3)), np.full(5, 0.1), np.zeros((5, 2))])
    paths = []
    for i in range(5):
        paths.append(tmp_path / f"log{i}.csv")
        write_motion_csv(paths[-1], times, poses)
    first = load_recording(paths[0])
    assert load_recording(str(paths[0])) is first
    port = load_recording(paths[0], "vessel", (0.0, 2.0, 0.0))
    starboard = load_recording(paths[0], "vessel", (0.0, -2.0, 0.0))
    assert port is not first and starboard is not port
    # the deck 2 m to port rises as the vessel rolls port up; the one to starboard sinks
    assert port.samples[0, 2] == pytest.approx(2.0 * math.sin(0.1))
    assert starboard.samples[0, 2] == pytest.approx(-2.0 * math.sin(0.1))
    assert first.samples[0, 2] == 0.0
    # the lever arm of the deck frame is no part of its key
    assert load_recording(paths[0], "deck", (5.0, 0.0, 0.0)) is first
    with pytest.raises(ConfigError) as info:
        load_recording(paths[0], "hull")
    assert info.value.key == "frame"
    # four recordings are kept: one in use again stays, the least recently used goes
    first = load_recording(paths[0])
    kept = [load_recording(path) for path in paths[1:4]]
    assert load_recording(paths[0]) is first
    assert [load_recording(path) for path in paths[2:4]] == kept[1:]
    load_recording(paths[4])  # a fifth: the least recently used, paths[1], is dropped
    assert load_recording(paths[0]) is first
    assert load_recording(paths[1]) is not kept[0]


def test_a_replay_holds_its_first_and_last_pose_still_or_loops_over_its_span() -> None:
    times = np.array([10.0, 11.0, 12.0, 14.0])
    poses = np.outer([0.0, 1.0, 4.0, 2.0], np.ones(6)) * 0.01
    hold = CsvMotion(times, poses, "hold", offset_s=10.0)
    local, held = hold.file_times(np.array([-5.0, 0.0, 1.0, 4.0, 9.0]))
    np.testing.assert_array_equal(local, [10.0, 10.0, 11.0, 14.0, 14.0])
    np.testing.assert_array_equal(held, [True, True, False, True, True])
    rates = hold.velocities(np.array([-5.0, 0.5, 9.0]))
    assert np.all(rates[[0, 2]] == 0.0) and np.all(rates[1] > 0.0)
    loop = CsvMotion(times, poses, "loop", offset_s=10.0)
    local, held = loop.file_times(np.array([0.0, 4.0, 5.0, 9.5, 13.0]))
    np.testing.assert_allclose(local, [10.0, 10.0, 11.0, 11.5, 11.0])
    np.testing.assert_array_equal(held, [True, False, False, False, False])
    assert loop.velocity(5.5)[0] == pytest.approx(hold.velocity(1.5)[0])
    with pytest.raises(ConfigError) as info:
        CsvMotion(times, poses, "pause")
    assert info.value.key == "end"
    with pytest.raises(ValueError, match="offset_s must be finite, got nan"):
        CsvMotion(times, poses, offset_s=float("nan"))
    assert hold.offset_s == 10.0 and CsvMotion(times, poses).offset_s == 0.0


def test_a_random_start_keeps_its_margin_unless_the_recording_is_shorter(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    write_motion_csv(path, 100.0 + np.arange(0.0, 31.0), np.zeros((31, 6)))
    short = CsvMotionConfig(str(path), start="random", random_margin_s=45.0)
    assert csv_motion_from_config(short, np.random.default_rng(1)).offset_s == 100.0
    config = CsvMotionConfig(str(path), start="random", random_margin_s=10.0)
    draw = np.random.default_rng(4).uniform(0.0, 1.0)
    offset = csv_motion_from_config(config, np.random.default_rng(4)).offset_s
    assert offset == pytest.approx(100.0 + draw * 20.0, rel=1e-15)
    looped = CsvMotionConfig(str(path), start="random", end="loop", random_margin_s=10.0)
    offset = csv_motion_from_config(looped, np.random.default_rng(4)).offset_s
    assert offset == pytest.approx(100.0 + draw * 30.0, rel=1e-15)
    # a replay of a vessel's log carries it to the config's helideck
    vessel = CsvMotionConfig(str(path), frame="vessel", helideck_position_m=(1.0, 2.0, 3.0))
    source = csv_motion_from_config(vessel, np.random.default_rng(0))
    assert source.recording is load_recording(path, "vessel", (1.0, 2.0, 3.0))
    assert source.end == "hold" and source.offset_s == 0.0


def test_a_csv_numpy_cannot_parse_at_once_is_read_row_by_row_to_the_same_samples(
    tmp_path: Path,
) -> None:
    path = tmp_path / "quoted.csv"
    path.write_text('t,x,y,z,roll,pitch,yaw\n"0",1,2,3,90,0,0\n   \n"1",1,2,3,180,0,0\n')
    times, poses = read_recording(path)
    np.testing.assert_array_equal(times, [0.0, 1.0])
    np.testing.assert_allclose(poses[:, 3], [math.pi / 2, math.pi])
    with pytest.raises(FileNotFoundError, match=r"motion recording '.*none\.csv' does not exist"):
        read_recording(tmp_path / "none.csv")


def test_a_recording_path_may_start_at_the_home_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HOME", str(tmp_path))
    write_motion_csv(tmp_path / "home.csv", np.array([0.0, 1.0]), np.full((2, 6), 0.25))
    times, poses = read_recording("~/home.csv")
    np.testing.assert_array_equal(times, [0.0, 1.0])
    assert poses[1, 0] == 0.25
    assert load_recording("~/home.csv").samples[0, 0] == 0.25
    source = CsvMotion.from_file("~/home.csv", end="loop", offset_s=0.5)
    assert source.offset_s == 0.5 and source.end == "loop"
    np.testing.assert_allclose(source.pose(0.0)[0], 0.25)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # a blank first line: the header is checked on the row-by-row path, naming the file
        (
            "\nT,x,y,z\n0,0,0,0\n",
            "bad.csv: header is 't,x,y,z'; expected 't,x,y,z,roll,pitch,yaw' "
            "(seconds, metres, degrees)",
        ),
        # rows numpy reads at once, but of another width than seven
        ("t,x,y,z,roll,pitch,yaw\n5\n", "bad.csv, line 2: expected 7 columns, got 1"),
        (
            "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0,0\n1,0,0,0,0,0,0,0\n",
            "bad.csv, line 2: expected 7 columns, got 8",
        ),
    ],
)
def test_a_recording_of_another_width_or_after_a_blank_line_is_refused_by_file_and_line(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(CsvMotionError) as info:
        read_recording(path)
    assert str(info.value) == f"{path}{message[len('bad.csv') :]}"


def test_an_npy_recording_of_another_shape_is_told_the_columns_it_needs(tmp_path: Path) -> None:
    np.save(tmp_path / "six.npy", np.zeros((3, 6)))
    with pytest.raises(CsvMotionError) as info:
        read_recording(tmp_path / "six.npy")
    assert str(info.value).endswith(
        "expected (N, 7) numbers, columns t,x,y,z,roll,pitch,yaw (seconds, metres, degrees)"
    )


def test_whole_number_poses_are_written_at_their_value_and_unpaired_ones_refused(
    tmp_path: Path,
) -> None:
    poses = np.array([[0, 0, 1, 1, 0, 0], [1, 2, 3, 0, 1, -1]])
    write_motion_csv(tmp_path / "whole.csv", [0, 1], poses)
    times, read = read_recording(tmp_path / "whole.csv")
    np.testing.assert_array_equal(times, [0.0, 1.0])
    np.testing.assert_allclose(read, poses, rtol=1e-15, atol=0.0)
    # three times and two poses: refused, not cut to two samples
    with pytest.raises(ValueError, match="zip"):
        write_motion_csv(tmp_path / "unpaired.csv", [0.0, 1.0, 2.0], poses)


def test_samples_are_held_in_double_precision_and_refused_with_what_they_need() -> None:
    recording = Recording.from_samples([0, 1, 3], np.ones((3, 6), dtype=np.float32))
    assert recording.times.dtype == np.float64 and recording.samples.dtype == np.float64
    np.testing.assert_array_equal(recording.times, [0.0, 1.0, 3.0])
    np.testing.assert_array_equal(recording.samples, np.ones((3, 6)))
    for times, poses, message in (
        ([0.0], np.zeros((1, 6)), "need at least two samples of (t, x, y, z, roll, pitch, yaw)"),
        ([0.0, 1.0], np.full((2, 6), np.nan), "samples must be finite"),
    ):
        with pytest.raises(CsvMotionError) as info:
            Recording.from_samples(np.array(times), poses)
        assert str(info.value) == message


def test_recordings_of_one_size_and_time_stamp_are_told_apart_by_their_path(
    tmp_path: Path,
) -> None:
    paths = [tmp_path / "a.csv", tmp_path / "b.csv"]
    for path, height_m in zip(paths, (0.25, 0.75), strict=True):
        write_motion_csv(path, np.array([0.0, 1.0]), np.full((2, 6), height_m))
        os.utime(path, ns=(1_700_000_000_000_000_000, 1_700_000_000_000_000_000))
    assert paths[0].stat().st_size == paths[1].stat().st_size
    assert load_recording(paths[0]).samples[0, 0] == 0.25
    assert load_recording(paths[1]).samples[0, 0] == 0.75


def test_a_replay_from_a_file_carries_a_vessels_log_to_the_helideck_given(tmp_path: Path) -> None:
    path = tmp_path / "vessel.csv"
    write_motion_csv(
        path, np.array([0.0, 1.0]), np.column_stack([np.zeros((2, 3)), np.full((2, 3), 0.1)])
    )
    source = CsvMotion.from_file(path, frame="vessel", helideck_position_m=(1.0, 2.0, 3.0))
    assert source.recording is load_recording(path, "vessel", (1.0, 2.0, 3.0))
    assert source.recording is not load_recording(path, "vessel")


def test_a_loop_wraps_over_the_files_span_whatever_its_first_stamp() -> None:
    # stamped from 3 s, 10 s long: episode time 15.5 s plays file time 3 + 12.5 mod 10
    times = np.array([3.0, 8.0, 13.0])
    loop = CsvMotion(times, np.zeros((3, 6)), "loop")
    local, held = loop.file_times(np.array([15.5, 24.0]))
    np.testing.assert_allclose(local, [5.5, 4.0], rtol=1e-15)
    assert not held.any()


def test_a_replay_takes_a_time_or_times_of_any_shape_and_precision() -> None:
    # a log stamped in Unix time: float32 episode times are taken at their value
    times, poses = smooth_log(1.7e9, 20.0, 10.0)
    source = CsvMotion(times, poses, "loop", offset_s=1.7e9)
    episode = np.array([0.25, 12.5], dtype=np.float32)
    local, held = source.file_times(episode)
    np.testing.assert_array_equal(local, 1.7e9 + episode.astype(float))
    local, held = source.file_times(3.0)
    assert local.shape == (1,) and held.shape == (1,) and local[0] == 1.7e9 + 3.0
    # episode times for the replay, file times for its interpolant: one row each, any shape
    for method, shift_s in (
        (source.poses, 0.0),
        (source.velocities, 0.0),
        (source.recording.interpolant, 1.7e9),
    ):
        column = np.array([[0.25], [12.5]]) + shift_s
        rows = method(column.reshape(-1))
        assert rows.shape == (2, 6)
        np.testing.assert_array_equal(method(column), rows)
        np.testing.assert_array_equal(method(column[0, 0]), rows[:1])


def test_an_array_file_whose_time_goes_back_is_refused_naming_the_sample(tmp_path: Path) -> None:
    values = np.zeros((4, 7))
    values[:, 0] = [0.0, 0.1, 0.2, 0.15]
    path = tmp_path / "back.npy"
    np.save(path, values)
    with pytest.raises(CsvMotionError) as info:
        load_recording(path)
    assert str(info.value) == f"{path}, sample 4: time 0.15 does not increase (previous 0.2)"
