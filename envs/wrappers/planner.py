"""The planner's wrappers: the carrot of a certified path in a policy's observation, or a residual on the planner.

``PlannerWaypointWrapper`` shows a policy the carrot of ``envs.planner.PathFollower``; ``PlannerResidualWrapper``
adds a policy's correction to ``envs.controllers.PlannerController``'s action. Both need a planar robot with a
certified grid (``task_region="grid"``, the 3-RPR ids).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs.controllers import PlannerController
from envs.kernels.generic import observation_layout
from envs.params import FamilyParams
from envs.planner import PathFollower

__all__ = ["PlannerResidualWrapper", "PlannerWaypointWrapper"]


class _PlannerWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """What the planner's wrappers share: the check of the env, the path follower and the waypoint's bounds."""

    def _setup(self, env: gym.Env, lookahead: float, extra_low: np.ndarray, extra_high: np.ndarray) -> None:
        gym.Wrapper.__init__(self, env)
        base = env.unwrapped
        params = getattr(base, "params", None)
        if "targets" not in getattr(type(base), "reset_options", ()) or not isinstance(params, FamilyParams):
            raise TypeError(f"{type(self).__name__} wraps the Reach environments of envs, got {type(base).__name__}")
        self.follower = PathFollower(base.params, lookahead)
        box = env.observation_space
        error = observation_layout("planar", 3, False)["error"]
        self._low, self._high = box.low[error].astype(np.float64), box.high[error].astype(np.float64)
        self.observation_space = spaces.Box(
            np.concatenate([box.low, box.low[error], extra_low]).astype(np.float32),
            np.concatenate([box.high, box.high[error], extra_high]).astype(np.float32),
            dtype=np.float32,
        )

    def _offset(self, info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """(pose, carrot) of the step's ``info``, each (3,)."""
        pose = np.asarray(info["pose"], dtype=float)
        return pose, self.follower.carrot(0, pose, np.asarray(info["target"], dtype=float))

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the wrapped env and plan from its start to its target."""
        obs, info = self.env.reset(seed=seed, options=options)
        self.follower.reset_row(0, np.asarray(info["pose"], dtype=float), np.asarray(info["target"], dtype=float))
        return self._augment(obs, info), info


class PlannerWaypointWrapper(_PlannerWrapper):
    """Show a policy the planner's next waypoint: the observation gains the carrot's offset from the pose.

    The flat observation of a planar Reach environment with a certified grid gets three more entries, the carrot of
    ``PathFollower`` minus the pose, (Δx [m], Δy [m], Δφ [rad]) (Δφ wrapped to (−π, π]; each clipped to the
    error block's bounds), float32. Where the straight line to the target is safe, or once the carrot has
    reached the end of the path, this is the target error again; on a detour it points along the safe
    path. The plan is made at reset from the true start and target (``info["pose"]``, ``info["target"]``);
    rewards, terminations and infos are the wrapped environment's. One of the levers of the hard targets:
    the planner knows where a safe path runs, the policy learns to drive along it.

    Args:
        env: A planar Reach environment with a certified grid (``gym.make("Planar3RPRReach-v0")`` and its variants).
        lookahead: Distance of the carrot ahead of the path's closest point, in z = (x, y, ℓ_c φ) [m].
    """

    def __init__(self, env: gym.Env, lookahead: float = 0.1) -> None:
        """Wrap ``env``; see the class docstring."""
        gym.utils.RecordConstructorArgs.__init__(self, lookahead=lookahead)
        self._setup(env, lookahead, np.empty(0), np.empty(0))

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        pose, carrot = self._offset(info)
        return np.concatenate([obs, np.clip(carrot - pose, self._low, self._high)]).astype(np.float32)

    def step(self, action: Any):
        """Step the wrapped env; the observation gains the carrot's offset."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._augment(obs, info), reward, terminated, truncated, info


class PlannerResidualWrapper(_PlannerWrapper):
    """Residual learning over the planner: the policy's action corrects the planner controller's.

    The environment receives a = clip(a_p + ``scale`` · a_π, −1, 1), where a_p is the action of
    ``envs.controllers.PlannerController`` (resolved-rate toward the carrot of a certified safe path, from the
    true pose ``info["pose"]``) and a_π ∈ [−1, 1]³ the policy's. A policy that outputs zero is the planner
    controller; training learns what to change. The observation of a planar Reach environment gains six
    entries, float32: the carrot's offset from the pose (Δx [m], Δy [m], Δφ [rad], as in
    ``PlannerWaypointWrapper``) and a_p (normalised stroke rates, in [−1, 1]). Rewards, terminations and infos
    are the wrapped environment's, and ``info["planner_action"]`` holds a_p of the step's action. A
    ``SingularityShield`` inside this wrapper filters the summed action.

    Args:
        env: A planar Reach environment with a certified grid (``gym.make("Planar3RPRReach-v0")`` and its variants).
        scale: Weight of the policy's action, in (0, 2]: 0.5 lets it move any leg by half its rate range.
        lookahead: Distance of the carrot ahead of the path's closest point, in z = (x, y, ℓ_c φ) [m].
    """

    def __init__(self, env: gym.Env, scale: float = 0.5, lookahead: float = 0.1) -> None:
        """Wrap ``env``; see the class docstring."""
        if not (isinstance(scale, (int, float)) and np.isfinite(scale) and 0.0 < scale <= 2.0):
            raise ValueError(f"scale must be a number in (0, 2], got {scale!r}")
        gym.utils.RecordConstructorArgs.__init__(self, scale=scale, lookahead=lookahead)
        self._setup(env, lookahead, -np.ones(3), np.ones(3))
        self.scale = float(scale)
        # one plan per episode, shared by the observation and the action
        self.controller = PlannerController(env.unwrapped.params, follower=self.follower)
        self._planner_action = np.zeros(3, dtype=np.float32)

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        pose, carrot = self._offset(info)
        self._planner_action = self.controller.steer(pose[None], carrot[None], np.zeros((1, 3)))[0]
        offset = np.clip(carrot - pose, self._low, self._high)
        return np.concatenate([obs, offset, self._planner_action]).astype(np.float32)

    def action(self, action: Any) -> np.ndarray:
        """The summed action the wrapped env receives for the policy's ``action`` (shape (3,)), float32."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be 3 finite numbers, got shape {a.shape} with values {a!r}")
        return np.clip(self._planner_action + self.scale * np.clip(a, -1.0, 1.0), -1.0, 1.0).astype(np.float32)

    def step(self, action: Any):
        """Step the wrapped env with the summed action; the observation gains the carrot and a_p."""
        planner_action = self._planner_action
        obs, reward, terminated, truncated, info = self.env.step(self.action(action))
        info["planner_action"] = planner_action
        return self._augment(obs, info), reward, terminated, truncated, info
