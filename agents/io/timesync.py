"""The offset between an autopilot's clock and the companion computer's, from TIMESYNC (#111).

MAVLink's time synchronisation (common message TIMESYNC, mavlink.io/en/services/timesync):
a request carries the sender's clock in ``ts1`` (nanoseconds) and ``tc1 = 0``; the reply
echoes ``ts1`` and puts the replier's own clock in ``tc1``.  The sender of the request, on
receiving the reply at ``t1``, knows the round-trip time ``t1 - ts1`` and, taking the two
legs as equally long, one sample of the offset ``tc1 - (ts1 + t1) / 2``.

:class:`ClockSync` filters those samples by the rules PX4 applies to its own
(``src/lib/timesync/Timesync.cpp`` and ``Timesync.hpp`` in github.com/PX4/PX4-Autopilot,
read to learn them):

* a sample whose round trip took :data:`MAX_RTT_S` (10 ms) or longer is not used;
* the estimate is double exponential smoothing (an offset and its drift per sample), whose
  gains fall from :data:`GAIN_INITIAL` (0.05) to :data:`GAIN_FINAL` (0.003) along the first
  :data:`CONVERGENCE_WINDOW` (500) used samples, as ``final + (initial - final) *
  exp(-k / (2 (N - k)))`` after ``k`` of ``N`` samples; the first sample is taken as it is;
* the estimate has converged after :data:`CONVERGENCE_WINDOW` used samples;
* once converged, a sample more than :data:`MAX_DEVIATION_S` (100 ms) from the estimate is
  not used, and more than :data:`MAX_HIGH_DEVIATIONS` (5) such samples in a row (a jump of
  either clock) restart the filter.

Here the offset is ``autopilot clock - companion clock``: an autopilot's stamp ``t_ap`` is
the companion's ``t_ap - offset_s``.  It is what PX4 computes the other way round: PX4
adds its own estimate to a companion's ``time_usec`` (``Timesync::sync_stamp``).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from estimation.errors import ConfigError

#: samples whose round trip took this long or longer are not used (PX4: 10 ms)
MAX_RTT_S = 0.010
#: once converged, samples this far from the estimate are not used (PX4: 100 ms)
MAX_DEVIATION_S = 0.100
#: more such samples in a row restart the filter (PX4: 5)
MAX_HIGH_DEVIATIONS = 5
#: used samples until the estimate has converged and the gains are final (PX4: 500)
CONVERGENCE_WINDOW = 500
#: the smoothing gains of offset and drift, at the start and once converged (PX4's)
GAIN_INITIAL = 0.05
GAIN_FINAL = 0.003

USED = "used"


def smoothing_gain(samples: int, window: int) -> float:
    """The gain after ``samples`` used samples: from :data:`GAIN_INITIAL` down to
    :data:`GAIN_FINAL`, reached at ``window`` samples."""
    if samples >= window:
        return GAIN_FINAL
    weight_initial = math.exp(-samples / (2.0 * (window - samples)))
    return GAIN_FINAL + (GAIN_INITIAL - GAIN_FINAL) * weight_initial


@dataclass
class ClockSync:
    """The filtered offset ``autopilot clock - companion clock`` from TIMESYNC exchanges.

    :attr:`offset_s` (NaN before the first used sample), :attr:`rtt_s` (the last round trip
    seen, used or not), :attr:`samples` (used since the last restart), :attr:`converged`,
    and :attr:`rejected` (samples not used, by reason) are there for logging.
    """

    convergence_window: int = CONVERGENCE_WINDOW
    max_rtt_s: float = MAX_RTT_S
    max_deviation_s: float = MAX_DEVIATION_S
    offset_s: float = math.nan
    drift_s: float = 0.0
    rtt_s: float = math.nan
    samples: int = 0
    restarts: int = 0
    rejected: Counter = field(default_factory=Counter)
    _high_deviations: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.convergence_window, int) or self.convergence_window < 1:
            raise ConfigError(
                "convergence_window",
                f"{self.convergence_window!r} is out of range; allowed an integer >= 1",
            )
        for name in ("max_rtt_s", "max_deviation_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ConfigError(name, f"{value!r} is out of range; allowed (0, inf)")

    @property
    def converged(self) -> bool:
        return self.samples >= self.convergence_window

    def restart(self) -> None:
        """Forget the estimate (a clock jumped)."""
        self.offset_s, self.drift_s, self.samples = math.nan, 0.0, 0
        self._high_deviations = 0
        self.restarts += 1

    def add_exchange(self, sent_ns: int, remote_ns: int, received_ns: int) -> str:
        """One reply: our request left at ``sent_ns`` (its ``ts1``), the autopilot stamped
        ``remote_ns`` (``tc1``), we received it at ``received_ns``; all nanoseconds.
        Returns :data:`USED` or why the sample was not used."""
        if not all(isinstance(v, int) for v in (sent_ns, remote_ns, received_ns)):
            return self._reject("stamps not integers")
        rtt_ns = received_ns - sent_ns
        if rtt_ns < 0:
            return self._reject("reply received before its request was sent")
        self.rtt_s = rtt_ns * 1e-9
        if self.rtt_s >= self.max_rtt_s:
            return self._reject(f"round trip >= {self.max_rtt_s * 1e3:g} ms")
        # exact in integers, then seconds: offset = tc1 - (ts1 + t1) / 2
        sample_s = (2 * remote_ns - sent_ns - received_ns) * 0.5e-9
        if self.converged and abs(sample_s - self.offset_s) > self.max_deviation_s:
            self._high_deviations += 1
            if self._high_deviations > MAX_HIGH_DEVIATIONS:
                self.restart()
                return self._reject("far from the estimate: filter restarted")
            return self._reject(f"more than {self.max_deviation_s * 1e3:g} ms from the estimate")
        self._high_deviations = 0
        if self.samples == 0:
            self.offset_s, self.drift_s = sample_s, 0.0
        else:
            gain = smoothing_gain(self.samples, self.convergence_window)
            previous = self.offset_s
            self.offset_s = gain * sample_s + (1.0 - gain) * (previous + self.drift_s)
            self.drift_s = gain * (self.offset_s - previous) + (1.0 - gain) * self.drift_s
        self.samples += 1
        return USED

    def _reject(self, reason: str) -> str:
        self.rejected[reason] += 1
        return reason

    def to_companion_s(self, autopilot_s: float) -> float:
        """An autopilot stamp on the companion's clock (NaN before the first sample)."""
        return autopilot_s - self.offset_s

    def to_autopilot_s(self, companion_s: float) -> float:
        """A companion stamp on the autopilot's clock (NaN before the first sample)."""
        return companion_s + self.offset_s
