"""An asymmetric actor-critic for ``DeckLanding``: the critic reads the ``privileged`` key (the
truth ``gym.make(id, privileged=True)`` adds), the actor never does.

:class:`PrivilegedCriticPolicy` is SB3's ``MultiInputPolicy`` with
``share_features_extractor=False``: the actor's features extractor (:class:`ActorFeatures`)
drops the ``privileged`` key, the critic's takes every key, and each has its own input width
into its network. Both extractors are :class:`DeckFeatures`, which can add the stopping rule's
margin as a feature (``features_extractor_kwargs``). A trained actor therefore runs on an
environment built without the key. Importing this module registers the class under the alias
``PrivilegedCriticPolicy`` with SB3's on-policy algorithms (PPO, A2C, sb3-contrib's
RecurrentPPO is not covered), so an rl-zoo3 config names it as it names ``MultiInputPolicy``;
importing :mod:`landing_env` does it where SB3 is already loaded
(``rl_zoo3.train --gym-packages landing_env``). The full path
``landing_env.privileged.PrivilegedCriticPolicy`` works in rl-zoo3 too.
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


class DeckFeatures(CombinedExtractor):
    """SB3's ``CombinedExtractor`` (every key flattened and concatenated), with two options.

    ``stopping_rule_key``: the name of the deck-tilt predictor's ``prediction`` key
    (its chances of a level deck at the contact times, the value of waiting on, its validity;
    :meth:`~landing_env.anticipation.onboard_tilt_prediction.DeckPrediction.prediction_values`).
    One feature is appended: the margin of ``predictive``'s stopping rule, the best chance
    minus the value of waiting, over ``stopping_rule_scale`` and clipped to [-1, 1] (-1 while
    the prediction is invalid).  The rule commits where the margin is at least 0; an MLP reads
    that boundary off the observation's chances only to within a few hundredths, and a commit
    a few hundredths early is waved off and spends the band's time.  The key must reach the
    network as the environment gives it: leave it out of ``VecNormalize``'s
    ``norm_obs_keys`` (its values lie in [0, 1]), and stack no frames.
    ``drop_privileged``: leave out the ``privileged`` key (the actor's extractor).
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        stopping_rule_key: str | None = None,
        stopping_rule_scale: float = 0.005,
        drop_privileged: bool = False,
        **kwargs: Any,
    ) -> None:
        space = without_privileged(observation_space) if drop_privileged else observation_space
        super().__init__(space, **kwargs)
        if stopping_rule_key is not None:
            if stopping_rule_key not in space.spaces:
                raise ValueError(
                    f"features_extractor_kwargs.stopping_rule_key: {stopping_rule_key!r} is not "
                    f"an observation key (keys: {', '.join(space.spaces)})"
                )
            width = space.spaces[stopping_rule_key].shape or ()
            if len(width) != 1 or width[0] < 3:
                raise ValueError(
                    f"features_extractor_kwargs.stopping_rule_key: {stopping_rule_key!r} has "
                    f"shape {width}; the prediction key is (chances..., value, valid)"
                )
            if not stopping_rule_scale > 0.0:
                raise ValueError(
                    "features_extractor_kwargs.stopping_rule_scale: "
                    f"{stopping_rule_scale!r} is not a positive number"
                )
            self._features_dim += 1
        self.stopping_rule_key = stopping_rule_key
        self.stopping_rule_scale = float(stopping_rule_scale)

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        features = super().forward(observations)
        if self.stopping_rule_key is None:
            return features
        return th.cat([features, self.stopping_margin(observations[self.stopping_rule_key])], 1)

    def stopping_margin(self, prediction: th.Tensor) -> th.Tensor:
        """The stopping rule's margin feature of a batch of ``prediction`` rows, (N, 1)."""
        prediction = prediction.reshape(prediction.shape[0], -1)
        chances, value, valid = prediction[:, :-2], prediction[:, -2], prediction[:, -1]
        margin = (chances.max(dim=1).values - value) / self.stopping_rule_scale
        margin = th.where(valid > 0.5, margin.clamp(-1.0, 1.0), th.full_like(margin, -1.0))
        return margin.unsqueeze(1)


class ActorFeatures(DeckFeatures):
    """:class:`DeckFeatures` over every key but ``privileged`` (which it never reads)."""

    def __init__(self, observation_space: spaces.Dict, **kwargs: Any) -> None:
        kwargs.pop("drop_privileged", None)
        super().__init__(observation_space, drop_privileged=True, **kwargs)


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
        kwargs.setdefault("features_extractor_class", DeckFeatures)
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
