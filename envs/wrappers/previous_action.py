"""The policy's own previous command appended to the observation.

A Reach observation is a function of the robot's state and the target only. A controller that goes around a
singular band from such an observation must choose its way around from the pose alone, so where two ways around
are about as good, its choice can flip from one control period to the next. A real controller knows the command
it sent one period ago; ``PreviousActionWrapper`` gives it that command, which carries the direction the platform
is moving in, and with it the way around already taken. It is the single-env wrapper a run names with
``env_wrapper: envs.PreviousActionWrapper`` (``training.config.ENV_WRAPPERS``); it has no vector form, so such a
run is evaluated on single envs.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["PreviousActionWrapper"]


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

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        obs_space, act_space = env.observation_space, env.action_space
        for name, space in (("observation", obs_space), ("action", act_space)):
            if not (isinstance(space, gym.spaces.Box) and len(space.shape) == 1):
                raise TypeError(f"PreviousActionWrapper needs a one-dimensional Box {name} space, got {space}")
        self._low = act_space.low.astype(np.float32)
        self._high = act_space.high.astype(np.float32)
        self.observation_space = gym.spaces.Box(
            np.concatenate([obs_space.low, self._low]).astype(np.float32),
            np.concatenate([obs_space.high, self._high]).astype(np.float32),
            dtype=np.float32,
        )
        self._previous = np.zeros(act_space.shape, dtype=np.float32)

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
