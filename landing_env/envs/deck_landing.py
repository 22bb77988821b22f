"""``DeckLanding-v0``: fly from a hover above the moving deck to a touchdown on it."""

from __future__ import annotations

from landing_env.envs.base import DeckLandingBaseEnv


class DeckLandingEnv(DeckLandingBaseEnv):
    """Land on the Stewart-platform deck, steering by velocity set-points.

    Action: Box(4) in [-1, 1] scaled to (vx, vy, vz, yaw rate) of the heading frame.
    Observation: the configured estimator's deck pose (tag in the camera frame) with its
    validity, the four ToF ranges with their validity, and the mean IMU reading of the step.
    The reward and termination rules are those of the base class (see the README).
    """
