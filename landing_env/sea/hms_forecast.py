"""The helideck forecast: the ship's HMS record a few seconds ahead.

A direct multi-horizon linear predictor
(:class:`~estimation.deck_prediction.LinearMotionPredictor`) maps the HMS's last
:data:`WINDOW_S` of surge, sway, heave, roll and pitch at the helideck
(:class:`~landing_env.sea.hms.HelideckMonitor`) to the same five every 0.5 s up to
:data:`HORIZONS_S`'s 8 s: the classical ship-motion prediction from the recent past.  It is
fitted on :data:`REALIZATIONS` HMS records of the scenario's own sea drawn with other seeds
(other days in the same sea state: a record of the episode's own sea would let a linear model
lock onto the simulated sea's finitely many wave frequencies, which no real sea has).

Read by the ``deck-forecast`` policies (:mod:`agents.timing.deck_forecast`) and by the timing task's
``forecast`` observation (:mod:`landing_env.timing.env`).
"""

from __future__ import annotations

import numpy as np

from estimation.deck_prediction import LinearMotionPredictor
from landing_env.errors import ConfigError, require_range
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.stewart.motion import MotionConfig, make_motion_source, sample_poses

#: the forecast's horizons, seconds: every 0.5 s to 8 s (a commit's descent, contact and
#: settle take 3-7 s)
HORIZONS_S = np.round(np.arange(0.0, 8.0 + 1e-9, 0.5), 2)
#: the HMS history the forecast reads, seconds (two peak periods at sea state 5)
WINDOW_S = 20.0
#: HMS samples averaged into one feature (0.5 s at 10 Hz)
BLOCK = 5
#: records of other realisations of the scenario's sea the forecast is fitted on
REALIZATIONS = 8
#: length of each record, seconds
RECORD_S = 1200.0
#: one example every this many seconds of a record
EXAMPLE_EVERY_S = 1.0
#: the first seed of the fitting records (the evaluations' seeds are 1 000 000 on)
FIT_SEED = 9000
#: motion kinds whose sources are a fixed function of time with a past (sums of waves)
FORECAST_KINDS: tuple[str, ...] = ("ship", "sea_state")

_FITTED: dict[str, LinearMotionPredictor] = {}


def fit_deck_forecast(
    motion: MotionConfig,
    hms: HelideckMonitorConfig | None = None,
    realizations: int = REALIZATIONS,
    record_s: float = RECORD_S,
    seed: int = FIT_SEED,
) -> LinearMotionPredictor:
    """The helideck forecast of the sea ``motion`` describes, fitted on ``realizations`` HMS
    records of it (seeds ``seed``, ``seed + 1``, ...), each ``record_s`` long; the last quarter
    of the records is held out for the ridge and the error (the predictor's metadata)."""
    if motion.kind not in FORECAST_KINDS:
        raise ConfigError(
            "motion.kind",
            f"is {motion.kind!r}; the deck forecast needs a sea ({', '.join(FORECAST_KINDS)})",
        )
    require_range("realizations", realizations, 2, 1000)
    require_range("record_s", record_s, 2 * (WINDOW_S + HORIZONS_S[-1]), 1e6)
    hms = hms or HelideckMonitorConfig()
    dt = hms.dt_s
    n_window = round(WINDOW_S / dt)
    steps = np.round(HORIZONS_S / dt).astype(int)
    stride = max(1, round(EXAMPLE_EVERY_S / dt))
    histories, futures, groups = [], [], []
    for k in range(realizations):
        source = make_motion_source(motion, np.random.default_rng([seed + k]))
        monitor = HelideckMonitor(source, hms, seed=seed + k)
        times, measured = monitor.window(0.0, record_s)
        truth = sample_poses(source, times)[:, : len(HMS_CHANNELS)]
        ends = np.arange(n_window - 1, len(times) - steps[-1], stride)
        windows = np.stack([measured[end - n_window + 1 : end + 1] for end in ends])
        histories.append(np.concatenate([windows, np.ones((*windows.shape[:2], 1))], axis=2))
        futures.append(truth[ends[:, None] + steps[None, :]])
        groups.append(np.full(len(ends), k))
    return LinearMotionPredictor.fit(
        np.concatenate(histories),
        np.concatenate(futures),
        np.concatenate(groups),
        HORIZONS_S,
        WINDOW_S,
        dt,
        block=BLOCK,
        channels=HMS_CHANNELS,
        targets=HMS_CHANNELS,
        metadata={"realizations": realizations, "record_s": record_s, "seed": seed},
    )


def deck_forecast_for(motion: MotionConfig, hms: HelideckMonitorConfig) -> LinearMotionPredictor:
    """:func:`fit_deck_forecast` with the defaults, once per sea and HMS in a process."""
    key = repr((motion, hms))
    if key not in _FITTED:
        _FITTED[key] = fit_deck_forecast(motion, hms)
    return _FITTED[key]
