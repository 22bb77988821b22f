"""Save and restore an environment's whole state in memory, to look ahead and come back.

A snapshot holds PyBullet's in-memory state (``saveState``) and a deep copy of the
environment's Python state (the world's drone, controller, deck motion, sensors and their
random streams, the estimators, the task's history).  Restoring both puts the episode back
exactly where it was: the steps that follow are the same, bit for bit, as if the look-ahead
had never run (``tests/agents/policies/test_oracle.py`` checks it).  The PyBullet client and
the config are shared, not copied.  This is privileged simulation access: the oracle timing uses it
(:mod:`agents.policies.oracle`); a policy for a real drone cannot.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any


@dataclass
class EnvSnapshot:
    """One saved state of a :class:`~landing_env.envs.base.DeckLandingBaseEnv`."""

    bullet_state_id: int
    python_state: dict[str, Any]
    released: bool = False


def _shared(env: Any) -> dict[int, Any]:
    """Objects a snapshot shares instead of copying (deepcopy's memo)."""
    client = env.world.client
    return {id(client): client, id(env.config): env.config}


def save_snapshot(env: Any) -> EnvSnapshot:
    """Save ``env``'s state (the unwrapped environment)."""
    state_id = int(env.world.client.saveState())
    return EnvSnapshot(state_id, copy.deepcopy(env.__dict__, _shared(env)))


def restore_snapshot(env: Any, snapshot: EnvSnapshot, keep: bool = True) -> None:
    """Put ``env`` back into ``snapshot``'s state; with ``keep`` the snapshot can be restored
    again, otherwise it is released."""
    if snapshot.released:
        raise ValueError("this snapshot has been released; save a new one")
    # a constraint the look-ahead made (a harpoon fired at its touchdown) is not in the
    # snapshot, and restoreState keeps it: let go of it first
    env.world.release_from_deck()
    env.world.client.restoreState(stateId=snapshot.bullet_state_id)
    state = copy.deepcopy(snapshot.python_state, _shared(env)) if keep else snapshot.python_state
    env.__dict__.update(state)
    if not keep:
        release_snapshot(env, snapshot)


def release_snapshot(env: Any, snapshot: EnvSnapshot) -> None:
    """Free PyBullet's copy of the state (idempotent)."""
    if not snapshot.released:
        env.world.client.removeState(snapshot.bullet_state_id)
        snapshot.released = True
        snapshot.python_state = {}
