"""The companion side of the MAVLink bridge: TIMESYNC answered and estimated (PX4's rules),
the vehicle's pose from the autopilot's telemetry interpolated to a measurement's stamp, and
LANDING_TARGET in local NED from it, with a pymavlink autopilot on loopback UDP."""

from __future__ import annotations

import itertools
import math
import socket
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

pytest.importorskip("pymavlink")
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2
from scipy.spatial.transform import Rotation

from agents.cli import main
from agents.io.autopilot_listener import AutopilotListener
from agents.io.autopilot_pose import AutopilotPoses
from agents.io.landing_target import CameraMount, VehiclePose, px4_fields
from agents.io.mavlink import LandingTargetBridge, MavlinkLink
from agents.io.timesync import (
    GAIN_FINAL,
    GAIN_INITIAL,
    MAX_RTT_S,
    ClockSync,
    smoothing_gain,
)
from estimation.errors import ConfigError
from estimation.frames import matrix_from_euler_zyx
from estimation.types import DeckPoseEstimate

F32 = np.float32
NS = 1_000_000_000
#: the fake autopilot booted 100 s before the test: its clock minus the companion's
OFFSET_NS = 100 * NS - time.monotonic_ns()


def synced(offset_s: float = 0.0) -> ClockSync:
    """A converged ClockSync with the given offset (one exact exchange, window 1)."""
    sync = ClockSync(convergence_window=1)
    assert sync.add_exchange(0, round(offset_s * NS) + 500, 1000) == "used"
    return sync


# ------------------------------------------------------------------ ClockSync, by numbers
def test_one_exchange_gives_the_offset_and_the_round_trip() -> None:
    sync = ClockSync()
    # sent at 1.000 s, the autopilot stamped 51.0015 s, received at 1.002 s: 1 ms each way
    assert sync.add_exchange(1_000_000_000, 51_001_500_000, 1_002_000_000) == "used"
    assert sync.offset_s == pytest.approx(50.0005, abs=1e-12)
    assert sync.rtt_s == pytest.approx(0.002, abs=1e-12)
    assert sync.samples == 1 and not sync.converged
    assert sync.to_companion_s(60.0) == pytest.approx(9.9995, abs=1e-12)


def test_a_slow_round_trip_is_not_used() -> None:
    sync = ClockSync()
    sync.add_exchange(0, 5 * NS, 2_000_000)
    reason = sync.add_exchange(10 * NS, 99 * NS, 10 * NS + round(MAX_RTT_S * NS))
    assert reason == "round trip >= 10 ms"
    assert sync.offset_s == pytest.approx(5.0 - 0.001) and sync.samples == 1
    assert sync.add_exchange(5, 0, 4) == "reply received before its request was sent"


def test_the_gains_fall_from_initial_to_final_over_the_window() -> None:
    gains = [smoothing_gain(k, 500) for k in range(0, 520, 20)]
    assert gains[0] == pytest.approx(GAIN_INITIAL)
    assert gains[-1] == GAIN_FINAL and smoothing_gain(500, 500) == GAIN_FINAL
    assert all(a >= b for a, b in itertools.pairwise(gains))


def test_the_estimate_converges_through_jitter_and_ignores_slow_outliers() -> None:
    rng = np.random.default_rng(0)
    offset_ns, sync, t_ns = 7_123_456_789, ClockSync(), 10 * NS
    for _ in range(700):
        up, down = rng.uniform(0.2e6, 2.0e6, 2)  # 0.2 to 2 ms each way
        if rng.random() < 0.2:  # a congested exchange: 40 ms one way
            up += 40e6
        remote = t_ns + up + offset_ns
        sync.add_exchange(t_ns, int(remote), int(t_ns + up + down))
        t_ns += 20_000_000
    assert sync.converged
    assert sync.rejected["round trip >= 10 ms"] > 80
    # each used sample is off by at most 0.9 ms (half the asymmetry); the filter averages
    assert abs(sync.offset_s - offset_ns / NS) < 2e-4


def test_a_clock_jump_restarts_the_filter_after_five_far_samples() -> None:
    sync = ClockSync(convergence_window=10)
    for k in range(10):
        sync.add_exchange(k * NS, k * NS + 3 * NS + 1000, k * NS + 2000)
    assert sync.converged and sync.offset_s == pytest.approx(3.0, abs=1e-6)
    jumped = [sync.add_exchange(k * NS, k * NS + 9 * NS, k * NS + 2000) for k in range(10, 16)]
    assert jumped[:5] == ["more than 100 ms from the estimate"] * 5
    assert jumped[5] == "far from the estimate: filter restarted"
    assert sync.restarts == 1 and sync.samples == 0 and not sync.converged
    assert sync.add_exchange(16 * NS, 25 * NS, 16 * NS + 2000) == "used"
    assert sync.offset_s == pytest.approx(9.0, abs=1e-5)


@pytest.mark.parametrize(
    ("key", "kwargs"),
    [
        ("convergence_window", {"convergence_window": 0}),
        ("max_rtt_s", {"max_rtt_s": math.nan}),
        ("max_rtt_s", {"max_rtt_s": 0.0}),
        ("max_deviation_s", {"max_deviation_s": -1.0}),
    ],
)
def test_bad_clock_sync_settings_are_refused_naming_the_key(key: str, kwargs: dict) -> None:
    with pytest.raises(ConfigError, match=key) as refused:
        ClockSync(**kwargs)
    assert refused.value.key == key and "allowed" in str(refused.value)


def test_the_gain_halfway_through_the_window_weighs_the_initial_gain_by_exp_minus_a_half() -> None:
    # PX4's schedule final + (initial - final) * exp(-k / (2 (N - k))): at k = N / 2, exp(-1/2)
    expected = GAIN_FINAL + (GAIN_INITIAL - GAIN_FINAL) * math.exp(-0.5)
    assert smoothing_gain(250, 500) == pytest.approx(expected, rel=1e-12)
    assert smoothing_gain(400, 500) == pytest.approx(
        GAIN_FINAL + (GAIN_INITIAL - GAIN_FINAL) * math.exp(-2.0), rel=1e-12
    )


def test_stamps_that_are_not_integers_are_not_used_and_counted_once_under_their_reason() -> None:
    sync = ClockSync()
    assert sync.add_exchange(0.0, 5 * NS, 2_000_000) == "stamps not integers"
    assert sync.add_exchange(0, 5 * NS, 20 * NS) == "round trip >= 10 ms"
    assert sync.add_exchange(0, 5 * NS, 20 * NS) == "round trip >= 10 ms"
    assert sync.rejected == {"stamps not integers": 1, "round trip >= 10 ms": 2}
    assert sync.samples == 0 and math.isnan(sync.offset_s)


def test_a_reply_received_in_the_nanosecond_its_request_left_is_used() -> None:
    sync = ClockSync()
    assert sync.add_exchange(1000, 3 * NS + 1000, 1000) == "used"
    assert sync.offset_s == pytest.approx(3.0, abs=1e-12) and sync.rtt_s == 0.0


def test_a_sample_exactly_at_the_deviation_bound_is_used() -> None:
    # "more than max_deviation_s from the estimate" is not used: at the bound it still is
    sync = ClockSync(convergence_window=1, max_deviation_s=0.125)
    assert sync.add_exchange(0, 3 * NS + 500, 1000) == "used"
    assert sync.converged and sync.offset_s == 3.0
    assert sync.add_exchange(0, 3 * NS + 500 + NS // 8, 1000) == "used"
    assert (
        sync.add_exchange(0, 3 * NS + 500 + NS // 4, 1000) == "more than 125 ms from the estimate"
    )


def test_each_clock_jump_counts_one_restart() -> None:
    sync = ClockSync(convergence_window=1)
    for jump, offset_s in enumerate((5, 9), start=1):
        assert sync.add_exchange(0, 1000, 1000) == "used"
        for _ in range(5):
            sync.add_exchange(0, offset_s * NS, 1000)
        assert (
            sync.add_exchange(0, offset_s * NS, 1000) == "far from the estimate: filter restarted"
        )
        assert sync.restarts == jump and sync.samples == 0


# ------------------------------------------------------------------ the pose history
def trajectory(t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A known flight in local NED (autopilot seconds): a straight line at constant
    velocity, yawing at a constant rate with a fixed roll and pitch, so that linear
    interpolation and slerp between samples are exact."""
    tau = t_s - 100.0
    position = np.array([2.0 + 0.5 * tau, -1.0 + 0.3 * tau, -6.0 + 0.1 * tau])
    rotation = matrix_from_euler_zyx(0.05, -0.03, 0.2 + 0.4 * tau)  # FRD in NED
    return position, rotation


def q_wxyz(rotation: np.ndarray) -> tuple[float, float, float, float]:
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return (w, x, y, z)


def test_the_pose_is_interpolated_at_the_stamp_through_the_offset() -> None:
    poses = AutopilotPoses(synced(offset_s=90.0))
    for k in range(20):  # 50 Hz on the autopilot's clock, from 100.0 s
        t = 100.0 + 0.02 * k
        position, rotation = trajectory(t)
        assert poses.add_position(t, position) == "kept"
        assert poses.add_attitude(t, q_wxyz(rotation)) == "kept"
    for stamp in (10.0, 10.013, 10.2577, 10.38):  # companion seconds: autopilot - 90
        pose = poses(stamp)
        assert isinstance(pose, VehiclePose)
        position, rotation = trajectory(stamp + 90.0)
        assert pose.position_ned_m == pytest.approx(position, abs=1e-9)
        assert np.allclose(pose.rotation_ned_frd, rotation, atol=1e-9)
    assert poses(9.99) == "stamp before the oldest position"
    assert poses(10.381) == "stamp after the newest position"
    assert poses.misses == {
        "stamp before the oldest position": 1,
        "stamp after the newest position": 1,
    }


def test_without_a_converged_clock_or_telemetry_there_is_no_pose() -> None:
    assert AutopilotPoses(ClockSync())(1.0) == "clock not synchronised yet (TIMESYNC)"
    poses = AutopilotPoses(synced())
    assert poses(1.0) == "no position yet"
    poses.add_position(1.0, (0.0, 0.0, 0.0))
    assert poses(1.0) == "no attitude yet"
    assert poses(math.nan) == "bad stamp"


def test_bad_telemetry_is_skipped_and_counted() -> None:
    poses = AutopilotPoses(synced(), history_s=2.0)
    assert poses.add_position(5.0, (1.0, 2.0, 3.0)) == "kept"
    assert poses.add_position(4.9, (1.0, 2.0, 3.0)) == "position: out of time order"
    assert poses.add_position(5.0, (1.0, 2.0, 3.0)) == "position: repeated stamp"
    assert poses.add_position(5.1, (1.0, math.nan, 3.0)) == "position: not finite"
    assert poses.add_position(5.1, (1.0, 2.0)) == "position: not finite"
    assert poses.add_attitude(5.1, (0.0, 0.0, 0.0, 0.0)).endswith("not of unit norm")
    assert poses.add_attitude(math.inf, (1.0, 0.0, 0.0, 0.0)) == "attitude: not finite"
    # an autopilot restarting its clock: far back in time starts the history again
    assert poses.add_position(0.5, (0.0, 0.0, 0.0)) == "kept"
    assert poses.positions.times_s == [0.5]
    assert sum(poses.skipped.values()) == 6


def test_odometry_becomes_the_only_source_once_it_arrives() -> None:
    poses = AutopilotPoses(synced())
    assert poses.add_odometry(1.0, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)) == "kept"
    assert poses.add_position(1.5, (9.0, 9.0, 9.0)).startswith("LOCAL_POSITION_NED ignored")
    assert poses.add_odometry(2.0, (3.0, 2.0, 1.0), (1.0, 0.0, 0.0, 0.0)) == "kept"
    pose = poses(1.5)
    assert isinstance(pose, VehiclePose)
    assert pose.position_ned_m == pytest.approx((2.0, 2.0, 2.0))


def test_a_sample_exactly_the_history_behind_the_newest_is_out_of_order_not_a_restart() -> None:
    poses = AutopilotPoses(synced(), history_s=2.0)
    assert poses.add_position(5.0, (1.0, 2.0, 3.0)) == "kept"
    assert poses.add_position(3.0, (0.0, 0.0, 0.0)) == "position: out of time order"
    assert poses.positions.times_s == [5.0]
    assert poses.add_position(2.5, (0.0, 0.0, 0.0)) == "kept"  # further back: a restart
    assert poses.positions.times_s == [2.5]


@pytest.mark.parametrize("history_s", [0, -1.0, math.inf, "2 s"])
def test_a_bad_history_length_is_refused_naming_it(history_s) -> None:
    with pytest.raises(ConfigError, match="history_s") as refused:
        AutopilotPoses(synced(), history_s=history_s)
    assert refused.value.key == "history_s" and "allowed (0, inf)" in str(refused.value)


def test_once_odometry_arrives_both_separate_messages_are_ignored_naming_them() -> None:
    poses = AutopilotPoses(synced())
    assert poses.add_odometry(1.0, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)) == "kept"
    assert poses.add_attitude(1.5, (0.0, 1.0, 0.0, 0.0)) == (
        "ATTITUDE_QUATERNION ignored: ODOMETRY in use"
    )
    assert poses.add_position(1.5, (9.0, 9.0, 9.0)) == "LOCAL_POSITION_NED ignored: ODOMETRY in use"
    assert poses.attitudes.times_s == [1.0] and poses.positions.times_s == [1.0]


@pytest.mark.parametrize(
    ("stamp", "position", "q"),
    [
        (1.0, (1.0, math.nan, 3.0), (1.0, 0.0, 0.0, 0.0)),
        (1.0, (1.0, 2.0, 3.0), (1.0, math.inf, 0.0, 0.0)),
        (math.nan, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)),
    ],
)
def test_an_odometry_with_any_part_not_finite_keeps_nothing_and_leaves_the_sources(
    stamp, position, q
) -> None:
    poses = AutopilotPoses(synced())
    assert poses.add_odometry(stamp, position, q) == "odometry: not finite"
    assert poses.skipped == {"odometry: not finite": 1}
    assert not poses.odometry and not poses.positions.times_s and not poses.attitudes.times_s
    assert poses.add_position(2.0, (1.0, 2.0, 3.0)) == "kept"


def test_each_sample_is_counted_once_as_kept_or_skipped_and_each_miss_once() -> None:
    poses = AutopilotPoses(synced())
    for t in (1.0, 2.0, 3.0):
        assert poses.add_position(t, (t, 0.0, 0.0)) == "kept"
    assert poses.add_position(2.0, (0.0, 0.0, 0.0)) == "position: out of time order"
    assert poses.kept == {"position": 3}
    assert poses.skipped == {"position: out of time order": 1}
    assert poses(0.5) == poses(0.6) == "stamp before the oldest position"
    assert poses.misses == {"stamp before the oldest position": 2}


def test_a_quaternion_with_a_huge_entry_is_refused_without_a_warning() -> None:
    import warnings

    poses = AutopilotPoses(synced())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reason = poses.add_attitude(1.0, (1e200, 0.0, 0.0, 0.0))
    assert reason == "attitude: quaternion not of unit norm"


def test_values_that_are_not_numbers_are_skipped_and_a_column_vector_is_taken() -> None:
    poses = AutopilotPoses(synced())
    assert poses.add_position(1.0, (1.0, None, 3.0)) == "position: not finite"
    assert poses.add_attitude(1.0, ("w", 0.0, 0.0, 0.0)) == "attitude: not finite"
    assert poses.add_position(1.0, np.array([[1.0], [2.0], [3.0]])) == "kept"
    assert poses.positions.values[0] == pytest.approx([1.0, 2.0, 3.0])


@settings(max_examples=200, deadline=None)
@given(
    events=st.lists(
        st.tuples(
            st.sampled_from(["position", "attitude", "lookup"]),
            st.one_of(
                st.floats(allow_nan=True, allow_infinity=True),
                st.floats(-5.0, 5.0),
                st.integers(-(2**63), 2**63),
            ),
            st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4),
        ),
        max_size=60,
    )
)
def test_random_stamps_never_break_the_history(events: list) -> None:
    poses = AutopilotPoses(synced(offset_s=0.25), history_s=1.0)
    for kind, stamp, values in events:
        if kind == "position":
            poses.add_position(stamp, values[:3])
        elif kind == "attitude":
            poses.add_attitude(stamp, values)
        else:
            result = poses(stamp)
            if isinstance(result, VehiclePose):
                kept = np.array(poses.positions.values)
                assert np.all(result.position_ned_m >= kept.min(axis=0) - 1e-9)
                assert np.all(result.position_ned_m <= kept.max(axis=0) + 1e-9)
                r = result.rotation_ned_frd
                assert np.allclose(r.T @ r, np.eye(3), atol=1e-9)
            else:
                assert isinstance(result, str) and result
        for track in (poses.positions, poses.attitudes):
            times = track.times_s
            assert all(a < b for a, b in itertools.pairwise(times))
            assert not times or times[-1] - times[0] <= 1.0


# ------------------------------------------------------------------ on the wire
class FakeAutopilot:
    """A pymavlink autopilot on loopback (system 1, component 1) with its own clock
    (the companion's monotonic clock + OFFSET_NS): it answers TIMESYNC after a 1 ms delay
    each way, sends its own requests, and streams LOCAL_POSITION_NED and
    ATTITUDE_QUATERNION of :func:`trajectory` at 50 Hz."""

    def __init__(self, delay_s: float = 0.001, telemetry: bool = True) -> None:
        self.conn = mavutil.mavlink_connection(
            "udpin:127.0.0.1:0", source_system=1, source_component=1
        )
        self.mav = mavlink2.MAVLink(self.conn, srcSystem=1, srcComponent=1)
        decoder = mavlink2.MAVLink(self.conn, srcSystem=1, srcComponent=1)
        decoder.robust_parsing = True
        self.conn.mav, self.conn.first_byte = decoder, False
        self.port = self.conn.port.getsockname()[1]
        self.delay_s, self.telemetry = delay_s, telemetry
        self.requests: list = []  # the bridge's requests
        self.replies: list = []  # (the bridge's reply, our clock at receipt)
        self.targets: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @staticmethod
    def now_ns() -> int:
        return time.monotonic_ns() + OFFSET_NS

    def _run(self) -> None:
        next_telemetry = next_request = 0.0
        while not self._stop.is_set():
            message = self.conn.recv_match(blocking=True, timeout=0.002)
            if message is not None:
                self._handle(message)
            if not self.conn.clients:  # udpin: nobody to send to before the bridge spoke
                continue
            now = time.monotonic()
            if now >= next_request:
                next_request = now + 0.02
                self.mav.timesync_send(0, self.now_ns())
            if self.telemetry and now >= next_telemetry:
                next_telemetry = now + 0.02
                t_ms = self.now_ns() // 1_000_000
                position, rotation = trajectory(t_ms / 1000.0)
                self.mav.local_position_ned_send(t_ms, *position, 0.0, 0.0, 0.0)
                self.mav.attitude_quaternion_send(t_ms, *q_wxyz(rotation), 0.0, 0.0, 0.0)

    def _handle(self, message) -> None:
        kind = message.get_type()
        if kind == "TIMESYNC" and message.tc1 == 0:
            self.requests.append(message)
            time.sleep(self.delay_s)
            tc1 = self.now_ns()
            time.sleep(self.delay_s)
            self.mav.timesync_send(tc1, message.ts1)
        elif kind == "TIMESYNC":
            self.replies.append((message, self.now_ns()))
        elif kind == "LANDING_TARGET":
            self.targets.append(message)

    def __enter__(self) -> FakeAutopilot:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.conn.close()


def wait_for(condition, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


@pytest.fixture
def autopilot() -> Iterator[FakeAutopilot]:
    with FakeAutopilot() as fake:
        yield fake


def test_the_bridge_answers_timesync_with_its_clock_and_the_autopilot_syncs_on_it(
    autopilot: FakeAutopilot,
) -> None:
    with MavlinkLink(f"udpout:127.0.0.1:{autopilot.port}", system_id=1) as link:
        with AutopilotListener(link, sync=ClockSync(convergence_window=50)):
            wait_for(lambda: len(autopilot.replies) >= 30)
    replies = autopilot.replies[:30]
    for reply, received_ns in replies:
        assert (reply.get_srcSystem(), reply.get_srcComponent()) == (1, 191)
        # the echoed ts1 is a request the autopilot sent: its clock, before the receipt
        assert 0 < received_ns - reply.ts1 < 0.5 * NS
        # tc1 is the companion's monotonic clock (ns), between the request and the reply
        assert reply.ts1 - OFFSET_NS <= reply.tc1 <= received_ns - OFFSET_NS
    # the autopilot's side of the exchange (as PX4 computes it): companion - autopilot
    samples = [tc1 - (ts1 + t1) / 2 for tc1, ts1, t1 in ((r.tc1, r.ts1, t) for r, t in replies)]
    assert abs(np.median(samples) + OFFSET_NS) < 2e6  # within 2 ms


def test_the_offset_estimate_converges_to_the_autopilots_clock(autopilot: FakeAutopilot) -> None:
    sync = ClockSync(convergence_window=100)
    with MavlinkLink(f"udpout:127.0.0.1:{autopilot.port}") as link:
        with AutopilotListener(link, sync=sync, request_period_s=0.005) as listener:
            wait_for(lambda: sync.converged)
    # every request the bridge sent was a request: tc1 = 0 and ts1 its clock
    assert all(m.tc1 == 0 and m.ts1 > 0 for m in autopilot.requests)
    assert listener.handled["TIMESYNC replies used"] == sync.samples >= 100
    # each reply took 2 ms or more (1 ms each way at the autopilot) and under 10 ms if used
    assert 0.002 <= sync.rtt_s
    # within 2 ms of the true offset (the worst single sample is off by half its round trip)
    assert abs(sync.offset_s - OFFSET_NS / NS) < 2e-3
    print(f"offset error {(sync.offset_s - OFFSET_NS / NS) * 1e6:.0f} us, rtt {sync.rtt_s:.4f} s")


def test_px4_landing_target_places_the_deck_with_the_autopilots_pose_at_the_stamp(
    autopilot: FakeAutopilot,
) -> None:
    mount = CameraMount(t_bc=np.array([0.05, 0.0, -0.04]))
    r_cd = matrix_from_euler_zyx(0.04, -0.02, 0.3)
    t_cd = np.array([0.2, -0.1, 2.5])
    sync = ClockSync(convergence_window=20)
    with MavlinkLink(f"udpout:127.0.0.1:{autopilot.port}") as link:
        with AutopilotListener(link, sync=sync, request_period_s=0.005) as listener:
            bridge = LandingTargetBridge(link, "px4", mount, vehicle_pose=listener.poses)
            wait_for(lambda: sync.converged and listener.handled["ATTITUDE_QUATERNION"] >= 10)
            now_s = time.monotonic()
            stamps = [now_s - 0.15, now_s - 0.1234, now_s - 0.05]
            # the listener goes on refining the offset while the bridge sends: each stamp was
            # mapped with an estimate between these two
            offset_before_s = sync.offset_s
            results = [
                bridge.send(s, DeckPoseEstimate("tight", s, True, r_cd, t_cd)) for s in stamps
            ]
            offset_after_s = sync.offset_s
            late = bridge.send(now_s + 1.0, DeckPoseEstimate("tight", 0.0, True, r_cd, t_cd))
            wait_for(lambda: len(autopilot.targets) >= 3)
    assert results == ["sent"] * 3
    assert late == "no vehicle pose at the stamp: stamp after the newest position"
    assert bridge.stats.skipped[late] == 1
    errors = []
    for message, stamp in zip(autopilot.targets, stamps, strict=True):
        wanted = []
        for offset_s in (offset_before_s, offset_after_s):
            position, rotation = trajectory(stamp + offset_s)
            expected = px4_fields(r_cd, t_cd, mount, VehiclePose(position, rotation))
            wanted.append(np.array([expected.x, expected.y, expected.z]))
        # time_usec stays on the companion's clock: PX4 maps it through its own TIMESYNC
        assert message.time_usec == round(stamp * 1e6)
        assert message.frame == mavlink2.MAV_FRAME_LOCAL_NED and message.position_valid == 1
        got = np.array([message.x, message.y, message.z])
        # the motion during the offset's change between the two estimates, beyond float32
        drift = float(np.max(np.abs(wanted[1] - wanted[0])))
        errors.append(float(np.max(np.abs(got - wanted[1]))) - drift)
        assert np.asarray(message.q, F32) == pytest.approx(np.asarray(expected.q, F32), abs=1e-5)
    # float32 positions and quaternions on the wire (telemetry and target): a few ulps of 6 m,
    # plus 50 us of timing at the target's speed in NED (about 1.1 m/s: the line and the yaw
    # swinging the 2.5 m camera offset) for the threads' scheduling on a busy machine
    assert max(errors) < 5e-6 + 1.1 * 50e-6, errors

    print(f"max position error {max(errors):.2e} m")


def test_a_stamp_older_than_the_history_gives_no_message_and_its_reason() -> None:
    with FakeAutopilot() as fake:
        sync = ClockSync(convergence_window=10)
        with MavlinkLink(f"udpout:127.0.0.1:{fake.port}") as link:
            with AutopilotListener(link, sync=sync, history_s=0.5) as listener:
                bridge = LandingTargetBridge(link, "px4", vehicle_pose=listener.poses)
                wait_for(lambda: sync.converged and listener.handled["LOCAL_POSITION_NED"] > 30)
                stamp = time.monotonic() - 2.0
                est = DeckPoseEstimate("tight", stamp, True, np.eye(3), np.array([0, 0, 2.0]))
                reason = bridge.send(stamp, est)
    assert reason == "no vehicle pose at the stamp: stamp before the oldest position"
    assert bridge.stats.sent == 0 and bridge.stats.skipped == {reason: 1}
    assert not fake.targets


def test_bad_frames_and_stray_messages_are_skipped_and_counted_never_raised() -> None:
    ap = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1, source_component=1)
    try:
        mav = mavlink2.MAVLink(ap, srcSystem=1, srcComponent=1)
        other = mavlink2.MAVLink(ap, srcSystem=1, srcComponent=42)
        port = ap.port.getsockname()[1]
        with MavlinkLink(f"udpout:127.0.0.1:{port}") as link:
            listener = AutopilotListener(link, sync=ClockSync(convergence_window=1))
            listener.poll(0.0)  # our first request: the autopilot learns our address
            wait_for(lambda: ap.recv_match(blocking=True, timeout=0.1) is not None)
            (address,) = ap.clients
            ap.port.sendto(b"\xfd\x05\x00\x00\x00\x01\x01\x6f\x00\x00garbage!!", address)
            ap.port.sendto(bytes(range(200)), address)
            mav.local_position_ned_send(2000, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)
            mav.local_position_ned_send(1000, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)  # older
            mav.attitude_quaternion_send(2000, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            mav.local_position_ned_send(3000, math.nan, 2.0, 3.0, 0.0, 0.0, 0.0)
            body_ned, body_frd = mavlink2.MAV_FRAME_BODY_NED, mavlink2.MAV_FRAME_BODY_FRD
            odometry = [4000, body_ned, body_frd, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0]]
            mav.odometry_send(*odometry, *[0.0] * 6, [0.0] * 21, [0.0] * 21)
            other.local_position_ned_send(2500, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)
            mav.timesync_send(123, 456)  # a reply to a request we never sent
            mav.timesync_send(0, 789)  # a request: answered
            expected = {
                "bad data (a corrupt or unknown frame)",
                "position: out of time order",
                "attitude: quaternion not of unit norm",
                "position: not finite",
                "ODOMETRY pose not in MAV_FRAME_LOCAL_NED",
                "LOCAL_POSITION_NED from another component",
                "TIMESYNC reply to no request of ours",
            }
            seen = listener.skipped.keys() | listener.poses.skipped.keys()

            def all_handled() -> bool:
                listener.poll(0.01)
                seen.update(listener.skipped.keys() | listener.poses.skipped.keys())
                return expected <= seen and listener.handled["answered TIMESYNC request"] == 1

            wait_for(all_handled)
            reply = ap.recv_match(
                type="TIMESYNC", condition="TIMESYNC.tc1>0", blocking=True, timeout=2.0
            )
    finally:
        ap.close()
    assert listener.handled["LOCAL_POSITION_NED"] == 1
    assert reply is not None and reply.ts1 == 789


# ------------------------------------------------------------------ the command
def test_the_command_with_the_autopilots_pose_sends_nothing_before_timesync(
    listener: socket.socket, capsys
) -> None:
    port = listener.getsockname()[1]
    argv = ["bridge", "--to", f"udpout:127.0.0.1:{port}", "--autopilot", "px4"]
    argv += ["--estimator", "truth", "--vehicle-pose", "mavlink"]
    argv += ["--set", "simulation.max_episode_s=0.3"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "(px4): 0 sent" in out
    assert "not sent, no vehicle pose at the stamp: clock not synchronised yet (TIMESYNC): 7" in out
    assert "TIMESYNC: offset (autopilot - companion) nan s" in out
    decoder = mavlink2.MAVLink(None)
    kinds: list = []
    while "TIMESYNC" not in kinds:
        kinds += [m.get_type() for m in decoder.parse_buffer(listener.recv(4096)) or []]
    assert "LANDING_TARGET" not in kinds


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--autopilot", "ardupilot"], "only px4 needs the vehicle's pose"),
        (["--autopilot", "px4", "--speed", "0"], "--speed 0 is not allowed"),
    ],
)
def test_the_autopilots_pose_is_refused_where_it_cannot_work(
    extra: list, message: str, capsys
) -> None:
    argv = ["bridge", "--to", "udpout:127.0.0.1:14550", "--vehicle-pose", "mavlink", *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--vehicle-pose mavlink" in err and message in err


# ------------------------------------------------------- the listener, message by message
class Message:
    """A decoded MAVLink message as the listener reads it: type, source and fields."""

    def __init__(self, kind: str, source: tuple[int, int] = (1, 1), **fields) -> None:
        self.kind, self.source = kind, source
        self.__dict__.update(fields)

    def get_type(self) -> str:
        return self.kind

    def get_srcSystem(self) -> int:
        return self.source[0]

    def get_srcComponent(self) -> int:
        return self.source[1]


class FakeLink:
    """A link with the bridge's ids (system 1, component 191) that records what is sent and
    hands out queued messages (or raises a queued error), waiting its timeout when empty."""

    system_id, component_id = 1, 191

    def __init__(self, *incoming) -> None:
        self.incoming = list(incoming)
        self.sent: list[tuple[int, int, int, int]] = []

    def receive(self, timeout_s: float):
        if not self.incoming:
            time.sleep(timeout_s)
            return None
        item = self.incoming.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    def send_timesync(self, tc1: int, ts1: int, target_system: int = 0, target_component=0):
        self.sent.append((tc1, ts1, target_system, target_component))


def test_a_request_is_answered_to_its_sender_and_our_own_looped_back_is_not() -> None:
    link = FakeLink()
    listener = AutopilotListener(link, clock_s=lambda: 2.5)
    for source in ((1, 1), (7, 42)):
        answer = listener.handle(Message("TIMESYNC", source, tc1=0, ts1=1234))
        assert answer == "answered TIMESYNC request"
    assert link.sent == [(2_500_000_000, 1234, 1, 1), (2_500_000_000, 1234, 7, 42)]
    looped = listener.handle(Message("TIMESYNC", (1, 191), tc1=0, ts1=99))
    assert looped == "TIMESYNC request of our own, looped back"
    assert len(link.sent) == 2
    assert listener.handled == {"answered TIMESYNC request": 2}
    assert listener.skipped == {"TIMESYNC request of our own, looped back": 1}


def test_a_reply_addressed_to_us_by_system_and_component_feeds_the_clock_at_its_receipt() -> None:
    link = FakeLink()
    listener = AutopilotListener(link, clock_s=lambda: 1.0, sync=ClockSync(convergence_window=1))
    ts1 = listener.send_request()
    reply = Message("TIMESYNC", tc1=ts1 + 5 * NS, ts1=ts1, target_system=1, target_component=191)
    # received 2 ms after the request left: the round trip is the receipt's, not the clock's
    assert listener.handle(reply, received_ns=ts1 + 2_000_000) == "used"
    assert listener.sync.rtt_s == pytest.approx(0.002, abs=1e-12)
    assert listener.sync.offset_s == pytest.approx(5.0 - 0.001, abs=1e-12)
    assert listener.handled == {"TIMESYNC requests sent": 1, "TIMESYNC replies used": 1}


def test_replies_not_for_us_are_skipped_each_under_its_reason() -> None:
    listener = AutopilotListener(FakeLink(), clock_s=lambda: 1.0)
    ts1 = listener.send_request()
    replies = [
        Message("TIMESYNC", tc1=-5, ts1=ts1),
        Message("TIMESYNC", tc1=9, ts1=ts1, target_system=1, target_component=7),
        Message("TIMESYNC", tc1=9, ts1=ts1, target_system=2, target_component=191),
        Message("TIMESYNC", (1, 42), tc1=9, ts1=ts1),
        Message("HEARTBEAT"),
    ]
    results = [listener.handle(m, received_ns=ts1 + 1000) for m in replies]
    assert results == [
        "TIMESYNC: negative tc1",
        "TIMESYNC reply addressed to another component",
        "TIMESYNC reply addressed to another component",
        "TIMESYNC reply from another component",
        "ignored",
    ]
    assert listener.skipped == {
        "TIMESYNC: negative tc1": 1,
        "TIMESYNC reply addressed to another component": 2,
        "TIMESYNC reply from another component": 1,
    }
    assert listener.sync.samples == 0


def test_a_malformed_message_is_counted_by_its_error_and_never_raised() -> None:
    listener = AutopilotListener(FakeLink())
    assert (
        listener.handle(Message("TIMESYNC", tc1="soon", ts1=1)) == "malformed message (ValueError)"
    )
    assert listener.handle(Message("LOCAL_POSITION_NED")) == "malformed message (AttributeError)"
    assert listener.skipped == {
        "malformed message (ValueError)": 1,
        "malformed message (AttributeError)": 1,
    }


def test_the_autopilot_named_by_its_system_id_is_the_one_listened_to() -> None:
    listener = AutopilotListener(FakeLink(), autopilot_system_id=7)
    position = {"time_boot_ms": 1000, "x": 1.0, "y": 2.0, "z": 3.0}
    assert listener.handle(Message("LOCAL_POSITION_NED", (7, 1), **position)) == "kept"
    other = listener.handle(Message("LOCAL_POSITION_NED", (1, 1), **position))
    assert other == "LOCAL_POSITION_NED from another component"


def test_every_request_is_counted_and_a_reply_to_one_long_forgotten_is_not_ours() -> None:
    clock = itertools.count(1)
    listener = AutopilotListener(FakeLink(), clock_s=lambda: next(clock) * 1e-3)
    sent = [listener.send_request() for _ in range(65)]
    assert listener.handled["TIMESYNC requests sent"] == 65
    forgotten = Message("TIMESYNC", tc1=9, ts1=sent[0])
    assert (
        listener.handle(forgotten, received_ns=sent[-1]) == "TIMESYNC reply to no request of ours"
    )
    remembered = Message("TIMESYNC", tc1=sent[1] + 500, ts1=sent[1])
    assert listener.handle(remembered, received_ns=sent[1] + 1000) == "used"


@pytest.mark.parametrize("period", [0, -0.05, 1e6, math.inf, "fast"])
def test_a_bad_request_period_is_refused_naming_it(period) -> None:
    with pytest.raises(ConfigError, match="request_period_s") as refused:
        AutopilotListener(FakeLink(), request_period_s=period)
    assert refused.value.key == "request_period_s" and "allowed (0, 1e6)" in str(refused.value)


def test_the_summary_line_gives_the_offset_round_trip_samples_state_and_requests_answered() -> None:
    listener = AutopilotListener(FakeLink(), sync=ClockSync(convergence_window=1))
    assert "(not converged)" in listener.summary()
    listener.handle(Message("TIMESYNC", (1, 1), tc1=0, ts1=5))
    listener.sync.add_exchange(0, 3 * NS + 4_000_000, 8_000_000)
    assert listener.summary() == (
        "TIMESYNC: offset (autopilot - companion) 3.000000 s, last round trip 8.00 ms, "
        "1 samples used (converged), 1 requests answered"
    )


def test_a_link_error_is_counted_once_and_the_listener_goes_on_listening() -> None:
    error = OSError("link down")
    link = FakeLink(error, error, Message("TIMESYNC", (1, 1), tc1=0, ts1=77))
    with AutopilotListener(link, request_period_s=1e3) as listener:
        wait_for(lambda: listener.handled["answered TIMESYNC request"] == 1)
    assert listener.skipped == {"link error: link down": 2}


def test_on_a_quiet_link_requests_go_out_every_request_period() -> None:
    link = FakeLink()
    with AutopilotListener(link, request_period_s=0.01):
        wait_for(lambda: len(link.sent) >= 20)
    # each a request (tc1 0) addressed to the autopilot: system 1, component 1
    assert all((tc1, *target) == (0, 1, 1) for tc1, _, *target in link.sent)


def test_the_companions_clock_reads_at_least_one_nanosecond_and_the_history_is_passed_on() -> None:
    """tc1 = 0 marks a request, so a clock at 0 (or before) reads 1 ns; the history asked for
    is the length the autopilot's poses are kept."""
    assert AutopilotListener(FakeLink(), clock_s=lambda: 0.0).now_ns() == 1
    assert AutopilotListener(FakeLink(), clock_s=lambda: 2e-9).now_ns() == 2
    listener = AutopilotListener(FakeLink(), history_s=3.5)
    assert listener.poses.positions.history_s == listener.poses.attitudes.history_s == 3.5


def test_a_listener_stopped_can_start_again_and_one_never_started_stops_quietly() -> None:
    AutopilotListener(FakeLink()).stop()
    link = FakeLink()
    listener = AutopilotListener(link, request_period_s=1e3)
    for run in (1, 2):
        link.incoming.append(Message("TIMESYNC", (1, 1), tc1=0, ts1=run))
        with listener:
            wait_for(lambda run=run: listener.handled["answered TIMESYNC request"] == run)
        assert not any(t.name == "autopilot" for t in threading.enumerate())


def test_a_listener_left_running_never_keeps_the_program_from_exiting() -> None:
    import os
    import subprocess
    import sys

    program = (
        "import time\n"
        "from agents.io.autopilot_listener import AutopilotListener\n"
        "class Link:\n"
        "    system_id, component_id = 1, 191\n"
        "    def receive(self, timeout_s):\n"
        "        time.sleep(timeout_s)\n"
        "    def send_timesync(self, *args):\n"
        "        pass\n"
        "AutopilotListener(Link()).start()\n"
    )
    with AutopilotListener(FakeLink(), request_period_s=1e3) as listener:  # here it ends
        wait_for(lambda: listener.handled["TIMESYNC requests sent"] == 1)
    # the same code as this process imports
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    done = subprocess.run([sys.executable, "-c", program], env=env, timeout=120, check=False)
    assert done.returncode == 0
