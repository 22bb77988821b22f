"""The training families of seas: each member is a real sea of its scenario, none is a held-out
sea, and a fit takes a family but refuses a held-out sea."""

from __future__ import annotations

import numpy as np
import pytest

from agents.training.tilt_predictor_fit import fit_family, main
from landing_env.anticipation.hms_forecast import fit_deck_forecast, forecast_rms
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.scenarios import SCENARIOS
from landing_env.sea.heldout import HELD_OUT_SEAS
from landing_env.sea.training_seas import TRAINING_FAMILIES, member_config, training_family


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
