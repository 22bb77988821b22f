"""The training families of seas: what a model or predictor that must carry over to seas it has
not seen is fitted on, in place of the one sea of its scenario.

A family is a list of members, each a scenario (its platform, flight and sensing) and the
dotted overrides of its sea (:mod:`landing_env.waves.generator`): one-peak and two-peak spectra
(JONSWAP, Torsethaugen, Ochi-Hubble), seas from every quarter, the vessel at rest and under
way, and sea states that build or decay during the episode.  The members span the range of
the generator's parameters; none is a held-out sea (:mod:`landing_env.sea.heldout`), and
``tests/landing_env/sea/test_training_seas.py`` checks that no member repeats a held-out sea's
spectrum, periods, headings and speed.

``python -m agents.training.tilt_predictor_fit fit --family bench-broad ...`` fits the bench's
deck-tilt predictor on :data:`TRAINING_FAMILIES` ``["bench-broad"]``; a config's
``deck_forecast: ship-broad`` fits the ship's helideck forecast
(:mod:`landing_env.anticipation.hms_forecast`) on ``["ship-broad"]``'s seas (the held-out ship seas'
configs identify it online instead, which forecasts them better).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from landing_env.config import DeckLandingConfig, load_config
from landing_env.errors import require_choice

_SEA = "motion.sea_state."
_SHIP = "motion.ship."


@dataclass(frozen=True)
class TrainingSea:
    """One member of a training family: ``scenario`` (a scenario of
    :data:`landing_env.scenarios.SCENARIOS`, flown on the shipped config of its name) with its
    sea replaced by ``overrides`` (dotted config keys)."""

    name: str
    scenario: str
    overrides: dict[str, Any] = field(default_factory=dict)
    #: what the member stands for, in words
    description: str = ""


def _member(
    name: str,
    scenario: str,
    description: str,
    sea: tuple[float, float, float] | None = None,
    swell: tuple[float, float, float] | None = None,
    **keys: Any,
) -> TrainingSea:
    """A member whose sea is the scenario's (the bench's ``motion.sea_state``, a ship's
    ``motion.ship``) with ``keys`` changed (``gen_``: a key of its ``generator``); ``sea``:
    (Hs m, Tp s, wave direction deg) in place of its sea state; ``swell``: an Ochi-Hubble
    spectrum's swell (peak period s, share of the variance, direction deg)."""
    root = _SHIP if scenario.startswith("ship") else _SEA
    head: dict[str, Any] = {}
    if sea is not None:
        head["sea_state"] = None
        head.update(
            zip(("significant_height_m", "peak_period_s", "wave_direction_deg"), sea, strict=True)
        )
    if swell is not None:
        head["gen_spectrum"] = "ochi_hubble"
        swell_keys = ("peak_period_s", "energy_fraction", "direction_deg")
        head.update(zip((f"gen_swell_{key}" for key in swell_keys), swell, strict=True))
    keys = {**head, **keys}
    overrides = {
        (root + "generator." + key[4:] if key.startswith("gen_") else root + key): value
        for key, value in keys.items()
    }
    return TrainingSea(name, scenario, overrides, description)


def _bench(name: str, description: str, **keys: Any) -> TrainingSea:
    return _member(name, "bench-ss4", description, **keys)


#: family name -> its members (each member's episodes are seeded as the fit's seeds)
TRAINING_FAMILIES: dict[str, tuple[TrainingSea, ...]] = {
    "bench-broad": (
        TrainingSea("ss3", "bench-ss3", {}, "the bench-ss3 scenario's JONSWAP sea"),
        TrainingSea("ss4", "bench-ss4", {}, "the bench-ss4 scenario's JONSWAP sea"),
        TrainingSea("ss5", "bench-ss5", {}, "the bench-ss5 scenario's JONSWAP sea"),
        _bench(
            "torsethaugen-head",
            "Torsethaugen sea of sea state 4 from ahead, under way at 1 m/s",
            wave_direction_deg=180.0,
            gen_spectrum="torsethaugen",
            gen_speed_m_s=1.0,
        ),
        _bench(
            "torsethaugen-following",
            "Torsethaugen sea, Hs 2.2 m, Tp 10 s, from the starboard quarter, at rest",
            sea=(2.2, 10.0, 45.0),
            gen_spectrum="torsethaugen",
        ),
        _bench(
            "ochi-hubble-bow",
            "wind sea 5 s with a 10 s swell (40 % of the variance) on the port bow, 3 m/s",
            sea=(1.6, 5.0, 170.0),
            swell=(10.0, 0.4, 150.0),
            gen_speed_m_s=3.0,
        ),
        _bench(
            "ochi-hubble-quarter-building",
            "wind sea 7 s with a 14 s following swell (60 %), 1 m/s, Hs 2.0 -> 2.4 m",
            sea=(2.0, 7.0, 60.0),
            swell=(14.0, 0.6, 30.0),
            gen_speed_m_s=1.0,
            gen_hs_end_m=2.4,
            gen_ramp_start_s=10.0,
            gen_ramp_duration_s=30.0,
        ),
        _bench(
            "ochi-hubble-beam-decaying",
            "wind sea 6.5 s with a 9 s beam swell from port (30 %), at rest, Hs 2.2 -> 1.6 m",
            sea=(2.2, 6.5, 240.0),
            swell=(9.0, 0.3, 270.0),
            gen_hs_end_m=1.6,
            gen_ramp_start_s=5.0,
            gen_ramp_duration_s=40.0,
        ),
        _bench(
            "jonswap-fast",
            "JONSWAP sea of sea state 4 abeam, under way at 4 m/s, Tp 8.8 -> 7 s",
            wave_direction_deg=100.0,
            gen_speed_m_s=4.0,
            gen_tp_end_s=7.0,
            gen_ramp_start_s=0.0,
            gen_ramp_duration_s=40.0,
        ),
    ),
    "ship-broad": (
        TrainingSea("ss3", "ship-ss3", {}, "the ship-ss3 scenario's JONSWAP sea, hove-to"),
        TrainingSea("ss4", "ship-ss4", {}, "the ship-ss4 scenario's JONSWAP sea, hove-to"),
        TrainingSea("ss5", "ship-ss5", {}, "the ship-ss5 scenario's JONSWAP sea, hove-to"),
        TrainingSea("ss6", "ship-ss6", {}, "the ship-ss6 scenario's JONSWAP sea, hove-to"),
        _member(
            "torsethaugen-head",
            "ship-ss4",
            "Torsethaugen sea of sea state 4 from ahead, under way at 2 m/s",
            wave_direction_deg=180.0,
            gen_spectrum="torsethaugen",
            gen_speed_m_s=2.0,
        ),
        _member(
            "torsethaugen-quarter",
            "ship-ss5",
            "Torsethaugen sea, Hs 3.0 m, Tp 10 s, from the starboard quarter, 1 m/s",
            sea=(3.0, 10.0, 45.0),
            gen_spectrum="torsethaugen",
            gen_speed_m_s=1.0,
        ),
        _member(
            "ochi-hubble-bow",
            "ship-ss4",
            "wind sea 5.5 s with a 10 s swell (35 % of the variance) off the starboard bow, 5 m/s",
            sea=(1.8, 5.5, 190.0),
            swell=(10.0, 0.35, 160.0),
            gen_speed_m_s=5.0,
        ),
        _member(
            "ochi-hubble-beam-building",
            "ship-ss5",
            "wind sea 7.5 s with a 15 s beam swell (55 %), 2 m/s, Hs 2.8 -> 3.5 m",
            sea=(2.8, 7.5, 120.0),
            swell=(15.0, 0.55, 90.0),
            gen_speed_m_s=2.0,
            gen_hs_end_m=3.5,
            gen_ramp_start_s=10.0,
            gen_ramp_duration_s=30.0,
        ),
        _member(
            "jonswap-following-decaying",
            "ship-ss5",
            "JONSWAP sea of sea state 5 from astern, under way at 3 m/s, Hs 3.25 -> 2.6 m",
            wave_direction_deg=10.0,
            gen_speed_m_s=3.0,
            gen_hs_end_m=2.6,
            gen_ramp_start_s=5.0,
            gen_ramp_duration_s=40.0,
        ),
    ),
}


def training_family(name: str) -> tuple[TrainingSea, ...]:
    """The members of the training family ``name`` (an unknown name is refused, naming the
    families)."""
    require_choice("family", name, tuple(TRAINING_FAMILIES))
    return TRAINING_FAMILIES[name]


def member_config(member: TrainingSea, **keys: Any) -> DeckLandingConfig:
    """The full config of ``member``: its scenario's config with its sea's overrides (and
    ``keys``, further arguments of :func:`~landing_env.config.load_config`)."""
    return load_config(member.scenario, overrides=member.overrides, **keys)


def training_sea(name: str) -> TrainingSea:
    """The member ``FAMILY/MEMBER`` (e.g. ``ship-broad/ochi-hubble-bow``); an unknown family or
    member is refused, naming what there is."""
    family, _, member = name.partition("/")
    members = {m.name: m for m in training_family(family)}
    require_choice("sea", member, tuple(members))
    return members[member]
