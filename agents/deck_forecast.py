"""``deck-forecast``: timing by a forecast of the ship's helideck, tried in a look-ahead.

The deck oracle (:class:`agents.oracle.DeckOracleTimingPolicy`) shows what knowing the deck's
future is worth: at sea state 5 it lands 90 % where the best rule on the drone's own deck
estimate lands 78.5 %.  A drone landing on a ship can know much of that future: the ship's
helideck monitoring system (:mod:`landing_env.sea.hms`, required on moving helidecks by
CAP 437) measures the helideck's motion and passes it on, and ship motion a few seconds ahead
is predictable from its recent past (the classical ship-motion prediction of
:mod:`estimation.deck_prediction`).  This policy is the deck oracle with the deck's true
future replaced by that forecast:

* **The forecast.** A direct multi-horizon linear predictor
  (:class:`~estimation.deck_prediction.LinearMotionPredictor`) maps the HMS's last
  :data:`WINDOW_S` of surge, sway, heave, roll and pitch at the helideck to the same five
  every 0.5 s up to :data:`HORIZONS_S`'s 8 s.  It is fitted, when the policy is built, on
  :data:`REALIZATIONS` HMS records of the scenario's own sea drawn with other seeds (other
  days in the same sea state: a record of the episode's own sea would let a linear model lock
  onto the simulated sea's finitely many wave frequencies, which no real sea has).
* **The look-ahead.** Every ``check_every_s`` of the wait it tries a commit now in ``draws``
  futures (the gusts and the sensors' noise drawn anew, as the deck oracle does) in which the
  deck follows the forecast (:class:`~landing_env.stewart.motion.ForecastMotion`), and commits
  when all of them land with ``min_margin`` of slack on every graded criterion (the
  forecast's error eats into the margin the deck oracle can spend to the last bit).

What it still shares with the oracles: the look-ahead flies a saved copy of the simulation
(:mod:`landing_env.envs.snapshot`), so the drone's side of the prediction (its own state, the
guidance, the touchdown's physics) is a perfect model.  A drone would carry a model of its own
closed loop instead; what this policy measures is how much of the deck oracle's lead a
realistic deck forecast keeps.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from agents.oracle import DeckOracleTimingPolicy
from estimation.deck_prediction import LinearMotionPredictor
from landing_env.errors import ConfigError, require_range
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.stewart.motion import (
    ForecastMotion,
    MotionConfig,
    make_motion_source,
    sample_poses,
)

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

#: the HMS errors' stream of an episode (apart from the look-ahead's draws)
_HMS_STREAM = 0x4D5

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


class DeckForecastTimingPolicy(DeckOracleTimingPolicy):
    """Commit when a commit now lands in every look-ahead whose deck follows the HMS forecast.

    ``last_forecast`` holds the latest forecast: (H, 5) poses at :data:`HORIZONS_S`, or the
    reason there was none.
    """

    name = "deck-forecast"

    def __init__(
        self,
        env: Any,
        draws: int = 16,
        min_chance: float = 1.0,
        check_every_s: float = 0.2,
        seed: int = 0,
        min_margin: float = 0.15,
        hms: HelideckMonitorConfig | None = None,
        forecast: LinearMotionPredictor | None = None,
    ) -> None:
        super().__init__(env, draws, min_chance, check_every_s, seed, min_margin)
        self.hms = hms or HelideckMonitorConfig()
        self.forecast = forecast or deck_forecast_for(self.env.config.motion, self.hms)
        if (
            tuple(self.forecast.channels) != HMS_CHANNELS
            or tuple(self.forecast.targets) != HMS_CHANNELS
        ):
            raise ValueError(f"the forecast must read and predict {HMS_CHANNELS}")
        if abs(self.forecast.dt_s - self.hms.dt_s) > 1e-9:
            raise ValueError(
                f"the forecast reads {1 / self.forecast.dt_s:g} Hz; the HMS gives "
                f"{self.hms.rate_hz:g} Hz"
            )
        self._monitor: HelideckMonitor | None = None
        self.last_forecast: np.ndarray | str = "no forecast yet"

    def reset(self) -> None:
        super().reset()
        self._monitor = None
        self.last_forecast = "no forecast yet"

    def monitor(self) -> HelideckMonitor:
        """The HMS of this episode's ship (its errors seeded by the episode and ``seed``)."""
        if self._monitor is None:
            episode_seed = int(self.env.np_random_seed) % 2**32
            sequence = np.random.SeedSequence([self.seed, episode_seed, _HMS_STREAM])
            hms_seed = int(sequence.generate_state(1)[0])
            self._monitor = HelideckMonitor(self.env.world.stewart.motion, self.hms, hms_seed)
        return self._monitor

    def deck_future(self) -> Any:
        world = self.env.world
        t0 = float(world.time)
        _, measured = self.monitor().window(t0, self.forecast.window_s)
        poses = self.forecast.predict_targets(measured, np.ones(len(measured), dtype=bool))
        self.last_forecast = poses
        if isinstance(poses, str):
            return None
        truth = world.stewart.motion
        full = np.zeros((len(self.forecast.horizons_s), 6))
        full[:, : len(HMS_CHANNELS)] = poses
        full[:, 5] = float(np.asarray(truth.pose(t0))[5])  # the heading: held
        if not np.all(np.isfinite(full)) or not math.isfinite(t0):
            return None
        return ForecastMotion(truth, t0, self.forecast.horizons_s, full)


def plot_forecasts(
    forecast: LinearMotionPredictor,
    source: Any,
    scenario: str,
    path: str,
    starts_s: tuple[float, ...] = (40.0, 57.0, 74.0, 91.0),
) -> str:
    """Heave, roll and pitch of a sea the forecast never saw: the truth, the HMS record, and
    the forecast made at each of ``starts_s`` with its held-out 1-sigma band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monitor = HelideckMonitor(source, HelideckMonitorConfig(), seed=FIT_SEED - 1)
    span = np.arange(starts_s[0] - 12.0, starts_s[-1] + HORIZONS_S[-1], 0.05)
    truth = sample_poses(source, span)
    times, measured = monitor.window(span[-1], span[-1] - span[0])
    sigma = np.sqrt(np.diagonal(forecast.covariance, axis1=1, axis2=2))
    figure, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    for axis, (channel, label, scale) in zip(
        axes,
        (
            (2, "heave (m)", 1.0),
            (3, "roll (deg)", math.degrees(1.0)),
            (4, "pitch (deg)", math.degrees(1.0)),
        ),
        strict=True,
    ):
        axis.plot(span, scale * truth[:, channel], color="k", lw=1.2, label="truth")
        axis.plot(times, scale * measured[:, channel], ".", color="0.6", ms=2, label="HMS (10 Hz)")
        for k, t0 in enumerate(starts_s):
            _, window = monitor.window(t0, forecast.window_s)
            predicted = forecast.predict_targets(window, np.ones(len(window), dtype=bool))
            if isinstance(predicted, str):
                continue
            ahead = t0 + forecast.horizons_s
            mean = scale * predicted[:, channel]
            band = scale * sigma[:, channel]
            axis.plot(ahead, mean, color="C0", lw=1.5, label="forecast" if k == 0 else None)
            axis.fill_between(ahead, mean - band, mean + band, color="C0", alpha=0.2, lw=0)
            axis.axvline(t0, color="C0", lw=0.5, ls=":")
        axis.set_ylabel(label)
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    axes[-1].set_xlabel("time (s)")
    figure.suptitle(
        f"{scenario}: the helideck forecast from the ship's HMS, 8 s ahead (band: held-out 1 sigma)"
    )
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.deck_forecast --scenario ship-ss5``: fit the scenario's forecast and
    print its held-out error per horizon, against holding the present (persistence)."""
    import argparse

    from agents.evaluation.landing import SCENARIOS
    from landing_env.config import load_config

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--scenario", nargs="+", default=["ship-ss5"], choices=sorted(SCENARIOS))
    parser.add_argument(
        "--plot", metavar="PNG", help="also plot forecasts against the truth (first scenario)"
    )
    args = parser.parse_args(argv)
    for index, scenario in enumerate(args.scenario):
        motion = load_config(SCENARIOS[scenario].config).motion
        forecast = fit_deck_forecast(motion)
        source = make_motion_source(motion, np.random.default_rng([FIT_SEED - 1]))
        if args.plot and index == 0:
            print(f"wrote {plot_forecasts(forecast, source, scenario, args.plot)}")
        times = np.arange(0.0, RECORD_S, 0.1)
        poses = sample_poses(source, times)[:, : len(HMS_CHANNELS)]
        print(f"{scenario}: held-out RMS error (x, y, z m; roll, pitch deg), persistence after")
        for k, horizon in enumerate(forecast.horizons_s):
            lag = round(horizon / 0.1)
            hold = np.sqrt(np.mean((poses[lag:] - poses[: len(poses) - lag]) ** 2, axis=0))
            hold[3:] = np.degrees(hold[3:])
            rms = forecast.metadata["heldout_rms"][k]
            print(
                f"  {horizon:4.1f} s  "
                + "  ".join(f"{v:6.3f}" for v in rms)
                + "   | "
                + "  ".join(f"{v:6.3f}" for v in hold)
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
