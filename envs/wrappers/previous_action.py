"""The policy's own previous command appended to the observation.

A Reach observation is a function of the robot's state and the target only. A controller that goes around a
singular band from such an observation must choose its way around from the pose alone, so where two ways around
are about as good, its choice can flip from one control period to the next. A real controller knows the command
it sent one period ago; ``PreviousActionWrapper`` gives it that command, which carries the direction the platform
is moving in, and with it the way around already taken. It is the single-env wrapper a run names with
``env_wrapper: envs.PreviousActionWrapper`` (``training.config.ENV_WRAPPERS``); ``VectorPreviousActionWrapper`` is its
vector form on the native vector env (row i is the single wrapper on sub-environment i).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from envs.vector import episode_starts

__all__ = ["PreviousActionWrapper", "VectorPreviousActionWrapper"]


def _appended(space: gym.Space, action_space: gym.Space, name: str) -> gym.spaces.Box:
    """``space`` (a 1-D Box) with the action space's bounds (a 1-D Box) appended."""
    for kind, box in (("observation", space), ("action", action_space)):
        if not (isinstance(box, gym.spaces.Box) and len(box.shape) == 1):
            raise TypeError(f"{name} needs a one-dimensional Box {kind} space, got {box}")
    return gym.spaces.Box(
        np.concatenate([space.low, action_space.low]).astype(np.float32),
        np.concatenate([space.high, action_space.high]).astype(np.float32),
        dtype=np.float32,
    )


class PreviousActionWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Append the previous action to the observation: ``[obs, a_{t−1}]``, shape (D + n,), float32.

    ``a_{t−1}`` is the action passed to the last ``step``, clipped to the action space's bounds (the normalised
    stroke rates in [-1, 1] the env applies), and zeros after ``reset`` (the robot starts at rest). The
    observation space is the env's Box with the action space's bounds appended. Dynamics, reward, termination
    and info are the env's own.

    Args:
        env: An environment with a flat Box observation space of shape (D,) and a Box action space of shape (n,)
            (a ``gym.make`` Reach or Track env, possibly wrapped).

    Raises:
        TypeError: If the observation or action space is not a one-dimensional Box.
    """

    vector_form = "VectorPreviousActionWrapper"

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self.observation_space = _appended(env.observation_space, env.action_space, type(self).__name__)
        self._low = env.action_space.low.astype(np.float32)
        self._high = env.action_space.high.astype(np.float32)
        self._previous = np.zeros_like(self._low)

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(obs, dtype=np.float32), self._previous])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """The env's reset; the previous action is zero."""
        obs, info = self.env.reset(seed=seed, options=options)
        self._previous = np.zeros_like(self._low)
        return self._observe(obs), info

    def step(self, action: np.ndarray):
        """The env's step with ``action`` (n,); the next observation ends with ``action`` clipped to its bounds."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._previous = np.clip(np.asarray(action, dtype=np.float32).reshape(self._low.shape), self._low, self._high)
        return self._observe(obs), reward, terminated, truncated, info


class VectorPreviousActionWrapper(gym.vector.VectorWrapper):
    """``PreviousActionWrapper`` on a vector env: row i's observation ends with row i's previous action.

    A row whose episode starts at this step (after ``reset``, or by autoreset: at the step after its end with
    ``AutoresetMode.NEXT_STEP``, which ignores that step's action; at its end with ``SAME_STEP``, which returns the
    next episode's first observation) shows zeros, as the single wrapper does after ``reset``.

    Args:
        env: A vector env with one-dimensional Box single observation and action spaces.

    Raises:
        TypeError: If a single space is not a one-dimensional Box.
    """

    def __init__(self, env: gym.vector.VectorEnv) -> None:
        super().__init__(env)
        self.single_observation_space = _appended(
            env.single_observation_space, env.single_action_space, type(self).__name__
        )
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, env.num_envs)
        self._low = env.single_action_space.low.astype(np.float32)
        self._high = env.single_action_space.high.astype(np.float32)
        self._previous = np.zeros((env.num_envs, *self._low.shape), dtype=np.float32)
        self._ended = np.zeros(env.num_envs, dtype=bool)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        """The vector env's reset; the reset rows' previous actions are zero."""
        obs, info = self.env.reset(seed=seed, options=options)
        mask = (options or {}).get("reset_mask")
        rows = np.flatnonzero(mask) if mask is not None else np.arange(self.num_envs)
        self._previous[rows] = 0.0
        self._ended[rows] = False
        return np.concatenate([obs, self._previous], axis=1).astype(np.float32), info

    def step(self, actions: np.ndarray):
        """The vector env's step; each row's observation ends with its action, clipped (zeros where one starts)."""
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        previous = np.clip(np.asarray(actions, dtype=np.float32).reshape(self._previous.shape), self._low, self._high)
        mode = getattr(self.env.unwrapped, "autoreset_mode", gym.vector.AutoresetMode.NEXT_STEP)
        previous[episode_starts(mode, self._ended, terminated, truncated)] = 0.0
        self._previous = previous
        self._ended = np.asarray(terminated | truncated)
        return np.concatenate([obs, previous], axis=1).astype(np.float32), rewards, terminated, truncated, info
