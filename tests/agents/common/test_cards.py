"""A trained timing model carries its card (what it was trained on) and refuses a mismatch."""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

from agents.common.cards import (
    LEGACY_OBSERVATION,
    METADATA_NAME,
    ModelMetadata,
    check_compatible,
    env_signature,
    merge_cards,
    observation_signature,
    read_metadata,
    sensing_profile,
    write_metadata,
)
from agents.policies.registry import make_env_and_policy, make_policy
from agents.policies.timing import SHIPPED_TIMING_MODEL, TrainedTimingPolicy, shipped_timing_model
from landing_env.config import load_config
from landing_env.errors import ConfigError
from landing_env.timing_config import TimingConfig

#: the shipped model of the svgs-routine's commit was trained on the range-scheduled descent
RANGE_DESCENT = {"timing.guidance.descent_profile": "range"}
SHIPPED = str(SHIPPED_TIMING_MODEL)


def _shipped_in(scenario: str = "bench-ss4", **kwargs: Any) -> tuple[Any, Any]:
    extra = {**RANGE_DESCENT, **kwargs.pop("extra_overrides", {})}
    return make_env_and_policy(
        "timing-model", scenario, model_path=SHIPPED, extra_overrides=extra, **kwargs
    )


def test_the_shipped_model_says_what_it_was_trained_on() -> None:
    card = read_metadata(SHIPPED_TIMING_MODEL)
    assert card is not None and card.env_id == "DeckLandingTiming-BenchSS4-v6"
    assert card.estimator == "ihrcf" and card.sensing == ["ideal"]
    assert card.camera_mode == "project" and card.algo == "dqn"
    assert card.training_config_source.endswith("configs/train/timing_dqn.yaml")
    assert card.training_config["hyperparams"]["gamma"] == 0.998
    # written before the descent was recorded: the card stands for the range-scheduled one
    assert "descent" not in card.observation
    assert {**LEGACY_OBSERVATION, **card.observation} == observation_signature(TimingConfig(), 20.0)
    assert card.observation["size"] == 409


def test_the_shipped_model_loads_into_the_environment_it_was_trained_for() -> None:
    env, policy = _shipped_in()
    env.close()
    assert isinstance(policy, TrainedTimingPolicy) and policy.metadata.estimator == "ihrcf"


def test_every_shipped_model_belongs_to_a_registered_policy_and_id() -> None:
    from agents.policies.registry import MODEL_DIR, POLICIES
    from landing_env.scenarios import SCENARIO_IDS

    registered = {spec.model for spec in POLICIES.values() if spec.model}
    for path in MODEL_DIR.glob("*.zip"):
        card = read_metadata(path)
        assert card is not None, path.name
        assert all(env_id in SCENARIO_IDS for env_id in card.env_ids()), path.name
        assert path.name in registered or path == SHIPPED_TIMING_MODEL, path.name


def test_the_predictive_dqn_runs_as_shipped_under_ideal_and_realistic_sensing() -> None:
    card = read_metadata(shipped_timing_model("dqn-predictive"))
    assert card is not None and card.estimator == "tight"
    assert card.sensing == ["ideal", "realistic"]
    assert card.env_ids() == ["DeckLandingTiming-BenchSS4-v6", "DeckLandingTiming-BenchSS5-v6"]
    for sensing in ("realistic", None):
        # the policy brings its estimator and its timing settings: no flag is needed
        env, policy = make_env_and_policy("timing-dqn-predictive", "bench-ss5", sensing=sensing)
        env.close()
        assert isinstance(policy, TrainedTimingPolicy)
    with pytest.raises(ConfigError, match=r"^estimator: "):
        make_env_and_policy("timing-dqn-predictive", "bench-ss4", "ihrcf")
    with pytest.raises(ConfigError, match=r"^env_id: .*BenchSS3-v6"):
        make_env_and_policy("timing-dqn-predictive", "bench-ss3")


def test_a_registered_id_is_signed_with_its_own_name_and_version() -> None:
    env = gym.make("DeckLandingTiming-BenchSS4-v6")
    try:
        assert env_signature(env)["env_id"] == "DeckLandingTiming-BenchSS4-v6"
    finally:
        env.close()


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"estimator": "crhf"}, r"^estimator: .*ihrcf.*crhf"),
        ({"extra_overrides": {"tof.noise": "vl53l1x"}}, r"^sensing: .*tof\.noise=vl53l1x"),
    ],
)
def test_a_different_estimator_or_sensing_is_refused_by_name(kwargs: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        _shipped_in(**kwargs)


def test_a_mismatch_can_be_allowed_on_purpose() -> None:
    env, policy = _shipped_in(extra_overrides={"tof.noise": "vl53l1x"}, allow_mismatch=("sensing",))
    env.close()
    assert isinstance(policy, TrainedTimingPolicy)


def test_a_same_shape_observation_of_another_meaning_is_refused() -> None:
    # the same size (409) but z and the ranges relative to another hold height
    env = gym.make(
        "DeckLandingTiming-BenchSS4-v6",
        overrides={**RANGE_DESCENT, "timing.hold_height_m": 0.5},
    )
    try:
        assert env.unwrapped.layout.size == 409
        with pytest.raises(ConfigError, match=r"observation\.hold_height_m: .*0\.7.*0\.5"):
            make_policy("timing-model", env, SHIPPED)
    finally:
        env.close()


def test_another_env_version_is_refused() -> None:
    card = read_metadata(SHIPPED_TIMING_MODEL)
    # the card names v6, so the observation matches and only the version differs
    assert card is not None and card.env_ids() == ["DeckLandingTiming-BenchSS4-v6"]
    signature = {"env_id": "DeckLandingTiming-BenchSS4-v5", "observation": card.observation}
    with pytest.raises(ConfigError, match=r"^env_id: .*BenchSS4-v6.*BenchSS4-v5"):
        check_compatible(card, signature)
    with pytest.raises(ConfigError, match="allow_mismatch"):
        check_compatible(card, signature, allow=("colour",))


def _card(sensing: str, estimator: str = "tight", **timing: object) -> ModelMetadata:
    """A card trained on ``DeckLandingTiming-v0`` with ``timing`` laid over the defaults."""
    observation = observation_signature(TimingConfig(**timing), 20.0)  # type: ignore[arg-type]
    return ModelMetadata("DeckLandingTiming-v0", observation, estimator, [sensing])


def test_a_card_fitted_over_two_timing_tasks_accepts_either_and_refuses_a_third() -> None:
    ship = _card("realistic,lens=wide", hold_height_m=2.0)
    bench = _card("realistic", hold_height_m=0.7)
    card = merge_cards([ship, bench, ship])
    assert card.observation == ship.observation and card.other_observations == [bench.observation]
    assert card.sensing == ["realistic", "realistic,lens=wide"]
    for one in (ship, bench):
        check_compatible(card, {"observation": one.observation, "sensing": "realistic"})
    third = _card("realistic", hold_height_m=1.0)
    with pytest.raises(ConfigError, match=r"observation\.hold_height_m: .*2\.0.*1\.0.*1 other"):
        check_compatible(card, {"observation": third.observation})
    # a card of one observation says so without the count
    with pytest.raises(ConfigError, match=r"hold_height_m: .*the environment has 1\.0: use"):
        check_compatible(bench, {"observation": third.observation})
    again = ModelMetadata.from_json(card.to_json())
    assert again.observations() == [ship.observation, bench.observation]


def test_cards_of_another_estimator_are_not_merged_and_the_ids_are_joined() -> None:
    with pytest.raises(ConfigError, match=r"^estimator: .*'tight'.*'ihrcf'"):
        merge_cards([_card("realistic"), _card("realistic", estimator="ihrcf")])
    other = _card("realistic")
    other.env_id = "DeckLandingTiming-ShipSS5-v7"
    merged = merge_cards([_card("realistic"), other])
    assert merged.env_ids() == ["DeckLandingTiming-v0", "DeckLandingTiming-ShipSS5-v7"]
    with pytest.raises(ConfigError, match=r"^cards"):
        merge_cards([])


def test_a_model_without_a_card_is_refused(tmp_path: Path) -> None:
    bare = tmp_path / "bare.zip"
    with zipfile.ZipFile(SHIPPED_TIMING_MODEL) as source, zipfile.ZipFile(bare, "w") as out:
        for info in source.infolist():
            if info.filename != METADATA_NAME:
                out.writestr(info, source.read(info.filename))
    assert read_metadata(bare) is None
    with pytest.raises(ConfigError, match=r"no card.*deck-landing train timing"):
        TrainedTimingPolicy(bare)


def test_a_card_round_trips_and_a_bad_card_names_the_field(tmp_path: Path) -> None:
    model = tmp_path / "model.zip"
    shutil.copyfile(SHIPPED_TIMING_MODEL, model)
    card = read_metadata(model)
    # the copy's card is the shipped one, of ideal sensing only: the change below is a real one
    assert card is not None and card.sensing == ["ideal"]
    card.sensing = ["ideal", "realistic"]
    write_metadata(model, card)
    again = read_metadata(model)
    assert again == card
    with zipfile.ZipFile(model) as archive:
        assert archive.namelist().count(METADATA_NAME) == 1
        assert "policy.pth" in archive.namelist()
    assert TrainedTimingPolicy(model).act(__import__("numpy").zeros(409, "float32")) in (0, 1)
    with pytest.raises(ConfigError, match="unknown fields"):
        ModelMetadata.from_json('{"env_id": "x", "colour": 1}')
    with pytest.raises(ConfigError, match="missing fields"):
        ModelMetadata.from_json('{"env_id": "x"}')


def test_sensing_profile_names_what_departs_from_ideal() -> None:
    assert sensing_profile(load_config("default")) == "ideal"
    noisy = load_config("default", {"tof.noise": "vl53l1x", "camera.dropout_prob": 0.1})
    assert sensing_profile(noisy) == "tof.noise=vl53l1x,camera.dropout_prob=0.1"


def test_env_signature_reads_the_environment() -> None:
    env, _ = make_env_and_policy("land-now", "bench-ss5", estimator="crhf")
    try:
        signature = env_signature(env)
    finally:
        env.close()
    assert signature["env_id"] == "DeckLandingTiming-BenchSS5-v6"
    assert signature["estimator"] == "crhf" and signature["sensing"] == "ideal"


@pytest.mark.parametrize(
    ("trained", "flags"),
    [
        (["realistic"], "--sensors realistic;"),
        (["realistic-2x", "realistic,lens=wide"], "--sensors realistic --set lens=wide;"),
        (["tof.noise=vl53l1x"], "--set tof.noise=vl53l1x;"),
    ],
)
def test_a_sensing_mismatch_suggests_the_flags_of_the_trained_sensing(
    trained: list[str], flags: str
) -> None:
    card = _card("ideal")
    card.sensing = trained
    with pytest.raises(ConfigError, match=r"^sensing: .*'ideal': run it under its own") as error:
        check_compatible(card, {"sensing": "ideal"})
    assert flags in str(error.value)
    assert str(error.value).endswith("to use it anyway: --allow-mismatch sensing)")


def test_a_prediction_trained_model_blames_the_observation_kind_not_its_size() -> None:
    policy = TrainedTimingPolicy(Path(SHIPPED).with_name("timing_dqn_predictive.zip"))
    env = gym.make("DeckLandingTiming-BenchSS5-v6")
    try:
        with pytest.raises(
            ConfigError,
            match=r"^observation\.observation: .*'prediction', the environment has 'history'.*"
            r"--set timing\.observation=prediction",
        ):
            policy.check_env(env)
    finally:
        env.close()
