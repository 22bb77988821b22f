"""Domain randomisation for the timing task: a new scenario, sensing and wind every episode.

:class:`RandomisedTimingEnv` is a ``DeckLandingTiming`` environment whose every ``reset`` draws
a :class:`Variant` from :class:`RandomiseSettings`:

* a **scenario** by name from the evaluation's registry (``agents.evaluation.landing.SCENARIOS``:
  the bench sea states today; the ship scenarios join it by name when they are added);
* a **sensing profile** by name from :data:`SENSING_PROFILES`, the presets of
  ``configs/sensors/`` as dotted overrides (``ideal``, ``tof-vl53l1x``, ``realistic``,
  ``realistic-2x``);
* a **wind** (mean speed uniform in ``wind_speed_mps``, direction uniform) and a **start
  height** of the camera above the deck (uniform in ``start_height_m``; the guidance brings it
  to the hold height during the warm-up).

Scenario and sensing change the world, so each (scenario, sensing) pair has its own inner
environment, built on first use and kept (a handful per process); wind and start height are
drawn per episode on the same world (the wind model is rebuilt at every reset from the
config).  Every inner environment has the same timing settings, so the observation space is
one.  Draws come from the environment's own seeded generator: a seeded reset gives the same
variant, and vector workers with distinct seeds draw distinct sequences.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from agents.common.cards import sensing_profile
from estimation.registry import ESTIMATOR_NAMES
from landing_env.config import load_config, sensing_profiles
from landing_env.config_loading import build_dataclass, nested_to_dotted
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.scenarios import SCENARIOS, TIMING_TASK, landing_overrides
from landing_env.timing_config import CAMERA_BELOW_COM_M

#: sensing profile name -> the dotted overrides that make it: the presets of
#: ``configs/sensors/`` (:func:`landing_env.config.sensing_profiles`)
SENSING_PROFILES: dict[str, dict[str, Any]] = sensing_profiles()


def register_sensing_profile(name: str, overrides: dict[str, Any]) -> None:
    """Add a sensing profile by name for this process (a shipped one is a file in
    ``configs/sensors/``)."""
    if not name or not isinstance(overrides, dict):
        raise ConfigError("sensing", "a profile needs a name and a dict of dotted overrides")
    SENSING_PROFILES[name] = dict(overrides)


def make_timing_env(
    scenario: str,
    sensing: str,
    estimator: str = "tight",
    overrides: dict[str, Any] | None = None,
) -> Any:
    """The timing environment of ``scenario`` under the sensing profile ``sensing``
    (:data:`SENSING_PROFILES`), built as the evaluation builds it (``overrides`` under
    ``timing.`` set the timing task, e.g. its descent)."""
    require_choice("sensing", sensing, tuple(SENSING_PROFILES))
    require_choice("scenario", scenario, tuple(SCENARIOS))
    settings = {
        **SCENARIOS[scenario].overrides(TIMING_TASK, estimator),
        **SENSING_PROFILES[sensing],
        **(overrides or {}),
    }
    return gym.make(
        TIMING_TASK, config=SCENARIOS[scenario].config, overrides=settings, render_mode=None
    )


def _pair(key: str, values: Sequence[float], low: float, high: float) -> tuple[float, float]:
    if len(values) != 2:
        raise ConfigError(key, f"{list(values)!r} needs two values [low, high]")
    lo, hi = (float(v) for v in values)
    require_range(key, lo, low, high)
    require_range(key, hi, lo, high)
    return lo, hi


@dataclass
class RandomiseSettings:
    """What :class:`RandomisedTimingEnv` draws from (the ``randomise`` section of a training
    YAML's ``deck_landing``)."""

    scenarios: list[str] = field(default_factory=lambda: ["bench-ss4"])
    sensing: list[str] = field(default_factory=lambda: ["ideal"])
    #: the estimator in the observation of every variant
    estimator: str = "ihrcf"
    #: mean wind speed, uniform in [low, high], m/s (0 and 0: no wind)
    wind_speed_mps: list[float] = field(default_factory=lambda: [0.0, 0.0])
    #: camera height above the deck at the start, uniform in [low, high], metres; empty: the
    #: hold height
    start_height_m: list[float] = field(default_factory=list)
    #: overrides applied to every variant (after the scenario's and the profile's)
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:

        for key, what, allowed in (
            ("scenarios", "scenario", SCENARIOS),
            ("sensing", "sensing profile", SENSING_PROFILES),
        ):
            if not getattr(self, key):
                raise ConfigError(key, f"needs at least one {what}")
            for name in getattr(self, key):
                require_choice(key, name, allowed)
        require_choice("estimator", self.estimator, ESTIMATOR_NAMES)
        self.wind_speed_mps = list(_pair("wind_speed_mps", self.wind_speed_mps, 0.0, 20.0))
        if self.start_height_m:
            self.start_height_m = list(_pair("start_height_m", self.start_height_m, 0.3, 3.0))


@dataclass(frozen=True)
class Variant:
    """One episode's draw."""

    scenario: str
    sensing: str
    wind_speed_mps: float
    wind_direction_rad: float
    #: camera height at the start, metres (NaN: the hold height)
    start_height_m: float


class RandomisedTimingEnv(gym.Env):
    """``DeckLandingTiming-v0`` over a new :class:`Variant` every episode (module docstring).

    ``info["variant"]`` names the episode's draw; ``unwrapped`` is the current inner
    environment (what a model card describes).
    """

    metadata = {"render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        randomise: RandomiseSettings | dict[str, Any] | None = None,
        timing: dict[str, Any] | None = None,
        render_mode: str | None = None,
        max_worlds: int = 8,
    ) -> None:
        super().__init__()
        if isinstance(randomise, RandomiseSettings):
            self.settings = randomise
        else:
            self.settings = build_dataclass(RandomiseSettings, randomise or {}, "randomise")
        if render_mode is not None:
            raise ValueError("render_mode: the randomised training env renders nothing")
        self.timing = dict(timing or {})
        self.max_worlds = max_worlds
        self._worlds: dict[tuple[str, str], gym.Env] = {}
        #: each world's configured wind, which the draws replace per episode
        self._wind: dict[tuple[str, str], Any] = {}
        self._space: gym.Space | None = None
        first = self._world(self.settings.scenarios[0], self.settings.sensing[0])
        self._space = first.observation_space
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self._current = first
        self.variant: Variant | None = None

    # ------------------------------------------------------------------ worlds
    def _world(self, scenario: str, sensing: str) -> gym.Env:
        key = (scenario, sensing)
        if key not in self._worlds:
            if len(self._worlds) >= self.max_worlds:
                oldest = next(iter(self._worlds))
                self._worlds.pop(oldest).close()
                self._wind.pop(oldest)
            overrides = variant_overrides(self.settings, scenario, sensing)
            env = gym.make(
                TIMING_TASK,
                config=SCENARIOS[scenario].config,
                overrides={**overrides, **nested_to_dotted(self.timing or {}, "timing")},
            )
            if self._space is not None and env.observation_space != self._space:
                env.close()
                raise ConfigError(
                    "randomise", f"{key} gives another observation space; keep the timing settings"
                )
            self._worlds[key] = env
            self._wind[key] = env.unwrapped.config.wind
        return self._worlds[key]

    @property
    def unwrapped(self) -> gym.Env:  # type: ignore[override]
        return self._current.unwrapped

    def draw(self) -> Variant:
        """The next episode's variant, from this environment's generator."""
        s, rng = self.settings, self.np_random
        height = rng.uniform(*s.start_height_m) if s.start_height_m else math.nan
        return Variant(
            scenario=str(rng.choice(s.scenarios)),
            sensing=str(rng.choice(s.sensing)),
            wind_speed_mps=float(rng.uniform(*s.wind_speed_mps)),
            wind_direction_rad=float(rng.uniform(-math.pi, math.pi)),
            start_height_m=float(height),
        )

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        variant = self.draw()
        self.variant = variant
        env = self._world(variant.scenario, variant.sensing)
        base = env.unwrapped
        configured = self._wind[(variant.scenario, variant.sensing)]
        if self.settings.wind_speed_mps[1] > 0.0:
            speed, direction = variant.wind_speed_mps, variant.wind_direction_rad
            # the world rebuilds its wind model from the config at every reset
            base.config.wind = dataclasses.replace(
                configured,
                enabled=speed > 0.0 or configured.enabled,
                mean_velocity_w=(speed * math.cos(direction), speed * math.sin(direction), 0.0),
            )
        options = dict(options or {})
        if math.isfinite(variant.start_height_m):
            options.setdefault("height_m", variant.start_height_m + CAMERA_BELOW_COM_M)
        self._current = env
        # the inner episode's seed comes from this generator: reproducible, distinct per worker
        inner_seed = int(self.np_random.integers(0, 2**31 - 1))
        observation, info = env.reset(seed=inner_seed, options=options)
        info["variant"] = dataclasses.asdict(variant)
        return observation, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self._current.step(action)
        if self.variant is not None:
            info["variant"] = dataclasses.asdict(self.variant)
        return observation, reward, terminated, truncated, info

    def close(self) -> None:
        for env in self._worlds.values():
            env.close()
        self._worlds.clear()


def variant_overrides(settings: RandomiseSettings, scenario: str, sensing: str) -> dict[str, Any]:
    """The dotted overrides of one (scenario, sensing) world."""
    require_choice("scenario", scenario, tuple(SCENARIOS))
    return {
        **landing_overrides(TIMING_TASK),
        "estimation.observed": settings.estimator,
        **SENSING_PROFILES[sensing],
        **settings.overrides,
    }


def sensing_signatures(settings: RandomiseSettings) -> list[str]:
    """The sensing profiles of every world the settings can draw, as a model card names them
    (:func:`agents.common.cards.sensing_profile`)."""

    return sorted(
        {
            sensing_profile(
                load_config(SCENARIOS[scenario].config, variant_overrides(settings, scenario, name))
            )
            for scenario in settings.scenarios
            for name in settings.sensing
        }
    )


def make_randomised_env(
    randomise: dict[str, Any] | None = None,
    timing: dict[str, Any] | None = None,
    render_mode: str | None = None,
) -> RandomisedTimingEnv:
    """The factory :func:`agents.training.trainer.make_envs` hands to SB3 (top level: it
    pickles)."""
    return RandomisedTimingEnv(randomise, timing, render_mode)
