"""The policy registry. What ``evaluate landing --scenario S`` flies without ``--policy``: the
measured recommendation of S (:data:`agents.policies.registry.RECOMMENDED`), and on a held-out
sea what its sibling's recommendation is (nothing is chosen on a held-out sea); then what each
of the registry's functions gives and refuses, with stand-ins for the builders and
``gym.make`` (no environment is made)."""

from __future__ import annotations

import zipfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

from agents.policies import registry
from agents.policies.registry import (
    DEFAULT_POLICY,
    MODEL_DIR,
    POLICIES,
    RECOMMENDED,
    PolicySpec,
    Recommendation,
    check_registry,
    default_policy,
    env_settings,
    find_model,
    make_env_and_policy,
    make_policy,
    policy_spec,
    require_model,
    scenario_config,
)
from landing_env.config import SENSORS_ENV
from landing_env.errors import ConfigError
from landing_env.scenarios import (
    HELD_OUT_SCENARIOS,
    LANDING_TASK,
    SCENARIOS,
    TIMING_TASK,
    scenario_id,
    step_limit_on,
)

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


# --- the registry's own functions: what each gives, and each refusal's key and message --------


def _built(env: Any, model_path: str | None, allow_mismatch: tuple[str, ...]) -> tuple:
    """A stand-in builder: what the registry hands a policy's builder."""
    return env, model_path, allow_mismatch


def _failing(env: Any, model_path: str | None, allow_mismatch: tuple[str, ...]) -> None:
    raise ConfigError("--model", "refused by its card")


def _with_builder(monkeypatch: pytest.MonkeyPatch, name: str, builder: str) -> None:
    monkeypatch.setitem(POLICIES, name, replace(POLICIES[name], builder=builder))


def test_a_shipped_models_name_is_found_with_or_without_zip() -> None:
    assert find_model("timing_dqn") == MODEL_DIR / "timing_dqn.zip"
    assert find_model("timing_dqn.zip") == MODEL_DIR / "timing_dqn.zip"


def test_a_model_file_in_the_working_folder_is_taken_before_a_shipped_one_of_its_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    with zipfile.ZipFile("timing_dqn.zip", "w") as archive:
        archive.writestr("data", "{}")
    assert find_model("timing_dqn.zip") == Path("timing_dqn.zip")


def test_a_missing_model_path_is_returned_as_given_for_its_reader_to_name() -> None:
    assert find_model("no/such/timing_dqn") == Path("no/such/timing_dqn")
    assert find_model("no_such_model") == Path("no_such_model")


def test_a_file_that_is_not_a_model_zip_is_refused_naming_it(tmp_path: Path) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a model", encoding="utf-8")
    with pytest.raises(ConfigError) as refused:
        find_model(text)
    assert str(refused.value) == (
        f"model: {text} is not a model (an SB3 .zip; `deck-landing list models` names the "
        "shipped ones)"
    )


def test_a_policy_flies_its_shipped_model_unless_given_one() -> None:
    assert require_model("lander", None) == str(MODEL_DIR / "lander_ppo.zip")
    assert require_model("lander", "timing_dqn") == str(MODEL_DIR / "timing_dqn.zip")
    assert require_model("timing-model", "timing_dqn.zip") == str(MODEL_DIR / "timing_dqn.zip")


def test_a_heuristics_own_file_is_passed_on_as_given() -> None:
    assert require_model("predictive", None) is None
    assert require_model("predictive", "no/such/predictor.npz") == "no/such/predictor.npz"


def test_a_trained_policy_without_a_model_or_with_a_missing_one_is_refused_naming_model() -> None:
    with pytest.raises(ConfigError) as refused:
        require_model("timing-model", None)
    assert str(refused.value) == (
        "--model: timing-model runs a trained model: give --model PATH, or a name "
        "`deck-landing list models` prints"
    )
    with pytest.raises(ConfigError) as refused:
        require_model("timing-model", "no_such_model")
    assert str(refused.value) == "--model: no_such_model: no such file, nor a shipped model's name"


def test_a_policy_spec_takes_the_allowed_values_and_refuses_others_naming_the_field() -> None:
    spec = PolicySpec("mine", "heuristic", "supported", LANDING_TASK, "m:f", "mine")
    assert spec.tasks == (LANDING_TASK,)
    for field, bad in (("kind", "wizard"), ("status", "shiny"), ("task", "hover")):
        values = {"kind": "heuristic", "status": "supported", "task": TIMING_TASK, field: bad}
        with pytest.raises(ConfigError, match=rf"^mine\.{field}: '{bad}' is not allowed; "):
            PolicySpec("mine", builder="m:f", summary="mine", **values)


def test_a_timing_policys_spec_acts_in_the_timing_task() -> None:
    built = registry._timing("mine", kind="baseline", status="legacy", builder="m:f", summary="s")
    assert built == PolicySpec("mine", "baseline", "legacy", TIMING_TASK, "m:f", "s")


def test_unknown_names_are_refused_under_their_key() -> None:
    with pytest.raises(ConfigError, match=r"^policy: 'hover' is not allowed; .*'predictive'"):
        policy_spec("hover")
    for refuse in (default_policy, scenario_config):
        with pytest.raises(ConfigError, match=r"^scenario: 'bench-ss9' is not allowed; "):
            refuse("bench-ss9")
    with pytest.raises(ConfigError, match=r"^scenario: 'bench-ss9' is not allowed; "):
        env_settings("quiescent", "bench-ss9")
    with pytest.raises(
        ConfigError, match=r"^mode: 'raytrace' is not allowed; choose one of 'project', 'render'$"
    ):
        env_settings("quiescent", "bench-ss4", camera_mode="raytrace")


def test_a_held_out_sea_flies_its_own_config() -> None:
    assert scenario_config("bench-unseen") == SCENARIOS["bench-unseen"].config
    assert scenario_config("bench-ss4") == SCENARIOS["bench-ss4"].config
    assert scenario_config("bench-unseen") != scenario_config("bench-ss4")


def test_the_settings_hold_only_what_the_policy_and_the_caller_set(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(SENSORS_ENV, raising=False)
    env_id, overrides = env_settings("align-descend", "bench-ss4")
    assert env_id == scenario_id("bench-ss4", LANDING_TASK)
    assert overrides == {}
    _, overrides = env_settings(
        "align-descend", "bench-ss4", "ihrcf", camera_mode="render", sensing="ideal"
    )
    assert overrides == {
        "estimation.observed": "ihrcf",
        "camera.mode": "render",
        "sensors": "ideal",
    }


def test_a_policy_brings_its_sensing_unless_the_run_names_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(SENSORS_ENV, raising=False)
    _, overrides = env_settings("timing-dqn-lookahead", "ship-ss6")
    assert overrides["sensors"] == "realistic"
    _, overrides = env_settings("timing-dqn-lookahead", "ship-ss6", sensing="ideal")
    assert overrides["sensors"] == "ideal"
    monkeypatch.setenv(SENSORS_ENV, "ideal")
    _, overrides = env_settings("timing-dqn-lookahead", "ship-ss6")
    assert "sensors" not in overrides


def test_a_policy_flies_its_own_id_and_settings_where_it_names_them_for_a_scenario() -> None:
    """The lookahead DQN was trained on v7 of the ship timing ids, not the newest; over a
    ship's helideck `predictive` takes the HMS forecast identified online, on the bench its
    own settings."""
    assert env_settings("timing-dqn-lookahead", "ship-ss6")[0] == "DeckLandingTiming-ShipSS6-v7"
    assert scenario_id("ship-ss6", policy_spec("timing-dqn-lookahead").task) != (
        "DeckLandingTiming-ShipSS6-v7"
    )
    _, ship = env_settings("predictive", "ship-ss5")
    _, bench = env_settings("predictive", "bench-ss4")
    assert ship["deck_forecast"] == "online" and ship["timing.opportunity_s"] == 2.0
    assert "deck_forecast" not in bench


def test_the_callers_overrides_are_laid_over_the_policys(monkeypatch: pytest.MonkeyPatch) -> None:
    _, own = env_settings("predictive", "bench-ss4")
    assert own["timing.wave_off_rule"] == "value"
    _, mine = env_settings(
        "predictive", "bench-ss4", extra_overrides={"timing.wave_off_rule": "model"}
    )
    assert mine == {**own, "timing.wave_off_rule": "model"}


def test_a_policys_builder_gets_the_env_its_model_and_the_allowed_mismatches(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    for name in ("lander", "timing-model", "predictive"):
        _with_builder(monkeypatch, name, f"{__name__}:_built")
    assert make_policy("lander", "env") == ("env", str(MODEL_DIR / "lander_ppo.zip"), ())
    assert make_policy("timing-model", "env", "timing_dqn", ["sensing"]) == (
        "env",
        str(MODEL_DIR / "timing_dqn.zip"),
        ("sensing",),
    )
    assert make_policy("predictive", "env") == ("env", None, ())


class _Env:
    closed = False

    def __init__(self, env_id: str, **kwargs: Any) -> None:
        self.made = (env_id, kwargs)

    def close(self) -> None:
        self.closed = True


def test_the_env_is_made_from_the_scenarios_config_with_the_policys_settings_and_its_limit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(SENSORS_ENV, raising=False)
    monkeypatch.setattr(gym, "make", _Env)
    _with_builder(monkeypatch, "timing-model", f"{__name__}:_built")
    extra = {"timing.wait_limit_s": 7.0}
    env, policy = make_env_and_policy(
        "timing-model",
        "bench-unseen",
        estimator="ihrcf",
        camera_mode="render",
        model_path="timing_dqn",
        render_mode="rgb_array",
        extra_overrides=extra,
        allow_mismatch=["sensing"],
        sensing="ideal",
    )
    env_id, overrides = env_settings(
        "timing-model", "bench-unseen", "ihrcf", "render", "ideal", extra
    )
    config = SCENARIOS["bench-unseen"].config
    limit = step_limit_on(env_id, config, overrides)
    assert limit != step_limit_on(env_id, config)  # the caller's wait limit counts
    assert env.made == (
        env_id,
        {
            "config": config,
            "overrides": overrides,
            "render_mode": "rgb_array",
            "max_episode_steps": limit,
        },
    )
    assert policy == (env, str(MODEL_DIR / "timing_dqn.zip"), ("sensing",))


def test_an_env_whose_policy_is_refused_is_closed(monkeypatch: pytest.MonkeyPatch) -> None:
    made: list[_Env] = []
    monkeypatch.setattr(gym, "make", lambda *a, **k: made.append(_Env(*a, **k)) or made[-1])
    _with_builder(monkeypatch, "land-now", f"{__name__}:_failing")
    with pytest.raises(ConfigError, match="refused by its card"):
        make_env_and_policy("land-now", "bench-ss4")
    assert made[0].closed


def test_a_registry_contradicting_itself_is_refused_naming_the_table(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    check_registry()
    monkeypatch.setitem(DEFAULT_POLICY, "ship-ss3", "lander")
    with pytest.raises(ConfigError) as refused:
        check_registry()
    assert str(refused.value) == "DEFAULT_POLICY: lander is not made for ship-ss3"
    monkeypatch.setitem(DEFAULT_POLICY, "ship-ss3", "quiescent")
    wrong = Recommendation("bench, ideal", "bench-ss4", "ideal", "align-descend", "x")
    monkeypatch.setattr(registry, "RECOMMENDED", (*RECOMMENDED, wrong))
    with pytest.raises(ConfigError) as refused:
        check_registry()
    assert str(refused.value) == "RECOMMENDED: align-descend is recommended but not so marked"
