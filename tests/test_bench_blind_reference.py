"""The privileged horizontal reference of benchmarks/bench_blind_reference.py."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from benchmarks.bench_blind_reference import aided_tracker
from landing_env.timing.deck_tracker import DeckTracker


def _fake_env(x: float, y: float) -> SimpleNamespace:
    deck = SimpleNamespace(tag_centre_w=np.array([x, y, 5.0]))
    return SimpleNamespace(world=SimpleNamespace(deck_state=lambda: deck))


BLIND = {
    "deck_pose_valid": np.array([0.0]),
    "deck_pose": np.zeros(6),
    "tof_valid": np.zeros(4),
    "tof_range": np.zeros(4),
}


def test_an_unseen_tag_is_placed_at_its_true_position_only_inside_and_only_for_its_own_env():
    own = SimpleNamespace(yaw=0.0)
    assert np.isnan(DeckTracker.measure(BLIND, own)).all()

    with aided_tracker(_fake_env(1.0, 2.0)):
        inside = DeckTracker.measure(BLIND, own)
    with aided_tracker(_fake_env(-3.0, 4.0)):
        second = DeckTracker.measure(BLIND, own)

    assert inside[:2].tolist() == [1.0, 2.0] and np.isnan(inside[2])
    # a second run reads its own environment, not the first's
    assert second[:2].tolist() == [-3.0, 4.0]
    assert np.isnan(DeckTracker.measure(BLIND, own)).all()
