"""The MAVLink bridge: LANDING_TARGET and HEARTBEAT as a real pymavlink client decodes them,
each autopilot's frame convention on hand-worked cases, and clear errors for bad arguments."""

from __future__ import annotations

import math
import socket

import numpy as np
import pytest

pytest.importorskip("pymavlink")
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from agents.cli import main
from agents.common.user_input import UserError
from agents.io.landing_target import (
    CameraMount,
    VehiclePose,
    ardupilot_fields,
    ardupilot_parameters,
    landing_target_fields,
    px4_fields,
    quaternion_wxyz,
)
from agents.io.mavlink import (
    LandingTargetBridge,
    MavlinkLink,
    parse_connection_url,
    time_usec_of,
)
from estimation.errors import ConfigError
from estimation.frames import deck_pose_in_camera, matrix_from_euler_zyx
from estimation.types import DeckPoseEstimate

F32 = np.float32


def receive(sock: socket.socket, count: int, max_datagrams: int = 2000) -> list:
    """Decode with pymavlink until ``count`` messages arrived (bounded; a timeout raises)."""
    decoder = mavlink2.MAVLink(None)
    messages: list = []
    for _ in range(max_datagrams):
        if len(messages) >= count:
            break
        data, _ = sock.recvfrom(4096)
        messages += decoder.parse_buffer(data) or []
    return messages


def url_of(sock: socket.socket) -> str:
    return f"udpout:127.0.0.1:{sock.getsockname()[1]}"


def estimate(rotation: np.ndarray, translation, stamp: float = 0.0) -> DeckPoseEstimate:
    return DeckPoseEstimate(
        "tight", stamp, True, np.asarray(rotation, float), np.asarray(translation, float)
    )


class FakeClock:
    def __init__(self, step_s: float) -> None:
        self.now, self.step_s = 0.0, step_s

    def __call__(self) -> float:
        now = self.now
        self.now += self.step_s
        return now


# ------------------------------------------------------------------ frames, hand-worked
def test_ardupilot_gets_the_line_of_sight_from_the_camera_in_body_frd() -> None:
    # level drone: the tag 0.3 m right in the image, 0.2 m up the image (forward), 2 m down
    mount = CameraMount(t_bc=np.array([0.1, 0.0, -0.05]))
    fields = ardupilot_fields(np.eye(3), np.array([0.3, -0.2, 2.0]), mount)
    assert fields.frame == mavlink2.MAV_FRAME_BODY_FRD
    assert (fields.x, fields.y, fields.z) == pytest.approx((0.2, 0.3, 2.0), abs=1e-12)
    assert fields.distance == pytest.approx(math.sqrt(0.09 + 0.04 + 4.0), abs=1e-12)
    assert fields.q == pytest.approx((1.0, 0.0, 0.0, 0.0), abs=1e-12)
    assert fields.angle_x == pytest.approx(math.atan(0.3 / 2.0))
    assert fields.angle_y == pytest.approx(math.atan(-0.2 / 2.0))
    # the camera's offset is ArduPilot's parameter, in body FRD (0.05 m above: -0.05 down)
    params = ardupilot_parameters(mount)
    assert (params["PLND_CAM_POS_X"], params["PLND_CAM_POS_Y"]) == (0.1, 0.0)
    assert params["PLND_CAM_POS_Z"] == pytest.approx(0.05)
    assert params["PLND_ORIENT"] == 25 and params["PLND_YAW_ALIGN"] == 0


def test_px4_gets_the_tag_centre_in_local_ned_from_the_vehicle_pose() -> None:
    # the same level drone at world (1, 2, 5): NED (1, -2, -5); tag at body FLU
    # (0.1, 0, -0.05) + (0.2, -0.3, -2.0) = (0.3, -0.3, -2.05) -> NED offset (0.3, 0.3, 2.05)
    mount = CameraMount(t_bc=np.array([0.1, 0.0, -0.05]))
    vehicle = VehiclePose.from_world(np.array([1.0, 2.0, 5.0]), np.eye(3))
    fields = px4_fields(np.eye(3), np.array([0.3, -0.2, 2.0]), mount, vehicle)
    assert fields.frame == mavlink2.MAV_FRAME_LOCAL_NED
    assert (fields.x, fields.y, fields.z) == pytest.approx((1.3, -1.7, -2.95), abs=1e-12)
    assert fields.q == pytest.approx((1.0, 0.0, 0.0, 0.0), abs=1e-12)


def test_a_drone_yawed_left_sees_the_north_facing_deck_turned_right_in_body_frd() -> None:
    # yaw +90 deg (FLU world: the nose to +y_W, west); a level deck, bow north, 1 m ahead
    # of the nose and 2 m below the camera
    r_wb = matrix_from_euler_zyx(0.0, 0.0, math.pi / 2)
    t_wb = np.array([0.0, 0.0, 2.0])
    r_cd, t_cd = deck_pose_in_camera(t_wb, r_wb, np.array([0.0, 1.0, 0.0]), np.eye(3), np.zeros(3))
    assert t_cd == pytest.approx((0.0, -1.0, 2.0), abs=1e-12)
    mount = CameraMount()
    ardu = ardupilot_fields(r_cd, t_cd, mount)
    assert (ardu.x, ardu.y, ardu.z) == pytest.approx((1.0, 0.0, 2.0), abs=1e-12)
    # the deck's bow lies 90 deg to the right of the nose: yaw +90 deg about FRD z
    half = math.sqrt(0.5)
    assert ardu.q == pytest.approx((half, 0.0, 0.0, half), abs=1e-12)
    px4 = px4_fields(r_cd, t_cd, mount, VehiclePose.from_world(t_wb, r_wb))
    # 1 m west of the vehicle (NED y = -1), on the ground (2 m below it: z = 0)
    assert (px4.x, px4.y, px4.z) == pytest.approx((0.0, -1.0, 0.0), abs=1e-12)
    assert px4.q == pytest.approx((1.0, 0.0, 0.0, 0.0), abs=1e-12)


def test_px4_turns_the_camera_ray_of_a_rolled_drone_into_ned() -> None:
    # right wing down by 10 deg; the tag on the optical axis 3 m away lies west, below
    roll = math.radians(10.0)
    vehicle = VehiclePose.from_world(np.zeros(3), matrix_from_euler_zyx(roll, 0.0, 0.0))
    fields = px4_fields(np.eye(3), np.array([0.0, 0.0, 3.0]), CameraMount(), vehicle)
    expected = (0.0, -3.0 * math.sin(roll), 3.0 * math.cos(roll))
    assert (fields.x, fields.y, fields.z) == pytest.approx(expected, abs=1e-12)


def test_the_quaternion_is_scalar_first_and_non_negative() -> None:
    q = quaternion_wxyz(np.diag([-1.0, -1.0, 1.0]))  # 180 deg about z
    assert q == pytest.approx((0.0, 0.0, 0.0, 1.0), abs=1e-12)
    w, *_ = quaternion_wxyz(matrix_from_euler_zyx(0.1, -0.2, 3.0))
    assert w >= 0.0


# ------------------------------------------------------------------ on the wire
@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_pymavlink_listener_decodes_every_field_as_the_estimate_gives_it(
    listener: socket.socket, autopilot: str
) -> None:
    rng = np.random.default_rng(3)
    mount = CameraMount(t_bc=np.array([0.02, -0.01, -0.03]))
    vehicle = VehiclePose.from_world(
        np.array([3.0, -4.0, 6.5]), matrix_from_euler_zyx(0.05, -0.08, 1.2)
    )
    estimates = [
        estimate(
            matrix_from_euler_zyx(*rng.uniform(-0.2, 0.2, 3)),
            [*rng.uniform(-0.5, 0.5, 2), rng.uniform(0.5, 4.0)],
            stamp=12.345678 + 0.05 * k,
        )
        for k in range(5)
    ]
    with MavlinkLink(url_of(listener), system_id=7, component_id=191) as link:
        bridge = LandingTargetBridge(
            link, autopilot, mount, vehicle_pose=lambda stamp: vehicle, clock=FakeClock(0.0)
        )
        stats = bridge.run((e.timestamp, e) for e in estimates)
    assert stats.sent == 5 and stats.heartbeats == 1 and not stats.skipped
    messages = receive(listener, 6)
    heartbeat, targets = messages[0], messages[1:]
    assert heartbeat.get_type() == "HEARTBEAT"
    assert heartbeat.type == mavlink2.MAV_TYPE_ONBOARD_CONTROLLER
    assert heartbeat.autopilot == mavlink2.MAV_AUTOPILOT_INVALID
    assert heartbeat.system_status == mavlink2.MAV_STATE_ACTIVE
    assert (heartbeat.get_srcSystem(), heartbeat.get_srcComponent()) == (7, 191)
    assert [m.get_type() for m in targets] == ["LANDING_TARGET"] * 5
    for message, sent in zip(targets, estimates, strict=True):
        expected = landing_target_fields(autopilot, sent.rotation, sent.translation, mount, vehicle)
        assert message.get_header().mlen > 30  # MAVLink 2 with its extension fields
        assert message.time_usec == round(sent.timestamp * 1e6)
        assert message.frame == expected.frame
        assert message.position_valid == 1
        assert message.type == mavlink2.LANDING_TARGET_TYPE_VISION_FIDUCIAL
        assert message.target_num == 0
        for name in ("x", "y", "z", "distance", "angle_x", "angle_y"):
            assert F32(getattr(message, name)) == F32(getattr(expected, name)), name
        assert (message.size_x, message.size_y) == (0.0, 0.0)
        assert np.array_equal(np.asarray(message.q, F32), np.asarray(expected.q, F32))
        assert (message.get_srcSystem(), message.get_srcComponent()) == (7, 191)


def test_invalid_and_stale_estimates_are_never_sent_as_valid(listener: socket.socket) -> None:
    good = estimate(np.eye(3), [0.1, 0.2, 1.5], stamp=1.0)
    nan = estimate(np.eye(3), [np.nan, 0.2, 1.5], stamp=1.1)
    behind = estimate(np.eye(3), [0.0, 0.0, -1.0], stamp=1.2)
    later = estimate(np.eye(3), [0.1, 0.2, 1.4], stamp=1.3)
    stream = [
        (1.0, good),
        (1.05, DeckPoseEstimate.invalid("tight", 1.05, "out_of_view")),
        (1.0, good),  # the vision link holding the last delivery: the same stamp again
        (1.1, nan),
        (1.2, behind),
        (1.3, later),
    ]
    with MavlinkLink(url_of(listener)) as link:
        bridge = LandingTargetBridge(link, "ardupilot", clock=FakeClock(0.0))
        results = [bridge.send(stamp, est) for stamp, est in stream]
    assert results == [
        "sent",
        "invalid: out_of_view",
        "not newer than the last sent",
        "non-finite pose",
        "target not in front of the camera",
        "sent",
    ]
    messages = [m for m in receive(listener, 3) if m.get_type() == "LANDING_TARGET"]
    assert [m.time_usec for m in messages] == [1_000_000, 1_300_000]
    assert all(m.position_valid == 1 for m in messages)


def test_the_heartbeat_goes_out_about_once_a_second(listener: socket.socket) -> None:
    with MavlinkLink(url_of(listener)) as link:
        bridge = LandingTargetBridge(link, "ardupilot", clock=FakeClock(0.25))
        for k in range(9):  # 0 .. 2.0 s on the bridge's clock
            bridge.send(k * 0.1 + 0.1, estimate(np.eye(3), [0.0, 0.0, 2.0]))
    assert bridge.stats.heartbeats == 3
    kinds = [m.get_type() for m in receive(listener, 12)]
    assert kinds.count("HEARTBEAT") == 3 and kinds.count("LANDING_TARGET") == 9


@settings(max_examples=150, deadline=None)
@given(
    valid=st.booleans(),
    values=st.lists(
        st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-10.0, 10.0)),
        min_size=12,
        max_size=12,
    ),
    stamp=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(0.0, 1e5)),
    autopilot=st.sampled_from(["px4", "ardupilot"]),
)
def test_no_estimate_crashes_the_bridge_or_leaves_as_a_non_finite_message(
    valid: bool, values: list[float], stamp: float, autopilot: str
) -> None:
    sent: list = []

    class RecordingLink:
        def send_heartbeat(self) -> None:
            pass

        def send_landing_target(self, time_usec: int, fields) -> None:
            sent.append((time_usec, fields))

    rotation = np.asarray(values[:9]).reshape(3, 3)
    with np.errstate(all="ignore"):
        proper = np.all(np.isfinite(rotation)) and abs(np.linalg.det(rotation)) > 1e-3
    if valid and proper:
        rotation = np.linalg.qr(rotation)[0]  # often a rotation, sometimes a reflection
    fuzzed = DeckPoseEstimate("tight", 0.0, valid, rotation, np.asarray(values[9:]))
    vehicle = VehiclePose.from_world(np.zeros(3), np.eye(3))
    bridge = LandingTargetBridge(
        RecordingLink(), autopilot, vehicle_pose=lambda s: vehicle, clock=FakeClock(0.0)
    )
    result = bridge.send(stamp, fuzzed)
    assert (result == "sent") == bool(sent)
    for time_usec, fields in sent:
        assert valid and time_usec >= 0
        values_out = [fields.x, fields.y, fields.z, fields.distance, *fields.q]
        assert all(math.isfinite(v) for v in values_out)
        assert fields.distance > 0.0


# ------------------------------------------------------------------ the live simulator
def test_the_simulator_bridged_to_px4_puts_the_true_tag_at_its_ned_position(
    listener: socket.socket,
) -> None:
    from agents.io.sim_source import SimulatorSource

    truth: dict[float, np.ndarray] = {}
    with (
        SimulatorSource(
            estimator="truth",
            speed=0.0,
            overrides={"simulation.max_episode_s": 0.5},
        ) as source,
        MavlinkLink(url_of(listener)) as link,
    ):
        bridge = LandingTargetBridge(link, "px4", source.mount, source.vehicle_pose)
        for stamp, est in source:
            tag_w = source.base.world.deck_state().tag_centre_w
            truth[stamp] = np.array([tag_w[0], -tag_w[1], -tag_w[2]])  # world -> NED
            assert bridge.send(stamp, est) == "sent"
    assert len(truth) == 11  # the reset and 10 steps of 0.05 s
    messages = [m for m in receive(listener, 12) if m.get_type() == "LANDING_TARGET"]
    assert [m.time_usec for m in messages] == [time_usec_of(s) for s in truth]
    for message, expected in zip(messages, truth.values(), strict=True):
        assert (message.x, message.y, message.z) == pytest.approx(tuple(expected), abs=1e-5)


def test_the_simulators_stamps_run_on_across_episodes() -> None:
    from agents.io.sim_source import SimulatorSource

    with SimulatorSource(
        estimator="truth", episodes=2, speed=0.0, overrides={"simulation.max_episode_s": 0.2}
    ) as source:
        stamps = [stamp for stamp, _ in source]
        assert source.vehicle_pose(stamps[-1]) is not None
    assert len(stamps) == 10 and len(source.outcomes) == 2
    assert np.all(np.diff(stamps) > 0.0)
    # the second episode starts one control period after the first one's end
    assert stamps[5] == pytest.approx(0.2 + 0.05)


def test_the_bridge_command_flies_an_episode_and_sends_it(listener: socket.socket, capsys) -> None:
    port = listener.getsockname()[1]
    argv = ["bridge", "--to", f"udpout:127.0.0.1:{port}", "--autopilot", "ardupilot"]
    argv += ["--speed", "0", "--set", "simulation.max_episode_s=0.5"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"LANDING_TARGET to udpout:127.0.0.1:{port} (ardupilot)" in out
    assert "PLND_CAM_POS_Z=" in out
    sent = int(out.split("): ")[1].split(" sent")[0])
    heartbeats = int(out.split("Hz), ")[1].split(" heartbeats")[0])
    messages = receive(listener, sent + heartbeats)
    targets = [m for m in messages if m.get_type() == "LANDING_TARGET"]
    assert len(targets) == sent >= 1
    assert all(m.frame == mavlink2.MAV_FRAME_BODY_FRD and m.position_valid == 1 for m in targets)


# ------------------------------------------------------------------ bad arguments
@pytest.mark.parametrize(
    "url", ["udpout:127.0.0.1", "udpout:127.0.0.1:99999", "http://x:1", "localhost:14550", ""]
)
def test_a_bad_connection_url_is_refused_naming_the_argument_and_the_forms(url: str) -> None:
    with pytest.raises(UserError, match="--to"):
        parse_connection_url(url)


def test_the_bridge_command_reports_a_bad_url_in_one_line(capsys) -> None:
    assert main(["bridge", "--to", "udp-out:1.2.3.4:1", "--autopilot", "px4"]) == 2
    err = capsys.readouterr().err
    assert "--to: 'udp-out:1.2.3.4:1' is not a MAVLink connection" in err
    assert "udpout:HOST:PORT" in err


def test_an_unknown_autopilot_is_refused_with_the_choices(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["bridge", "--to", "udpout:127.0.0.1:14550", "--autopilot", "inav"])
    assert exit_info.value.code == 2
    assert "'inav'" in capsys.readouterr().err
    with pytest.raises(ConfigError, match=r"autopilot.*'px4', 'ardupilot'"):
        LandingTargetBridge(object(), "inav")  # type: ignore[arg-type]


def test_px4_without_the_vehicle_pose_is_refused_naming_the_frame() -> None:
    with pytest.raises(ConfigError, match="MAV_FRAME_LOCAL_NED"):
        LandingTargetBridge(object(), "px4")  # type: ignore[arg-type]


def test_out_of_range_mavlink_ids_are_refused() -> None:
    with pytest.raises(UserError, match="--system-id: 0 is out of range"):
        MavlinkLink("udpout:127.0.0.1:14550", system_id=0)
