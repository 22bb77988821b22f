"""A ship in a regular sea: one wave component of a chosen period and direction."""

from __future__ import annotations

import numpy as np

from landing_env.waves.ship import ShipMotion, ShipMotionConfig


def regular_ship(period_s: float, direction_deg: float, **settings) -> ShipMotion:
    """One wave component of period ~``period_s`` (a 0.2 % band), 1 m high, from one
    direction; ``settings`` are the rest of the ship's config (the hull, the generator)."""
    config = ShipMotionConfig(
        sea_state=None,
        significant_height_m=1.0,
        peak_period_s=period_s,
        n_components=1,
        band_low=0.999,
        band_high=1.001,
        wave_direction_deg=direction_deg,
        direction_spread_deg=0.0,
        **settings,
    )
    return ShipMotion(config, np.random.default_rng(0))
