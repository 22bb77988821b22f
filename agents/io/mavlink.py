"""Deck-pose estimates to an autopilot over MAVLink 2: HEARTBEAT and LANDING_TARGET (#149).

The core, :class:`LandingTargetBridge`, takes ``(stamp_s, estimate)`` pairs
(:class:`~estimation.types.DeckPoseEstimate`, the deck pose in the camera frame) from any
source: the live simulator (:mod:`agents.io.sim_source`) or a recording.  For each valid
estimate newer than the last one sent it sends one LANDING_TARGET in the frame the chosen
autopilot reads (:mod:`agents.io.landing_target` names the conventions and their sources)
with ``position_valid = 1`` and ``time_usec`` the measurement's stamp (not the send time).
A companion computer's HEARTBEAT (``MAV_TYPE_ONBOARD_CONTROLLER``,
``MAV_AUTOPILOT_INVALID``, from component ``MAV_COMP_ID_ONBOARD_COMPUTER`` by default) goes
out first and then about once a second.

An estimate is not sent, and is counted by reason in :class:`BridgeStats`, when it is
invalid (PX4 and ArduPilot both read ``position_valid = 0`` as an angle *measurement*, so
an invalid estimate is skipped, never flagged), not newer than the last one sent (a held,
stale estimate), not finite, behind the camera, or (PX4) without the vehicle's pose at its
stamp (with the reason the pose source gives).  Messages are MAVLink 2 (LANDING_TARGET's
x, y, z, q, type and position_valid are MAVLink 2 extension fields), encoded by pymavlink's
``common`` dialect; the link is pymavlink's ``mavutil`` connection (``udpout:HOST:PORT`` and
friends).  The link also receives: :class:`agents.io.autopilot_listener.AutopilotListener`
answers and sends TIMESYNC on it and collects the vehicle's pose from the autopilot.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from agents.common.user_input import UserError
from agents.io.landing_target import (
    AUTOPILOTS,
    LANDING_TARGET_TYPE_VISION_FIDUCIAL,
    CameraMount,
    LandingTargetFields,
    VehiclePose,
    landing_target_fields,
)
from estimation.errors import ConfigError, require_choice
from estimation.types import DeckPoseEstimate

#: the companion computer's component id (MAVLink common MAV_COMPONENT)
DEFAULT_COMPONENT_ID = mavlink2.MAV_COMP_ID_ONBOARD_COMPUTER
#: the vehicle's system id: a companion computer speaks as part of its vehicle
DEFAULT_SYSTEM_ID = 1
#: seconds between HEARTBEATs (MAVLink's microservices expect about 1 Hz)
HEARTBEAT_PERIOD_S = 1.0

#: whether pymavlink's TIMESYNC has the MAVLink 2 target fields (newer message definitions)
TIMESYNC_HAS_TARGETS = "target_system" in mavlink2.MAVLink_timesync_message.fieldnames

#: the vehicle's pose at a measurement's stamp: a VehiclePose, or None / the reason it has none
VehiclePoseSource = Callable[[float], VehiclePose | str | None]

_NETWORK = re.compile(r"^(udpout|udpin|udp|udpbcast|tcp|tcpin):([^:\s]+):(\d+)$")
_SERIAL = re.compile(r"^((?:/dev/\S+?)|(?:COM\d+))(?::(\d+))?$")
CONNECTION_HELP = (
    "udpout:HOST:PORT (send to HOST), udpin:HOST:PORT (listen), tcp:HOST:PORT, "
    "tcpin:HOST:PORT, or a serial device /dev/ttyXXX[:BAUD] (COMn[:BAUD] on Windows)"
)


@dataclass(frozen=True)
class ConnectionUrl:
    """A checked MAVLink connection string: ``device`` as pymavlink takes it, and the baud."""

    text: str
    device: str
    baud: int = 57600


def parse_connection_url(text: str) -> ConnectionUrl:
    """Check ``--to``: a network endpoint with a port in 1..65535 or a serial device."""
    text = str(text).strip()
    match = _NETWORK.match(text)
    if match:
        port = int(match.group(3))
        if not 1 <= port <= 65535:
            raise UserError(f"--to: port {port} in {text!r} is out of range; allowed 1..65535")
        return ConnectionUrl(text, text)
    match = _SERIAL.match(text)
    if match:
        baud = int(match.group(2)) if match.group(2) else 57600
        if baud <= 0:
            raise UserError(f"--to: baud {baud} in {text!r} must be positive")
        return ConnectionUrl(text, match.group(1), baud)
    raise UserError(f"--to: {text!r} is not a MAVLink connection; allowed: {CONNECTION_HELP}")


class MavlinkLink:
    """A MAVLink 2 sender and receiver over a pymavlink connection, as one system/component.

    Sending is thread-safe (a listener's thread answers TIMESYNC while the bridge sends);
    :meth:`receive` decodes with the v2 ``common`` dialect, which also reads MAVLink 1.
    """

    def __init__(
        self,
        url: str | ConnectionUrl,
        system_id: int = DEFAULT_SYSTEM_ID,
        component_id: int = DEFAULT_COMPONENT_ID,
    ) -> None:
        for key, value in (("--system-id", system_id), ("--component-id", component_id)):
            if not isinstance(value, int) or not 1 <= value <= 255:
                raise UserError(f"{key}: {value!r} is out of range; allowed 1..255")
        self.url = url if isinstance(url, ConnectionUrl) else parse_connection_url(url)
        try:
            self._connection = mavutil.mavlink_connection(
                self.url.device,
                baud=self.url.baud,
                source_system=system_id,
                source_component=component_id,
            )
        except OSError as exc:
            raise UserError(f"--to: cannot open {self.url.text!r}: {exc}") from None
        # the encoder of the v2 common dialect, whatever dialect mavutil was set to
        self._mav = mavlink2.MAVLink(
            self._connection, srcSystem=system_id, srcComponent=component_id
        )
        # and its decoder, in place of mavutil's (which switches pymavlink's dialect globally)
        decoder = mavlink2.MAVLink(self._connection, srcSystem=system_id, srcComponent=component_id)
        decoder.robust_parsing = True  # a corrupt frame comes back as BAD_DATA, not raised
        self._connection.mav = decoder
        self._connection.first_byte = False
        self._send_lock = threading.Lock()
        self.system_id = system_id
        self.component_id = component_id

    def send_heartbeat(self) -> None:
        """A companion computer's HEARTBEAT: onboard controller, no autopilot, active."""
        with self._send_lock:
            self._mav.heartbeat_send(
                mavlink2.MAV_TYPE_ONBOARD_CONTROLLER,
                mavlink2.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink2.MAV_STATE_ACTIVE,
            )

    def send_landing_target(self, time_usec: int, fields: LandingTargetFields) -> None:
        """One LANDING_TARGET with ``position_valid = 1`` (sizes unknown: 0)."""
        with self._send_lock:
            self._mav.landing_target_send(
                time_usec,
                0,
                fields.frame,
                fields.angle_x,
                fields.angle_y,
                fields.distance,
                0.0,
                0.0,
                fields.x,
                fields.y,
                fields.z,
                list(fields.q),
                LANDING_TARGET_TYPE_VISION_FIDUCIAL,
                1,
            )

    def send_timesync(
        self, tc1: int, ts1: int, target_system: int = 0, target_component: int = 0
    ) -> None:
        """One TIMESYNC (a request: ``tc1 = 0``); the target fields are filled where
        pymavlink's message has them (:data:`TIMESYNC_HAS_TARGETS`)."""
        targets = (target_system, target_component) if TIMESYNC_HAS_TARGETS else ()
        with self._send_lock:
            self._mav.timesync_send(tc1, ts1, *targets)

    def receive(self, timeout_s: float = 0.0):
        """The next decoded message, waiting up to ``timeout_s``; None when none came."""
        if timeout_s <= 0.0:
            return self._connection.recv_match(blocking=False)
        return self._connection.recv_match(blocking=True, timeout=timeout_s)

    def close(self) -> None:
        self._connection.close()

    def __enter__(self) -> MavlinkLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def time_usec_of(stamp_s: float) -> int:
    """LANDING_TARGET's ``time_usec`` of a measurement stamp in seconds (rounded)."""
    return round(stamp_s * 1e6)


@dataclass
class BridgeStats:
    """What the bridge did: messages sent, estimates skipped (by reason), wall seconds."""

    sent: int = 0
    heartbeats: int = 0
    skipped: Counter = field(default_factory=Counter)
    first_stamp_s: float = math.nan
    last_stamp_s: float = math.nan
    wall_s: float = 0.0

    @property
    def rate_hz(self) -> float:
        """LANDING_TARGETs per wall-clock second."""
        return self.sent / self.wall_s if self.wall_s > 0.0 else math.nan


class LandingTargetBridge:
    """Sends each usable estimate of a ``(stamp_s, estimate)`` stream as LANDING_TARGET.

    ``vehicle_pose(stamp_s)``: the vehicle's pose in the local NED frame at a measurement's
    stamp, or None (or the reason, a string) when unknown; PX4 needs it (its frame is
    MAV_FRAME_LOCAL_NED).  The simulator's truth (``SimulatorSource.vehicle_pose``) or the
    autopilot's telemetry (:class:`agents.io.autopilot_pose.AutopilotPoses`).
    ``on_sent(stamp_s)`` is called right after each LANDING_TARGET leaves (benchmarks time
    the latency with it).  ``clock``: the wall clock of the heartbeat period.
    """

    def __init__(
        self,
        link: MavlinkLink,
        autopilot: str,
        mount: CameraMount | None = None,
        vehicle_pose: VehiclePoseSource | None = None,
        on_sent: Callable[[float], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        heartbeat_period_s: float = HEARTBEAT_PERIOD_S,
    ) -> None:
        require_choice("autopilot", autopilot, AUTOPILOTS)
        if autopilot == "px4" and vehicle_pose is None:
            raise ConfigError(
                "vehicle_pose",
                "px4 reads LANDING_TARGET in MAV_FRAME_LOCAL_NED: give the vehicle's pose "
                "at each measurement (a source of VehiclePose)",
            )
        self.link = link
        self.autopilot = autopilot
        self.mount = mount or CameraMount()
        self.vehicle_pose = vehicle_pose
        self.on_sent = on_sent
        self.clock = clock
        self.heartbeat_period_s = heartbeat_period_s
        self.stats = BridgeStats()
        self._last_heartbeat = -math.inf

    def heartbeat_if_due(self) -> None:
        now = self.clock()
        if now - self._last_heartbeat >= self.heartbeat_period_s:
            self.link.send_heartbeat()
            self.stats.heartbeats += 1
            self._last_heartbeat = now

    def _refusal(self, stamp_s: float, estimate: DeckPoseEstimate) -> str:
        """Why the estimate is not sent ("" when it is)."""
        if not estimate.valid:
            return f"invalid: {estimate.reason or 'no reason given'}"
        if not isinstance(stamp_s, (int, float)) or not math.isfinite(stamp_s) or stamp_s < 0:
            return "bad stamp (not a finite time >= 0)"
        last = self.stats.last_stamp_s
        if not math.isnan(last) and time_usec_of(stamp_s) <= time_usec_of(last):
            return "not newer than the last sent"
        rotation = np.asarray(estimate.rotation, dtype=float)
        translation = np.asarray(estimate.translation, dtype=float)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            return "malformed pose"
        if not (np.all(np.isfinite(rotation)) and np.all(np.isfinite(translation))):
            return "non-finite pose"
        with np.errstate(all="ignore"):  # a huge entry overflows: then not orthonormal
            orthonormal = float(np.max(np.abs(rotation.T @ rotation - np.eye(3)))) <= 1e-6
        if not orthonormal:
            return "rotation not orthonormal"
        if np.linalg.det(rotation) <= 0.0:
            return "rotation is a reflection"
        if translation[2] <= 0.0:
            return "target not in front of the camera"
        return ""

    def send(self, stamp_s: float, estimate: DeckPoseEstimate) -> str:
        """Send one estimate; returns "sent" or the reason it was skipped."""
        self.heartbeat_if_due()
        reason = self._refusal(stamp_s, estimate)
        vehicle = None
        if not reason and self.autopilot == "px4":
            assert self.vehicle_pose is not None
            vehicle = self.vehicle_pose(stamp_s)
            if not isinstance(vehicle, VehiclePose):
                why = vehicle if isinstance(vehicle, str) and vehicle else "unknown"
                reason = f"no vehicle pose at the stamp: {why}"
        if not reason:
            fields = landing_target_fields(
                self.autopilot, estimate.rotation, estimate.translation, self.mount, vehicle
            )
            values = (fields.x, fields.y, fields.z, fields.distance, *fields.q)
            if not all(math.isfinite(v) and abs(v) < 3.0e38 for v in values):
                reason = "fields beyond float32"
        if reason:
            self.stats.skipped[reason] += 1
            return reason
        self.link.send_landing_target(time_usec_of(stamp_s), fields)
        if self.on_sent is not None:
            self.on_sent(stamp_s)
        stats = self.stats
        stats.sent += 1
        stats.last_stamp_s = float(stamp_s)
        if math.isnan(stats.first_stamp_s):
            stats.first_stamp_s = float(stamp_s)
        return "sent"

    def run(self, samples: Iterable[tuple[float, DeckPoseEstimate]]) -> BridgeStats:
        """Send a whole stream; returns the statistics (also kept in :attr:`stats`)."""
        start = time.perf_counter()
        try:
            for stamp_s, estimate in samples:
                self.send(stamp_s, estimate)
        finally:
            self.stats.wall_s += time.perf_counter() - start
        return self.stats


__all__ = [
    "CONNECTION_HELP",
    "DEFAULT_COMPONENT_ID",
    "DEFAULT_SYSTEM_ID",
    "TIMESYNC_HAS_TARGETS",
    "BridgeStats",
    "ConnectionUrl",
    "LandingTargetBridge",
    "MavlinkLink",
    "VehiclePoseSource",
    "parse_connection_url",
    "time_usec_of",
]
