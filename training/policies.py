"""Policy classes for Stable-Baselines3 beyond its own: the plan-free learner whose speed is damped by the observed k.

``DampedMlpPolicy`` is PPO's ``MlpPolicy`` whose Gaussian mean is the network's output times the planner
controller's damping factor of the observed inverse condition number, f = clip((k / k_d)², 0.05, 1)
(``envs.controllers.damping_factor``). The factor is a fixed layer, not a learned one: distilled from the damped
planner (``training.distill --damped-output``), the network fits the expert's action divided by f, the undamped
resolved-rate step, and an error of the network near a Type II band is scaled down by f as the expert's own
step is. It reads nothing but the observation, so the policy needs no planner, certificate or model at run time;
it saves, loads, evaluates and exports (``training.export``) as any SB3 policy.

The policy sees the observation normalised by ``VecNormalize``; it recovers k as ``k_mean + k_scale · o[k_index]``
with the normaliser's fixed mean and scale √(var + ε) of that column (``training.distill`` freezes them), which
holds while the normalised k stays inside the normaliser's clip (±10 standard deviations).
"""

from __future__ import annotations

import math
from typing import Any

import torch
from stable_baselines3.common.distributions import DiagGaussianDistribution, Distribution
from stable_baselines3.common.policies import ActorCriticPolicy

from envs.controllers import DAMPING_FLOOR

__all__ = ["DampedMlpPolicy"]


class DampedMlpPolicy(ActorCriticPolicy):
    """``MlpPolicy`` with the Gaussian mean f(k) · μ_θ(o), f the planner's damping of the observed k.

    Args:
        observation_space: The (normalised) observation space, a flat Box.
        action_space: The action space, a Box (the mean is a diagonal Gaussian's).
        lr_schedule: SB3's learning-rate schedule.
        k_index: Column of k in the observation (``envs.kernels.generic.observation_layout``'s "k").
        k_mean: The normaliser's mean of that column (0 without normalisation).
        k_scale: Its scale √(var + ε) (1 without normalisation), > 0.
        damping_threshold: k_d, the k below which f < 1, in (0, 1] (the env's k_safe for the planner's default).
        **kwargs: ``ActorCriticPolicy``'s other arguments (``net_arch``, ``log_std_init``, ...).

    Raises:
        ValueError: If ``k_index`` is not a column of the observation, ``k_mean`` is not finite, ``k_scale`` is
            not a positive finite number, ``damping_threshold`` is not in (0, 1], or the action distribution is
            not a diagonal Gaussian (gSDE is refused).
    """

    def __init__(
        self,
        observation_space: Any,
        action_space: Any,
        lr_schedule: Any,
        *,
        k_index: int,
        k_mean: float,
        k_scale: float,
        damping_threshold: float,
        **kwargs: Any,
    ) -> None:
        shape = getattr(observation_space, "shape", None)
        if shape is None or len(shape) != 1:
            raise ValueError(f"observation_space must be a flat Box, got {observation_space}")
        if isinstance(k_index, bool) or not isinstance(k_index, int) or not 0 <= k_index < shape[0]:
            raise ValueError(f"k_index must be an integer column in [0, {shape[0]}), got {k_index!r}")
        if not math.isfinite(k_mean):
            raise ValueError(f"k_mean must be finite, got {k_mean}")
        if not (math.isfinite(k_scale) and k_scale > 0.0):
            raise ValueError(f"k_scale must be a finite number > 0, got {k_scale}")
        if not 0.0 < damping_threshold <= 1.0:
            raise ValueError(f"damping_threshold must be in (0, 1], got {damping_threshold}")
        if kwargs.get("use_sde", False):
            raise ValueError("DampedMlpPolicy scales a diagonal Gaussian's mean; use_sde must be False, got True")
        self.k_index = int(k_index)
        self.k_mean = float(k_mean)
        self.k_scale = float(k_scale)
        self.damping_threshold = float(damping_threshold)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)
        if not isinstance(self.action_dist, DiagGaussianDistribution):
            raise ValueError(
                f"DampedMlpPolicy needs a diagonal Gaussian action distribution (a Box action space), "
                f"got {type(self.action_dist).__name__}"
            )

    def damping(self, obs: torch.Tensor) -> torch.Tensor:
        """f(k) of each row of a normalised observation batch (B, D): shape (B, 1)."""
        k = self.k_mean + self.k_scale * obs[:, self.k_index : self.k_index + 1].float()
        return torch.clamp((k / self.damping_threshold) ** 2, DAMPING_FLOOR, 1.0)

    def _damped_distribution(self, obs: torch.Tensor, latent_pi: torch.Tensor) -> Distribution:
        mean = self.action_net(latent_pi) * self.damping(obs)
        return self.action_dist.proba_distribution(mean, self.log_std)

    def _latents(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        features = self.extract_features(obs)
        if self.share_features_extractor:
            return self.mlp_extractor(features)
        pi_features, vf_features = features
        return self.mlp_extractor.forward_actor(pi_features), self.mlp_extractor.forward_critic(vf_features)

    def forward(self, obs: torch.Tensor, deterministic: bool = False) -> tuple[torch.Tensor, ...]:
        """Actions, values and log-probabilities (``ActorCriticPolicy.forward`` with the damped mean)."""
        latent_pi, latent_vf = self._latents(obs)
        distribution = self._damped_distribution(obs, latent_pi)
        actions = distribution.get_actions(deterministic=deterministic)
        log_prob = distribution.log_prob(actions)
        return actions.reshape((-1, *self.action_space.shape)), self.value_net(latent_vf), log_prob

    def evaluate_actions(self, obs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Values, log-likelihoods of ``actions`` and entropies (``ActorCriticPolicy.evaluate_actions``)."""
        latent_pi, latent_vf = self._latents(obs)
        distribution = self._damped_distribution(obs, latent_pi)
        return self.value_net(latent_vf), distribution.log_prob(actions), distribution.entropy()

    def get_distribution(self, obs: torch.Tensor) -> Distribution:
        """The action distribution at ``obs`` (what ``predict`` and ``training.export`` use)."""
        features = super().extract_features(obs, self.pi_features_extractor)
        return self._damped_distribution(obs, self.mlp_extractor.forward_actor(features))

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            k_index=self.k_index, k_mean=self.k_mean, k_scale=self.k_scale, damping_threshold=self.damping_threshold
        )
        return data
