"""Headless evaluation of a trained run or a classical controller on fixed-seed episodes.

Usage::

    python -m training.evaluate --run DIR | --controller resolved-rate|singularity-aware|planner
                                [--env ID] [--episodes 100] [--seed 0] [--targets standard|hard]
                                [--video] [--out DIR] [--model final|best] [--planner auto|ompl|grid]
                                [--env-kwargs KEY:VALUE ...]

Without ``--video`` every episode runs at once on the id's native vector env (``evaluate_vector``); with it, one
after the other on the single env (``evaluate_agent``), filmed. Writes ``metrics.json`` (aggregates),
``episodes.csv`` (one row per episode), ``trajectories.png`` (paths over the inverse-condition-number map),
``condition_number.png`` (k over time) and, with ``--video``, ``episodes.gif``; prints the metrics as a table.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs
from envs.params import REWARD_FIELDS
from envs.physics import TERMINATION_REASONS
from training.config import ConfigError, algorithm_class, resolve_env_wrapper
from training.controllers import CONTROLLERS
from training.intervals import SUCCESS_CI_NOTE, format_success_interval
from training.records import EpisodeRecord

__all__ = [
    "EpisodeRecord",
    "EvaluationError",
    "aggregate",
    "check_compatible",
    "evaluate_agent",
    "evaluate_rows",
    "evaluate_vector",
    "evaluation_env_kwargs",
    "load_controller",
    "load_model",
    "load_run",
    "main",
    "make_vector_env",
    "parse_env_kwargs",
    "run_env_kwargs",
    "wrap_for_run",
    "wrap_vector_for_run",
]

#: Termination reasons that mean the robot met a singularity (Type II, and Type I for cranks and sliders).
SINGULARITY_REASONS = ("singular", "singularity_crossed", "assembly_mode_change", "newton_failed", "actuator_singular")
TARGET_SETS = ("standard", "hard")
Agent = Callable[[np.ndarray], np.ndarray]


class EvaluationError(ValueError):
    """A run folder, controller, env id or option cannot be evaluated; the message says why."""


#: Settling time excluded from the tracking metrics [s]: the platform starts on the reference, and the first
#: second is the controller's transient.
TRACKING_SETTLING_S = 1.0
#: Largest lag searched when estimating the tracking lag [s].
TRACKING_MAX_LAG_S = 1.0


def tracking_metrics(
    position_errors: np.ndarray,
    orientation_errors: np.ndarray,
    costs: np.ndarray,
    positions: np.ndarray,
    target_positions: np.ndarray,
    dt: float,
) -> dict[str, float]:
    """RMS and maximum tracking errors, cost fraction and lag of one Track episode, after the settling time.

    The lag is the delay τ (a multiple of dt, 0 … ``TRACKING_MAX_LAG_S``) that minimises the mean distance
    between the platform position at t and the target position at t − τ.

    Args:
        position_errors: ‖p* − p‖ per step, including the start [m], shape (T + 1,).
        orientation_errors: Orientation error per step [rad], shape (T + 1,).
        costs: ``cost`` per step (after each action), shape (T,).
        positions: Platform positions [m], shape (T + 1, d).
        target_positions: Target positions [m], shape (T + 1, d).
        dt: Control period [s].

    Returns:
        {"rms_position_mm", "max_position_mm", "rms_orientation_deg", "max_orientation_deg", "cost_fraction",
        "lag_s", "settling_s"}; NaN where the episode ended before the settling time.
    """
    skip = int(round(TRACKING_SETTLING_S / dt))
    pe, oe, cost = position_errors[skip:], orientation_errors[skip:], costs[skip:]
    if pe.size == 0:
        nan = float("nan")
        return dict.fromkeys(
            (
                "rms_position_mm",
                "max_position_mm",
                "rms_orientation_deg",
                "max_orientation_deg",
                "cost_fraction",
                "lag_s",
            ),
            nan,
        ) | {"settling_s": TRACKING_SETTLING_S}
    lags = range(min(int(round(TRACKING_MAX_LAG_S / dt)), len(positions) - skip - 1) + 1)
    mismatch = [
        float(np.mean(np.linalg.norm(positions[skip + s :] - target_positions[skip : len(positions) - s], axis=-1)))
        for s in lags
    ]
    return {
        "rms_position_mm": 1000.0 * float(np.sqrt(np.mean(pe**2))),
        "max_position_mm": 1000.0 * float(np.max(pe)),
        "rms_orientation_deg": float(np.degrees(np.sqrt(np.mean(oe**2)))),
        "max_orientation_deg": float(np.degrees(np.max(oe))),
        "cost_fraction": float(np.mean(cost)) if cost.size else 0.0,
        "lag_s": float(np.argmin(mismatch)) * dt,
        "settling_s": TRACKING_SETTLING_S,
    }


# -- agents ----------------------------------------------------------------------------------------


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
    cls = getattr(wrapper, "func", wrapper)
    kwargs = getattr(wrapper, "keywords", {})
    form = getattr(cls, "vector_form", None)
    return None if form is None else getattr(envs, form)(venv, **kwargs)


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


# -- episodes --------------------------------------------------------------------------------------


def _target_options(env: Any, targets: str | None) -> dict[str, str] | None:
    """The reset options for ``targets`` (None keeps the env's own setting); refuses what the env cannot take."""
    if targets is None:
        return None
    if targets not in TARGET_SETS:
        raise EvaluationError(f"--targets must be one of {list(TARGET_SETS)}, got {targets!r}")
    base = env.unwrapped
    options = getattr(base, "reset_options", None) or getattr(getattr(base, "_sampler", None), "reset_options", ())
    if "targets" not in options:
        name = env.spec.id if getattr(env, "spec", None) else type(base).__name__
        raise EvaluationError(f"--targets applies only to the Reach environments, not {name}")
    return {"targets": targets}


def _episode_record(
    base: Any,
    episode: int,
    last: dict[str, Any],
    total: float,
    series: dict[str, np.ndarray],
    costs: np.ndarray,
    planner: dict[str, float] | None,
) -> EpisodeRecord:
    """The record of one finished episode.

    Args:
        base: The unwrapped env (single or vector: ``with_velocity`` and ``params``).
        episode: Its index.
        last: The last step's info of this episode (scalars).
        total: Sum of its rewards.
        series: "pose", "target" (T + 1, m), "inverse_condition_number", "position_error", "orientation_error",
            "is_success" (T + 1,): from the reset to the last step.
        costs: ``cost`` per step, shape (T,).
        planner: The planning agent's ``episode_metrics``, or None.
    """
    reason = last["termination_reason"]
    tracking = None
    if getattr(base, "with_velocity", False):  # a Track environment
        poses, goal = series["pose"], series["target"]
        d = 3 if poses.shape[1] == 6 else 2  # position coordinates of the pose (spatial or planar)
        tracking = tracking_metrics(
            series["position_error"], series["orientation_error"], costs, poses[:, :d], goal[:, :d],
            float(base.params.dt),
        )  # fmt: skip
    reached = np.flatnonzero(series["is_success"])
    dt = getattr(getattr(base, "params", None), "dt", None)  # the family envs' control period; else unknown
    return EpisodeRecord(
        episode=episode,
        success=bool(last["is_success"]),
        final_position_error_mm=1000.0 * last["position_error"],
        final_orientation_error_deg=float(np.degrees(last["orientation_error"])),
        episode_return=total,
        min_inverse_condition=float(np.min(series["inverse_condition_number"])),
        singularity_termination=reason in SINGULARITY_REASONS,
        termination_reason=reason,
        cost_fraction=float(np.mean(costs)) if costs.size else 0.0,
        length=len(costs),
        poses=series["pose"],
        targets=series["target"],
        inverse_condition=series["inverse_condition_number"],
        tracking=tracking,
        planner=planner,
        time_to_target_s=float(reached[0] * dt) if reached.size and dt is not None else None,
    )


#: The per-step info entries an episode record keeps.
_SERIES = ("pose", "target", "inverse_condition_number", "position_error", "orientation_error", "is_success")


def evaluate_agent(
    agent: Agent,
    env: gym.Env,
    episodes: int,
    seed: int = 0,
    targets: str | None = None,
    frames: list[np.ndarray] | None = None,
    video_episodes: int = 3,
) -> list[EpisodeRecord]:
    """Run fixed-seed episodes (episode i resets with seed + i) and record them.

    Args:
        agent: Batched agent.
        env: A ``gym.make`` environment (with its TimeLimit).
        episodes: Number of episodes.
        seed: Seed of the first episode.
        targets: "standard" or "hard" (Reach environments only); None keeps the env's own setting
            (``Planar3RPRReachHard-v0`` samples hard targets).
        frames: If given, RGB frames of the first ``video_episodes`` episodes are appended to it.
        video_episodes: Episodes to film.

    Returns:
        One record per episode.
    """
    options = _target_options(env, targets)
    records = []
    for episode in range(episodes):
        obs, info = env.reset(seed=seed + episode, options=options)
        series = {key: [info[key]] for key in _SERIES}
        costs: list[float] = []
        total, done = 0.0, False
        film = frames is not None and episode < video_episodes
        if film:
            frames.append(env.render())
        while not done:
            batch = {key: value[None] for key, value in obs.items()} if isinstance(obs, dict) else obs[None]
            action = agent(batch)[0]
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            done = terminated or truncated
            for key in _SERIES:
                series[key].append(info[key])
            costs.append(info["cost"])
            if film:
                frames.append(env.render())
        planner = agent.episode_metrics() if hasattr(agent, "episode_metrics") else None
        arrays = {key: np.array(values) for key, values in series.items()}
        records.append(_episode_record(env.unwrapped, episode, info, total, arrays, np.array(costs), planner))
    return records


def make_vector_env(
    env_id: str, episodes: int, env_kwargs: dict[str, Any] | None = None, shield: float | None = None
) -> gym.vector.VectorEnv:
    """The native vector env of ``env_id`` with one row per episode (behind ``envs.VectorSingularityShield``)."""
    if env_id not in envs.ENV_IDS or gym.spec(env_id).vector_entry_point is None:
        raise EvaluationError(f"{env_id} has no native vector env of envs; ids: {list(envs.ENV_IDS)}")
    venv = gym.make_vec(env_id, num_envs=episodes, vectorization_mode="vector_entry_point", **(env_kwargs or {}))
    return venv if shield is None else envs.VectorSingularityShield(venv, k_guard=shield)


def evaluate_vector(
    agent: Agent, venv: gym.vector.VectorEnv, seed: int = 0, targets: str | None = None
) -> list[EpisodeRecord]:
    """Run one fixed-seed episode per row of a native vector env at once and record them.

    Row i resets with seed + i and is recorded up to its first end, so that its record is the one
    ``evaluate_agent`` makes of episode i on the single env (the vector env's row i is that single env to the
    last bit; a policy's actions for a batch may differ from its actions one at a time in the last bit of
    float32). The agent acts on every row at each step, which is where the time goes: one batched call per step
    instead of one per step and episode.

    Args:
        agent: Batched agent (a ``PlannerController`` plans per row).
        venv: ``make_vector_env(env_id, episodes, ...)``: a native vector env in ``AutoresetMode.NEXT_STEP``
            (rows that end restart at the next step and are no longer recorded).
        seed: Seed of the first row.
        targets: As ``evaluate_agent``.

    Returns:
        One record per row, in row order.
    """
    options = _target_options(venv, targets)
    n = venv.num_envs
    obs, info = venv.reset(seed=seed, options=options)
    series = {key: [np.array(info[key])] for key in _SERIES}
    costs: list[np.ndarray] = []
    totals = np.zeros(n)
    active = np.ones(n, dtype=bool)
    ends: dict[int, tuple[int, dict[str, Any], dict[str, float] | None]] = {}
    while active.any():
        obs, reward, terminated, truncated, info = venv.step(agent(obs))
        totals[active] += reward[active]  # the same additions, in the same order, as the single env's loop
        for key in _SERIES:
            series[key].append(np.array(info[key]))
        costs.append(np.array(info["cost"]))
        for i in np.flatnonzero(active & (terminated | truncated)):
            last = {
                "is_success": bool(info["is_success"][i]),
                "termination_reason": str(info["termination_reason"][i]),
                "position_error": float(info["position_error"][i]),
                "orientation_error": float(info["orientation_error"][i]),
            }
            planner = agent.episode_metrics(int(i)) if hasattr(agent, "episode_metrics") else None
            ends[int(i)] = (len(costs), last, planner)
            active[i] = False
    stacked = {key: np.stack(values) for key, values in series.items()}
    cost_steps = np.stack(costs)
    records = []
    for i in range(n):
        length, last, planner = ends[i]
        row = {key: np.ascontiguousarray(values[: length + 1, i]) for key, values in stacked.items()}
        records.append(
            _episode_record(venv.unwrapped, i, last, float(totals[i]), row, cost_steps[:length, i].copy(), planner)
        )
    return records


def evaluate_rows(
    agent: Agent,
    config: dict[str, Any],
    env_id: str,
    episodes: int,
    seed: int,
    targets: str | None,
    shield: float | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> list[EpisodeRecord]:
    """Episodes i = 0 … episodes − 1 (reset seed ``seed + i``) of ``agent`` on ``env_id``, behind the shield if set.

    The env is built with ``env_kwargs`` (default: the run's own but its reward, ``evaluation_env_kwargs(config)``);
    ``config`` is the
    run's config ({} for a classical controller).

    All episodes run at once on the id's native vector env (``evaluate_vector``, with the vector
    form of the run's ``env_wrapper``), except for a run whose wrapper has no vector form (the goal view of HER),
    which runs them one after the other (``evaluate_agent``). The records are the same either way (a policy's
    batched actions aside, which may differ in the last bit of float32). The shield sits inside the run's wrapper:
    it filters the action the env receives (a residual policy's sum).
    """
    env_kwargs = evaluation_env_kwargs(config) if env_kwargs is None else env_kwargs
    if env_id in envs.ENV_IDS:
        plain = make_vector_env(env_id, episodes, env_kwargs, shield)
        venv = wrap_vector_for_run(plain, config)
        try:
            if venv is not None:
                return evaluate_vector(agent, venv, seed, targets)
        finally:
            plain.close()
    env = gym.make(env_id, **env_kwargs)
    if shield is not None:
        env = envs.SingularityShield(env, k_guard=shield)
    env = wrap_for_run(env, config)
    try:
        return evaluate_agent(agent, env, episodes, seed, targets)
    finally:
        env.close()


def aggregate(records: list[EpisodeRecord]) -> dict[str, Any]:
    """Aggregate metrics over episodes (means with standard deviations where it makes sense).

    Args:
        records: Evaluated episodes.

    Returns:
        A JSON-ready dict.
    """

    def stats(values: list[float]) -> dict[str, float]:
        arr = np.asarray(values, dtype=float)
        return {"mean": float(arr.mean()), "std": float(arr.std()), "median": float(np.median(arr))}

    reasons = [r.termination_reason for r in records]
    tracking = {}
    if records and all(r.tracking is not None for r in records):
        keys = [k for k in records[0].tracking if k != "settling_s"]
        tracking = {
            "tracking": {
                "settling_s": records[0].tracking["settling_s"],
                **{k: stats([r.tracking[k] for r in records if np.isfinite(r.tracking[k])] or [np.nan]) for k in keys},
            }
        }
    planner = {}
    if records and all(r.planner is not None for r in records):
        planner = {
            "planner": {
                "path_found_rate": float(np.mean([r.planner["path_found"] for r in records])),
                **{
                    k: stats([r.planner[k] for r in records])
                    for k in ("planned_length_ratio", "planned_min_k", "planning_s")
                },
            }
        }
    reached = [r.time_to_target_s for r in records if r.time_to_target_s is not None]
    time_to_target = {"time_to_target_s": {**stats(reached), "episodes": len(reached)}} if reached else {}
    return {
        "episodes": len(records),
        "success_rate": float(np.mean([r.success for r in records])),
        "final_position_error_mm": stats([r.final_position_error_mm for r in records]),
        "final_orientation_error_deg": stats([r.final_orientation_error_deg for r in records]),
        "return": stats([r.episode_return for r in records]),
        "min_inverse_condition": {
            **stats([r.min_inverse_condition for r in records]),
            "min": float(min(r.min_inverse_condition for r in records)),
        },
        "singularity_terminations": int(sum(r.singularity_termination for r in records)),
        "terminations": {name: reasons.count(name) for name in TERMINATION_REASONS[1:] if reasons.count(name)},
        "cost_fraction": stats([r.cost_fraction for r in records]),
        "episode_length": stats([r.length for r in records]),
        **tracking,
        **planner,
        **time_to_target,
    }


def format_table(rows: dict[str, dict[str, Any]]) -> str:
    """A Markdown table of aggregated metrics, one row per agent/target set, and its note.

    "success 95 % CI" is ``training.intervals.success_interval`` of the row's one run: rliable's stratified
    bootstrap (95 %, percentile) of the success rate, resampling the run's episodes. A line under the table says so.

    Args:
        rows: Label → ``aggregate`` output.

    Returns:
        The table and its note as Markdown text.
    """
    head = (
        "| agent | targets | success | success 95 % CI | final pos. error [mm] | final orient. error [deg] "
        "| min k (mean / worst) | singularity terminations | cost fraction | return |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for label, m in rows.items():
        agent, _, targets = label.partition(" @ ")
        lines.append(
            f"| {agent} | {targets or '-'} | {100 * m['success_rate']:.0f} % | {format_success_interval([m])} "
            f"| {m['final_position_error_mm']['median']:.2f} (median) "
            f"| {m['final_orientation_error_deg']['median']:.2f} (median) "
            f"| {m['min_inverse_condition']['mean']:.3f} / {m['min_inverse_condition']['min']:.3f} "
            f"| {m['singularity_terminations']} / {m['episodes']} "
            f"| {m['cost_fraction']['mean']:.3f} | {m['return']['mean']:.1f} ± {m['return']['std']:.1f} |"
        )
    return head + "\n".join(lines) + f"\n\n{SUCCESS_CI_NOTE}\n"


def print_table(rows: dict[str, dict[str, Any]]) -> None:
    """Print aggregated metrics as a table on the terminal (rich)."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title="evaluation")
    for name in ("agent @ targets", "success", "pos. err [mm]", "orient. err [deg]", "min k", "sing. term.", "cost"):
        table.add_column(name)
    for label, m in rows.items():
        table.add_row(
            label,
            f"{100 * m['success_rate']:.0f} %",
            f"{m['final_position_error_mm']['median']:.2f}",
            f"{m['final_orientation_error_deg']['median']:.2f}",
            f"{m['min_inverse_condition']['mean']:.3f} / {m['min_inverse_condition']['min']:.3f}",
            f"{m['singularity_terminations']} / {m['episodes']}",
            f"{m['cost_fraction']['mean']:.3f}",
        )
    Console(width=140).print(table)


# -- output ----------------------------------------------------------------------------------------


def write_outputs(
    out: Path, label: str, env: gym.Env, records: list[EpisodeRecord], frames: list[np.ndarray] | None
) -> dict[str, Any]:
    """Write metrics.json, episodes.csv, the pictures and the GIF of one evaluation.

    Args:
        out: Output folder (created).
        label: Name of the agent and target set, for titles.
        env: The evaluated environment.
        records: Its episodes.
        frames: Video frames, or None.

    Returns:
        The aggregated metrics.
    """
    from training import plots

    out.mkdir(parents=True, exist_ok=True)
    metrics = aggregate(records)
    env_id = env.spec.id if env.spec is not None else None
    (out / "metrics.json").write_text(json.dumps({"label": label, "env_id": env_id, **metrics}, indent=2) + "\n")
    with open(out / "episodes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(records[0].row()))
        writer.writeheader()
        for r in records:
            writer.writerow(r.row())
    params = env.unwrapped.params
    workspace = getattr(env.unwrapped, "workspace", None)  # the planar 3-RPR's certified grid
    if workspace is not None:
        plots.trajectories_figure({label: records}, params, workspace, out / "trajectories.png")
    plots.condition_figure({label: records}, params, out / "condition_number.png")
    if frames:
        plots.save_gif(frames, out / "episodes.gif", fps=env.unwrapped.metadata["render_fps"])
    return metrics


def parse_env_kwargs(items: list[str]) -> dict[str, Any]:
    """Env keyword arguments from ``KEY:VALUE`` strings (the RL Zoo's ``--env-kwargs``; values read as YAML).

    Raises:
        EvaluationError: On an item without a colon, an empty key, a repeated key or a value YAML cannot read.
    """
    kwargs: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition(":")
        if not sep or not key:
            raise EvaluationError(f"--env-kwargs takes KEY:VALUE items, got {item!r}")
        if key in kwargs:
            raise EvaluationError(f"--env-kwargs gives {key!r} twice")
        try:
            kwargs[key] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise EvaluationError(f"--env-kwargs {item!r}: the value is not YAML ({exc})") from None
    return kwargs


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(prog="python -m training.evaluate", description=__doc__.split("\n")[0])
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--run", help="run folder written by training.train or by the RL Zoo (rl_zoo3.train)")
    source.add_argument("--controller", help=f"one of {sorted(CONTROLLERS)}")
    parser.add_argument("--env", default=None, help=f"one of {list(envs.ENV_IDS)}; default: the run's env")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0, help="episode i resets with seed + i")
    parser.add_argument(
        "--targets", default=None, help=f"one of {list(TARGET_SETS)} (Reach only); default: the env's own"
    )
    parser.add_argument("--video", action="store_true", help="write a GIF of the first episodes")
    parser.add_argument("--out", default=None, help="output folder; default: <run>/eval-<targets> or evals/...")
    parser.add_argument("--model", default="final", help="final (model.zip) or best (best_model.zip)")
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        default=[],
        metavar="KEY:VALUE",
        help="keyword arguments of the env, in the RL Zoo's form (values read as YAML: task_region:box, "
        "sample_low:[-0.1,-0.1,-0.5], robot:planar_3rpr)",
    )
    parser.add_argument(
        "--planner",
        default=None,
        choices=("auto", "ompl", "grid"),
        help="the planner controller's planner (default auto: the certified grid where the env has one, else OMPL)",
    )
    parser.add_argument(
        "--replan-distance",
        type=float,
        default=None,
        metavar="METRES",
        help="the planner controller plans afresh whenever the platform is farther than this from its path "
        "(default: one plan per episode)",
    )
    parser.add_argument(
        "--shield",
        type=float,
        default=None,
        metavar="K_GUARD",
        help="wrap the env in envs.SingularityShield with this guard level (for example 0.05)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m training.evaluate``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.episodes < 1:
            raise EvaluationError(f"--episodes must be ≥ 1, got {args.episodes}")
        run_kwargs: dict[str, Any] = {}
        if args.run is not None:
            config = read_run_config(args.run)
            env_id = args.env or config["env_id"]
            if env_id == config["env_id"]:  # the run's env as it was trained (its reward aside), unless told otherwise
                run_kwargs = evaluation_env_kwargs(config)
        else:
            env_id = args.env or "Planar3RPRReach-v0"
        if env_id not in envs.ENV_IDS:
            raise EvaluationError(f"unknown env id {env_id!r}; valid choices: {list(envs.ENV_IDS)}")
        if args.targets is not None and args.targets not in TARGET_SETS:
            raise EvaluationError(f"--targets must be one of {list(TARGET_SETS)}, got {args.targets!r}")
        env_kwargs = {**run_kwargs, **parse_env_kwargs(args.env_kwargs)}
        try:
            env = gym.make(env_id, render_mode="rgb_array" if args.video else None, **env_kwargs)
        except (TypeError, ValueError) as exc:
            raise EvaluationError(f"--env-kwargs {' '.join(args.env_kwargs)}: {exc}") from None
        shielded = " + shield" if args.shield is not None else ""
        if shielded:
            try:
                env = envs.SingularityShield(env, k_guard=args.shield)
            except ValueError as exc:
                raise EvaluationError(f"--shield: {exc}") from None
        reach = "targets" in type(env.unwrapped).reset_options
        targets = args.targets or (getattr(env.unwrapped, "targets", "standard") if reach else "track")
        if args.run is not None:
            agent, _ = load_run(args.run, args.model)
            env = wrap_for_run(env, config)
            check_compatible(agent, env, f"run {args.run!r}")
            name = f"{config['algo']} ({Path(args.run).name}){shielded}"
            out = Path(args.out) if args.out else Path(args.run) / f"eval-{env_id}-{targets}"
        else:
            for option in ("planner", "replan_distance"):
                if getattr(args, option) is not None and args.controller != "planner":
                    flag = "--" + option.replace("_", "-")
                    raise EvaluationError(f"{flag} applies to --controller planner, not {args.controller!r}")
            agent = load_controller(args.controller, env, args.planner, args.replan_distance)
            name = args.controller + (f" ({args.planner})" if args.planner else "") + shielded
            if args.replan_distance is not None:
                name += f", replanning {args.replan_distance:g} m off its path"
            out = Path(args.out) if args.out else Path("evals") / f"{args.controller}-{env_id}-{targets}"
        if shielded and args.out is None:
            out = out.with_name(f"{out.name}-shield")
        frames: list[np.ndarray] | None = [] if args.video else None
        if frames is None:  # every episode at once where the env (and the run's wrapper) has a vector form
            run_config = config if args.run is not None else {}
            records = evaluate_rows(
                agent, run_config, env_id, args.episodes, args.seed, args.targets, args.shield, env_kwargs
            )
        else:
            records = evaluate_agent(agent, env, args.episodes, args.seed, args.targets, frames)
        label = f"{name} @ {targets}"
        metrics = write_outputs(out, label, env, records, frames)
    except (EvaluationError, ConfigError) as exc:
        parser.error(str(exc))
    print_table({label: metrics})
    print(f"outputs written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
