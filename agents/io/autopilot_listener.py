"""What the companion computer hears from the autopilot on the bridge's MAVLink connection.

:class:`AutopilotListener` reads the connection of a :class:`agents.io.mavlink.MavlinkLink`
(on a thread of its own, so that TIMESYNC requests are answered within a millisecond or two:
PX4 does not use a round trip of 10 ms or more) and

* answers every TIMESYNC request (``tc1 = 0``) with ``tc1`` = the companion's clock in
  nanoseconds and ``ts1`` echoed, addressed to the requester where the message has target
  fields;
* sends TIMESYNC requests of its own every ``request_period_s`` and feeds the replies from
  the autopilot to a :class:`agents.io.timesync.ClockSync` (the offset of the autopilot's
  clock; a reply whose ``ts1`` is not one of its own recent requests is not its own and is
  skipped);
* feeds the autopilot's ``LOCAL_POSITION_NED``, ``ATTITUDE_QUATERNION`` and ``ODOMETRY`` (its
  pose in ``MAV_FRAME_LOCAL_NED``, whatever the velocity's ``child_frame_id``) to an
  :class:`agents.io.autopilot_pose.AutopilotPoses`, which the bridge asks for the vehicle's
  pose at each measurement.

The companion's clock (``clock_s``) must be the clock of the measurement stamps, since
LANDING_TARGET's ``time_usec`` is on it and PX4 maps it to its own clock through the same
exchange.  Corrupt frames, messages from elsewhere and malformed values are counted in
:attr:`AutopilotListener.skipped` and never raise.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from typing import Any, Protocol

from agents.io.autopilot_pose import HISTORY_S, KEPT, AutopilotPoses
from agents.io.landing_target import MAV_FRAME_LOCAL_NED
from agents.io.timesync import USED, ClockSync
from estimation.errors import ConfigError

#: MAV_COMP_ID_AUTOPILOT1 (MAVLink common MAV_COMPONENT): the autopilot's component id
AUTOPILOT_COMPONENT_ID = 1
#: seconds between the companion's own TIMESYNC requests
REQUEST_PERIOD_S = 0.05
#: own requests remembered for matching replies
PENDING_REQUESTS = 64


class Link(Protocol):
    """What the listener needs of a link (:class:`agents.io.mavlink.MavlinkLink`)."""

    system_id: int
    component_id: int

    def receive(self, timeout_s: float) -> Any: ...

    def send_timesync(
        self, tc1: int, ts1: int, target_system: int = 0, target_component: int = 0
    ) -> None: ...


class AutopilotListener:
    """Answers and sends TIMESYNC and collects the vehicle's pose from the autopilot.

    ``clock_s``: the companion's clock, seconds (that of the measurement stamps);
    ``autopilot_system_id`` (default: the link's system id) and ``autopilot_component_id``:
    whose replies and telemetry are used.  :meth:`start` runs it on a thread (or call
    :meth:`poll` yourself); :attr:`sync` holds the offset and round trip for logging.
    """

    def __init__(
        self,
        link: Link,
        clock_s: Callable[[], float] = time.monotonic,
        *,
        sync: ClockSync | None = None,
        autopilot_system_id: int | None = None,
        autopilot_component_id: int = AUTOPILOT_COMPONENT_ID,
        request_period_s: float = REQUEST_PERIOD_S,
        history_s: float = HISTORY_S,
    ) -> None:
        if not (isinstance(request_period_s, (int, float)) and 0.0 < request_period_s < 1e6):
            raise ConfigError(
                "request_period_s", f"{request_period_s!r} is out of range; allowed (0, 1e6)"
            )
        self.link = link
        self.clock_s = clock_s
        self.sync = sync or ClockSync()
        self.poses = AutopilotPoses(self.sync, history_s)
        self.autopilot = (
            link.system_id if autopilot_system_id is None else autopilot_system_id,
            autopilot_component_id,
        )
        self._own = (link.system_id, link.component_id)
        self.request_period_s = float(request_period_s)
        self.handled: Counter = Counter()
        self.skipped: Counter = Counter()
        self._pending: OrderedDict[int, None] = OrderedDict()
        self._next_request_s = -math.inf
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ---------------------------------------------------------------- the clock
    def now_ns(self) -> int:
        """The companion's clock in nanoseconds (at least 1: ``tc1 = 0`` means a request)."""
        return max(1, round(self.clock_s() * 1e9))

    # ---------------------------------------------------------------- messages
    def send_request(self) -> int:
        """One TIMESYNC request to the autopilot; returns its ``ts1``."""
        ts1 = self.now_ns()
        self._pending[ts1] = None
        while len(self._pending) > PENDING_REQUESTS:
            self._pending.popitem(last=False)
        self.link.send_timesync(0, ts1, *self.autopilot)
        self.handled["TIMESYNC requests sent"] += 1
        return ts1

    def handle(self, message: Any, received_ns: int | None = None) -> str:
        """Act on one decoded message; returns what was done or why it was skipped."""
        received_ns = self.now_ns() if received_ns is None else received_ns
        try:
            kind = message.get_type()
            if kind == "BAD_DATA":
                result = "bad data (a corrupt or unknown frame)"
            elif kind == "TIMESYNC":
                result = self._timesync(message, received_ns)
            elif kind in ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "ODOMETRY"):
                result = self._telemetry(kind, message)
            else:
                return "ignored"
        except (AttributeError, TypeError, ValueError, OverflowError) as exc:
            result = f"malformed message ({type(exc).__name__})"
        if result == KEPT:
            self.handled[kind] += 1
        elif result == USED:
            self.handled["TIMESYNC replies used"] += 1
        elif result.startswith("answered"):
            self.handled[result] += 1
        else:
            self.skipped[result] += 1
        return result

    def _from_autopilot(self, message: Any) -> bool:
        return (message.get_srcSystem(), message.get_srcComponent()) == self.autopilot

    def _timesync(self, message: Any, received_ns: int) -> str:
        tc1, ts1 = int(message.tc1), int(message.ts1)
        if tc1 == 0:
            if (message.get_srcSystem(), message.get_srcComponent()) == self._own:
                return "TIMESYNC request of our own, looped back"
            self.link.send_timesync(
                self.now_ns(), ts1, message.get_srcSystem(), message.get_srcComponent()
            )
            return "answered TIMESYNC request"
        if tc1 < 0:
            return "TIMESYNC: negative tc1"
        target = (getattr(message, "target_system", 0), getattr(message, "target_component", 0))
        if target != (0, 0) and target != (self.link.system_id, self.link.component_id):
            return "TIMESYNC reply addressed to another component"
        if not self._from_autopilot(message):
            return "TIMESYNC reply from another component"
        if ts1 not in self._pending:
            return "TIMESYNC reply to no request of ours"
        del self._pending[ts1]
        return self.sync.add_exchange(ts1, tc1, received_ns)

    def _telemetry(self, kind: str, message: Any) -> str:
        if not self._from_autopilot(message):
            return f"{kind} from another component"
        poses = self.poses
        if kind == "LOCAL_POSITION_NED":
            return poses.add_position(
                message.time_boot_ms * 1e-3, (message.x, message.y, message.z)
            )
        if kind == "ATTITUDE_QUATERNION":
            q = (message.q1, message.q2, message.q3, message.q4)
            return poses.add_attitude(message.time_boot_ms * 1e-3, q)
        # the pose's frame; child_frame_id is the velocity's, which is not read (PX4 sends
        # MAV_FRAME_BODY_FRD up to v1.13, MAV_FRAME_LOCAL_NED from v1.14 on)
        if message.frame_id != MAV_FRAME_LOCAL_NED:
            return "ODOMETRY pose not in MAV_FRAME_LOCAL_NED"
        position = (message.x, message.y, message.z)
        return poses.add_odometry(message.time_usec * 1e-6, position, list(message.q))

    # ---------------------------------------------------------------- the loop
    def poll(self, timeout_s: float = 0.01) -> None:
        """Send a TIMESYNC request when due, then handle what arrives within ``timeout_s``."""
        now_s = time.monotonic()
        if now_s >= self._next_request_s:
            self._next_request_s = now_s + self.request_period_s
            self.send_request()
        message = self.link.receive(timeout_s)
        while message is not None:
            self.handle(message)
            message = self.link.receive(0.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.poll(0.005)
            except OSError as exc:  # the connection closed under the thread
                self.skipped[f"link error: {exc}"] += 1
                if self._stop.wait(0.1):
                    break

    def start(self) -> AutopilotListener:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="autopilot", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def __enter__(self) -> AutopilotListener:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def summary(self) -> str:
        """One line for logs: the offset, the round trip, the samples, convergence."""
        sync = self.sync
        state = "converged" if sync.converged else "not converged"
        return (
            f"TIMESYNC: offset (autopilot - companion) {sync.offset_s:.6f} s, last round trip "
            f"{sync.rtt_s * 1e3:.2f} ms, {sync.samples} samples used ({state}), "
            f"{self.handled['answered TIMESYNC request']} requests answered"
        )


__all__ = ["AUTOPILOT_COMPONENT_ID", "REQUEST_PERIOD_S", "AutopilotListener"]
