"""What ``evaluate landing --scenario S`` flies without ``--policy``: the measured
recommendation of S (:data:`agents.policies.registry.RECOMMENDED`), and on a held-out sea what
its sibling's recommendation is (nothing is chosen on a held-out sea)."""

from __future__ import annotations

import pytest

from agents.policies.registry import DEFAULT_POLICY, RECOMMENDED, default_policy
from landing_env.scenarios import HELD_OUT_SCENARIOS, SCENARIOS

RECOMMENDED_SCENARIOS = sorted({rec.scenario for rec in RECOMMENDED})


def test_every_scenario_has_a_default_policy() -> None:
    assert set(DEFAULT_POLICY) == set(SCENARIOS)


@pytest.mark.parametrize("scenario", RECOMMENDED_SCENARIOS)
def test_a_scenarios_default_policy_is_its_measured_recommendation(scenario: str) -> None:
    recommended = {rec.policy for rec in RECOMMENDED if rec.scenario == scenario}
    # one policy per scenario, whatever the sensing it was measured with
    assert len(recommended) == 1, recommended
    assert default_policy(scenario) == recommended.pop()


@pytest.mark.parametrize("scenario", sorted(HELD_OUT_SCENARIOS))
def test_a_held_out_sea_flies_the_default_of_the_scenario_whose_ids_it_flies(
    scenario: str,
) -> None:
    (sibling,) = (
        name
        for name, other in SCENARIOS.items()
        if other.ids == SCENARIOS[scenario].ids and not other.held_out
    )
    assert default_policy(scenario) == default_policy(sibling)
