"""The smallest tag36h11 side (px) that pupil-apriltags decodes in render mode.

The default deck (one 0.30 m tag), the drone pinned level over it at the height that gives
each side, the deck static; 10 frames per side at random small offsets and yaws.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import landing_env  # noqa: F401  (registers the environments)

SIDES_PX = (24, 20, 16, 14, 13, 12, 11, 10, 9)
TAG_SIZE_M = 0.30
FX = 458.5
CAMERA_BELOW_COM_M = 0.03


def main() -> None:
    env = gym.make(
        "DeckLanding-v2",
        config="default",
        overrides={
            "camera.mode": "render",
            "simulation.drone_fixed": True,
            "motion.kind": "static",
            "estimation.observed": "truth",
            "camera.far": 60.0,
            "simulation.arena_max_height_m": 60.0,
        },
    )
    rng = np.random.default_rng(0)
    for side in SIDES_PX:
        height = FX * TAG_SIZE_M / side
        decoded = 0
        for k in range(10):
            offset = rng.uniform(-0.3, 0.3, 2) * height / 4
            _, info = env.reset(
                seed=k,
                options={
                    "height_m": height + CAMERA_BELOW_COM_M,
                    "offset_m": tuple(offset),
                    "yaw": rng.uniform(-np.pi, np.pi),
                },
            )
            decoded += info["tag_miss_reason"] == ""
        print(f"side {side:3d} px (camera {height:5.1f} m): decoded {decoded}/10")
    env.close()


if __name__ == "__main__":
    main()
