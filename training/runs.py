"""Run folders and agents: a run's configuration, model and env wrapper, and the classical controllers."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs  # noqa: F401  (registers the ids)
from envs.params import REWARD_FIELDS
from robot_control.controllers import CONTROLLERS
from training.config import ConfigError, algorithm_class, resolve_env_wrapper, vector_wrapper

__all__ = [
    "Agent",
    "EvaluationError",
    "check_compatible",
    "evaluation_env_kwargs",
    "load_controller",
    "load_model",
    "load_run",
    "read_run_config",
    "run_env_kwargs",
    "wrap_for_run",
    "wrap_vector_for_run",
    "zoo_layout",
]

#: A batched agent: observations, shape (N, D), to actions, shape (N, n).
Agent = Callable[[np.ndarray], np.ndarray]


class EvaluationError(ValueError):
    """A run folder, controller, env id or option cannot be evaluated; the message says why."""


def load_controller(name: str, env: gym.Env, planner: str | None = None, replan_distance: float | None = None) -> Agent:
    """A classical controller for an environment.

    Args:
        name: "resolved-rate", "singularity-aware" or "planner".
        env: The environment (its parameters configure the controller).
        planner: The planner controller's planner ("auto", "ompl" or "grid"); None: "auto".
        replan_distance: The planner controller's ``replan_distance`` [m] (replan when this far off the path);
            None: one plan per episode.

    Returns:
        A batched agent: observations (N, D) → actions (N, n).

    Raises:
        EvaluationError: For an unknown name, listing the valid ones.
    """
    params = env.unwrapped.params
    if name not in CONTROLLERS:
        raise EvaluationError(f"unknown controller {name!r}; valid choices: {sorted(CONTROLLERS)}")
    try:
        options = {"planner": planner} if planner else {}
        if replan_distance is not None:
            options["replan_distance"] = replan_distance
        return CONTROLLERS[name](params, **options)
    except ValueError as exc:  # the grid planner on a robot without a certified grid
        raise EvaluationError(
            f"controller {name!r} cannot drive {env.spec.id if env.spec else 'this env'}: {exc}"
        ) from exc


class _ZooLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads the RL Zoo's ``config.yml`` (an ``OrderedDict`` of key, value pairs)."""


def _ordered_dict(loader: yaml.SafeLoader, node: yaml.Node) -> dict[str, Any]:
    (pairs,) = loader.construct_sequence(node, deep=True)  # apply:collections.OrderedDict [[[key, value], ...]]
    return {key: value for key, value in pairs}


_ZooLoader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict", _ordered_dict)


def zoo_layout(run_dir: str | Path) -> tuple[str, str, Path] | None:
    """(algo, env id, parameter folder) of a run folder written by the RL Zoo, or None for any other folder.

    The RL Zoo writes ``<log>/<algo>/<env id>_<n>/`` holding the model ``<env id>.zip`` (and ``best_model.zip``)
    and a folder ``<env id>/`` with ``config.yml``, ``args.yml`` and ``vecnormalize.pkl``.

    Args:
        run_dir: A folder.

    Returns:
        The layout, or None.
    """
    run = Path(run_dir)
    env_id = run.name.rsplit("_", 1)[0]
    params = run / env_id
    if (params / "config.yml").is_file() and (params / "args.yml").is_file():
        return run.parent.name, env_id, params
    return None


def read_run_config(run_dir: str | Path) -> dict[str, Any]:
    """The resolved configuration a run folder was trained with.

    Args:
        run_dir: A run folder written by ``training.train``, or by the RL Zoo (``rl_zoo3.train``).

    Returns:
        The contents of ``config.yml`` (for an RL Zoo folder: its algorithm, env id and hyperparameters, with
        ``"source": "rl_zoo3"``).

    Raises:
        EvaluationError: If the folder or its ``config.yml`` is missing or unreadable.
    """
    run = Path(run_dir)
    if not run.is_dir():
        raise EvaluationError(f"run folder {str(run)!r} does not exist")
    zoo = zoo_layout(run)
    if zoo is not None:
        algo, env_id, params = zoo
        try:
            hyperparams = yaml.load((params / "config.yml").read_text(), Loader=_ZooLoader)
            args = yaml.load((params / "args.yml").read_text(), Loader=_ZooLoader)
        except yaml.YAMLError as exc:
            raise EvaluationError(f"{str(params)!r} holds a corrupt RL Zoo config: {exc}") from exc
        if not isinstance(hyperparams, dict) or not isinstance(args, dict):
            raise EvaluationError(f"{str(params)!r} holds a corrupt RL Zoo config")
        return {
            "algo": algo,
            "env_id": env_id,
            "seed": args.get("seed"),
            "hyperparams": hyperparams,
            "source": "rl_zoo3",
        }
    path = run / "config.yml"
    if not path.is_file():
        present = sorted(p.name for p in run.iterdir())
        raise EvaluationError(f"{str(run)!r} is not a run folder: no config.yml (it holds {present})")
    try:
        config = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise EvaluationError(f"{str(path)!r} is corrupt: {exc}") from exc
    if not isinstance(config, dict) or "algo" not in config or "env_id" not in config:
        raise EvaluationError(f"{str(path)!r} is corrupt: it must name 'algo' and 'env_id'")
    return config


def load_model(run_dir: str | Path, which: str = "final") -> tuple[Any, Any, dict[str, Any]]:
    """Load a run folder's SB3 model and its observation normalisation.

    Args:
        run_dir: The run folder written by ``training.train`` (or the RL Zoo, or ``training.distill``).
        which: "final" (``model.zip``) or "best" (``best_model.zip`` of the periodic evaluations).

    Returns:
        (the model on the CPU, its ``VecNormalize`` in evaluation mode or None, the run's configuration).

    Raises:
        EvaluationError: If the folder, the model or the normalisation statistics are missing or corrupt.
    """
    import torch
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    torch.set_num_threads(1)  # small MLPs: threads only contend with the environment
    config = read_run_config(run_dir)
    run = Path(run_dir)
    zoo = config.get("source") == "rl_zoo3"
    names = {"final": f"{config['env_id']}.zip" if zoo else "model.zip", "best": "best_model.zip"}
    if which not in names:
        raise EvaluationError(f"--model must be one of {sorted(names)}, got {which!r}")
    model_path = run / names[which]
    if not model_path.is_file():
        raise EvaluationError(f"run folder {str(run)!r} has no {names[which]}")
    try:
        cls = algorithm_class(config["algo"])
    except ConfigError as exc:
        raise EvaluationError(f"{str(run / 'config.yml')!r}: {exc}") from exc
    load_env = None
    if config.get("hyperparams", {}).get("replay_buffer_class"):  # SB3 rebuilds a HER buffer around an env
        env_id = config.get("env_id")
        load_env = DummyVecEnv([lambda: wrap_for_run(gym.make(env_id), config)])
    try:
        with warnings.catch_warnings():
            # A run with n_steps > 1 saved its NStepReplayBuffer class; on reload SB3 warns that n_steps is
            # then ignored. The buffer is not used for evaluation.
            warnings.filterwarnings("ignore", message=r"`n_steps=\d+` is ignored", category=UserWarning)
            model = cls.load(model_path, env=load_env, device="cpu")
    except Exception as exc:  # SB3 raises many kinds on a damaged zip
        raise EvaluationError(f"cannot load {str(model_path)!r}: {type(exc).__name__}: {exc}") from exc
    normalizer = None
    if zoo:  # the RL Zoo keeps one set of statistics, saved with the model
        stats = run / config["env_id"] / "vecnormalize.pkl"
    else:
        stats = run / ("best_vecnormalize.pkl" if which == "best" else "vecnormalize.pkl")
    if config.get("hyperparams", {}).get("normalize"):
        if not stats.is_file():
            raise EvaluationError(f"run folder {str(run)!r} normalises observations but has no {stats.name}")
        env_id, env_kwargs = config["env_id"], run_env_kwargs(config)
        try:
            venv = DummyVecEnv([lambda: wrap_for_run(gym.make(env_id, **env_kwargs), config)])
            normalizer = VecNormalize.load(str(stats), venv)
        except Exception as exc:
            raise EvaluationError(f"cannot load {str(stats)!r}: {type(exc).__name__}: {exc}") from exc
        normalizer.training = False
    return model, normalizer, config


def load_run(run_dir: str | Path, which: str = "final") -> tuple[Agent, dict[str, Any]]:
    """Load a trained policy and its observation normalisation from a run folder.

    Args:
        run_dir: The run folder written by ``training.train``.
        which: "final" (``model.zip``) or "best" (``best_model.zip`` of the periodic evaluations).

    Returns:
        (a batched deterministic agent, the run's configuration).

    Raises:
        EvaluationError: If the folder, the model or the normalisation statistics are missing or corrupt.
    """
    model, normalizer, config = load_model(run_dir, which)

    def agent(obs: np.ndarray) -> np.ndarray:
        if normalizer is not None:
            obs = normalizer.normalize_obs(obs)
        action, _ = model.predict(obs, deterministic=True)
        return action

    agent.observation_space = model.observation_space  # type: ignore[attr-defined]
    return agent, config


def run_env_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """The env keyword arguments a run was trained with (its config's ``env_kwargs``; {} if none)."""
    return dict(config.get("hyperparams", {}).get("env_kwargs") or {})


def evaluation_env_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """``run_env_kwargs(config)`` without the reward-only settings (``envs.params.REWARD_FIELDS``).

    An evaluation leaves them at the id's values, so that every agent's return is the same reward's and returns
    compare across agents (a run trained with ``success_reward`` is scored without it).
    """
    return {key: value for key, value in run_env_kwargs(config).items() if key not in REWARD_FIELDS}


def wrap_for_run(env: gym.Env, config: dict[str, Any]) -> gym.Env:
    """Apply the run's ``env_wrapper`` (for example the goal view HER trains on), if it has one.

    Args:
        env: The environment to evaluate on.
        config: The run's ``config.yml``.

    Returns:
        ``env`` wrapped as in training.

    Raises:
        EvaluationError: If the config names an unknown wrapper or the env cannot take it.
    """
    try:
        wrapper = resolve_env_wrapper(config.get("hyperparams", {}).get("env_wrapper"))
        return env if wrapper is None else wrapper(env)
    except (ConfigError, TypeError) as exc:
        raise EvaluationError(f"cannot wrap {env.spec.id if env.spec else env} as the run was trained: {exc}") from exc


def wrap_vector_for_run(venv: gym.vector.VectorEnv, config: dict[str, Any]) -> gym.vector.VectorEnv | None:
    """Apply the vector form of the run's ``env_wrapper`` (its ``vector_form``) to a native vector env.

    Returns:
        ``venv`` wrapped as the run's single envs were (``venv`` itself for a run without a wrapper), or None when
        the run's wrapper has no vector form (``envs.GoalReachWrapper``): evaluate it on single envs.

    Raises:
        EvaluationError: If the config names an unknown wrapper.
    """
    try:
        wrapper = resolve_env_wrapper(config.get("hyperparams", {}).get("env_wrapper"))
    except ConfigError as exc:
        raise EvaluationError(f"cannot wrap the vector env as the run was trained: {exc}") from exc
    if wrapper is None:
        return venv
    form = vector_wrapper(wrapper)
    return None if form is None else form(venv)


def _shapes(space: gym.Space) -> Any:
    if isinstance(space, gym.spaces.Dict):
        return {key: sub.shape for key, sub in space.spaces.items()}
    return space.shape


def check_compatible(agent: Agent, env: gym.Env, source: str) -> None:
    """Raise if a trained agent expects observations of another shape than ``env`` gives.

    Args:
        agent: An agent from ``load_run`` (classical controllers have no fixed shape and always pass).
        env: The environment to evaluate on.
        source: Where the agent came from, for the message.

    Raises:
        EvaluationError: On a shape mismatch, naming both shapes.
    """
    space = getattr(agent, "observation_space", None)
    if space is not None and _shapes(space) != _shapes(env.observation_space):
        raise EvaluationError(
            f"{source} was trained on observations of shape {_shapes(space)}, but {env.spec.id} gives "
            f"{_shapes(env.observation_space)}; evaluate it on the env it was trained on"
        )
