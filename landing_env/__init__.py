"""deck-landing simulation: a quadrotor over a moving Stewart-platform deck (PyBullet).

Importing the package registers ``DeckLanding-v1``, ``DeckLandingTiming-v0`` and the scenario
ids of :data:`landing_env.scenarios.SCENARIO_IDS` (e.g. ``DeckLandingTiming-BenchSS4-v0``)
with Gymnasium.
"""

from landing_env._quiet import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time from C on import
    import pybullet  # noqa: F401

from landing_env.scenarios import SCENARIO_IDS, register_all

register_all()

__all__ = ["SCENARIO_IDS", "register_all"]
