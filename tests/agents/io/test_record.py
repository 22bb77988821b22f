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

import landing_env  # noqa: F401
from agents.cli import main
from agents.io.record import McapRecorder

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
