"""The helideck forecast's error, and how honest its claimed error is, on tuned and held-out seas.

    nice -n 19 python -m benchmarks.bench_deck_forecast \\
        [--scenario ship-ss6 --scenario ship-unseen-5] [--forecast ship-broad --forecast online] \\
        [--horizon 1 --horizon 3] [--record-s 600]

``predictive`` at sea (:class:`agents.policies.timing.HelideckPredictivePolicy`) weighs the
chance that the deck's tilt at the contact, 2.7-4.5 s after a commit, is within the limit,
from the helideck forecast's prediction and its *claimed* error: the covariance of its
residuals on the examples its fit held out.  For each scenario and forecast this prints, at
each horizon, the RMS error of heave (m), roll and pitch (deg) on one HMS record of the
scenario's sea that no fit read (:func:`~landing_env.anticipation.hms_forecast.forecast_rms`,
seed ``FIT_SEED - 1``), the claimed RMS, and their ratio (1: honest; above 1: the forecast
claims to know more than it does).

* ``ship-broad``: fitted on the training family of seas
  (:mod:`landing_env.sea.training_seas`), none of them held out;
* ``online``: identified from the ship's own HMS record of the 20 min before the measured
  record (:func:`~landing_env.anticipation.hms_forecast.fit_online_forecast`), as an episode
  of ``deck_forecast: online`` does; its claimed error is that of its own held-out parts.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import numpy as np

from estimation.anticipation.linear_predictors import LinearMotionPredictor
from landing_env.anticipation.hms_forecast import (
    FIT_SEED,
    ONLINE,
    deck_forecast_for,
    fit_online_forecast,
    forecast_rms,
)
from landing_env.config import load_config
from landing_env.errors import require_choice, require_range
from landing_env.scenarios import SCENARIOS
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.sea.training_seas import TRAINING_FAMILIES
from landing_env.stewart.motion import make_motion_source

DEFAULT_SCENARIOS = ("ship-ss4", "ship-ss5", "ship-ss6", "ship-unseen-4", "ship-unseen-5")
FORECASTS = (*(name for name in TRAINING_FAMILIES if name.startswith("ship")), ONLINE)
#: the values reported: heave (the helideck's z, m), roll and pitch (deg)
VALUES = ("z", "roll", "pitch")
_COLUMNS = [HMS_CHANNELS.index(name) for name in VALUES]
_SCALE = np.array([1.0, np.degrees(1.0), np.degrees(1.0)])


def measure(
    scenario: str, forecast_name: str, horizons_s: Sequence[float], record_s: float
) -> dict[str, Any]:
    """The forecast's measured and claimed RMS (heave m, roll and pitch deg) at
    ``horizons_s`` on one unseen HMS record of ``scenario``'s sea."""
    require_choice("scenario", scenario, tuple(n for n in SCENARIOS if n.startswith("ship")))
    require_choice("forecast", forecast_name, FORECASTS)
    motion = load_config(SCENARIOS[scenario].config).motion
    hms = HelideckMonitorConfig()
    seed = FIT_SEED - 1
    forecast: LinearMotionPredictor | None
    if forecast_name == ONLINE:
        # the same record forecast_rms measures on ends at 0: fit on the 20 min before it
        source = make_motion_source(motion, np.random.default_rng([seed]))
        forecast = fit_online_forecast(HelideckMonitor(source, hms, seed=seed), -record_s)
    else:
        config = load_config(SCENARIOS[scenario].config, overrides={"deck_forecast": forecast_name})
        forecast = deck_forecast_for(config, hms)
    if forecast is None:
        raise ValueError(f"no fitted forecast for {scenario} ({forecast_name})")
    measured = forecast_rms(forecast, motion, hms, record_s=record_s, seed=seed)
    claimed = np.sqrt(np.einsum("hii->hi", forecast.covariance))
    rows = []
    for horizon_s in horizons_s:
        k = int(np.argmin(np.abs(forecast.horizons_s - horizon_s)))
        m = measured[k, _COLUMNS] * _SCALE
        c = claimed[k, _COLUMNS] * _SCALE
        rows.append((float(forecast.horizons_s[k]), m, c))
    return {"scenario": scenario, "forecast": forecast_name, "rows": rows}


def table(results: list[dict[str, Any]]) -> str:
    """A Markdown table: each cell ``measured / claimed (ratio)``."""
    lines = [
        "| scenario | forecast | horizon (s) | heave (m) | roll (deg) | pitch (deg) |",
        "|---|---|---|---|---|---|",
    ]
    for result in results:
        for horizon_s, m, c in result["rows"]:
            cells = [
                f"{mv:.2f} / {cv:.2f} ({mv / cv:.2f})" if cv > 0 else f"{mv:.2f} / -"
                for mv, cv in zip(m, c, strict=True)
            ]
            lines.append(
                f"| `{result['scenario']}` | {result['forecast']} | {horizon_s:g} | "
                + " | ".join(cells)
                + " |"
            )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.bench_deck_forecast", description=__doc__
    )
    parser.add_argument("--scenario", action="append", help="a ship scenario (repeatable)")
    parser.add_argument("--forecast", action="append", choices=FORECASTS)
    parser.add_argument("--horizon", action="append", type=float, help="seconds ahead")
    parser.add_argument("--record-s", type=float, default=600.0)
    args = parser.parse_args(argv)
    require_range("--record-s", args.record_s, 200.0, 1e5)
    horizons = args.horizon or [1.0, 2.0, 3.0, 4.0]
    for horizon in horizons:
        require_range("--horizon", horizon, 0.0, 8.0)
    results = [
        measure(scenario, name, horizons, args.record_s)
        for scenario in (args.scenario or DEFAULT_SCENARIOS)
        for name in (args.forecast or FORECASTS)
    ]
    print(
        "measured RMS / claimed RMS (measured / claimed) on an HMS record no fit read, "
        f"{args.record_s:g} s"
    )
    print(table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
