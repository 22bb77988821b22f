"""The timing task's ``forecast`` observation: the ship's helideck forecast and the drone's own
state.

:class:`ForecastObservation` holds the helideck forecast of the scenario's sea
(:func:`~landing_env.anticipation.hms_forecast.deck_forecast_for`, fitted once per machine) and each
episode's HMS record (:class:`~landing_env.sea.hms.HelideckMonitor`), and gives the values the
observation carries after the history's newest row
(:class:`~landing_env.timing.layout.TimingObservationLayout`): the deck's surge, sway, heave,
roll and pitch forecast 0-8 s ahead, and the drone's velocity in its heading frame and its lean.
"""

from __future__ import annotations

import math

import numpy as np

from estimation.frames import euler_zyx_from_matrix
from landing_env.anticipation.hms_forecast import FORECAST_KINDS, EpisodeForecast, deck_forecast_for
from landing_env.config import DeckLandingConfig
from landing_env.errors import ConfigError
from landing_env.sea.hms import HelideckMonitor, HelideckMonitorConfig
from landing_env.stewart.motion import MotionSource


class ForecastObservation:
    """The helideck forecast and own state of the ``forecast`` observation.

    ``config``: the task's config; a ``motion.kind`` without a sea to forecast is refused with
    a :class:`~landing_env.errors.ConfigError` naming ``timing.observation``.
    """

    def __init__(self, config: DeckLandingConfig) -> None:
        kind = config.motion.kind
        if kind not in FORECAST_KINDS:
            raise ConfigError(
                "timing.observation",
                f"'forecast' needs a sea to forecast (motion.kind one of {FORECAST_KINDS}), "
                f"not {kind!r}",
            )
        #: the helideck forecast of this scenario's sea, fitted once per machine (None:
        #: each episode identifies its own, ``deck_forecast: online``)
        self.deck_forecast = deck_forecast_for(config, HelideckMonitorConfig())
        #: this episode's HMS record and forecast (None before the first reset)
        self._monitor: HelideckMonitor | None = None
        self._forecast: EpisodeForecast | None = None

    def reset(self, motion: MotionSource, seed: int) -> None:
        """Start the ship's HMS record of an episode of the deck ``motion``, its errors drawn
        from ``seed``."""
        self._monitor = HelideckMonitor(motion, HelideckMonitorConfig(), seed)
        self._forecast = EpisodeForecast(self.deck_forecast, self._monitor)

    def values(
        self, t_s: float, velocity_w: np.ndarray, rotation_wb: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray]:
        """The helideck forecast made at ``t_s`` (None: none could be made) and the drone's
        own state (its world velocity ``velocity_w`` turned into its heading frame, its roll
        and pitch from ``rotation_wb``)."""
        roll, pitch, yaw = euler_zyx_from_matrix(rotation_wb)
        c, s = math.cos(yaw), math.sin(yaw)
        v = np.asarray(velocity_w, dtype=float)
        own = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2], roll, pitch])
        if self._monitor is None or self._forecast is None:
            return None, own
        forecast = self._forecast.at(t_s)
        if forecast is None:
            return None, own
        _, measured = self._monitor.window(t_s, forecast.window_s)
        poses = forecast.predict_targets(measured, np.ones(len(measured), dtype=bool))
        if isinstance(poses, str) or not np.all(np.isfinite(poses)):
            return None, own
        poses = np.array(poses, dtype=float)
        poses[:, :3] -= poses[0, :3]
        return poses, own
