"""Test-wide settings.

Hypothesis runs derandomized by default, so that a CI run is reproducible: the same examples
every time, chosen from the test's own strategies. ``HYPOTHESIS_PROFILE=explore`` draws fresh
random examples (and more of them) to search for new failures; ``benchmarks/fuzz_soak.py``
is the long search.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("deterministic", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))
