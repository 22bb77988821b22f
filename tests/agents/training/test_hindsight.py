"""Hindsight commit labels are the touchdowns that committing then gives, and the replay of a
commit rule on them commits where the rule first says so."""

from __future__ import annotations

import numpy as np
import pytest

from agents.training.hindsight import (
    MIN_MARGIN,
    LabelSet,
    collect_labels,
    make_timing_env,
    replay_rule,
)


def test_a_hindsight_label_is_the_touchdown_that_committing_then_gives(tmp_path) -> None:
    env = make_timing_env("bench-ss4", "realistic", "tight")
    try:
        labels = collect_labels(env, [800_123], max_decisions=5, every=2, progress=False)
        assert list(labels.decision) == [0, 2, 4]
        assert len(labels.waited[0]) == 6  # the first observation and five waits
        # the episode went on as if nothing had been tried: waiting 4 decisions and then
        # committing for real gives the labelled observation and touchdown
        observation, _ = env.reset(seed=800_123)
        for _ in range(4):
            observation, *_ = env.step(0)
        np.testing.assert_array_equal(observation, labels.observations[2])
        np.testing.assert_array_equal(observation, labels.waited[0][4])
        _, _, terminated, _, info = env.step(1)
    finally:
        env.close()
    assert terminated
    assert labels.success[2] == (info["outcome"] == "success")
    assert labels.deck_tilt_deg[2] == pytest.approx(info["touchdown"]["deck_tilt_deg"])
    assert np.all(labels.margin >= MIN_MARGIN)
    # the labels are written for later analysis and read back the same
    saved = np.load(labels.save(tmp_path / "labels" / "bench-ss4.npz"))
    assert "waited" not in saved.files
    np.testing.assert_array_equal(saved["observations"], labels.observations)
    np.testing.assert_array_equal(saved["success"], labels.success)
    loaded = LabelSet.load(tmp_path / "labels" / "bench-ss4.npz")
    np.testing.assert_array_equal(loaded.margin, labels.margin)
    np.testing.assert_array_equal(loaded.decision, labels.decision)
    assert loaded.waited == []


def test_the_replay_commits_at_the_first_decision_the_rule_accepts() -> None:
    episode = np.array([0, 0, 0, 1, 1])
    margin = np.array([-0.5, 0.4, -0.1, -0.3, -0.2])
    commit = np.array([False, True, True, False, False])
    replay = replay_rule(margin, commit, episode)
    # episode 0 commits at its second decision and lands; episode 1 never commits and its
    # last labelled decision fails
    assert replay["success"] == 0.5
    assert replay["precision"] == 1.0
    assert replay["episodes_without_commit"] == 1.0
