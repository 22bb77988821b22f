"""The helideck forecast identified online from the HMS's own record, against the forecasts
fitted offline: on the tuned seas and on the held-out ones.

For each scenario and seed, the sea of an episode is drawn as the evaluation does, and each
forecast is measured on the episode's first ``--eval-s`` seconds (the wait and the landing):

* ``online``: fitted on the same HMS's record of the 20 min before the reset
  (:func:`landing_env.sea.hms_forecast.fit_online_forecast`);
* ``family``: fitted on the ``ship-broad`` training family (other seas);
* ``own sea``: fitted on other realisations of the scenario's own sea (the tuned scenarios'
  default; not computed on a held-out sea, which nothing is fitted on).

If the online fit were locking onto the simulated sea's finitely many wave components (200
per sea), it would beat the own-sea fit, which sees the same spectrum in other realisations;
it must not.  Prints the RMS error of heave (m) and roll and pitch (deg) at 1, 2 and 4 s.

    python benchmarks/bench_online_deck_forecast.py --scenario ship-ss5 ship-unseen-5 --seeds 4
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from landing_env.config import load_config
from landing_env.scenarios import SCENARIOS
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.sea.hms_forecast import (
    fit_deck_forecast,
    fit_online_forecast,
    held_out_sea,
)
from landing_env.sea.training_seas import TRAINING_FAMILIES, member_config
from landing_env.stewart.motion import make_motion_source, sample_poses

HORIZONS = (1.0, 2.0, 4.0)


def errors(forecast, monitor, source, eval_s: float) -> np.ndarray:
    """Squared errors (examples, horizons, 5) of ``forecast`` over (0, eval_s]."""
    dt = monitor.dt_s
    n_window = round(forecast.window_s / dt)
    steps = np.round(np.asarray(forecast.horizons_s) / dt).astype(int)
    times = np.arange(-n_window + 1, round(eval_s / dt) + steps[-1] + 1) * dt
    _, measured = monitor.window(float(times[-1]), len(times) * dt)
    truth = sample_poses(source, times)[:, : len(HMS_CHANNELS)]
    out = []
    for end in range(n_window - 1, len(times) - steps[-1], round(0.5 / dt)):
        poses = forecast.predict_targets(
            measured[end - n_window + 1 : end + 1], np.ones(n_window, bool)
        )
        if not isinstance(poses, str):
            out.append((poses - truth[end + steps]) ** 2)
    return np.asarray(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", nargs="+", default=["ship-ss5", "ship-unseen-5"])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--first-seed", type=int, default=5_000_000)
    parser.add_argument("--eval-s", type=float, default=120.0)
    args = parser.parse_args()
    hms = HelideckMonitorConfig()
    family = fit_deck_forecast(
        [member_config(m).motion for m in TRAINING_FAMILIES["ship-broad"]], hms
    )
    report = {}
    for scenario in args.scenario:
        motion = load_config(SCENARIOS[scenario].config).motion
        own = None if held_out_sea(motion) else fit_deck_forecast(motion, hms)
        squared: dict[str, list[np.ndarray]] = {"online": [], "family": [], "own sea": []}
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            source = make_motion_source(motion, np.random.default_rng([seed]))
            monitor = HelideckMonitor(source, hms, seed=seed)
            online = fit_online_forecast(monitor, 0.0)
            for name, forecast in (("online", online), ("family", family), ("own sea", own)):
                if forecast is not None:
                    squared[name].append(errors(forecast, monitor, source, args.eval_s))
        horizons = list(family.horizons_s)
        columns = [horizons.index(h) for h in HORIZONS]
        report[scenario] = {}
        print(f"{scenario}: RMS error at {HORIZONS} s: heave (m) | roll (deg) | pitch (deg)")
        for name, parts in squared.items():
            if not parts:
                continue
            rms = np.sqrt(np.mean(np.concatenate(parts), axis=0))[columns]
            rms[:, 3:] = np.degrees(rms[:, 3:])
            row = {"heave_m": rms[:, 2], "roll_deg": rms[:, 3], "pitch_deg": rms[:, 4]}
            report[scenario][name] = {k: [round(float(x), 3) for x in v] for k, v in row.items()}
            print(
                f"  {name:8s} " + " | ".join(" ".join(f"{x:5.2f}" for x in v) for v in row.values())
            )
    print(json.dumps(report))


if __name__ == "__main__":
    main()
