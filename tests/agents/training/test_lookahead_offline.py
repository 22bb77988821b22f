"""The offline DQN on recorded look-ahead transitions: the exact replay of a policy on recorded
episodes, the held-out split, and a DQN fitted by SB3 that learns to wait for a good check."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.policies.lookahead import LookaheadSettings, check_features
from agents.training.lookahead_data import (
    TRANSITION_KEYS,
    collect_transitions,
    load_transitions,
    replay_success,
)
from agents.training.lookahead_training import split_episodes, train_offline
from landing_env.errors import ConfigError
from tests.paths import ROOT

CONFIG = ROOT / "configs/train/timing_dqn_lookahead_offline.yaml"


def _config(draws: int) -> dict:
    """The shipped offline YAML, its look-ahead of ``draws`` and of nominal airframes (the
    synthetic episodes' own), one DQN rather than its ensemble (fast; the ensemble has its
    own test)."""
    config = yaml.safe_load(CONFIG.read_text())
    config["deck_landing"]["lookahead"]["draws"] = draws
    config["deck_landing"]["lookahead"].pop("airframe_in_trim", None)
    assert config["offline"]["ensemble"] > 1
    config["offline"]["ensemble"] = 1
    return config


def _episodes(
    path: Path,
    seeds: range,
    settings: LookaheadSettings,
    rng,
    scenario: str = "ship-ss5",
    estimator: str | None = None,
    sensing: str = "realistic",
) -> Path:
    """Recorded episodes where a commit lands exactly when the check's chance is 0.75 or
    more (one check in four), and the forced commit at the end lands half the time (with
    ``estimator``: the file says which estimate was observed and under which ``sensing``, as
    collected files do)."""
    rows = {key: [] for key in TRANSITION_KEYS}
    for seed in seeds:
        chances = rng.choice([0.0, 0.25, 0.5, 0.75, 1.0], size=12, p=[0.25, 0.25, 0.25, 0.15, 0.1])
        observations = []
        for k, chance in enumerate(chances):
            check = [1.0, chance, max(chance, 0.5), -1.0 + 1.2 * chance, -1.0]
            last = observations[-1][:5] if observations else [0.0, 0.0, 0.0, -1.0, -1.0]
            observations.append(np.array([*check, *last, k / 12], np.float32))
        forced = bool(rng.random() < 0.5)
        for k, chance in enumerate(chances):
            end = k == len(chances) - 1
            lands = chance >= 0.75
            values = (
                observations[k],
                6.0 if lands else -2.0,
                lands,
                True,
                (6.0 if forced else -2.0) if end else -0.05,
                observations[min(k + 1, len(chances) - 1)],
                end,
                forced and end,
                seed,
            )
            for key, value in zip(TRANSITION_KEYS, values, strict=True):
                rows[key].append(value)
    np.savez_compressed(
        path,
        settings=json.dumps(settings.signature()),
        scenario=scenario,
        **({"estimator": estimator, "sensing": sensing} if estimator else {}),
        **{key: np.asarray(value) for key, value in rows.items()},
    )
    return path


def test_a_policy_is_replayed_to_its_first_commit_or_the_forced_end(tmp_path) -> None:
    settings = LookaheadSettings()
    path = _episodes(tmp_path / "a.npz", range(40), settings, np.random.default_rng(0))
    data = load_transitions([path])
    never, chosen = replay_success(data, lambda obs: np.zeros(len(obs), int))
    forced = [data["wait_success"][data["episode"] == s][-1] for s in range(40)]
    assert never == pytest.approx(np.mean(forced)) and np.all(chosen == -1)
    at_once, chosen = replay_success(data, lambda obs: np.ones(len(obs), int))
    first = [data["commit_success"][data["episode"] == s][0] for s in range(40)]
    assert at_once == pytest.approx(np.mean(first)) and np.all(chosen == 0)
    # waiting for a chance of 0.75 lands wherever such a check comes
    patient, _ = replay_success(data, lambda obs: (obs[:, 1] >= 0.75).astype(int))
    reachable = [data["observation"][data["episode"] == s][:, 1].max() >= 0.75 for s in range(40)]
    assert patient >= np.mean(reachable) > at_once


def test_every_fifth_episode_is_held_out() -> None:
    episodes = np.repeat(np.arange(100, 110), 3)
    train, held = split_episodes(episodes, 5)
    assert set(episodes[held]) == {104, 109} and not np.any(train & held)
    with pytest.raises(ConfigError) as error:
        split_episodes(episodes, 1)
    assert error.value.key == "holdout_every"


def test_transitions_of_another_lookahead_are_refused(tmp_path) -> None:
    rng = np.random.default_rng(1)
    a = _episodes(tmp_path / "a.npz", range(3), LookaheadSettings(), rng)
    b = _episodes(tmp_path / "b.npz", range(3), LookaheadSettings(draws=8), rng)
    with pytest.raises(ConfigError) as error:
        load_transitions([a, b])
    assert error.value.key == "data"


def test_a_file_that_is_not_a_lookahead_record_is_refused_naming_it(tmp_path) -> None:
    text = tmp_path / "notes.npz"
    text.write_text("not an archive")
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    array = tmp_path / "array.npy"
    np.save(array, np.zeros(3))
    for path in (text, other, array, tmp_path / "missing.npz"):
        with pytest.raises(ConfigError) as error:
            load_transitions([path])
        assert error.value.key == "data"
        assert path.name in str(error.value)


def test_the_offline_dqn_learns_to_wait_for_a_check_that_lands(tmp_path) -> None:
    settings = LookaheadSettings()
    data_path = _episodes(tmp_path / "d.npz", range(150), settings, np.random.default_rng(2))
    config = _config(draws=settings.draws)
    config["offline"].update(rounds=4, gradient_steps=500, cross_validate=False)
    config_path = tmp_path / "offline.yaml"
    config_path.write_text(yaml.safe_dump(config))
    summary = train_offline(config_path, [data_path], tmp_path / "out", progress=False)
    data = load_transitions([data_path])
    at_once, _ = replay_success(data, lambda obs: np.ones(len(obs), int))
    best_held = summary["best_heldout_replay"][0]
    assert summary["held_out_episodes"] == 30
    assert best_held >= 0.8 > at_once + 0.3  # it waits for the good checks
    from agents.common.cards import read_metadata

    card = read_metadata(tmp_path / "out" / "best_model.zip")
    assert card is not None and card.observation["lookahead"] == settings.signature()
    assert card.env_id.startswith("DeckLandingTiming-ShipSS") and card.sensing[0].startswith(
        "realistic"
    )


def test_a_fit_on_ship_and_bench_records_is_signed_by_both_timing_tasks(tmp_path) -> None:
    from agents.training.lookahead_training import sign_card

    settings = LookaheadSettings()
    rng = np.random.default_rng(5)
    ship = _episodes(tmp_path / "ship.npz", range(4), settings, rng)
    bench = _episodes(tmp_path / "bench.npz", range(10, 14), settings, rng, "bench-ss4", "tight")
    data = load_transitions([ship, bench])
    # a file without the estimator observed is the scenario's own (the ship's: tight)
    assert set(data["estimator"].tolist()) == {"tight"}
    config_path = tmp_path / "offline.yaml"
    config_path.write_text(yaml.safe_dump(_config(draws=settings.draws)))
    from agents.training.trainer import load_train_config

    card = sign_card(load_train_config(config_path), data)
    assert card.sensing == ["realistic", "realistic,lens=wide"]
    assert card.estimator == "tight" and len(card.observations()) == 2
    descents = {o["descent"]["profile"] for o in card.observations()}
    assert descents == {"range", "timed"}  # the ship's descent and the bench's
    assert {o["hold_height_m"] for o in card.observations()} == {0.7, 2.0}
    assert all(o["lookahead"] == settings.signature() for o in card.observations())
    one = sign_card(load_train_config(config_path), data, "ship-ss5")
    assert one.sensing == ["realistic,lens=wide"] and one.other_observations == []
    with pytest.raises(ConfigError, match=r"^offline\.scenario"):
        sign_card(load_train_config(config_path), data, "ship-ss9")
    # the sensing profiles the records were collected under sign the card
    ideal = _episodes(
        tmp_path / "i.npz", range(30, 32), settings, rng, "bench-ss4", "tight", "ideal"
    )
    both = sign_card(load_train_config(config_path), load_transitions([ship, bench, ideal]))
    assert both.sensing == ["ideal", "realistic", "realistic,lens=wide"]
    mixed = _episodes(tmp_path / "mixed.npz", range(20, 22), settings, rng, "bench-ss5", "ihrcf")
    with pytest.raises(ConfigError, match=r"^estimator"):
        sign_card(load_train_config(config_path), load_transitions([ship, mixed]))


#: the look-ahead of the collected records: three draws a check, a check a second
DRAWS_3 = LookaheadSettings(draws=3, check_every_s=1.0)


@pytest.fixture(scope="module")
def replayed_record(small_forecast, tmp_path_factory) -> Path:
    """One ship-ss4 episode collected by the replays of ``DRAWS_3`` under the named profile
    realistic-2x (read, never written, by the tests that share it)."""
    return collect_transitions(
        "ship-ss4",
        [5000],
        tmp_path_factory.mktemp("replayed") / "t.npz",
        DRAWS_3,
        progress=False,
        forecast=small_forecast,
        sensing="realistic-2x",
    )


def test_recorded_draws_rebuild_the_observations_and_those_of_fewer_draws_under_a_named_profile(
    replayed_record, tmp_path
) -> None:
    settings, path = DRAWS_3, replayed_record
    recorded = load_transitions([path])
    # the records say the profile they were flown under, by its name
    assert set(recorded["sensing"].tolist()) == {"realistic-2x"}
    with pytest.raises(ConfigError) as error:
        collect_transitions("ship-ss4", [5000], tmp_path / "x.npz", settings, sensing="noisy")
    assert error.value.key == "sensing" and "realistic-2x" in str(error.value)
    rebuilt = load_transitions([path], settings)  # the file's own look-ahead: as recorded
    assert np.array_equal(rebuilt["observation"], recorded["observation"])
    tried = np.flatnonzero(recorded["check_tried"])
    assert len(tried) >= 5 and recorded["draw_lands"].shape[1] == 3
    # every observation rebuilt from the draws equals the recorded one, the next ones too
    from agents.training.lookahead_data import with_draws

    same = with_draws(recorded, settings)
    assert np.array_equal(same["observation"], recorded["observation"])
    assert np.array_equal(same["next_observation"], recorded["next_observation"])
    one = load_transitions([path], LookaheadSettings(draws=1, check_every_s=1.0))
    invalid = check_features(None)
    episodes = recorded["episode"]
    for i in tried:
        assert one["observation"][i][1] == float(recorded["draw_lands"][i][0])
        # the check before is the previous record's of the episode; none at its first
        first = i == 0 or episodes[i - 1] != episodes[i]
        previous = invalid if first else one["observation"][i - 1][:5]
        assert np.array_equal(one["observation"][i][5:10], previous)
    assert not np.array_equal(one["observation"], recorded["observation"])
    # the episode's first record has no check before it; a record with no check tried (the
    # deck not in view) sees the invalid check as its newest
    assert np.array_equal(one["observation"][0][5:10], invalid)
    for i in np.flatnonzero(~recorded["check_tried"].astype(bool)):
        assert np.array_equal(one["observation"][i][:5], invalid)
    for asked, key in (
        (LookaheadSettings(draws=4, check_every_s=1.0), "data"),
        (LookaheadSettings(draws=2, check_every_s=1.0, min_margin=0.3), "data"),
    ):
        with pytest.raises(ConfigError) as error:
            load_transitions([path], asked)
        assert error.value.key == key


def test_records_flown_by_the_reduced_model_say_so_and_are_not_mixed_with_the_replays(
    small_forecast, replayed_record, tmp_path
) -> None:
    reduced = LookaheadSettings(draws=3, check_every_s=1.0, model="reduced")
    path = collect_transitions(
        "ship-ss4", [5001], tmp_path / "r.npz", reduced, progress=False, forecast=small_forecast
    )
    recorded = load_transitions([path])
    tried = np.flatnonzero(recorded["check_tried"])
    assert len(tried) >= 3 and recorded["draw_lands"].shape[1] == 3
    # a check flown is a valid look-ahead, its features inside the observation's bounds
    assert np.all(recorded["observation"][tried, 0] == 1.0)
    assert np.all(np.abs(recorded["observation"]) <= 1.0)
    # the replays' records of the same draws and checks are another look-ahead's
    with pytest.raises(ConfigError, match="another look-ahead"):
        load_transitions([path, replayed_record])


def test_cross_validation_scores_every_episode_held_out_and_refits_on_all(tmp_path) -> None:
    settings = LookaheadSettings()
    data_path = _episodes(tmp_path / "d.npz", range(100), settings, np.random.default_rng(3))
    config = _config(draws=settings.draws)
    config["offline"].update(rounds=3, gradient_steps=400, holdout_every=4, cross_validate=True)
    config_path = tmp_path / "offline.yaml"
    config_path.write_text(yaml.safe_dump(config))
    summary = train_offline(config_path, [data_path], tmp_path / "out", progress=False)
    assert summary["held_out_episodes"] == 100 and summary["cross_validated"]
    assert [row[0] for row in summary["replay"]] == [400, 800, 1200]
    score, steps = summary["best_heldout_replay"]
    assert score == max(row[1] for row in summary["replay"]) and steps in (400, 800, 1200)
    # the model refitted on every episode for the chosen steps waits for the good checks
    data = load_transitions([data_path])
    at_once, _ = replay_success(data, lambda obs: np.ones(len(obs), int))
    assert summary["chosen_model_replay_all_episodes"] >= 0.8 > at_once + 0.3
    config["offline"]["cross_validate"] = "yes"
    config_path.write_text(yaml.safe_dump(config))
    with pytest.raises(ConfigError) as error:
        train_offline(config_path, [data_path], tmp_path / "bad", progress=False)
    assert error.value.key == "offline.cross_validate"


def test_an_ensemble_is_scored_by_its_mean_q_and_shipped_as_one_distilled_dqn(tmp_path) -> None:
    from stable_baselines3 import DQN

    from agents.training.lookahead_training import greedy, mean_q

    settings = LookaheadSettings()
    data_path = _episodes(tmp_path / "d.npz", range(60), settings, np.random.default_rng(8))
    config = _config(draws=settings.draws)
    config["offline"].update(
        rounds=2, gradient_steps=400, holdout_every=3, cross_validate=True, ensemble=3
    )
    config_path = tmp_path / "offline.yaml"
    config_path.write_text(yaml.safe_dump(config))
    summary = train_offline(config_path, [data_path], tmp_path / "out", progress=False)
    assert summary["ensemble"] == 3
    data = load_transitions([data_path])
    members = [
        DQN.load(tmp_path / "out" / "best_model_members" / f"member{k}.zip", device="cpu")
        for k in range(3)
    ]
    # three members of distinct seeds: distinct Q-values, and the ensemble's is their mean
    q = [mean_q(member, data["observation"]) for member in members]
    assert not np.allclose(q[0], q[1])
    np.testing.assert_allclose(mean_q(members, data["observation"]), np.mean(q, axis=0), 1e-5)
    assert summary["chosen_model_replay_all_episodes"] == pytest.approx(
        replay_success(data, greedy(members))[0], abs=1e-4
    )
    # the one DQN shipped decides as the ensemble on (nearly) every recorded observation
    assert summary["distilled_agreement"]["best_model.zip"] >= 0.98
    shipped = DQN.load(tmp_path / "out" / "best_model.zip", device="cpu")
    agree = greedy(shipped)(data["observation"]) == greedy(members)(data["observation"])
    assert agree.mean() >= 0.98
    assert (
        abs(
            summary["saved_model_replay_all_episodes"] - summary["chosen_model_replay_all_episodes"]
        )
        <= 0.05
    )
    for bad in (0, 2.5, True):
        config["offline"]["ensemble"] = bad
        config_path.write_text(yaml.safe_dump(config))
        with pytest.raises(ConfigError) as error:
            train_offline(config_path, [data_path], tmp_path / "bad", progress=False)
        assert error.value.key == "offline.ensemble"


def test_a_fit_asked_for_airframes_in_trim_takes_only_records_made_so_and_signs_it(
    tmp_path,
) -> None:
    rng = np.random.default_rng(5)
    trim = LookaheadSettings(airframe_in_trim=True)
    in_trim = _episodes(tmp_path / "trim.npz", range(20), trim, rng)
    nominal = _episodes(tmp_path / "nominal.npz", range(20, 40), LookaheadSettings(), rng)
    config = _config(draws=trim.draws)
    config["offline"].update(rounds=1, gradient_steps=50, cross_validate=False)
    config_path = tmp_path / "offline.yaml"
    config_path.write_text(yaml.safe_dump(config))
    train_offline(config_path, [in_trim], tmp_path / "out", progress=False, airframe_in_trim=True)
    from agents.common.cards import read_metadata

    card = read_metadata(tmp_path / "out" / "best_model.zip")
    assert card is not None and card.observation["lookahead"]["airframe_in_trim"] is True
    with pytest.raises(ConfigError) as error:
        train_offline(
            config_path, [nominal], tmp_path / "bad", progress=False, airframe_in_trim=True
        )
    assert error.value.key == "data"


def test_an_episode_seed_recorded_in_two_files_is_refused(tmp_path) -> None:
    rng = np.random.default_rng(4)
    a = _episodes(tmp_path / "a.npz", range(5), LookaheadSettings(), rng)
    b = _episodes(tmp_path / "b.npz", range(4, 8), LookaheadSettings(), rng, "ship-ss6")
    with pytest.raises(ConfigError) as error:
        load_transitions([a, b])
    assert error.value.key == "data" and "seed 4" in str(error.value)


def test_a_fit_on_two_scenarios_reports_each_ones_and_each_sensing_profiles_replay(
    tmp_path,
) -> None:
    settings = LookaheadSettings()
    rng = np.random.default_rng(5)
    a = _episodes(tmp_path / "a.npz", range(60), settings, rng, "ship-ss5", "tight")
    b = _episodes(
        tmp_path / "b.npz", range(100, 140), settings, rng, "ship-ss6", "tight", "realistic-2x"
    )
    data = load_transitions([a, b])
    assert set(data["scenario"][data["episode"] < 100]) == {"ship-ss5"}
    assert set(data["scenario"][data["episode"] >= 100]) == {"ship-ss6"}
    config = _config(draws=settings.draws)
    config["offline"].update(rounds=2, gradient_steps=500, cross_validate=True)
    config_path = tmp_path / "offline.yaml"
    config_path.write_text(yaml.safe_dump(config))
    summary = train_offline(config_path, [a, b], tmp_path / "out", progress=False)
    by_scenario = summary["best_heldout_replay_by_scenario"]
    assert by_scenario["ship-ss5"][1] == 60 and by_scenario["ship-ss6"][1] == 40
    # the overall held-out replay is the episodes' mean of the scenarios' own
    overall = (by_scenario["ship-ss5"][0] * 60 + by_scenario["ship-ss6"][0] * 40) / 100
    assert summary["best_heldout_replay"][0] == pytest.approx(overall, abs=1e-3)
    # here each scenario has one profile: the same figures by profile
    by_sensing = summary["best_heldout_replay_by_sensing"]
    assert by_sensing == {
        "realistic": by_scenario["ship-ss5"],
        "realistic-2x": by_scenario["ship-ss6"],
    }
    baselines = summary["baselines_heldout_replay_by_scenario"]["ship-ss6"]
    held_b = load_transitions([b])
    at_once, _ = replay_success(held_b, lambda obs: np.ones(len(obs), int))
    assert baselines["commit_at_once"] == pytest.approx(at_once, abs=1e-4)
    from agents.common.cards import read_metadata

    card = read_metadata(tmp_path / "out" / "best_model.zip")
    assert card is not None and "60 of ship-ss5, 40 of ship-ss6" in card.note
    assert card.sensing == ["realistic", "realistic-2x"]


def test_records_on_a_training_sea_fly_its_sea_with_the_forecast_identified_online(
    tmp_path,
) -> None:
    from landing_env.sea.training_seas import training_sea

    sea = training_sea("ship-broad/ochi-hubble-bow")
    settings = LookaheadSettings(draws=1, check_every_s=1.0)
    path = collect_transitions(
        "ship-ss4", [5002], tmp_path / "sea.npz", settings, progress=False, sea=sea
    )
    with np.load(path) as data:
        assert str(data["sea"]) == "ochi-hubble-bow" and str(data["scenario"]) == "ship-ss4"
        assert data["check_tried"].any()
    recorded = load_transitions([path])
    assert len(recorded["episode"]) > 0 and set(recorded["scenario"].tolist()) == {"ship-ss4"}
    with pytest.raises(ConfigError) as error:
        collect_transitions("ship-ss5", [5002], tmp_path / "x.npz", settings, sea=sea)
    assert error.value.key == "sea"
    with pytest.raises(ConfigError) as error:
        collect_transitions("ship-unseen-4", [5002], tmp_path / "x.npz", settings)
    assert error.value.key == "scenario" and "held-out" in str(error.value)
    with pytest.raises(ConfigError, match="ochi-hubble-bow"):
        training_sea("ship-broad/ochi-hubble-everywhere")
