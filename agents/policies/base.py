"""What the project's policies share: calling a policy on an observation is its ``act``."""

from __future__ import annotations

from typing import Any


class Policy:
    """A policy: ``act(observation)`` gives the action, and so does calling it; ``reset()``
    starts an episode."""

    def __call__(self, observation: Any) -> Any:
        return self.act(observation)  # type: ignore[attr-defined]
