"""The deck motions on which ``fused``'s online deck-motion identification is tuned and those
on which it is judged (benchmarks/bench_fused_unseen.py,
tests/estimation/fusion/test_filter_identification.py).

TUNING motions (the only ones any setting of the identification was chosen on): the bench's
JONSWAP sea (``motion.kind: sea_state``, sea state 3 and 4, the bench vessel), seeds 0-99.

HELD-OUT motions (never used to choose a setting; seeds from 7_000_000, which no fit, tuning
or training in this project uses): bench-scale CSV replays (``motion.kind: csv``) of spectra
the tuning never saw:

* ``bimodal``: a swell (Hs 1.5 m, Tp 14 s, peaked, gamma 3.3, from astern-quarter) plus a
  wind sea (Hs 1.6 m, Tp 5.5 s, from the beam), through a vessel with other natural periods
  (roll 7 s, pitch 4.5 s): two separated peaks, as DNV-RP-C205's two-peak spectra;
* ``long-swell``: a narrow long swell (Hs 2 m, Tp 16 s, gamma 5) alone, bow-quartering, with a
  stiffer vessel (roll 4 s).

Each is a sum of :class:`landing_env.stewart.motion.SeaStateMotion` records (the project's
JONSWAP synthesis) at the bench's default per-axis scale.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: seeds no fit or tuning uses (held-out motions only)
HELD_OUT_SEED_BASE = 7_000_000
#: the tuning motions' overrides of the ``realistic`` bench, and their seeds
TUNING_MOTIONS: dict[str, dict] = {
    "jonswap-ss3": {"motion.kind": "sea_state", "motion.sea_state.sea_state": 3},
    "jonswap-ss4": {"motion.kind": "sea_state", "motion.sea_state.sea_state": 4},
}
TUNING_SEEDS = range(100)

#: held-out spectra: (component settings of SeaStateConfig) summed
HELD_OUT_SPECTRA: dict[str, tuple[dict, ...]] = {
    "bimodal": (
        {
            "sea_state": None,
            "significant_height_m": 1.5,
            "peak_period_s": 14.0,
            "gamma": 3.3,
            "wave_direction_deg": 200.0,
            "direction_spread_deg": 15.0,
            "roll_period_s": 7.0,
            "pitch_period_s": 4.5,
        },
        {
            "sea_state": None,
            "significant_height_m": 1.6,
            "peak_period_s": 5.5,
            "gamma": 1.0,
            "wave_direction_deg": 100.0,
            "direction_spread_deg": 40.0,
            "roll_period_s": 7.0,
            "pitch_period_s": 4.5,
        },
    ),
    "long-swell": (
        {
            "sea_state": None,
            "significant_height_m": 2.0,
            "peak_period_s": 16.0,
            "gamma": 5.0,
            "wave_direction_deg": 120.0,
            "direction_spread_deg": 10.0,
            "roll_period_s": 4.0,
        },
    ),
}


def held_out_poses(name: str, seed: int, times: np.ndarray) -> np.ndarray:
    """The held-out motion ``name`` drawn with ``seed``: platform poses (N, 6; m, rad)."""
    from landing_env.stewart.motion import SeaStateConfig, SeaStateMotion  # the simulator's

    rng = np.random.default_rng(seed)
    total = np.zeros((len(times), 6))
    for component in HELD_OUT_SPECTRA[name]:
        total += SeaStateMotion(SeaStateConfig(**component), rng).poses(np.asarray(times))
    return total


def write_held_out_csv(name: str, seed: int, path: Path, duration_s: float) -> Path:
    """Write the held-out motion as a motion CSV at 100 Hz (``motion.kind: csv``)."""
    from landing_env.stewart.motion import write_motion_csv

    times = np.arange(0.0, duration_s + 1.0, 0.01)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_motion_csv(path, times, held_out_poses(name, seed, times))
    return path
