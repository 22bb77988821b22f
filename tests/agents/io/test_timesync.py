"""The TIMESYNC offset follows an autopilot clock that runs fast: the estimate's drift term
(PX4's double exponential smoothing) keeps it on the moving offset once converged."""

from __future__ import annotations

import pytest

from agents.io.autopilot_listener import REQUEST_PERIOD_S
from agents.io.timesync import CONVERGENCE_WINDOW, ClockSync

NS = 1_000_000_000


@pytest.mark.parametrize("drift_ppm", [50.0, -50.0, 200.0])
def test_the_offset_follows_a_drifting_autopilot_clock_within_50_us(drift_ppm: float) -> None:
    sync = ClockSync()
    boot_offset_ns = 123 * NS  # the autopilot's clock minus the companion's at 0
    one_way_ns = 1_000_000  # 1 ms each way
    errors_s = []
    for k in range(3 * CONVERGENCE_WINDOW):  # a request every 50 ms, as the listener sends
        sent_ns = 10 * NS + round(k * REQUEST_PERIOD_S * NS)
        at_autopilot_ns = sent_ns + one_way_ns
        drift_ns = round(drift_ppm * 1e-6 * at_autopilot_ns)
        remote_ns = at_autopilot_ns + boot_offset_ns + drift_ns
        assert sync.add_exchange(sent_ns, remote_ns, sent_ns + 2 * one_way_ns) == "used"
        if sync.converged:
            # the offset when the autopilot stamped its reply
            errors_s.append(sync.offset_s - (boot_offset_ns + drift_ns) / NS)
    assert len(errors_s) == 2 * CONVERGENCE_WINDOW + 1
    assert max(abs(e) for e in errors_s) < 50e-6, max(errors_s, key=abs)
