"""A goal-conditioned view of the Reach environments, for hindsight experience replay (HER).

SB3's ``HerReplayBuffer`` (Andrychowicz et al., NeurIPS 2017) relabels stored transitions with goals the
robot actually reached and asks the environment for the reward it would have paid. That needs the
observation split into ``observation`` / ``achieved_goal`` / ``desired_goal`` and a vectorised
``compute_reward``. ``GoalReachWrapper`` provides both on top of `Planar3RPRReach-v0` (or its hard
variant) without touching the dynamics: ``compute_reward`` calls the environment's own batched
``envs.physics.reward_terms`` for the tracking, conditioning and success terms (success judged on the relabelled
goal, never at a terminated step) and takes the action and termination terms from ``info``, so for the goal the
episode really had it returns exactly the reward ``step`` paid.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs.kernels.packing import observation_layout
from envs.physics import reward_terms
from envs.state import TERMINATION_REASONS

__all__ = ["OBSERVATION_INDEX", "GoalReachWrapper", "goal_free_index"]


def goal_free_index(pose_space: str, n: int) -> np.ndarray:
    """Entries of the flat observation that do not depend on the goal: pose code, normalised strokes and k.

    The layout is ``envs.kernels.packing.observation_layout``, which the 3-RPR's ``core.observation`` shares.

    Args:
        pose_space: "planar", "spatial" or "translational".
        n: Number of actuators.

    Returns:
        Indices into the observation vector, int array.
    """
    layout = observation_layout(pose_space, n, False)
    return np.concatenate([np.arange(layout[name].start, layout[name].stop) for name in ("pose", "strokes", "k")])


#: The 3-RPR's goal-free entries: pose (x, y, cos φ, sin φ), the normalised strokes and k.
OBSERVATION_INDEX = goal_free_index("planar", 3)


class GoalReachWrapper(gym.Wrapper):
    """Dict observations {observation, achieved_goal, desired_goal} and ``compute_reward`` for HER.

    * ``observation``: float32 (8,), the goal-independent entries of the flat observation
      (``OBSERVATION_INDEX``).
    * ``achieved_goal``: the pose (x [m], y [m], φ [rad]), float32 (3,).
    * ``desired_goal``: the target pose (x* [m], y* [m], φ* [rad]), float32 (3,).

    Rewards, terminations and infos are the wrapped environment's.

    Args:
        env: A Reach environment (any Reach id of ``envs``), possibly wrapped.
    """

    def __init__(self, env: gym.Env) -> None:
        """Wrap ``env``; see the class docstring."""
        super().__init__(env)
        base = env.unwrapped
        if "targets" not in getattr(type(base), "reset_options", ()) or not hasattr(base, "params"):
            raise TypeError(f"GoalReachWrapper needs a Reach environment of envs, got {type(base).__name__}")
        self.params = base.params
        self._n = base.action_space.shape[0]
        self._index = goal_free_index(self.params.robot.pose_space.name, self._n)
        flat = env.observation_space
        goal_low = np.array(self.params.pose_low, dtype=np.float32)
        goal_high = np.array(self.params.pose_high, dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(flat.low[self._index], flat.high[self._index], dtype=np.float32),
                "achieved_goal": spaces.Box(goal_low, goal_high, dtype=np.float32),
                "desired_goal": spaces.Box(goal_low, goal_high, dtype=np.float32),
            }
        )

    def _goal_obs(self, obs: np.ndarray, info: dict[str, Any]) -> dict[str, np.ndarray]:
        space = self.observation_space
        return {
            "observation": obs[self._index],
            # The pose stays inside its bounds except at an out-of-bounds termination: clip for the space.
            "achieved_goal": np.clip(info["pose"], space["achieved_goal"].low, space["achieved_goal"].high).astype(
                np.float32
            ),
            "desired_goal": np.asarray(info["target"], dtype=np.float32),
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the wrapped env; the observation becomes the goal dict."""
        obs, info = self.env.reset(seed=seed, options=options)
        return self._goal_obs(obs, info), info

    def step(self, action: Any):
        """Step the wrapped env; the observation becomes the goal dict (reward and info unchanged)."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._goal_obs(obs, info), reward, terminated, truncated, info

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        """The reward of a transition had the goal been ``desired_goal`` (batched, for HER).

        reward = tracking(achieved, desired) + singularity(k) + info's action term + info's termination
        term (+ info's Type I term, for the family) + success(achieved, desired), summed in the order ``step``
        sums them; the tracking, singularity and success terms come from ``envs.physics.reward_terms``, the last
        with the step's termination reason (``info["termination_reason"]``): ``success_reward`` where the step
        did not terminate and ``achieved`` is within the success tolerances of ``desired``.

        Args:
            achieved_goal: Poses reached, shape (3,) or (B, 3).
            desired_goal: Goals, same shape.
            info: The step's info dict, or a sequence / array of B of them.

        Returns:
            A float, or rewards of shape (B,).
        """
        achieved = np.asarray(achieved_goal, dtype=np.float64)
        desired = np.asarray(desired_goal, dtype=np.float64)
        single = achieved.ndim == 1
        m = len(self.params.pose_low)
        achieved, desired = achieved.reshape(-1, m), desired.reshape(-1, m)
        infos = [info] if isinstance(info, dict) else list(np.asarray(info, dtype=object).ravel())
        n = len(achieved)
        if desired.shape != achieved.shape or len(infos) != n:
            raise ValueError(
                f"achieved_goal {achieved.shape}, desired_goal {desired.shape} and {len(infos)} infos must match"
            )
        k = np.array([i["inverse_condition_number"] for i in infos], dtype=np.float64)
        action = np.array([i["reward_action"] for i in infos], dtype=np.float64)
        termination = np.array([i["reward_termination"] for i in infos], dtype=np.float64)
        reason = np.array([TERMINATION_REASONS.index(i["termination_reason"]) for i in infos], dtype=np.int64)
        terms = reward_terms(self.params, achieved, desired, k, np.zeros((n, self._n)), reason)
        actuator = np.array([i["reward_actuator_singularity"] for i in infos], dtype=np.float64)  # goal-free Type I
        reward = terms["reward_tracking"] + terms["reward_singularity"] + action + termination + actuator
        reward += terms["reward_success"]
        return float(reward[0]) if single else reward
