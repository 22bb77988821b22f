"""The sea of a scenario: one config for the bench's stand-in vessel and the ship alike.

:class:`SeaConfig` holds what a sea is (a WMO sea state or Hs and Tp, the JONSWAP spectrum's
discretisation, the waves' mean direction and spread, and the generator of other seas,
:mod:`landing_env.waves.generator`) and checks it once; the bench's
:class:`~landing_env.stewart.motion.SeaStateConfig` and the ship's
:class:`~landing_env.waves.ship.ShipMotionConfig` add their vessel's response to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from estimation.limits import Limit, limited
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.waves.generator import SeaGeneratorConfig, require_generator
from landing_env.waves.spectrum import SEA_STATE_TABLE, JonswapSeaFields


@dataclass(frozen=True)
class SeaConfig(JonswapSeaFields):
    """A JONSWAP sea (or the generator's): give ``sea_state`` (WMO code, typical Hs and Tp from
    :data:`~landing_env.waves.spectrum.SEA_STATE_TABLE`) and/or explicit
    ``significant_height_m`` and ``peak_period_s``, which take precedence."""

    #: the Hs (m) and Tp (s) a vessel of this kind is modelled for
    HS_RANGE_M: ClassVar[tuple[float, float]] = (0.0, 20.0)
    TP_RANGE_S: ClassVar[tuple[float, float]] = (0.5, 30.0)

    #: WMO sea-state code (typical Hs and Tp from SEA_STATE_TABLE), or None with both below
    sea_state: int | None = 4
    significant_height_m: float | None = None
    peak_period_s: float | None = None
    #: JONSWAP peak enhancement factor (1 gives Pierson-Moskowitz); None: by the DNV-RP-C205
    #: rule from Hs and Tp (:func:`~landing_env.waves.spectrum.dnv_gamma`: 1 for the tabled
    #: sea states 3-6, whose Tp/sqrt(Hs) >= 5)
    gamma: float | None = None
    #: number of wave components (one per frequency bin)
    n_components: int = 150
    #: spectrum band as multiples of the peak frequency
    band_low: float = 0.5
    band_high: float = 5.0
    #: direction the waves travel towards, from the bow (x) counter-clockwise (deg): 0
    #: following seas, 180 head seas, 90 beam seas from starboard
    wave_direction_deg: float = limited(135.0, physical=Limit.symmetric(360.0))
    #: half-width of the uniform random spread of component directions (short-crested sea)
    direction_spread_deg: float = limited(30.0, physical=Limit.non_negative(180.0))
    #: other seas than the JONSWAP above: bimodal spectra, vessel speed, a changing sea state
    #: (landing_env/waves/generator.py); its defaults keep the JONSWAP sea at zero speed
    generator: SeaGeneratorConfig = field(default_factory=SeaGeneratorConfig)

    def check_sea(self) -> None:
        """Refuse a sea outside what it can be, naming the key (the subclasses' checks call it
        first)."""
        object.__setattr__(self, "generator", require_generator(self.generator))
        if self.sea_state is not None:
            require_choice("sea_state", self.sea_state, tuple(SEA_STATE_TABLE))
        elif self.significant_height_m is None or self.peak_period_s is None:
            raise ConfigError(
                "sea_state",
                "None needs both significant_height_m and peak_period_s; "
                f"or choose one of {', '.join(str(k) for k in SEA_STATE_TABLE)}",
            )
        if self.significant_height_m is not None:
            require_range("significant_height_m", self.significant_height_m, *self.HS_RANGE_M)
        if self.peak_period_s is not None:
            require_range("peak_period_s", self.peak_period_s, *self.TP_RANGE_S)
        if self.gamma is not None:
            require_range("gamma", self.gamma, 1.0, 10.0)
        require_range("n_components", self.n_components, 1, 10_000)
        require_range("band_low", self.band_low, 0.0, 1.0, low_inclusive=False)
        require_range("band_high", self.band_high, 1.0, 20.0, low_inclusive=False)
        require_range("direction_spread_deg", self.direction_spread_deg, 0.0, 180.0)
        self.generator.check_sea(self.hs, self.tp)


__all__ = ["SeaConfig"]
