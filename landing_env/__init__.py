"""deck-landing simulation: a quadrotor over a moving Stewart-platform deck (PyBullet).

Importing the package registers ``DeckLanding-v0`` with Gymnasium.
"""

from gymnasium.envs.registration import register, registry

from landing_env._quiet import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time from C on import
    import pybullet  # noqa: F401

if "DeckLanding-v0" not in registry:
    register(
        id="DeckLanding-v0",
        entry_point="landing_env.envs.deck_landing:DeckLandingEnv",
        disable_env_checker=False,
    )
if "DeckLandingTiming-v0" not in registry:
    register(
        id="DeckLandingTiming-v0",
        entry_point="landing_env.envs.timing:DeckLandingTimingEnv",
        disable_env_checker=False,
    )

__all__ = ["register"]
