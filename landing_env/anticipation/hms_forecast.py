"""The helideck forecast: the ship's HMS record a few seconds ahead.

A direct multi-horizon linear predictor
(:class:`~estimation.anticipation.linear_predictors.LinearMotionPredictor`) maps the HMS's last
:data:`WINDOW_S` of surge, sway, heave, roll and pitch at the helideck
(:class:`~landing_env.sea.hms.HelideckMonitor`) to the same five every 0.5 s up to
:data:`HORIZONS_S`'s 8 s: the classical ship-motion prediction from the recent past.  By
default it is fitted on :data:`REALIZATIONS` HMS records of the scenario's own sea drawn with
other seeds (other days in the same sea state: a record of the episode's own sea would let a
linear model lock onto the simulated sea's finitely many wave frequencies, which no real sea
has).  A config's ``deck_forecast`` chooses otherwise: ``online`` identifies the forecast in
each episode from the ship's own HMS record of the last 20 min, refitted every 30 s
(:func:`fit_online_forecast`, :class:`EpisodeForecast`: a ship's HMS records all the time, so
a sea never seen before is identified from its own past; fitted on the past alone it does not
lock onto the simulated sea's components: it measured no better than the fit on other
realisations of the sea, ``docs/experiments/ship-timing.md``); a training family of seas
(:mod:`landing_env.sea.training_seas`, ``ship-broad``) fits it on the family, one record per
member.  A held-out sea's config must name one of these: :func:`deck_forecast_for` refuses to
fit on a held-out sea.

The fit is deterministic given its inputs and takes tens of seconds, so
:func:`deck_forecast_for` fits each forecast once per machine: :func:`cached_deck_forecast`
keeps it in the user cache directory (:func:`~landing_env.resources.cache_dir`,
``DECK_LANDING_CACHE_DIR`` overrides it), keyed by a hash of everything the fit reads (the
seas, the HMS, the sizes, the seed, the fitting code's source and NumPy's version), and gives
back the fitted forecast to the bit; one process fits while the others wait for its file.

Read by the onboard look-ahead of ``timing-dqn-lookahead`` (:mod:`agents.policies.deck_forecast`).
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import inspect
import json
import math
import platform
from collections.abc import Sequence
from dataclasses import asdict
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from estimation.anticipation.linear_predictors import LinearMotionPredictor
from estimation.array_files import locked
from landing_env.config import DeckLandingConfig, load_config
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.resources import cache_dir
from landing_env.sea.heldout import HELD_OUT_SEAS
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.sea.training_seas import TRAINING_FAMILIES, member_config
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

#: the modules (a package: each of its files) whose code the fit runs: a cached forecast
#: (:func:`cached_deck_forecast`) is keyed by their source, so an edit to any of them refits
FIT_CODE: tuple[str, ...] = (
    __name__,
    "estimation.anticipation.linear_predictors",
    "landing_env.sea.hms",
    "landing_env.stewart.motion",
    "landing_env.waves",
)
#: the folder of the cached forecasts, under :func:`~landing_env.resources.cache_dir`
CACHE_FOLDER = "deck-forecasts"

_FITTED: dict[str, LinearMotionPredictor] = {}


def fit_deck_forecast(
    motion: MotionConfig | Sequence[MotionConfig],
    hms: HelideckMonitorConfig | None = None,
    realizations: int = REALIZATIONS,
    record_s: float = RECORD_S,
    seed: int = FIT_SEED,
) -> LinearMotionPredictor:
    """The helideck forecast of the sea ``motion`` describes (or of the seas of a sequence of
    motions, in turn), fitted on ``realizations`` HMS records (seeds ``seed``, ``seed + 1``,
    ...; at least one per sea), each ``record_s`` long; the last quarter of the records is held
    out for the ridge and the error (the predictor's metadata)."""
    motions = [motion] if isinstance(motion, MotionConfig) else list(motion)
    if not motions:
        raise ConfigError("motion", "no sea to fit the deck forecast on")
    for each in motions:
        if each.kind not in FORECAST_KINDS:
            raise ConfigError(
                "motion.kind",
                f"is {each.kind!r}; the deck forecast needs a sea ({', '.join(FORECAST_KINDS)})",
            )
    realizations = max(realizations, len(motions))
    require_range("realizations", realizations, 2, 1000)
    require_range("record_s", record_s, 2 * (WINDOW_S + HORIZONS_S[-1]), 1e6)
    hms = hms or HelideckMonitorConfig()
    records = []
    for k in range(realizations):
        source = make_motion_source(motions[k % len(motions)], np.random.default_rng([seed + k]))
        monitor = HelideckMonitor(source, hms, seed=seed + k)
        times, measured = monitor.window(0.0, record_s)
        records.append((measured, sample_poses(source, times)[:, : len(HMS_CHANNELS)]))
    metadata = {"realizations": realizations, "record_s": record_s, "seed": seed}
    return _fit(records, hms.dt_s, {**metadata, "seas": len(motions)})


_FIT_SIGNATURE = inspect.signature(fit_deck_forecast)


def _fit(
    records: list[tuple[np.ndarray, np.ndarray]], dt_s: float, metadata: dict[str, float]
) -> LinearMotionPredictor:
    """The forecast fitted on ``records`` (each the HMS's measurements and the targets, one
    group of examples each; the last quarter of them held out)."""
    examples = [_examples(measured, targets, dt_s) for measured, targets in records]
    return LinearMotionPredictor.fit(
        np.concatenate([windows for windows, _ in examples]),
        np.concatenate([future for _, future in examples]),
        np.concatenate([np.full(len(w), k) for k, (w, _) in enumerate(examples)]),
        HORIZONS_S,
        WINDOW_S,
        dt_s,
        block=BLOCK,
        channels=HMS_CHANNELS,
        targets=HMS_CHANNELS,
        metadata=metadata,
    )


def _examples(
    measured: np.ndarray, targets: np.ndarray, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """The examples of one HMS record: every :data:`EXAMPLE_EVERY_S`, the last
    :data:`WINDOW_S` of ``measured`` (with a valid column) and ``targets`` at
    :data:`HORIZONS_S` after its end."""
    n_window = round(WINDOW_S / dt_s)
    steps = np.round(HORIZONS_S / dt_s).astype(int)
    stride = max(1, round(EXAMPLE_EVERY_S / dt_s))
    ends = np.arange(n_window - 1, len(measured) - steps[-1], stride)
    windows = np.stack([measured[end - n_window + 1 : end + 1] for end in ends])
    windows = np.concatenate([windows, np.ones((*windows.shape[:2], 1))], axis=2)
    return windows, targets[ends[:, None] + steps[None, :]]


#: how much of the HMS's own record the online forecast is fitted on, seconds before the
#: decision (a ship's HMS records all the time: twice the window of its standard report)
ONLINE_RECORD_S = 1200.0
#: the online fit's record is cut into this many parts; the last quarter is held out
ONLINE_PARTS = 8


def fit_online_forecast(
    monitor: HelideckMonitor, t_end_s: float, record_s: float = ONLINE_RECORD_S
) -> LinearMotionPredictor:
    """The helideck forecast identified online: fitted on the HMS's own record of the
    ``record_s`` before ``t_end_s`` (its measurements as the targets too: the truth is not
    known on board), cut into :data:`ONLINE_PARTS` consecutive parts, the last quarter held
    out for the ridge and the error.  It needs no prior sea: a held-out sea is identified from
    its own past, as a real ship's would be."""
    require_range("record_s", record_s, ONLINE_PARTS * (WINDOW_S + HORIZONS_S[-1]), 1e6)
    _, measured = monitor.window(t_end_s, record_s)
    part = len(measured) // ONLINE_PARTS
    # each part keeps its own futures: no example reads past its part's end
    chunks = [measured[k * part : (k + 1) * part] for k in range(ONLINE_PARTS)]
    metadata = {"online_record_s": record_s, "t_end_s": t_end_s}
    return _fit([(chunk, chunk) for chunk in chunks], monitor.dt_s, metadata)


#: ``deck_forecast: online``: each episode identifies its forecast from its own HMS record
ONLINE = "online"
#: the online forecast is refitted once it is this old, seconds (the sea changes over minutes)
ONLINE_REFIT_S = 30.0


def deck_forecast_for(
    config: DeckLandingConfig, hms: HelideckMonitorConfig
) -> LinearMotionPredictor | None:
    """The helideck forecast of ``config`` (:func:`fit_deck_forecast` with the defaults, once
    per sea and HMS on a machine: :func:`cached_deck_forecast`): on the training family its
    ``deck_forecast`` names, else on its own sea, which must not be a held-out sea (refused,
    naming ``deck_forecast``); None for ``deck_forecast: online``, where each episode
    identifies its own (:class:`EpisodeForecast`)."""
    family = config.deck_forecast
    if family == ONLINE:
        return None
    if family:
        require_choice("deck_forecast", family, (ONLINE, *TRAINING_FAMILIES))
        motions = tuple(member_config(m).motion for m in TRAINING_FAMILIES[family])
    else:
        held_out = held_out_sea(config.motion)
        if held_out:
            raise ConfigError(
                "deck_forecast",
                f"is empty, and the sea is the held-out {held_out!r}, which nothing is fitted "
                f"on (landing_env/sea/heldout.py): use {ONLINE!r} or a training family of seas "
                f"({', '.join(TRAINING_FAMILIES)})",
            )
        motions = (config.motion,)
    key = repr((motions, hms))
    if key not in _FITTED:
        _FITTED[key] = cached_deck_forecast(motions, hms)
    return _FITTED[key]


def cached_deck_forecast(*args: Any, **kwargs: Any) -> LinearMotionPredictor:
    """:func:`fit_deck_forecast` of the same arguments, fitted once and then read from its
    file (:func:`forecast_cache_path`), equal to a fresh fit to the bit.  Processes that ask
    for the same forecast at once wait for the first one's fit; an entry that cannot be read
    is fitted again and replaced."""
    arguments = _fit_arguments(*args, **kwargs)
    path = forecast_cache_path(**arguments)
    with locked(path):
        if path.is_file():
            with contextlib.suppress(ValueError):
                return LinearMotionPredictor.load(path)
        forecast = fit_deck_forecast(**arguments)
        forecast.save(path, exact=True)
    return forecast


def forecast_cache_path(*args: Any, **kwargs: Any) -> Path:
    """The file :func:`cached_deck_forecast` keeps the forecast of these arguments (those of
    :func:`fit_deck_forecast`) in: named by a hash of every argument, the fit's constants, the
    source of :data:`FIT_CODE`, NumPy's version and the machine's architecture (what a fresh
    fit's last bits depend on)."""
    inputs: dict[str, Any] = _fit_arguments(*args, **kwargs)
    motion = inputs["motion"]
    motions = [motion] if isinstance(motion, MotionConfig) else list(motion)
    inputs["motion"] = [asdict(each) for each in motions]
    inputs["hms"] = asdict(inputs["hms"] or HelideckMonitorConfig())
    inputs.update(
        constants=[HORIZONS_S.tolist(), WINDOW_S, BLOCK, EXAMPLE_EVERY_S],
        code=_code_digest(),
        numpy=np.__version__,
        machine=platform.machine(),
    )
    text = json.dumps(inputs, sort_keys=True, default=repr)
    name = hashlib.sha256(text.encode()).hexdigest()[:24]
    return cache_dir() / CACHE_FOLDER / f"forecast_{name}.npz"


def _fit_arguments(*args: Any, **kwargs: Any) -> dict[str, Any]:
    """:func:`fit_deck_forecast`'s arguments by name, defaults included."""
    bound = _FIT_SIGNATURE.bind(*args, **kwargs)
    bound.apply_defaults()
    return dict(bound.arguments)


@cache
def _code_digest() -> str:
    """A hash of the source of :data:`FIT_CODE`."""
    digest = hashlib.sha256()
    for name in FIT_CODE:
        path = Path(str(importlib.import_module(name).__file__))
        files = sorted(path.parent.glob("*.py")) if path.name == "__init__.py" else [path]
        for file in files:
            digest.update(f"{name}/{file.name}".encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()


class EpisodeForecast:
    """The helideck forecast an episode flies with: ``fitted`` (:func:`deck_forecast_for`),
    or where that is None, the one identified online from the episode's own HMS record
    (:func:`fit_online_forecast` on the ``monitor``'s last :data:`ONLINE_RECORD_S`), refitted
    once it is :data:`ONLINE_REFIT_S` old."""

    def __init__(self, fitted: LinearMotionPredictor | None, monitor: HelideckMonitor) -> None:
        self.fitted = fitted
        self.monitor = monitor
        self._online: LinearMotionPredictor | None = None
        self._fitted_at = -math.inf

    def at(self, t_s: float) -> LinearMotionPredictor | None:
        """The forecast to make at ``t_s`` (seconds of episode time); None at a time that is
        not finite (no record ends there)."""
        if self.fitted is not None:
            return self.fitted
        if not math.isfinite(t_s):
            return None
        if self._online is None or not (0.0 <= t_s - self._fitted_at < ONLINE_REFIT_S):
            self._online = fit_online_forecast(self.monitor, t_s)
            self._fitted_at = t_s
        return self._online


@cache
def _held_out_motions() -> tuple[tuple[str, MotionConfig], ...]:
    return tuple((name, load_config(name).motion) for name in HELD_OUT_SEAS)


def held_out_sea(motion: MotionConfig) -> str:
    """The name of the held-out sea (:mod:`landing_env.sea.heldout`) ``motion`` is, or ``""``."""
    return next((name for name, held in _held_out_motions() if held == motion), "")


def forecast_rms(
    forecast: LinearMotionPredictor,
    motion: MotionConfig,
    hms: HelideckMonitorConfig | None = None,
    record_s: float = RECORD_S,
    seed: int = FIT_SEED - 1,
) -> np.ndarray:
    """The RMS error of ``forecast`` on one HMS record of the sea ``motion`` describes (seed
    ``seed``, which no fit uses), (H, 5) at its horizons: metres, and radians for roll and
    pitch.  Measuring a forecast on a sea fits nothing to it, so a held-out sea may be given."""
    hms = hms or HelideckMonitorConfig()
    source = make_motion_source(motion, np.random.default_rng([seed]))
    monitor = HelideckMonitor(source, hms, seed=seed)
    times, measured = monitor.window(0.0, record_s)
    truth = sample_poses(source, times)[:, : len(HMS_CHANNELS)]
    n_window = round(forecast.window_s / hms.dt_s)
    steps = np.round(np.asarray(forecast.horizons_s) / hms.dt_s).astype(int)
    stride = max(1, round(EXAMPLE_EVERY_S / hms.dt_s))
    errors = []
    for end in range(n_window - 1, len(times) - steps[-1], stride):
        window = measured[end - n_window + 1 : end + 1]
        poses = forecast.predict_targets(window, np.ones(len(window), dtype=bool))
        if not isinstance(poses, str):
            errors.append(poses - truth[end + steps])
    if not errors:
        raise ConfigError("record_s", f"{record_s:g} s holds no forecast window")
    return np.sqrt(np.mean(np.square(errors), axis=0))
