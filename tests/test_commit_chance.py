"""A commit's chance of success learned from hindsight labels (agents.timing.commit_chance)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agents.timing.commit_chance import (
    NOW_STATISTICS,
    WINDOW_STATISTICS,
    CommitChanceModel,
    commit_features,
    feature_names,
)

DT = 0.05
WINDOWS = (1.0, 4.0)


def _history(rng: np.random.Generator, amplitude_rad: float, n: int = 80) -> np.ndarray:
    """A (n, 10) history of a deck rolling at ``amplitude_rad`` with a 4 s period."""
    t = np.arange(n) * DT + rng.uniform(0.0, 4.0)
    rows = np.zeros((n, 10))
    rows[:, 2] = 2.0 + 0.05 * rng.standard_normal(n)
    rows[:, 3] = amplitude_rad * np.sin(2 * np.pi * t / 4.0)
    rows[:, 4] = 0.3 * amplitude_rad * np.cos(2 * np.pi * t / 4.0)
    rows[:, 7] = amplitude_rad * 2 * np.pi / 4.0 * np.cos(2 * np.pi * t / 4.0)
    rows[:, 9] = 1.0
    return rows


def _labelled(seed: int, episodes: int = 60, per_episode: int = 10):
    """Episodes whose deck rolls with an amplitude of 1-9 deg; a commit succeeds with a chance
    that falls with the amplitude (the labels of a deck whose calm spells land)."""
    rng = np.random.default_rng(seed)
    x, y, g = [], [], []
    for episode in range(episodes):
        for _ in range(per_episode):
            amplitude = math.radians(rng.uniform(1.0, 9.0))
            features = commit_features(_history(rng, amplitude), DT, WINDOWS, np.ones(4), 0.2)
            chance = 1.0 / (1.0 + math.exp((math.degrees(amplitude) - 5.0) * 1.5))
            x.append(features)
            y.append(rng.random() < chance)
            g.append(episode)
    return np.array(x), np.array(y), np.array(g)


def test_the_features_are_named_per_window_then_for_the_newest_sample():
    names = feature_names(WINDOWS)
    assert len(names) == 2 * len(WINDOW_STATISTICS) + len(NOW_STATISTICS)
    assert names[0] == "tilt_max_deg@1s" and names[len(WINDOW_STATISTICS)] == "tilt_max_deg@4s"
    features = commit_features(
        _history(np.random.default_rng(0), 0.1), DT, WINDOWS, [1, 1, 0, 0], 0.5
    )
    assert features.shape == (len(names),)
    # a 0.1 rad (5.7 deg) roll amplitude: the 4 s window holds the whole period's peak
    assert features[names.index("tilt_max_deg@4s")] == pytest.approx(5.95, abs=0.3)
    assert features[names.index("tof_on_deck")] == 2.0
    assert features[names.index("wait_fraction")] == 0.5


def test_a_model_fitted_on_labels_of_calm_spells_ranks_held_out_decisions_by_the_deck_s_motion():
    x, y, g = _labelled(seed=1)
    model = CommitChanceModel.fit(x, y, g, WINDOWS, DT, metadata={"scenario": "synthetic"})
    # held out by episode, the chance ranks successes above failures far better than chance
    assert model.metadata["heldout_auc"] > 0.8
    assert model.metadata["episodes"] == 60 and model.metadata["scenario"] == "synthetic"
    assert len(model.heldout_chances) == len(y)
    rng = np.random.default_rng(2)
    calm = model.chance(_history(rng, math.radians(1.5)), np.ones(4), 0.2)
    rough = model.chance(_history(rng, math.radians(8.5)), np.ones(4), 0.2)
    assert calm.valid and rough.valid
    assert calm.probability > 0.8 > 0.2 > rough.probability
    # the value of waiting on lies between the mean chance and the best
    values = model.stopping_values()
    assert np.mean(model.heldout_chances) <= values.value(5) <= np.max(model.heldout_chances)


def test_the_model_file_round_trips_and_a_malformed_one_is_refused_naming_it(tmp_path):
    x, y, g = _labelled(seed=3, episodes=20)
    model = CommitChanceModel.fit(x, y, g, WINDOWS, DT)
    path = model.save(tmp_path / "chance.npz")
    loaded = CommitChanceModel.load(path)
    assert loaded.windows_s == WINDOWS and loaded.metadata == model.metadata
    np.testing.assert_allclose(loaded.probabilities(x), model.probabilities(x))
    np.savez(tmp_path / "bad.npz", windows_s=np.array([1.0]), dt_s=DT)
    with pytest.raises(ValueError, match=r"bad\.npz"):
        CommitChanceModel.load(tmp_path / "bad.npz")
    np.savez(
        tmp_path / "shape.npz",
        windows_s=np.array([1.0]),
        dt_s=DT,
        mean=np.zeros(3),
        scale=np.ones(3),
        weights=np.zeros(4),
        heldout_chances=np.zeros(0),
        metadata="{}",
    )
    with pytest.raises(ValueError, match="do not match its windows"):
        CommitChanceModel.load(tmp_path / "shape.npz")


def test_fitting_refuses_labels_that_do_not_match_their_features():
    x, y, g = _labelled(seed=4, episodes=5)
    with pytest.raises(ValueError, match="do not match"):
        CommitChanceModel.fit(x, y[:-1], g, WINDOWS, DT)
    with pytest.raises(ValueError, match="features; windows"):
        CommitChanceModel.fit(x[:, :-1], y, g, WINDOWS, DT)
    with pytest.raises(ValueError, match="must be positive"):
        CommitChanceModel.fit(x, y, g, WINDOWS, 0.0)
    with pytest.raises(ValueError, match="must be positive"):
        CommitChanceModel.fit(x, y, g, (), DT)


def test_too_little_seen_gives_an_invalid_chance_with_its_reason():
    x, y, g = _labelled(seed=5, episodes=10)
    model = CommitChanceModel.fit(x, y, g, WINDOWS, DT)
    short = model.chance(np.zeros((10, 10)), np.ones(4), 0.0)
    assert not short.valid and "history rows" in short.reason
    unseen = model.chance(np.zeros((80, 10)), np.ones(4), 0.0)
    assert not unseen.valid and "valid" in unseen.reason
    wrong = model.chance(np.zeros((80, 3)), np.ones(4), 0.0)
    assert not wrong.valid and "shape" in wrong.reason


@settings(max_examples=60, deadline=None)
@given(
    history=arrays(
        np.float64,
        st.tuples(st.integers(0, 100), st.sampled_from([3, 10])),
        elements=st.floats(allow_nan=True, allow_infinity=True, width=64),
    ),
    tof=arrays(np.float64, 4, elements=st.floats(allow_nan=True, allow_infinity=True)),
    wait=st.floats(allow_nan=True, allow_infinity=True),
)
def test_any_history_gives_a_chance_in_0_1_or_an_invalid_one_and_never_raises(history, tof, wait):
    x, y, g = _labelled(seed=6, episodes=6, per_episode=5)
    model = _fuzz_model(x, y, g)
    chance = model.chance(history, tof, wait)
    assert (chance.valid and 0.0 <= chance.probability <= 1.0) or (
        not chance.valid and chance.reason
    )
    features = commit_features(history, DT, WINDOWS, tof, wait)
    assert np.all(np.isfinite(features))


_FUZZ_MODEL: list[CommitChanceModel] = []


def _fuzz_model(x: np.ndarray, y: np.ndarray, g: np.ndarray) -> CommitChanceModel:
    if not _FUZZ_MODEL:
        _FUZZ_MODEL.append(CommitChanceModel.fit(x, y, g, WINDOWS, DT))
    return _FUZZ_MODEL[0]
