"""Hyperparameters as data: the RL Zoo's YAML layout, read with a safe YAML loader and checked key by key."""

from __future__ import annotations

import copy
import inspect
import re
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from sb3_contrib import TQC
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm

__all__ = [
    "ALGORITHMS",
    "EVAL_DEFAULTS",
    "ConfigError",
    "algorithm_class",
    "load_hyperparams",
    "parse_overrides",
    "resolve_action_noise",
    "resolve_env_wrapper",
    "resolve_policy_kwargs",
    "resolve_replay_buffer",
    "resolve_schedules",
    "vector_wrapper",
]

#: Algorithms the project trains, by command-line name.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3, "tqc": TQC}

#: Keys of an env entry that belong to the run, not to the algorithm's constructor (RL Zoo layout).
RUN_KEYS = (
    "n_envs",
    "n_timesteps",
    "policy",
    "normalize",
    "env_kwargs",
    "env_wrapper",
)

#: Periodic evaluation during training, per algorithm: (every so many environment steps, episodes). These are run
#: settings, not hyperparameters (the RL Zoo's ``--eval-freq`` and ``--eval-episodes`` flags, which
#: ``training.train`` takes under the same names), so the YAML files stay loadable by the RL Zoo unchanged.
EVAL_DEFAULTS = {"ppo": (100_000, 20), "sac": (20_000, 20), "td3": (20_000, 20), "tqc": (20_000, 20)}

#: Run keys of the off-policy algorithms (those whose constructor takes ``action_noise``), as in the RL Zoo:
#: ``noise_type`` names the exploration noise added to the deterministic actor's output, ``noise_std`` its
#: standard deviation per action dimension (in the normalised action units of [-1, 1]).
NOISE_KEYS = ("noise_type", "noise_std")

#: Noise types that ``noise_type`` may name, with SB3's class names.
NOISE_TYPES = {"normal": "NormalActionNoise", "ornstein-uhlenbeck": "OrnsteinUhlenbeckActionNoise"}

#: Wrappers that ``env_wrapper`` may name (the RL Zoo's key; an allow-list, nothing is imported by name).
ENV_WRAPPERS = (
    "envs.GoalReachWrapper",
    "robot_control.ComputedTorqueResidualWrapper",
    "robot_control.PlannerResidualWrapper",
    "robot_control.PlannerWaypointWrapper",
    "envs.PreviousActionWrapper",
)

#: Wrapper names of run folders written before the planner's wrappers moved from ``envs`` to ``robot_control``.
RENAMED_ENV_WRAPPERS = {
    "envs.PlannerResidualWrapper": "robot_control.PlannerResidualWrapper",
    "envs.PlannerWaypointWrapper": "robot_control.PlannerWaypointWrapper",
}

#: Replay buffers that ``replay_buffer_class`` may name.
REPLAY_BUFFERS = ("HerReplayBuffer",)

#: Activation functions that ``policy_kwargs.activation_fn`` may name (no ``eval`` of strings).
_ACTIVATIONS = ("ReLU", "Tanh", "ELU", "LeakyReLU", "GELU", "SiLU")

#: Constructor arguments set by the training script itself, never from a config.
_RESERVED = ("self", "policy", "env", "seed", "device", "verbose", "tensorboard_log", "_init_setup_model")


class _Loader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads YAML 1.2 floats such as ``1e-3`` (YAML 1.1 needs a dot)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def safe_load(text: str) -> Any:
    """``yaml.safe_load`` with YAML 1.2 floats: no Python objects are ever constructed.

    Args:
        text: YAML text.

    Returns:
        The parsed data.
    """
    return yaml.load(text, Loader=_Loader)  # _Loader derives from SafeLoader


class ConfigError(ValueError):
    """A hyperparameter file, entry or override is invalid; the message lists the valid choices."""


def algorithm_class(algo: str) -> type[BaseAlgorithm]:
    """The SB3 class for an algorithm name.

    Args:
        algo: "ppo", "sac", "td3" or "tqc" (case-insensitive).

    Returns:
        The algorithm class.

    Raises:
        ConfigError: For an unknown name, listing the valid ones.
    """
    key = str(algo).lower()
    if key not in ALGORITHMS:
        raise ConfigError(f"unknown algorithm {algo!r}; valid choices: {sorted(ALGORITHMS)}")
    return ALGORITHMS[key]


def valid_keys(algo: str) -> set[str]:
    """Every key an env entry of ``algo``'s YAML file may hold.

    Args:
        algo: Algorithm name.

    Returns:
        The run keys and the algorithm constructor's own arguments. An algorithm that takes
        ``action_noise`` gets ``noise_type`` and ``noise_std`` in its place (an object YAML cannot hold).
    """
    params = inspect.signature(algorithm_class(algo).__init__).parameters
    keys = set(RUN_KEYS) | {name for name in params if name not in _RESERVED}
    if "action_noise" in keys:
        keys = (keys - {"action_noise"}) | set(NOISE_KEYS)
    return keys


def default_config_path(algo: str) -> Path:
    """The shipped YAML file of an algorithm: ``training/<algo>.yml``.

    Args:
        algo: Algorithm name.

    Returns:
        Its path.
    """
    algorithm_class(algo)
    return Path(str(resources.files("training").joinpath(f"{algo.lower()}.yml")))


def load_hyperparams(
    algo: str, env_id: str, path: str | Path | None = None, overrides: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Read the hyperparameters of ``env_id`` for ``algo`` and apply command-line overrides.

    Args:
        algo: Algorithm name.
        env_id: Environment id, a top-level key of the YAML file.
        path: YAML file; default ``training/<algo>.yml``.
        overrides: Keys to replace (already parsed, see ``parse_overrides``).

    Returns:
        A fresh dict of hyperparameters (run keys and algorithm arguments).

    Raises:
        ConfigError: If the file is missing or malformed, has no entry for ``env_id``, or an entry or
            override holds a key the algorithm does not take.
    """
    path = Path(path) if path is not None else default_config_path(algo)
    if not path.is_file():
        raise ConfigError(f"hyperparameter file {str(path)!r} does not exist")
    try:
        data = safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"hyperparameter file {str(path)!r} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"hyperparameter file {str(path)!r} must map env ids to settings, got {type(data).__name__}")
    if env_id not in data:
        raise ConfigError(f"{str(path)!r} has no entry for env {env_id!r}; entries: {sorted(data)}")
    entry = data[env_id]
    if not isinstance(entry, dict):
        raise ConfigError(f"entry {env_id!r} of {str(path)!r} must be a mapping, got {type(entry).__name__}")
    config = copy.deepcopy(entry)
    config.update(overrides or {})
    allowed = valid_keys(algo)
    unknown = sorted(set(config) - allowed)
    if unknown:
        raise ConfigError(
            f"unknown hyperparameter(s) {unknown} for {algo.upper()} (from {str(path)!r} or the command line); "
            f"valid keys: {sorted(allowed)}"
        )
    for key in ("n_envs", "n_timesteps"):
        value = config.get(key, 1)
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
            raise ConfigError(f"{key} must be a positive integer, got {value!r}")
    return config


def parse_overrides(items: list[str] | None) -> dict[str, Any]:
    """Parse ``key=value`` overrides; values are YAML scalars or flow collections (``yaml.safe_load``).

    Args:
        items: Strings such as ``"learning_rate=1e-3"`` or ``"policy_kwargs={net_arch: [64, 64]}"``.

    Returns:
        The overrides as a dict.

    Raises:
        ConfigError: On an item without ``=`` or with an unparsable value.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"override {item!r} must look like key=value")
        try:
            out[key.strip()] = safe_load(raw)
        except yaml.YAMLError as exc:
            raise ConfigError(f"override {item!r}: value is not valid YAML: {exc}") from exc
    return out


def resolve_policy_kwargs(policy_kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """Turn the YAML form of ``policy_kwargs`` into SB3's (an activation name into its torch class).

    Args:
        policy_kwargs: As written in YAML, or None.

    Returns:
        A new dict ready for the algorithm's constructor.

    Raises:
        ConfigError: For an activation function outside the allowed list.
    """
    import torch

    kwargs = dict(policy_kwargs or {})
    name = kwargs.get("activation_fn")
    if name is not None:
        if name not in _ACTIVATIONS:
            raise ConfigError(f"policy_kwargs.activation_fn {name!r} is not one of {list(_ACTIVATIONS)}")
        kwargs["activation_fn"] = getattr(torch.nn, name)
    return kwargs


#: Hyperparameters that SB3 accepts as a schedule of the remaining progress (1 → 0).
SCHEDULED_KEYS = ("learning_rate", "clip_range", "clip_range_vf")


def resolve_schedules(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """Turn the RL Zoo's ``lin_<value>`` strings into linear schedules (value · remaining progress).

    Args:
        hyperparams: Algorithm arguments as written in YAML.

    Returns:
        A new dict where e.g. ``learning_rate: lin_3e-4`` became a callable decaying 3e-4 → 0.

    Raises:
        ConfigError: For a string that is not ``lin_<positive number>``.
    """
    out = dict(hyperparams)
    for key in SCHEDULED_KEYS:
        value = out.get(key)
        if not isinstance(value, str):
            continue
        prefix, _, number = value.partition("_")
        try:
            initial = float(number)
        except ValueError:
            initial = -1.0
        if prefix != "lin" or not initial > 0:
            raise ConfigError(f"{key} must be a number or 'lin_<positive number>', got {value!r}")
        out[key] = LinearSchedule(initial)
    return out


class LinearSchedule:
    """initial · progress_remaining, picklable (SB3 saves schedules with the model)."""

    def __init__(self, initial: float) -> None:
        self.initial = float(initial)

    def __call__(self, progress_remaining: float) -> float:
        """The value at ``progress_remaining`` (1 at the start of training, 0 at the end)."""
        return self.initial * progress_remaining

    def __repr__(self) -> str:
        return f"lin_{self.initial!r}"


def resolve_action_noise(noise_type: Any, noise_std: Any, n_actions: int) -> Any:
    """SB3's action-noise object for the RL Zoo keys ``noise_type`` and ``noise_std``.

    Args:
        noise_type: ``"normal"``, ``"ornstein-uhlenbeck"`` or None (no noise).
        noise_std: Standard deviation per action dimension, in action units (> 0); required with a type.
        n_actions: Size of the action vector.

    Returns:
        A ``NormalActionNoise`` or ``OrnsteinUhlenbeckActionNoise`` with zero mean and σ = noise_std in every
        dimension, or None. SB3 wraps it per environment when there are several.

    Raises:
        ConfigError: For an unknown type, a missing or non-positive σ, or a σ without a type.
    """
    if noise_type is None:
        if noise_std is not None:
            raise ConfigError(f"noise_std {noise_std!r} needs a noise_type, one of {list(NOISE_TYPES)}")
        return None
    if noise_type not in NOISE_TYPES:
        raise ConfigError(f"noise_type {noise_type!r} is not one of {list(NOISE_TYPES)}")
    if isinstance(noise_std, bool) or not isinstance(noise_std, (int, float)) or not 0.0 < noise_std < np.inf:
        raise ConfigError(f"noise_std must be a positive number with noise_type {noise_type!r}, got {noise_std!r}")
    from stable_baselines3.common import noise

    cls = getattr(noise, NOISE_TYPES[noise_type])
    return cls(mean=np.zeros(n_actions), sigma=float(noise_std) * np.ones(n_actions))


def resolve_env_wrapper(name: Any) -> Any:
    """The wrapper an ``env_wrapper`` entry names (None for none), as the RL Zoo reads it.

    Args:
        name: A string of ``ENV_WRAPPERS`` (or a former name in ``RENAMED_ENV_WRAPPERS``), a one-entry mapping
            {name: keyword arguments} (the RL Zoo's form for a wrapper with arguments, e.g.
            ``{robot_control.PlannerWaypointWrapper: {lookahead: 0.05}}``), or None.

    Returns:
        The class (or the class with its keyword arguments bound, ``functools.partial``), or None.

    Raises:
        ConfigError: For any other value, listing the valid ones.
    """
    if name is None:
        return None
    kwargs: dict[str, Any] = {}
    if isinstance(name, dict):
        if len(name) != 1 or not isinstance(next(iter(name.values())) or {}, dict):
            raise ConfigError(f"env_wrapper must be a name or {{name: {{keyword: value}}}}, got {name!r}")
        name, kwargs = next(iter(name.items()))
        kwargs = kwargs or {}
    name = RENAMED_ENV_WRAPPERS.get(name, name) if isinstance(name, str) else name
    if not isinstance(name, str) or name not in ENV_WRAPPERS:
        raise ConfigError(f"env_wrapper {name!r} is not one of {list(ENV_WRAPPERS)}")
    import functools
    import importlib

    module, _, attribute = name.rpartition(".")
    cls = getattr(importlib.import_module(module), attribute)
    return functools.partial(cls, **kwargs) if kwargs else cls


def resolve_replay_buffer(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """Turn a ``replay_buffer_class`` name into SB3's class.

    Args:
        hyperparams: Algorithm arguments as written in YAML.

    Returns:
        A new dict with the class in place of its name.

    Raises:
        ConfigError: For a name outside ``REPLAY_BUFFERS``.
    """
    out = dict(hyperparams)
    name = out.get("replay_buffer_class")
    if name is None:
        return out
    if name not in REPLAY_BUFFERS:
        raise ConfigError(f"replay_buffer_class {name!r} is not one of {list(REPLAY_BUFFERS)}")
    from stable_baselines3 import HerReplayBuffer

    out["replay_buffer_class"] = HerReplayBuffer
    return out


def vector_wrapper(wrapper: Any) -> Any:
    """The vector form of a resolved ``env_wrapper`` (``resolve_env_wrapper``), with the same keyword arguments.

    Args:
        wrapper: A wrapper class, a ``functools.partial`` of one, or None.

    Returns:
        A callable that wraps a native vector env as ``wrapper`` wraps each single env (the class its
        ``vector_form`` names, in the same module), or None when ``wrapper`` is None or has no vector form.
    """
    if wrapper is None:
        return None
    import functools
    import sys

    cls = getattr(wrapper, "func", wrapper)
    form = getattr(cls, "vector_form", None)
    if form is None:
        return None
    vector_cls = getattr(sys.modules[cls.__module__], form)
    kwargs = getattr(wrapper, "keywords", {})
    return functools.partial(vector_cls, **kwargs) if kwargs else vector_cls
