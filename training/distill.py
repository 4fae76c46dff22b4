"""Plan-free policies: the planner distilled into an SB3 policy by behaviour cloning, then DAgger.

Usage::

    python -m training.distill --env Planar3RPRReachMixed-v0 --seed 1 --run-dir runs/distill-3rpr-s1
    python -m training.evaluate --run runs/distill-3rpr-s1 --env Planar3RPRReach-v0 --targets hard --episodes 100

The *expert* is ``envs.controllers.PlannerController`` whose ``envs.planner.PathFollower`` plans afresh whenever
the platform is more than ``replan_distance`` from its path, so that its action is a function of the pose and
the target alone (what a policy that sees only the observation can learn). The *learner* is Stable-Baselines3
PPO's ``MlpPolicy`` on the env's own observation, normalised by fixed statistics of the expert's data (no planner
at run time). Training (the DAgger of Ross, Gordon and Bagnell, 2011, written on SB3's policy class because the
``imitation`` library pins Gymnasium 0.29):

1. Behaviour cloning: ``expert_episodes`` episodes driven by the expert; the learner's Gaussian mean is fitted to
   the expert's actions (mean squared error, Adam) on the (observation, action) pairs.
2. DAgger: ``iterations`` rounds of ``episodes`` episodes in which the learner acts (the expert instead, per
   step, with probability β: ``beta`` in the first round, 0 after) and the expert labels every state visited;
   the learner is refitted on all pairs gathered so far. With ``band_weight`` w > 0 each pair's squared error is
   weighted by 1 + w · clip((k_safe − k) / (k_safe − k_hard), 0, 1), where k is the inverse condition number of
   J_x at the pair's state and k_safe, k_hard are the env's ``safe_threshold`` and ``hard_threshold``: the few
   states near the band, where an error of a few per cent of the rate range ends the episode, weigh up to 1 + w
   times the many far from it.
3. With ``select_round="best"``, the learner of the round that did best when it acted (success rate minus
   singularity terminations per episode (every reason of ``training.evaluate.SINGULARITY_REASONS``, Newton
   failures and assembly-mode changes included), on that round's training episodes; the last learner is scored on
   ``episodes`` more) is kept, as DAgger's guarantee is for the best of its policies; with "last", the last one.
   With "validated", every round's learner (the behaviour-cloned one included) acts alone on the same
   ``select_episodes`` hard and ``select_episodes`` standard validation episodes (reset seeds from
   ``3_000_000 · (seed + 1)`` on, away from the training and the evaluation seeds; no expert, no labels) and the
   one with the highest success rate minus singularity terminations per episode, over both sets, is kept: the
   rounds' own training episodes are few and on mixed targets, so their scores differ by less than their noise.
4. Optionally ``ppo_steps`` of PPO fine-tuning of the folder, in place (``finetune``).

With ``start_episodes`` N > 0, each round (behaviour cloning included) also runs N episodes cut after
``start_steps`` steps, acted as the round's full episodes are and labelled the same way: most pairs of full
episodes hold the platform at its target, while the approach, where a step at full speed beside a thin band must
be precise (the 3-RRR), is a few per cent of them.

With ``damped_output``, ``hold_fraction`` or ``error_gain`` the learner is ``training.policies.PlanFreeMlpPolicy``,
whose mean passes through fixed layers of the observation: the expert's own damping factor f(k) of the observed k
(the network then fits the undamped step), an in-position hold (the mean is 0 while the observed errors are within
``hold_fraction`` times the env's success tolerances), and an error gain (the network gives a matrix that
multiplies the observed pose error, so that the action is 0 at the target).

With ``platform_loss`` λ > 0 each pair's loss also counts the platform motion its action error causes:
λ ‖G (μ(o) − a)‖², G = diag(1/tolerances) · J_f(q, x) · max_rate · dt (``platform_gains``), the one-step pose
change of a unit action error in success tolerances at the pair's state. Beside a Type II band J_f is large, and an
action error too small to matter elsewhere turns the platform into the band; the plain squared error weighs it
as it weighs the same error far from the band.

With ``action_noise`` σ > 0 every training episode (the expert's, the cut ones and the learner's) executes its action
plus Gaussian noise of standard deviation σ per actuator (in units of the rate range, clipped to it), while the
label stays the expert's clean action: the noise injection of DART (Laskey et al., 2017). The learner then sees
labelled states around its own path, in the directions its errors take it, rather than only on it. The rounds'
figures (and the ``select_round="best"`` scores) are those of the noisy episodes.

With ``previous_action`` the learner sees its own previous action too (``envs.PreviousActionWrapper``, named as
the run's ``env_wrapper``): the direction it is moving in, which tells the way around already taken where the
pose alone leaves two about equally good; the expert still reads the env's own observation.

``finetune`` (``--from-run``) fine-tunes a distilled run with PPO on the env's own reward: the critic alone is
fitted first (``warmup_steps``, the actor frozen, so that the first policy updates use a value function of the
distilled policy rather than a random one), then actor and critic together with a small step (learning rate
``learning_rate``, clip range 0.1 and an early stop at a KL divergence of ``target_kl`` per update).

The run folder is a ``training.train`` run folder (``config.yml``, ``model.zip``, ``vecnormalize.pkl``), so
``training.evaluate --run`` scores it like any other; ``distill.json`` holds the per-round figures and the time
per decision of the learner against the expert's planning time. Episodes reset with seeds from
``1_000_000 · (seed + 1)`` on, away from the evaluation seeds.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs
from envs.controllers import PlannerController
from envs.planner import PathFollower
from training.config import resolve_env_wrapper
from training.evaluate import SINGULARITY_REASONS, EvaluationError, evaluate_agent, parse_env_kwargs

__all__ = [
    "DistillConfig",
    "FinetuneConfig",
    "band_weights",
    "collect",
    "distill",
    "finetune",
    "fit",
    "main",
    "pair_loss",
    "platform_gains",
]


@dataclass(frozen=True)
class DistillConfig:
    """Settings of one distillation run (the command-line options of ``main``)."""

    env_id: str = "Planar3RPRReachMixed-v0"
    #: Keyword arguments of ``gym.make`` (``{"targets": "mixed"}`` on a robot without a Mixed id).
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    expert_episodes: int = 200
    iterations: int = 6
    episodes: int = 100
    beta: float = 0.5
    epochs: int = 15
    batch_size: int = 256
    learning_rate: float = 1e-3
    net_arch: tuple[int, ...] = (256, 256)
    planner: str = "auto"
    replan_distance: float = 0.03
    lookahead: float = 0.1
    ppo_steps: int = 0
    #: "last": keep the last round's learner; "best": the round's learner that did best when it acted;
    #: "validated": the one that does best on ``select_episodes`` validation episodes per target set.
    select_round: str = "last"
    select_episodes: int = 200
    #: The expert's speed damping near the band (``PlannerController``'s ``damping``; the shipped plan-free
    #: policies were distilled with it).
    expert_damping: bool = False
    #: k_d of the expert's damping (``PlannerController``'s ``damping_threshold``); None: the env's k_safe.
    damping_threshold: float | None = None
    #: The expert's ``PlannerController`` ``damping_kind``: "scale" or "cap".
    damping_kind: str = "scale"
    #: w of the band weighting of the fit (0: every pair weighs the same; see the module docstring).
    band_weight: float = 0.0
    #: Anneal each fit's learning rate to 0 on a cosine over its epochs (False: constant ``learning_rate``), so
    #: that the learner a round keeps is a converged iterate rather than the last of Adam's full-size steps.
    lr_decay: bool = False
    #: Label with the first-order resolved-rate step J_i ẋ (``PlannerController``'s ``exact_step=False``) instead
    #: of the exact step to the aimed pose.
    first_order_expert: bool = False
    #: The learner also sees its own previous action (``envs.PreviousActionWrapper``; the run's ``env_wrapper``).
    previous_action: bool = False
    #: Each round also runs this many episodes cut after ``start_steps`` steps (the expert acting in round 0, as
    #: the round's full episodes otherwise): the approach, where a step at full speed beside the band must be
    #: precise, is a few per cent of full episodes' pairs, most of which hold the platform at its target.
    start_episodes: int = 0
    start_steps: int = 40
    #: The learner's mean is its network's output times the expert's damping factor of the observed k
    #: (``training.policies.PlanFreeMlpPolicy``); needs ``expert_damping`` with ``damping_kind`` "scale".
    damped_output: bool = False
    #: h > 0: the learner's mean is 0 while the observed position and orientation errors are within h times the
    #: env's success tolerances (``training.policies.PlanFreeMlpPolicy``'s in-position hold); 0: no hold.
    hold_fraction: float = 0.0
    #: The learner's network gives a gain matrix that multiplies the observed pose error
    #: (``training.policies.PlanFreeMlpPolicy``'s error gain): its action is 0 at the target.
    error_gain: bool = False
    #: λ ≥ 0 of the platform term λ ‖G (μ(o) − a)‖² of each pair's loss (``platform_gains``; 0: none).
    platform_loss: float = 0.0
    #: σ ≥ 0 of the Gaussian noise on every training episode's executed action (DART; 0: none).
    action_noise: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.action_noise) and 0.0 <= self.action_noise < 1.0):
            raise ValueError(f"action_noise must be in [0, 1), got {self.action_noise}")
        if not (np.isfinite(self.platform_loss) and self.platform_loss >= 0.0):
            raise ValueError(f"platform_loss must be finite and ≥ 0, got {self.platform_loss}")
        if not 0.0 <= self.hold_fraction < 1.0:
            raise ValueError(f"hold_fraction must be in [0, 1), got {self.hold_fraction}")
        if self.start_episodes < 0 or self.start_steps < 1:
            raise ValueError(
                f"start_episodes must be ≥ 0 and start_steps ≥ 1, got {self.start_episodes} and {self.start_steps}"
            )
        if self.damped_output and not (self.expert_damping and self.damping_kind == "scale"):
            raise ValueError(
                "damped_output needs expert_damping with damping_kind 'scale' (the label is then f times the "
                f"network's target), got expert_damping={self.expert_damping}, damping_kind={self.damping_kind!r}"
            )


@dataclass(frozen=True)
class FinetuneConfig:
    """Settings of a PPO fine-tuning of a distilled run (``finetune``)."""

    steps: int = 1_000_000
    warmup_steps: int = 100_000
    n_envs: int = 16
    n_steps: int = 128
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 1e-4
    clip_range: float = 0.1
    target_kl: float = 0.02
    gamma: float = 0.98
    gae_lambda: float = 0.95
    log_std: float = -1.6
    seed: int = 0
    #: Env keyword arguments of the fine-tuning env only, over the distilled run's (a reward setting such as
    #: ``termination_penalty``); the run folder keeps the distilled run's, so it is evaluated on the env it was
    #: distilled on.
    reward_kwargs: dict[str, Any] = field(default_factory=dict)


def _expert(env: gym.Env, config: DistillConfig) -> PlannerController:
    params = env.unwrapped.params
    follower = PathFollower(params, config.lookahead, config.planner, config.replan_distance)
    return PlannerController(
        params,
        follower=follower,
        damping=config.expert_damping,
        damping_threshold=config.damping_threshold,
        damping_kind=config.damping_kind,
        exact_step=not config.first_order_expert,
    )


def collect(
    env: gym.Env,
    expert: PlannerController,
    learner: Any | None,
    episodes: int,
    beta: float,
    first_seed: int,
    rng: np.random.Generator,
    max_steps: int | None = None,
    noise: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, float], np.ndarray]:
    """Run episodes, acting with the learner (or the expert with probability ``beta``), labelled by the expert.

    Args:
        env: A ``gym.make`` Reach environment, possibly wrapped in ``envs.PreviousActionWrapper`` (the expert then
            reads the env's own observation, the first columns).
        expert: The labelling planner controller (its plan log is cleared first, then holds these episodes' plans).
        learner: A function of one observation (D,) to an action (n,), or None (the expert acts).
        episodes: Number of episodes; episode i resets with seed ``first_seed + i``.
        beta: Probability that the expert's action is executed at a step.
        first_seed: Reset seed of the first episode.
        rng: The generator of the β draws.
        max_steps: Cut every episode after this many steps (None: run each to its end); a cut episode counts as
            a success if its last step ends within the tolerances.
        noise: σ ≥ 0 of the Gaussian noise added to each executed action (clipped to [−1, 1]), drawn from ``rng``;
            the labels stay the expert's clean actions.

    Returns:
        (observations (S, D) float32, expert actions (S, n) float32, the true inverse condition number of J_x at
        each observation's state (S,) float64 (from the env's info), figures: success rate, singularity
        terminations per episode (the reasons of ``training.evaluate.SINGULARITY_REASONS``), mean episode length,
        mean planning time [s]), the true state of each pair: actuator coordinates q then pose x of {P} in {B}
        (S, n + m) float64 (``envs.FamilyState``'s ``q`` and ``x``)).

    Raises:
        ValueError: If ``noise`` is negative or not finite.
    """
    if not (np.isfinite(noise) and noise >= 0.0):
        raise ValueError(f"noise must be finite and ≥ 0, got {noise}")
    observations, actions, conditioning, states = [], [], [], []
    successes = singular = steps = 0
    expert.log.clear()  # the plans of these episodes alone
    width = env.unwrapped.observation_space.shape[0]  # the env's own observation, without a wrapper's columns
    for i in range(episodes):
        obs, info = env.reset(seed=first_seed + i)
        for t in itertools.count(1):
            label = expert(obs[None, :width])[0]
            observations.append(obs)
            actions.append(label)
            conditioning.append(float(info["inverse_condition_number"]))
            state = env.unwrapped.state
            states.append(np.concatenate([state.q[0], state.x[0]]))
            act = label if learner is None or rng.random() < beta else learner(obs)
            if noise > 0.0:
                act = np.clip(act + rng.normal(0.0, noise, size=np.shape(act)), -1.0, 1.0)
            obs, _, terminated, truncated, info = env.step(act)
            steps += 1
            if terminated or truncated or t == max_steps:
                successes += bool(info.get("is_success", False))
                singular += info.get("termination_reason") in SINGULARITY_REASONS
                break
    plans = list(expert.log)
    figures = {
        "success_rate": successes / episodes,
        "singular_terminations": singular / episodes,
        "mean_length": steps / episodes,
        "mean_planning_s": float(np.mean([p.seconds for p in plans])) if plans else 0.0,
        "plans_per_episode": len(plans) / episodes,
    }
    return (
        np.asarray(observations, dtype=np.float32),
        np.asarray(actions, dtype=np.float32),
        np.asarray(conditioning, dtype=np.float64),
        figures,
        np.asarray(states, dtype=np.float64).reshape(len(observations), -1),
    )


def validate(env: gym.Env, learner: Any, episodes: int, first_seed: int) -> dict[str, float]:
    """The learner alone on ``episodes`` hard and ``episodes`` standard episodes (reset seeds ``first_seed + i``).

    Args:
        env: A Reach env whose reset takes the ``targets`` option (possibly wrapped).
        learner: A function of one observation (D,) to an action (n,).
        episodes: Episodes per target set, ≥ 1.
        first_seed: Reset seed of each set's first episode.

    Returns:
        success rate and singularity terminations per episode (``training.evaluate``'s records) over both sets,
        and the hard set's alone ("hard_success_rate", "hard_singular_terminations").
    """
    counts = {}
    for targets in ("hard", "standard"):
        records = evaluate_agent(lambda o: np.stack([learner(x) for x in o]), env, episodes, first_seed, targets)
        counts[targets] = (
            float(np.mean([r.success for r in records])),
            float(np.mean([r.singularity_termination for r in records])),
        )
    return {
        "success_rate": (counts["hard"][0] + counts["standard"][0]) / 2,
        "singular_terminations": (counts["hard"][1] + counts["standard"][1]) / 2,
        "hard_success_rate": counts["hard"][0],
        "hard_singular_terminations": counts["hard"][1],
    }


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
    from envs.kernels.generic import observation_layout
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


def distill(config: DistillConfig, run_dir: Path, log=print) -> dict[str, Any]:
    """Train a plan-free policy (see the module docstring) and write its run folder; returns the figures."""
    import torch
    from stable_baselines3 import PPO

    torch.manual_seed(config.seed)
    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(config.seed)
    env = _make_env(config)
    expert = _expert(env, config)
    seed = 1_000_000 * (config.seed + 1)
    clock = time.perf_counter()
    params = env.unwrapped.params

    def weigh(k: np.ndarray) -> np.ndarray:
        return band_weights(k, params.safe_threshold, params.hard_threshold, config.band_weight)

    def gains(states: np.ndarray) -> np.ndarray | None:
        """√λ G of each pair (``platform_gains``), or None without a platform loss."""
        if config.platform_loss == 0.0:
            return None
        return np.sqrt(config.platform_loss) * platform_gains(params, states)

    def with_starts(obs, act, k, states, learner, beta):
        """The round's pairs and those of its ``start_episodes`` cut episodes (each array concatenated)."""
        nonlocal seed
        if config.start_episodes == 0:
            return obs, act, k, states
        more = collect(
            env, expert, learner, config.start_episodes, beta, seed, rng, config.start_steps, noise=config.action_noise
        )
        seed += config.start_episodes
        return tuple(np.concatenate([a, b]) for a, b in zip((obs, act, k, states), (*more[:3], more[4]), strict=True))

    weigh(np.zeros(1))  # refuse a bad band weight before any episode
    obs, act, k, figures, states = collect(
        env, expert, None, config.expert_episodes, 1.0, seed, rng, noise=config.action_noise
    )
    seed += config.expert_episodes
    obs, act, k, states = with_starts(obs, act, k, states, None, 1.0)
    rounds = [{"round": 0, "beta": 1.0, "pairs": len(obs), **figures, "seconds": time.perf_counter() - clock}]
    log(f"expert: {figures['success_rate']:.0%} success, {len(obs)} pairs")
    normalizer = _normalizer(config, obs)
    policy_name, policy_kwargs = _policy(config, params, normalizer)
    model = PPO(policy_name, normalizer, seed=config.seed, device="cpu", policy_kwargs=policy_kwargs, verbose=0)
    policy = model.policy

    def learner(o: np.ndarray) -> np.ndarray:
        action, _ = model.predict(normalizer.normalize_obs(o[None]), deterministic=True)
        return np.clip(action[0], -1.0, 1.0)

    all_obs, all_act, all_k, all_states = [obs], [act], [k], [states]
    rounds[0]["mse"] = fit(policy, normalizer.normalize_obs(obs), act, config, config.seed, weigh(k), gains(states))
    snapshots = [copy.deepcopy(policy.state_dict())]  # the learner after each round's fit
    for r in range(1, config.iterations + 1):
        clock = time.perf_counter()
        beta = config.beta if r == 1 else 0.0
        obs, act, k, figures, states = collect(
            env, expert, learner, config.episodes, beta, seed, rng, noise=config.action_noise
        )
        seed += config.episodes
        obs, act, k, states = with_starts(obs, act, k, states, learner, beta)
        all_obs.append(obs)
        all_act.append(act)
        all_k.append(k)
        all_states.append(states)
        data_obs, data_act = np.concatenate(all_obs), np.concatenate(all_act)
        data_weights, data_gains = weigh(np.concatenate(all_k)), gains(np.concatenate(all_states))
        mse = fit(
            policy, normalizer.normalize_obs(data_obs), data_act, config, config.seed + r, data_weights, data_gains
        )
        rounds.append(
            {"round": r, "beta": beta, "pairs": len(data_obs), **figures, "mse": mse,
             "seconds": time.perf_counter() - clock}
        )  # fmt: skip
        snapshots.append(copy.deepcopy(policy.state_dict()))
        log(
            f"round {r} (β {beta}): learner {figures['success_rate']:.0%} success, "
            f"{figures['singular_terminations']:.2f} singular/episode; {len(data_obs)} pairs, fit loss {mse:.4f}"
        )
    kept = len(snapshots) - 1
    if config.select_round == "best" and config.iterations > 0:
        # the last learner has not acted yet: score it on as many fresh training episodes
        _, _, _, figures, _ = collect(env, expert, learner, config.episodes, 0.0, seed, rng, noise=config.action_noise)
        seed += config.episodes
        rounds.append({"round": len(snapshots), "beta": 0.0, "scoring_only": True, **figures})
        # round r's figures score the learner fitted after round r − 1 (rounds with β > 0 are the expert's too)
        scores = {
            r["round"] - 1: r["success_rate"] - r["singular_terminations"] for r in rounds[1:] if r["beta"] == 0.0
        }
        kept = max(scores, key=lambda i: (scores[i], i))
        policy.load_state_dict(snapshots[kept])
        log(f"kept the learner of round {kept} (score {scores[kept]:.2f}: success − singular per episode)")
    elif config.select_round == "validated":
        validation = []
        for i, snapshot in enumerate(snapshots):
            policy.load_state_dict(snapshot)
            figures = validate(env, learner, config.select_episodes, 3_000_000 * (config.seed + 1))
            validation.append(
                {"round": i, **figures, "score": figures["success_rate"] - figures["singular_terminations"]}
            )
            log(
                f"validated round {i}: {figures['success_rate']:.1%} success, "
                f"{figures['singular_terminations']:.3f} singular/episode"
            )
        kept = max(range(len(snapshots)), key=lambda i: (validation[i]["score"], i))
        policy.load_state_dict(snapshots[kept])
        rounds_validation = validation
        log(f"kept the learner of round {kept} (validation score {validation[kept]['score']:.3f})")
    model.save(run_dir / "model.zip")
    normalizer.save(str(run_dir / "vecnormalize.pkl"))
    # time per decision of the learner (one observation) against the expert's planning time per episode
    sample = np.concatenate(all_obs)[:200]
    clock = time.perf_counter()
    for o in sample:
        learner(o)
    decision_s = (time.perf_counter() - clock) / len(sample)
    planning = [p["mean_planning_s"] for p in rounds if p["mean_planning_s"] > 0]
    result = {
        "config": asdict(config),
        "rounds": rounds,
        "kept_round": kept,
        **({"validation": rounds_validation} if config.select_round == "validated" else {}),
        "decision_s": decision_s,
        "expert_planning_s": float(np.mean(planning)) if planning else 0.0,
    }
    (run_dir / "distill.json").write_text(json.dumps(result, indent=2))
    hyperparams = {
        "policy": policy_name if isinstance(policy_name, str) else f"{policy_name.__module__}.{policy_name.__name__}",
        "normalize": {"norm_obs": True, "norm_reward": False},
        "policy_kwargs": policy_kwargs,
        **({"env_kwargs": dict(config.env_kwargs)} if config.env_kwargs else {}),
        **({"env_wrapper": "envs.PreviousActionWrapper"} if config.previous_action else {}),
    }
    run_config = {
        "algo": "ppo",
        "env_id": config.env_id,
        "seed": config.seed,
        "vec": "dummy",
        "hyperparams": hyperparams,
        "distilled_from": "planner",
    }
    (run_dir / "config.yml").write_text(yaml.safe_dump(run_config, sort_keys=False))
    (run_dir / "command.txt").write_text(" ".join(["python -m training.distill", *sys.argv[1:]]) + "\n")
    if config.ppo_steps > 0:  # fine-tune the folder in place
        result["finetune"] = finetune(run_dir, run_dir, FinetuneConfig(steps=config.ppo_steps, seed=config.seed), log)
    return result


def finetune(source: Path, run_dir: Path, config: FinetuneConfig, log=print) -> dict[str, Any]:
    """Fine-tune the distilled run ``source`` with PPO on its env's reward; write the run folder ``run_dir``.

    The observation normalisation of ``source`` stays frozen, so the fine-tuned policy reads the observation the
    way the distilled one did. Episodes reset with seeds from ``2_000_000 · (seed + 1)`` on, away from the
    distillation's and the evaluation's seeds.

    Returns:
        The figures written to ``finetune.json`` (wall time, the rollouts' success rate per phase).
    """
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from training.train import make_training_env

    source_config = yaml.safe_load((source / "config.yml").read_text())
    if source_config.get("distilled_from") != "planner":
        raise ValueError(
            f"--from-run must be a training.distill run folder, got {source} ({source_config.get('algo')})"
        )
    env_id = source_config["env_id"]
    torch.manual_seed(config.seed)
    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    env_kwargs = {**(source_config.get("hyperparams", {}).get("env_kwargs") or {}), **config.reward_kwargs}
    wrapper = resolve_env_wrapper(source_config.get("hyperparams", {}).get("env_wrapper"))
    vec = "native" if wrapper is None else "dummy"  # a wrapper applies to single envs
    venv = make_training_env(env_id, config.n_envs, 2_000_000 * (config.seed + 1), vec, run_dir, env_kwargs, wrapper)
    venv = VecNormalize.load(str(source / "vecnormalize.pkl"), venv)
    venv.training, venv.norm_reward = False, False
    model = PPO.load(
        source / "model.zip",
        env=venv,
        device="cpu",
        seed=config.seed,
        custom_objects={
            "n_steps": config.n_steps,
            "batch_size": config.batch_size,
            "n_epochs": config.n_epochs,
            "learning_rate": config.learning_rate,
            "clip_range": config.clip_range,
            "target_kl": config.target_kl,
            "gamma": config.gamma,
            "gae_lambda": config.gae_lambda,
            "ent_coef": 0.0,
        },
    )
    policy = model.policy
    with torch.no_grad():
        policy.log_std.fill_(config.log_std)
    actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(), policy.log_std]
    phases = []
    clock = time.perf_counter()
    for name, steps, frozen in (("critic", config.warmup_steps, True), ("both", config.steps, False)):
        if steps <= 0:
            continue
        for parameter in actor:
            parameter.requires_grad_(not frozen)
        start = time.perf_counter()
        model.learn(steps, reset_num_timesteps=False, progress_bar=False)
        buffer = list(model.ep_info_buffer)
        success = float(np.mean([info.get("is_success", 0.0) for info in buffer])) if buffer else float("nan")
        phases.append({"phase": name, "steps": steps, "seconds": time.perf_counter() - start,
                       "recent_success": success})  # fmt: skip
        log(f"{name}: {steps} steps, recent rollouts {success:.0%} success")
    model.save(run_dir / "model.zip")
    venv.save(str(run_dir / "vecnormalize.pkl"))
    run_config = {**source_config, "finetuned_from": str(source), "finetune": asdict(config)}
    (run_dir / "config.yml").write_text(yaml.safe_dump(run_config, sort_keys=False))
    (run_dir / "command.txt").write_text(" ".join(["python -m training.distill", *sys.argv[1:]]) + "\n")
    result = {"source": str(source), "config": asdict(config), "phases": phases,
              "wall_time_s": time.perf_counter() - clock}  # fmt: skip
    (run_dir / "finetune.json").write_text(json.dumps(result, indent=2))
    venv.close()
    return result


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    defaults = DistillConfig()
    parser = argparse.ArgumentParser(prog="python -m training.distill", description=__doc__.splitlines()[0])
    parser.add_argument("--env", default=defaults.env_id, help="a Reach id (default %(default)s)")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--run-dir", required=True)
    parser.add_argument(
        "--env-kwargs", nargs="*", default=[], metavar="KEY:VALUE", help="gym.make keyword arguments (targets:mixed)"
    )
    counts = ("expert_episodes", "iterations", "episodes", "epochs", "batch_size", "ppo_steps")
    for name in (*counts, "start_episodes", "start_steps"):
        parser.add_argument("--" + name.replace("_", "-"), type=int, default=getattr(defaults, name))
    for name in ("beta", "learning_rate", "replan_distance", "lookahead", "band_weight"):
        parser.add_argument("--" + name.replace("_", "-"), type=float, default=getattr(defaults, name))
    parser.add_argument(
        "--net-arch",
        type=int,
        nargs="+",
        default=list(defaults.net_arch),
        metavar="WIDTH",
        help="the learner's hidden layer widths (default %(default)s)",
    )
    parser.add_argument("--planner", default=defaults.planner, choices=("auto", "ompl", "grid"))
    parser.add_argument(
        "--select-round",
        default=defaults.select_round,
        choices=("last", "best", "validated"),
        help="keep the last round's learner, the one that did best when it acted, or the one that does best on "
        "--select-episodes validation episodes per target set (default %(default)s)",
    )
    parser.add_argument("--select-episodes", type=int, default=defaults.select_episodes)
    parser.add_argument(
        "--expert-damping", action="store_true", help="label with the planner controller's damping near the band"
    )
    parser.add_argument(
        "--damping-threshold",
        type=float,
        default=None,
        help="k below which the expert's damping slows down (with --expert-damping; default the env's k_safe)",
    )
    parser.add_argument(
        "--damping-kind",
        default=DistillConfig.damping_kind,
        choices=("scale", "cap"),
        help="the expert's damping: scale the action, or cap its largest rate (default %(default)s)",
    )
    parser.add_argument(
        "--lr-decay", action="store_true", help="anneal each fit's learning rate to 0 on a cosine over its epochs"
    )
    parser.add_argument(
        "--first-order-expert",
        action="store_true",
        help="label with the first-order step J_i xdot instead of the exact step to the aimed pose",
    )
    parser.add_argument(
        "--previous-action",
        action="store_true",
        help="the learner also sees its own previous action (envs.PreviousActionWrapper)",
    )
    parser.add_argument(
        "--damped-output",
        action="store_true",
        help="the learner's action is its network's output times the expert's damping of the observed k "
        "(training.policies.PlanFreeMlpPolicy; needs --expert-damping)",
    )
    parser.add_argument(
        "--error-gain",
        action="store_true",
        help="the learner's network gives a gain matrix times the observed pose error "
        "(training.policies.PlanFreeMlpPolicy): its action is 0 at the target",
    )
    parser.add_argument(
        "--hold-fraction",
        type=float,
        default=defaults.hold_fraction,
        help="the learner's action is 0 while its observed errors are within this fraction of the success "
        "tolerances (training.policies.PlanFreeMlpPolicy's in-position hold; default %(default)s: none)",
    )
    parser.add_argument(
        "--platform-loss",
        type=float,
        default=defaults.platform_loss,
        help="λ of the loss's platform term λ ‖G (μ − a)‖², G = J_f · max_rate · dt over the success tolerances: "
        "the pose change an action error causes (default %(default)s: none)",
    )
    parser.add_argument(
        "--action-noise",
        type=float,
        default=defaults.action_noise,
        help="σ of the Gaussian noise on every training episode's executed action, in units of the rate range; "
        "the labels stay the expert's (DART; default %(default)s: none)",
    )
    parser.add_argument(
        "--from-run", default=None, help="fine-tune this distilled run with PPO (--ppo-steps, default 1M) instead"
    )
    parser.add_argument("--warmup-steps", type=int, default=FinetuneConfig.warmup_steps, help="critic-only steps")
    parser.add_argument(
        "--reward-kwargs",
        nargs="*",
        default=[],
        metavar="KEY:VALUE",
        help="env keyword arguments of the fine-tuning env only (termination_penalty:200)",
    )
    args = parser.parse_args(argv)
    if args.from_run is not None:
        steps = args.ppo_steps or FinetuneConfig.steps
        if steps < 1 or args.warmup_steps < 0:
            parser.error(f"--ppo-steps must be ≥ 1 and --warmup-steps ≥ 0, got {steps} and {args.warmup_steps}")
        try:
            config = FinetuneConfig(
                steps, args.warmup_steps, seed=args.seed, reward_kwargs=parse_env_kwargs(args.reward_kwargs)
            )
            finetune(Path(args.from_run), Path(args.run_dir), config)
        except (ValueError, FileNotFoundError, EvaluationError) as exc:
            parser.error(str(exc))
        return 0
    if args.env not in envs.ENV_IDS or "Reach" not in args.env:
        parser.error(f"--env must be a Reach id of {envs.ENV_IDS}, got {args.env!r}")
    for name in ("expert_episodes", "epochs", "batch_size", "select_episodes", "start_steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be ≥ 1, got {getattr(args, name)}")
    if min(args.net_arch) < 1:
        parser.error(f"--net-arch widths must be ≥ 1, got {args.net_arch}")
    if not 0.0 <= args.hold_fraction < 1.0:
        parser.error(f"--hold-fraction must be in [0, 1), got {args.hold_fraction}")
    if args.start_episodes < 0:
        parser.error(f"--start-episodes must be ≥ 0, got {args.start_episodes}")
    if not 0.0 <= args.beta <= 1.0:
        parser.error(f"--beta must be in [0, 1], got {args.beta}")
    if args.damping_threshold is not None and not (args.expert_damping and 0.0 < args.damping_threshold <= 1.0):
        parser.error(f"--damping-threshold needs --expert-damping and a value in (0, 1], got {args.damping_threshold}")
    if args.damping_kind != DistillConfig.damping_kind and not args.expert_damping:
        parser.error(f"--damping-kind {args.damping_kind} needs --expert-damping")
    if args.damped_output and not (args.expert_damping and args.damping_kind == "scale"):
        parser.error(
            "--damped-output needs --expert-damping and --damping-kind scale, got "
            f"{'' if args.expert_damping else 'no '}--expert-damping and --damping-kind {args.damping_kind}"
        )
    for name in ("band_weight", "platform_loss"):
        if not (np.isfinite(getattr(args, name)) and getattr(args, name) >= 0.0):
            parser.error(f"--{name.replace('_', '-')} must be finite and ≥ 0, got {getattr(args, name)}")
    if not (np.isfinite(args.action_noise) and 0.0 <= args.action_noise < 1.0):
        parser.error(f"--action-noise must be in [0, 1), got {args.action_noise}")
    try:
        env_kwargs = parse_env_kwargs(args.env_kwargs)
    except EvaluationError as exc:
        parser.error(str(exc))
    config = DistillConfig(
        env_id=args.env,
        env_kwargs=env_kwargs,
        seed=args.seed,
        expert_episodes=args.expert_episodes,
        iterations=args.iterations,
        episodes=args.episodes,
        beta=args.beta,
        epochs=args.epochs,
        batch_size=args.batch_size,
        learning_rate=args.learning_rate,
        net_arch=tuple(args.net_arch),
        planner=args.planner,
        replan_distance=args.replan_distance,
        lookahead=args.lookahead,
        ppo_steps=args.ppo_steps,
        expert_damping=args.expert_damping,
        select_round=args.select_round,
        select_episodes=args.select_episodes,
        band_weight=args.band_weight,
        lr_decay=args.lr_decay,
        damping_threshold=args.damping_threshold,
        damping_kind=args.damping_kind,
        previous_action=args.previous_action,
        first_order_expert=args.first_order_expert,
        damped_output=args.damped_output,
        hold_fraction=args.hold_fraction,
        error_gain=args.error_gain,
        start_episodes=args.start_episodes,
        start_steps=args.start_steps,
        platform_loss=args.platform_loss,
        action_noise=args.action_noise,
    )
    distill(config, Path(args.run_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
