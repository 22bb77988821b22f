"""``deck-landing evaluate landing --record FILE.mcap``: the first episode as ROS 2 messages,
readable by the independent ``mcap`` reader, and the same episode as in the results."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mcap_ros2")
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from agents.cli import main
from agents.evaluation.landing import HELD_OUT_SEED
from agents.policies.registry import make_env_and_policy

SCENARIO = "bench-ss4"
POLICY = "align-descend"
MAX_EPISODE_S = 0.5


def _evaluate(out: Path, workers: int, *extra: str) -> int:
    return main(
        ["evaluate", "landing", "--policy", POLICY, "--scenario", SCENARIO, "--episodes", "2",
         "--workers", str(workers), "--mode", "render", "--no-progress", "--out", str(out),
         "--set", f"simulation.max_episode_s={MAX_EPISODE_S}", *extra]
    )  # fmt: skip


def _results(out: Path) -> list[dict]:
    path = out / f"landing_{SCENARIO}_{POLICY}.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()]


def _read(path: Path) -> tuple[dict[str, str], dict[str, int], list]:
    """Topic -> schema name, topic -> message count, and the decoded /truth/drone poses."""
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = {
            summary.channels[cid].topic: n
            for cid, n in summary.statistics.channel_message_counts.items()
        }
        drone = []
        for _, _, _, message in reader.iter_decoded_messages(topics=["/truth/drone"]):
            p = message.pose.position
            drone.append((p.x, p.y, p.z))
    return schemas, counts, drone


def _first_position_of_the_seed() -> np.ndarray:
    overrides = {"simulation.max_episode_s": MAX_EPISODE_S}
    env, _ = make_env_and_policy(POLICY, SCENARIO, extra_overrides=overrides)
    try:
        env.reset(seed=HELD_OUT_SEED)
        return env.unwrapped.world.drone_state().position_w.copy()
    finally:
        env.close()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("landing")
    record = out / "first.mcap"
    assert _evaluate(out, 1, "--record", str(record)) == 0
    return out, record


def test_the_recording_holds_the_sensors_tf_and_estimates_as_ros2_schemas(
    recorded: tuple[Path, Path],
) -> None:
    _, record = recorded
    schemas, counts, _ = _read(record)
    assert schemas["/camera/image_raw"] == "sensor_msgs/msg/Image"
    assert schemas["/tof/range"] == "sensor_msgs/msg/Range"
    assert schemas["/imu/data"] == "sensor_msgs/msg/Imu"
    assert schemas["/tf"] == "tf2_msgs/msg/TFMessage"
    assert schemas["/estimates/status"] == "deck_landing_msgs/msg/EstimateStatus"
    poses = [t for t in schemas if t.startswith("/estimates/") and t != "/estimates/status"]
    assert poses and all(schemas[t] == "geometry_msgs/msg/PoseWithCovarianceStamped" for t in poses)
    # one frame at the reset and one per step, four ranges each: one episode, not two
    frames = counts["/tf"]
    assert counts["/camera/image_raw"] == frames and counts["/tof/range"] == 4 * frames
    assert counts["/imu/data"] >= frames


def test_the_recorded_episode_is_the_first_seeds_and_recording_changes_no_result(
    recorded: tuple[Path, Path], tmp_path: Path
) -> None:
    out, record = recorded
    _, _, drone = _read(record)
    np.testing.assert_allclose(drone[0], _first_position_of_the_seed(), rtol=0, atol=1e-9)
    assert _evaluate(tmp_path, 1) == 0
    assert _results(out) == _results(tmp_path)
    assert [r["seed"] for r in _results(out)] == [HELD_OUT_SEED, HELD_OUT_SEED + 1]


def test_with_two_workers_the_worker_running_the_first_seed_records_it(
    recorded: tuple[Path, Path], tmp_path: Path
) -> None:
    _, serial = recorded
    record = tmp_path / "first.mcap"
    assert _evaluate(tmp_path / "out", 2, "--record", str(record)) == 0
    serial_schemas, serial_counts, serial_drone = _read(serial)
    schemas, counts, drone = _read(record)
    assert (schemas, counts) == (serial_schemas, serial_counts)
    # Ray's workers run BLAS on one thread: the same trajectory to round-off
    np.testing.assert_allclose(drone, serial_drone, rtol=0, atol=1e-9)


def test_resume_runs_the_recorded_seed_again_and_keeps_the_others(tmp_path: Path) -> None:
    assert _evaluate(tmp_path, 1) == 0
    before = _results(tmp_path)
    record = tmp_path / "first.mcap"
    assert _evaluate(tmp_path, 1, "--resume", "--record", str(record)) == 0
    _, counts, _ = _read(record)
    assert counts["/tf"] > 1
    after = _results(tmp_path)
    # the recorded seed ran again (appended, the same record); the other one was kept
    assert after == [*before, before[0]]
