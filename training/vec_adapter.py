"""Stable-Baselines3 ``VecEnv`` on top of the native vector environment (same-step autoreset)."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn

import envs  # noqa: F401  (registers the ids)
from envs.vector import FamilyVectorEnv

__all__ = ["NativeVecEnvAdapter"]

#: Keys of a Gymnasium vector info that are not per-environment values.
_VECTOR_ONLY_KEYS = ("final_obs", "final_info")


def _split_infos(infos: dict[str, Any], n: int, rows: Sequence[int] | np.ndarray | None = None) -> list[dict[str, Any]]:
    """Per-environment info dicts from Gymnasium's vector layout (``key`` arrays and ``_key`` masks).

    Scalars become Python ``float`` / ``bool`` / ``str`` and vectors NumPy rows, as a single env gives them.

    Args:
        infos: Vector infos; ``infos[key]`` has a leading dimension n.
        n: Number of environments.
        rows: Environments to extract (default all).

    Returns:
        One dict per environment of ``rows`` (all: n dicts), holding the keys whose mask is set.
    """
    rows = range(n) if rows is None else [int(i) for i in rows]
    out: list[dict[str, Any]] = [{} for _ in rows]
    for key, value in infos.items():
        if key.startswith("_") or key in _VECTOR_ONLY_KEYS:
            continue
        mask = infos.get(f"_{key}")
        column = value.tolist() if value.ndim == 1 and value.dtype != object else list(value)
        for info, i in zip(out, rows):
            if mask is None or mask[i]:
                info[key] = column[i]
    return out


class NativeVecEnvAdapter(VecEnv):
    """SB3's ``VecEnv`` contract over a native ``FamilyVectorEnv`` (no Python loop over robots per step).

    SB3 expects the reset of an ended environment within the step that ends it, so the native env
    runs in ``AutoresetMode.SAME_STEP``. ``step_wait`` returns (obs (N, obs_dim) float32, rewards
    (N,) float32, dones (N,) bool, infos): ``infos[i]`` is the single env's info dict of the step,
    plus ``"TimeLimit.truncated"`` (truncated and not terminated) and, when ``dones[i]``,
    ``"terminal_observation"`` (the last observation of the episode, shape (obs_dim,)); the reset
    info of the new episode goes to ``reset_infos[i]`` and ``obs[i]`` is its first observation.
    This is what ``DummyVecEnv`` of ``gym.make`` envs gives, with the same seeds (``seed(s)`` then
    ``reset()`` seeds environment i with s + i).

    Sub-environments are rows of one batch, not objects: ``get_attr`` gives the single env's
    attribute (spaces, ``params``, ``targets``, ...; ``np_random`` per environment),
    ``set_attr`` sets shared attributes only, ``env_method`` supports ``"render"``, and
    ``env_is_wrapped`` is False for every wrapper.

    Args:
        venv: A native vector env in ``SAME_STEP`` autoreset mode (see ``from_id``), or a vector wrapper over one
            (the ``vector_form`` of a run's ``env_wrapper``): steps, resets and frames go through the wrapper,
            attributes are the native env's.
    """

    def __init__(self, venv: FamilyVectorEnv | gym.vector.VectorWrapper) -> None:
        native = venv.unwrapped
        if not isinstance(native, FamilyVectorEnv):
            raise TypeError(f"venv must be a FamilyVectorEnv or a wrapper of one, got {type(native).__name__}")
        if native.metadata.get("autoreset_mode") is not AutoresetMode.SAME_STEP:
            raise ValueError(
                "the native vector env must use autoreset_mode=AutoresetMode.SAME_STEP for SB3, "
                f"got {native.metadata.get('autoreset_mode')}"
            )
        self.venv = venv
        self._native = native
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)

    @classmethod
    def from_id(cls, env_id: str, n_envs: int, wrapper: Any = None, **env_kwargs: Any) -> NativeVecEnvAdapter:
        """Make the native vector env of a registered id (``gym.make_vec``) in same-step mode and wrap it.

        Args:
            env_id: A registered id with a ``vector_entry_point`` (every id of ``envs.ENV_IDS``).
            n_envs: Number of environments.
            wrapper: A callable that wraps the native vector env (a vector wrapper class), or None.
            **env_kwargs: Keyword arguments of the env (and ``max_episode_steps``, ``render_mode``).

        Returns:
            The adapter.
        """
        venv = gym.make_vec(
            env_id,
            num_envs=n_envs,
            vectorization_mode="vector_entry_point",
            autoreset_mode=AutoresetMode.SAME_STEP,
            **env_kwargs,
        )
        return cls(venv if wrapper is None else wrapper(venv))

    # -- the VecEnv contract ---------------------------------------------------------------------

    def reset(self) -> VecEnvObs:
        """Reset every environment with the seeds of ``seed()`` and the options of ``set_options()``.

        Returns:
            Observations, shape (N, obs_dim), float32. ``reset_infos`` holds the N reset infos.
        """
        seeds = list(self._seeds) if any(s is not None for s in self._seeds) else None
        options = self._options
        if all(o == options[0] for o in options[1:]):
            obs, infos = self.venv.reset(seed=seeds, options=dict(options[0]) or None)
            self.reset_infos = _split_infos(infos, self.num_envs)
        else:
            if self._native.state is None:
                raise ValueError("per-environment options need a first reset with options common to every env")
            groups: list[tuple[dict[str, Any], np.ndarray]] = []
            for i, option in enumerate(options):
                for common, mask in groups:
                    if common == option:
                        mask[i] = True
                        break
                else:
                    mask = np.zeros(self.num_envs, dtype=bool)
                    mask[i] = True
                    groups.append((option, mask))
            for option, mask in groups:
                obs, infos = self.venv.reset(seed=seeds, options={**option, "reset_mask": mask})
                for i, info in zip(np.flatnonzero(mask), _split_infos(infos, self.num_envs, np.flatnonzero(mask))):
                    self.reset_infos[i] = info
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions of the next ``step_wait``.

        Args:
            actions: Shape (N, 3).
        """
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every robot; ended episodes restart at once (see the class docstring).

        Returns:
            (obs (N, obs_dim) float32, rewards (N,) float32, dones (N,) bool, list of N info dicts).
        """
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        dones = terminated | truncated
        step_infos = _split_infos(infos, self.num_envs)
        ended = np.flatnonzero(dones)
        if ended.size:
            finals = _split_infos(infos["final_info"], self.num_envs, ended)
            for i, final in zip(ended, finals):
                self.reset_infos[i] = step_infos[i]
                final["terminal_observation"] = infos["final_obs"][i]
                step_infos[i] = final
        time_limit = (truncated & ~terminated).tolist()
        for info, flag in zip(step_infos, time_limit):
            info["TimeLimit.truncated"] = flag
        return obs, rewards.astype(np.float32), dones, step_infos

    def close(self) -> None:
        """Close the native vector env."""
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The frames of the N environments (``render_mode="rgb_array"``).

        Returns:
            N uint8 arrays (H, W, 3); N Nones with a warning in another render mode.
        """
        if self.render_mode != "rgb_array":
            warnings.warn(
                f"The render mode is {self.render_mode}, but this method assumes it is `rgb_array` to obtain images.",
                stacklevel=2,
            )
            return [None] * self.num_envs
        return list(self.venv.render())

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """An attribute of each selected environment (see the class docstring).

        Args:
            attr_name: Attribute name, for example ``"render_mode"``, ``"params"`` or ``"np_random"``.
            indices: Environments to read (default all).

        Returns:
            One value per selected environment.
        """
        values = self._native.get_attr(attr_name)
        return [values[i] for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set a shared attribute (such as ``targets``) of the environments.

        Args:
            attr_name: Attribute name.
            value: New value.
            indices: Must select every environment (they share the attribute) unless the value is unchanged.

        Raises:
            ValueError: If only some environments are selected and the value would change.
        """
        selected = list(self._get_indices(indices))
        if sorted(selected) != list(range(self.num_envs)):
            current = self._native.get_attr(attr_name)
            if all(current[i] == value for i in selected):
                return
            raise ValueError(
                f"the native environments share {attr_name!r}; set it for all {self.num_envs} at once, "
                f"not for indices {selected}"
            )
        self._native.set_attr(attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        """Call a method of each selected environment: ``"render"`` (frames) or ``"get_wrapper_attr"``.

        Args:
            method_name: "render" or "get_wrapper_attr".
            *method_args: Arguments of the method (the attribute name for ``get_wrapper_attr``).
            indices: Environments (default all).
            **method_kwargs: Keyword arguments of the method (none are used).

        Returns:
            One result per selected environment.

        Raises:
            NotImplementedError: For another method name.
        """
        if method_name == "render":
            frames = self.venv.render()
            if frames is None:
                return [None for _ in self._get_indices(indices)]
            return [frames[i] for i in self._get_indices(indices)]
        if method_name == "get_wrapper_attr":
            return self.get_attr(method_args[0], indices)
        raise NotImplementedError(
            f"env_method({method_name!r}) is not available: the native environments are rows of one batch; "
            "supported methods are 'render' and 'get_wrapper_attr'"
        )

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        """No Gymnasium wrapper sits around the native environments.

        Args:
            wrapper_class: Any wrapper class.
            indices: Environments (default all).

        Returns:
            False for each selected environment.
        """
        return [False for _ in self._get_indices(indices)]
