"""An asymmetric actor-critic for ``DeckLanding``: the critic reads the ``privileged`` key
(the truth ``gym.make(id, privileged=True)`` adds), the actor never does.

:class:`PrivilegedCriticPolicy` is SB3's ``MultiInputPolicy`` with
``share_features_extractor=False``: the actor's features extractor
(:class:`ActorFeatures`) drops the ``privileged`` key, the critic's takes every key, and each
has its own input width into its network.  A trained actor therefore runs on an environment
built without the key.  Importing this module registers the class under the alias
``PrivilegedCriticPolicy`` with SB3's on-policy algorithms (PPO, A2C, sb3-contrib's
RecurrentPPO is not covered), so an rl-zoo3 config names it as it names ``MultiInputPolicy``;
importing :mod:`landing_env` does it where SB3 is already loaded (``rl_zoo3.train
--gym-packages landing_env``).  The full path ``landing_env.privileged.PrivilegedCriticPolicy``
works in rl-zoo3 too.
"""

from __future__ import annotations

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import MultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import CombinedExtractor, MlpExtractor
from torch import nn

from landing_env.envs.deck_landing import PRIVILEGED_KEY

#: the alias an rl-zoo3 config (``policy: PrivilegedCriticPolicy``) names the policy by
POLICY_ALIAS = "PrivilegedCriticPolicy"


def without_privileged(space: spaces.Dict) -> spaces.Dict:
    """The observation space as the actor sees it: every key but ``privileged``."""
    return spaces.Dict({k: v for k, v in space.spaces.items() if k != PRIVILEGED_KEY})


class ActorFeatures(CombinedExtractor):
    """SB3's ``CombinedExtractor`` over every key but ``privileged`` (which it never reads)."""

    def __init__(self, observation_space: spaces.Dict, **kwargs: Any) -> None:
        super().__init__(without_privileged(observation_space), **kwargs)


class _TwoInputMlp(nn.Module):
    """SB3's ``MlpExtractor`` with its own input width for the actor and for the critic."""

    def __init__(
        self, pi_dim: int, vf_dim: int, net_arch: Any, activation_fn: type[nn.Module], device: Any
    ) -> None:
        super().__init__()
        self.actor = MlpExtractor(pi_dim, net_arch, activation_fn, device)
        self.critic = MlpExtractor(vf_dim, net_arch, activation_fn, device)
        self.latent_dim_pi = self.actor.latent_dim_pi
        self.latent_dim_vf = self.critic.latent_dim_vf

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        return self.actor.forward_actor(features)

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        return self.critic.forward_critic(features)


class PrivilegedCriticPolicy(MultiInputActorCriticPolicy):
    """``MultiInputPolicy`` whose actor does not see the ``privileged`` key and whose critic
    does (``share_features_extractor`` is always False).  Without the key in the observation
    space both read the same keys, as ``MultiInputPolicy`` with separate extractors."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["share_features_extractor"] = False
        super().__init__(*args, **kwargs)

    def make_features_extractor(self) -> Any:
        # SB3 makes the actor's extractor first (``features_extractor``), then the critic's
        if not isinstance(getattr(self, "features_extractor", None), nn.Module):
            return ActorFeatures(self.observation_space, **self.features_extractor_kwargs)
        return super().make_features_extractor()

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = _TwoInputMlp(  # type: ignore[assignment]
            self.pi_features_extractor.features_dim,
            self.vf_features_extractor.features_dim,
            self.net_arch,
            self.activation_fn,
            self.device,
        )


def register_policy_aliases() -> None:
    """Name :class:`PrivilegedCriticPolicy` ``PrivilegedCriticPolicy`` for SB3's on-policy
    algorithms (idempotent)."""
    from stable_baselines3 import A2C, PPO

    for algorithm in (PPO, A2C):
        algorithm.policy_aliases = {
            **algorithm.policy_aliases,
            POLICY_ALIAS: PrivilegedCriticPolicy,
        }


__all__ = [
    "POLICY_ALIAS",
    "ActorFeatures",
    "PrivilegedCriticPolicy",
    "register_policy_aliases",
    "without_privileged",
]
