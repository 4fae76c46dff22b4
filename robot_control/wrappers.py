"""Wrappers over the classical controllers: the carrot of a certified path in a policy's observation, or residuals.

``PlannerWaypointWrapper`` shows a policy the carrot of ``robot_control.planner.PathFollower``;
``PlannerResidualWrapper`` adds a policy's correction to ``robot_control.controllers.PlannerController``'s action.
Both wrap the Reach environment of any robot of the family (the planner: ``robot_control.planner``, the certified
grid's graph where the env has one, else OMPL). ``ComputedTorqueResidualWrapper`` adds a policy's correction to
computed torque's efforts on any force-control env. ``VectorPlannerWaypointWrapper``,
``VectorPlannerResidualWrapper`` and ``VectorComputedTorqueResidualWrapper`` are the same wrappers on the native
vector env (the ``vector_form`` of the single ones).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs.kernels.packing import observation_layout
from envs.params import FamilyParams
from envs.vector import episode_starts
from robot_control.controllers import ComputedTorqueAgent, PlannerController, pose_error
from robot_control.planner import PathFollower

__all__ = [
    "ComputedTorqueResidualWrapper",
    "PlannerResidualWrapper",
    "PlannerWaypointWrapper",
    "VectorComputedTorqueResidualWrapper",
    "VectorPlannerResidualWrapper",
    "VectorPlannerWaypointWrapper",
]


def _augmented_box(box: spaces.Box, params: FamilyParams, n_extra: int) -> tuple[np.ndarray, np.ndarray, spaces.Box]:
    """The error block's bounds and the observation box with the carrot's offset and ``n_extra`` entries appended.

    Returns:
        (lower and upper bounds of the error block of ``box``, float64; the box with the offset (the error
        block's bounds) and ``n_extra`` entries in [−1, 1] appended).
    """
    error = observation_layout(params.robot.pose_space.name, params.robot.n_actuators, False)["error"]
    low, high = box.low[error].astype(np.float64), box.high[error].astype(np.float64)
    extra = np.ones(n_extra)
    augmented = spaces.Box(
        np.concatenate([box.low, box.low[error], -extra]).astype(np.float32),
        np.concatenate([box.high, box.high[error], extra]).astype(np.float32),
        dtype=np.float32,
    )
    return low, high, augmented


def _carrot_offsets(wrapper: Any, pose: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each row's carrot and its twist offset from the pose, clipped to the error block's bounds.

    Args:
        wrapper: A planner wrapper (its ``follower`` plans row i, its ``params``, ``_low`` and ``_high``).
        pose: Poses of rows 0 … N − 1, shape (N, m) [m, rad].
        target: Their targets, shape (N, m).

    Returns:
        (poses, carrots, offsets), each (N, m).
    """
    pose, target = np.asarray(pose, dtype=float), np.asarray(target, dtype=float)
    carrot = np.stack([wrapper.follower.carrot(i, pose[i], target[i]) for i in range(len(pose))])
    offset = np.clip(pose_error(wrapper.params, pose, carrot), wrapper._low, wrapper._high)
    return pose, carrot, offset


def _residual_scale(scale: Any) -> float:
    """``scale`` as a float, refused unless a number in (0, 2]."""
    if not (isinstance(scale, (int, float)) and np.isfinite(scale) and 0.0 < scale <= 2.0):
        raise ValueError(f"scale must be a number in (0, 2], got {scale!r}")
    return float(scale)


def _summed(base_action: np.ndarray, scale: float, action: Any) -> np.ndarray:
    """clip(a_b + scale · clip(a_π, −1, 1), −1, 1) as float32, a_π refused unless finite with a_b's shape.

    Args:
        base_action: The base controller's action, shape (n,) (a single wrapper) or (N, n) (a vector wrapper).
        scale: Weight of the policy's action.
        action: The policy's action a_π, the shape of ``base_action``.
    """
    a = np.asarray(action, dtype=np.float64)
    if a.shape != base_action.shape or not np.all(np.isfinite(a)):
        if base_action.ndim == 1:
            n = base_action.size
            raise ValueError(f"action must be {n} finite numbers, got shape {a.shape} with values {a!r}")
        raise ValueError(f"actions must be finite with shape {base_action.shape}, got shape {a.shape}")
    return np.clip(base_action + scale * np.clip(a, -1.0, 1.0), -1.0, 1.0).astype(np.float32)


class _PlannerWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """What the planner's wrappers share: the check of the env, the path follower and the waypoint's bounds."""

    def _setup(self, env: gym.Env, lookahead: float, planner: str, n_extra: int) -> None:
        gym.Wrapper.__init__(self, env)
        base = env.unwrapped
        params = getattr(base, "params", None)
        if "targets" not in getattr(type(base), "reset_options", ()) or not isinstance(params, FamilyParams):
            raise TypeError(f"{type(self).__name__} wraps the Reach environments of envs, got {type(base).__name__}")
        self.params = params
        self.follower = PathFollower(params, lookahead, planner)
        self._low, self._high, self.observation_space = _augmented_box(env.observation_space, params, n_extra)

    def _offset(self, info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pose, carrot, the carrot's twist offset clipped to the error block's bounds) of ``info``, each (m,)."""
        pose, carrot, offset = _carrot_offsets(self, np.asarray(info["pose"])[None], np.asarray(info["target"])[None])
        return pose[0], carrot[0], offset[0]

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the wrapped env and plan from its start to its target."""
        obs, info = self.env.reset(seed=seed, options=options)
        self.follower.reset_row(0, np.asarray(info["pose"], dtype=float), np.asarray(info["target"], dtype=float))
        return self._augment(obs, info), info


class PlannerWaypointWrapper(_PlannerWrapper):
    """Show a policy the planner's next waypoint: the observation gains the carrot's offset from the pose.

    The flat observation of a Reach environment gets m more entries: the twist from the pose to the carrot of
    ``PathFollower``, as the observation's error block (planar (Δx [m], Δy [m], Δφ [rad]) with Δφ wrapped to
    (−π, π]; spatial (Δp [m], Δθ [rad]) with Δθ the rotation vector of R_carrot Rᵀ; translational Δp [m]), each
    clipped to the error block's bounds, float32. Where the straight line to the target is safe, or once the carrot has
    reached the end of the path, this is the target error again; on a detour it points along the safe
    path. The plan is made at reset from the true start and target (``info["pose"]``, ``info["target"]``);
    rewards, terminations and infos are the wrapped environment's. One of the levers of the hard targets:
    the planner knows where a safe path runs, the policy learns to drive along it.

    Args:
        env: A Reach environment of ``envs`` (``gym.make("Planar3RPRReach-v0")``, ``"DeltaReach-v0"``, ...).
        lookahead: Distance of the carrot ahead of the path's closest point, in z = (p, ℓ_c θ) [m].
        planner: ``robot_control.planner.PathFollower``'s planner: "auto", "ompl" or "grid".
    """

    #: The name of the same wrapper on the native vector env.
    vector_form = "VectorPlannerWaypointWrapper"

    def __init__(self, env: gym.Env, lookahead: float = 0.1, planner: str = "auto") -> None:
        """Wrap ``env``; see the class docstring."""
        gym.utils.RecordConstructorArgs.__init__(self, lookahead=lookahead, planner=planner)
        self._setup(env, lookahead, planner, 0)

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        return np.concatenate([obs, self._offset(info)[2]]).astype(np.float32)

    def step(self, action: Any):
        """Step the wrapped env; the observation gains the carrot's offset."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._augment(obs, info), reward, terminated, truncated, info


class PlannerResidualWrapper(_PlannerWrapper):
    """Residual learning over the planner: the policy's action corrects the planner controller's.

    The environment receives a = clip(a_p + ``scale`` · a_π, −1, 1), where a_p is the action of
    ``robot_control.controllers.PlannerController`` (resolved-rate toward the carrot of a certified safe path, from the
    true pose ``info["pose"]``) and a_π ∈ [−1, 1]ⁿ the policy's. A policy that outputs zero is the planner
    controller; training learns what to change. The observation of a Reach environment gains m + n entries,
    float32: the carrot's offset from the pose (as in ``PlannerWaypointWrapper``) and a_p (normalised actuator
    rates, in [−1, 1]). Rewards, terminations and infos
    are the wrapped environment's, and ``info["planner_action"]`` holds a_p of the step's action. A
    ``SingularityShield`` inside this wrapper filters the summed action.

    Args:
        env: A Reach environment of ``envs`` (``gym.make("Planar3RPRReach-v0")``, ``"DeltaReach-v0"``, ...).
        scale: Weight of the policy's action, in (0, 2]: 0.5 lets it move any actuator by half its rate range.
        lookahead: Distance of the carrot ahead of the path's closest point, in z = (p, ℓ_c θ) [m].
        planner: ``robot_control.planner.PathFollower``'s planner: "auto", "ompl" or "grid".
    """

    #: The name of the same wrapper on the native vector env.
    vector_form = "VectorPlannerResidualWrapper"

    def __init__(self, env: gym.Env, scale: float = 0.5, lookahead: float = 0.1, planner: str = "auto") -> None:
        """Wrap ``env``; see the class docstring."""
        self.scale = _residual_scale(scale)
        gym.utils.RecordConstructorArgs.__init__(self, scale=scale, lookahead=lookahead, planner=planner)
        n = env.action_space.shape[0] if isinstance(env.action_space, spaces.Box) else 0  # _setup refuses others
        self._setup(env, lookahead, planner, n)
        # one plan per episode, shared by the observation and the action
        # the base action the shipped residual policies were trained over (first-order steps)
        self.controller = PlannerController(self.params, follower=self.follower, exact_step=False)
        self._planner_action = np.zeros(n, dtype=np.float32)

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        pose, carrot, offset = self._offset(info)
        self._planner_action = self.controller.steer(pose[None], carrot[None], np.zeros((1, pose.size)))[0]
        return np.concatenate([obs, offset, self._planner_action]).astype(np.float32)

    def action(self, action: Any) -> np.ndarray:
        """The summed action the wrapped env receives for the policy's ``action`` (shape (n,)), float32."""
        return _summed(self._planner_action, self.scale, action)

    def step(self, action: Any):
        """Step the wrapped env with the summed action; the observation gains the carrot and a_p."""
        planner_action = self._planner_action
        obs, reward, terminated, truncated, info = self.env.step(self.action(action))
        info["planner_action"] = planner_action
        return self._augment(obs, info), reward, terminated, truncated, info


class _VectorPlannerWrapper(gym.vector.VectorWrapper):
    """The planner's wrappers on the native vector env: row i is the single env's wrapper on sub-environment i.

    One ``PathFollower`` plans per row. A row is planned afresh at ``reset`` and when the vector env starts its next
    episode (autoreset), as the single wrapper plans at each ``reset``.
    """

    def _setup(self, env: gym.vector.VectorEnv, lookahead: float, planner: str, n_extra: int) -> None:
        gym.vector.VectorWrapper.__init__(self, env)
        base = env.unwrapped
        params = getattr(base, "params", None)
        sampler = getattr(base, "_sampler", None)
        if "targets" not in getattr(sampler, "reset_options", ()) or not isinstance(params, FamilyParams):
            raise TypeError(
                f"{type(self).__name__} wraps the native Reach vector envs of envs, got {type(base).__name__}"
            )
        self.params = params
        self.follower = PathFollower(params, lookahead, planner)
        self._low, self._high, self.single_observation_space = _augmented_box(
            env.single_observation_space, params, n_extra
        )
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, env.num_envs)
        self._ended = np.zeros(env.num_envs, dtype=bool)

    def _offsets(self, info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(poses, carrots, the carrots' twist offsets clipped to the error block's bounds), each (N, m)."""
        return _carrot_offsets(self, info["pose"], info["target"])

    def _plan(self, rows: np.ndarray, info: dict[str, Any]) -> None:
        for i in rows:
            self.follower.reset_row(int(i), np.asarray(info["pose"][i], float), np.asarray(info["target"][i], float))

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        raise NotImplementedError

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        """Reset the wrapped vector env and plan each reset row from its start to its target."""
        obs, info = self.env.reset(seed=seed, options=options)
        mask = (options or {}).get("reset_mask")
        rows = np.flatnonzero(mask) if mask is not None else np.arange(self.num_envs)
        self._plan(rows, info)
        self._ended[rows] = False
        return self._augment(obs, info), info

    def _step(self, actions: np.ndarray):
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        starts = episode_starts(self.env.unwrapped.autoreset_mode, self._ended, terminated, truncated)
        self._plan(np.flatnonzero(starts), info)  # the rows that started their next episode
        self._ended = terminated | truncated
        return obs, rewards, terminated, truncated, info


class VectorPlannerWaypointWrapper(_VectorPlannerWrapper):
    """``PlannerWaypointWrapper`` on the native vector env (row i: the single wrapper on sub-environment i)."""

    def __init__(self, env: gym.vector.VectorEnv, lookahead: float = 0.1, planner: str = "auto") -> None:
        """Wrap ``env``; see ``PlannerWaypointWrapper``."""
        self._setup(env, lookahead, planner, 0)

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        return np.concatenate([obs, self._offsets(info)[2]], axis=1).astype(np.float32)

    def step(self, actions: Any):
        """Step the wrapped vector env; each observation gains its carrot's offset."""
        obs, rewards, terminated, truncated, info = self._step(actions)
        return self._augment(obs, info), rewards, terminated, truncated, info


class VectorPlannerResidualWrapper(_VectorPlannerWrapper):
    """``PlannerResidualWrapper`` on the native vector env (row i: the single wrapper on sub-environment i)."""

    def __init__(
        self, env: gym.vector.VectorEnv, scale: float = 0.5, lookahead: float = 0.1, planner: str = "auto"
    ) -> None:
        """Wrap ``env``; see ``PlannerResidualWrapper``."""
        self.scale = _residual_scale(scale)
        n = env.single_action_space.shape[0]
        self._setup(env, lookahead, planner, n)
        # the base action the shipped residual policies were trained over (first-order steps)
        self.controller = PlannerController(self.params, follower=self.follower, exact_step=False)
        self._planner_action = np.zeros((env.num_envs, n), dtype=np.float32)

    def _augment(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        pose, carrot, offset = self._offsets(info)
        self._planner_action = self.controller.steer(pose, carrot, np.zeros_like(pose))
        return np.concatenate([obs, offset, self._planner_action], axis=1).astype(np.float32)

    def actions(self, actions: Any) -> np.ndarray:
        """The summed actions the wrapped env receives for the policy's ``actions`` (shape (N, n)), float32."""
        return _summed(self._planner_action, self.scale, actions)

    def step(self, actions: Any):
        """Step the wrapped vector env with the summed actions; each observation gains its carrot and a_p."""
        planner_action = self._planner_action
        obs, rewards, terminated, truncated, info = self._step(self.actions(actions))
        info["planner_action"] = planner_action
        info["_planner_action"] = np.ones(self.num_envs, dtype=bool)
        return self._augment(obs, info), rewards, terminated, truncated, info


def _force_params(env: Any, name: str) -> FamilyParams:
    """The ``FamilyParams`` of a force-control env of ``envs`` (single or native vector), else TypeError."""
    params = getattr(env.unwrapped, "params", None)
    if not isinstance(params, FamilyParams) or params.control != "force":
        control = getattr(params, "control", None)
        raise TypeError(
            f"{name} wraps the force-control envs of envs (control='force'), got {type(env.unwrapped).__name__}"
            f" with control={control!r}"
        )
    return params


def _with_actions(box: spaces.Box, n: int) -> spaces.Box:
    """``box`` with n entries in [−1, 1] appended (float32)."""
    extra = np.ones(n)
    return spaces.Box(
        np.concatenate([box.low, -extra]).astype(np.float32),
        np.concatenate([box.high, extra]).astype(np.float32),
        dtype=np.float32,
    )


class ComputedTorqueResidualWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Residual learning over computed torque: the policy's action corrects ``ComputedTorqueAgent``'s efforts.

    The environment receives a = clip(a_c + ``scale`` · a_π, −1, 1), where a_c ∈ [−1, 1]ⁿ is the action of
    ``robot_control.controllers.ComputedTorqueAgent`` (inverse dynamics of the env's model + PD toward the target,
    the offset from the holding forces in units of the drive limits, read from the observation as a policy reads
    it) and a_π ∈ [−1, 1]ⁿ the policy's. A policy that outputs zero is computed torque; training learns what to
    change (where the drives saturate, or where the straight way to the target runs near a Type II singularity).
    The observation gains a_c (n entries, float32). Rewards, terminations and infos are the wrapped env's, and
    ``info["base_action"]`` holds a_c of the step's action. A ``SingularityShield`` inside this wrapper filters
    the summed action.

    Args:
        env: A force-control env of ``envs`` (``gym.make("Planar3RPRForceReach-v0")``, any id with
            ``control="force"``).
        scale: Weight of the policy's action, in (0, 2].
        bandwidth: ω [rad/s] of computed torque's error dynamics (``ComputedTorqueAgent``).
    """

    #: The name of the same wrapper on the native vector env.
    vector_form = "VectorComputedTorqueResidualWrapper"

    def __init__(self, env: gym.Env, scale: float = 0.5, bandwidth: float = 4.0) -> None:
        """Wrap ``env``; see the class docstring."""
        self.scale = _residual_scale(scale)
        gym.utils.RecordConstructorArgs.__init__(self, scale=scale, bandwidth=bandwidth)
        gym.Wrapper.__init__(self, env)
        self.params = _force_params(env, type(self).__name__)
        self.controller = ComputedTorqueAgent(self.params, bandwidth)
        n = self.params.robot.n_actuators
        self.observation_space = _with_actions(env.observation_space, n)
        self._base_action = np.zeros(n, dtype=np.float32)

    def _augment(self, obs: np.ndarray) -> np.ndarray:
        self._base_action = self.controller(np.asarray(obs)[None])[0]
        return np.concatenate([obs, self._base_action]).astype(np.float32)

    def action(self, action: Any) -> np.ndarray:
        """The summed action the wrapped env receives for the policy's ``action`` (shape (n,)), float32."""
        return _summed(self._base_action, self.scale, action)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the wrapped env; the observation gains computed torque's action."""
        obs, info = self.env.reset(seed=seed, options=options)
        return self._augment(obs), info

    def step(self, action: Any):
        """Step the wrapped env with the summed action; the observation gains computed torque's next action."""
        base_action = self._base_action
        obs, reward, terminated, truncated, info = self.env.step(self.action(action))
        info["base_action"] = base_action
        return self._augment(obs), reward, terminated, truncated, info


class VectorComputedTorqueResidualWrapper(gym.vector.VectorWrapper):
    """``ComputedTorqueResidualWrapper`` on the native vector env (row i: the single wrapper on sub-environment i).

    Computed torque is computed for all rows at once from the batch of observations; a row that starts its next
    episode gets the action for its first observation, as the single wrapper at ``reset``, and the last observation
    of an ended episode (``info["final_obs"]``, same-step autoreset) is augmented with the action for it.
    """

    def __init__(self, env: gym.vector.VectorEnv, scale: float = 0.5, bandwidth: float = 4.0) -> None:
        """Wrap ``env``; see ``ComputedTorqueResidualWrapper``."""
        self.scale = _residual_scale(scale)
        gym.vector.VectorWrapper.__init__(self, env)
        self.params = _force_params(env, type(self).__name__)
        self.controller = ComputedTorqueAgent(self.params, bandwidth)
        n = self.params.robot.n_actuators
        self.single_observation_space = _with_actions(env.single_observation_space, n)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, env.num_envs)
        self._base_action = np.zeros((env.num_envs, n), dtype=np.float32)

    def _augment(self, obs: np.ndarray) -> np.ndarray:
        self._base_action = self.controller(obs)
        return np.concatenate([obs, self._base_action], axis=1).astype(np.float32)

    def actions(self, actions: Any) -> np.ndarray:
        """The summed actions the wrapped env receives for the policy's ``actions`` (shape (N, n)), float32."""
        return _summed(self._base_action, self.scale, actions)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        """Reset the wrapped vector env; each observation gains computed torque's action."""
        obs, info = self.env.reset(seed=seed, options=options)
        return self._augment(obs), info  # a pure function of each row's observation, reset or not

    def step(self, actions: Any):
        """Step the wrapped vector env with the summed actions; each observation gains computed torque's action."""
        base_action = self._base_action
        obs, rewards, terminated, truncated, info = self.env.step(self.actions(actions))
        info["base_action"] = base_action
        info["_base_action"] = np.ones(self.num_envs, dtype=bool)
        ended = np.flatnonzero(info.get("_final_obs", ()))
        if ended.size:  # same-step autoreset: the ended episodes' last observations, augmented as they were
            final = np.stack([info["final_obs"][i] for i in ended])
            augmented = np.concatenate([final, self.controller(final)], axis=1).astype(np.float32)
            info["final_obs"] = info["final_obs"].copy()
            for row, i in enumerate(ended):
                info["final_obs"][i] = augmented[row]
        return self._augment(obs), rewards, terminated, truncated, info
