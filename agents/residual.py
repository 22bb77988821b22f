"""Residual actions: a learner that corrects a scripted lander rather than replacing it.

Residual reinforcement learning (Johannink et al. 2019, *Residual Reinforcement Learning for
Robot Control*, ICRA; Silver et al. 2018, *Residual Policy Learning*) adds a learned
correction to a hand-designed controller: the action sent to the environment is
``clip(base(observation) + scale · a, -1, 1)`` with ``a`` the learner's action in ``[-1, 1]``.
The learner starts from the controller's behaviour (its correction is near zero at first) and
learns only what the controller lacks; ``scale`` bounds how far it may move from it.

:class:`ResidualLanderWrapper` wraps a ``DeckLanding`` environment so that any SB3 algorithm
trains the correction of a scripted lander (:data:`RESIDUAL_BASES`: ``align-descend``); it is
an rl-zoo3 ``env_wrapper`` as well.  The trained lander (:mod:`agents.lander`) reads the same
settings from its card and applies the same sum when it flies.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from agents.align_descend import build_align_descend
from landing_env.errors import ConfigError, require_choice, require_range

#: the scripted landers a residual may correct: name -> builder(env) of a policy with
#: ``reset()`` and ``__call__(observation) -> Box(4) action``
RESIDUAL_BASES: dict[str, Callable[[Any], Any]] = {
    "align-descend": lambda env: build_align_descend(env, None, ()),
}


def residual_settings(base: Any, scale: Any) -> dict[str, Any]:
    """``{"base", "scale"}`` checked: ``base`` one of :data:`RESIDUAL_BASES`, ``scale`` in
    ``(0, 2]`` (2 lets the correction reach any action from any base action)."""
    require_choice("residual.base", base, tuple(RESIDUAL_BASES))
    if isinstance(scale, bool) or not isinstance(scale, (int, float)):
        raise ConfigError("residual.scale", f"must be a number in (0, 2]; got {scale!r}")
    require_range("residual.scale", float(scale), 0.0, 2.0, low_inclusive=False)
    return {"base": str(base), "scale": float(scale)}


def residual_action(base_action: np.ndarray, correction: np.ndarray, scale: float) -> np.ndarray:
    """The action sent: the base's plus ``scale`` times the correction, clipped to [-1, 1]."""
    total = np.asarray(base_action, dtype=np.float64) + scale * np.asarray(correction, float)
    return np.clip(total, -1.0, 1.0).astype(np.float32)


class ResidualLanderWrapper(gym.Wrapper):
    """A ``DeckLanding`` environment whose action is a correction of the scripted ``base``.

    The observation, reward and spaces are the environment's; ``info["base_action"]`` is what
    the base asked for at the step.  The base sees every observation once, in order, as it
    does when it flies alone.
    """

    def __init__(self, env: gym.Env, base: str = "align-descend", scale: float = 0.5) -> None:
        super().__init__(env)
        #: read by the model card (:func:`agents.timing.cards.env_signature`)
        self.residual_settings = residual_settings(base, scale)
        self.base = RESIDUAL_BASES[self.residual_settings["base"]](env)
        self._observation: dict[str, np.ndarray] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self.base.reset()
        self._observation = observation
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._observation is None:
            raise RuntimeError("ResidualLanderWrapper.step before reset")
        correction = np.asarray(action, dtype=np.float64)
        if correction.shape != self.action_space.shape or not np.all(np.isfinite(correction)):
            raise ValueError(
                f"action must be a finite array of shape {self.action_space.shape} "
                f"(the correction of {self.residual_settings['base']}); got {action!r}"
            )
        base_action = self.base(self._observation)
        total = residual_action(base_action, correction, self.residual_settings["scale"])
        observation, reward, terminated, truncated, info = self.env.step(total)
        self._observation = observation
        info["base_action"] = np.asarray(base_action, dtype=np.float32)
        return observation, reward, terminated, truncated, info


#: the learner's exploration at the start, the standard deviation of its (pre-squash) Gaussian
INITIAL_CORRECTION_STD = 0.1


def start_at_zero_correction(model: Any, std: float = INITIAL_CORRECTION_STD) -> bool:
    """Make a new SAC or TQC model's correction zero (its mean layer zeroed) with a small,
    state-independent exploration ``std``, so that its first episodes fly as the base does
    rather than as an untrained network's bias would; ``True`` when done.  A model with
    gSDE, or of another algorithm, is left as it is (``False``)."""
    import torch

    actor = getattr(model, "actor", None)
    if actor is None or getattr(actor, "use_sde", False):
        return False
    mean, log_std = getattr(actor, "mu", None), getattr(actor, "log_std", None)
    if not isinstance(mean, torch.nn.Linear) or not isinstance(log_std, torch.nn.Linear):
        return False
    with torch.no_grad():
        mean.weight.zero_()
        mean.bias.zero_()
        log_std.weight.zero_()
        log_std.bias.fill_(float(np.log(std)))
    return True
