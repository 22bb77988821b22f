"""Measurement stamps played on the wall clock: a source's pace and its companion clock.

A source of ``(stamp_s, estimate)`` pairs (the simulator, :mod:`agents.io.sim_source`, or a
recording, :mod:`agents.io.recording_source`) paces itself with a :class:`StampPacer`: the
stamp ``origin_s`` is played at the pacer's start (the first call of :meth:`StampPacer.start`,
:meth:`StampPacer.clock_s` or :meth:`StampPacer.wait_until`), and a stamp ``t`` is due
``(t - origin_s) / speed`` wall seconds later.  ``speed`` 1 is real time, 2 twice as fast;
0 is not paced (nothing waits, and the stamps follow no clock).

:meth:`StampPacer.clock_s` is the clock of the stamps read on the wall clock: the companion
computer's clock for TIMESYNC (:class:`agents.io.autopilot_listener.AutopilotListener`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from estimation.errors import ConfigError


def _number(value: object, key: str) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError(key, f"{value!r} is not a number") from None


class StampPacer:
    """Plays stamps (seconds) on the wall clock at ``speed`` (module doc).

    ``wall_clock`` and ``sleep`` default to :func:`time.perf_counter` and :func:`time.sleep`
    (the tests give their own)."""

    def __init__(
        self,
        speed: float,
        origin_s: float = 0.0,
        wall_clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        speed = _number(speed, "speed")
        if not 0.0 <= speed < math.inf:
            raise ConfigError("speed", f"{speed} is out of range; allowed [0, inf), 0: unpaced")
        origin_s = _number(origin_s, "origin_s")
        if not math.isfinite(origin_s):
            raise ConfigError("origin_s", f"{origin_s} is not a finite stamp (seconds)")
        self.speed = speed
        self.origin_s = origin_s
        self._wall_clock = wall_clock
        self._sleep = sleep
        self._wall0: float | None = None

    def start(self) -> float:
        """The wall time at which ``origin_s`` is played (fixed by the first call)."""
        if self._wall0 is None:
            self._wall0 = self._wall_clock()
        return self._wall0

    def clock_s(self) -> float:
        """Now, on the clock of the stamps (paced runs only)."""
        if self.speed == 0.0:
            raise ConfigError(
                "speed", "0 (unpaced): the stamps follow no clock; pace the source (> 0)"
            )
        return self.origin_s + (self._wall_clock() - self.start()) * self.speed

    def wait_until(self, stamp_s: float) -> float:
        """Sleep until ``stamp_s`` is due (no wait when unpaced or already late); returns the
        seconds slept."""
        wall0 = self.start()
        if self.speed == 0.0:
            return 0.0
        wait = wall0 + (stamp_s - self.origin_s) / self.speed - self._wall_clock()
        if wait > 0.0:
            self._sleep(wait)
            return wait
        return 0.0


__all__ = ["StampPacer"]
