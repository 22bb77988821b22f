"""Test-wide settings.

Hypothesis runs derandomized by default, so that a CI run is reproducible: the same examples
every time, chosen from the test's own strategies. ``HYPOTHESIS_PROFILE=explore`` draws fresh
random examples (and more of them) to search for new failures; ``benchmarks/fuzz_soak.py``
is the long search.

The long tests run first (:func:`pytest_collection_modifyitems`): under ``make test``
(``pytest -n 2 --dist worksteal``) the worker that runs out of tests takes half of the
other's queue, so the short ones fill the end rather than one worker running the last long
blocks while the other idles.
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

#: the documented blocks, each run in a fresh process (5-60 s each)
_FRESH_PROCESS_TESTS = "tests/test_docs_snippets.py::test_the_documented_block_runs"


def _runs_long(item: pytest.Item) -> bool:
    return item.get_closest_marker("slow") is not None or item.nodeid.startswith(
        _FRESH_PROCESS_TESTS
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The long tests first, each group in its collected order (the same on every worker)."""
    items[:] = [item for item in items if _runs_long(item)] + [
        item for item in items if not _runs_long(item)
    ]


#: mutmut's first pass (``MUTANT_UNDER_TEST=stats``) credits the functions a test calls to
#: that test, its fixtures' setup included; a module- or session-scoped fixture is set up
#: for the first test that asks for it alone, so each later test that asks for it is
#: credited with what the fixture's setup called too, or no mutant there would run it
_SHARED_SETUP_HITS: dict[int, set[str]] = {}


def _collecting_mutation_stats() -> bool:
    return os.environ.get("MUTANT_UNDER_TEST") == "stats"


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef: pytest.FixtureDef, request: pytest.FixtureRequest):
    if fixturedef.scope == "function" or not _collecting_mutation_stats():
        return (yield)
    from mutmut.state import state

    before, state()._stats = state()._stats, set()
    try:
        return (yield)
    finally:
        hits = state()._stats
        _SHARED_SETUP_HITS.setdefault(id(fixturedef), set()).update(hits)
        state()._stats = before | hits


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_teardown(item: pytest.Item) -> None:
    if not (_SHARED_SETUP_HITS and _collecting_mutation_stats()):
        return
    from mutmut.state import state

    info = getattr(item, "_fixtureinfo", None)
    for definitions in info.name2fixturedefs.values() if info is not None else ():
        for fixturedef in definitions:
            state()._stats.update(_SHARED_SETUP_HITS.get(id(fixturedef), ()))


@pytest.fixture(scope="session")
def small_forecast():
    """A helideck forecast of ship-ss4's sea fitted on three short records (seconds to fit),
    through the forecasts' cache as the scenarios' own: the first test worker that asks fits
    it, the other reads it back (the same to the bit)."""
    from landing_env.anticipation.hms_forecast import cached_deck_forecast
    from landing_env.config import load_config
    from landing_env.scenarios import SCENARIOS

    motion = load_config(SCENARIOS["ship-ss4"].config).motion
    return cached_deck_forecast(motion, realizations=3, record_s=400.0)


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
