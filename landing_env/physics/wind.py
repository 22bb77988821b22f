"""Wind: a constant mean plus an Ornstein–Uhlenbeck gust process, in the world frame W.

Each gust component is a first-order Gauss–Markov (Ornstein–Uhlenbeck) process with standard
deviation ``gust_intensity`` and correlation time ``gust_time_constant``; this is the
first-order Dryden form, whose time constant for a vehicle flying through frozen turbulence is
the turbulence length scale divided by the airspeed.  The process is advanced with its exact
discretisation, so its statistics do not depend on the step size.

``turbulence: dryden`` sets the gusts by the low-altitude Dryden model of MIL-F-8785C
(Sec. 3.7.2.3) / MIL-HDBK-1797 instead of by hand: with W20 the mean wind speed (the horizontal
norm of ``mean_velocity_w``, taken as the wind at 20 ft) and h the height above the sea
(``reference_height_m``, in feet inside the formulas, 10-1000 ft):
sigma_w = 0.1 W20, sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4,
L_w = h, L_u = L_v = h / (0.177 + 0.000823 h)^1.2; u along the mean wind, v across it, w up.
A hovering vehicle sees the frozen turbulence carried past by the mean wind, so each
component's correlation time is its length scale over the mean wind speed.  Dryden's u filter is
first order (exactly this process); its v and w filters are second order and are taken here as
first order with the same variance and length scale (a documented simplification).
Optional **airwake** over the deck: within ``airwake_radius_m`` of the deck's home position
and ``airwake_height_m`` above it, a downdraft of ``airwake_downdraft_fraction`` times the
mean wind speed is added and the gusts are multiplied by ``airwake_turbulence_factor``
(order of magnitude from ship-airwake measurements behind a superstructure: downwash a few
percent to ~10 % of the free stream and turbulence intensity up to doubled; e.g. Polsky
2002, AIAA 2002-1022, and the SFS2 data).  Off by default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.limits import POSITIVE, Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice, require_range

#: how many standard normals are drawn at once (drawing one triple per physics step is slow)
_NORMAL_BLOCK = 4096


@dataclass(frozen=True)
class WindConfig:
    """Wind settings: the mean velocity (m/s, world frame) and the gust process."""

    enabled: bool = False
    #: mean wind velocity in W (m/s): the air's velocity, not the direction it comes from
    mean_velocity_w: tuple[float, float, float] = limited(
        (0.0, 0.0, 0.0), physical=Limit.symmetric(100.0, "m/s; hurricane force is ~33 m/s")
    )
    #: stationary standard deviation of the gust in each world axis (m/s)
    gust_intensity: tuple[float, float, float] = limited(
        (0.5, 0.5, 0.2), physical=Limit.non_negative(100.0)
    )
    #: correlation time of the gust process (s)
    gust_time_constant: float = limited(2.0, POSITIVE, physical=Limit.positive(1e3))
    #: "ou": gust_intensity and gust_time_constant as given; "dryden": both from the
    #: MIL-F-8785C low-altitude Dryden model for the mean wind and reference_height_m
    turbulence: str = "ou"
    #: height above the surface for the Dryden scales (m)
    reference_height_m: float = limited(10.0, Limit(3.0, 300.0))
    #: airwake over the deck (0 radius: off): region, downdraft and turbulence increase
    airwake_radius_m: float = limited(0.0, Limit(0.0, 100.0))
    airwake_height_m: float = limited(5.0, Limit(0.0, 100.0))
    airwake_downdraft_fraction: float = limited(0.0, Limit(0.0, 0.5))
    airwake_turbulence_factor: float = limited(1.0, Limit(1.0, 5.0))

    def __post_init__(self) -> None:
        require_choice("turbulence", self.turbulence, ("ou", "dryden"))
        require_limits(self)
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

    @property
    def mean_speed(self) -> float:
        """Horizontal mean wind speed (m/s)."""
        return math.hypot(self.mean_velocity_w[0], self.mean_velocity_w[1])

    def dryden(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(sigma_u, sigma_v, sigma_w) in m/s and (L_u, L_v, L_w) in m, MIL-F-8785C low altitude."""
        feet = 0.3048
        h_ft = min(1000.0, max(10.0, self.reference_height_m / feet))
        sigma_w = 0.1 * self.mean_speed
        base = 0.177 + 0.000823 * h_ft
        sigma_uv = sigma_w / base**0.4
        length_uv = h_ft / base**1.2 * feet
        return (sigma_uv, sigma_uv, sigma_w), (length_uv, length_uv, h_ft * feet)

    def gust_process(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Per axis (u, v, w or world x, y, z) the gust standard deviation and correlation time."""
        if self.turbulence == "ou":
            tau = self.gust_time_constant
            return self.gust_intensity, (tau, tau, tau)
        sigma, lengths = self.dryden()
        speed = max(self.mean_speed, 0.5)  # a calm day's turbulence still moves
        return sigma, (lengths[0] / speed, lengths[1] / speed, lengths[2] / speed)


class WindModel:
    """The wind velocity over time, seeded by a :class:`numpy.random.Generator`."""

    def __init__(self, config: WindConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._mean = tuple(float(v) for v in config.mean_velocity_w)
        sigma, taus = config.gust_process()
        self._sigma = tuple(float(v) for v in sigma)
        self._taus = tuple(float(v) for v in taus)
        # Dryden axes: u along the mean wind, v across it (horizontal), w up
        speed = config.mean_speed
        if config.turbulence == "dryden" and speed > 0.0:
            self._axes = (config.mean_velocity_w[0] / speed, config.mean_velocity_w[1] / speed)
        else:
            self._axes = (1.0, 0.0)
        self._normals: list[float] = []
        self._next_normal = 0
        self._gust = [0.0, 0.0, 0.0]
        self._last_time = -math.inf
        self._decay_dt = -1.0
        self._decay = (0.0, 0.0, 0.0)
        self._drive = (0.0, 0.0, 0.0)
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

    def redraw(self, rng: np.random.Generator) -> None:
        """Draw the gusts' future innovations from ``rng``, keeping the present gust: the wind
        from now on is another realisation of the same process, from the same state (what
        a look-ahead that must not know the future gusts tries, :mod:`agents.policies.oracle`)."""
        self._rng = rng
        self._normals = []
        self._next_normal = 0

    def set_present_gust_w(self, gust_w: np.ndarray) -> None:
        """Replace the present gust (m/s, world frame, without the mean) by ``gust_w``; the
        process goes on from it.  A model that does not know the present gust exactly plays
        one drawn around its estimate (:mod:`agents.policies.deck_forecast`).  Disabled wind stays
        zero; a non-finite gust is refused by name."""
        gust = np.asarray(gust_w, dtype=float).reshape(-1)
        if gust.shape != (3,) or not np.all(np.isfinite(gust)):
            raise ValueError(f"gust_w must be 3 finite m/s values, got {gust_w!r}")
        if not self.config.enabled:
            return
        cx, sx = self._axes
        gx, gy, gz = (float(v) for v in gust)
        self._gust = [cx * gx + sx * gy, -sx * gx + cx * gy, gz]

    @property
    def gust_w(self) -> np.ndarray:
        """The current gust component (m/s, world frame), without the mean."""
        return np.array(self._gust_world())

    def _gust_world(self) -> tuple[float, float, float]:
        cx, sx = self._axes
        gu, gv, gw = self._gust
        return (cx * gu - sx * gv, sx * gu + cx * gv, gw)

    def velocity(self, t: float, dt: float) -> np.ndarray:
        """The wind velocity (m/s, world frame) at time ``t``, after advancing the gusts by ``dt``.

        Calling again with the same ``t`` returns the same value without advancing, so several
        users can ask at one instant.  Disabled wind is zero.
        """
        if not self.config.enabled:
            return np.zeros(3)
        if t != self._last_time:
            self._last_time = t
            if dt > 0.0:
                self._advance(dt)
        return self._compose()

    def velocity_tuple(self, t: float, dt: float) -> tuple[float, float, float]:
        """As :meth:`velocity` but as plain floats (the physics hot path avoids arrays)."""
        if not self.config.enabled:
            return (0.0, 0.0, 0.0)
        if t != self._last_time:
            self._last_time = t
            if dt > 0.0:
                self._advance(dt)
        g = self._gust_world()
        m = self._mean
        return (m[0] + g[0], m[1] + g[1], m[2] + g[2])

    def _advance(self, dt: float) -> None:
        if dt != self._decay_dt:
            # Exact OU discretisation: x' = a x + sigma sqrt(1 - a^2) n.
            self._decay_dt = dt
            decay = tuple(math.exp(-dt / tau) for tau in self._taus)
            self._decay = decay  # type: ignore[assignment]
            self._drive = tuple(math.sqrt(1.0 - a * a) for a in decay)  # type: ignore[assignment]
        a = self._decay
        b = self._drive
        g = self._gust
        s = self._sigma
        for i in range(3):
            g[i] = a[i] * g[i] + b[i] * s[i] * self._normal()

    def _normal(self) -> float:
        if self._next_normal >= len(self._normals):
            self._normals = self._rng.standard_normal(_NORMAL_BLOCK).tolist()
            self._next_normal = 0
        value = self._normals[self._next_normal]
        self._next_normal += 1
        return value

    def _compose(self) -> np.ndarray:
        return np.array(self._mean) + np.array(self._gust_world())

    def airwake(
        self, wind: tuple[float, float, float], offset_from_deck_w: tuple[float, float, float]
    ) -> tuple[float, float, float]:
        """``wind`` with the airwake at a point ``offset_from_deck_w`` from the deck home."""
        c = self.config
        dx, dy, dz = offset_from_deck_w
        if (
            c.airwake_radius_m <= 0.0
            or dx * dx + dy * dy > c.airwake_radius_m**2
            or not 0.0 <= dz <= c.airwake_height_m
        ):
            return wind
        m = self._mean
        k = c.airwake_turbulence_factor
        down = c.airwake_downdraft_fraction * c.mean_speed
        return (
            m[0] + k * (wind[0] - m[0]),
            m[1] + k * (wind[1] - m[1]),
            m[2] + k * (wind[2] - m[2]) - down,
        )
