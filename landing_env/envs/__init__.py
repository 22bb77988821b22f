"""Gymnasium environments on top of :class:`landing_env.world.World`."""

from landing_env.envs.deck_landing import DeckLandingEnv

__all__ = ["DeckLandingEnv"]
