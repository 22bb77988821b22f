"""deck-landing simulation: a quadrotor over a moving Stewart-platform deck (PyBullet).

Importing the package registers ``DeckLanding-v2``, ``DeckLandingTiming-v0`` and the scenario
ids of :data:`landing_env.scenarios.SCENARIO_IDS` (e.g. ``DeckLandingTiming-BenchSS4-v6``)
with Gymnasium, and, where stable-baselines3 is already loaded (rl-zoo3's
``--gym-packages landing_env``), the policy alias ``PrivilegedCriticPolicy``
(:mod:`landing_env.privileged`).
"""

import sys

from landing_env._quiet import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time from C on import
    import pybullet  # noqa: F401

from landing_env.scenarios import SCENARIO_IDS, register_all

register_all()

if "stable_baselines3" in sys.modules:
    from landing_env.privileged import register_policy_aliases

    register_policy_aliases()

__all__ = ["SCENARIO_IDS", "register_all"]
