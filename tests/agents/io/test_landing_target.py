"""Properties of LANDING_TARGET for any pose: the fields each autopilot reads place the tag
where it is in the world (PX4: local NED; ArduPilot: the line of sight in body FRD), and every
field leaves the bridge's link and decodes in pymavlink as it was given, to float32."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

pytest.importorskip("pymavlink")
from pymavlink.dialects.v20 import common as mavlink2

from agents.io.landing_target import (
    S_FLIP,
    CameraMount,
    LandingTargetFields,
    VehiclePose,
    ardupilot_fields,
    px4_fields,
)
from agents.io.mavlink import MavlinkLink
from estimation.frames import deck_pose_in_camera, matrix_from_euler_zyx

F32 = np.float32
PROPERTY = settings(max_examples=150, deadline=None)

metres = st.floats(-100.0, 100.0)
angles = st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6), st.floats(-3.14, 3.14))
offsets = st.tuples(*[st.floats(-0.3, 0.3)] * 3).map(np.array)


@st.composite
def scenes(draw: st.DrawFn) -> dict:
    """A drone (tilted, any heading) above a tilted deck, the camera off the body origin."""
    t_wb = np.array([draw(metres), draw(metres), draw(st.floats(0.5, 60.0))])
    t_wp = np.array([t_wb[0] + draw(st.floats(-5, 5)), t_wb[1] + draw(st.floats(-5, 5)), 0.0])
    t_wp[2] = draw(st.floats(-3.0, 3.0))
    return {
        "t_wb": t_wb,
        "r_wb": matrix_from_euler_zyx(*draw(angles)),
        "t_wp": t_wp,
        "r_wp": matrix_from_euler_zyx(*draw(angles)),
        "t_bc": draw(offsets),
    }


def camera_view(scene: dict) -> tuple[np.ndarray, np.ndarray]:
    return deck_pose_in_camera(
        scene["t_wb"], scene["r_wb"], scene["t_wp"], scene["r_wp"], scene["t_bc"]
    )


def rotation_of_wxyz(q: tuple[float, ...]) -> np.ndarray:
    w, x, y, z = q
    return Rotation.from_quat([x, y, z, w]).as_matrix()


@PROPERTY
@given(scene=scenes())
def test_px4_gets_the_tags_own_position_and_the_decks_heading_in_local_ned(scene: dict) -> None:
    r_cd, t_cd = camera_view(scene)
    vehicle = VehiclePose.from_world(scene["t_wb"], scene["r_wb"])
    fields = px4_fields(r_cd, t_cd, CameraMount(t_bc=scene["t_bc"]), vehicle)
    assert fields.frame == mavlink2.MAV_FRAME_LOCAL_NED
    # the world W (x north, y west, z up) is NED with y and z flipped
    np.testing.assert_allclose([fields.x, fields.y, fields.z], S_FLIP @ scene["t_wp"], atol=1e-9)
    # the deck FRD frame F (bow, starboard, down) in NED
    r_ned_f = S_FLIP @ scene["r_wp"] @ S_FLIP
    np.testing.assert_allclose(rotation_of_wxyz(fields.q), r_ned_f, atol=1e-9)
    assert fields.distance == pytest.approx(float(np.linalg.norm(t_cd)), abs=1e-12)


@PROPERTY
@given(scene=scenes())
def test_ardupilot_gets_the_line_of_sight_from_the_camera_in_body_frd(scene: dict) -> None:
    r_cd, t_cd = camera_view(scene)
    fields = ardupilot_fields(r_cd, t_cd, CameraMount(t_bc=scene["t_bc"]))
    assert fields.frame == mavlink2.MAV_FRAME_BODY_FRD
    r_wb, camera_w = scene["r_wb"], scene["t_wb"] + scene["r_wb"] @ scene["t_bc"]
    sight_frd = S_FLIP @ r_wb.T @ (scene["t_wp"] - camera_w)
    np.testing.assert_allclose([fields.x, fields.y, fields.z], sight_frd, atol=1e-9)
    assert fields.distance == pytest.approx(float(np.linalg.norm(sight_frd)), abs=1e-9)
    np.testing.assert_allclose(
        rotation_of_wxyz(fields.q), S_FLIP @ r_wb.T @ scene["r_wp"] @ S_FLIP, atol=1e-9
    )
    # the camera looks down the body: the image angles are the sight's (ArduPilot's angle path)
    if fields.z > 1e-3:
        np.testing.assert_allclose(
            [fields.x / fields.z, fields.y / fields.z],
            [-np.tan(fields.angle_y), np.tan(fields.angle_x)],
            rtol=1e-9,
            atol=1e-9,
        )


# ------------------------------------------------------------------ on the wire
@pytest.fixture(scope="module")
def wire() -> Iterator[tuple[MavlinkLink, socket.socket]]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    link = MavlinkLink(f"udpout:127.0.0.1:{sock.getsockname()[1]}", system_id=3)
    try:
        yield link, sock
    finally:
        link.close()
        sock.close()


floats32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


@PROPERTY
@given(
    time_usec=st.integers(0, 2**64 - 1),
    frame=st.sampled_from([mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_FRAME_BODY_FRD]),
    values=st.lists(floats32, min_size=10, max_size=10),
)
def test_every_field_of_a_landing_target_decodes_as_it_was_sent(
    wire: tuple[MavlinkLink, socket.socket], time_usec: int, frame: int, values: list[float]
) -> None:
    link, sock = wire
    x, y, z, distance, angle_x, angle_y, *q = values
    fields = LandingTargetFields(frame, x, y, z, tuple(q), distance, angle_x, angle_y)
    link.send_landing_target(time_usec, fields)
    (message,) = mavlink2.MAVLink(None).parse_buffer(sock.recv(4096))
    assert message.get_type() == "LANDING_TARGET"
    assert (message.get_srcSystem(), message.get_srcComponent()) == (3, link.component_id)
    assert message.time_usec == time_usec and message.frame == frame
    assert message.position_valid == 1 and message.target_num == 0
    assert message.type == mavlink2.LANDING_TARGET_TYPE_VISION_FIDUCIAL
    for name in ("x", "y", "z", "distance", "angle_x", "angle_y"):
        assert F32(getattr(message, name)) == F32(getattr(fields, name)), name
    assert [F32(v) for v in message.q] == [F32(v) for v in q]
    assert (message.size_x, message.size_y) == (0.0, 0.0)
