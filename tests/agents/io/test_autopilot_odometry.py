"""The vehicle's pose from the autopilot's ODOMETRY, as PX4 streams it, on the wire: the
TIMESYNC offset and ODOMETRY's ``time_usec`` put the pose at a measurement's stamp, and the
bridge sends the LANDING_TARGET it places.

A pymavlink autopilot on loopback UDP plays PX4's side of each exchange in turn (one thread):
it answers the companion's TIMESYNC request with its own clock and streams ODOMETRY of a known
flight (:func:`tests.test_mavlink_autopilot.trajectory`), in the frames PX4 sends.  PX4's
``ODOMETRY`` stream (``src/modules/mavlink/streams/ODOMETRY.hpp``) sends ``frame_id =
MAV_FRAME_LOCAL_NED`` for the estimator's pose; its ``child_frame_id`` names the velocity's
frame: ``MAV_FRAME_BODY_FRD`` up to v1.13, ``MAV_FRAME_LOCAL_NED`` from v1.14 on (EKF2
publishes the velocity in NED).  ``MAV_FRAME_LOCAL_FRD`` (a world frame of arbitrary heading)
is what PX4 loops back from an external vision system: not NED, so not a pose here."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest

pytest.importorskip("pymavlink")
from pymavlink.dialects.v20 import common as mavlink2

from agents.io.autopilot_listener import AutopilotListener
from agents.io.landing_target import CameraMount, VehiclePose, px4_fields
from agents.io.mavlink import LandingTargetBridge, MavlinkLink
from agents.io.timesync import ClockSync
from estimation.frames import matrix_from_euler_zyx
from estimation.types import DeckPoseEstimate
from tests.agents.io.test_mavlink_autopilot import FakeAutopilot, q_wxyz, trajectory

#: the frames PX4's ODOMETRY carries the estimator's pose in: up to v1.13, and from v1.14 on
PX4_ODOMETRY_FRAMES = {
    "px4-1.13": (mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_FRAME_BODY_FRD),
    "px4-1.14": (mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_FRAME_LOCAL_NED),
}


class Px4Odometry(FakeAutopilot):
    """The fake autopilot's end of loopback UDP (system 1, component 1), without its thread:
    the test drives each exchange."""

    def __init__(self) -> None:
        super().__init__(telemetry=False)
        #: the autopilot's seconds of each ODOMETRY sent
        self.sent_s: list[float] = []

    def answer_request(self) -> None:
        """Wait for the companion's TIMESYNC request and answer it with the autopilot's clock."""
        request = self.conn.recv_match(
            type="TIMESYNC", condition="TIMESYNC.tc1==0", blocking=True, timeout=2.0
        )
        assert request is not None, "no TIMESYNC request from the companion"
        self.mav.timesync_send(self.now_ns(), request.ts1)

    def send_odometry(self, frames: tuple[int, int]) -> None:
        """One ODOMETRY of the known flight now (``time_usec``: the autopilot's microseconds)."""
        t_us = self.now_ns() // 1000
        position, rotation = trajectory(t_us * 1e-6)
        self.mav.odometry_send(
            t_us, *frames, *position, list(q_wxyz(rotation)), *[0.0] * 6, [0.0] * 21, [0.0] * 21
        )
        self.sent_s.append(t_us * 1e-6)

    def landing_targets(self, count: int) -> list:
        targets = []
        while len(targets) < count:
            message = self.conn.recv_match(type="LANDING_TARGET", blocking=True, timeout=2.0)
            assert message is not None, f"{len(targets)} of {count} LANDING_TARGETs arrived"
            targets.append(message)
        return targets


@pytest.fixture
def px4() -> Iterator[Px4Odometry]:
    autopilot = Px4Odometry()
    try:
        yield autopilot
    finally:
        autopilot.conn.close()


def stream(
    px4: Px4Odometry, listener: AutopilotListener, frames: tuple[int, int], rounds: int
) -> int:
    """TIMESYNC exchanges, each followed by one ODOMETRY, handled as they come: ``rounds`` of
    them, and more until the offset has converged (a round trip of 10 ms or more on a busy
    machine is not used); returns how many."""
    done = 0
    while done < rounds or not listener.sync.converged:
        assert done < 50 * rounds, "the offset did not converge"
        listener.send_request()
        px4.answer_request()
        px4.send_odometry(frames)
        deadline = time.monotonic() + 2.0
        seen = sum(listener.handled.values()) + sum(listener.skipped.values())
        # the reply and the odometry: two more messages handled or skipped
        while sum(listener.handled.values()) + sum(listener.skipped.values()) < seen + 2:
            assert time.monotonic() < deadline, "the autopilot's messages did not arrive"
            listener.poll(0.01)
        done += 1
        time.sleep(0.002)  # the samples a few milliseconds apart, as PX4's 50-250 Hz
    return done


@pytest.mark.parametrize("frames", PX4_ODOMETRY_FRAMES.values(), ids=PX4_ODOMETRY_FRAMES)
def test_px4s_odometry_places_the_landing_target_at_the_measurements_stamp(
    px4: Px4Odometry, frames: tuple[int, int]
) -> None:
    mount = CameraMount(t_bc=np.array([0.05, 0.0, -0.04]))
    r_cd = matrix_from_euler_zyx(0.04, -0.02, 0.3)
    t_cd = np.array([0.2, -0.1, 2.5])
    sync = ClockSync(convergence_window=10)
    with MavlinkLink(f"udpout:127.0.0.1:{px4.port}") as link:
        # requests only when the test sends them
        listener = AutopilotListener(link, sync=sync, request_period_s=1e5)
        listener.poll(0.0)  # the first request: the autopilot learns the companion's address
        px4.answer_request()
        sent = stream(px4, listener, frames, rounds=20)
        assert listener.poses.odometry and listener.handled["ODOMETRY"] == sent
        bridge = LandingTargetBridge(link, "px4", mount, vehicle_pose=listener.poses)
        # measurements between the autopilot's latest samples, on the companion's clock
        first_s, last_s = px4.sent_s[-10], px4.sent_s[-2]
        stamps = [t - sync.offset_s for t in np.linspace(first_s, last_s, 4)]
        results = [bridge.send(s, DeckPoseEstimate("tight", s, True, r_cd, t_cd)) for s in stamps]
        assert results == ["sent"] * len(stamps)
        targets = px4.landing_targets(len(stamps))
    for message, stamp in zip(targets, stamps, strict=True):
        position, rotation = trajectory(stamp + sync.offset_s)
        expected = px4_fields(r_cd, t_cd, mount, VehiclePose(position, rotation))
        assert message.time_usec == round(stamp * 1e6)
        assert message.frame == mavlink2.MAV_FRAME_LOCAL_NED and message.position_valid == 1
        # float32 on the wire (telemetry and target): a few ulps of each coordinate (the fake
        # autopilot's clock, and the flight along it, follow the machine's uptime)
        got = np.array([message.x, message.y, message.z])
        assert got == pytest.approx(
            [expected.x, expected.y, expected.z], rel=4 * float(np.finfo(np.float32).eps), abs=1e-5
        )


def test_odometry_in_a_frame_of_arbitrary_heading_is_no_pose(px4: Px4Odometry) -> None:
    sync = ClockSync(convergence_window=5)
    frames = (mavlink2.MAV_FRAME_LOCAL_FRD, mavlink2.MAV_FRAME_BODY_FRD)
    with MavlinkLink(f"udpout:127.0.0.1:{px4.port}") as link:
        listener = AutopilotListener(link, sync=sync, request_period_s=1e5)
        listener.poll(0.0)
        px4.answer_request()
        sent = stream(px4, listener, frames, rounds=8)
    assert not listener.poses.odometry
    assert listener.skipped["ODOMETRY pose not in MAV_FRAME_LOCAL_NED"] == sent
    assert listener.poses(px4.sent_s[-2] - sync.offset_s) == "no position yet"
