"""Policy classes for Stable-Baselines3 beyond its own: the plan-free learner's fixed output layers.

``PlanFreeMlpPolicy`` is PPO's ``MlpPolicy`` whose Gaussian mean μ_θ(o) passes through fixed layers that read
the observation alone (no planner, certificate or model at run time):

- **damping** (``damping_threshold`` k_d): the mean is f(k) · μ_θ(o), f = clip((k / k_d)², 0.05, 1) the planner
  controller's damping factor of the observed inverse condition number (``robot_control.controllers.damping_factor``).
  Distilled from the damped planner (``training.distill --damped-output``), the network fits the expert's action
  divided by f, the undamped step, and its error near a Type II band shrinks with f as the expert's step does.
- **in-position hold** (``hold_position`` [m], ``hold_orientation`` [rad]): the mean is 0 while the observed
  position error ‖p* − p‖ and orientation error (|φ* − φ| planar, the rotation vector's norm spatial) are both
  within them, as a servo drive's in-position band: actuators at rest keep the platform still, where the
  learner's own error of a few thousandths of the rate range, amplified by J_f next to an ill-conditioned
  target, would drift it into the band (``training.distill --hold-fraction``).
- **error gain** (``error_gain``): the network's output is a gain matrix M_θ(o) (n × m) and the mean is
  M_θ(o) ẽ, ẽ the observed pose error (the position columns, then the orientation ones) divided by the
  normaliser's scale of each column: the action vanishes at the target (up to the float32 rounding of the
  normalised observation) as the resolved-rate law's K J_i e does,
  so the learner has no bias there to drift on, and it is still any function of the observation that is 0 at
  e = 0 (``training.distill --error-gain``).

The policy sees the observation normalised by ``VecNormalize`` and recovers the columns it reads as
``raw_mean + raw_scale · o`` with the normaliser's fixed mean and scale √(var + ε), which holds where the
normaliser does not clip those columns (``training.distill`` freezes the statistics and turns the clip off). It
saves, loads, evaluates and exports (``training.export``) as any SB3 policy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import torch
from stable_baselines3.common.distributions import DiagGaussianDistribution, Distribution
from stable_baselines3.common.policies import ActorCriticPolicy

from robot_control.controllers import DAMPING_FLOOR

__all__ = ["PlanFreeMlpPolicy"]


def _columns(name: str, columns: Sequence[int], width: int) -> list[int]:
    out = list(columns)
    if any(isinstance(c, bool) or not isinstance(c, int) or not 0 <= c < width for c in out):
        raise ValueError(f"{name} must be integer columns in [0, {width}), got {columns!r}")
    return out


class PlanFreeMlpPolicy(ActorCriticPolicy):
    """``MlpPolicy`` whose Gaussian mean passes through the error gain, the damping and the hold (module docstring).

    Args:
        observation_space: The (normalised) observation space, a flat Box of D columns.
        action_space: The action space, a Box (the mean is a diagonal Gaussian's).
        lr_schedule: SB3's learning-rate schedule.
        raw_mean: The normaliser's mean of each observation column, length D (zeros without normalisation).
        raw_scale: Its scale √(var + ε) of each column, length D, each > 0 (ones without normalisation).
        k_index: Column of k in the observation (``envs.kernels.packing.observation_layout``'s "k").
        damping_threshold: k_d of the damping, in (0, 1] (the env's k_safe for the planner's default); None: no
            damping.
        position_columns: Columns of the position error p* − p [m] (2 planar, 3 spatial and translational).
        orientation_columns: Columns of the orientation error [rad] (1 planar, 3 spatial, none translational).
        hold_position: Position error [m] within which (with the orientation's) the mean is 0, > 0; None: no hold.
        hold_orientation: Orientation error [rad] of the hold, > 0 (with ``hold_position``).
        error_gain: The mean is M_θ(o) ẽ (module docstring); needs ``position_columns``.
        **kwargs: ``ActorCriticPolicy``'s other arguments (``net_arch``, ``log_std_init``, ...).

    Raises:
        ValueError: If a column is outside the observation, ``raw_mean`` or ``raw_scale`` has the wrong length or
            a non-finite (or, for the scale, non-positive) entry, ``damping_threshold`` is not in (0, 1], a hold
            tolerance is not positive and finite or is given without the other, or the action distribution is not
            a diagonal Gaussian (gSDE is refused).
    """

    def __init__(
        self,
        observation_space: Any,
        action_space: Any,
        lr_schedule: Any,
        *,
        raw_mean: Sequence[float],
        raw_scale: Sequence[float],
        k_index: int,
        damping_threshold: float | None = None,
        position_columns: Sequence[int] = (),
        orientation_columns: Sequence[int] = (),
        hold_position: float | None = None,
        hold_orientation: float | None = None,
        error_gain: bool = False,
        **kwargs: Any,
    ) -> None:
        shape = getattr(observation_space, "shape", None)
        if shape is None or len(shape) != 1:
            raise ValueError(f"observation_space must be a flat Box, got {observation_space}")
        width = shape[0]
        self.k_index = _columns("k_index", [k_index], width)[0]
        self.position_columns = _columns("position_columns", position_columns, width)
        self.orientation_columns = _columns("orientation_columns", orientation_columns, width)
        mean, scale = [float(v) for v in raw_mean], [float(v) for v in raw_scale]
        if len(mean) != width or not all(math.isfinite(v) for v in mean):
            raise ValueError(f"raw_mean must hold {width} finite numbers, got {len(mean)}: {raw_mean!r}")
        if len(scale) != width or not all(math.isfinite(v) and v > 0.0 for v in scale):
            raise ValueError(f"raw_scale must hold {width} finite numbers > 0, got {len(scale)}: {raw_scale!r}")
        if damping_threshold is not None and not 0.0 < damping_threshold <= 1.0:
            raise ValueError(f"damping_threshold must be None or in (0, 1], got {damping_threshold}")
        hold = (hold_position, hold_orientation)
        if (hold_position is None) != (hold_orientation is None) or not all(
            v is None or (math.isfinite(v) and v > 0.0) for v in hold
        ):
            raise ValueError(
                f"hold_position [m] and hold_orientation [rad] must both be None or both > 0, got {hold!r}"
            )
        if hold_position is not None and not self.position_columns:
            raise ValueError("an in-position hold needs position_columns, got none")
        if error_gain and not self.position_columns:
            raise ValueError("an error gain needs position_columns, got none")
        self.error_gain = bool(error_gain)
        if kwargs.get("use_sde", False):
            raise ValueError("PlanFreeMlpPolicy shapes a diagonal Gaussian's mean; use_sde must be False, got True")
        self.raw_mean, self.raw_scale = mean, scale
        self.damping_threshold = None if damping_threshold is None else float(damping_threshold)
        self.hold_position = None if hold_position is None else float(hold_position)
        self.hold_orientation = None if hold_orientation is None else float(hold_orientation)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)
        if not isinstance(self.action_dist, DiagGaussianDistribution):
            raise ValueError(
                f"PlanFreeMlpPolicy needs a diagonal Gaussian action distribution (a Box action space), "
                f"got {type(self.action_dist).__name__}"
            )
        self.register_buffer("_raw_mean", torch.tensor(mean, dtype=torch.float64), persistent=False)
        self.register_buffer("_raw_scale", torch.tensor(scale, dtype=torch.float64), persistent=False)
        for name, columns in (
            ("k", [self.k_index]),
            ("position", self.position_columns),
            ("orientation", self.orientation_columns),
            ("error", self.position_columns + self.orientation_columns),
        ):
            self.register_buffer(f"_{name}_columns", torch.tensor(columns, dtype=torch.long), persistent=False)

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        if self.error_gain:  # the actor's head gives the n × m gain matrix, initialised as SB3 does its head
            n, m = self.action_space.shape[0], len(self.position_columns) + len(self.orientation_columns)
            self.action_net = torch.nn.Linear(self.mlp_extractor.latent_dim_pi, n * m)
            if self.ortho_init:
                self.action_net.apply(lambda module: self.init_weights(module, gain=0.01))
            self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _raw(self, obs: torch.Tensor, columns: torch.Tensor) -> torch.Tensor:
        """The raw values (B, C) of ``columns`` (C,) of a normalised observation batch, float64."""
        return self._raw_mean[columns] + self._raw_scale[columns] * obs[:, columns].double()

    def gate(self, obs: torch.Tensor) -> torch.Tensor:
        """The factor (B, 1) the network's output is multiplied by: f(k), 0 within the hold, 1 without either."""
        factor = torch.ones((obs.shape[0], 1), dtype=torch.float64)
        if self.damping_threshold is not None:
            k = self._raw(obs, self._k_columns)
            factor = torch.clamp((k / self.damping_threshold) ** 2, DAMPING_FLOOR, 1.0)
        if self.hold_position is not None:
            inside = torch.linalg.vector_norm(self._raw(obs, self._position_columns), dim=1) <= self.hold_position
            if self.orientation_columns:
                angle = torch.linalg.vector_norm(self._raw(obs, self._orientation_columns), dim=1)
                inside = inside & (angle <= self.hold_orientation)
            factor = torch.where(inside[:, None], torch.zeros_like(factor), factor)
        return factor.float()

    def _gated_distribution(self, obs: torch.Tensor, latent_pi: torch.Tensor) -> Distribution:
        out = self.action_net(latent_pi)
        if self.error_gain:
            columns = self._error_columns
            scaled = (self._raw(obs, columns) / self._raw_scale[columns]).float()
            out = torch.einsum("bij,bj->bi", out.view(out.shape[0], -1, columns.shape[0]), scaled)
        mean = out * self.gate(obs)
        return self.action_dist.proba_distribution(mean, self.log_std)

    def _latents(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        features = self.extract_features(obs)
        if self.share_features_extractor:
            return self.mlp_extractor(features)
        pi_features, vf_features = features
        return self.mlp_extractor.forward_actor(pi_features), self.mlp_extractor.forward_critic(vf_features)

    def forward(self, obs: torch.Tensor, deterministic: bool = False) -> tuple[torch.Tensor, ...]:
        """Actions, values and log-probabilities (``ActorCriticPolicy.forward`` with the gated mean)."""
        latent_pi, latent_vf = self._latents(obs)
        distribution = self._gated_distribution(obs, latent_pi)
        actions = distribution.get_actions(deterministic=deterministic)
        log_prob = distribution.log_prob(actions)
        return actions.reshape((-1, *self.action_space.shape)), self.value_net(latent_vf), log_prob

    def evaluate_actions(self, obs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Values, log-likelihoods of ``actions`` and entropies (``ActorCriticPolicy.evaluate_actions``)."""
        latent_pi, latent_vf = self._latents(obs)
        distribution = self._gated_distribution(obs, latent_pi)
        return self.value_net(latent_vf), distribution.log_prob(actions), distribution.entropy()

    def get_distribution(self, obs: torch.Tensor) -> Distribution:
        """The action distribution at ``obs`` (what ``predict`` and ``training.export`` use)."""
        features = super().extract_features(obs, self.pi_features_extractor)
        return self._gated_distribution(obs, self.mlp_extractor.forward_actor(features))

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            raw_mean=self.raw_mean,
            raw_scale=self.raw_scale,
            k_index=self.k_index,
            damping_threshold=self.damping_threshold,
            position_columns=self.position_columns,
            orientation_columns=self.orientation_columns,
            hold_position=self.hold_position,
            hold_orientation=self.hold_orientation,
            error_gain=self.error_gain,
        )
        return data
