"""The onboard look-ahead: commits tried in futures of the ship's deck that the drone's own
model draws, the planner behind ``timing-dqn-lookahead`` (:mod:`agents.policies.lookahead`).

The deck oracle (:class:`agents.policies.oracle.DeckOracleTimingPolicy`) shows what knowing the
deck's future is worth.  A drone landing on a ship can know much of that future: the ship's
helideck monitoring system (:mod:`landing_env.sea.hms`, required on moving helidecks by
CAP 437) measures the helideck's motion and passes it on, and ship motion a few seconds ahead
is predictable from its recent past (the classical ship-motion prediction of
:mod:`estimation.anticipation.linear_predictors`).  :class:`DeckForecastTimingPolicy` is the
deck oracle with the deck's true future replaced by that forecast, played as a model the
drone carries:

* **The forecast** (:mod:`landing_env.anticipation.hms_forecast`).  A direct multi-horizon
  linear predictor (:class:`~estimation.anticipation.linear_predictors.LinearMotionPredictor`)
  maps the HMS's last ``WINDOW_S`` of surge, sway, heave, roll and pitch at the helideck to the
  same five every 0.5 s up to ``HORIZONS_S``'s 8 s.  By default it is fitted on ``REALIZATIONS``
  HMS records of the scenario's own sea drawn with other seeds (other days in the same sea
  state); the config's ``deck_forecast: online`` identifies it in each episode from the HMS's
  own record of the last 20 min instead, as the held-out seas do.
* **The look-ahead.**  At a check it tries a commit now in ``draws`` futures (the gusts and
  the sensors' noise drawn anew, as the deck oracle does) in which the deck follows the
  forecast (:class:`~landing_env.stewart.motion.ForecastMotion`); a draw lands with
  ``min_margin`` of slack on every graded criterion (the forecast's error eats into the
  margin the deck oracle can spend to the last bit).
* **What the drone knows of the present** (:class:`OnboardModelConfig`).  Where it is over the
  deck: its deck-pose estimate (the observed estimator's), not the truth; each look-ahead moves
  the drone so that the deck is where the estimate puts it plus a draw of the estimate's
  error, and with no valid estimate it waits.  The present gust: the drone's wind estimate
  (the truth plus an error drawn once per decision), and in each look-ahead a draw around it.
  Its own airframe: each look-ahead scales the linear drag and the rotors' thrust by draws
  within :class:`OnboardModelConfig`'s fractions.

The guidance, the controller, the touchdown's physics and the estimators' software are the
drone's own code and stay exact (the look-ahead flies a saved copy of the simulation,
:mod:`landing_env.envs.snapshot`); so do its own attitude and velocity (its navigation).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from agents.policies.oracle import DeckOracleTimingPolicy
from estimation.anticipation.linear_predictors import LinearMotionPredictor
from estimation.limits import Limit, limited, require_limits
from landing_env.anticipation.hms_forecast import EpisodeForecast, deck_forecast_for
from landing_env.errors import ConfigError, require_range
from landing_env.sea.hms import HMS_CHANNELS, HelideckMonitor, HelideckMonitorConfig
from landing_env.stewart.motion import ForecastMotion

#: the HMS errors' stream of an episode (apart from the look-ahead's draws)
_HMS_STREAM = 0x4D5

#: the onboard model's streams: the wind estimate of a decision, and each look-ahead's draws
_WIND_ESTIMATE_STREAM = 0x57E
_MODEL_STREAM = 0x30D


@dataclass(frozen=True)
class OnboardModelConfig:
    """What the onboard look-ahead does not know of the present, 1 sigma.

    * ``gust_error_mps`` (x, y, z in the world frame): the error of the drone's estimate of
      the present wind.  Yu et al. (2025, *Design and implementation of a high-precision
      wind-estimation UAV with onboard sensors*, arXiv:2512.10428) estimate it from the
      airframe's dynamics (a disturbance observer) to 0.22 m/s RMS in outdoor hover, under
      0.38 m/s in dynamic flight and under 0.17 m/s vertically, with a purpose-built
      airframe; 0.4 m/s per horizontal axis and 0.2 m/s vertically take a drone that was
      not built to measure wind.
    * ``drag_error_fraction``: each look-ahead scales the linear drag by a uniform draw in
      1 +- this (the identified drag of a quadrotor is known to a few tens of percent; an
      assumption, not a measured figure).
    * ``thrust_error_fraction``: each look-ahead scales the rotors' thrust coefficient by a
      uniform draw in 1 +- this: thrust goes with the air's density, and a 30 degC day at
      sea is 5 % thinner than the ISA's 15 degC (ideal gas law) that the model assumes.
    * ``position_from_estimate``: start from the deck-pose estimate (False: the true
      relative position), moved by a draw of its error,
      ``position_error_m`` (camera axes x, y, z).  The defaults round up `tight`'s measured
      RMS error at the 2 m hold of ``ship-ss5`` with realistic sensing, 2.5, 2.5 and
      10.4 mm (``git show 4d17a9e:benchmarks/bench_onboard_estimate_error.py``); its own
      covariance reports 0.1-0.4 mm there, some 25 times too confident to draw from.
    * ``airframe_in_trim``: each drawn airframe starts in its own trim, as a drone that has
      held its position for a while does: the aerodynamic force it holds is the one it
      feels (its lean and thrust say so), so a drawn drag comes with the airspeed that gives
      that force (the wind a disturbance observer infers moves with its drag model), and
      the controller's thrust model is the drawn thrust (a hover-thrust estimator: PX4's
      ``MPC_USE_HTE``, ArduPilot's ``MOT_THST_HOVER`` learning).  What stays unknown is how
      the drag answers a change of airspeed, and the thrust's ceiling.
      False (the default, the shipped look-ahead's): a drawn airframe starts with the
      nominal one's trim and finds its own during the descent.
    """

    gust_error_mps: tuple[float, float, float] = (0.4, 0.4, 0.2)
    drag_error_fraction: float = limited(0.2, Limit(0.0, 0.9))
    position_from_estimate: bool = True
    position_error_m: tuple[float, float, float] = (0.003, 0.003, 0.010)
    thrust_error_fraction: float = limited(0.05, Limit(0.0, 0.5))
    airframe_in_trim: bool = False

    def __post_init__(self) -> None:
        for key, high, axes in (
            ("gust_error_mps", 10.0, "m/s, world x, y, z"),
            ("position_error_m", 1.0, "m, camera x, y, z"),
        ):
            values = tuple(float(v) for v in getattr(self, key))
            if len(values) != 3:
                raise ConfigError(key, f"needs 3 values ({axes})")
            for value in values:
                require_range(key, value, 0.0, high)
            object.__setattr__(self, key, values)
        require_limits(self)
        for key in ("position_from_estimate", "airframe_in_trim"):
            value = getattr(self, key)
            if not isinstance(value, bool):
                raise ConfigError(key, f"must be true or false, got {value!r}")

    def signature(self) -> dict[str, Any]:
        """The model's fields for a card (``airframe_in_trim`` only where set: a card made
        before it existed signs as before)."""
        fields = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        if not self.airframe_in_trim:
            del fields["airframe_in_trim"]
        return fields


def episode_monitor(
    env: Any, seed: int = 0, hms: HelideckMonitorConfig | None = None
) -> HelideckMonitor:
    """The HMS of the episode ``env`` (the unwrapped timing task, reset) was reset to: the ship's
    deck motion, its errors seeded by the episode's seed and ``seed`` (a policy's own)."""
    episode_seed = int(env.np_random_seed) % 2**32
    sequence = np.random.SeedSequence([seed, episode_seed, _HMS_STREAM])
    hms_seed = int(sequence.generate_state(1)[0])
    return HelideckMonitor(env.world.stewart.motion, hms or HelideckMonitorConfig(), hms_seed)


class DeckForecastTimingPolicy(DeckOracleTimingPolicy):
    """Commit when a commit now lands in every look-ahead of the drone's onboard model, whose
    deck follows the HMS forecast (the look-ahead :mod:`agents.policies.lookahead` observes).

    ``last_forecast`` holds the latest forecast: (H, 5) poses at the forecast's horizons
    (:data:`~landing_env.anticipation.hms_forecast.HORIZONS_S`), or the reason there was
    none.  ``rule`` are the commit rule's settings, as the deck oracle's (``draws``,
    ``min_chance``, ``check_every_s``, ``seed``); its ``min_margin`` is 0.15 here.
    """

    name = "onboard-look-ahead"

    def __init__(
        self,
        env: Any,
        hms: HelideckMonitorConfig | None = None,
        forecast: LinearMotionPredictor | None = None,
        onboard: OnboardModelConfig | None = None,
        *,
        min_margin: float = 0.15,
        **rule: Any,
    ) -> None:
        super().__init__(env, min_margin=min_margin, **rule)
        self.onboard = onboard or OnboardModelConfig()
        #: this decision's (estimate - truth) of the deck's position in C, the factor of the
        #: estimate's error, and the drone's wind estimate (world, m/s)
        self._belief: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.hms = hms or HelideckMonitorConfig()
        #: the fitted forecast; None: each episode identifies its own online (``deck_forecast:
        #: online``, :class:`~landing_env.anticipation.hms_forecast.EpisodeForecast`)
        self.forecast = forecast or deck_forecast_for(self.env.config, self.hms)
        if self.forecast is not None and (
            tuple(self.forecast.channels) != HMS_CHANNELS
            or tuple(self.forecast.targets) != HMS_CHANNELS
        ):
            raise ValueError(f"the forecast must read and predict {HMS_CHANNELS}")
        if self.forecast is not None and abs(self.forecast.dt_s - self.hms.dt_s) > 1e-9:
            raise ValueError(
                f"the forecast reads {1 / self.forecast.dt_s:g} Hz; the HMS gives "
                f"{self.hms.rate_hz:g} Hz"
            )
        self._episode_forecast: EpisodeForecast | None = None
        self._monitor: HelideckMonitor | None = None
        self.last_forecast: np.ndarray | str = "no forecast yet"

    def reset(self) -> None:
        super().reset()
        self._monitor = None
        self._episode_forecast = None
        self.last_forecast = "no forecast yet"

    def monitor(self) -> HelideckMonitor:
        """The HMS of this episode's ship (its errors seeded by the episode and ``seed``)."""
        if self._monitor is None:
            self._monitor = episode_monitor(self.env, self.seed, self.hms)
        return self._monitor

    def deck_future(self, decision: int = 0) -> Any:
        world = self.env.world
        t0 = float(world.time)
        belief = self._onboard_belief(decision)
        self._belief = None
        if isinstance(belief, str):
            self.last_forecast = belief
            return None
        self._belief = belief
        if self._episode_forecast is None:
            self._episode_forecast = EpisodeForecast(self.forecast, self.monitor())
        forecast = self._episode_forecast.at(t0)
        if forecast is None:
            self.last_forecast = "the time is not finite"
            return None
        _, measured = self.monitor().window(t0, forecast.window_s)
        poses = forecast.predict_targets(measured, np.ones(len(measured), dtype=bool))
        self.last_forecast = poses
        if isinstance(poses, str):
            return None
        truth = world.stewart.motion
        full = np.zeros((len(forecast.horizons_s), 6))
        full[:, : len(HMS_CHANNELS)] = poses
        full[:, 5] = float(np.asarray(truth.pose(t0))[5])  # the heading: held
        if not np.all(np.isfinite(full)) or not math.isfinite(t0):
            return None
        return ForecastMotion(truth, t0, forecast.horizons_s, full)

    def _onboard_belief(self, decision: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | str:
        """What the drone believes of the present at ``decision``: the deck's position in C as
        estimated less the truth, the factor of that estimate's error (1 sigma), and its wind
        estimate; or why it cannot say."""
        env = self.env
        sensing = getattr(env, "_sensing", None)
        if sensing is None:
            return "no sensing yet"
        estimate = sensing.estimates.get(env.config.estimation.observed)
        if estimate is None or not estimate.valid:
            return "no valid deck-pose estimate: the drone does not know where the deck is"
        t_est = np.asarray(estimate.translation, dtype=float)
        if t_est.shape != (3,) or not np.all(np.isfinite(t_est)):
            return "the deck-pose estimate is not finite"
        factor = np.diag(self.onboard.position_error_m)
        _, t_true = env.world.true_deck_pose_c()
        episode_seed = int(env.np_random_seed) % 2**32
        sequence = np.random.SeedSequence(
            [self.seed, episode_seed, decision, _WIND_ESTIMATE_STREAM]
        )
        error = np.random.default_rng(sequence).normal(0.0, self.onboard.gust_error_mps)
        wind_estimate = env.world.wind.gust_w + error
        return t_est - np.asarray(t_true, dtype=float), factor, wind_estimate

    def drawn_unknowns(
        self, decision: int, draw: int
    ) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Draw ``draw`` of ``decision``'s unknowns of the present (after :meth:`deck_future`
        made this decision's belief): the drone's shift from where it is (m, world: the deck,
        seen from the camera, where the estimate puts it less a draw of the estimate's error;
        zero without ``position_from_estimate``), the present gust (world, m/s) and the drag
        and thrust scales."""
        assert self._belief is not None
        env = self.env
        offset_c, factor, wind_estimate = self._belief
        episode_seed = int(env.np_random_seed) % 2**32
        rng = np.random.default_rng(
            np.random.SeedSequence([self.seed, episode_seed, decision, draw, _MODEL_STREAM])
        )
        normals = rng.standard_normal(7)  # position 3, gust 3, one spare (kept: the streams)
        drag_scale, thrust_scale = 1.0 + (2.0 * rng.random(2) - 1.0) * (
            self.onboard.drag_error_fraction,
            self.onboard.thrust_error_fraction,
        )
        shift_w = np.zeros(3)
        if self.onboard.position_from_estimate:
            _, rotation_wc = env.world.camera_pose_w()
            shift_w = -(rotation_wc @ (offset_c - factor @ normals[:3]))
        gust = wind_estimate + np.asarray(self.onboard.gust_error_mps) * normals[3:6]
        return shift_w, gust, float(drag_scale), float(thrust_scale)

    def model_draw(self, decision: int, draw: int) -> None:
        """Make the restored copy the drone's model of the present:
        the drone where its estimate (and a draw of its error) puts it over the deck, the
        present gust drawn around its wind estimate, the drag and the thrust scaled by
        draws (the plant; the controller keeps its nominal model)."""
        if self._belief is None:
            return
        env = self.env
        world = env.world
        shift_w, gust, drag_scale, thrust_scale = self.drawn_unknowns(decision, draw)
        if self.onboard.position_from_estimate:
            world.shift_drone(shift_w)
        world.wind.set_present_gust_w(gust)
        params = world.drone.params
        world.drone.params = dataclasses.replace(
            params,
            linear_drag_b=np.asarray(params.linear_drag_b, dtype=float) * drag_scale,
            k_f=float(params.k_f) * thrust_scale,
        )
        if self.onboard.airframe_in_trim:
            # the force the drone holds is what it feels: with drag_scale times the drag, the
            # air goes past it 1/drag_scale as fast (the wind it infers from that force, as a
            # disturbance observer does, moves with the drag model); the thrust model is
            # the drawn rotors'
            air_w = world.drone_state().velocity_w - np.asarray(world.drone.last_wind_w)
            world.shift_wind_at_drone(air_w * (1.0 - 1.0 / drag_scale))
            world.controller.scale_thrust_model(float(thrust_scale))
            world.drone.set_rotor_speeds(world.drone.rotor_speeds / math.sqrt(thrust_scale))
