"""``lander-model``: a Stable-Baselines3 model that flies ``DeckLanding`` end to end.

The model maps the observation (stacked over the last ``frame_stack`` steps as SB3's
``VecFrameStack`` stacks them in training, and normalised by the ``VecNormalize`` statistics
saved beside it, ``vecnormalize.pkl``, where it was trained with them) to the Box action: the
velocity set-point and, on ``DeckLanding-v2``, the land trigger.  A model whose critic read
the ``privileged`` key (:class:`landing_env.privileged.PrivilegedCriticPolicy`) flies an
environment built without it: its actor never reads the key.  Its card
(:mod:`agents.common.cards`) records the id, the observation's keys and stacking, the
estimator and the sensing it was trained on, and is checked against the environment on load.

Train one with ``deck-landing train landing --config configs/train/lander_ppo.yaml``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from agents.common.cards import (
    METADATA_NAME,
    check_compatible,
    env_signature,
    model_class,
    read_metadata,
)
from agents.policies.base import Policy
from agents.policies.registry import MODEL_DIR, find_model
from landing_env.envs.deck_landing import PRIVILEGED_KEY
from landing_env.errors import ConfigError

#: the ``VecNormalize`` statistics a training run saves beside its models (rl-zoo3's name)
NORMALIZE_NAME = "vecnormalize.pkl"


def normalization_path(model: Path) -> Path:
    """Where the ``VecNormalize`` statistics of the model at ``model`` are saved:
    ``<stem>_vecnormalize.pkl`` beside it (the statistics of that model's own moment of
    training, e.g. the best model's at its evaluation), or, for a checkpoint
    ``<prefix>_<N>_steps.zip``, SB3's ``<prefix>_vecnormalize_<N>_steps.pkl``."""
    checkpoint = re.fullmatch(r"(?P<prefix>.+)_(?P<steps>\d+)_steps", model.stem)
    if checkpoint is not None:
        return model.with_name(
            f"{checkpoint['prefix']}_vecnormalize_{checkpoint['steps']}_steps.pkl"
        )
    return model.with_name(f"{model.stem}_{NORMALIZE_NAME}")


def shipped_lander_model(algo: str) -> Path:
    """Where the trained lander of ``algo`` is installed: ``agents/models/lander_<algo>.zip``."""
    return MODEL_DIR / f"lander_{algo}.zip"


class TrainedLanderPolicy(Policy):
    """A trained SB3 lander acting deterministically on ``DeckLanding`` observations."""

    def __init__(self, path: str | Path, device: str = "cpu") -> None:
        self.path = find_model(path)
        if not self.path.is_file():
            raise FileNotFoundError(
                f"no trained lander at {self.path}; train one with `deck-landing train landing "
                "--config configs/train/lander_ppo.yaml --install`"
            )
        card = read_metadata(self.path)
        if card is None:
            raise ConfigError(
                "model",
                f"{self.path.name} has no card ({METADATA_NAME}); train it with "
                "`deck-landing train landing`",
            )
        if card.observation.get("task") != "DeckLanding":
            raise ConfigError(
                "model",
                f"{self.path.name} was trained on {card.env_id}, not a DeckLanding task: "
                "evaluate it with --policy timing-model",
            )
        self.card = card
        self.frame_stack = int(card.observation.get("frame_stack", 1))
        self.model = model_class(self.path).load(self.path, device=device)
        self.normalize = model_normalization(self.path)
        self._stack: dict[str, np.ndarray] | None = None

    def check_env(self, env: Any, allow_mismatch: tuple[str, ...] = ()) -> None:
        """Refuse ``env`` unless it is what the model was trained on (its card)."""
        signature = env_signature(env, frame_stack=self.frame_stack)
        check_compatible(self.card, signature, self.path.name, allow_mismatch)
        # no mismatch to allow here: a model cannot act in another action space
        trained, have = self.model.action_space.shape, env.action_space.shape
        if trained != have:
            raise ConfigError(
                "model",
                f"{self.path.name} acts with {trained[0]} entries, the environment takes "
                f"{have[0]}: a DeckLanding-v2 lander trained with action.land_trigger "
                f"{'false' if trained[0] == 4 else 'true'} flies only an environment built so",
            )

    def reset(self) -> None:
        """Forget the stacked steps (a new episode starts from zeros, as ``VecFrameStack``)."""
        self._stack = None

    def stacked(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``observation`` stacked with the previous steps along the last axis, oldest first,
        zeros before the episode's first step (what ``VecFrameStack`` gives a model)."""
        if self._stack is None:
            self._stack = {
                key: np.zeros(
                    (*np.shape(value)[:-1], np.shape(value)[-1] * self.frame_stack)
                ).astype(np.float32)
                for key, value in observation.items()
            }
        for key, value in observation.items():
            width = np.shape(value)[-1]
            stack = self._stack[key]
            stack[..., :-width] = stack[..., width:]
            stack[..., -width:] = value
        return {key: value.copy() for key, value in self._stack.items()}

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        stacked = self.stacked(observation)
        spaces = self.model.observation_space.spaces
        if PRIVILEGED_KEY in spaces and PRIVILEGED_KEY not in stacked:
            # the critic's key: the actor never reads it, so any value stands in for it
            stacked[PRIVILEGED_KEY] = np.zeros(spaces[PRIVILEGED_KEY].shape, np.float32)
        if self.normalize is not None:
            stacked = self.normalize.normalize_obs(stacked)
        action, _ = self.model.predict(stacked, deterministic=True)
        return np.asarray(action, dtype=np.float32).reshape(-1)


def model_normalization(model: Path) -> Any:
    """The ``VecNormalize`` statistics of the model at ``model`` (frozen): its own
    (:func:`normalization_path`), else the run's (rl-zoo3's ``vecnormalize.pkl`` beside it),
    else None."""
    own = normalization_path(model)
    return _normalization(own if own.is_file() else model.parent / NORMALIZE_NAME)


def _normalization(path: Path) -> Any:
    """The ``VecNormalize`` saved at ``path`` (its statistics, frozen), or None."""
    if not path.is_file():
        return None
    import pickle

    with path.open("rb") as stream:
        normalize = pickle.load(stream)
    normalize.training = False
    return normalize


def build_lander(env: Any, model_path: str | None, allow: tuple[str, ...]) -> TrainedLanderPolicy:
    """``lander-model`` for ``env``: the trained lander at ``--model``, checked on its card."""
    if not model_path:
        raise ConfigError(
            "--model",
            "lander-model runs a trained lander: give --model PATH (train one with "
            "`deck-landing train landing --config configs/train/lander_ppo.yaml`)",
        )
    policy = TrainedLanderPolicy(model_path)

    policy.check_env(env, allow)
    return policy
