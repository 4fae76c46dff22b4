"""The expert and the episodes of a distillation: the planner that labels, the rollouts, the validation."""

from __future__ import annotations

import itertools
from typing import Any

import gymnasium as gym
import numpy as np

from envs.kernels.evaluation import reference_batch
from robot_control.controllers import ComputedTorqueAgent, PlannerComputedTorqueAgent, PlannerController
from robot_control.planner import PathFollower
from training.distill_config import DistillConfig
from training.episodes import SINGULARITY_REASONS, evaluate_agent

__all__ = ["ReferenceTeacher", "collect", "validate"]


class ReferenceTeacher(ComputedTorqueAgent):
    """``ComputedTorqueAgent`` that also feeds forward the reference's acceleration over the coming period.

    A privileged teacher: ẍ_d = (ẋ*(t + 1) − ẋ*(t)) / dt, ẋ* the Track reference's velocity at the env's step t,
    read from the env's state (the observation holds ẋ*(t) only); the learner it labels for sees the observation
    alone. On a Reach env the target is at rest and ẍ_d = 0.

    Args:
        env: The force-control env whose episodes it labels (its current state is the observation's).
        bandwidth: ω [rad/s] of the error dynamics.
    """

    name = "reference-computed-torque"

    def __init__(self, env: gym.Env, bandwidth: float) -> None:
        super().__init__(env.unwrapped.params, bandwidth)
        self._env = env

    def _acceleration(self, obs: np.ndarray) -> np.ndarray:
        state, packed, dt = self._env.unwrapped.state, self.params.packed, self.params.dt
        ref = state.reference
        now = reference_batch(packed, state.t, ref.center, ref.amplitude, ref.phase)[1]
        later = reference_batch(packed, state.t + 1, ref.center, ref.amplitude, ref.phase)[1]
        return (later - now) / dt


def _expert(env: gym.Env, config: DistillConfig) -> PlannerController | ComputedTorqueAgent:
    """The labelling expert of ``config`` on the robot of ``env``.

    ``config.expert`` "planner": the planner controller; under force control (``control="force"``) computed torque
    along the planner's path (``PlannerComputedTorqueAgent``), where the rate-control expert's options (damping,
    first-order step) do not apply. "computed-torque" (force control only): ``ComputedTorqueAgent`` toward the
    observed target, or with ``config.reference_acceleration`` the ``ReferenceTeacher``. The computed-torque
    experts use ``config.bandwidth``.

    Raises:
        ValueError: If a rate-control expert option is set on a force-control env, or the computed-torque expert
            on a rate-control env.
    """
    params = env.unwrapped.params
    if config.expert == "computed-torque":  # ComputedTorqueAgent refuses a rate-control env
        if config.reference_acceleration:
            return ReferenceTeacher(env, config.bandwidth)
        return ComputedTorqueAgent(params, bandwidth=config.bandwidth)
    if params.control == "force":
        rate_only = {
            "expert_damping": config.expert_damping,
            "first_order_expert": config.first_order_expert,
            "damped_output": config.damped_output,
        }
        if any(rate_only.values()):
            raise ValueError(f"these options label stroke rates (control='rate'), got {rate_only} on a force env")
        return PlannerComputedTorqueAgent(
            params, config.bandwidth, config.lookahead, config.planner, config.replan_distance
        )
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
    expert: PlannerController | ComputedTorqueAgent,
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
        expert: The labelling expert (``_expert``); a planner's plan log is cleared first, then holds these
            episodes' plans.
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
    log = getattr(expert, "log", None)  # the planner's plans (computed torque plans nothing)
    if log is not None:
        log.clear()  # the plans of these episodes alone
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
    plans = [] if log is None else list(log)
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
