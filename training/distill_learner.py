"""The learner of a distillation: its env, normalisation and policy, and its fit to the expert's labels."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

import envs
from training.distill_config import DistillConfig

__all__ = ["band_weights", "fit", "pair_loss", "platform_gains"]


def band_weights(k: np.ndarray, safe_threshold: float, hard_threshold: float, weight: float) -> np.ndarray:
    """Per-pair fit weights 1 + w · clip((k_safe − k) / (k_safe − k_hard), 0, 1) (see the module docstring).

    Args:
        k: Inverse condition numbers of J_x at the pairs' states, shape (S,), dimensionless in [0, 1].
        safe_threshold: k_safe, the env's ``safe_threshold`` (the weight is 1 at and above it).
        hard_threshold: k_hard < k_safe, the env's ``hard_threshold`` (the weight is 1 + w at and below it).
        weight: w ≥ 0.

    Returns:
        Weights, shape (S,), in [1, 1 + w].

    Raises:
        ValueError: If w is negative or not finite, or k_hard ≥ k_safe.
    """
    if not (np.isfinite(weight) and weight >= 0.0):
        raise ValueError(f"band weight must be finite and ≥ 0, got {weight}")
    if not hard_threshold < safe_threshold:
        raise ValueError(f"hard_threshold must be < safe_threshold, got {hard_threshold} and {safe_threshold}")
    depth = np.clip((safe_threshold - np.asarray(k, dtype=np.float64)) / (safe_threshold - hard_threshold), 0.0, 1.0)
    return 1.0 + weight * depth


def platform_gains(params: Any, states: np.ndarray) -> np.ndarray:
    """G = diag(1/tolerances) · J_f(q, x) · max_rate · dt at each state (the platform term of ``pair_loss``).

    G a is the first-order pose change, in success tolerances, of one period at the normalised action a.

    Args:
        params: The env's ``FamilyParams`` (its robot, ``max_rate``, ``dt`` and success tolerances).
        states: Actuator coordinates q then pose x of {P} in {B} per row, shape (S, n + m) (``collect``'s last
            output).

    Returns:
        Shape (S, m, n), dimensionless: row j of G maps an action error (n,) to pose coordinate j's change over
        one period divided by the position tolerance (position columns) or the orientation tolerance (rotation
        columns, ``PoseSpace.rotation_columns``).

    Raises:
        ValueError: If ``states`` is not finite of shape (S, n + m).
    """
    robot = params.robot
    n, m = robot.n_actuators, robot.pose_space.n_pose
    states = np.asarray(states, dtype=np.float64)
    if states.ndim != 2 or states.shape[1] != n + m or not np.isfinite(states).all():
        raise ValueError(f"states must be finite of shape (S, {n + m}) (q then x), got shape {states.shape}")
    tolerance = np.full(m, float(params.success_position_tolerance))
    tolerance[list(robot.pose_space.rotation_columns)] = float(params.success_orientation_tolerance)
    forward = robot.forward_jacobian(states[:, :n], states[:, n:], validate=False)
    return forward * (float(params.max_rate) * float(params.dt) / tolerance)[:, None]


def pair_loss(mean: Any, target: Any, weights: Any, gains: Any | None) -> Any:
    """The fit's loss of a batch: Σ_i w_i (‖e_i‖² + ‖G_i e_i‖²) / (n Σ_i w_i), e_i = μ(o_i) − a_i.

    Args:
        mean: The learner's Gaussian means, torch tensor (B, n).
        target: The labels, torch tensor (B, n).
        weights: Positive pair weights, torch tensor (B,).
        gains: Per-pair matrices G_i (B, m, n) (``platform_gains`` times √λ), or None: the squared error alone.

    Returns:
        A scalar torch tensor.
    """
    import torch

    error = mean - target
    per_pair = torch.sum(error**2, dim=1)
    if gains is not None:
        per_pair = per_pair + torch.sum(torch.einsum("bmn,bn->bm", gains, error) ** 2, dim=1)
    return torch.sum(weights * per_pair) / (torch.sum(weights) * mean.shape[1])


def fit(
    policy: Any,
    observations: np.ndarray,
    actions: np.ndarray,
    config: DistillConfig,
    seed: int,
    weights: np.ndarray | None = None,
    gains: np.ndarray | None = None,
) -> float:
    """Fit the policy's Gaussian mean to ``actions`` (S, n) at normalised ``observations`` (S, D).

    ``weights`` (S,), positive, weigh each pair's loss (None: all the same); ``gains`` (S, m, n), finite, add the
    platform term ‖G_i e_i‖² to it (None: none); the loss of a batch is ``pair_loss``'s. Adam at
    ``config.learning_rate``, annealed to 0 on a cosine over the ``config.epochs`` epochs with ``config.lr_decay``.
    Returns the last epoch's (weighted) loss.
    """
    import torch

    generator = torch.Generator().manual_seed(seed)
    obs_t = torch.as_tensor(observations)
    act_t = torch.as_tensor(np.clip(actions, -1.0, 1.0))
    if weights is None:
        weights = np.ones(len(observations))
    weights = np.asarray(weights, dtype=np.float32)
    if weights.shape != (len(observations),):
        raise ValueError(f"weights must be ({len(observations)},), finite and > 0, got shape {weights.shape}")
    if not np.all(np.isfinite(weights) & (weights > 0.0)):
        raise ValueError(f"weights must be ({len(observations)},), finite and > 0, got a minimum of {weights.min()}")
    w_t = torch.as_tensor(weights)
    g_t = None
    if gains is not None:
        gains = np.asarray(gains, dtype=np.float32)
        expected = f"gains must be ({len(observations)}, m, {actions.shape[1]}) and finite"
        if gains.ndim != 3 or gains.shape[0] != len(observations) or gains.shape[2] != actions.shape[1]:
            raise ValueError(f"{expected}, got shape {gains.shape}")
        if not np.isfinite(gains).all():
            raise ValueError(f"{expected}, got a non-finite entry")
        g_t = torch.as_tensor(gains)
    optimizer = torch.optim.Adam(policy.parameters(), lr=config.learning_rate)
    steps = config.epochs * -(-len(obs_t) // config.batch_size)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=steps) if config.lr_decay else None
    loss_value = float("nan")
    for _ in range(config.epochs):
        order = torch.randperm(len(obs_t), generator=generator)
        total = 0.0
        for start in range(0, len(order), config.batch_size):
            index = order[start : start + config.batch_size]
            mean = policy.get_distribution(obs_t[index]).distribution.mean
            w = w_t[index]
            loss = pair_loss(mean, act_t[index], w, None if g_t is None else g_t[index])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            if schedule is not None:
                schedule.step()
            total += float(loss.detach()) * float(torch.sum(w))
        loss_value = total / float(torch.sum(w_t))
    return loss_value


def _make_env(config: DistillConfig) -> gym.Env:
    """The learner's env: ``config.env_id`` with its keyword arguments, and the previous action if asked for."""
    env = gym.make(config.env_id, **config.env_kwargs)
    return envs.PreviousActionWrapper(env) if config.previous_action else env


def _normalizer(config: DistillConfig, observations: np.ndarray):
    """A frozen ``VecNormalize`` (observations only) with the mean and variance of ``observations``.

    For a ``PlanFreeMlpPolicy`` learner (``damped_output``, ``hold_fraction``, ``error_gain``) it does not clip,
    so that the policy recovers every raw column it reads, however far from the expert's data.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    clip = np.inf if config.damped_output or config.hold_fraction > 0.0 or config.error_gain else 10.0
    venv = DummyVecEnv([lambda: _make_env(config)])
    vec = VecNormalize(venv, norm_obs=True, norm_reward=False, clip_obs=clip)
    vec.obs_rms.mean = observations.mean(axis=0).astype(np.float64)
    vec.obs_rms.var = observations.var(axis=0).astype(np.float64)
    vec.obs_rms.count = float(len(observations))
    vec.training = False
    return vec


def _policy(config: DistillConfig, params: Any, normalizer: Any) -> tuple[Any, dict[str, Any]]:
    """The learner's SB3 policy (a name or a class) and its ``policy_kwargs``."""
    kwargs: dict[str, Any] = {"net_arch": list(config.net_arch), "log_std_init": -1.0}
    if not (config.damped_output or config.hold_fraction > 0.0 or config.error_gain):
        return "MlpPolicy", kwargs
    from envs.kernels.packing import observation_layout
    from training.policies import PlanFreeMlpPolicy

    space = params.robot.pose_space
    layout = observation_layout(space.name, params.robot.n_actuators, False)
    error = range(layout["error"].start, layout["error"].stop)  # the twist's coordinates: δp, then δθ if any
    rotations = [error[j] for j in space.rotation_columns]
    threshold = params.safe_threshold if config.damping_threshold is None else config.damping_threshold
    hold = config.hold_fraction > 0.0
    kwargs.update(
        raw_mean=[float(v) for v in normalizer.obs_rms.mean],
        raw_scale=[float(v) for v in np.sqrt(normalizer.obs_rms.var + normalizer.epsilon)],
        k_index=layout["k"].start,
        damping_threshold=float(threshold) if config.damped_output else None,
        position_columns=[c for c in error if c not in rotations],
        orientation_columns=rotations,
        hold_position=config.hold_fraction * params.success_position_tolerance if hold else None,
        hold_orientation=config.hold_fraction * params.success_orientation_tolerance if hold else None,
        error_gain=config.error_gain,
    )
    return PlanFreeMlpPolicy, kwargs
