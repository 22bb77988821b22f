"""``deck-landing bridge --input REC``: a recording's estimates, as ``deck-landing estimate``
gives them, sent as LANDING_TARGET and decoded by a pymavlink listener on loopback; the
recording's pace and vehicle pose; bad input named as ``estimate`` names it."""

from __future__ import annotations

import csv
import shutil
import socket
from argparse import Namespace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
pytest.importorskip("pymavlink")
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

import landing_env  # noqa: F401  (registers the environments)
from agents.cli import main
from agents.io.landing_target import CameraMount, VehiclePose, landing_target_fields
from agents.io.pacing import StampPacer
from agents.io.record import McapRecorder
from agents.io.recording import PoseSeries, write_folder
from agents.io.recording_source import RecordingSource
from agents.policies.align_descend import AlignDescendPolicy
from estimation.errors import ConfigError
from estimation.frames import R_BC
from landing_env.config import SHIPPED_INTRINSICS_FILE, load_config
from landing_env.physics.quadrotor_params import QuadrotorParams

F32 = np.float32
EPISODE_S = 3.0


def record_landing(path: Path) -> Path:
    """A few seconds of the align-descend policy in project mode, recorded to ``path``."""
    overrides = {"camera.mode": "project", "simulation.max_episode_s": EPISODE_S}
    env = McapRecorder(gym.make("DeckLanding-v2", config="default", overrides=overrides), path)
    base = env.unwrapped
    policy = AlignDescendPolicy(
        base.config.action, dt=base.env_dt, tof_mounts_c=base.config.tof.mount_offsets_c
    )
    observation, _ = env.reset(seed=5)
    policy.reset()
    while True:
        observation, _, terminated, truncated, _ = env.step(policy(observation))
        if terminated or truncated:
            break
    env.close()
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record_landing(tmp_path_factory.mktemp("rec") / "landing.mcap")


@pytest.fixture(scope="module")
def estimated(recording: Path, tmp_path_factory: pytest.TempPathFactory) -> list[dict]:
    """``deck-landing estimate``'s rows (every frame, in order) for ``tight``."""
    out = tmp_path_factory.mktemp("est") / "tight.csv"
    assert (
        main(["estimate", "--input", str(recording), "--estimator", "tight", "--out", str(out)])
        == 0
    )
    with out.open(newline="") as stream:
        return list(csv.DictReader(stream))


def _recorded(path: Path) -> tuple[list[int], dict[int, tuple], np.ndarray]:
    """The camera frames' stamps (ns, in order), the tf world -> body per stamp (ns) as
    (position, quaternion xyzw), and the tf body -> camera translation."""
    stamps, poses, mounts = [], {}, []
    with AnyReader([path]) as reader:
        wanted = [c for c in reader.connections if c.topic in ("/camera/tag_detections", "/tf")]
        for connection, _, raw in reader.messages(connections=wanted):
            message = reader.deserialize(raw, connection.msgtype)
            if connection.topic == "/camera/tag_detections":
                stamps.append(message.header.stamp.sec * 10**9 + message.header.stamp.nanosec)
                continue
            for tf in message.transforms:
                ns = tf.header.stamp.sec * 10**9 + tf.header.stamp.nanosec
                p, q = tf.transform.translation, tf.transform.rotation
                if (tf.header.frame_id, tf.child_frame_id) == ("world", "body"):
                    poses[ns] = (np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]))
                elif (tf.header.frame_id, tf.child_frame_id) == ("body", "camera"):
                    mounts.append(np.array([p.x, p.y, p.z]))
    # every recorded tf body -> camera is the vehicle's camera mount
    t_bc = QuadrotorParams.from_yaml(None).camera_offset_b
    assert len(mounts) >= len(stamps) and np.array_equal(np.unique(mounts, axis=0), [t_bc])
    return stamps, poses, mounts[0]


def _receive(sock: socket.socket, count: int) -> list:
    decoder = mavlink2.MAVLink(None)
    messages: list = []
    while len(messages) < count:
        data, _ = sock.recvfrom(4096)  # the socket's timeout bounds the wait
        messages += decoder.parse_buffer(data) or []
    return messages


def _bridge(listener: socket.socket, recording: Path, capsys, *extra: str) -> tuple[list, str]:
    """Run the command with ``--speed 0``; the LANDING_TARGETs decoded, and its report."""
    port = listener.getsockname()[1]
    argv = ["bridge", "--input", str(recording), "--to", f"udpout:127.0.0.1:{port}"]
    argv += ["--speed", "0", *extra]
    assert main(argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    sent = int(out.split("): ")[1].split(" sent")[0])
    heartbeats = int(out.split("Hz), ")[1].split(" heartbeats")[0])
    messages = _receive(listener, sent + heartbeats)
    targets = [m for m in messages if m.get_type() == "LANDING_TARGET"]
    assert len(targets) == sent
    return targets, out


def _pose_of(row: dict) -> tuple[np.ndarray, np.ndarray]:
    t_cd = np.array([float(row[f"{a}_camera_m"]) for a in "xyz"])
    q = [float(row[f"q{a}_camera"]) for a in "xyzw"]
    return Rotation.from_quat(q).as_matrix(), t_cd


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_the_recording_bridged_sends_what_estimate_gives_stamped_with_the_images(
    listener: socket.socket, recording: Path, estimated: list[dict], autopilot: str, capsys
) -> None:
    targets, out = _bridge(listener, recording, capsys, "--autopilot", autopilot)
    stamps_ns, poses, t_bc = _recorded(recording)
    assert len(estimated) == len(stamps_ns) >= 20
    valid = [(ns, row) for ns, row in zip(stamps_ns, estimated, strict=True) if row["valid"] == "1"]
    assert len(valid) >= len(estimated) // 2
    # every valid estimate went out, once, in order, each with its image's stamp
    assert len(targets) == len(valid)
    assert [m.time_usec for m in targets] == [round(ns / 1000) for ns, _ in valid]
    assert f"frames: {len(stamps_ns)} of {recording}" in out
    mount = CameraMount(R_BC, t_bc)  # the recorded camera mount
    for message, (ns, row) in zip(targets, valid, strict=True):
        r_cd, t_cd = _pose_of(row)
        vehicle = None
        if autopilot == "px4":
            position, q = poses[ns]  # the recorded tf at the image's stamp
            vehicle = VehiclePose.from_world(position, Rotation.from_quat(q).as_matrix())
        expected = landing_target_fields(autopilot, r_cd, t_cd, mount, vehicle)
        assert message.frame == expected.frame and message.position_valid == 1
        for name in ("x", "y", "z", "distance", "angle_x", "angle_y"):
            # from t_CD alone: the estimate's float64 to float32, bit for bit
            assert F32(getattr(message, name)) == F32(getattr(expected, name)), name
        # q passes through the CSV's quaternion: within one float32 step
        np.testing.assert_allclose(np.asarray(message.q), np.asarray(expected.q), atol=6e-8)
    if autopilot == "px4":  # the recorded tf puts the tag where the recorded deck is
        truth = _recorded_deck_ned(recording)
        errors = [np.linalg.norm([m.x, m.y, m.z] - truth[m.time_usec]) for m in targets]
        # tight in project mode, float32 on the wire: measured 35 um at most
        assert max(errors) < 1e-3, max(errors)


def _recorded_deck_ned(path: Path) -> dict[int, np.ndarray]:
    """The recorded tag centre in local NED, per stamp (us)."""
    truth = {}
    with AnyReader([path]) as reader:
        deck = [c for c in reader.connections if c.topic == "/truth/deck"]
        for connection, _, raw in reader.messages(connections=deck):
            message = reader.deserialize(raw, connection.msgtype)
            ns = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
            p = message.pose.position
            truth[round(ns / 1000)] = np.array([p.x, -p.y, -p.z])  # world -> NED
    return truth


def test_frames_are_played_at_their_stamps_pace(recording: Path) -> None:
    args = Namespace(
        input=str(recording), estimator="tight", config="default", calibration=None, set=[],
        tolerance=0.02, align="nearest",
    )  # fmt: skip
    source = RecordingSource(args, speed=2.0)
    now = [0.0]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    def wall() -> float:
        now[0] += 0.001  # each estimate takes a millisecond of wall time
        return now[0]

    first = source.rec.frames[0].timestamp
    source.pacer = StampPacer(2.0, first, wall, sleep)
    stamps = [stamp for stamp, _ in source]
    assert stamps == [f.timestamp for f in source.rec.frames]
    # each frame waited for (stamp - first) / 2 after the start: 25 ms at a 20 Hz camera
    assert len(slept) == len(stamps) - 1
    assert now[0] == pytest.approx(0.001 + (stamps[-1] - first) / 2.0)
    assert all(0.02 < s < 0.025 for s in slept[1:])
    assert source.clock_s() == pytest.approx(first + (now[0] - 0.001) * 2.0, abs=0.01)


# ------------------------------------------------------------------ bad input
def _error(capsys, argv: list[str]) -> str:
    """The command's one-line error, after ``deck-landing COMMAND: error:``."""
    assert main(argv) == 2
    return capsys.readouterr().err.strip().splitlines()[-1].split(": error: ", 1)[1]


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("missing", "no such file or folder"),
        ("truncated", "truncated or corrupt recording"),
        ("no camera topic", "missing topic: neither camera topic /nothing nor /nowhere"),
        ("no range topic", "--range-topics /no/ranges: not in"),
        ("estimator", "--estimator 'truth'; allowed:"),
    ],
)
def test_bad_input_gets_the_error_estimate_gives(
    recording: Path, tmp_path: Path, case: str, message: str, capsys
) -> None:
    path, extra, estimator = recording, [], "tight"
    if case == "missing":
        path = tmp_path / "nowhere.mcap"
    elif case == "truncated":
        path = tmp_path / "cut.mcap"
        path.write_bytes(recording.read_bytes()[: recording.stat().st_size // 2])
    elif case == "no camera topic":
        extra = ["--image-topic", "/nothing", "--detections-topic", "/nowhere"]
    elif case == "no range topic":
        extra = ["--range-topics", "/no/ranges", "--exact-ranges-topic", ""]
        estimator = "ihrcf"
    elif case == "estimator":
        estimator = "truth"
    common = ["--input", str(path), "--estimator", estimator, *extra]
    bridged = _error(
        capsys, ["bridge", "--to", "udpout:127.0.0.1:14550", "--autopilot", "ardupilot", *common]
    )
    if case != "estimator":  # estimate's own parser refuses an unknown estimator first
        assert bridged == _error(capsys, ["estimate", *common, "--out", str(tmp_path / "o.csv")])
    assert message in bridged


def test_px4_without_a_recorded_vehicle_pose_names_the_option(
    recording: Path, tmp_path: Path, capsys
) -> None:
    to = ["bridge", "--to", "udpout:127.0.0.1:14550", "--autopilot", "px4"]
    err = _error(capsys, [*to, "--input", str(recording), "--tf-topic", "/no_tf"])
    assert "px4 needs the vehicle's pose" in err and "--vehicle-pose mavlink" in err
    assert "no world -> body transform on /no_tf" in err
    # a plain folder holds no vehicle pose
    camera = load_config("default").camera
    image = np.full((camera.height, camera.width), 128, np.uint8)
    folder = write_folder(tmp_path / "rec", [(0.0, "f0.png", image)], [(0.0, [1.0] * 4)])
    err = _error(capsys, [*to, "--input", str(folder)])
    assert "a plain folder holds no vehicle pose" in err and "--vehicle-pose mavlink" in err


def test_the_camera_mount_is_needed_for_either_autopilot(
    recording: Path, tmp_path: Path, capsys
) -> None:
    calibration = tmp_path / "cal"
    calibration.mkdir()
    shutil.copy(SHIPPED_INTRINSICS_FILE, calibration / "intrinsics.json")
    argv = ["bridge", "--to", "udpout:127.0.0.1:14550", "--autopilot", "ardupilot"]
    err = _error(capsys, [*argv, "--input", str(recording), "--calibration", str(calibration)])
    assert f"--calibration {calibration}: no extrinsics.json" in err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--input", "REC", "--episodes", "2"], "--episodes: the simulator's options"),
        (["--input", "REC", "--seed", "3", "--mode", "render"], "--mode, --seed: the simulator's"),
        (["--tolerance", "0.01"], "--tolerance: the options of a recording; give --input"),
        (["--tf-topic", "/tf"], "--tf-topic: the options of a recording"),
        (["--vehicle-pose", "recording"], "--vehicle-pose recording: the pose recorded in"),
        (["--input", "REC", "--vehicle-pose", "truth"], "--vehicle-pose truth: the simulator's"),
    ],
)
def test_options_of_the_other_source_are_refused_by_name(
    recording: Path, extra: list[str], message: str, capsys
) -> None:
    extra = [str(recording) if e == "REC" else e for e in extra]
    argv = ["bridge", "--to", "udpout:127.0.0.1:14550", "--autopilot", "px4", *extra]
    assert message in _error(capsys, argv)


def test_input_with_a_config_or_scenario_is_refused(recording: Path, capsys) -> None:
    for other in (["--config", "default"], ["--scenario", "bench-ss4"]):
        argv = ["bridge", "--to", "udpout:127.0.0.1:14550", "--autopilot", "px4"]
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--input", str(recording), *other])
        assert exit_info.value.code == 2
        assert "not allowed with argument --input" in capsys.readouterr().err


# ------------------------------------------------------------------ the vehicle's pose
def _rotation(k: int) -> np.ndarray:
    return Rotation.from_rotvec([0.1 * k, -0.2 * k, 0.3 + 0.05 * k]).as_matrix()


@settings(max_examples=100, deadline=None)
@given(
    stamps=st.lists(st.floats(0.0, 10.0), min_size=0, max_size=8),
    query=st.one_of(st.floats(-1.0, 11.0), st.just(float("nan")), st.just(float("inf"))),
    tolerance=st.floats(0.0, 2.0),
    mode=st.sampled_from(["nearest", "interpolate"]),
)
def test_the_vehicle_pose_is_a_recorded_one_within_the_tolerance_or_none(
    stamps: list[float], query: float, tolerance: float, mode: str
) -> None:
    series = PoseSeries()
    for k, t in enumerate(stamps):  # any order
        series.add(t, _rotation(k), np.array([t, -t, 2.0 * t]))
    found = series.at(query, tolerance, mode)
    near = [t for t in stamps if abs(t - query) <= tolerance + 1e-12]
    if not near:
        assert found is None
        return
    # a pose of a stamp within the tolerance: nearest to the query, or between two stamps
    assert found is not None and min(near) - 1e-9 <= found[1][0] <= max(near) + 1e-9
    r_wb, t_wb = found
    assert np.allclose(r_wb @ r_wb.T, np.eye(3), atol=1e-9) and np.linalg.det(r_wb) > 0
    # the position is that of a recorded stamp, or between two: on the line x = -y = z / 2
    assert t_wb[0] == pytest.approx(-t_wb[1]) and t_wb[2] == pytest.approx(2.0 * t_wb[0])
    if mode == "nearest":
        assert abs(t_wb[0] - query) == pytest.approx(min(abs(t - query) for t in near))


# ------------------------------------------------------------------ the recording as a source
def _source(path: Path, align: str = "nearest", **topics: str) -> RecordingSource:
    args = Namespace(
        input=str(path), estimator="tight", config="default", calibration=None, set=[],
        tolerance=0.03, align=align, **topics,
    )  # fmt: skip
    return RecordingSource(args)


def test_a_source_plays_as_recorded_from_its_first_frame_by_default(tmp_path: Path) -> None:
    camera = load_config("default").camera
    image = np.full((camera.height, camera.width), 128, np.uint8)
    frames = [(1.7e9 + 0.05 * k, f"f{k}.png", image) for k in range(2)]  # stamps since 1970
    folder = write_folder(tmp_path / "rec", frames, [(t, [1.0] * 4) for t, _, _ in frames])
    source = _source(folder)
    assert source.pacer.speed == 1.0
    assert source.pacer.origin_s == 1.7e9  # the first frame is played at the start


def test_a_source_says_exactly_where_it_looked_for_the_vehicles_pose(
    recording: Path, tmp_path: Path
) -> None:
    camera = load_config("default").camera
    image = np.full((camera.height, camera.width), 128, np.uint8)
    folder = write_folder(tmp_path / "rec", [(0.0, "f0.png", image)], [(0.0, [1.0] * 4)])
    assert _source(folder).where_vehicle_poses() == "a plain folder holds no vehicle pose"
    assert _source(recording, tf_topic="").where_vehicle_poses() == "no tf topic read"
    assert (
        _source(recording, tf_topic="/no_tf", tf_frames="map,base").where_vehicle_poses()
        == "no map -> base transform on /no_tf (--tf-topic, --tf-frames)"
    )


def test_a_source_aligns_the_vehicles_pose_and_the_ranges_by_its_alignment(
    recording: Path,
) -> None:
    """With the ranges and poses halfway between frames, interpolation and the nearest sample
    differ: the source uses the alignment it was given for both."""
    source = _source(recording, "interpolate")
    rec = source.rec
    for series in rec.sensors:  # the ranges 20 ms after the frames
        series.t_s = [t + 0.02 for t in series.t_s]
    t_s = rec.vehicle.t_s[10] + 0.02
    between = rec.vehicle.at(t_s, 0.03, "interpolate")
    nearest = rec.vehicle.at(t_s, 0.03, "nearest")
    assert between is not None and nearest is not None
    assert not np.allclose(between[1], nearest[1])
    pose = source.vehicle_pose(t_s)
    assert isinstance(pose, VehiclePose)
    np.testing.assert_array_equal(
        pose.position_ned_m, VehiclePose.from_world(*between[::-1]).position_ned_m
    )
    played = [estimate.translation for _, estimate in source]
    interpolated = [e.translation for e, _ in source.runner.run(rec, 0.03, "interpolate")]
    nearest_ones = [e.translation for e, _ in source.runner.run(rec, 0.03, "nearest")]
    np.testing.assert_array_equal(played, interpolated)
    assert not np.allclose(played, nearest_ones, equal_nan=True)


# ------------------------------------------------------------------ the pace of the stamps
def test_a_pacer_refuses_a_speed_or_origin_it_cannot_play_naming_it() -> None:
    cases = [
        ({"speed": "fast"}, "speed: 'fast' is not a number"),
        ({"speed": None}, "speed: None is not a number"),
        ({"speed": -0.5}, "speed: -0.5 is out of range; allowed [0, inf), 0: unpaced"),
        ({"speed": float("inf")}, "speed: inf is out of range; allowed [0, inf), 0: unpaced"),
        ({"speed": float("nan")}, "speed: nan is out of range; allowed [0, inf), 0: unpaced"),
        ({"speed": 1.0, "origin_s": "x"}, "origin_s: 'x' is not a number"),
        ({"speed": 1.0, "origin_s": float("nan")}, "origin_s: nan is not a finite stamp (seconds)"),
        ({"speed": 1.0, "origin_s": -float("inf")}, "origin_s: -inf is not a finite stamp"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ConfigError) as refused:
            StampPacer(**kwargs)
        assert str(refused.value).startswith(message), (kwargs, str(refused.value))
    unpaced = StampPacer(0, origin_s="2.5")
    assert (unpaced.speed, unpaced.origin_s) == (0.0, 2.5)
    with pytest.raises(ConfigError) as refused:
        unpaced.clock_s()
    assert str(refused.value) == (
        "speed: 0 (unpaced): the stamps follow no clock; pace the source (> 0)"
    )
    assert unpaced.wait_until(1e9) == 0.0
    slept: list[float] = []
    paced = StampPacer(1.0, wall_clock=lambda: 5.0, sleep=slept.append)
    assert paced.origin_s == 0.0  # by default
    assert paced.wait_until(0.0) == 0.0 and paced.wait_until(-1.0) == 0.0 and not slept


@settings(max_examples=100, deadline=None)
@given(
    speed=st.floats(0.1, 10.0),
    origin_s=st.floats(-100.0, 100.0),
    start_s=st.floats(0.0, 1e4),
    ahead_s=st.lists(st.integers(-2000, 2000).map(lambda ms: ms * 1e-3), min_size=1, max_size=6),
)
def test_a_pacer_sleeps_until_each_stamp_is_due_on_the_clock_started_at_its_first_use(
    speed: float, origin_s: float, start_s: float, ahead_s: list[float]
) -> None:
    now = [start_s]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    pacer = StampPacer(speed, origin_s, lambda: now[0], sleep)
    assert pacer.clock_s() == origin_s  # the first use starts the clock
    assert pacer.start() == start_s  # and only the first
    for ahead in ahead_s:
        stamp_s = pacer.clock_s() + ahead
        waited = pacer.wait_until(stamp_s)
        if ahead > 0.0:
            assert waited == slept[-1] == pytest.approx(ahead / speed)
            assert pacer.clock_s() == pytest.approx(stamp_s)
        else:  # late or on time: no wait
            assert waited == 0.0
    assert sum(slept) == pytest.approx(now[0] - start_s)
