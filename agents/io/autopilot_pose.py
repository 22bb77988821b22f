"""The vehicle's pose from its autopilot's telemetry, looked up at a measurement's stamp.

PX4 reads LANDING_TARGET in its local NED frame (:mod:`agents.io.landing_target`), so the
companion computer needs the vehicle's pose at each measurement's time.  The autopilot
streams it: ``LOCAL_POSITION_NED`` (#32: x, y, z of the body origin in the local NED frame)
and ``ATTITUDE_QUATERNION`` (#31: ``q1..q4`` = ``(w, x, y, z)``, the body FRD axes in NED),
each stamped ``time_boot_ms`` on the autopilot's clock, or ``ODOMETRY`` (#331) with both at
once (``time_usec``; used with ``frame_id = MAV_FRAME_LOCAL_NED`` only: ``child_frame_id`` is
the velocity's frame, not read, which PX4 sends as ``MAV_FRAME_BODY_FRD`` up to v1.13 and as
``MAV_FRAME_LOCAL_NED`` from v1.14 on).

:class:`AutopilotPoses` keeps a short history of each, on the autopilot's clock, and answers
``poses(stamp_s)`` for a stamp on the companion's clock: the stamp goes to the autopilot's
clock through the TIMESYNC offset (:class:`agents.io.timesync.ClockSync`), then the position
is interpolated linearly and the attitude by slerp (SciPy) between the two samples around it.
Without a converged offset, or outside the history, it returns the reason as a string instead
of a pose (the bridge then sends nothing and counts the reason).  Samples out of time order,
repeated, or not finite are skipped and counted, never raised.  Once an ``ODOMETRY`` in the
right frames arrives it is the only source (the two separate messages are then ignored).
"""

from __future__ import annotations

import bisect
import math
import threading
from collections import Counter

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from agents.io.landing_target import VehiclePose
from agents.io.timesync import ClockSync
from estimation.errors import ConfigError

#: seconds of telemetry kept (the vision link delivers up to a few hundred ms late)
HISTORY_S = 2.0
#: at most this many samples per quantity, whatever their spacing
MAX_SAMPLES = 2048
#: a quaternion whose norm is this far from 1 is not an attitude
QUATERNION_NORM_TOLERANCE = 0.01

KEPT = "kept"


class _Track:
    """Time-ordered samples of one quantity on the autopilot's clock."""

    def __init__(self, name: str, history_s: float) -> None:
        self.name = name
        self.history_s = history_s
        self.times_s: list[float] = []
        self.values: list[np.ndarray] = []

    def add(self, time_s: float, value: np.ndarray) -> str:
        if self.times_s:
            newest = self.times_s[-1]
            if time_s == newest:
                return f"{self.name}: repeated stamp"
            if time_s < newest - self.history_s:  # the autopilot restarted its clock
                self.times_s.clear()
                self.values.clear()
            elif time_s < newest:
                return f"{self.name}: out of time order"
        self.times_s.append(time_s)
        self.values.append(value)
        cut = bisect.bisect_left(self.times_s, time_s - self.history_s)
        cut = max(cut, len(self.times_s) - MAX_SAMPLES)
        if cut > 0:
            del self.times_s[:cut]
            del self.values[:cut]
        return KEPT

    def bracket(self, time_s: float) -> tuple[int, float] | str:
        """``(i, fraction)``: ``time_s`` lies between samples i and i+1 (fraction 0 at i);
        or why it lies outside."""
        times = self.times_s
        if not times:
            return f"no {self.name} yet"
        if time_s < times[0]:
            return f"stamp before the oldest {self.name}"
        if time_s > times[-1]:
            return f"stamp after the newest {self.name}"
        i = bisect.bisect_right(times, time_s) - 1
        if i == len(times) - 1:
            return i, 0.0
        return i, (time_s - times[i]) / (times[i + 1] - times[i])


class AutopilotPoses:
    """The vehicle's pose in the local NED frame from the autopilot's telemetry, at companion
    stamps; call it as ``poses(stamp_s)`` (a :class:`VehiclePose`, or why there is none).

    ``sync``: the TIMESYNC offset of the autopilot's clock; ``history_s``: seconds kept.
    :attr:`skipped` counts the samples not kept, :attr:`misses` the lookups without a pose,
    by reason.  Thread-safe: telemetry may arrive on a listener's thread.
    """

    def __init__(self, sync: ClockSync, history_s: float = HISTORY_S) -> None:
        if not (isinstance(history_s, (int, float)) and 0.0 < history_s < math.inf):
            raise ConfigError("history_s", f"{history_s!r} is out of range; allowed (0, inf)")
        self.sync = sync
        self.positions = _Track("position", float(history_s))
        self.attitudes = _Track("attitude", float(history_s))
        self.odometry = False
        self.kept: Counter = Counter()
        self.skipped: Counter = Counter()
        self.misses: Counter = Counter()
        self._lock = threading.Lock()

    # ---------------------------------------------------------------- telemetry in
    def add_position(self, time_s: float, position_ned_m, *, odometry: bool = False) -> str:
        """One ``LOCAL_POSITION_NED`` (``time_s``: the autopilot's clock, seconds)."""
        if self.odometry and not odometry:
            return self._skip("LOCAL_POSITION_NED ignored: ODOMETRY in use")
        value = _finite_vector(position_ned_m, 3)
        if value is None or not _finite_time(time_s):
            return self._skip("position: not finite")
        return self._add(self.positions, float(time_s), value)

    def add_attitude(self, time_s: float, q_wxyz, *, odometry: bool = False) -> str:
        """One ``ATTITUDE_QUATERNION`` (``q_wxyz``: the body FRD axes in NED)."""
        if self.odometry and not odometry:
            return self._skip("ATTITUDE_QUATERNION ignored: ODOMETRY in use")
        value = _finite_vector(q_wxyz, 4)
        if value is None or not _finite_time(time_s):
            return self._skip("attitude: not finite")
        with np.errstate(over="ignore"):  # a huge entry: an infinite norm, refused below
            norm = float(np.linalg.norm(value))
        if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
            return self._skip("attitude: quaternion not of unit norm")
        w, x, y, z = value / norm
        return self._add(self.attitudes, float(time_s), np.array([x, y, z, w]))

    def add_odometry(self, time_s: float, position_ned_m, q_wxyz) -> str:
        """One ``ODOMETRY`` in local NED / body FRD: position and attitude at one stamp."""
        value = _finite_vector(position_ned_m, 3)
        quaternion = _finite_vector(q_wxyz, 4)
        if value is None or quaternion is None or not _finite_time(time_s):
            return self._skip("odometry: not finite")
        self.odometry = True
        reason = self.add_position(time_s, value, odometry=True)
        if reason != KEPT:
            return reason
        return self.add_attitude(time_s, quaternion, odometry=True)

    def _add(self, track: _Track, time_s: float, value: np.ndarray) -> str:
        with self._lock:
            reason = track.add(time_s, value)
        if reason == KEPT:
            self.kept[track.name] += 1
            return reason
        return self._skip(reason)

    def _skip(self, reason: str) -> str:
        self.skipped[reason] += 1
        return reason

    # ---------------------------------------------------------------- lookups
    def __call__(self, stamp_s: float) -> VehiclePose | str:
        """The pose at ``stamp_s`` on the companion's clock, or why there is none."""
        result = self.lookup(stamp_s)
        if isinstance(result, str):
            self.misses[result] += 1
        return result

    def lookup(self, stamp_s: float) -> VehiclePose | str:
        if not _finite_time(stamp_s):
            return "bad stamp"
        sync = self.sync
        if not sync.converged:
            return "clock not synchronised yet (TIMESYNC)"
        time_s = sync.to_autopilot_s(float(stamp_s))
        with self._lock:
            where_p = self.positions.bracket(time_s)
            where_q = self.attitudes.bracket(time_s)
            if isinstance(where_p, str):
                return where_p
            if isinstance(where_q, str):
                return where_q
            position = _lerp(self.positions, *where_p)
            i, fraction = where_q
            quaternions = self.attitudes.values[i : i + 2]
        if len(quaternions) == 1 or fraction == 0.0:
            rotation = Rotation.from_quat(quaternions[0])
        else:
            rotation = Slerp([0.0, 1.0], Rotation.from_quat(np.array(quaternions)))(fraction)
        return VehiclePose(position, rotation.as_matrix())


def _lerp(track: _Track, i: int, fraction: float) -> np.ndarray:
    if fraction == 0.0:
        return track.values[i].copy()
    return (1.0 - fraction) * track.values[i] + fraction * track.values[i + 1]


def _finite_vector(values, size: int) -> np.ndarray | None:
    try:
        vector = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        return None
    return vector


def _finite_time(value: float) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


__all__ = ["HISTORY_S", "KEPT", "AutopilotPoses"]
