"""Simulator -> MCAP -> ``deck-landing estimate``: the same estimates, standard schemas."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

import landing_env  # noqa: F401
from agents.cli import main
from agents.io.record import McapRecorder
from estimation.types import DeckPoseEstimate

STEPS = 12
COMPARED = ["atda", "crhf", "tight"]


def record_episode(path: Path) -> Path:
    """A short project-mode episode, hovering, recorded to ``path``."""
    overrides = {"camera.mode": "project", "estimation.compare": COMPARED}
    env = McapRecorder(gym.make("DeckLanding-v2", config="default", overrides=overrides), path)
    env.reset(seed=3)
    for _ in range(STEPS):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record_episode(tmp_path_factory.mktemp("rec") / "episode.mcap")


def _poses(path: Path, topic: str) -> dict[int, tuple]:
    """Per stamp (ns), the pose on ``topic`` as decoded by mcap-ros2-support."""
    poses = {}
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, _, _, message in reader.iter_decoded_messages(topics=[topic]):
            p = message.pose.pose
            stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
            poses[stamp] = (
                p.position.x,
                p.position.y,
                p.position.z,
                p.orientation.x,
                p.orientation.y,
                p.orientation.z,
                p.orientation.w,
            )
    return poses


def test_the_recording_opens_in_rosbags_as_standard_ros2_schemas(recording: Path) -> None:
    with AnyReader([recording]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
        tf_frames = set()
        for connection, _, raw in reader.messages(
            connections=[c for c in reader.connections if c.topic == "/tf"]
        ):
            for transform in reader.deserialize(raw, connection.msgtype).transforms:
                tf_frames.add((transform.header.frame_id, transform.child_frame_id))
    assert types["/tof/range"] == "sensor_msgs/msg/Range"
    assert types["/imu/data"] == "sensor_msgs/msg/Imu"
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert types["/estimates/ihrcf"] == "geometry_msgs/msg/PoseWithCovarianceStamped"
    assert types["/truth/deck_pose"] == "geometry_msgs/msg/PoseStamped"
    assert counts["/tof/range"] == 4 * (STEPS + 1)
    assert counts["/tf"] == STEPS + 1
    assert tf_frames == {("world", "body"), ("body", "camera"), ("world", "deck")}


@pytest.mark.parametrize("method", ["ihrcf", *COMPARED])
def test_estimate_on_the_recording_reproduces_the_simulator_exactly(
    recording: Path, tmp_path: Path, method: str
) -> None:
    out = tmp_path / f"{method}.mcap"
    code = main(["estimate", "--input", str(recording), "--estimator", method, "--out", str(out)])
    assert code == 0
    in_sim = _poses(recording, f"/estimates/{method}")
    replayed = _poses(out, "/deck_pose/camera")
    assert len(in_sim) >= STEPS // 2
    assert replayed == in_sim  # bit for bit, the same frames valid
    assert out.with_suffix(".csv").read_text().count("\n") == STEPS + 2


def test_the_truth_is_recorded_on_its_topics_in_its_frames(recording: Path) -> None:
    frames: dict[str, set[str]] = {}
    with AnyReader([recording]) as reader:
        truth = [c for c in reader.connections if c.topic.startswith("/truth/")]
        for connection, _, raw in reader.messages(connections=truth):
            message = reader.deserialize(raw, connection.msgtype)
            frames.setdefault(connection.topic, set()).add(message.header.frame_id)
        counts = {c.topic: c.msgcount for c in truth}
    assert frames == {
        "/truth/drone": {"world"},
        "/truth/deck": {"world"},
        "/truth/deck_pose": {"camera"},
    }
    assert set(counts.values()) == {STEPS + 1}


def test_a_rendered_episode_records_its_images_and_only_the_first_episode_by_default(
    tmp_path: Path,
) -> None:
    path = tmp_path / "new" / "folder" / "rendered.mcap"  # made with its parents
    overrides = {"camera.mode": "render", "estimation.compare": []}
    env = McapRecorder(gym.make("DeckLanding-v2", config="default", overrides=overrides), path)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    env.reset(seed=3)
    env.step(zero)
    env.reset(seed=4)  # a second episode: not recorded
    env.step(zero)
    assert env.episodes == 2
    written = env.messages
    env.close()
    with AnyReader([path]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        images = [c for c in reader.connections if c.topic == "/camera/image_raw"]
        for connection, _, raw in reader.messages(connections=images):
            image = reader.deserialize(raw, connection.msgtype)
            assert (image.header.frame_id, image.encoding) == ("camera", "rgb8")
        detections = [c for c in reader.connections if c.topic == "/camera/tag_detections"]
        for connection, _, raw in reader.messages(connections=detections):
            assert reader.deserialize(raw, connection.msgtype).header.frame_id == "camera"
    assert counts["/camera/image_raw"] == counts["/tf"] == 2  # the reset and the step
    assert written == sum(counts.values())


def test_every_imu_sample_is_recorded_with_the_attitude_only_at_the_frames_stamp(
    tmp_path: Path,
) -> None:
    path = tmp_path / "imu.mcap"
    overrides = {"camera.mode": "project", "estimation.compare": []}
    env = McapRecorder(gym.make("DeckLanding-v2", config="default", overrides=overrides), path)
    _, info = env.reset(seed=3)
    samples = [np.asarray(info["imu_samples"], dtype=float).reshape(-1, 7)]
    attitudes = {}  # R_WB at each frame's stamp (ns)
    for _ in range(3):
        state = env.unwrapped.world.drone_state()
        attitudes[round(env.unwrapped._sensing.frame.timestamp * 1e9)] = state.rotation_wb
        _, _, _, _, info = env.step(np.full(env.action_space.shape, 0.5, dtype=np.float32))
        samples.append(np.asarray(info["imu_samples"], dtype=float).reshape(-1, 7))
    state = env.unwrapped.world.drone_state()
    attitudes[round(env.unwrapped._sensing.frame.timestamp * 1e9)] = state.rotation_wb
    env.close()
    rows = np.concatenate(samples)
    assert len(rows) > 4
    with AnyReader([path]) as reader:
        imu = [c for c in reader.connections if c.topic == "/imu/data"]
        got = [
            (log_ns, reader.deserialize(raw, c.msgtype))
            for c, log_ns, raw in reader.messages(connections=imu)
        ]
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/tof/ranges"] == counts["/camera/tag_detections"] == 4
    assert len(got) == len(rows)
    at_frames = 0
    for (log_ns, message), row in zip(got, rows, strict=True):
        stamp_ns = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        assert stamp_ns == log_ns == round(row[0] * 1e9) and message.header.frame_id == "body"
        a, g = message.linear_acceleration, message.angular_velocity
        assert [a.x, a.y, a.z, g.x, g.y, g.z] == row[1:].tolist()
        q = message.orientation
        if stamp_ns in attitudes:  # the frame's sample: the attitude, known
            at_frames += 1
            assert message.orientation_covariance[0] == 0.0
            np.testing.assert_allclose(
                Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), attitudes[stamp_ns],
                atol=1e-12,
            )  # fmt: skip
        else:  # REP 145: unknown
            assert message.orientation_covariance.tolist() == [-1.0] + [0.0] * 8
            assert [q.x, q.y, q.z, q.w] == [0.0, 0.0, 0.0, 1.0]
    assert at_frames >= 3
    # the drone tilted: every component of its quaternion tells
    tilted = [Rotation.from_matrix(r).as_quat() for r in attitudes.values()]
    assert max(abs(q[0] - q[1]) for q in tilted) > 1e-3


def test_each_estimate_has_its_status_and_only_a_valid_finite_one_a_pose(tmp_path: Path) -> None:
    path = tmp_path / "estimates.mcap"
    overrides = {"camera.mode": "project", "estimation.compare": []}
    env = McapRecorder(gym.make("DeckLanding-v2", config="default", overrides=overrides), path)
    env.reset(seed=3)
    nan_t = np.array([np.nan, 0.0, 1.0])
    finite_t = np.array([0.1, 0.2, 1.0])
    estimates = {
        "good": DeckPoseEstimate("g", 0.5, True, np.eye(3), finite_t, covariance=np.eye(6)),
        "nan_translation": DeckPoseEstimate("n", 0.5, True, np.eye(3), nan_t),
        "nan_rotation": DeckPoseEstimate("r", 0.5, True, np.full((3, 3), np.nan), finite_t),
        "invalid": DeckPoseEstimate("i", 0.5, False, np.eye(3), finite_t, reason="why"),
    }
    for name, estimate in estimates.items():
        env._estimate(name, estimate, 0.5)
    env.close()
    with AnyReader([path]) as reader:
        topics = {c.topic for c in reader.connections}
        status = [c for c in reader.connections if c.topic == "/estimates/status"]
        said = [
            reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=status)
        ]
        poses = [c for c in reader.connections if c.topic == "/estimates/good"]
        (pose,) = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(poses)]
    mine = [s for s in said if s.method in estimates]
    assert [(s.method, s.valid, s.reason, s.header.frame_id) for s in mine] == [
        ("good", True, "", "camera"), ("nan_translation", True, "", "camera"),
        ("nan_rotation", True, "", "camera"), ("invalid", False, "why", "camera"),
    ]  # fmt: skip
    assert not topics & {
        "/estimates/nan_translation",
        "/estimates/nan_rotation",
        "/estimates/invalid",
    }
    assert pose.header.frame_id == "camera"
    assert pose.pose.covariance.tolist() == np.eye(6).reshape(-1).tolist()
