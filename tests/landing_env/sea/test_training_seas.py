"""The training families of seas: each member is a real sea of its scenario, none is a held-out
sea, and a fit takes a family but refuses a held-out sea; how a member's overrides are built and
how a member is named."""

from __future__ import annotations

import numpy as np
import pytest

from agents.training.tilt_predictor_fit import fit_family, main
from landing_env.anticipation.hms_forecast import fit_deck_forecast, forecast_rms
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.scenarios import SCENARIOS
from landing_env.sea.heldout import HELD_OUT_SEAS
from landing_env.sea.training_seas import (
    TRAINING_FAMILIES,
    TrainingSea,
    _bench,
    _member,
    member_config,
    training_family,
    training_sea,
)


def _sea(config):
    return config.motion.ship if config.motion.kind == "ship" else config.motion.sea_state


def _signature(config) -> tuple:
    sea = _sea(config)
    g = sea.generator
    return (
        g.spectrum,
        sea.peak_period_s or sea.sea_state,
        g.swell_peak_period_s if g.spectrum == "ochi_hubble" else None,
        sea.wave_direction_deg,
        g.swell_direction_deg,
        g.speed_m_s,
    )


MEMBERS = [(family, m) for family, members in TRAINING_FAMILIES.items() for m in members]


@pytest.mark.parametrize(("family", "member"), MEMBERS, ids=lambda v: getattr(v, "name", v))
def test_a_training_member_builds_its_sea_and_is_no_held_out_sea(family, member) -> None:
    assert not SCENARIOS[member.scenario].held_out
    config = load_config(SCENARIOS[member.scenario].config, overrides=member.overrides)
    held_out = {_signature(load_config(name)) for name in HELD_OUT_SEAS}
    assert _signature(config) not in held_out
    # the overrides took: a member that names a spectrum, speed or heading has it
    sea = _sea(config)
    for key, value in member.overrides.items():
        owner = sea.generator if ".generator." in key else sea
        assert getattr(owner, key.rsplit(".", 1)[1]) == value, key


@pytest.mark.parametrize(("family", "member"), MEMBERS, ids=lambda v: getattr(v, "name", v))
def test_a_member_is_flown_on_its_scenarios_config(family, member) -> None:
    """member_config loads the shipped config named as the scenario, as the scenario does."""
    assert SCENARIOS[member.scenario].config == member.scenario
    expected = load_config(SCENARIOS[member.scenario].config, overrides=member.overrides)
    assert member_config(member) == expected


def test_the_bench_family_spans_spectra_headings_speeds_and_ramps() -> None:
    seas = [
        _sea(load_config(SCENARIOS[m.scenario].config, overrides=m.overrides))
        for m in training_family("bench-broad")
    ]
    assert {s.generator.spectrum for s in seas} == {"jonswap", "torsethaugen", "ochi_hubble"}
    assert {s.generator.speed_m_s > 0 for s in seas} == {True, False}
    assert any(s.generator.ramped for s in seas)
    headings = sorted({s.wave_direction_deg % 360 for s in seas})
    assert headings[-1] - headings[0] >= 180.0


def test_the_ship_family_spans_spectra_headings_speeds_and_ramps_at_every_sea_state() -> None:
    configs = [member_config(m) for m in training_family("ship-broad")]
    assert {c.deck_mount for c in configs} == {"ship"}
    seas = [c.motion.ship for c in configs]
    assert {s.generator.spectrum for s in seas} == {"jonswap", "torsethaugen", "ochi_hubble"}
    assert {s.generator.speed_m_s > 0 for s in seas} == {True, False}
    assert any(s.generator.ramped for s in seas)
    assert {s.sea_state for s in seas} >= {3, 4, 5, 6}
    headings = sorted({s.wave_direction_deg % 360 for s in seas})
    assert headings[-1] - headings[0] >= 180.0


def test_a_forecast_fitted_on_several_seas_takes_a_record_of_each_in_turn() -> None:
    motions = [member_config(m).motion for m in training_family("ship-broad")[:3]]
    forecast = fit_deck_forecast(motions, realizations=2, record_s=200.0)
    assert forecast.metadata["seas"] == 3
    assert forecast.metadata["realizations"] == 3  # at least one record per sea
    rms = forecast_rms(forecast, motions[1], record_s=200.0)
    assert rms.shape == (len(forecast.horizons_s), 5) and np.all(np.isfinite(rms))
    # heave a second ahead: better than 8 s ahead, where the forecast has little skill left
    one_s = list(forecast.horizons_s).index(1.0)
    assert rms[one_s, 2] < rms[-1, 2]


def test_an_unknown_family_is_refused_naming_the_families() -> None:
    with pytest.raises(ConfigError, match="bench-broad"):
        training_family("bench-everything")
    with pytest.raises(SystemExit):
        main(["fit", "--family", "bench-everything", "--out", "x.npz"])


@pytest.mark.parametrize("name", sorted(HELD_OUT_SEAS))
def test_a_fit_refuses_a_held_out_sea(name) -> None:
    with pytest.raises(ConfigError, match=r"scenario: .* is a held-out sea"):
        fit_family([name], "ideal", 1, progress=False)


def test_a_members_sea_and_swell_are_laid_over_its_scenarios_sea_under_its_root() -> None:
    ship = _member(
        "mine", "ship-ss4", "mine", sea=(1.5, 6.0, 90.0), swell=(12.0, 0.3, 45.0), gen_speed_m_s=2.0
    )
    assert ship == TrainingSea(
        "mine",
        "ship-ss4",
        {
            "motion.ship.sea_state": None,
            "motion.ship.significant_height_m": 1.5,
            "motion.ship.peak_period_s": 6.0,
            "motion.ship.wave_direction_deg": 90.0,
            "motion.ship.generator.spectrum": "ochi_hubble",
            "motion.ship.generator.swell_peak_period_s": 12.0,
            "motion.ship.generator.swell_energy_fraction": 0.3,
            "motion.ship.generator.swell_direction_deg": 45.0,
            "motion.ship.generator.speed_m_s": 2.0,
        },
        "mine",
    )
    # a sea or a swell of other than three values is refused
    for short in ({"sea": (1.5, 6.0)}, {"swell": (12.0, 0.3, 45.0, 1.0)}):
        with pytest.raises(ValueError, match="zip"):
            _member("mine", "ship-ss4", "mine", **short)
    bench = _bench("calm", "calm", wave_direction_deg=10.0)
    assert bench == TrainingSea(
        "calm", "bench-ss4", {"motion.sea_state.wave_direction_deg": 10.0}, "calm"
    )


def test_a_member_is_named_family_slash_member_and_an_unknown_one_is_refused() -> None:
    assert (
        training_sea("ship-broad/ochi-hubble-bow").overrides
        == next(m for m in TRAINING_FAMILIES["ship-broad"] if m.name == "ochi-hubble-bow").overrides
    )
    with pytest.raises(ConfigError, match=r"^family: 'bench-everything' is not allowed; "):
        training_family("bench-everything")
    with pytest.raises(ConfigError, match=r"^sea: 'nope' is not allowed; choose one of 'ss3', "):
        training_sea("ship-broad/nope")
    with pytest.raises(ConfigError, match=r"^sea: 'ss3/ss4' is not allowed; "):
        training_sea("ship-broad/ss3/ss4")


def test_a_members_config_takes_further_sections() -> None:
    member = training_family("bench-broad")[3]
    assert member_config(member).camera.mode == "render"
    config = member_config(member, camera={"mode": "project"})
    assert config.camera.mode == "project"
    assert config == load_config(
        member.scenario, overrides=member.overrides, camera={"mode": "project"}
    )
