"""A start curriculum for training a lander of ``DeckLanding``: low and centred first, then the
scenario's own start.

A learner that starts 1.5-4 m up and 1 m off the deck seldom finds a touchdown by exploring:
descending before lining up loses the tag.  :class:`StartCurriculum` starts the first
episodes just above the deck and over its centre, where any descent touches it and the
touchdown terms of the reward teach *how* and *when* to land, then widens the start to the
scenario's own over ``ramp_steps``; a share of episodes (``full_fraction``) always starts as
the scenario does.  The wrapper passes the start through ``reset``'s options (``height_m``,
``offset_m``, ``yaw``), which the environment documents; with ``options`` given by the
caller it changes nothing.  It counts its own environment's steps, so with ``n`` parallel
environments the schedule is in steps per environment.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from landing_env.errors import require_range


class StartCurriculum(gym.Wrapper):
    """Start episodes low and centred, then widen to the scenario's start (see the module
    docstring).  Heights are the drone centre's above the deck's home surface, metres."""

    def __init__(
        self,
        env: gym.Env,
        height_m: tuple[float, float] = (0.5, 0.8),
        offset_m: float = 0.05,
        yaw_deg: float = 3.0,
        hold_steps: int = 20_000,
        ramp_steps: int = 80_000,
        full_fraction: float = 0.2,
    ) -> None:
        super().__init__(env)
        low, high = (float(v) for v in height_m)
        require_range("height_m[0]", low, 0.2)
        require_range("height_m[1]", high, low)
        require_range("offset_m", offset_m, 0.0)
        require_range("yaw_deg", yaw_deg, 0.0, 180.0)
        require_range("hold_steps", hold_steps, 0)
        require_range("ramp_steps", ramp_steps, 1)
        require_range("full_fraction", full_fraction, 0.0, 1.0)
        self.height_m = (low, high)
        self.offset_m = float(offset_m)
        self.yaw_deg = float(yaw_deg)
        self.hold_steps = int(hold_steps)
        self.ramp_steps = int(ramp_steps)
        self.full_fraction = float(full_fraction)
        self.steps = 0
        self._rng: np.random.Generator | None = None

    @property
    def difficulty(self) -> float:
        """0 (the easy start) to 1 (the scenario's own), by the steps taken."""
        return float(np.clip((self.steps - self.hold_steps) / self.ramp_steps, 0.0, 1.0))

    def start_options(self) -> dict[str, Any]:
        """The next episode's start (empty: the scenario's own)."""
        if self._rng is None:
            self._rng = np.random.default_rng(0)
        d = self.difficulty
        if d >= 1.0 or self._rng.uniform() < self.full_fraction:
            return {}
        start = self.env.unwrapped.config.start
        low, high = self.height_m
        top = high + d * (max(start.height_m[1], high) - high)
        radius = (self.offset_m + d * (start.max_offset_m - self.offset_m)) * math.sqrt(
            self._rng.uniform()
        )
        bearing = self._rng.uniform(-math.pi, math.pi)
        yaw = self.yaw_deg + d * (start.max_yaw_deg - self.yaw_deg)
        return {
            "height_m": float(self._rng.uniform(low, top)),
            "offset_m": (radius * math.cos(bearing), radius * math.sin(bearing)),
            "yaw": math.radians(float(self._rng.uniform(-yaw, yaw))),
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        if seed is not None and self._rng is None:
            self._rng = np.random.default_rng(seed)
        if not options:
            options = self.start_options()
        observation, info = self.env.reset(seed=seed, options=options)
        info["curriculum_difficulty"] = self.difficulty
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self.steps += 1
        return self.env.step(action)
