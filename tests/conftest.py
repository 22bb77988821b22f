"""Test-wide settings.

Hypothesis runs derandomized by default, so that a CI run is reproducible: the same examples
every time, chosen from the test's own strategies. ``HYPOTHESIS_PROFILE=explore`` draws fresh
random examples (and more of them) to search for new failures; ``benchmarks/fuzz_soak.py``
is the long search.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Iterator

import pytest
from hypothesis import settings

settings.register_profile("deterministic", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))


@pytest.fixture(scope="session")
def small_forecast():
    """A helideck forecast of ship-ss4's sea fitted on three short records (seconds to fit)."""
    from landing_env.anticipation.hms_forecast import fit_deck_forecast
    from landing_env.config import load_config
    from landing_env.scenarios import SCENARIOS

    motion = load_config(SCENARIOS["ship-ss4"].config).motion
    return fit_deck_forecast(motion, realizations=3, record_s=400.0)


@pytest.fixture
def listener() -> Iterator[socket.socket]:
    """A UDP socket on loopback that the MAVLink bridge sends to (udpout), with a short timeout."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    try:
        yield sock
    finally:
        sock.close()
