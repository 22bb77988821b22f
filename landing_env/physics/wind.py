"""Wind: a constant mean plus an Ornstein–Uhlenbeck gust process, in the world frame W.

Each gust component is a first-order Gauss–Markov (Ornstein–Uhlenbeck) process with standard
deviation ``gust_intensity`` and correlation time ``gust_time_constant``; this is the
first-order Dryden form, whose time constant for a vehicle flying through frozen turbulence is
the turbulence length scale divided by the airspeed.  The process is advanced with its exact
discretisation, so its statistics do not depend on the step size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from landing_env.errors import ConfigError, require_range

#: how many standard normals are drawn at once (drawing one triple per physics step is slow)
_NORMAL_BLOCK = 4096


@dataclass(frozen=True)
class WindConfig:
    """Wind settings: the mean velocity (m/s, world frame) and the gust process."""

    enabled: bool = False
    #: mean wind velocity in W (m/s): the air's velocity, not the direction it comes from
    mean_velocity_w: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: stationary standard deviation of the gust in each world axis (m/s)
    gust_intensity: tuple[float, float, float] = (0.5, 0.5, 0.2)
    #: correlation time of the gust process (s)
    gust_time_constant: float = 2.0

    def __post_init__(self) -> None:
        # Accept lists and arrays, store plain float tuples (hashable, immutable).
        object.__setattr__(self, "mean_velocity_w", tuple(float(v) for v in self.mean_velocity_w))
        object.__setattr__(self, "gust_intensity", tuple(float(v) for v in self.gust_intensity))
        if len(self.mean_velocity_w) != 3:
            raise ConfigError("mean_velocity_w", "needs 3 components (m/s, world frame)")
        if len(self.gust_intensity) != 3:
            raise ConfigError("gust_intensity", "needs 3 components (m/s, world frame)")
        for value in self.mean_velocity_w:
            if not math.isfinite(value):
                raise ConfigError("mean_velocity_w", f"{value!r} is not finite")
        for value in self.gust_intensity:
            require_range("gust_intensity", value, 0.0, 50.0)
        require_range("gust_time_constant", self.gust_time_constant, 0.0, low_inclusive=False)


class WindModel:
    """The wind velocity over time, seeded by a :class:`numpy.random.Generator`."""

    def __init__(self, config: WindConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._mean = tuple(float(v) for v in config.mean_velocity_w)
        self._sigma = tuple(float(v) for v in config.gust_intensity)
        self._normals: list[float] = []
        self._next_normal = 0
        self._gust = [0.0, 0.0, 0.0]
        self._last_time = -math.inf
        self._last_value = np.zeros(3)
        self._decay_dt = -1.0
        self._decay = 0.0
        self._drive = 0.0
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Restart the gust process from its stationary distribution (new ``rng`` if given)."""
        if rng is not None:
            self._rng = rng
        self._normals = []
        self._next_normal = 0
        self._last_time = -math.inf
        if self.config.enabled:
            # Start in the stationary state so the statistics hold from t = 0.
            self._gust = [s * self._normal() for s in self._sigma]
        else:
            self._gust = [0.0, 0.0, 0.0]
        self._last_value = self._compose()

    @property
    def gust_w(self) -> np.ndarray:
        """The current gust component (m/s, world frame), without the mean."""
        return np.array(self._gust)

    def velocity(self, t: float, dt: float) -> np.ndarray:
        """The wind velocity (m/s, world frame) at time ``t``, after advancing the gusts by ``dt``.

        Calling again with the same ``t`` returns the same value without advancing, so several
        users can ask at one instant.  Disabled wind is zero.
        """
        if not self.config.enabled:
            return np.zeros(3)
        if t == self._last_time:
            return self._last_value.copy()
        self._last_time = t
        if dt > 0.0:
            self._advance(dt)
        self._last_value = self._compose()
        return self._last_value.copy()

    def velocity_tuple(self, t: float, dt: float) -> tuple[float, float, float]:
        """As :meth:`velocity` but as plain floats (the physics hot path avoids arrays)."""
        if not self.config.enabled:
            return (0.0, 0.0, 0.0)
        if t != self._last_time:
            self._last_time = t
            if dt > 0.0:
                self._advance(dt)
            self._last_value = self._compose()
        g = self._gust
        m = self._mean
        return (m[0] + g[0], m[1] + g[1], m[2] + g[2])

    def _advance(self, dt: float) -> None:
        if dt != self._decay_dt:
            # Exact OU discretisation: x' = a x + sigma sqrt(1 - a^2) n.
            self._decay_dt = dt
            self._decay = math.exp(-dt / self.config.gust_time_constant)
            self._drive = math.sqrt(1.0 - self._decay * self._decay)
        a = self._decay
        b = self._drive
        g = self._gust
        s = self._sigma
        for i in range(3):
            g[i] = a * g[i] + b * s[i] * self._normal()

    def _normal(self) -> float:
        if self._next_normal >= len(self._normals):
            self._normals = self._rng.standard_normal(_NORMAL_BLOCK).tolist()
            self._next_normal = 0
        value = self._normals[self._next_normal]
        self._next_normal += 1
        return value

    def _compose(self) -> np.ndarray:
        return np.array(self._mean) + np.array(self._gust)
