"""The MAVLink bridge: LANDING_TARGET and HEARTBEAT as a real pymavlink client decodes them,
each autopilot's frame convention on hand-worked cases, and clear errors for bad arguments."""

from __future__ import annotations

import math
import socket
from collections.abc import Iterator

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
    LandingTargetFields,
    VehiclePose,
    ardupilot_fields,
    ardupilot_parameters,
    landing_target_fields,
    px4_fields,
    quaternion_wxyz,
)
from agents.io.mavlink import (
    ConnectionUrl,
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


def test_ardupilots_parameters_enable_mavlink_precision_landing_at_the_cameras_offset() -> None:
    mount = CameraMount(t_bc=np.array([0.1, 0.02, -0.05]))
    assert ardupilot_parameters(mount) == pytest.approx(
        {
            "PLND_ENABLED": 1,
            "PLND_TYPE": 1,  # MAVLink
            "PLND_ORIENT": 25,  # down
            "PLND_YAW_ALIGN": 0,
            "PLND_CAM_POS_X": 0.1,
            "PLND_CAM_POS_Y": -0.02,
            "PLND_CAM_POS_Z": 0.05,
        }
    )


PROPER = ": must be a proper rotation (R^T R = I, det +1)"


@pytest.mark.parametrize(
    ("kwargs", "key", "allowed"),
    [
        ({"r_bc": np.eye(2)}, "camera mount r_bc", "must be a finite 3x3 rotation"),
        ({"r_bc": np.diag([1.0, 1.0, 1.3])}, "camera mount r_bc", PROPER),
        ({"r_bc": -np.eye(3)}, "camera mount r_bc", PROPER),
        ({"t_bc": np.array([0.1, math.nan, 0.0])}, "camera mount t_bc", "must be 3 finite metres"),
        ({"t_bc": np.zeros(2)}, "camera mount t_bc", "must be 3 finite metres"),
    ],
)
def test_a_bad_camera_mount_is_refused_naming_the_field_and_what_it_must_be(
    kwargs: dict, key: str, allowed: str
) -> None:
    with pytest.raises(ConfigError) as refused:
        CameraMount(**kwargs)
    assert refused.value.key == key and allowed in str(refused.value)


def test_a_camera_mount_given_as_lists_or_rounded_to_float32_holds_its_float_rotation() -> None:
    # a calibration stored in float32: orthonormal to about 1e-7, not to 1e-8
    r_bc = matrix_from_euler_zyx(0.01, -0.02, 0.3).astype(np.float32).astype(float)
    r_bc[0, 1] += 4e-7
    mount = CameraMount(r_bc=r_bc.tolist(), t_bc=[0, 0, 1])
    assert isinstance(mount.r_bc, np.ndarray) and mount.r_bc.dtype == float
    assert isinstance(mount.t_bc, np.ndarray) and mount.t_bc.dtype == float
    assert mount.r_bc.T.shape == (3, 3) and mount.t_bc_frd == pytest.approx([0.0, 0.0, -1.0])
    quarter_turn = CameraMount(r_bc=[[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert quarter_turn.r_bc.dtype == float


def test_the_fields_are_refused_for_an_unknown_autopilot_and_for_px4_without_a_pose() -> None:
    with pytest.raises(ConfigError) as refused:
        landing_target_fields("inav", np.eye(3), np.array([0.0, 0.0, 2.0]), CameraMount())
    assert refused.value.key == "autopilot" and "'px4', 'ardupilot'" in str(refused.value)
    with pytest.raises(ConfigError) as refused:
        landing_target_fields("px4", np.eye(3), np.array([0.0, 0.0, 2.0]), CameraMount())
    assert refused.value.key == "vehicle pose"
    assert refused.value.detail == (
        "px4 reads LANDING_TARGET in MAV_FRAME_LOCAL_NED, which needs the vehicle's "
        "attitude and local position at the measurement's time; none was given"
    )


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


@pytest.fixture(scope="module")
def wire() -> Iterator[tuple[MavlinkLink, socket.socket]]:
    """A link as system 9, component 190, sending to a loopback socket: one for every
    example of a property."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    link = MavlinkLink(url_of(sock), system_id=9, component_id=190)
    try:
        yield link, sock
    finally:
        link.close()
        sock.close()


@settings(max_examples=60, deadline=None)
@given(
    time_usec=st.integers(0, 2**64 - 1),
    frame=st.sampled_from([mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_FRAME_BODY_FRD]),
    values=st.lists(
        st.floats(width=32, allow_nan=False, allow_infinity=False), min_size=10, max_size=10
    ),
)
def test_any_landing_target_is_unpacked_with_the_float32_fields_it_was_packed_with(
    wire: tuple[MavlinkLink, socket.socket], time_usec: int, frame: int, values: list[float]
) -> None:
    link, sock = wire
    x, y, z, w, qx, qy, qz, distance, angle_x, angle_y = values
    fields = LandingTargetFields(frame, x, y, z, (w, qx, qy, qz), distance, angle_x, angle_y)
    link.send_landing_target(time_usec, fields)
    (message,) = receive(sock, 1)
    assert message.get_type() == "LANDING_TARGET"
    assert (message.get_srcSystem(), message.get_srcComponent()) == (9, 190)
    assert (message.time_usec, message.frame, message.position_valid) == (time_usec, frame, 1)
    for name in ("x", "y", "z", "distance", "angle_x", "angle_y"):
        assert F32(getattr(message, name)) == F32(getattr(fields, name)), name
    assert np.array_equal(np.asarray(message.q, F32), np.asarray(fields.q, F32))


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


@pytest.mark.parametrize(("scenario", "low_m"), [("svgs-100m", 100.0), ("bench-ss4", 1.0)])
def test_the_simulator_flies_a_scenario_from_its_own_starts(scenario: str, low_m: float) -> None:
    from agents.io.sim_source import SimulatorSource

    with SimulatorSource(
        scenario=scenario,
        estimator="truth",
        speed=0.0,
        overrides={"simulation.max_episode_s": 0.1},
    ) as source:
        heights, stamps = [], []
        for stamp, _ in source:
            world = source.base.world
            heights.append(world.drone_state().position_w[2] - world.deck_state().tag_centre_w[2])
            stamps.append(stamp)
    start_m = heights[0]
    # svgs-100m starts 101.65-106.65 m over its pad, not at the bench's 1.5-4 m
    assert start_m > low_m
    assert len(stamps) == 3 and len(source.outcomes) == 1


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


def test_ports_1_to_65535_and_serial_devices_with_or_without_a_baud_are_taken() -> None:
    assert parse_connection_url("udpout:10.0.0.2:65535").device == "udpout:10.0.0.2:65535"
    assert parse_connection_url("udpin:0.0.0.0:1").device == "udpin:0.0.0.0:1"
    with pytest.raises(UserError, match=r"--to: port 65536 .* out of range; allowed 1\.\.65535"):
        parse_connection_url("udpout:10.0.0.2:65536")
    assert parse_connection_url(" /dev/ttyUSB0 ") == ConnectionUrl(
        "/dev/ttyUSB0", "/dev/ttyUSB0", 57600
    )
    assert parse_connection_url("/dev/ttyACM0:921600") == ConnectionUrl(
        "/dev/ttyACM0:921600", "/dev/ttyACM0", 921600
    )
    assert parse_connection_url("COM3:115200") == ConnectionUrl("COM3:115200", "COM3", 115200)
    assert parse_connection_url("/dev/ttyS1:1").baud == 1  # the lowest positive baud
    with pytest.raises(UserError, match=r"--to: baud 0 in '/dev/ttyUSB0:0' must be positive"):
        parse_connection_url("/dev/ttyUSB0:0")


def test_ids_up_to_255_are_taken_and_256_is_refused_naming_the_argument() -> None:
    with MavlinkLink("udpout:127.0.0.1:14550", system_id=255, component_id=255) as link:
        assert (link.system_id, link.component_id) == (255, 255)
    for key in ("system_id", "component_id"):
        flag = "--" + key.replace("_", "-")
        with pytest.raises(UserError, match=rf"^{flag}: 256 is out of range; allowed 1\.\.255$"):
            MavlinkLink("udpout:127.0.0.1:14550", **{key: 256})


def test_an_endpoint_that_cannot_be_opened_is_refused_naming_it() -> None:
    with pytest.raises(UserError, match=r"^--to: cannot open 'udpin:192\.0\.2\.1:14550': "):
        MavlinkLink("udpin:192.0.2.1:14550")


def test_the_heartbeat_is_an_active_onboard_controller_with_no_autopilot_and_no_modes(
    listener: socket.socket,
) -> None:
    with MavlinkLink(url_of(listener)) as link:
        link.send_heartbeat()
    (heartbeat,) = receive(listener, 1)
    assert heartbeat.get_srcComponent() == mavlink2.MAV_COMP_ID_ONBOARD_COMPUTER
    assert heartbeat.type == mavlink2.MAV_TYPE_ONBOARD_CONTROLLER
    assert heartbeat.autopilot == mavlink2.MAV_AUTOPILOT_INVALID
    assert (heartbeat.base_mode, heartbeat.custom_mode) == (0, 0)
    assert heartbeat.system_status == mavlink2.MAV_STATE_ACTIVE


def test_receive_waits_its_timeout_and_without_one_takes_what_has_arrived() -> None:
    import threading

    from pymavlink import mavutil

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    with MavlinkLink(f"udpin:127.0.0.1:{port}") as link:
        sender = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1)
        try:
            assert link.receive(0.2) is None  # nothing came: None once the timeout is over
            later = threading.Timer(0.6, sender.mav.heartbeat_send, (6, 8, 0, 0, 4))
            later.start()
            assert link.receive() is None  # no timeout: nothing has arrived yet
            message = link.receive(10.0)  # a timeout: waits for the heartbeat
            later.join()
            soon = threading.Timer(0.05, sender.mav.heartbeat_send, (6, 8, 0, 0, 4))
            soon.start()
            second = link.receive(1.0)  # a second is a timeout too
            soon.join()
        finally:
            sender.close()
    assert message is not None and message.get_type() == "HEARTBEAT"
    assert second is not None and second.get_type() == "HEARTBEAT"


class RecordingLink:
    """A link that keeps what the bridge sends."""

    def __init__(self) -> None:
        self.targets: list = []

    def send_heartbeat(self) -> None:
        pass

    def send_landing_target(self, time_usec: int, fields) -> None:
        self.targets.append((time_usec, fields))


def test_the_bridge_is_refused_naming_the_autopilot_or_the_missing_pose_source() -> None:
    with pytest.raises(ConfigError) as refused:
        LandingTargetBridge(RecordingLink(), "inav")  # type: ignore[arg-type]
    assert refused.value.key == "autopilot"
    with pytest.raises(ConfigError) as refused:
        LandingTargetBridge(RecordingLink(), "px4")  # type: ignore[arg-type]
    assert refused.value.key == "vehicle_pose"
    assert refused.value.detail == (
        "px4 reads LANDING_TARGET in MAV_FRAME_LOCAL_NED: give the vehicle's pose "
        "at each measurement (a source of VehiclePose)"
    )


def test_each_estimate_not_sent_is_skipped_under_its_own_reason_without_a_warning() -> None:
    import warnings

    bridge = LandingTargetBridge(RecordingLink(), "ardupilot")  # type: ignore[arg-type]
    eye, ahead = np.eye(3), np.array([0.1, 0.0, 2.0])
    cases = [
        (1.0, DeckPoseEstimate("tight", 1.0, False), "invalid: no reason given"),
        (math.nan, estimate(eye, ahead), "bad stamp (not a finite time >= 0)"),
        (math.inf, estimate(eye, ahead), "bad stamp (not a finite time >= 0)"),
        (2.0, estimate(np.eye(2), ahead), "malformed pose"),
        (2.0, estimate(eye, [0.0, 2.0]), "malformed pose"),
        (2.0, estimate(np.diag([1.0, 1.0, 1.3]), ahead), "rotation not orthonormal"),
        (2.0, estimate(np.diag([1e200, 1.0, 1.0]), ahead), "rotation not orthonormal"),
        (2.0, estimate(np.diag([1.0, 1.0, -1.0]), ahead), "rotation is a reflection"),
        (2.0, estimate(eye, [0.1, 0.0, 0.0]), "target not in front of the camera"),
        (2.0, estimate(eye, [0.0, 0.0, 1e39]), "fields beyond float32"),
        (2.0, estimate(eye, [0.1, 0.0, 0.5]), "sent"),  # half a metre in front
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        results = [bridge.send(stamp, est) for stamp, est, _ in cases]
    assert results == [why for *_, why in cases]
    assert sum(bridge.stats.skipped.values()) == len(cases) - 1 and bridge.stats.sent == 1


def test_a_pose_source_giving_none_or_an_empty_reason_is_counted_as_unknown() -> None:
    answers = iter([None, ""])
    bridge = LandingTargetBridge(RecordingLink(), "px4", vehicle_pose=lambda s: next(answers))  # type: ignore[arg-type]
    for stamp in (1.0, 2.0):
        assert bridge.send(stamp, estimate(np.eye(3), [0.0, 0.0, 2.0])) == (
            "no vehicle pose at the stamp: unknown"
        )
    assert bridge.stats.skipped == {"no vehicle pose at the stamp: unknown": 2}


def test_on_sent_hears_each_sent_stamp_and_the_wall_time_of_runs_adds_up(monkeypatch) -> None:
    import time as time_module

    heard: list = []
    bridge = LandingTargetBridge(RecordingLink(), "ardupilot", on_sent=heard.append)  # type: ignore[arg-type]
    ticks = iter([10.0, 12.0, 20.0, 23.0])
    monkeypatch.setattr(time_module, "perf_counter", lambda: next(ticks))
    bridge.run([(1.0, estimate(np.eye(3), [0.0, 0.0, 2.0]))])
    stats = bridge.run([(2.0, estimate(np.eye(3), [0.0, 0.0, 2.0]))])
    assert heard == [1.0, 2.0]
    assert stats.wall_s == 5.0 and stats.rate_hz == pytest.approx(0.4)


def test_a_link_receiving_mavlink_2_leaves_pymavlinks_own_dialect_as_it_was() -> None:
    import os
    import subprocess
    import sys

    program = (
        "import os, socket\n"
        "os.environ.pop('MAVLINK20', None)\n"
        "from pymavlink import mavutil\n"
        "from pymavlink.dialects.v20 import common\n"
        "from agents.io.mavlink import MavlinkLink\n"
        "dialect = mavutil.mavlink\n"
        "probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
        "probe.bind(('127.0.0.1', 0))\n"
        "port = probe.getsockname()[1]\n"
        "probe.close()\n"
        "link = MavlinkLink(f'udpin:127.0.0.1:{port}')\n"
        "sender = mavutil.mavlink_connection(f'udpout:127.0.0.1:{port}')\n"
        "common.MAVLink(sender, srcSystem=1, srcComponent=1).heartbeat_send(6, 8, 0, 0, 4)\n"
        "message = link.receive(10.0)\n"
        "assert message is not None and message.get_type() == 'HEARTBEAT'\n"
        "assert mavutil.mavlink is dialect and 'MAVLINK20' not in os.environ\n"
    )
    MavlinkLink("udpout:127.0.0.1:14550").close()  # the link opens here too
    # the same code as this process imports, in an interpreter where pymavlink speaks MAVLink 1
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK20"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    done = subprocess.run([sys.executable, "-c", program], env=env, timeout=120, check=False)
    assert done.returncode == 0


def test_a_simulator_source_refuses_a_bad_choice_naming_it_and_keeps_its_defaults() -> None:
    from agents.io.sim_source import SimulatorSource

    cases = [
        ({"estimator": "nope"}, "estimator: 'nope' is not allowed; choose one of "),
        ({"camera_mode": "x"}, "mode: 'x' is not allowed; choose one of 'project', 'render'"),
        ({"episodes": 0}, "episodes: 0 is out of range; allowed [1, inf]"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ConfigError) as refused:
            SimulatorSource(**kwargs)
        assert str(refused.value).startswith(message), str(refused.value)
    with SimulatorSource(overrides={"simulation.max_episode_s": 0.1}) as source:
        assert (source.estimator, source.seed, source.speed, source.pacer.speed) == (
            "tight", 0, 1.0, 1.0,
        )  # fmt: skip
        assert source.base.config.estimation.observed == "tight"
        assert source.policy.dt == source.base.env_dt
    with SimulatorSource(camera_mode="render", scenario="bench-ss4", estimator="truth") as source:
        config = source.base.config
        assert (config.camera.mode, config.estimation.observed) == ("render", "truth")


def test_the_same_seed_flies_the_same_episodes_and_the_summary_lists_each_outcome() -> None:
    from agents.io.sim_source import SimulatorSource

    flown = []
    for seed in (3, 3, 4):
        with SimulatorSource(
            estimator="truth", episodes=2, seed=seed, speed=0.0,
            overrides={"simulation.max_episode_s": 0.1},
        ) as source:  # fmt: skip
            flown.append([estimate.translation.tolist() for _, estimate in source])
            outcomes = source.outcomes
            assert source.summary() == f"episodes: {outcomes[0]}, {outcomes[1]}"
            assert outcomes == ["timeout", "timeout"]  # 0.1 s: no landing yet
    assert flown[0] == flown[1] and flown[0] != flown[2]


def test_the_vehicle_poses_of_the_last_256_captures_are_kept() -> None:
    from agents.io.sim_source import POSE_HISTORY, SimulatorSource

    with SimulatorSource(
        estimator="truth", episodes=60, speed=0.0, overrides={"simulation.max_episode_s": 0.2}
    ) as source:
        stamps = [stamp for stamp, _ in source]
        assert len(stamps) > POSE_HISTORY == 256
        assert np.all(np.diff(stamps) > 0.0)  # on across all 60 episodes
        assert [source.vehicle_pose(t) is None for t in stamps[-POSE_HISTORY - 1 :]] == [
            True, *[False] * POSE_HISTORY,
        ]  # fmt: skip


def test_a_paced_simulator_waits_for_each_captures_simulated_time() -> None:
    from agents.io.pacing import StampPacer
    from agents.io.sim_source import SimulatorSource

    now = [0.0]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    with SimulatorSource(
        estimator="truth", episodes=2, speed=2.0, overrides={"simulation.max_episode_s": 0.2}
    ) as source:
        source.pacer = StampPacer(2.0, 0.0, lambda: now[0], sleep)
        stamps = [stamp for stamp, _ in source]
    # each capture after the first of each episode waited for its stamp, at twice real time
    assert len(slept) == len(stamps) - 2
    assert now[0] == pytest.approx(stamps[-1] / 2.0)
    # 4 steps of 0.05 s an episode; the second's first step is a control period later
    assert slept == pytest.approx([0.025] * 4 + [0.05] + [0.025] * 3)


def test_a_simulator_source_flies_the_config_it_is_given() -> None:
    from agents.io.sim_source import SimulatorSource

    overrides = {"simulation.max_episode_s": 0.1}
    with SimulatorSource(config="high-approach", estimator="truth", overrides=overrides) as source:
        assert source.base.config.start.height_m == (20.0, 20.0)  # default.yaml's is not
        assert source.base.config.simulation.arena_max_height_m == 30.0
